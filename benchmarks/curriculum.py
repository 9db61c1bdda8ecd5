"""Experiment 2's costs on the GPU machine: a curriculum chunk, its parts, and bare PPO, in one run.

    python benchmarks/curriculum.py [--archive A.npz] [--trials 1,10] [--chunks 2] [--parts] [--curricula map,dr]
        [--recipe paper|wide] [--num-envs N --num-unrolls U] [--overlap off,on] [--truncation mask,bootstrap] [--start RUN]
        [--devices 1,2] [--robot NAME] [--out result.json]

Builds exactly what ``python -m experiments learn --preset gpu-short`` builds (``experiments.runner.setup``: the bank
of the archive, the base policy, the walker, the compiled block of chunks) and measures, each after its compile (the
compile seconds are reported too; ``JAX_COMPILATION_CACHE_DIR`` lets a second command on the same machine skip them):

1. ``block``: the learn command's jitted block (every trial's envs restart on its terrain, then ``--chunks`` chunks:
   PPO training on the current terrain, an evaluation, the GP update and the terrain switch) for each ``--trials``
   count T: seconds per chunk and env steps/s (T x 160 000 env steps per chunk);
2. ``train`` / ``evaluate``: the harness's two parts alone, vmapped over T trials on fixed terrains: seconds per
   chunk each (where a chunk's time goes), and the sequential env steps of each (training: updates x unroll length
   x unrolls; evaluation, on a tiled walker: the walks' loop counted once more, until every walk of every trial
   ended);
3. ``ppo``: bare PPO (``rl.run_updates``, the curriculum's PPO config, one fixed terrain, the same updates per chunk,
   no evaluation, no curriculum) at T = 1: the peer of the curriculum-overhead ratio (issue 13: >= 0.9x).

``--overlap off,on`` times the block both ways (``CurriculumConfig.overlap``: each chunk's evaluation walks ride
along the next chunk's PPO steps); with overlap a block of n chunks takes one step more per terrain switch, so
``s_per_chunk`` is per chunk done (the mean over trials), and ``switches`` counts the switches in the timed chunks.
``loop_steps`` / ``s_per_step``: the loop's steps in the timed call (from the history: an upper bound by one) and
the seconds per step, which with the switches of a whole run (``history.csv``) give its time.
``--truncation mask,bootstrap`` times bare PPO and the block under each ``PPOConfig.truncation`` (``bootstrap``: one
more value-net call per env step, on the observation before the auto-reset; default: the preset's), in the order
given (``mask,bootstrap,mask`` brackets the one with the other, to see the machine's drift); the ratio printed is
bootstrap's seconds per chunk over the mean of mask's; the other ratios use the first mode given.
``--curricula map,dr,levels`` times the block of each curriculum (the first the peer): ``dr_vs_map_T10`` is dr's env
steps/s over map's at 10 trials (issue 46: a per-env selector costs at most 10 %, ratio >= 0.9).
``--devices 1,2`` times each block with its trials split over that many devices (``learn --devices N``:
``curriculum.make_runner`` over a mesh; without the flag, the one-device runner): ``devices_N_vs_1_T{trials}`` is
the env steps/s on N devices over one's (issue 48: >= 1.8x on 2 GPUs).
``--start RUN`` starts every block from the checkpoint of a ``learn`` run of the same preset and trial count (e.g.
the paper run at chunk 550, where terrains change less often than in the first chunks) instead of chunk 0; pass
the run's ``--archive`` too. With ``--parts`` the parts then time each trial's restored policy on its current
terrain. An ``--overlap`` run's checkpoint starts an overlapped block where it stood (its chunk
trained ahead still pending).

Ratios printed: curriculum overhead = block env steps/s at T=1 / bare PPO's (``curriculum_overhead_overlap``: the
overlapped block's, per chunk done); trials at once = block env steps/s at the largest T / at T=1 (issue 13: >= 3x
for 10 trials). Extrapolated: a paper-budget trial (750 chunks) at T=1
and the 10 trials of a treatment, from the measured seconds per chunk.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import common  # noqa: E402
from jaxterrain.curriculum import presets, run_config, runner  # noqa: E402
from jaxterrain import rl  # noqa: E402
from jaxterrain.rl.config import TRUNCATIONS  # noqa: E402
from jaxterrain.curriculum import walker as W  # noqa: E402
from jaxterrain.runtime import sharding  # noqa: E402


def timed(fn, *args):
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn(*args))
    return out, time.perf_counter() - t0


def learn_cfg(args, trials: int, overlap: bool = False, truncation: str | None = None,
              curriculum: str | None = None) -> dict:
    cfg = {**presets.FLAT_PRESETS[args.preset], "seed": 0, "trials": trials, "overlap": overlap}
    if curriculum is not None:
        cfg["curriculum"] = curriculum
    if truncation is not None:
        cfg["truncation"] = truncation
    if args.archive:
        cfg["archive"] = args.archive
    if args.backend and "backend" in cfg:
        cfg["backend"] = args.backend
    elif args.backend not in (None, "jax"):
        raise SystemExit(f"this learn command has no backend setting; --backend {args.backend} is not available")
    if args.recipe:
        from jaxterrain.curriculum import recipe

        cfg.update(recipe=args.recipe, **recipe(args.recipe))
    if args.num_envs:
        cfg["num_envs"] = args.num_envs
    if args.num_unrolls:
        cfg["num_unrolls"] = args.num_unrolls
    if args.headings:
        cfg["headings"] = args.headings
    if args.robot:
        cfg["robot"] = args.robot
    return cfg


def start_states(folder, states):
    """``states`` (a learn block's, stripped of env states) replaced by the checkpoint in ``folder``: a plain run's
    (for an overlapped block nothing is pending then) or an ``--overlap`` run's (its pending chunk kept for an
    overlapped block; dropped for a plain one, whose policy then holds the chunk trained ahead: fine for timing,
    not for comparing end states)."""
    from jaxterrain.runtime import driver

    saved = bool(((driver.read_meta(folder) or {}).get("config") or {}).get("overlap"))
    nothing = jnp.zeros(np.shape(states.chunk), bool)
    restored = driver.restore(Path(folder), like=states._replace(pending=nothing if saved else None))
    if restored is None:
        raise SystemExit(f"--start {folder}: no checkpoint there")
    if states.pending is None:
        return restored[0]._replace(pending=None)
    return restored[0] if saved else restored[0]._replace(pending=nothing)


def trial_switches(states, before) -> np.ndarray:
    """``[T]`` terrain switches decided by the evaluations of each trial's chunks ``before[t] ..`` (the history:
    chunk c's terrain differs from chunk c + 1's, or the trial ended by switching to a terrain not yet recorded)."""
    terrain, chunk = np.asarray(states.history.terrain), np.asarray(states.chunk)
    out = np.zeros(terrain.shape[0], np.int64)
    for t in range(terrain.shape[0]):
        seq = list(terrain[t, before[t]:chunk[t]]) + [int(np.asarray(states.terrain)[t])]
        out[t] = sum(a != b for a, b in zip(seq[:-1], seq[1:]))
    return out


def chunk_kinds(config, states) -> dict:
    """``{"replay_chunks" / "edit_chunks": [T]}``, the selector's own counts so far (plr, accel; else empty)."""
    from jaxterrain.curriculum import get_selector

    summary = jax.vmap(get_selector(config).summary)(states.selector)
    return {k: np.asarray(v) for k, v in summary.items() if k in ("replay_chunks", "edit_chunks")}


