"""``python -m experiments difficulty-spread``: how the base policy's fitness spreads per generator and height scale.

The height scale (metres for heightmap value 1.0, ``TerrainScale.height``) sets how hard every terrain is. It should
make fitness informative: random terrains of each generator spread over [0.1, 0.9] rather than piling up at 0 or 1.
For each height scale and generator this samples ``--n`` random genomes, renders them and evaluates them with
``jaxterrain.difficulty.evaluate`` (``--attempts``, ``--best``), and writes:

- ``fitness.csv``   height, generator, index, fitness
- ``spread.md``     per height and generator: mean, quantiles 10/50/90 %, share in [0.1, 0.9]; and two anchors at
                    1.0 m height scale: flat ground and a 1 m wall (0.4 m thick) across the middle of the course
                    (a calibrated walker crosses the first and is stopped by the second)
- ``spread.png``    fitness histograms, one panel per height scale
- ``config.json``

``--robot NAME`` walks that robot's shipped base policy (``jaxterrain.difficulty.robot_base_policy``; default the
humanoid's).
"""

from __future__ import annotations

import argparse

from experiments import common
from experiments.common import UsageError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--heights", nargs="+", type=float, default=[0.5], help="height scales to try (metres, > 0)")
    common.add_terrains_argument(parser, "n", "each walked by the base policy at every height", default=16,
                                 aliases=("--n",))
    parser.add_argument("--attempts", type=int, default=20, help="walks per terrain in total (the paper: 20)")
    parser.add_argument("--best", type=int, default=5,
                        help="fitness = mean of the best this many walks, <= --attempts (the paper: 5)")
    parser.add_argument("--generators", nargs="*", default=None,
                        help="generator names (default: every generator that loads)")
    parser.add_argument("--seed", type=int, default=0, help="PRNG seed of the terrains and walks")
    parser.add_argument("--out", default=None, help="run folder (default runs/difficulty-spread-<time>)")
    parser.add_argument("--robot", default="humanoid", metavar="NAME",
                        help="walk this robot's shipped base policy (default humanoid)")


def anchor_maps(size: int = 256):
    """``{name: [size, size] float32 heightmap}``: flat ground and a wall of height value 1.0 (1 m at the 1.0 m
    height scale), 10 cells thick (0.4 m at 0.04 m cells), across every row in the middle of the course."""
    import numpy as np

    wall = np.zeros((size, size), np.float32)
    wall[:, size // 2 - 5:size // 2 + 5] = 1.0
    return {"flat": np.zeros((size, size), np.float32), "wall_1m": wall}


def main(args: argparse.Namespace) -> int:
    import csv
    import io
    import time
    import jax
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from experiments.common import run_folder, save_figure, write_config
    from jaxterrain import difficulty, generators
    from jaxterrain.runtime.io import atomic_write_text
    from jaxterrain.terrain import TerrainScale

    if args.n < 1:
        raise UsageError("--terrains must be >= 1")
    if any(h <= 0 for h in args.heights):
        raise UsageError("--heights must all be > 0 (metres)")
    try:
        policy = difficulty.robot_base_policy(args.robot)
    except ValueError as err:
        raise UsageError(f"--robot: {err}") from None
    run = run_folder("difficulty-spread", args.out)
    run.mkdir(parents=True, exist_ok=True)
    write_config(run, {**vars(args), "command": "difficulty-spread"})

    maps = {}
    key = jax.random.key(args.seed)
    for name in args.generators or generators.names():
        try:
            gen = generators.get(name)
        except Exception as err:
            print(f"skip {name}: {str(err).splitlines()[0]}")
            continue
        key, k = jax.random.split(key)
        maps[name] = gen.render(gen.sample(k, args.n))

    from jaxterrain.runtime import estimates

    estimates.announce("walks", f"{args.attempts} walks a terrain; once per terrain count and height")
    results: dict[tuple[float, str], np.ndarray] = {}
    for height in args.heights:
        scale = TerrainScale(cell_size=TerrainScale().cell_size, height=height)
        for name, hm in maps.items():
            t0 = time.perf_counter()
            fit = np.asarray(difficulty.evaluate(hm, jax.random.key(args.seed + 1), attempts=args.attempts,
                                                 best=args.best, scale=scale, policy=policy))
            results[(height, name)] = fit
            print(f"height {height:.2f} m  {name:15s} fitness mean {fit.mean():.3f}  "
                  f"q10/50/90 {np.quantile(fit, 0.1):.2f}/{np.median(fit):.2f}/{np.quantile(fit, 0.9):.2f}  "
                  f"({time.perf_counter() - t0:.0f} s)", flush=True)

    anchors = anchor_maps()
    fit = np.asarray(difficulty.evaluate(np.stack(list(anchors.values())), jax.random.key(args.seed + 2),
                                         attempts=args.attempts, best=args.best, scale=TerrainScale(), policy=policy))
    anchor_fit = dict(zip(anchors, fit.tolist()))
    print("anchors at 1.0 m: " + ", ".join(f"{k} {v:.3f}" for k, v in anchor_fit.items()), flush=True)

    out = io.StringIO()
    w = csv.writer(out)
    w.writerow(["height", "generator", "index", "fitness"])
    for (height, name), fit in results.items():
        for i, f in enumerate(fit):
            w.writerow([height, name, i, f"{f:.4f}"])
    for name, f in anchor_fit.items():
        w.writerow([TerrainScale().height, f"anchor:{name}", 0, f"{f:.4f}"])
    atomic_write_text(run / "fitness.csv", out.getvalue())

    lines = [f"# fitness spread ({args.robot}: {args.n} random terrains per generator, best {args.best} of "
             f"{args.attempts})", "",
             "Anchors at the 1.0 m height scale: " + ", ".join(f"{k} {v:.3f}" for k, v in anchor_fit.items()), "",
             "| height (m) | generator | mean | q10 | median | q90 | share in [0.1, 0.9] |", "|---|---|---|---|---|---|---|"]
    for (height, name), fit in results.items():
        inside = np.mean((fit >= 0.1) & (fit <= 0.9))
        lines.append(f"| {height:.2f} | {name} | {fit.mean():.3f} | {np.quantile(fit, 0.1):.3f} | {np.median(fit):.3f} "
                     f"| {np.quantile(fit, 0.9):.3f} | {inside:.0%} |")
    atomic_write_text(run / "spread.md", "\n".join(lines) + "\n")

    fig, axes = plt.subplots(1, len(args.heights), figsize=(4 * len(args.heights), 3), squeeze=False)
    for ax, height in zip(axes[0], args.heights):
        for name in maps:
            ax.hist(results[(height, name)], bins=np.linspace(0, 1, 11), histtype="step", label=name)
        ax.set_title(f"height scale {height:.2f} m"), ax.set_xlabel("fitness")
    axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, run / "spread.png", dpi=80)
    print(f"wrote {run}")
    return 0
