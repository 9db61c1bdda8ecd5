"""Worley maps per second of each ``select`` variant at 256 x 256, with compile times, memory and accuracy vs "sort".

    python benchmarks/worley_variants.py [--variants sort bisect bracket tiled] [--batch 256 1024 4096]
        [--size 256] [--repeats 5] [--chunk 0] [--hlo-dir DIR] [--out result.json]

A variant is ``select[:option...]`` with options ``major`` (points on the major axis of the count reductions,
``_POINTS_AXIS = "major"``), ``flat`` (one reduced dim of 400 instead of 16 x 25, ``_POINT_GROUPS``), ``groups=AxB``
(another grouping),
``untied`` (no optimisation barrier in the loops: the pre-fix code, where XLA hoists
the [B, H, W, 400] distance tensor out of the loop), ``step=K`` (coarse step of "bracket" / "tiled"), ``tol=X``
(pixels), and for "tiled" ``tile=K`` (tile side) and ``cap=AxB`` (candidate slots per tile as reduced dims,
``_CAP_GROUPS``; e.g. ``cap=96`` flat), and for "pallas" ``warps=K`` (warps per kernel program), ``topk=K``
(bisect until at most K candidates per pixel bracket, then keep their sorted values), ``pipe=K`` (Triton
``num_stages``) and ``fused`` / ``unfused`` (lists and selection in one kernel or two).
``--stages`` also times the prefixes of "tiled" and "pallas" (coarse grid + bounds; + candidate lists).
For each variant and batch size: ``jit(vmap(render_one))`` over fresh genomes (or ``lax.map`` over chunks of
``--chunk`` genomes when > 0), compile time (lower + compile), XLA's temp memory (``memory_analysis``; the ratio
``temp/d2`` to one [B, H, W, 400] float32 tensor shows whether the distances are materialised: >= 1 means yes), and
the median of ``--repeats`` timed calls after a warm-up, rotating through three genome sets. A batch size that runs
out of memory is skipped. Then the max |difference| of the unnormalised distance map (pixels) and of the rendered
[0, 1] map vs "sort" on a small batch (random genomes plus edge cases: D = 0, D = N / 4, N = 2, N = 400,
duplicate points), and the fraction of pixels that differ by more than 1e-4 px. ``--hlo-dir`` writes each
variant's optimised HLO (smallest batch) there. Prints Markdown tables; ``--out`` writes JSON.
"""

from __future__ import annotations

import argparse
import contextlib
import re
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402

from jaxterrain.generators import get  # noqa: E402
from jaxterrain.generators import worley_pallas  # noqa: E402
from jaxterrain.generators import worley as wm  # noqa: E402


@contextlib.contextmanager
def variant_settings(variant: str):
    """Parse ``select[:opt...]``; temporarily set the module knobs it names. Yields the select name and the
    method's keyword options (``step``, ``tol``, ``tile``)."""
    select, *opts = variant.split(":")
    saved = (wm._POINTS_AXIS, wm._tie, dict(wm._KTH), wm._POINT_GROUPS, wm._CAP_GROUPS,
             worley_pallas.NUM_WARPS, worley_pallas.TOP_K, worley_pallas.NUM_STAGES, worley_pallas.FUSED)
    method_kw = {}
    try:
        for o in opts:
            if o == "major":
                wm._POINTS_AXIS = "major"
            elif o == "flat":
                wm._POINT_GROUPS = (wm.MAX_POINTS,)
            elif o.startswith("groups="):
                wm._POINT_GROUPS = tuple(int(v) for v in o[7:].split("x"))
            elif o == "untied":
                wm._tie = lambda arrays, carry: arrays
            elif o.startswith("step="):
                method_kw["step"] = int(o[5:])
            elif o.startswith("tol="):
                method_kw["tol"] = float(o[4:])
            elif o.startswith("tile="):
                method_kw["tile"] = int(o[5:])
            elif o.startswith("cap="):
                wm._CAP_GROUPS = tuple(int(v) for v in o[4:].split("x"))
            elif o.startswith("warps="):
                worley_pallas.NUM_WARPS = int(o[6:])
            elif o.startswith("topk="):
                worley_pallas.TOP_K = int(o[5:])
            elif o.startswith("pipe="):
                worley_pallas.NUM_STAGES = int(o[5:])
            elif o in ("fused", "unfused"):
                worley_pallas.FUSED = o == "fused"
            else:
                raise ValueError(f"unknown option {o!r} in variant {variant!r}")
        if method_kw:
            base = saved[2][select]
            wm._KTH[select] = lambda dy2, dx2, d: base(dy2, dx2, d, **method_kw)
        yield select, method_kw
    finally:
        (wm._POINTS_AXIS, wm._tie, kth, wm._POINT_GROUPS, wm._CAP_GROUPS, worley_pallas.NUM_WARPS,
         worley_pallas.TOP_K, worley_pallas.NUM_STAGES, worley_pallas.FUSED) = saved
        wm._KTH.clear()
        wm._KTH.update(kth)


