"""How long a curriculum's evaluation walks last, from a treatment's checkpoint.

    python docs/results/exp2_paper_bootstrap/walk_lengths.py RUN/TREATMENT [--trials 0,1,...] [--backend jax|warp]
        [--park off|on|off,on,...] [--out F.json]

Restores each trial's policy (params, normaliser) and current terrain from ``TREATMENT/checkpoint.npz`` of a
``curriculum`` / ``learn`` run, walks the treatment's evaluation (its protocol's attempts and headings, laid out on
tiles as the learn block lays them out) with the deterministic policy, and records when each walk ended and how
(fell, reached the goal, or the episode limit); on MJX-JAX also the feet's contacts with the terrain per step
(``dist < 0``; at most 8: two feet, up to four heightfield contacts each). Printed per trial: the walk lengths
(median, 90th percentile, max), the outcome counts and the contacts per step. Over all trials: the walks' loop
length (its longest walk: the sequential env steps the evaluation adds to a chunk beyond the PPO steps it rides
along under ``--overlap``).

Why: the Perlin map treatment's chunks took about 4, 6 and 8.6 s on the GPU as its evaluation fell (exp2_paper.md).
Two suspects: longer walks (the loop runs until its longest walk ends) and more contacts per step (more constraint
rows for the solver). ``--backend`` (default ``jax``, which every machine has) picks the physics; the run's was
``warp``. Timed: ``compile_s`` (trace and compile) and ``seconds`` (the walks alone).

Solver readout (``--backend warp``; MJX-JAX neither records its iterations nor varies its rows): per walk-step,
split into walks still running and walks already ended (which the loop keeps stepping until its longest walk ends),
the last substep's Newton iterations (``solver_niter``), the share at the iteration cap and the constraint rows
(``nefc``, per world); per loop step, their maximum over all walks. ``--park on`` parks every ended walker after
each step (``WalkerEnv.park``: out of contact; its result is already recorded, so the walks' ends must not change):
``off,on`` times both in one process, to see what the ended walks cost. The ``*_warp_park.json`` outputs of d97325d
lifted walkers 100 m above their own height instead of above the terrain's top (the same rows: none in contact).
"""
import argparse
import json
import pathlib
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[3]))

from jaxterrain.curriculum import runner  # noqa: E402
from jaxterrain.curriculum.run_config import from_flat  # noqa: E402
from jaxterrain import rl  # noqa: E402
from jaxterrain.curriculum import walker as W  # noqa: E402


def restore_policies(npz, like):
    """``(params, normaliser)`` of every trial ([T, ...] leaves) from the checkpoint, shaped like ``like``'s."""
    def read(prefix, tree):
        return jax.tree_util.tree_map_with_path(
            lambda path, _: jnp.asarray(npz[f"leaf:.policy.{prefix}" + jax.tree_util.keystr(path)]), tree)

    return read("params", like.params), read("normaliser", like.normaliser)


STATS = ("steps", "running", "niter_running", "niter_ended", "nefc_running", "nefc_ended", "cap_running",
         "cap_ended", "max_niter", "max_nefc")


