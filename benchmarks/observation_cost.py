"""What perception costs: physics steps/s of the blind and the perceptive walker side by side, in one run.

Every variant walks the same envs on the same terrains (a bank of ``--bank`` Perlin maps of ``--size`` pixels, env
``i`` on map ``i % bank``), MJX-JAX, the policy in the loop with auto-reset (``rollouts.bench_ours``: obs -> policy
MLP -> ``env.step``), the same reset keys, per ``--layouts`` (``classic``: per-env heightfields; ``tiles``: one
heightfield of the bank's tiles) and ``--batch-sizes``:

- ``blind``: ``WalkerConfig(observation="blind")`` with the robot's shipped blind base policy;
- ``perceptive``: ``observation="perceptive"`` (the robot's default scan grid, e.g. the humanoid's 17 x 9 heights)
  with its shipped perceptive twin (``jaxterrain/assets/base_policy[_ROBOT]_perceptive``; where it is missing, the
  blind policy widened by ``rl.widen_inputs`` with unit statistics: the same network sizes, so the same cost);
- ``perceptive-noise``: the same with ``scan_noise = --scan-noise`` metres (the noise's hash and draws).

The timed calls of the variants are interleaved (blind, perceptive, noise, blind, ...; best of ``--repeats``), so
a drift of the machine's clock hits all of them alike. Results: one row per (layout, batch, variant) with physics
steps/s and the ratio to the blind walker of the same layout and batch, printed as a table and written to
``--out`` (JSON) after every layout and batch; a second run with the same ``--out`` skips what is there (resumable).

    python benchmarks/observation_cost.py --out runs/observation_cost.json              # ~6 min on one H200
    python benchmarks/observation_cost.py --robot ant --out runs/observation_cost_ant.json
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from common import block, environment, markdown_table, write_json  # noqa: E402
from rollouts import per_env_terrains, terrain_bank  # noqa: E402
from jaxterrain import difficulty, rl, walker  # noqa: E402
from jaxterrain.terrain import TerrainScale  # noqa: E402
from jaxterrain.walker import WalkerConfig, WalkerEnv  # noqa: E402

VARIANTS = ("blind", "perceptive", "perceptive-noise")


def log(*a):
    print(f"[{time.strftime('%H:%M:%S')}]", *a, flush=True)


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default=None, help="JSON result path (resumable: rows already there are skipped)")
    p.add_argument("--robot", default="humanoid", metavar="NAME", help="humanoid or ant (or a registered robot)")
    p.add_argument("--batch-sizes", default="8192", help="comma list of envs per batch")
    p.add_argument("--layouts", default="classic,tiles", help="comma list: classic, tiles")
    p.add_argument("--variants", default=",".join(VARIANTS), help=f"comma list of {', '.join(VARIANTS)}")
    p.add_argument("--env-steps", type=int, default=100, help="env steps per timed call (x n_frames physics steps)")
    p.add_argument("--repeats", type=int, default=3, help="timed calls per variant (best kept)")
    p.add_argument("--size", type=int, default=256, help="terrain samples per side")
    p.add_argument("--bank", type=int, default=64, help="distinct terrains")
    p.add_argument("--scan-noise", type=float, default=0.02, help="perceptive-noise: scan noise std, metres")
    args = p.parse_args(argv)
    try:
        walker.robots.get(args.robot)
        sizes = [int(v) for v in args.batch_sizes.split(",") if v]
    except ValueError as err:
        p.exit(2, f"{p.prog}: error: {err}\n")
    bad = [v for v in args.layouts.split(",") if v not in ("classic", "tiles")] + [
        v for v in args.variants.split(",") if v not in VARIANTS]
    if bad or not sizes or min(sizes) < 1 or args.env_steps < 1 or args.repeats < 1 or args.bank < 1 \
            or not args.scan_noise >= 0:
        p.exit(2, f"{p.prog}: error: bad --layouts / --variants {bad}, or a count < 1, or --scan-noise < 0\n")
    args.sizes = sizes
    return args


def policies(robot: str, blind_env: WalkerEnv, seeing_env: WalkerEnv) -> tuple[dict, dict]:
    """``({"blind": policy, "perceptive": policy}, descriptions)``."""
    blind = difficulty.robot_base_policy(robot)
    desc = {"blind": str(blind.path)}
    try:
        seeing = difficulty.robot_base_policy(robot, "perceptive")
        desc["perceptive"] = str(seeing.path)
    except ValueError as err:
        log(f"no shipped perceptive policy ({err}); widening the blind one with unit statistics")
        extra = seeing_env.observation_size - blind_env.observation_size
        params, stats = rl.widen_inputs(blind.params, blind.normaliser, extra, jnp.zeros(extra), jnp.ones(extra))
        cfg, a = blind.config, blind.action_size

        def seeing(obs):
            return rl.deterministic_action(cfg, a, params, stats, obs)

        desc["perceptive"] = "blind policy widened by rl.widen_inputs (unit scan statistics)"
    if int(getattr(seeing, "observation_size", seeing_env.observation_size)) != seeing_env.observation_size:
        raise SystemExit(f"the perceptive policy observes {seeing.observation_size}, the env {seeing_env.observation_size}")
    return {"blind": blind, "perceptive": seeing}, desc


def make_run(env: WalkerEnv, policy, terrains, axes, b: int, env_steps: int):
    """``(run(state) -> state, init)``: ``env_steps`` steps of the policy in the loop with auto-reset.

    The terrains and the reset state are arguments of the compiled program, not constants captured in it: at 8 192
    envs of the classic layout the per-env heightfields are ~2 GB, and capturing them made XLA's compile take minutes
    (measured on an H200, 2026-11-29: the first call of one variant ran past 100 s).
    """
    reset = jax.vmap(env.reset, in_axes=(0, axes))
    step = jax.vmap(env.step, in_axes=(0, 0, axes))
    act = jax.vmap(policy)
    init = jax.jit(reset)(jax.random.split(jax.random.PRNGKey(1), b), terrains)

    @jax.jit
    def program(state, start, ground):
        def body(s, _):
            s = step(s, act(s.obs), ground)
            return env.select(s.done > 0, start, s), None

        return jax.lax.scan(body, state, None, length=env_steps)[0]

    def run(state):
        return program(state, init, terrains)

    return run, init


def measure(args, layout: str, b: int, bank_m, robot: str) -> list[dict]:
    """The rows of one layout and batch size: every variant compiled, then timed interleaved."""
    cfg = WalkerConfig(terrain_shape=(args.size, args.size), scale=TerrainScale(), robot=robot)
    if layout == "tiles":
        cfg = cfg._replace(tiles=int(bank_m.shape[0]))
    configs = {"blind": cfg, "perceptive": cfg._replace(observation="perceptive"),
               "perceptive-noise": cfg._replace(observation="perceptive", scan_noise=float(args.scan_noise))}
    envs = {v: WalkerEnv(configs[v]) for v in configs}
    pols, desc = policies(robot, envs["blind"], envs["perceptive"])
    runs, states, first = {}, {}, {}
    for v in [v for v in args.variants.split(",") if v]:
        env = envs[v]
        terrains, axes = per_env_terrains(env, bank_m, b)
        run, init = make_run(env, pols["blind" if v == "blind" else "perceptive"], terrains, axes, b, args.env_steps)
        t0 = time.perf_counter()
        states[v] = block(run(init))
        first[v] = time.perf_counter() - t0
        runs[v] = run
        log(f"{layout} {b} {v}: compiled and first call {first[v]:.1f} s")
    best = {v: float("inf") for v in runs}
    for _ in range(args.repeats):
        for v, run in runs.items():
            t0 = time.perf_counter()
            states[v] = block(run(states[v]))
            best[v] = min(best[v], time.perf_counter() - t0)
    n_frames = cfg.n_frames
    rows = []
    for v in runs:
        sps = b * args.env_steps * n_frames / best[v]
        rows.append({"layout": layout, "batch": b, "variant": v, "observation_size": envs[v].observation_size,
                     "steps_per_s": sps, "seconds": best[v], "first_call_s": first[v],
                     "finite": bool(jnp.all(jnp.isfinite(states[v].obs))),
                     "policy": desc["blind" if v == "blind" else "perceptive"]})
    base = next((r["steps_per_s"] for r in rows if r["variant"] == "blind"), None)
    for r in rows:
        r["ratio_to_blind"] = None if base is None else r["steps_per_s"] / base
    return rows


def main(argv=None) -> int:
    args = parse_args(argv)
    out = Path(args.out) if args.out else None
    result = json.loads(out.read_text()) if out is not None and out.is_file() else {}
    result.setdefault("environment", environment())
    result.update(robot=args.robot, terrain={"shape": [args.size, args.size], "distinct": args.bank},
                  env_steps=args.env_steps, repeats=args.repeats, scan_noise=args.scan_noise)
    result.setdefault("rows", [])
    log("environment", result["environment"])
    bank_m = terrain_bank(jax.random.PRNGKey(11), args.bank, args.size) * TerrainScale().height
    for layout in [v for v in args.layouts.split(",") if v]:
        for b in args.sizes:
            if any(r["layout"] == layout and r["batch"] == b and r.get("robot", "humanoid") == args.robot
                   for r in result["rows"]):
                log(f"{layout} {b}: in {out}, skipped")
                continue
            rows = measure(args, layout, b, bank_m, args.robot)
            for r in rows:
                r["robot"] = args.robot
            result["rows"] += rows
            write_json(out, result)
    table = [{"layout": r["layout"], "batch": r["batch"], "variant": r["variant"], "obs": r["observation_size"],
              "M steps/s": r["steps_per_s"] / 1e6, "ratio": r["ratio_to_blind"], "compile+1st s": r["first_call_s"]}
             for r in result["rows"] if r.get("robot", "humanoid") == args.robot]
    print(f"\ndevice: {result['environment'].get('device')}; robot {args.robot}; {args.size} x {args.size} terrains "
          f"({args.bank} distinct); MJX-JAX, policy in the loop")
    print(markdown_table(table, ["layout", "batch", "variant", "obs", "M steps/s", "ratio", "compile+1st s"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
