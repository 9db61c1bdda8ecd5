"""``python -m experiments features``: Experiment 1a (paper Figure 4), feature alignment with difficulty.

For each generator (default CPPN and Perlin) it renders random genomes and chains of mutated ones (so that the
terrains span easy to hard), computes TRI, TPI and roughness at several windows (default 5, 10, 20, 30, 40; stride
2), any extra registered descriptor (e.g. a learned traversability model, when registered in ``jaxterrain.features``)
and the ground-truth difficulty (1 - fitness of the walker's base policy; ``--fitness slope`` for a cheap stand-in),
then the Pearson correlation matrix of all of them. The presets add the learned ``traversability`` descriptor
(:mod:`jaxterrain.features.learned`, the paper's fourth feature).

Writes into the run folder: ``config.json``, ``values_<generator>.csv`` (one row per terrain), ``correlations.csv``
(generator, feature_a, feature_b, r), ``correlation_<generator>.png`` (heatmaps like Figure 4) and
``correlations.png`` (both side by side), ``figure4.png`` / ``figure4.csv`` (Figure 4: TRI, TPI and roughness at
``figure_window``, the extra descriptors and difficulty, one heatmap per generator), plus with ``--calibrate``
``ranges.json``: the [0.5, 99.5] percentile of each descriptor over all generators at the archive window (the
recipe of ``jaxterrain.qd.DEFAULT_RANGES``).

Long runs go through ``jaxterrain.runtime.driver.run_chunks``, one step per batch of ``batch`` terrains (generator after
generator): after every batch ``checkpoint.npz`` (the columns measured so far; the one before kept as
``checkpoint.prev.npz``), ``metrics.csv`` and TensorBoard events (``tb/``: the batch's mean difficulty and
traversable fraction) and a progress bar; ``--time-limit MIN`` stops after a batch (exit code 3) and ``--resume RUN``
continues from there with the same values.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
from pathlib import Path
from typing import Any, NamedTuple

from experiments import common

PRESETS: dict[str, dict] = common.with_preset_names({
    "paper": dict(generators=["cppn", "perlin"], samples=250, mutation_steps=4, size=256, windows=[5, 10, 20, 30, 40],
                  stride=2, fitness="difficulty", attempts=20, best=5, batch=50, extra_descriptors=["traversability"],
                  calibrate=False, calibrate_window=30, figure_window=30),
    "gpu": dict(generators=["cppn", "perlin"], samples=250, mutation_steps=4, size=256, windows=[5, 10, 20, 30, 40],
                stride=2, fitness="difficulty", attempts=20, best=5, batch=250, extra_descriptors=["traversability"],
                calibrate=False, calibrate_window=30, figure_window=30),
    "smoke": dict(generators=["cppn", "perlin"], samples=6, mutation_steps=1, size=48, windows=[5, 10],
                  stride=2, fitness="slope", attempts=2, best=1, batch=12, extra_descriptors=["traversability"],
                  calibrate=False, calibrate_window=10, figure_window=10),
}, {"gpu-short": ("gpu", {"samples": 25})})
FEATURES = ("tri", "tpi", "roughness")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    common.add_run_arguments(parser, PRESETS, "smoke")
    parser.add_argument("--generators", nargs="+", default=None, help="generator names (default cppn perlin)")
    common.add_terrains_argument(parser, "samples", "random genomes, each also mutated --mutation-steps times "
                                            "(1 + mutation-steps terrains each)", aliases=("--samples",))
    parser.add_argument("--mutation-steps", type=int, default=None,
                        help="mutated descendants of each random genome, >= 0")
    parser.add_argument("--size", type=int, default=None, help="heightmap side in pixels")
    parser.add_argument("--windows", nargs="+", type=int, default=None,
                        help="window sides (pixels, >= 2) at which TRI / TPI / roughness are computed")
    parser.add_argument("--fitness", choices=common.FITNESS_NAMES, default=None,
                        help="what the features are correlated with: difficulty (the base policy walks each "
                             "terrain) or slope (a cheap stand-in, no walking)")
    parser.add_argument("--extra-descriptors", nargs="+", default=None, metavar="NAME",
                        help="registered descriptors measured besides TRI / TPI / roughness, at the first of --windows "
                             "(e.g. faces max_step traversability)")
    parser.add_argument("--calibrate", action=argparse.BooleanOptionalAction, default=None,
                        help="also measure descriptor ranges (see jaxterrain.qd.DEFAULT_RANGES)")
    common.add_progress_argument(parser)


def overrides(args) -> dict:
    return dict(generators=args.generators, samples=args.samples, mutation_steps=args.mutation_steps,
                size=args.size, windows=args.windows, fitness=args.fitness, extra_descriptors=args.extra_descriptors,
                calibrate=args.calibrate)


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


def _windows(cfg: dict) -> list[int]:
    """Every window measured, ascending: ``windows``, the calibration window (with ``calibrate``) and the figure's."""
    extra = [int(cfg["calibrate_window"])] if cfg.get("calibrate") else []
    extra += [int(cfg["figure_window"])] if cfg.get("figure_window") else []
    return sorted(set([int(w) for w in cfg["windows"]] + extra))


