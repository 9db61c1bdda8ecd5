"""Scaling over devices (issue 16): terrain evaluation and PPO env steps/s on 1..N devices, in one run.

    python benchmarks/scaling.py [--devices 1,2] [--backends jax,warp] [--eval-terrains 2048] [--ppo-envs 3072]
                                 [--out result.json]

For each physics backend (``jax``: MJX-JAX, the classic layout; ``warp``: MuJoCo Warp on tiles, skipped where
``warp`` does not import) and each device count N of ``--devices`` (a ``jaxterrain.runtime.sharding`` mesh over the first N
visible devices), after a warm-up call (the compile):

1. ``eval``: ``difficulty.evaluate`` of ``--eval-terrains`` Perlin terrains (256 x 256, the paper's protocol: 20
   walks each, best 5) with ``mesh=``: the terrains split over the devices, each device's rollouts on its own pool
   of ``--eval-slots`` env slots (``none``: all walks at once). Terrains/s, and the largest fitness difference from
   the N=1 result (the same per-row keys: 0 on CPU; on a GPU, MJX is not bit-deterministic, see RESULTS.md).
2. ``ppo``: ``rl.run_updates`` (the default ``PPOConfig``, i.e. the base policy's training: ``--ppo-envs`` envs x
   10 steps x 4 unrolls per update, 8 epochs of 24 minibatches) data parallel with ``mesh=``: the envs split over
   the devices, gradients averaged with a ``psum`` in every minibatch. Env steps/s, each env on its own terrain of
   a bank of ``--bank`` Perlin terrains.

The global batch is the same on every N (strong scaling); speed-up = rate(N) / rate(1) in the same run (issue 16's
targets on 2 GPUs: evaluation >= 1.8x, PPO >= 1.7x). On CPU, force devices with
``XLA_FLAGS=--xla_force_host_platform_device_count=2`` (the CPU's cores are then shared: no speed-up expected).
"""

from __future__ import annotations

import argparse
import functools
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import common  # noqa: E402
from jaxterrain import difficulty, generators, rl, walker  # noqa: E402
from jaxterrain.walker.layout import make_env
from jaxterrain.runtime import sharding


def log(*a):
    print(f"[{time.strftime('%H:%M:%S')}]", *a, flush=True)


