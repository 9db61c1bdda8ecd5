"""Is terrain difficulty bit-reproducible on this device, where does it diverge, and what does determinism cost?

    python benchmarks/determinism.py [--terrains 64] [--size 256] [--out result.json]

Runs itself twice in child processes, once with XLA's default GPU kernels and once with
``XLA_FLAGS=--xla_gpu_deterministic_ops=true`` (deterministic scatter / reduction algorithms), and in each:

``--backend warp``: the walker on MuJoCo Warp (tiles); its kernels are Warp's, which XLA's flag does not reach.

1. ``difficulty.evaluate`` (the paper's protocol: 20 attempts, best 5) on ``--terrains`` Perlin terrains, twice with
   the same key: the largest fitness difference, the number of terrains that differ, and the seconds per call
   (median of ``--repeats`` after a compile call);
2. the walker's physics alone: the same batch of states stepped with the same actions twice, compared after 1, 10
   and 100 env steps (largest |qpos| difference): a difference after ONE step means the physics kernels themselves
   are not deterministic (atomic adds in scatters); none after 100 means the divergence lies elsewhere;
3. the policy alone (the MLP on the same observations twice).

On CPU XLA's kernels are deterministic and every difference is 0. The ratio of the two children's seconds per call
is the cost of ``--xla_gpu_deterministic_ops`` (same run, same device).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

DETERMINISTIC_FLAG = "--xla_gpu_deterministic_ops=true"


def child(args) -> dict:
    import jax
    import jax.numpy as jnp
    import numpy as np

    from jaxterrain import difficulty, generators, walker

    from jaxterrain.walker.layout import make_env
    from jaxterrain.terrain import TerrainScale

    gen = generators.get("perlin")
    hm = gen.render(gen.sample(jax.random.key(3), args.terrains))
    hm = jax.image.resize(hm, (hm.shape[0], args.size, args.size), "linear") if hm.shape[1] != args.size else hm
    key = jax.random.key(7)
    policy = difficulty.default_policy()
    cfg = difficulty.default_env_config((args.size, args.size), TerrainScale(), policy, backend=args.backend)

    def fn(h, k):  # validates on the host, compiles its rollout once per shape
        return difficulty.evaluate(h, k, env_config=cfg)

    a = np.asarray(fn(hm, key))  # compile + first call
    times, runs = [], []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        runs.append(np.asarray(jax.block_until_ready(fn(hm, key))))
        times.append(time.perf_counter() - t0)
    diffs = [np.abs(r - a) for r in runs]
    out = {"backend": args.backend, "flags": os.environ.get("XLA_FLAGS", ""), "device": str(jax.devices()[0].device_kind),
           "seconds_per_call": float(np.median(times)), "fitness_mean": float(a.mean()),
           "max_fitness_diff": float(max(d.max() for d in diffs)),
           "terrains_differing": int(max((d > 0).sum() for d in diffs))}

    # physics alone: same states, same actions, twice
    if cfg.tiles:  # MuJoCo Warp: the terrains are tiles of one bank, one env per tile
        cfg = cfg._replace(tiles=args.terrains, warp_worlds=args.terrains)
    env = make_env(cfg)
    terrains, axes = (env.make_bank(hm * 1.0).at(jnp.arange(args.terrains)), walker.TILE_AXES) if cfg.tiles else (
        hm * 1.0, 0)
    keys = jax.random.split(jax.random.key(1), args.terrains)
    states = jax.jit(jax.vmap(env.reset, in_axes=(0, axes)))(keys, terrains)
    acts = jax.random.uniform(jax.random.key(2), (args.terrains, env.action_size), minval=-1, maxval=1)

    @jax.jit
    def walk(s, n):
        step = jax.vmap(env.step, in_axes=(0, 0, axes))
        return jax.lax.fori_loop(0, n, lambda i, s: step(s, acts, terrains), s)

    for n in (1, 10, 100):
        q1 = np.asarray(walk(states, n).data.qpos)
        q2 = np.asarray(walk(states, n).data.qpos)
        out[f"physics_max_qpos_diff_after_{n}"] = float(np.nanmax(np.abs(q1 - q2)))
    obs = states.obs
    pa = np.asarray(jax.jit(jax.vmap(policy))(obs))
    pb = np.asarray(jax.jit(jax.vmap(policy))(obs))
    out["policy_max_action_diff"] = float(np.abs(pa - pb).max())
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--terrains", type=int, default=64)
    p.add_argument("--size", type=int, default=256)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--backend", default="jax", choices=("jax", "warp"), help="walker physics (warp: MuJoCo Warp)")
    p.add_argument("--out", default=None)
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child:
        print(json.dumps(child(args)), flush=True)
        return

    import common

    env = common.environment()
    print(f"# determinism on {env['device']} ({env['date']}, commit {env['commit']}, jax {env['jax']})", flush=True)
    rows = []
    for flags in ("", DETERMINISTIC_FLAG):
        e = dict(os.environ)
        e["XLA_FLAGS"] = (e.get("XLA_FLAGS", "") + " " + flags).strip()
        cmd = [sys.executable, __file__, "--child", "--terrains", str(args.terrains), "--size", str(args.size),
               "--repeats", str(args.repeats), "--backend", args.backend]
        res = subprocess.run(cmd, env=e, capture_output=True, text=True)
        if res.returncode:
            print(res.stderr[-3000:], flush=True)
            raise SystemExit(f"child with XLA_FLAGS={flags!r} failed")
        row = json.loads(res.stdout.strip().splitlines()[-1])
        row["mode"] = "deterministic ops" if flags else "default"
        rows.append(row)
        print(row, flush=True)
    rows[1]["cost_vs_default"] = rows[1]["seconds_per_call"] / rows[0]["seconds_per_call"]
    cols = ["backend", "mode", "seconds_per_call", "cost_vs_default", "max_fitness_diff", "terrains_differing",
            "physics_max_qpos_diff_after_1", "physics_max_qpos_diff_after_10", "physics_max_qpos_diff_after_100",
            "policy_max_action_diff"]
    print()
    print(common.markdown_table(rows, cols))
    common.write_json(args.out, {"environment": env, "terrains": args.terrains, "rows": rows})


if __name__ == "__main__":
    main()