def batched_fn(select: str, size: int, chunk: int, distance: bool = False):
    one = (lambda g: wm.worley_distance(g, size, select)) if distance else (lambda g: wm.render_worley(g, size, select))
    if chunk <= 0:
        return jax.jit(jax.vmap(one))

    def chunked(genomes):
        b = genomes.shape[0]
        c = min(chunk, b)
        out = jax.lax.map(jax.vmap(one), genomes.reshape(b // c, c, genomes.shape[1]))
        return out.reshape(b, size, size)

    return jax.jit(chunked)


def edge_genomes(n_random: int) -> np.ndarray:
    gen = get("worley", size=64)
    rnd = np.asarray(gen.sample(jax.random.PRNGKey(123), n_random))
    edges = np.array([[3, 2, 0], [7, 400, 100], [11, 400, 0], [5, 8, 2], [42, 200, 50], [0, 4, 1]], np.float32)
    return np.concatenate([edges, rnd]).astype(np.float32)


def accuracy(variant: str, size: int, n_random: int) -> dict:
    genomes = jnp.asarray(edge_genomes(n_random))
    ref_d = np.asarray(batched_fn("sort", size, 0, distance=True)(genomes))
    ref_m = np.asarray(batched_fn("sort", size, 0)(genomes))
    with variant_settings(variant) as (select, _):
        got_d = np.asarray(batched_fn(select, size, 0, distance=True)(genomes))
        got_m = np.asarray(batched_fn(select, size, 0)(genomes))
    err = np.abs(got_d - ref_d)
    return {"max_abs_diff_px": float(err.max()), "max_abs_diff_map": float(np.abs(got_m - ref_m).max()),
            "frac_px_gt_1e-4": float((err > 1e-4).mean()), "accuracy_batch": int(genomes.shape[0])}


def while_body_summary(hlo: str) -> str:
    """Fusions per while-loop body in optimised HLO text, e.g. 'body0: 2 fusions; body1: 3 fusions'.

    A count trip should be the reduction fusion plus the small [B, H, W] update fusions; on GPU look for one
    ``kind=kInput`` (reduction) fusion per body in the ``--hlo-dir`` files.
    """
    comps = re.split(r"\n(?=\S)", hlo)
    bodies = set(re.findall(r"body=%?([\w.\-]+)", hlo))
    out = []
    for i, c in enumerate(x for x in comps if any(x.startswith(f"%{b} ") or x.startswith(f"{b} ") for b in bodies)):
        n = len(re.findall(r"= \S+ fusion\(", c))
        out.append(f"body{i}: {n} fusions")
    return "; ".join(out)


def stage_fns(select: str, size: int, step: int = wm._COARSE_STEP, tol: float = wm.TOLERANCE,
              tile: int = wm._TILE) -> dict:
    """Prefixes of "tiled" / "pallas" per genome: the coarse grid and bounds, then the candidate lists too."""
    pallas = select == "pallas"

    def bounds(g):
        dy2, dx2 = wm._separable_d2(g, size)
        lo, hi, _ = wm._tiled_bounds(dy2, dx2, jnp.round(g[2]), step, tol, tile, pallas)
        return dy2, dx2, lo, hi

    def lists(g):
        return wm._tile_lists(*bounds(g), tile, int(np.prod(wm._CAP_GROUPS)), pallas)

    return {"bounds": lambda g: bounds(g)[2:], "bounds+lists": lists}


def time_stages(variant: str, size: int, batch: int, repeats: int) -> list[dict]:
    """Time the prefixes of :func:`stage_fns` (the rest of the render is the difference to the full row)."""
    gen = get("worley", size=size)
    sets = [jax.device_put(gen.sample(k, batch)) for k in jax.random.split(jax.random.PRNGKey(0), 3)]
    rows = []
    with variant_settings(variant) as (select, kw):
        for name, fn in stage_fns(select, size, **kw).items():
            compiled = jax.jit(jax.vmap(fn)).lower(sets[0]).compile()
            t = common.median_time(compiled, sets, repeats=repeats)
            rows.append({"variant": f"{variant} [{name}]", "batch": batch, "size": size, "time_s": t,
                         "maps_per_s": batch / t})
    return rows


def time_variant(variant: str, size: int, batch: int, repeats: int, chunk: int, hlo_dir: str | None) -> dict:
    gen = get("worley", size=size)
    keys = jax.random.split(jax.random.PRNGKey(0), 3)
    sets = [jax.device_put(gen.sample(k, batch)) for k in keys]
    row = {"variant": variant, "batch": batch, "size": size, "chunk": chunk}
    with variant_settings(variant) as (select, _):
        fn = batched_fn(select, size, chunk)
        t0 = time.perf_counter()
        compiled = fn.lower(sets[0]).compile()
        row["compile_s"] = time.perf_counter() - t0
        try:
            mem = compiled.memory_analysis()
            row["temp_GB"] = mem.temp_size_in_bytes / 1e9
            row["temp/d2"] = mem.temp_size_in_bytes / (min(batch, chunk or batch) * size * size * wm.MAX_POINTS * 4)
        except Exception:  # pragma: no cover - not every backend reports it
            pass
        hlo = compiled.as_text()
        row["loop_bodies"] = while_body_summary(hlo)
        if hlo_dir:
            Path(hlo_dir).mkdir(parents=True, exist_ok=True)
            (Path(hlo_dir) / f"{variant.replace(':', '_')}_b{batch}.hlo.txt").write_text(hlo)
        t = common.median_time(compiled, sets, repeats=repeats)
    row["time_s"] = t
    row["maps_per_s"] = batch / t
    return row


def is_oom(e: Exception) -> bool:
    s = str(e)
    return "RESOURCE_EXHAUSTED" in s or "Out of memory" in s or "out of memory" in s or "OOM" in s


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--variants", nargs="*", default=["sort", "bisect", "bracket", "tiled"])
    p.add_argument("--batch", nargs="*", type=int, default=[256, 1024, 4096])
    p.add_argument("--size", type=int, default=256)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--chunk", type=int, default=0, help="> 0: lax.map over chunks of this many genomes")
    p.add_argument("--accuracy-random", type=int, default=10, help="random genomes in the accuracy batch")
    p.add_argument("--skip-accuracy", action="store_true")
    p.add_argument("--stages", action="store_true",
                   help="also time the prefixes of tiled / pallas: coarse grid + bounds, then + candidate lists")
    p.add_argument("--hlo-dir", default=None)
    p.add_argument("--out", default=None)
    args = p.parse_args()

    env = common.environment()
    print(f"# Worley variants, {args.size} x {args.size}, {env['device']} ({env['platform']}), jax {env['jax']}, "
          f"bracket iterations at step {wm._COARSE_STEP}: {wm.bracket_iterations(args.size)}", flush=True)
    rows, acc = [], []
    for v in args.variants:
        for b in args.batch:
            try:
                r = time_variant(v, args.size, b, args.repeats, args.chunk,
                                 args.hlo_dir if b == min(args.batch) else None)
            except Exception as e:  # noqa: BLE001
                if not is_oom(e):
                    raise
                r = {"variant": v, "batch": b, "size": args.size, "skipped": "OOM"}
            rows.append(r)
            print(common.markdown_table([r], ["variant", "batch", "maps_per_s", "time_s", "compile_s", "temp_GB",
                                              "temp/d2", "loop_bodies", "skipped"]).splitlines()[-1], flush=True)
            if args.stages and v.split(":")[0] in ("tiled", "pallas") and "skipped" not in r:
                for st in time_stages(v, args.size, b, args.repeats):
                    rows.append(st)
                    print(common.markdown_table([st], ["variant", "batch", "maps_per_s", "time_s"]).splitlines()[-1],
                          flush=True)
        if not args.skip_accuracy and v.split(":")[0] != "sort":
            a = {"variant": v, **accuracy(v, args.size, args.accuracy_random)}
            acc.append(a)
            print(a, flush=True)
    print()
    print(common.markdown_table(rows, ["variant", "batch", "maps_per_s", "time_s", "compile_s", "temp_GB", "temp/d2",
                                       "loop_bodies", "skipped"]))
    if acc:
        print()
        print(common.markdown_table(acc, ["variant", "max_abs_diff_px", "max_abs_diff_map", "frac_px_gt_1e-4",
                                          "accuracy_batch"]))
    common.write_json(args.out, {"environment": env, "benchmark": "worley_variants", "size": args.size,
                                 "bracket_iterations": wm.bracket_iterations(args.size), "rows": rows,
                                 "accuracy": acc})


if __name__ == "__main__":
    main()
