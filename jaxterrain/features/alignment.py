"""Experiment 1a (paper Figure 4): how well do terrain features align with difficulty?

For each generator, random genomes and chains of mutated ones (so that the terrains span easy to hard) are
rendered; TRI, TPI and roughness are measured at several windows, with any extra registered descriptor (e.g. the
learned ``traversability``), Algorithm 1 and a fitness function the caller gives (the walker's difficulty or a
cheap stand-in: this stage does not walk); then the Pearson correlations of all of them. :func:`feature_alignment`
runs it through ``jaxterrain.runtime.driver.run_chunks`` (one step per batch, checkpoints, a time limit, resume) and
writes the tables and figures; ``python -m experiments features`` is flags and files around it:

    >>> from jaxterrain.features import alignment
    >>> result = alignment.feature_alignment(alignment.AlignmentSettings(samples=6, size=48), slope, 0, "runs/f")
    >>> result.values["cppn"]["difficulty"]                # [N] per terrain; result.correlations: the CSV rows
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Any, Callable, NamedTuple, Optional

import jax
import numpy as np
from matplotlib.figure import Figure

from jaxterrain import generators
from jaxterrain.features.algorithm1 import is_traversable
from jaxterrain.features.registry import descriptors
from jaxterrain.runtime import driver, estimates
from jaxterrain.runtime.io import atomic_write_text, save_figure

__all__ = ["FEATURES", "AlignmentSettings", "AlignmentResult", "feature_alignment", "Plan", "generator_available",
           "terrain_set", "columns", "plan", "measure_batch", "make_chunk", "measure_all", "correlation_matrix",
           "plot_heatmap", "figure4", "write_values", "write_correlations", "write_ranges"]

FEATURES = ("tri", "tpi", "roughness")


class AlignmentSettings(NamedTuple):
    """What is measured. generators: names (``generators.get``; one that cannot render at ``size`` is skipped with
    a line). samples: random genomes per generator, each mutated ``mutation_steps`` times (``samples * (1 +
    mutation_steps)`` terrains). size: heightmap side. windows / stride: where TRI, TPI and roughness are measured
    (the extra descriptors at the first window). batch: terrains per driver step. extra_descriptors: registered
    names. calibrate / calibrate_window: also write ``ranges.json`` at that window. figure_window: Figure 4's
    window (0: no Figure 4). fitness_walks: walks per terrain of the fitness function (0: it does not walk; for the
    first-call note only)."""

    generators: tuple = ("cppn", "perlin")
    samples: int = 6
    mutation_steps: int = 1
    size: int = 48
    windows: tuple = (5, 10)
    stride: int = 2
    batch: int = 12
    extra_descriptors: tuple = ()
    calibrate: bool = False
    calibrate_window: int = 10
    figure_window: int = 10
    fitness_walks: int = 0


class AlignmentResult(NamedTuple):
    """What :func:`feature_alignment` returns: ``values`` (generator -> column -> [N] float64, ``difficulty`` = 1 -
    fitness included) and ``correlations`` (the rows of ``correlations.csv``: generator, feature_a, feature_b, r
    text); None instead when the time limit stopped the run (resumable)."""

    values: dict
    correlations: list


def generator_available(name: str, size: int) -> tuple[bool, str]:
    """Whether generator ``name`` can be built and render at ``size`` (e.g. the GAN needs weights), and why not."""
    try:
        gen = generators.get(name, size=size)
        gen.render(gen.sample(jax.random.key(0), 1))
        return True, ""
    except Exception as err:  # noqa: BLE001 - any failure means "skip this generator", reported to the user
        msg = str(err).splitlines()[0] if str(err) else ""
        return False, f"{type(err).__name__}: {msg[:100]}{'...' if len(msg) > 100 else ''}"


class Plan(NamedTuple):
    """One generator's terrains: its name, its index in ``settings.generators`` (which picks its keys), the
    generator, the genomes of :func:`terrain_set` and their count."""

    name: str
    index: int
    gen: Any
    genomes: Any
    n: int



def terrain_set(gen, key, samples: int, steps: int):
    """``samples * (steps + 1)`` genomes: random ones and ``steps`` generations of mutated descendants."""
    k_sample, k_mut = jax.random.split(key)
    g = gen.sample(k_sample, samples)
    out = [g]
    for s in range(steps):
        g = gen.mutate(jax.random.fold_in(k_mut, s), g)
        out.append(g)
    return jax.tree.map(lambda *xs: jax.numpy.concatenate(xs), *out)



def _windows(settings: AlignmentSettings) -> list[int]:
    """Every window measured, ascending: ``windows``, the calibration window (with ``calibrate``) and the figure's."""
    extra = [int(settings.calibrate_window)] if settings.calibrate else []
    extra += [int(settings.figure_window)] if settings.figure_window else []
    return sorted(set([int(w) for w in settings.windows] + extra))