def measure_block(args, trials: int, overlap: bool = False, truncation: str | None = None,
                  curriculum: str | None = None, devices: int | None = None) -> dict:
    """The learn command's block at ``trials``: compile seconds, seconds per chunk, env steps/s; ``devices``: the
    trials split over that many devices (a mesh, as ``learn --devices N``; None: the one-device runner)."""
    cfg = learn_cfg(args, trials, overlap, truncation, curriculum)
    run, config, arch, policy, env = runner.validate(run_config.from_flat(cfg))
    mesh = None if devices is None else sharding.setup(devices)
    t0 = time.perf_counter()
    bank, block, states = runner.setup(run, config, arch, policy, env, mesh)
    jax.block_until_ready(states)
    compile_s = time.perf_counter() - t0
    start = None  # --start's restored states, for the parts
    if args.start:
        states = start = start_states(args.start, states)
    states, first = timed(block, states, bank, 1)  # first call: a chunk (and any lazy work)
    before = np.asarray(states.chunk)
    kinds_before = chunk_kinds(config, states)
    pending = np.ones(trials, bool) if states.pending is None else np.asarray(states.pending)
    states, t = timed(block, states, bank, args.chunks)
    chunks = np.asarray(states.chunk) - before
    switched = trial_switches(states, before)
    kinds = {k: float(np.mean(v - kinds_before[k])) for k, v in chunk_kinds(config, states).items()}
    # loop steps: one per chunk; with overlap one more per switch and where nothing was pending at the start (the
    # last step of a trial that switched may fall outside the block: an upper bound)
    steps = int(np.max(chunks + (switched + ~pending if overlap else 0)))
    done = float(np.mean(chunks))
    per_chunk = t / done
    row = {"part": "block (learn)" + (", overlap" if overlap else ""), "curriculum": cfg["curriculum"],
           "recipe": cfg.get("recipe"), "num_envs": cfg["num_envs"], "num_unrolls": cfg["num_unrolls"],
           "trials": trials, "devices": devices or 1, "robot": cfg.get("robot") or "humanoid",
           "truncation": cfg["truncation"], "compile_s": compile_s,
           "first_chunk_s": first, "s_per_chunk": per_chunk,
           "env_steps_per_s": trials * config.steps_per_chunk / per_chunk, "chunks_done": done,
           "chunk_reached": int(np.max(np.asarray(states.chunk))), "switches": int(np.sum(switched)),
           "loop_steps": steps, "s_per_step": t / steps, "hardest_mean": float(np.mean(np.asarray(states.hardest))),
           **{f"{k}_timed": v for k, v in kinds.items()}}  # plr / accel: mean replay (edit) chunks per trial timed
    if args.parts and runner.selector_slots(run) == 1:  # the parts of a one-terrain curriculum
        row.update(measure_parts(cfg, config, bank, policy, env, trials, start))
    return row


