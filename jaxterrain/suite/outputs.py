"""An evaluation's files: ``fitness.csv`` (one row per policy and terrain), ``levels.csv`` (the highest level of each
family a policy passes with every level below it passed, and its mean fitness per level), ``robustness.csv`` (each
generator's samples: mean fitness and CVaR at 10 %, the worst decile; written when the suite has generator samples),
``summary.md``,
``levels.png`` (policies x families, coloured by the share of the family's levels passed) and ``suite.png`` (what the
families look like), all written atomically; and :func:`read_fitness`, which reads ``fitness.csv`` (or a gzipped
``fitness.csv.gz``) back.

The CSVs name each policy as given (a folder's whole path); ``summary.md`` and ``levels.png`` label it with
:func:`short_names` (its path relative to the folders' common parent, ``RUN/policies/trial_K`` as ``RUN/trial_K``)
and ``summary.md`` lists what each label stands for. Families the suite dropped at its size (``Suite.dropped``) and
generators it left out (``Suite.missing``) are named, with the reason, in ``summary.md`` and under the figure's
title."""

from __future__ import annotations

import csv
import gzip
import io
import textwrap
from pathlib import Path, PurePath
from typing import NamedTuple, Sequence

import numpy as np
from matplotlib.figure import Figure

from jaxterrain.runtime.io import atomic_write_csv, atomic_write_text, save_figure
from jaxterrain.suite.evaluation import CVAR_ALPHA, THRESHOLD, generator_robustness, level_fitness, passed_levels
from jaxterrain.suite.heldout import Suite

__all__ = ["Evaluation", "read_fitness", "write_evaluation", "level_table", "plot_levels", "plot_suite", "short_names"]


def level_table(names: Sequence[str], suite: Suite, fitness: np.ndarray, threshold: float = THRESHOLD) -> list:
    """``(policy, family, highest level passed, mean fitness, [mean fitness per level])`` per policy and family; the
    highest level passed is :func:`~jaxterrain.suite.evaluation.passed_levels`' (every level below it passed too)."""
    rows = []
    for name, f in zip(names, fitness):
        per = level_fitness(f, suite)
        passed = passed_levels(f, suite, threshold)
        for fam in suite.families():
            rows.append((name, fam, passed[fam], float(np.mean(f[suite.family == fam])), per[fam]))
    return rows


def short_names(names: Sequence[str]) -> list[str]:
    """Short, unique labels for policy names (rows of a table or figure), in order: a name that is a path of more
    than one part (a policy folder) becomes its path relative to the common parent of all such names, with a
    ``policies`` part left out where the labels stay unique (``/r/runs/cppn/policies/trial_0`` and
    ``/r/runs/perlin/policies/trial_0`` -> ``cppn/trial_0``, ``perlin/trial_0``; a single folder -> its last part);
    other names (``base``) are kept. A label that would repeat another keeps its whole name; a name given twice is
    numbered (``#2``)."""
    names = [str(n) for n in names]
    parts = [PurePath(n).parts for n in names]
    paths = [p for p in parts if len(p) > 1]
    common = 0
    if paths:
        limit = min(len(p) for p in paths) - 1  # every label keeps at least its last part
        while common < limit and all(p[common] == paths[0][common] for p in paths):
            common += 1
    rel = ["/".join(p[common:]) if len(p) > 1 else n for n, p in zip(names, parts)]
    bare = ["/".join(x for x in p[common:] if x != "policies") if len(p) > 1 else n for n, p in zip(names, parts)]
    labels = bare if len(set(bare)) == len(bare) else rel
    counts = {x: labels.count(x) for x in labels}
    labels = [n if counts[x] > 1 else x for n, x in zip(names, labels)]  # collisions: the whole name
    seen: dict[str, int] = {}
    out = []
    for x in labels:
        seen[x] = seen.get(x, 0) + 1
        out.append(x if seen[x] == 1 else f"{x} #{seen[x]}")
    return out