def columns(cfg: dict) -> list[str]:
    """The measured columns in their CSV order: ``<feature>_<window>`` for every window (ascending) and feature,
    the extra descriptors, ``traversable`` (Algorithm 1, 0 / 1) and ``fitness``; ``values_<generator>.csv`` adds
    ``difficulty`` = 1 - fitness."""
    return ([f"{f}_{w}" for w in _windows(cfg) for f in FEATURES] + list(cfg.get("extra_descriptors") or [])
            + ["traversable", "fitness"])


class Plan(NamedTuple):
    """One generator's terrains: its name, its index in ``cfg["generators"]`` (which picks its keys), the
    generator, the genomes of :func:`terrain_set` and their count."""

    name: str
    index: int
    gen: Any
    genomes: Any
    n: int


def plan(cfg: dict, key) -> list[Plan]:
    """The generators of ``cfg`` that can render at ``cfg["size"]`` (the others are skipped with a line saying
    why), each with its genomes from ``fold_in(key, 2 * index)``."""
    import jax

    from jaxterrain import generators

    size, plans = int(cfg["size"]), []
    for gi, name in enumerate(cfg["generators"]):
        ok, why = common.generator_available(name, size)
        if not ok:
            print(f"[{name}] skipped: {why}", flush=True)
            continue
        gen = generators.get(name, size=size)
        genomes = terrain_set(gen, jax.random.fold_in(key, 2 * gi), int(cfg["samples"]), int(cfg["mutation_steps"]))
        plans.append(Plan(name, gi, gen, genomes, int(jax.tree.leaves(genomes)[0].shape[0])))
    return plans


def measure_batch(heightmaps, cfg: dict, key, fitness_fn, descriptors_fn, traversable_fn) -> dict[str, Any]:
    """The :func:`columns` of ``heightmaps`` [B, H, W] as float32 ``[B]`` arrays: TRI, TPI and roughness at every
    window (``descriptors_fn``: jitted ``features.descriptors``), the extra descriptors at the first window,
    Algorithm 1 (``traversable_fn``) and ``fitness_fn(heightmaps, key)``."""
    import numpy as np

    stride = int(cfg["stride"])
    out = {}
    for w in _windows(cfg):
        d = np.asarray(descriptors_fn(heightmaps, names=FEATURES, window=w, stride=stride))
        out.update({f"{f}_{w}": d[:, j] for j, f in enumerate(FEATURES)})
    for extra in cfg.get("extra_descriptors") or []:
        out[extra] = np.asarray(descriptors_fn(heightmaps, names=(extra,), window=int(cfg["windows"][0]),
                                               stride=stride))[:, 0]
    out["traversable"] = np.asarray(traversable_fn(heightmaps)).astype(np.float32)
    out["fitness"] = np.asarray(fitness_fn(heightmaps, key))
    return out


def make_chunk(plans: list[Plan], cfg: dict, key, fitness_fn):
    """``(chunk, steps)``: the ``jaxterrain.runtime.driver`` chunk over the batches of ``cfg["batch"]`` terrains of every
    plan in turn, and their number. Step ``i`` measures its batch (terrains ``s .. s + batch`` of a generator, fitness
    key ``fold_in(fold_in(key, 2 * index + 1), s)``) into ``state[name][column][s:s + batch]``; its metrics are
    the batch's mean difficulty and traversable fraction."""
    import jax
    import numpy as np

    from jaxterrain import features

    batch = int(cfg["batch"])
    steps = [(p, s) for p in plans for s in range(0, p.n, batch)]
    render = {p.name: jax.jit(jax.vmap(p.gen.render_one)) for p in plans}
    descriptors_fn = jax.jit(features.descriptors, static_argnames=("names", "window", "stride"))
    traversable_fn = jax.jit(features.is_traversable)

    def chunk(state, a: int, b: int):
        state = jax.tree.map(np.array, state)  # host copies to write into
        difficulty, traversable = [], []
        for p, s in steps[a:b]:
            heightmaps = render[p.name](jax.tree.map(lambda x: x[s:s + batch], p.genomes))
            values = measure_batch(heightmaps, cfg, jax.random.fold_in(jax.random.fold_in(key, 2 * p.index + 1), s),
                                   fitness_fn, descriptors_fn, traversable_fn)
            for name, v in values.items():
                state[p.name][name][s:s + len(v)] = v
            common.say(f"  [{p.name}] {min(s + batch, p.n)}/{p.n} terrains measured")
            difficulty.append(1.0 - float(np.mean(values["fitness"])))
            traversable.append(float(np.mean(values["traversable"])))
        return state, {"difficulty": np.asarray(difficulty), "traversable": np.asarray(traversable)}

    return chunk, len(steps)