def columns(settings: AlignmentSettings) -> list[str]:
    """The measured columns in their CSV order: ``<feature>_<window>`` for every window (ascending) and feature,
    the extra descriptors, ``traversable`` (Algorithm 1, 0 / 1) and ``fitness``; ``values_<generator>.csv`` adds
    ``difficulty`` = 1 - fitness."""
    return ([f"{f}_{w}" for w in _windows(settings) for f in FEATURES] + list(settings.extra_descriptors or [])
            + ["traversable", "fitness"])



def plan(settings: AlignmentSettings, key, say=print) -> list[Plan]:
    """The generators of ``settings`` that can render at ``settings.size`` (the others are skipped with a line saying
    why), each with its genomes from ``fold_in(key, 2 * index)``."""
    size, plans = int(settings.size), []
    for gi, name in enumerate(settings.generators):
        ok, why = generator_available(name, size)
        if not ok:
            say(f"[{name}] skipped: {why}")
            continue
        gen = generators.get(name, size=size)
        genomes = terrain_set(gen, jax.random.fold_in(key, 2 * gi), int(settings.samples), int(settings.mutation_steps))
        plans.append(Plan(name, gi, gen, genomes, int(jax.tree.leaves(genomes)[0].shape[0])))
    return plans



def measure_batch(heightmaps, settings: AlignmentSettings, key, fitness_fn, descriptors_fn, traversable_fn) -> dict[str, Any]:
    """The :func:`columns` of ``heightmaps`` [B, H, W] as float32 ``[B]`` arrays: TRI, TPI and roughness at every
    window (``descriptors_fn``: jitted ``features.descriptors``), the extra descriptors at the first window,
    Algorithm 1 (``traversable_fn``) and ``fitness_fn(heightmaps, key)``."""
    stride = int(settings.stride)
    out = {}
    for w in _windows(settings):
        d = np.asarray(descriptors_fn(heightmaps, names=FEATURES, window=w, stride=stride))
        out.update({f"{f}_{w}": d[:, j] for j, f in enumerate(FEATURES)})
    for extra in settings.extra_descriptors or []:
        out[extra] = np.asarray(descriptors_fn(heightmaps, names=(extra,), window=int(settings.windows[0]),
                                               stride=stride))[:, 0]
    out["traversable"] = np.asarray(traversable_fn(heightmaps)).astype(np.float32)
    out["fitness"] = np.asarray(fitness_fn(heightmaps, key))
    return out



def make_chunk(plans: list[Plan], settings: AlignmentSettings, key, fitness_fn, say=print):
    """``(chunk, steps)``: the ``jaxterrain.runtime.driver`` chunk over the batches of ``settings.batch`` terrains of every
    plan in turn, and their number. Step ``i`` measures its batch (terrains ``s .. s + batch`` of a generator, fitness
    key ``fold_in(fold_in(key, 2 * index + 1), s)``) into ``state[name][column][s:s + batch]``; its metrics are
    the batch's mean difficulty and traversable fraction."""
    batch = int(settings.batch)
    steps = [(p, s) for p in plans for s in range(0, p.n, batch)]
    render = {p.name: jax.jit(jax.vmap(p.gen.render_one)) for p in plans}
    descriptors_fn = jax.jit(descriptors, static_argnames=("names", "window", "stride"))
    traversable_fn = jax.jit(is_traversable)

    def chunk(state, a: int, b: int):
        state = jax.tree.map(np.array, state)  # host copies to write into
        difficulty, traversable = [], []
        for p, s in steps[a:b]:
            heightmaps = render[p.name](jax.tree.map(lambda x: x[s:s + batch], p.genomes))
            values = measure_batch(heightmaps, settings, jax.random.fold_in(jax.random.fold_in(key, 2 * p.index + 1), s),
                                   fitness_fn, descriptors_fn, traversable_fn)
            for name, v in values.items():
                state[p.name][name][s:s + len(v)] = v
            say(f"  [{p.name}] {min(s + batch, p.n)}/{p.n} terrains measured")
            difficulty.append(1.0 - float(np.mean(values["fitness"])))
            traversable.append(float(np.mean(values["traversable"])))
        return state, {"difficulty": np.asarray(difficulty), "traversable": np.asarray(traversable)}

    return chunk, len(steps)