def measure_parts(cfg, config, bank, policy, env, trials: int, states=None) -> dict:
    """The harness's train and evaluate alone, vmapped over ``trials`` on fixed terrains (laid out as the block lays
    them out: through ``harness.layout`` on a tiled walker, e.g. Warp's, one tile per trial and heading): the base
    policy on the bank's first terrains, or with ``states`` (``--start``'s restored trial states) each trial's policy
    on its current terrain (where a late run's chunk time goes)."""
    ppo = config.ppo_config(policy.config)
    harness = W.walker_harness(env, ppo, config)
    if states is None:
        start = W.start_state(env, ppo, policy, bank.heightmaps.shape[1:])
        maps = bank.heightmaps[jnp.arange(trials) % bank.heightmaps.shape[0]]
        policies = jax.tree.map(lambda x: jnp.broadcast_to(x, (trials,) + x.shape), start)
    else:
        maps, policies = bank.heightmaps[states.terrain], states.policy
    terrains, axes = (maps, 0) if harness.layout is None else harness.layout(maps)
    keys = jax.random.split(jax.random.key(1), trials)

    def vmapped(fn):
        return jax.jit(jax.vmap(fn, in_axes=(0, 0, axes)))

    policies = vmapped(harness.reset)(policies, keys, terrains)
    train, evaluate = vmapped(harness.train), vmapped(harness.evaluate)
    t0 = time.perf_counter()
    trained = jax.block_until_ready(train(policies, keys, terrains))
    train_compile = time.perf_counter() - t0
    trained, train_s = timed(train, trained, keys, terrains)
    t0 = time.perf_counter()
    jax.block_until_ready(evaluate(trained, keys, terrains))
    eval_compile = time.perf_counter() - t0
    fit, eval_s = timed(evaluate, trained, keys, terrains)
    row = {"train_compile_s": train_compile, "train_s_per_chunk": train_s, "eval_compile_s": eval_compile,
           "eval_s_per_chunk": eval_s, "eval_fitness_mean": float(np.mean(np.asarray(fit))),
           "train_seq_steps": config.updates_per_chunk * ppo.unroll_length * ppo.num_unrolls}
    if harness.layout is not None:  # the evaluation's loop again, counting its sequential env steps
        protocol = config.protocol.validate()
        count = jax.jit(lambda s, k, t: W._tile_walks(
            env, rl.policy_fn(ppo, env.action_size), protocol.attempts, protocol.headings, t.bank.data, t.index, k,
            (s.params, s.normaliser), 0, steps=True)[1])
        row["eval_seq_steps"] = int(count(trained, keys, terrains))
    return row