def solver_summary(stats, walks: int) -> dict:
    """Means from the loop's sums: per running / ended walk-step, and of the per-step maximum over all walks."""
    steps, running = float(stats["steps"]), float(stats["running"])
    ended = steps * walks - running
    per = lambda x, n: float(x) / n if n else None  # noqa: E731
    return {"walk_steps_running": running, "walk_steps_ended": ended,
            "niter_running": per(stats["niter_running"], running), "niter_ended": per(stats["niter_ended"], ended),
            "nefc_running": per(stats["nefc_running"], running), "nefc_ended": per(stats["nefc_ended"], ended),
            "at_cap_running": per(stats["cap_running"], running), "at_cap_ended": per(stats["cap_ended"], ended),
            "max_niter": per(stats["max_niter"], steps), "max_nefc": per(stats["max_nefc"], steps)}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("treatment", type=pathlib.Path)
    p.add_argument("--trials", default=None, help="comma-separated trial indices (default: all)")
    p.add_argument("--backend", choices=("jax", "warp"), default="jax")
    p.add_argument("--park", default="off", help="off | on | off,on,...: lift ended walkers out of contact (A/B)")
    p.add_argument("--out", type=pathlib.Path, default=None)
    a = p.parse_args()
    cfg = {**json.loads((a.treatment / "config.json").read_text()), "backend": a.backend}
    npz = np.load(a.treatment / "checkpoint.npz")
    trials = [int(t) for t in a.trials.split(",")] if a.trials else list(range(int(cfg["trials"])))
    cfg["trials"] = len(trials)
    run, config, arch, policy, env = runner.validate(from_flat(cfg))
    bank, ppo, harness, start, _, _ = runner.inputs(run, config, arch, policy, env)
    params, normaliser = restore_policies(npz, start)
    pick = jnp.asarray(trials)
    params, normaliser = jax.tree.map(lambda x: x[pick], (params, normaliser))
    terrain = np.asarray(npz["leaf:.terrain"])[trials]
    keys = jax.random.split(jax.random.key(7), len(trials))
    protocol = config.protocol.validate()
    attempts, headings = protocol.attempts, protocol.headings
    tile, _ = harness.layout(bank.heightmaps[jnp.asarray(terrain)])
    act = rl.policy_fn(ppo, env.action_size)
    ride = config.updates_per_chunk * ppo.unroll_length * ppo.num_unrolls  # the PPO steps the walks ride along

    iterations = int(env.mjx_model.opt.iterations)

    def walk(data, index, keys, params, park):
        """[B, R] end step (0-based; -1: not ended), fell (a fall ends it), reached (the goal), contacts summed over
        its steps; [] the loop's steps; a dict of solver sums over the loop (``stats``). ``park``: after each step,
        park every ended walker (``WalkerEnv.park``; its result is already recorded), to see what the ended walks
        cost."""
        reset_keys = jax.vmap(lambda k: W._walk_keys(k, attempts, headings))(keys)
        world, inner = W._walk_tiles(W.Tile(W.TileBank(data), index), attempts, headings)
        reset = jax.vmap(jax.vmap(env.reset, in_axes=(0, inner)), in_axes=(0, W.TILE_AXES))
        step = jax.vmap(jax.vmap(env.step, in_axes=(0, 0, inner)), in_axes=(0, 0, W.TILE_AXES))
        policy = jax.vmap(jax.vmap(act, in_axes=(None, 0)), in_axes=(0, 0))
        state = reset(reset_keys, world)
        shape = reset_keys.shape[:2]
        zeros = jnp.zeros(shape, jnp.float32)
        stats0 = {k: jnp.float32(0) for k in STATS}
        carry = (jnp.int32(0), state, jnp.full(shape, -1, jnp.int32), zeros > 0, zeros > 0, zeros, stats0)

        def cond(c):
            return (c[0] < env.config.episode_length) & jnp.any(c[2] < 0)

        def body(c):
            t, s, end, fell, reached, contacts, stats = c
            running = end < 0
            s = step(s, policy(params, s.obs), world)
            if a.backend == "jax":
                contacts = contacts + jnp.where(running, jnp.sum(s.data._impl.contact.dist < 0, axis=-1), 0)
            if a.backend == "warp":  # [B, R]: the last substep's Newton iterations and constraint rows
                niter, nefc = (s.data._impl.solver_niter.astype(jnp.float32), s.data._impl.nefc.astype(jnp.float32))
            else:  # not recorded
                niter = nefc = jnp.full(shape, jnp.nan)
            ended = ~running
            stats = {"steps": stats["steps"] + 1,
                     "running": stats["running"] + jnp.sum(running),
                     "niter_running": stats["niter_running"] + jnp.sum(jnp.where(running, niter, 0)),
                     "niter_ended": stats["niter_ended"] + jnp.sum(jnp.where(ended, niter, 0)),
                     "nefc_running": stats["nefc_running"] + jnp.sum(jnp.where(running, nefc, 0)),
                     "nefc_ended": stats["nefc_ended"] + jnp.sum(jnp.where(ended, nefc, 0)),
                     "cap_running": stats["cap_running"] + jnp.sum(running & (niter >= iterations)),
                     "cap_ended": stats["cap_ended"] + jnp.sum(ended & (niter >= iterations)),
                     "max_niter": stats["max_niter"] + jnp.max(niter),
                     "max_nefc": stats["max_nefc"] + jnp.max(nefc)}
            new = running & (s.done > 0)
            end = jnp.where(new, t, end)
            if park:  # every ended walker (this step's too) out of contact
                s = env.park(s, end >= 0)
            return (t + 1, s, end, fell | (new & (s.truncation == 0)),
                    reached | (new & (s.truncation > 0) & (t + 1 < env.config.episode_length)), contacts, stats)

        t, _, end, fell, reached, contacts, stats = jax.lax.while_loop(cond, body, carry)
        return end, fell, reached, contacts, t, stats

    args = (tile.bank.data, tile.index, keys, (params, normaliser))
    runs, results = [], {}
    for park in [{"off": False, "on": True}[m] for m in a.park.split(",")]:  # a mode again: the machine's drift
        t0 = time.perf_counter()
        compiled = jax.jit(walk, static_argnums=4).lower(*args, park).compile()
        compile_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        result = jax.tree.map(np.asarray, jax.block_until_ready(compiled(*args)))
        seconds = time.perf_counter() - t0
        results.setdefault(park, result)
        runs.append({"park": park, "compile_s": compile_s, "seconds": seconds, "loop_steps": int(result[4]),
                     "solver": solver_summary(result[5], result[0].size) if a.backend == "warp" else None})
        print(json.dumps(runs[-1]))
    # the walks' record (rows below) from the first run; the ends of the two modes compared (MuJoCo Warp on a GPU is
    # not bit-deterministic, so there a few ends may differ either way)
    same_ends = float(np.mean(results[True][0] == results[False][0])) if len(results) == 2 else None
    end, fell, reached, contacts, loop, _ = results[runs[0]["park"]]
    compile_s, seconds = runs[0]["compile_s"], runs[0]["seconds"]
    length = np.where(end < 0, env.config.episode_length, end + 1)
    per_step = float(contacts.sum() / length.sum()) if a.backend == "jax" else None
    rows = []
    for i, t in enumerate(trials):
        rows.append({"trial": t, "terrain": int(terrain[i]), "median": float(np.median(length[i])),
                     "p90": float(np.percentile(length[i], 90)), "max": int(length[i].max()),
                     "fell": int(fell[i].sum()), "reached": int(reached[i].sum()),
                     "limit": int((~fell[i] & ~reached[i]).sum()),
                     "contacts_per_step": float(contacts[i].sum() / length[i].sum()) if per_step is not None else None})
        print(json.dumps(rows[-1]))
    out = {"treatment": str(a.treatment), "chunk": int(np.asarray(npz["leaf:.chunk"]).max()),
           "walks_per_trial": attempts, "episode_length": env.config.episode_length, "loop_steps": int(loop),
           "ride_steps": ride, "walks_past_ride": float((length > ride).mean()), "mean_length": float(length.mean()),
           "contacts_per_step": per_step,
           "backend": a.backend, "compile_s": compile_s, "seconds": seconds,
           "runs": runs,
           "same_ends_park_on_off": same_ends, "trials": rows}
    print(json.dumps({k: v for k, v in out.items() if k != "trials"}))
    if a.out:
        a.out.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