def perlin(key, n: int, size: int) -> jax.Array:
    """``[n, size, size]`` Perlin heightmaps in [0, 1], rendered in chunks of 256 (bounded memory)."""
    gen = generators.get("perlin", size=size)
    parts = [gen.render(gen.sample(k, min(256, n - i))) for i, k in zip(range(0, n, 256),
                                                                         jax.random.split(key, -(-n // 256)))]
    return jnp.clip(jnp.concatenate(parts).astype(jnp.float32), 0.0, 1.0)


def timed_calls(fn, repeats: int) -> tuple[float, float, object]:
    """(compile + first call s, median s of ``repeats`` further calls, last output)."""
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn())
    first = time.perf_counter() - t0
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = jax.block_until_ready(fn())
        times.append(time.perf_counter() - t0)
    return first, float(np.median(times)), out


def bench_eval(backend: str, heightmaps, devices: list[int], slots, repeats: int) -> list[dict]:
    cfg = difficulty.default_env_config(heightmaps.shape[1:], backend=backend)
    key, rows, base = jax.random.key(7), [], None
    for n in devices:
        mesh = sharding.make_mesh(n)
        call = functools.partial(difficulty.evaluate, heightmaps, key, env_config=cfg, slots=slots, mesh=mesh)
        first, t, fit = timed_calls(call, repeats)
        fit = np.asarray(fit)
        base = fit if base is None else base
        row = {"part": "eval", "backend": backend, "devices": n, "terrains": int(heightmaps.shape[0]),
               "slots_per_device": slots, "first_call_s": first, "s_per_call": t,
               "terrains_per_s": heightmaps.shape[0] / t, "fitness_mean": float(fit.mean()),
               "max_abs_diff_vs_1": float(np.max(np.abs(fit - base)))}
        log(row)
        rows.append(row)
    return rows


def bench_ppo(backend: str, bank, devices: list[int], num_envs: int, updates: int, repeats: int) -> list[dict]:
    config = rl.PPOConfig(num_envs=num_envs)
    env_cfg = difficulty.default_env_config(bank.shape[1:], backend=backend)
    if env_cfg.tiles:
        env_cfg = env_cfg._replace(tiles=int(bank.shape[0]), warp_worlds=num_envs)
    env = make_env(env_cfg)
    index = jnp.arange(num_envs) % bank.shape[0]
    terrains = env.make_bank(bank * env_cfg.scale.height).at(index) if env.tiles else (
        bank[index] * env_cfg.scale.height)
    steps = config.num_envs * config.unroll_length * config.num_unrolls * updates
    rows, base = [], None
    for n in devices:
        mesh = sharding.make_mesh(n)
        state = jax.jit(lambda k, t: rl.init(k, env, config, t))(jax.random.key(3), terrains)  # noqa: B023
        fn = rl.compiled_chunk(env, config, updates, mesh=mesh)
        state, data = sharding.replicate((state, terrains), mesh)
        box = {"state": state}

        def call():
            box["state"], metrics = fn(box["state"], data)  # noqa: B023
            return box["state"].params, metrics

        first, t, (_, metrics) = timed_calls(call, repeats)
        loss = float(np.asarray(metrics["total_loss"] if "total_loss" in metrics else
                                next(iter(metrics.values()))).ravel()[-1])
        row = {"part": "ppo", "backend": backend, "devices": n, "num_envs": num_envs, "updates_per_call": updates,
               "first_call_s": first, "s_per_call": t, "env_steps_per_s": steps / t, "last_metric": loss}
        log(row)
        rows.append(row)
    return rows


def speedups(rows: list[dict]) -> list[dict]:
    out = []
    for (part, backend) in sorted({(r["part"], r["backend"]) for r in rows}):
        group = [r for r in rows if r["part"] == part and r["backend"] == backend]
        one = next((r for r in group if r["devices"] == 1), None)
        for r in group:
            if one is not None:
                r["speedup_vs_1"] = one["s_per_call"] / r["s_per_call"]
            out.append(r)
    return out


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--devices", default=None, help="comma list of device counts (default: 1 and all visible)")
    p.add_argument("--backends", default="jax,warp", help="comma list: jax, warp (warp skipped where missing)")
    p.add_argument("--parts", default="eval,ppo", help="comma list: eval, ppo")
    p.add_argument("--size", type=int, default=256, help="terrain samples per side")
    p.add_argument("--eval-terrains", type=int, default=2048, help="terrains per evaluate call")
    p.add_argument("--eval-slots", default="8192", help="rollout pool slots per device ('none': all walks at once)")
    p.add_argument("--ppo-envs", type=int, default=3072, help="PPO envs (global, split over the devices)")
    p.add_argument("--ppo-updates", type=int, default=2, help="PPO updates per timed call")
    p.add_argument("--bank", type=int, default=64, help="distinct Perlin terrains under the PPO envs")
    p.add_argument("--repeats", type=int, default=2, help="timed calls after the warm-up")
    p.add_argument("--out", default=None, help="JSON result path")
    args = p.parse_args(argv)

    visible = jax.device_count()
    devices = [1, visible] if args.devices is None else [int(d) for d in args.devices.split(",")]
    devices = sorted(set(devices))
    if devices[0] < 1 or devices[-1] > visible:
        raise SystemExit(f"--devices: counts must be in [1, {visible}] (visible devices); got {args.devices}")
    backends = [b for b in args.backends.split(",") if b]
    if "warp" in backends and not walker.warp_available()[0]:
        log(f"warp rows skipped: {walker.warp_available()[1]}")
        backends.remove("warp")
    slots = None if args.eval_slots == "none" else int(args.eval_slots)
    env = common.environment()
    log(env, "devices:", [str(d) for d in jax.devices()])
    rows = []
    parts = args.parts.split(",")
    if "eval" in parts:
        maps = perlin(jax.random.key(0), args.eval_terrains, args.size)
        for b in backends:
            rows += bench_eval(b, maps, devices, slots, args.repeats)
    if "ppo" in parts:
        bank = perlin(jax.random.key(1), args.bank, args.size)
        for b in backends:
            rows += bench_ppo(b, bank, devices, args.ppo_envs, args.ppo_updates, args.repeats)
    rows = speedups(rows)
    cols = ["part", "backend", "devices", "s_per_call", "terrains_per_s", "env_steps_per_s", "speedup_vs_1",
            "max_abs_diff_vs_1", "first_call_s"]
    print(common.markdown_table(rows, cols))
    common.write_json(args.out, {"environment": env, "args": vars(args), "rows": rows})


if __name__ == "__main__":
    main()
