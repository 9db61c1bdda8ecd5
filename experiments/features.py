"""``python -m experiments features``: Experiment 1a (paper Figure 4), feature alignment with difficulty.

For each generator (default CPPN and Perlin) it renders random genomes and chains of mutated ones (so that the
terrains span easy to hard), computes TRI, TPI and roughness at several windows (default 5, 10, 20, 30, 40; stride
2), any extra registered descriptor (e.g. a learned traversability model, when registered in ``jaxterrain.features``)
and the ground-truth difficulty (1 - fitness of the walker's base policy; ``--fitness slope`` for a cheap stand-in),
then the Pearson correlation matrix of all of them. The presets add the learned ``traversability`` descriptor
(:mod:`jaxterrain.traversability`, the paper's fourth feature).

Writes into the run folder: ``config.json``, ``values_<generator>.csv`` (one row per terrain), ``correlations.csv``
(generator, feature_a, feature_b, r), ``correlation_<generator>.png`` (heatmaps like Figure 4) and
``correlations.png`` (both side by side), ``figure4.png`` / ``figure4.csv`` (Figure 4: TRI, TPI and roughness at
``figure_window``, the extra descriptors and difficulty, one heatmap per generator), plus with ``--calibrate``
``ranges.json``: the [0.5, 99.5] percentile of each descriptor over all generators at the archive window (the
recipe of ``jaxterrain.archive.DEFAULT_RANGES``).

Long runs: ``values_<generator>.partial.npz`` holds the rows measured so far (saved after every batch);
``--time-limit MIN`` stops between batches and ``--resume RUN`` continues from there with the same values.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
from pathlib import Path

from experiments import common

PRESETS: dict[str, dict] = {
    "paper": dict(generators=["cppn", "perlin"], samples=250, mutation_steps=4, size=256, windows=[5, 10, 20, 30, 40],
                  stride=2, fitness="difficulty", attempts=20, best=5, batch=50, extra_descriptors=["traversability"],
                  calibrate=False, calibrate_window=30, figure_window=30),
    "gpu": dict(generators=["cppn", "perlin"], samples=250, mutation_steps=4, size=256, windows=[5, 10, 20, 30, 40],
                stride=2, fitness="difficulty", attempts=20, best=5, batch=250, extra_descriptors=["traversability"],
                calibrate=False, calibrate_window=30, figure_window=30),
    "smoke": dict(generators=["cppn", "perlin"], samples=6, mutation_steps=1, size=48, windows=[5, 10],
                  stride=2, fitness="slope", attempts=2, best=1, batch=12, extra_descriptors=["traversability"],
                  calibrate=False, calibrate_window=10, figure_window=10),
}
FEATURES = ("tri", "tpi", "roughness")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    common.add_run_arguments(parser, PRESETS, "smoke")
    parser.add_argument("--generators", nargs="+", default=None, help="generator names (default cppn perlin)")
    parser.add_argument("--samples", type=int, default=None,
                        help="random genomes per generator; each also gives mutation_steps mutated descendants")
    parser.add_argument("--mutation-steps", type=int, default=None)
    parser.add_argument("--size", type=int, default=None)
    parser.add_argument("--windows", nargs="+", type=int, default=None)
    parser.add_argument("--fitness", choices=["difficulty", "slope"], default=None)
    parser.add_argument("--calibrate", action="store_const", const=True, default=None,
                        help="also measure descriptor ranges (see jaxterrain.archive.DEFAULT_RANGES)")


def overrides(args) -> dict:
    return dict(generators=args.generators, samples=args.samples, mutation_steps=args.mutation_steps,
                size=args.size, windows=args.windows, fitness=args.fitness, calibrate=args.calibrate)


def terrain_set(gen, key, samples: int, steps: int):
    """``samples * (steps + 1)`` genomes: random ones and ``steps`` generations of mutated descendants."""
    import jax

    k_sample, k_mut = jax.random.split(key)
    g = gen.sample(k_sample, samples)
    out = [g]
    for s in range(steps):
        g = gen.mutate(jax.random.fold_in(k_mut, s), g)
        out.append(g)
    return jax.tree.map(lambda *xs: jax.numpy.concatenate(xs), *out)


def measure(gen, genomes, cfg: dict, key, fitness_fn, progress=print, checkpoint: Path | None = None,
            clock: common.Clock | None = None) -> dict[str, "np.ndarray"]:  # noqa: F821
    """Columns ``{name: [N]}``: ``<feature>_<window>`` for every feature and window, extras, fitness, difficulty.

    The terrains are measured in batches of ``cfg["batch"]``; batch ``s`` walks with key ``fold_in(key, s)``. With
    ``checkpoint`` (an ``.npz`` path) the columns so far are saved after every batch and a saved file is continued
    from, so a killed or time-limited run (``clock``: raises :class:`common.TimeUp` between batches) resumes with
    the same values.
    """
    import jax
    import numpy as np

    from jaxterrain import features
    from jaxterrain.io import atomic_save_npz

    n = jax.tree.leaves(genomes)[0].shape[0]
    batch = int(cfg["batch"])
    windows = [int(w) for w in cfg["windows"]]
    calib = [int(cfg["calibrate_window"])] if cfg.get("calibrate") else []
    calib += [int(cfg["figure_window"])] if cfg.get("figure_window") else []
    cols: dict[str, list] = {}
    start = 0
    if checkpoint is not None and checkpoint.exists():
        with np.load(checkpoint) as saved:
            start = int(saved["_measured"])
            cols = {k: [saved[k]] for k in saved.files if k != "_measured"}
        progress(f"  [{gen.name}] continuing after {start}/{n} terrains ({checkpoint})")
    render = jax.jit(jax.vmap(gen.render_one))
    desc = jax.jit(features.descriptors, static_argnames=("names", "window", "stride"))
    trav = jax.jit(features.is_traversable)
    for s in range(start, n, batch):
        part = jax.tree.map(lambda x: x[s : s + batch], genomes)
        hm = render(part)
        for w in sorted(set(windows + calib)):
            d = np.asarray(desc(hm, names=FEATURES, window=w, stride=int(cfg["stride"])))
            for j, f in enumerate(FEATURES):
                cols.setdefault(f"{f}_{w}", []).append(d[:, j])
        for extra in cfg.get("extra_descriptors") or []:
            cols.setdefault(extra, []).append(np.asarray(desc(hm, names=(extra,), window=windows[0],
                                                              stride=int(cfg["stride"])))[:, 0])
        cols.setdefault("traversable", []).append(np.asarray(trav(hm)).astype(np.float32))
        fit = np.asarray(fitness_fn(hm, jax.random.fold_in(key, s)))
        cols.setdefault("fitness", []).append(fit)
        progress(f"  [{gen.name}] {min(s + batch, n)}/{n} terrains measured")
        del hm
        if checkpoint is not None:
            atomic_save_npz(checkpoint, _measured=np.int64(min(s + batch, n)),
                            **{k: np.concatenate(v) for k, v in cols.items()})
        if clock is not None and s + batch < n:
            clock.check()
    out = {k: np.concatenate(v).astype(np.float64) for k, v in cols.items()}
    out["difficulty"] = 1.0 - out["fitness"]
    return out


def correlations(values: dict, names: list[str]):
    """Pearson correlation matrix ``[len(names), len(names)]`` (NaN where a column is constant)."""
    import numpy as np

    x = np.stack([values[n] for n in names])
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.corrcoef(x)


def plot_heatmap(ax, r, names, title):
    img = ax.imshow(r, vmin=-1, vmax=1, cmap="RdBu_r")
    ax.set_xticks(range(len(names)), names, rotation=90, fontsize=6)
    ax.set_yticks(range(len(names)), names, fontsize=6)
    if len(names) <= 17:
        for i in range(len(names)):
            for j in range(len(names)):
                if r[i, j] == r[i, j]:
                    ax.text(j, i, f"{r[i, j]:.2f}", ha="center", va="center", fontsize=4)
    ax.set_title(title, fontsize=9)
    return img


def figure4(results: dict, cfg: dict, folder: Path) -> list[str]:
    """Figure 4: per generator, the Pearson correlations among TRI, TPI, roughness (at ``figure_window``), the
    extra descriptors and difficulty: ``figure4.png`` (one heatmap per generator) and ``figure4.csv``. Returns the
    feature names (empty when the window was not measured, e.g. a run from an older config)."""
    import matplotlib.pyplot as plt

    from jaxterrain.io import atomic_write_text

    w = cfg.get("figure_window")
    names = [f"{f}_{w}" for f in FEATURES] + list(cfg.get("extra_descriptors") or []) + ["difficulty"]
    if not w or not all(n in v for v in results.values() for n in names):
        return []
    fig, axes = plt.subplots(1, len(results), figsize=(4.4 * len(results) + 1, 4.4), squeeze=False,
                             layout="constrained")
    rows = []
    for ax, (gname, values) in zip(axes[0], results.items()):
        r = correlations(values, names)
        rows += [(gname, a, b, f"{r[i, j]:.6f}") for i, a in enumerate(names) for j, b in enumerate(names)]
        img = plot_heatmap(ax, r, names, f"{gname} (n = {len(values['difficulty'])})")
        for t in ax.texts:
            t.set_fontsize(7)
        order = sorted(zip(abs(r[-1, :-1]), names[:-1]))
        print(f"[{gname}] Figure 4 |r| with difficulty, weakest first: "
              + ", ".join(f"{n} {a:.3f}" for a, n in order), flush=True)
    fig.colorbar(img, ax=axes[0].tolist(), shrink=0.8, label="Pearson r")
    common.save_figure(fig, folder / "figure4.png", dpi=150)
    atomic_write_text(folder / "figure4.csv", _csv_text(["generator", "feature_a", "feature_b", "r"], rows))
    return names


def _csv_text(header, rows) -> str:
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(header)
    w.writerows(rows)
    return buf.getvalue()


def main(args) -> int:
    import jax
    import matplotlib
    import numpy as np

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jaxterrain import generators
    from jaxterrain.io import atomic_write_text

    folder, cfg = common.setup_run("features", args, PRESETS, "smoke", overrides(args))
    clock = common.Clock(args.time_limit)
    key = jax.random.key(int(cfg["seed"]))
    size = int(cfg["size"])
    windows = [int(w) for w in cfg["windows"]]
    fitness_fn = jax.jit(common.fitness_function(cfg["fitness"], int(cfg["attempts"]), int(cfg["best"]), size))
    results = {}
    calib_values = []
    for gi, name in enumerate(cfg["generators"]):
        ok, why = common.generator_available(name, size)
        if not ok:
            print(f"[{name}] skipped: {why}", flush=True)
            continue
        values_path = folder / f"values_{name}.csv"
        if values_path.exists():  # --resume: reuse finished generators
            with open(values_path) as f:
                rows = list(csv.reader(f))
            values = {h: np.array([float(r[i]) for r in rows[1:]]) for i, h in enumerate(rows[0])}
            print(f"[{name}] reusing {values_path}", flush=True)
        else:
            gen = generators.get(name, size=size)
            genomes = terrain_set(gen, jax.random.fold_in(key, 2 * gi), int(cfg["samples"]), int(cfg["mutation_steps"]))
            partial = folder / f"values_{name}.partial.npz"
            try:
                if results:
                    clock.check()  # between generators too
                values = measure(gen, genomes, cfg, jax.random.fold_in(key, 2 * gi + 1), fitness_fn,
                                 progress=lambda m: print(m, flush=True), checkpoint=partial, clock=clock)
            except common.TimeUp:
                print(f"time limit reached; continue with: python -m experiments features --resume {folder}",
                      flush=True)
                return 3
            cols = list(values)
            atomic_write_text(values_path, _csv_text(cols, zip(*[[f"{v:.8g}" for v in values[c]] for c in cols])))
            partial.unlink(missing_ok=True)
        results[name] = values
        if cfg.get("calibrate"):
            w = int(cfg["calibrate_window"])
            calib_values.append(np.stack([values[f"{f}_{w}"] for f in FEATURES], -1)[values["traversable"] > 0])
    if not results:
        print("no generator available", flush=True)
        return 1
    names = [f"{f}_{w}" for f in FEATURES for w in windows] + list(cfg.get("extra_descriptors") or []) + ["difficulty"]
    rows = []
    fig, axes = plt.subplots(1, len(results), figsize=(6.5 * len(results), 6), squeeze=False)
    for ax, (gname, values) in zip(axes[0], results.items()):
        r = correlations(values, names)
        rows += [(gname, a, b, f"{r[i, j]:.6f}") for i, a in enumerate(names) for j, b in enumerate(names)]
        img = plot_heatmap(ax, r, names, f"{gname} (n = {len(values['difficulty'])})")
        one, ax1 = plt.subplots(figsize=(6.5, 6))
        one.colorbar(plot_heatmap(ax1, r, names, f"Pearson r, {gname}"), ax=ax1)
        one.tight_layout()
        common.save_figure(one, folder / f"correlation_{gname}.png", dpi=150)
        best = max((abs(r[i, -1]), names[i]) for i in range(len(names) - 1) if r[i, -1] == r[i, -1])
        print(f"[{gname}] strongest |r| with difficulty: {best[1]} ({best[0]:.3f})", flush=True)
    fig.colorbar(img, ax=axes[0].tolist(), shrink=0.8)
    common.save_figure(fig, folder / "correlations.png", dpi=150)
    atomic_write_text(folder / "correlations.csv", _csv_text(["generator", "feature_a", "feature_b", "r"], rows))
    figure4(results, cfg, folder)
    if cfg.get("calibrate") and calib_values:
        allv = np.concatenate(calib_values)
        ranges = {}
        for j, f in enumerate(FEATURES):
            lo, hi = np.percentile(allv[:, j], [0.5, 99.5])
            ranges[f] = {"p0.5": float(lo), "p99.5": float(hi), "n": int(allv.shape[0])}
        atomic_write_text(folder / "ranges.json", json.dumps(ranges, indent=2) + "\n")
        print(f"descriptor percentiles at window {cfg['calibrate_window']}: {ranges}", flush=True)
    print(f"done -> {folder}", flush=True)
    return 0
