"""Terrains per second of every generator at 256 x 256, against CPU peers measured in the same run.

    python benchmarks/generators.py [--generators perlin worley ...] [--batch 1024 4096 16384] [--out result.json]

For each generator: the JAX render (jit of ``render`` over a batch of fresh genomes, device-resident, median of
``--repeats`` timed calls after a compile call, rotating through three genome sets) at each batch size; the same JAX
function on the host CPU backend (peer 1); and for the noise generators a NumPy/SciPy implementation of the same
algorithm (benchmarks/reference.py, one core, peer 2). Beside each batch: ``GiB@B``, XLA's planned device memory of
the compiled render (arguments + outputs + temporaries; the bound a public ``render`` must fit, issue 17), and the
process's running peak. Prints a Markdown table; ``--out`` writes JSON.
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

from jaxterrain import generators  # noqa: E402


def jax_rate(gen, batch: int, repeats: int, device=None) -> float:
    keys = jax.random.split(jax.random.key(0), 3)
    sets = [gen.sample(k, batch) for k in keys]
    if device is not None:
        sets = jax.device_put(sets, device)
    fn = jax.jit(gen.render)  # runs where the (committed) inputs live
    t = common.median_time(fn, sets, repeats=repeats)
    return batch / t


GIB = 2.0**30


def planned_gib(gen, batch: int) -> float:
    """XLA's planned device memory of ``render`` at ``batch`` (arguments + outputs + temporaries, GiB), from the
    compiled program's ``memory_analysis`` (NaN where the backend does not report it)."""
    genomes = jax.eval_shape(lambda k: gen.sample(k, batch), jax.random.key(0))
    try:
        m = jax.jit(gen.render).lower(genomes).compile().memory_analysis()
        return (m.argument_size_in_bytes + m.output_size_in_bytes + m.temp_size_in_bytes) / GIB
    except Exception:  # noqa: BLE001 - memory_analysis is optional per backend
        return float("nan")


def peak_gib() -> float:
    """The process's peak device memory so far (GiB; NaN where the device does not report it)."""
    stats = jax.devices()[0].memory_stats() or {}
    return stats.get("peak_bytes_in_use", float("nan")) / GIB


def numpy_rate(name: str, gen, n: int) -> float:
    fn = reference.GENERATORS[name]
    genomes = np.asarray(gen.sample(jax.random.key(1), n))
    fn(genomes[0], gen.size)  # warm caches / imports
    t0 = time.perf_counter()
    for g in genomes:
        fn(g, gen.size)
    return n / (time.perf_counter() - t0)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--generators", nargs="*", default=None, help="default: every registered generator that loads")
    p.add_argument("--batch", nargs="*", type=int, default=[1024, 4096, 16384])
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--cpu-batch", type=int, default=64, help="batch for the JAX-on-CPU peer")
    p.add_argument("--numpy-n", type=int, default=16, help="terrains timed for the NumPy peer")
    p.add_argument("--out", default=None)
    args = p.parse_args()

    env = common.environment()
    print(f"# generators on {env['device']} ({env['date']}, commit {env['commit']}, jax {env['jax']})")
    rows = []
    for name in args.generators or generators.names():
        try:
            gen = generators.get(name)
        except Exception as err:  # e.g. GAN weights not shipped
            print(f"skip {name}: {err}")
            continue
        row = {"generator": name}
        best = 0.0
        for b in args.batch:
            try:
                r = jax_rate(gen, b, args.repeats)
            except Exception as err:  # out of memory at this batch
                print(f"{name} batch {b}: {type(err).__name__}: {str(err)[:200]}")
                continue
            row[f"jax@{b}"] = r
            row[f"GiB@{b}"] = planned_gib(gen, b)
            best = max(best, r)
            print(f"{name:15s} batch {b:6d}: {r:12,.0f} terrains/s, planned {row[f'GiB@{b}']:.2f} GiB, process "
                  f"peak so far {peak_gib():.2f} GiB", flush=True)
        row["jax best"] = best
        cpu = jax.devices("cpu")[0]
        row["jax-cpu"] = jax_rate(gen, args.cpu_batch, 3, device=cpu)
        if name in reference.GENERATORS:
            row["numpy"] = numpy_rate(name, gen, args.numpy_n)
            row["speedup vs numpy"] = best / row["numpy"]
        row["speedup vs jax-cpu"] = best / row["jax-cpu"]
        rows.append(row)
        print(row, flush=True)
    cols = ["generator", *[f"jax@{b}" for b in args.batch], *[f"GiB@{b}" for b in args.batch], "jax-cpu", "numpy", "speedup vs numpy",
            "speedup vs jax-cpu"]
    print()
    print(common.markdown_table(rows, cols))
    common.write_json(args.out, {"environment": env, "unit": "terrains/s", "rows": rows})


if __name__ == "__main__":
    main()
