"""An evaluation's files: ``fitness.csv`` (one row per policy and terrain), ``levels.csv`` (the highest level of each
family a policy passes, and its mean fitness per level), ``summary.md``, ``levels.png`` (policies x families,
coloured by the highest level passed) and ``suite.png`` (what the families look like), all written atomically; and
:func:`read_fitness`, which reads ``fitness.csv`` (or a gzipped ``fitness.csv.gz``) back."""

from __future__ import annotations

import csv
import gzip
import io
from pathlib import Path
from typing import NamedTuple, Sequence

import numpy as np
from matplotlib.figure import Figure

from jaxterrain.runtime.io import atomic_write_csv, atomic_write_text, save_figure
from jaxterrain.suite.evaluation import THRESHOLD, level_fitness, passed_levels
from jaxterrain.suite.heldout import Suite

__all__ = ["Evaluation", "read_fitness", "write_evaluation", "level_table", "plot_levels", "plot_suite"]


def level_table(names: Sequence[str], suite: Suite, fitness: np.ndarray, threshold: float = THRESHOLD) -> list:
    """``(policy, family, highest level passed, mean fitness, [mean fitness per level])`` per policy and family."""
    rows = []
    for name, f in zip(names, fitness):
        per = level_fitness(f, suite)
        passed = passed_levels(f, suite, threshold)
        for fam in suite.families():
            rows.append((name, fam, passed[fam], float(np.mean(f[suite.family == fam])), per[fam]))
    return rows


def plot_levels(ax, names: Sequence[str], families: Sequence[str], passed: np.ndarray, title: str = "") -> None:
    """``passed`` [P, F] int (-1: none) as a grid: rows the policies, columns the families, coloured and labelled by
    the highest level passed."""
    im = ax.imshow(passed, cmap="viridis", vmin=-1, vmax=9, aspect="auto")
    for (i, j), v in np.ndenumerate(passed):
        ax.text(j, i, "-" if v < 0 else str(v), ha="center", va="center", fontsize=7,
                color="white" if v < 4 else "black")
    ax.set_xticks(range(len(families)), families, rotation=60, ha="right", fontsize=7)
    ax.set_yticks(range(len(names)), [n if len(n) < 40 else "..." + n[-37:] for n in names], fontsize=7)
    ax.set_title(title, fontsize=9)
    ax.figure.colorbar(im, ax=ax, label="highest level passed")


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
                     threshold: float = THRESHOLD) -> dict:
    """Write the evaluation of ``names`` (one per row of ``fitness`` [P, N]) on ``suite`` into ``folder``; returns
    ``{policy: {family: highest level passed}}``."""
    folder = Path(folder)
    fitness = np.asarray(fitness, np.float64)
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
    head = "| policy | " + " | ".join(fams) + " | mean |\n|---|" + "---|" * (len(fams) + 1) + "\n"
    body = "".join(f"| {n} | " + " | ".join(f"{'-' if passed[i, j] < 0 else passed[i, j]} ({means[(n, fam)]:.2f})"
                                            for j, fam in enumerate(fams))
                   + f" | {fitness[i].mean():.3f} |\n" for i, n in enumerate(names))
    text = (f"# Held-out evaluation: {suite.name}\n\n{suite.size} terrains; each cell: the highest level passed "
            f"(mean fitness of its terrains >= {threshold}; - for none) and, in brackets, the family's mean "
            f"fitness.\n\n" + head + body)
    if suite.missing:
        text += "\nLeft out: " + "; ".join(f"{g} ({why})" for g, why in suite.missing.items()) + "\n"
    atomic_write_text(folder / "summary.md", text)
    fig = Figure(figsize=(max(6.0, 3.0 + 0.55 * len(fams)), 1.6 + 0.35 * len(names)))
    plot_levels(fig.subplots(), names, fams, passed, f"{suite.name}: highest level at mean fitness >= {threshold}")
    fig.tight_layout()
    save_figure(fig, folder / "levels.png")
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
