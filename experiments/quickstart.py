"""``python -m experiments quickstart``: a small end-to-end run on CPU.

Samples terrains from every available generator, renders them, computes the paper's descriptors (TRI, TPI,
roughness at window 30, stride 2) and Algorithm 1, and writes into a new run folder:

- ``terrains.png``     a grid of sample terrains, one row per generator
- ``descriptors.csv``  generator, genome index, tri, tpi, roughness, traversable
- ``descriptors.png``  the descriptor pairs of Experiment 1, one colour per generator
- ``summary.md``       per-generator means and timings
- ``config.json``      the options of this run
"""

from __future__ import annotations

import argparse
from typing import Any, NamedTuple


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--n", type=int, default=32, help="terrains per generator (>= 1)")
    parser.add_argument("--size", type=int, default=256, help="heightmap side in pixels (32..1024)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--generators", nargs="*", default=None, help="default: every generator that loads")
    parser.add_argument("--out", default=None, help="run folder (default runs/quickstart-<time>)")


NAMES = ("tri", "tpi", "roughness")


class Sample(NamedTuple):
    """One generator's share of the quickstart: maps [n, S, S], descriptors [n, 3], traversable [n], render s."""

    maps: Any
    descriptors: Any
    traversable: Any
    render_s: float


def sample_generator(gen, key, n: int, size: int) -> Sample:
    """Render ``n`` random terrains of ``gen`` and describe them (window 30, or size / 4 on small maps)."""
    import time

    import jax
    import numpy as np

    from jaxterrain import features

    genomes = gen.sample(key, n)
    t0 = time.perf_counter()
    hm = jax.block_until_ready(gen.render(genomes))
    render_s = time.perf_counter() - t0
    window = min(30, size // 4)
    return Sample(np.asarray(hm), np.asarray(features.descriptors(hm, NAMES, window=window, stride=2)),
                  np.asarray(features.is_traversable(hm)), render_s)


def plot_terrains(samples: dict[str, Sample], path, cols: int = 6) -> None:
    """A grid of sample terrains, one row per generator."""
    import matplotlib.pyplot as plt

    from experiments.common import save_figure

    cols = min(cols, min(len(s.maps) for s in samples.values()))
    fig, axes = plt.subplots(len(samples), cols, figsize=(2 * cols, 2 * len(samples)), squeeze=False)
    for r, (name, s) in enumerate(samples.items()):
        for c in range(cols):
            ax = axes[r, c]
            ax.imshow(s.maps[c], cmap="terrain", vmin=0, vmax=1)
            ax.set_xticks([]), ax.set_yticks([])
            if c == 0:
                ax.set_ylabel(name)
    fig.tight_layout()
    save_figure(fig, path, dpi=80)


def plot_descriptor_pairs(samples: dict[str, Sample], path) -> None:
    """The three descriptor pairs of Experiment 1, one colour per generator."""
    import matplotlib.pyplot as plt

    from experiments.common import save_figure

    pairs = [("tri", "tpi"), ("tri", "roughness"), ("tpi", "roughness")]
    fig, axes = plt.subplots(1, 3, figsize=(12, 4))
    for ax, (a, b) in zip(axes, pairs):
        for name, s in samples.items():
            ax.scatter(s.descriptors[:, NAMES.index(a)], s.descriptors[:, NAMES.index(b)], s=8, label=name)
        ax.set_xlabel(a), ax.set_ylabel(b)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, path, dpi=80)


def descriptors_csv(samples: dict[str, Sample]) -> str:
    import csv
    import io

    out = io.StringIO()
    w = csv.writer(out)
    w.writerow(["generator", "index", *NAMES, "traversable"])
    for name, s in samples.items():
        for i, row in enumerate(s.descriptors):
            w.writerow([name, i, *(f"{v:.6g}" for v in row), int(s.traversable[i])])
    return out.getvalue()


def summary_markdown(samples: dict[str, Sample], skipped: dict[str, str], args: argparse.Namespace) -> str:
    lines = [f"# quickstart ({args.n} terrains per generator, {args.size} x {args.size}, seed {args.seed})", "",
             "| generator | mean TRI | mean TPI | mean roughness | traversable | render time (s, incl. compile) |",
             "|---|---|---|---|---|---|"]
    for name, s in samples.items():
        m = s.descriptors.mean(0)
        lines.append(f"| {name} | {m[0]:.4g} | {m[1]:.4g} | {m[2]:.4g} | {s.traversable.mean():.0%} | "
                     f"{s.render_s:.2f} |")
    lines += [f"| {name} | skipped: {why} | | | | |" for name, why in skipped.items()]
    lines += ["", "Files: terrains.png, descriptors.png, descriptors.csv, config.json.", ""]
    return "\n".join(lines)


def main(args: argparse.Namespace) -> int:
    import jax

    from experiments.common import run_folder, write_config
    from jaxterrain import generators
    from jaxterrain.io import atomic_write_text

    if args.n < 1:
        raise SystemExit("--n must be >= 1")
    if not 32 <= args.size <= 1024:
        raise SystemExit("--size must be in [32, 1024]")
    run = run_folder("quickstart", args.out)
    run.mkdir(parents=True, exist_ok=True)
    write_config(run, vars(args))

    key = jax.random.key(args.seed)
    samples, skipped = {}, {}
    for name in args.generators or generators.names():
        try:
            gen = generators.get(name, size=args.size)
        except Exception as err:  # e.g. GAN weights not shipped
            skipped[name] = str(err).splitlines()[0]
            print(f"skip {name}: {skipped[name]}")
            continue
        key, sample_key = jax.random.split(key)
        samples[name] = s = sample_generator(gen, sample_key, args.n, args.size)
        print(f"{name:15s} {args.n} terrains rendered in {s.render_s:.2f} s (incl. compile); "
              f"traversable {s.traversable.mean():.0%}", flush=True)
    if not samples:
        raise SystemExit("no generator could be loaded")

    plot_terrains(samples, run / "terrains.png")
    plot_descriptor_pairs(samples, run / "descriptors.png")
    atomic_write_text(run / "descriptors.csv", descriptors_csv(samples))
    atomic_write_text(run / "summary.md", summary_markdown(samples, skipped, args))
    print(f"wrote {run}")
    return 0