def measure_ppo(args, truncation: str | None = None) -> dict:
    """Bare PPO on one fixed terrain with the curriculum's PPO config, one chunk's updates per call (on a tiled
    walker, all its envs on one tile holding that terrain)."""
    cfg = learn_cfg(args, 1, truncation=truncation)
    run, config, arch, policy, env = runner.validate(run_config.from_flat(cfg))
    bank, _, _ = runner.setup(run, config, arch, policy, env)
    ppo = config.ppo_config(policy.config)
    terrain = bank.heightmaps[0]
    if env.tiles:  # a tiled walker (e.g. Warp's): that terrain on tile 0, every env on it
        tile, _ = W.tile_layout(env)(bank.heightmaps[:1])
        terrain = tile._replace(index=tile.index[0])
    start = W.start_state(env, ppo, policy, bank.heightmaps.shape[1:])
    state = jax.jit(lambda s, k, t: rl.reset_envs(s, k, t, env=env, config=ppo))(start, jax.random.key(2), terrain)
    run = jax.jit(lambda s, t: rl.run_updates(s, t, env=env, config=ppo, num_updates=config.updates_per_chunk)[0])
    t0 = time.perf_counter()
    state = jax.block_until_ready(run(state, terrain))
    compile_s = time.perf_counter() - t0
    times = []
    for _ in range(args.repeats):
        state, t = timed(run, state, terrain)
        times.append(t)
    t = float(np.median(times))
    return {"part": "bare PPO (one terrain)", "robot": cfg.get("robot") or "humanoid", "trials": 1, "devices": 1,
            "truncation": cfg["truncation"], "compile_s": compile_s,
            "s_per_chunk": t, "env_steps_per_s": config.steps_per_chunk / t}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--archive", default=None, help=f"default: the learn command's ({presets.CPPN_ARCHIVE})")
    p.add_argument("--preset", default="gpu-short", choices=sorted(presets.FLAT_PRESETS), help="the learn preset (smoke: CPU)")
    p.add_argument("--trials", default="1,10", help="comma list of trial counts")
    p.add_argument("--chunks", type=int, default=2, help="chunks per timed block call")
    p.add_argument("--repeats", type=int, default=2, help="bare PPO: timed calls")
    p.add_argument("--num-envs", type=int, default=None, help="PPO envs per trial (default: the preset's)")
    p.add_argument("--recipe", choices=("paper", "wide"), default=None,
                   help="learn's --recipe: the update's shape (jaxterrain.curriculum.RECIPES; before --num-envs)")
    p.add_argument("--num-unrolls", type=int, default=None,
                   help="PPO unrolls per update (default: the preset's); e.g. --num-envs 2000 --num-unrolls 2 keeps "
                        "40 000 env steps per update in a quarter of the sequential env steps")
    p.add_argument("--headings", type=int, choices=(1, 2, 4), default=None,
                   help="evaluation headings (default: the preset's, else the archive's protocol)")
    p.add_argument("--backend", default=None, help="walker backend, where the learn command has the setting")
    p.add_argument("--parts", action="store_true", help="also time train / evaluate alone (two more compiles)")
    p.add_argument("--skip-ppo", action="store_true", help="skip bare PPO")
    p.add_argument("--overlap", default="off", help="comma list of off / on: the block without / with overlap")
    p.add_argument("--truncation", default=None,
                   help="comma list of mask / bootstrap (PPOConfig.truncation; default: the preset's)")
    p.add_argument("--start", default=None, help="start the blocks from this learn run's checkpoint")
    p.add_argument("--curricula", default=None,
                   help="comma list of learn --curriculum names timed as blocks, the first the peer of the others' "
                        "ratios (e.g. map,dr,levels: the per-env selectors' cost; default: the preset's)")
    p.add_argument("--robot", default=None, metavar="NAME",
                   help="learn --robot NAME (its base policy; pass its --archive too, e.g. the ant's "
                        "docs/results/ant_gpushort/archive/archive.npz)")
    p.add_argument("--devices", default=None,
                   help="comma list of device counts, each block timed with its trials split over that many devices "
                        "(learn --devices N; default: the one-device runner)")
    p.add_argument("--out", default=None)
    args = p.parse_args()
    device_counts = [None] if args.devices is None else [int(n) for n in args.devices.split(",")]
    if any(n is not None and not 1 <= n <= jax.device_count() for n in device_counts):
        p.error(f"--devices: counts from 1 to the {jax.device_count()} devices here; got {args.devices!r}")
    modes = [{"off": False, "on": True}[m] for m in args.overlap.split(",")]
    truncations = (args.truncation or presets.FLAT_PRESETS[args.preset]["truncation"]).split(",")
    if not set(truncations) <= set(TRUNCATIONS):
        p.error(f"--truncation: a comma list of {', '.join(TRUNCATIONS)}; got {args.truncation!r}")

    env = common.environment()
    print(f"# curriculum on {env['device']} ({env['date']}, commit {env['commit']}, jax {env['jax']})", flush=True)
    rows = []
    if not args.skip_ppo:
        for truncation in truncations:
            rows.append(measure_ppo(args, truncation))
            print(rows[-1], flush=True)
    curricula = args.curricula.split(",") if args.curricula else [presets.FLAT_PRESETS[args.preset]["curriculum"]]
    for trials in [int(t) for t in args.trials.split(",")]:
        for overlap in modes:
            for truncation in truncations:
                for curriculum in curricula:
                    for devices in device_counts:
                        rows.append(measure_block(args, trials, overlap, truncation, curriculum, devices))
                        print(rows[-1], flush=True)
    ratios = {}
    first, reference = truncations[0], curricula[0]  # the reference mode / curriculum of every other ratio
    one = device_counts[0] or 1  # the device count of the ratios below but devices_N_vs_1
    rows_one = [r for r in rows if r["devices"] == one or not r["part"].startswith("block")]  # bare PPO: 1 device
    blocks = {r["trials"]: r for r in rows_one if r["part"] == "block (learn)" and r["truncation"] == first
              and r["curriculum"] == reference}
    for r in rows:  # each device count's env steps/s over one device's, same block otherwise
        peer = next((q for q in rows if q["devices"] == 1 and all(q.get(k) == r.get(k) for k in
                     ("part", "trials", "truncation", "curriculum"))), None)
        if r["part"].startswith("block") and r["devices"] > 1 and peer is not None:
            suffix = "_overlap" if r["part"].endswith("overlap") else ""
            ratios[f"devices_{r['devices']}_vs_1_T{r['trials']}{suffix}"] = r["env_steps_per_s"] / peer["env_steps_per_s"]
    block_rows = [r for r in rows_one if r["part"].startswith("block")]  # bare PPO has no curriculum
    for r in block_rows:  # each curriculum's env steps/s over the first's, same trials, mode and truncation
        peer = next((q for q in block_rows if q["part"] == r["part"] and q["trials"] == r["trials"]
                     and q["truncation"] == r["truncation"] and q["curriculum"] == reference), None)
        if r["curriculum"] != reference and peer is not None:
            ratios[f"{r['curriculum']}_vs_{reference}_T{r['trials']}"] = r["env_steps_per_s"] / peer["env_steps_per_s"]
    overlapped = {r["trials"]: r for r in rows_one if r["part"] == "block (learn), overlap" and r["truncation"] == first
                  and r["curriculum"] == reference}
    for part, name in (("bare PPO (one terrain)", "ppo"), ("block (learn)", "block"),
                       ("block (learn), overlap", "block_overlap")):
        for trials in sorted({r["trials"] for r in rows_one if r["part"] == part}):
            mode = {t: [r["s_per_chunk"] for r in rows_one
                        if (r["part"], r["trials"], r["truncation"]) == (part, trials, t)] for t in TRUNCATIONS}
            if mode["mask"] and mode["bootstrap"]:
                ratios[f"bootstrap_cost_{name}_T{trials}"] = float(np.mean(mode["bootstrap"]) / np.mean(mode["mask"]))
    paper_chunks = presets.FLAT_PRESETS["paper"]["max_epochs"] // presets.FLAT_PRESETS["paper"]["epochs_per_chunk"]
    ppo = next((r for r in rows if r["part"] == "bare PPO (one terrain)" and r["truncation"] == first), None)
    if 1 in blocks:
        ratios["paper_trial_minutes_T1"] = blocks[1]["s_per_chunk"] * paper_chunks / 60
        if ppo is not None:
            ratios["curriculum_overhead"] = blocks[1]["env_steps_per_s"] / ppo["env_steps_per_s"]
        big = max(blocks)
        if big > 1:
            ratios[f"trials_{big}_vs_1"] = blocks[big]["env_steps_per_s"] / blocks[1]["env_steps_per_s"]
            ratios[f"paper_treatment_minutes_T{big}"] = blocks[big]["s_per_chunk"] * paper_chunks / 60
    for trials, row in overlapped.items():
        ratios[f"overlap_paper_minutes_T{trials}"] = row["s_per_chunk"] * paper_chunks / 60
        if trials == 1 and ppo is not None:
            ratios["curriculum_overhead_overlap"] = row["env_steps_per_s"] / ppo["env_steps_per_s"]
        if trials in blocks:
            ratios[f"overlap_speedup_T{trials}"] = blocks[trials]["s_per_chunk"] / row["s_per_chunk"]
    print()
    cols = ["part", "robot", "curriculum", "recipe", "num_envs", "trials", "devices", "truncation", "compile_s", "s_per_chunk", "env_steps_per_s", "chunks_done", "switches",
            "loop_steps", "s_per_step", "train_s_per_chunk", "eval_s_per_chunk", "train_seq_steps", "eval_seq_steps",
            "train_compile_s", "eval_compile_s", "replay_chunks_timed", "edit_chunks_timed"]
    print(common.markdown_table(rows, cols))
    print(ratios, flush=True)
    common.write_json(args.out, {"environment": env, "rows": rows, "ratios": ratios})


if __name__ == "__main__":
    main()