def _fill(text: str, width_in: float, fontsize: float) -> str:
    """``text`` wrapped, line by line, to about ``width_in`` inches of ``fontsize``-point characters."""
    chars = max(20, int(width_in * 72 / (0.6 * fontsize)))
    return "\n".join(textwrap.fill(line, chars, break_on_hyphens=False) for line in text.splitlines())


def plot_levels(ax, names: Sequence[str], families: Sequence[str], passed: np.ndarray, title: str = "",
                levels: Sequence[int] | None = None) -> None:
    """``passed`` [P, F] int (-1: none) as a grid: rows the policies (``names``), columns the families, labelled by
    the highest level passed and coloured by the share of the family's levels passed, ``(passed + 1) / levels``
    (``levels`` [F]: each family's number of levels, default 10): a family of one level (``flat``) passed is the
    top colour, none passed the bottom one in every family. ``title`` is wrapped to the figure's width; the figure
    lays out best with ``layout="constrained"``."""
    passed = np.asarray(passed, np.int64).reshape(len(names), len(families))
    n = np.full(len(families), 10) if levels is None else np.asarray(levels, np.int64)
    share = np.clip((passed + 1) / np.maximum(n, 1)[None, :], 0.0, 1.0)
    im = ax.imshow(share, cmap="viridis", vmin=0.0, vmax=1.0, aspect="auto")
    for (i, j), v in np.ndenumerate(passed):
        ax.text(j, i, "-" if v < 0 else str(v), ha="center", va="center", fontsize=7,
                color="white" if share[i, j] < 0.6 else "black")
    ax.set_xticks(range(len(families)), families, rotation=60, ha="right", rotation_mode="anchor", fontsize=7)
    ax.set_yticks(range(len(names)), [n if len(n) < 40 else "..." + n[-37:] for n in names], fontsize=7)
    width = ax.figure.get_size_inches()[0]
    ax.set_title(_fill(title, 0.9 * width, 9), fontsize=9)
    bar = ax.figure.colorbar(im, ax=ax, ticks=[0.0, 0.5, 1.0], fraction=0.05, pad=0.02)
    bar.ax.set_yticklabels(["none", "half", "all"], fontsize=7)
    bar.set_label("share of the family's levels passed\n(level 0 up to the highest)", fontsize=7, labelpad=6)


def _levels_figure(labels: Sequence[str], families: Sequence[str], passed: np.ndarray, title: str,
                   levels: Sequence[int]) -> Figure:
    """``levels.png``'s figure: :func:`plot_levels` on a constrained layout sized to the rows, columns and labels."""
    width = max(6.0, 3.5 + 0.5 * len(families) + 0.06 * max(map(len, labels)))
    fig = Figure(figsize=(width, 2.2 + 0.3 * len(labels) + 0.15 * title.count("\n")), layout="constrained")
    plot_levels(fig.subplots(), labels, families, passed, title, levels)
    return fig


def plot_suite(suite: Suite, levels: Sequence[int] = (0, 4, 9)) -> Figure:
    """A figure of every family: its seed-0 terrain at each of ``levels`` (the nearest it has), heights in metres."""
    fams = suite.families()
    fig = Figure(figsize=(1.6 * len(levels), 1.5 * len(fams)))
    axes = fig.subplots(len(fams), len(levels), squeeze=False)
    for r, fam in enumerate(fams):
        rows = np.flatnonzero(suite.family == fam)
        for c, lv in enumerate(levels):
            ax = axes[r, c]
            ax.set_xticks([]), ax.set_yticks([])
            have = np.unique(suite.level[rows])
            k = int(have[np.argmin(np.abs(have - lv))])
            i = rows[(suite.level[rows] == k) & (suite.seed[rows] == suite.seed[rows][suite.level[rows] == k].min())][0]
            ax.imshow(suite.heightmaps[i] * suite.scale.height, cmap="terrain", vmin=0.0, vmax=suite.scale.height,
                      origin="lower")
            unit = suite.unit[fam]
            ax.set_title(f"{fam} L{k}\n{suite.value[i]:.3g} {unit}" if unit != "-" else fam, fontsize=6)
    fig.tight_layout()
    return fig


