"""Terrains per second of the descriptors (TRI, TPI, roughness at window 30, stride 2) and of Algorithm 1.

    python benchmarks/features.py [--batch 1024 4096 16384] [--out result.json]

JAX: ``features.descriptors`` (all three at once) and each descriptor alone, jit-compiled, on device-resident
256 x 256 Perlin heightmaps, median of ``--repeats`` calls rotating through three input sets. Peers in the same run:
the same JAX function on the host CPU backend, and the NumPy reference (benchmarks/reference.py, one core), whose
values are also compared with ours (max abs difference printed).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import jax
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402
import reference  # noqa: E402

from jaxterrain import features, generators  # noqa: E402

NAMES = ("tri", "tpi", "roughness")


def maps(batch: int, seed: int):
    gen = generators.get("perlin")
    return gen.render(gen.sample(jax.random.key(seed), batch))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--batch", nargs="*", type=int, default=[1024, 4096, 16384])
    p.add_argument("--window", type=int, default=30)
    p.add_argument("--stride", type=int, default=2)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--cpu-batch", type=int, default=64)
    p.add_argument("--numpy-n", type=int, default=8)
    p.add_argument("--out", default=None)
    args = p.parse_args()
    k, s = args.window, args.stride

    env = common.environment()
    print(f"# features on {env['device']} ({env['date']}, commit {env['commit']}, jax {env['jax']})")
    stages = {
        "descriptors (all 3)": lambda h: features.descriptors(h, NAMES, window=k, stride=s),
        **{n: (lambda h, n=n: features.descriptors(h, (n,), window=k, stride=s)) for n in NAMES},
        "is_traversable": lambda h: features.is_traversable(h),
    }
    rows = []
    for stage, fn in stages.items():
        row = {"stage": stage}
        best = 0.0
        for b in args.batch:
            try:
                sets = [maps(b, i) for i in range(3)]
                t = common.median_time(jax.jit(fn), sets, repeats=args.repeats)
            except Exception as err:
                print(f"{stage} batch {b}: {type(err).__name__}: {str(err)[:200]}")
                continue
            row[f"jax@{b}"] = b / t
            best = max(best, b / t)
            del sets
        cpu = jax.devices("cpu")[0]
        cpu_sets = jax.device_put([maps(args.cpu_batch, 10 + i) for i in range(2)], cpu)
        row["jax-cpu"] = args.cpu_batch / common.median_time(jax.jit(fn), cpu_sets, repeats=3)
        row["jax best"] = best
        rows.append(row)
        print(row, flush=True)

    # NumPy reference: all three descriptors of one map at a time; and agreement of values.
    h = np.asarray(maps(args.numpy_n, 99))
    reference.descriptors(h[0], NAMES, k, s)
    t0 = time.perf_counter()
    ref = np.stack([reference.descriptors(m, NAMES, k, s) for m in h])
    numpy_rate = args.numpy_n / (time.perf_counter() - t0)
    ours = np.asarray(features.descriptors(h, NAMES, window=k, stride=s))
    err = float(np.abs(ours - ref).max())
    rows[0]["numpy"] = numpy_rate
    rows[0]["speedup vs numpy"] = rows[0]["jax best"] / numpy_rate
    print(f"numpy reference: {numpy_rate:,.1f} terrains/s (all 3); max |jax - numpy| = {err:.2e}")
    cols = ["stage", *[f"jax@{b}" for b in args.batch], "jax-cpu", "numpy", "speedup vs numpy"]
    print()
    print(common.markdown_table(rows, cols))
    common.write_json(args.out, {"environment": env, "unit": "terrains/s", "window": k, "stride": s, "rows": rows,
                                 "max_abs_diff_vs_numpy": err})


if __name__ == "__main__":
    main()