def measure_all(plans: list[Plan], settings: AlignmentSettings, key, fitness_fn, folder: Path, resume: bool,
                time_limit_s: float | None, progress: bool | str = True, say=print) -> dict[str, dict] | None:
    """Measure every plan through ``jaxterrain.runtime.driver.run_chunks`` in ``folder`` (``resume``: from its checkpoint;
    ``time_limit_s`` seconds: stop after the batch in which they pass). Returns ``{generator: {column: [N]
    float64}}`` with ``difficulty``, or None when the time limit stopped the run first."""
    chunk, total = make_chunk(plans, settings, key, fitness_fn, say)
    names = columns(settings)
    state = {p.name: {c: np.zeros(p.n, np.float32) for c in names} for p in plans}
    start, history = 0, None
    restored = driver.restore(folder, like=state) if resume else None
    if restored is not None:
        state, start, history, _ = restored
        say(f"resumed after {start} of {total} batches")
    walks = settings.fitness_walks
    estimates.announce("walks" if walks else "map-elites-slope",
                       f"{int(settings.batch)} terrains a batch{', ' + str(walks) + ' walks each' if walks else ''}")
    state, done, _ = driver.run_chunks(
        chunk, state, total=total, every=1, start=start, history=history, run_dir=folder, key_metric="difficulty",
        time_limit_s=time_limit_s, desc="features", unit="batch", progress=progress,
        meta={"command": "features", "generators": [p.name for p in plans]})
    if done < total:
        return None
    results = {}
    for p in plans:
        values = {c: np.asarray(state[p.name][c]).astype(np.float64) for c in names}
        values["difficulty"] = 1.0 - values["fitness"]
        results[p.name] = values
    return results



def correlation_matrix(values: dict, names: list[str]):
    """Pearson correlation matrix ``[len(names), len(names)]`` (NaN where a column is constant)."""
    x = np.stack([values[n] for n in names])
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.corrcoef(x)



def plot_heatmap(ax, r, names, title):
    """Draw the correlation matrix ``r`` [D, D] of ``names`` on ``ax`` (values written in the cells up to 17 names)."""
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



def figure4(results: dict, settings: AlignmentSettings, folder: Path, say=print) -> list[str]:
    """Figure 4: per generator, the Pearson correlations among TRI, TPI, roughness (at ``figure_window``), the
    extra descriptors and difficulty: ``figure4.png`` (one heatmap per generator) and ``figure4.csv``. Returns the
    feature names (empty when the window was not measured, e.g. a run from an older config)."""
    w = settings.figure_window
    names = [f"{f}_{w}" for f in FEATURES] + list(settings.extra_descriptors or []) + ["difficulty"]
    if not w or not all(n in v for v in results.values() for n in names):
        return []
    fig = Figure(figsize=(4.4 * len(results) + 1, 4.4), layout="constrained")
    axes = fig.subplots(1, len(results), squeeze=False)
    rows = []
    for ax, (gname, values) in zip(axes[0], results.items()):
        r = correlation_matrix(values, names)
        rows += [(gname, a, b, f"{r[i, j]:.6f}") for i, a in enumerate(names) for j, b in enumerate(names)]
        img = plot_heatmap(ax, r, names, f"{gname} (n = {len(values['difficulty'])})")
        for t in ax.texts:
            t.set_fontsize(7)
        order = sorted(zip(abs(r[-1, :-1]), names[:-1]))
        say(f"[{gname}] Figure 4 |r| with difficulty, weakest first: "
            + ", ".join(f"{n} {a:.3f}" for a, n in order))
    fig.colorbar(img, ax=axes[0].tolist(), shrink=0.8, label="Pearson r")
    save_figure(fig, folder / "figure4.png", dpi=150)
    atomic_write_text(folder / "figure4.csv", _csv_text(["generator", "feature_a", "feature_b", "r"], rows))
    return names



def _csv_text(header, rows) -> str:
    """``rows`` under ``header`` as CSV text."""
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(header)
    w.writerows(rows)
    return buf.getvalue()



def write_values(results: dict, folder: Path) -> None:
    """``values_<generator>.csv``: one row per terrain, the columns of :func:`columns` and ``difficulty``."""
    for name, values in results.items():
        cols = list(values)
        atomic_write_text(folder / f"values_{name}.csv",
                          _csv_text(cols, zip(*[[f"{v:.8g}" for v in values[c]] for c in cols])))