def write_evaluation(folder: Path, names: Sequence[str], suite: Suite, fitness: np.ndarray,
                     threshold: float = THRESHOLD, suite_figure: bool = True) -> dict:
    """Write the evaluation of ``names`` (one per row of ``fitness`` [P, N]) on ``suite`` into ``folder``; returns
    ``{policy: {family: highest level passed}}`` (every level below it passed too; -1: level 0 fails).
    ``suite_figure=False`` leaves out ``suite.png`` (the terrains, the same for every evaluation of a suite)."""
    folder = Path(folder)
    fitness = np.asarray(fitness, np.float64)
    if fitness.shape != (len(names), suite.size):
        raise ValueError(f"fitness must have shape [P, N] = ({len(names)}, {suite.size}) (a row per name, a column per "
                         f"terrain); got {fitness.shape}")
    rows = [(n, fam, lv, s, f"{v:.4g}", unit, f"{f:.4f}")
            for n, fit in zip(names, fitness) for (fam, lv, s, v, unit), f in zip(suite.rows(), fit)]
    atomic_write_csv(folder / "fitness.csv", ["policy", "family", "level", "seed", "value", "unit", "fitness"], rows)
    table = level_table(names, suite, fitness, threshold)
    atomic_write_csv(folder / "levels.csv", ["policy", "family", "highest_level_passed", "mean_fitness", "per_level_fitness"],
         [(n, fam, lv, f"{m:.4f}", " ".join("nan" if np.isnan(x) else f"{x:.3f}" for x in per))
          for n, fam, lv, m, per in table])
    fams = suite.families()
    passed = np.array([[lv for n2, f2, lv, _, _ in table if n2 == n and f2 == fam] for n in names for fam in fams],
                      np.int64).reshape(len(names), len(fams))
    means = {(n, fam): m for n, fam, _, m, _ in table}
    labels = short_names(names)
    head = "| policy | " + " | ".join(fams) + " | mean |\n|---|" + "---|" * (len(fams) + 1) + "\n"
    body = "".join(f"| {label} | " + " | ".join(f"{'-' if passed[i, j] < 0 else passed[i, j]} ({means[(n, fam)]:.2f})"
                                                for j, fam in enumerate(fams))
                   + f" | {fitness[i].mean():.3f} |\n" for i, (n, label) in enumerate(zip(names, labels)))
    text = (f"# Held-out evaluation: {suite.name}\n\n{suite.size} terrains; each cell: the highest level passed with "
            f"every level below it passed too (a level passes when the mean fitness of its terrains is >= "
            f"{threshold}; - for none: level 0 fails) and, in brackets, the family's mean fitness.\n\n" + head + body)
    renamed = [(label, n) for n, label in zip(names, labels) if label != n]
    if renamed:
        text += "\nPolicies:\n\n" + "".join(f"- `{label}`: `{n}`\n" for label, n in renamed)
    side = int(suite.heightmaps.shape[-1])
    if suite.dropped:
        text += (f"\nDropped at {side} x {side} pixels, not walked (the family's features do not fit the map):\n\n"
                 + "".join(f"- {f}: {why}\n" for f, why in suite.dropped.items()))
    robust = {n: generator_robustness(f, suite.family) for n, f in zip(names, fitness)}
    gens = list(dict.fromkeys(g for r in robust.values() for g in r))
    if gens:
        atomic_write_csv(folder / "robustness.csv", ["policy", "generator", "samples", "mean", "cvar10"],
                         [(n, g, r[g]["samples"], f"{r[g]['mean']:.4f}", f"{r[g]['cvar']:.4f}")
                          for n, r in robust.items() for g in r])
        text += (f"\nGenerator samples: mean fitness / CVaR at {CVAR_ALPHA:g} (the mean of the worst "
                 f"{CVAR_ALPHA:.0%} of each generator's samples in this suite; samples: "
                 + ", ".join(f"{g} {robust[names[0]][g]['samples']}" for g in gens) + ")\n\n"
                 + "| policy | " + " | ".join(gens) + " |\n|---|" + "---|" * len(gens) + "\n"
                 + "".join(f"| {label} | " + " | ".join(f"{robust[n][g]['mean']:.3f} / {robust[n][g]['cvar']:.3f}"
                                                      for g in gens) + " |\n"
                           for n, label in zip(names, labels)))
    if suite.missing:
        text += "\nLeft out: " + "; ".join(f"{g} ({why})" for g, why in suite.missing.items()) + "\n"
    atomic_write_text(folder / "summary.md", text)
    title = f"{suite.name}\nhighest level passed with every level below it (mean fitness >= {threshold})"
    if suite.dropped:
        title += f"\ndropped at {side} pixels (too small for them): {', '.join(suite.dropped)}"
    levels = [int(suite.level[suite.family == fam].max()) + 1 for fam in fams]
    save_figure(_levels_figure(labels, fams, passed, title, levels), folder / "levels.png")
    if suite_figure:
        save_figure(plot_suite(suite), folder / "suite.png", dpi=90)
    return {n: dict(zip(fams, map(int, passed[i]))) for i, n in enumerate(names)}


