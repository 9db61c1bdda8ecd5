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


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--n", type=int, default=32, help="terrains per generator (>= 1)")
    parser.add_argument("--size", type=int, default=256, help="heightmap side in pixels (32..1024)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--generators", nargs="*", default=None, help="default: every generator that loads")
    parser.add_argument("--out", default=None, help="run folder (default runs/quickstart-<time>)")


def main(args: argparse.Namespace) -> int:
    import csv
    import io
    import time

    import jax
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from pathlib import Path

    from experiments.common import timestamp, write_config
    from jaxterrain import features, generators
    from jaxterrain.io import atomic_write_bytes, atomic_write_text

    if args.n < 1:
        raise SystemExit("--n must be >= 1")
    if not 32 <= args.size <= 1024:
        raise SystemExit("--size must be in [32, 1024]")
    run = Path(args.out or f"runs/quickstart-{timestamp()}")
    run.mkdir(parents=True, exist_ok=True)
    write_config(run, vars(args))
    names = ("tri", "tpi", "roughness")
    key = jax.random.key(args.seed)

    maps, desc, trav, timing, skipped = {}, {}, {}, {}, {}
    for name in args.generators or generators.names():
        try:
            gen = generators.get(name, size=args.size)
        except Exception as err:  # e.g. GAN weights not shipped
            skipped[name] = str(err).splitlines()[0]
            print(f"skip {name}: {skipped[name]}")
            continue
        key, sample_key = jax.random.split(key)
        genomes = gen.sample(sample_key, args.n)
        t0 = time.perf_counter()
        hm = jax.block_until_ready(gen.render(genomes))
        t_render = time.perf_counter() - t0
        window = min(30, args.size // 4)
        maps[name] = np.asarray(hm)
        desc[name] = np.asarray(features.descriptors(hm, names, window=window, stride=2))
        trav[name] = np.asarray(features.is_traversable(hm))
        timing[name] = t_render
        print(f"{name:15s} {args.n} terrains rendered in {t_render:.2f} s (incl. compile); "
              f"traversable {trav[name].mean():.0%}", flush=True)
    if not maps:
        raise SystemExit("no generator could be loaded")

    # terrains.png: up to 6 samples per generator
    cols = min(6, args.n)
    fig, axes = plt.subplots(len(maps), cols, figsize=(2 * cols, 2 * len(maps)), squeeze=False)
    for r, (name, hm) in enumerate(maps.items()):
        for c in range(cols):
            ax = axes[r, c]
            ax.imshow(hm[c], cmap="terrain", vmin=0, vmax=1)
            ax.set_xticks([]), ax.set_yticks([])
            if c == 0:
                ax.set_ylabel(name)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=80)
    plt.close(fig)
    atomic_write_bytes(run / "terrains.png", buf.getvalue())

    # descriptors.png: the three descriptor pairs of Experiment 1
    pairs = [("tri", "tpi"), ("tri", "roughness"), ("tpi", "roughness")]
    fig, axes = plt.subplots(1, 3, figsize=(12, 4))
    for ax, (a, b) in zip(axes, pairs):
        for name, d in desc.items():
            ax.scatter(d[:, names.index(a)], d[:, names.index(b)], s=8, label=name)
        ax.set_xlabel(a), ax.set_ylabel(b)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=80)
    plt.close(fig)
    atomic_write_bytes(run / "descriptors.png", buf.getvalue())

    out = io.StringIO()
    w = csv.writer(out)
    w.writerow(["generator", "index", *names, "traversable"])
    for name, d in desc.items():
        for i, row in enumerate(d):
            w.writerow([name, i, *(f"{v:.6g}" for v in row), int(trav[name][i])])
    atomic_write_text(run / "descriptors.csv", out.getvalue())

    lines = [f"# quickstart ({args.n} terrains per generator, {args.size} x {args.size}, seed {args.seed})", "",
             "| generator | mean TRI | mean TPI | mean roughness | traversable | render time (s, incl. compile) |",
             "|---|---|---|---|---|---|"]
    for name, d in desc.items():
        m = d.mean(0)
        lines.append(f"| {name} | {m[0]:.4g} | {m[1]:.4g} | {m[2]:.4g} | {trav[name].mean():.0%} | "
                     f"{timing[name]:.2f} |")
    for name, why in skipped.items():
        lines.append(f"| {name} | skipped: {why} | | | | |")
    lines += ["", "Files: terrains.png, descriptors.png, descriptors.csv, config.json.", ""]
    atomic_write_text(run / "summary.md", "\n".join(lines))
    print(f"wrote {run}")
    return 0