def write_correlations(results: dict, settings: AlignmentSettings, folder: Path, say=print) -> list:
    """``correlations.csv`` (generator, feature_a, feature_b, r) of every feature at every window, the extra
    descriptors and difficulty; ``correlation_<generator>.png`` and ``correlations.png`` (all side by side). Returns
    the rows."""
    names = ([f"{f}_{int(w)}" for f in FEATURES for w in settings.windows] + list(settings.extra_descriptors or [])
             + ["difficulty"])
    rows = []
    fig = Figure(figsize=(6.5 * len(results), 6))
    axes = fig.subplots(1, len(results), squeeze=False)
    for ax, (gname, values) in zip(axes[0], results.items()):
        r = correlation_matrix(values, names)
        rows += [(gname, a, b, f"{r[i, j]:.6f}") for i, a in enumerate(names) for j, b in enumerate(names)]
        img = plot_heatmap(ax, r, names, f"{gname} (n = {len(values['difficulty'])})")
        one = Figure(figsize=(6.5, 6))
        ax1 = one.subplots()
        one.colorbar(plot_heatmap(ax1, r, names, f"Pearson r, {gname}"), ax=ax1)
        one.tight_layout()
        save_figure(one, folder / f"correlation_{gname}.png", dpi=150)
        best = max((abs(r[i, -1]), names[i]) for i in range(len(names) - 1) if r[i, -1] == r[i, -1])
        say(f"[{gname}] strongest |r| with difficulty: {best[1]} ({best[0]:.3f})")
    fig.colorbar(img, ax=axes[0].tolist(), shrink=0.8)
    save_figure(fig, folder / "correlations.png", dpi=150)
    atomic_write_text(folder / "correlations.csv", _csv_text(["generator", "feature_a", "feature_b", "r"], rows))
    return rows



def write_ranges(results: dict, settings: AlignmentSettings, folder: Path, say=print) -> None:
    """``ranges.json``: the [0.5, 99.5] percentiles of TRI, TPI and roughness at ``calibrate_window`` over the
    traversable terrains of every generator (the recipe of ``jaxterrain.qd.DEFAULT_RANGES``)."""
    w = int(settings.calibrate_window)
    allv = np.concatenate([np.stack([values[f"{f}_{w}"] for f in FEATURES], -1)[values["traversable"] > 0]
                           for values in results.values()])
    ranges = {}
    for j, f in enumerate(FEATURES):
        lo, hi = np.percentile(allv[:, j], [0.5, 99.5])
        ranges[f] = {"p0.5": float(lo), "p99.5": float(hi), "n": int(allv.shape[0])}
    atomic_write_text(folder / "ranges.json", json.dumps(ranges, indent=2) + "\n")
    say(f"descriptor percentiles at window {w}: {ranges}")



def feature_alignment(settings: AlignmentSettings, fitness_fn: Callable, seed: int, folder, *, resume: bool = False,
                      time_limit_s: Optional[float] = None, progress: bool | str = True,
                      say: Callable[[str], None] = print) -> Optional[AlignmentResult]:
    """Measure every generator of ``settings`` into ``folder`` (``checkpoint.npz`` after every batch, ``metrics.csv``;
    ``resume``: from its checkpoint; ``time_limit_s``: stop after the batch in which it passes, returning None) and
    write ``values_<generator>.csv``, ``correlations.csv`` / ``.png``, ``correlation_<generator>.png``,
    ``figure4.png`` / ``.csv`` and with ``calibrate`` ``ranges.json``. ``fitness_fn(heightmaps [B, H, W], key) ->
    [B]`` in [0, 1] (e.g. jitted ``difficulty.named_fitness``). Raises ``ValueError`` when no generator renders."""
    folder = Path(folder)
    key = jax.random.key(int(seed))
    plans = plan(settings, key, say)
    if not plans:
        raise ValueError(f"no generator of {list(settings.generators)} renders at size {settings.size}")
    results = measure_all(plans, settings, key, fitness_fn, folder, resume, time_limit_s, progress, say)
    if results is None:
        return None
    write_values(results, folder)
    rows = write_correlations(results, settings, folder, say)
    figure4(results, settings, folder, say)
    if settings.calibrate:
        write_ranges(results, settings, folder, say)
    return AlignmentResult(results, rows)