class Evaluation(NamedTuple):
    """An evaluation read back from ``fitness.csv``: ``policies`` [P] names, ``family`` / ``level`` / ``seed`` [N]
    (the suite's terrains in order) and ``fitness`` [P, N] float64."""

    policies: list
    family: np.ndarray
    level: np.ndarray
    seed: np.ndarray
    fitness: np.ndarray


def read_fitness(path) -> Evaluation:
    """Read ``fitness.csv`` as :func:`write_evaluation` writes it (``path`` may end in ``.gz``); ValueError naming
    the file when the policies do not cover the same terrains in the same order, or naming the file and the row
    (its line) for a missing column or a value that is not a number (a fitness: finite, in [0, 1])."""
    path = Path(path)
    raw = path.read_bytes()
    try:
        text = (gzip.decompress(raw) if path.suffix == ".gz" else raw).decode()
    except (OSError, EOFError, UnicodeDecodeError) as err:
        raise ValueError(f"{path}: not a readable fitness.csv ({type(err).__name__}: {err})") from None
    reader = csv.DictReader(io.StringIO(text))
    missing = [c for c in ("policy", "family", "level", "seed", "fitness") if c not in (reader.fieldnames or [])]
    if missing:
        raise ValueError(f"{path}: not an evaluation's fitness.csv (no column {', '.join(missing)})")
    rows = []
    for line, r in enumerate(reader, start=2):  # line 1: the header
        try:
            level, seed, fitness = int(r["level"]), int(r["seed"]), float(r["fitness"])
        except (TypeError, ValueError):
            raise ValueError(f"{path}, line {line}: level and seed must be integers and fitness a number; got "
                             f"level={r['level']!r}, seed={r['seed']!r}, fitness={r['fitness']!r}") from None
        if not 0.0 <= fitness <= 1.0:  # also NaN
            raise ValueError(f"{path}, line {line}: fitness must be a finite number in [0, 1]; got {r['fitness']!r}")
        rows.append((r["policy"], (r["family"], level, seed), fitness))
    names = list(dict.fromkeys(r[0] for r in rows))
    per = {n: [r for r in rows if r[0] == n] for n in names}
    first = [r[1] for r in per[names[0]]] if names else []
    if not names or any([r[1] for r in per[n]] != first for n in names):
        raise ValueError(f"{path}: not an evaluation's fitness.csv (every policy on the same terrains, in order)")
    return Evaluation(names, np.array([t[0] for t in first]), np.array([t[1] for t in first], np.int64),
                      np.array([t[2] for t in first], np.int64),
                      np.array([[r[2] for r in per[n]] for n in names], np.float64))
