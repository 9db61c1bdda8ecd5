"""Traversability maps per second at 256 x 256: the jitted model on the default device against the same on the CPU.

    python benchmarks/traversability.py [--batch 1024 4096 16384] [--cpu-batch 64] [--out result.json]
    python benchmarks/traversability.py --quick          # small batches, a CPU-only machine: seconds, not minutes

The stage is the ``"traversability"`` descriptor: the shipped :class:`jaxterrain.features.learned.PatchCNN` applied
with stride 8 over each whole heightmap (a 29 x 29 map per 256 x 256 terrain, one pass of convolutions) and the
map's mean, jit-compiled, on device-resident Perlin heightmaps, median of ``--repeats`` calls rotating through three
input sets. Its peer in the same run: the same jitted function on the host's CPU backend (all its cores). The two
devices' descriptors are compared (max abs difference printed; on a GPU, XLA may run the convolutions in TF32
unless ``--precision highest``). Target (issue 15): >= 20 000 terrains/s on one H100 / H200.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402

from jaxterrain import generators  # noqa: E402
from jaxterrain.features import learned as trav  # noqa: E402


def maps(batch: int, seed: int, size: int):
    gen = generators.get("perlin", size=size) if size != 256 else generators.get("perlin")
    return gen.render(gen.sample(jax.random.key(seed), batch))


def model(random_weights: bool) -> trav.Model:
    if random_weights:
        return trav.Model(trav.init_params(jax.random.key(0)), trav.ModelConfig(), {})
    return trav.shipped()


def rate(fn, batch: int, device, repeats: int, size: int) -> tuple[float, np.ndarray]:
    """Terrains/s of ``fn`` at ``batch`` on ``device`` (median of ``repeats``) and its output on the first set."""
    sets = jax.device_put([maps(batch, i, size) for i in range(3)], device)
    t = common.median_time(fn, sets, repeats=repeats)
    return batch / t, np.asarray(fn(sets[0]))


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--batch", nargs="*", type=int, default=[1024, 4096, 16384], help="default-device batches")
    p.add_argument("--cpu-batch", type=int, default=64)
    p.add_argument("--size", type=int, default=256, help="heightmap side in pixels")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--precision", choices=["default", "highest"], default="default",
                   help="jax_default_matmul_precision for the run (convolutions too)")
    p.add_argument("--random-weights", action="store_true", help="a freshly initialised model instead of the shipped")
    p.add_argument("--quick", action="store_true", help="batch 8, cpu-batch 8, 2 repeats (a CPU-only smoke run)")
    p.add_argument("--out", default=None, help="write the result as JSON")
    args = p.parse_args(argv)
    if args.quick:
        args.batch, args.cpu_batch, args.repeats = [8], 8, 2
    if args.precision == "highest":
        jax.config.update("jax_default_matmul_precision", "highest")

    env = common.environment()
    m = model(args.random_weights)
    fn = jax.jit(trav.make_descriptor(m))
    print(f"# traversability on {env['device']} ({env['platform']}, {env['date']}, commit {env['commit']}, "
          f"jax {env['jax']}), {args.size} x {args.size}, precision {args.precision}", flush=True)
    row = {"stage": "traversability descriptor"}
    default = jax.devices()[0]
    ref = None
    for b in args.batch:
        try:
            row[f"{default.platform}@{b}"], out = rate(fn, b, default, args.repeats, args.size)
            ref = out if ref is None else ref
        except Exception as err:  # e.g. out of memory at the largest batch
            print(f"batch {b}: {type(err).__name__}: {str(err)[:200]}", flush=True)
    cpu = jax.devices("cpu")[0]
    peer = f"cpu peer@{args.cpu_batch}"
    row[peer], cpu_out = rate(fn, args.cpu_batch, cpu, max(2, min(args.repeats, 3)), args.size)
    best = max(v for k, v in row.items() if k.startswith(f"{default.platform}@"))
    row["default / cpu peer"] = best / row[peer]
    n = min(len(cpu_out), len(ref)) if ref is not None else 0
    diff = float(np.abs(cpu_out[:n] - ref[:n]).max()) if n else float("nan")  # same seeds -> same first maps
    print(common.markdown_table([row], list(row)), flush=True)
    print(f"max |default - cpu| descriptor on the same maps: {diff:.2e}; best {best:,.0f} terrains/s "
          f"(target >= 20,000 on one H100 / H200)", flush=True)
    result = {"environment": env, "unit": "terrains/s", "size": args.size, "precision": args.precision,
              "weights": "random" if args.random_weights else str(trav.ASSET_DIR), "rows": [row],
              "max_abs_diff_default_vs_cpu": diff}
    common.write_json(args.out, result)
    return result


if __name__ == "__main__":
    main()