def measure_all(plans: list[Plan], cfg: dict, key, fitness_fn, folder: Path, resume: bool,
                time_limit: float | None, progress: bool | str = True) -> dict[str, dict] | None:
    """Measure every plan through ``jaxterrain.runtime.driver.run_chunks`` in ``folder`` (``resume``: from its checkpoint;
    ``time_limit`` minutes: stop after the batch in which they pass). Returns ``{generator: {column: [N]
    float64}}`` with ``difficulty``, or None when the time limit stopped the run first."""
    import numpy as np

    from jaxterrain.runtime import driver

    chunk, total = make_chunk(plans, cfg, key, fitness_fn)
    names = columns(cfg)
    state = {p.name: {c: np.zeros(p.n, np.float32) for c in names} for p in plans}
    start, history = 0, None
    restored = driver.restore(folder, like=state) if resume else None
    if restored is not None:
        state, start, history, _ = restored
        print(f"resumed after {start} of {total} batches", flush=True)
    from jaxterrain.runtime import estimates

    walks = cfg["fitness"] == "difficulty"
    estimates.announce("walks" if walks else "map-elites-slope",
                       f"{int(cfg['batch'])} terrains a batch{', ' + str(cfg['attempts']) + ' walks each' if walks else ''}")
    state, done, _ = driver.run_chunks(
        chunk, state, total=total, every=1, start=start, history=history, run_dir=folder, key_metric="difficulty",
        time_limit_s=None if time_limit is None else 60.0 * time_limit, desc="features", unit="batch", progress=progress,
        meta={"command": "features", "generators": [p.name for p in plans]})
    if done < total:
        return None
    results = {}
    for p in plans:
        values = {c: np.asarray(state[p.name][c]).astype(np.float64) for c in names}
        values["difficulty"] = 1.0 - values["fitness"]
        results[p.name] = values
    return results


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

    from jaxterrain.runtime.io import atomic_write_text

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


def write_values(results: dict, folder: Path) -> None:
    """``values_<generator>.csv``: one row per terrain, the columns of :func:`columns` and ``difficulty``."""
    from jaxterrain.runtime.io import atomic_write_text

    for name, values in results.items():
        cols = list(values)
        atomic_write_text(folder / f"values_{name}.csv",
                          _csv_text(cols, zip(*[[f"{v:.8g}" for v in values[c]] for c in cols])))


def write_correlations(results: dict, cfg: dict, folder: Path) -> None:
    """``correlations.csv`` (generator, feature_a, feature_b, r) of every feature at every window, the extra
    descriptors and difficulty; ``correlation_<generator>.png`` and ``correlations.png`` (all side by side)."""
    import matplotlib.pyplot as plt

    from jaxterrain.runtime.io import atomic_write_text

    names = ([f"{f}_{int(w)}" for f in FEATURES for w in cfg["windows"]] + list(cfg.get("extra_descriptors") or [])
             + ["difficulty"])
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


def write_ranges(results: dict, cfg: dict, folder: Path) -> None:
    """``ranges.json``: the [0.5, 99.5] percentiles of TRI, TPI and roughness at ``calibrate_window`` over the
    traversable terrains of every generator (the recipe of ``jaxterrain.qd.DEFAULT_RANGES``)."""
    import numpy as np

    from jaxterrain.runtime.io import atomic_write_text

    w = int(cfg["calibrate_window"])
    allv = np.concatenate([np.stack([values[f"{f}_{w}"] for f in FEATURES], -1)[values["traversable"] > 0]
                           for values in results.values()])
    ranges = {}
    for j, f in enumerate(FEATURES):
        lo, hi = np.percentile(allv[:, j], [0.5, 99.5])
        ranges[f] = {"p0.5": float(lo), "p99.5": float(hi), "n": int(allv.shape[0])}
    atomic_write_text(folder / "ranges.json", json.dumps(ranges, indent=2) + "\n")
    print(f"descriptor percentiles at window {w}: {ranges}", flush=True)


def main(args) -> int:
    import jax

    from jaxterrain.difficulty import named_fitness
    import matplotlib

    matplotlib.use("Agg")

    folder, cfg = common.setup_resumable_run("features", args, PRESETS, "smoke", overrides(args))
    key = jax.random.key(int(cfg["seed"]))
    plans = plan(cfg, key)
    if not plans:
        print("no generator available", flush=True)
        return 1
    fitness_fn = jax.jit(named_fitness(cfg["fitness"], int(cfg["attempts"]), int(cfg["best"]), int(cfg["size"])))
    results = measure_all(plans, cfg, key, fitness_fn, folder, args.resume is not None, args.time_limit,
                          common.progress_mode(args))
    if results is None:
        print(f"time limit reached; continue with: python -m experiments features --resume {folder}", flush=True)
        return 3
    write_values(results, folder)
    write_correlations(results, cfg, folder)
    figure4(results, cfg, folder)
    if cfg.get("calibrate"):
        write_ranges(results, cfg, folder)
    print(f"done -> {folder}", flush=True)
    return 0
