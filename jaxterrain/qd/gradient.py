"""The difficulty gradient of MAP-Elites archives: does fitness fall with the distance from cell (0, 0)?

The map-based curriculum of Experiment 2 climbs an archive from cell (0, 0) outwards, so it needs fitness to FALL
with the distance from that cell (the paper's Figure 6). :func:`gradient` measures, over every archive's filled
cells, fitness against the cell's distance from cell (0, 0) (Pearson and Spearman correlations, a scatter figure)
and the share of filled cells with fitness >= ``threshold`` (0.9, the curriculum's "already easy") in bands of
``band_width`` (10) cells of distance (:func:`band_table`).

Distance: ``"corner"`` is :func:`jaxterrain.qd.cell_distance`, from the grid's origin corner to the cell's far
corner (the curriculum's and Table 2's measure, 1.41 to 70.71 on 50 x 50); ``"index"`` is ``hypot(b0, b1)``, between
the cells' indices (0 to 69.3), the measure issue 13 quoted its band shares in.

With a ``protocol`` every elite (or a ``sample`` of them, spread over distance) is re-rendered and walked again
under it in one batched call (``difficulty.timed_distances``), and the tables show the protocols side by side.
``python -m experiments gradient`` is flags and files around :func:`gradient`:

    >>> from jaxterrain.qd import gradient
    >>> result = gradient.gradient(["docs/results/exp1b_gpu_sound_perlin_archive.npz"], "runs/gradient")
    >>> [r["spearman"] for r in result.summary]
"""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Callable, NamedTuple, Optional, Sequence

import jax
import numpy as np

from jaxterrain import difficulty
from jaxterrain.qd.archive import reseat
from jaxterrain.qd.archive_io import load, save
from jaxterrain.qd.bank import from_archive
from jaxterrain.qd.grid import cell_bins, cell_distance
from jaxterrain.runtime import estimates
from jaxterrain.runtime.io import atomic_write_bytes, atomic_write_text, save_figure
from jaxterrain.terrain import TerrainScale
from jaxterrain.walker import WalkerConfig

__all__ = ["DISTANCES", "GradientSettings", "GradientResult", "gradient", "distance_from_origin", "band_table",
           "correlations", "spread_sample", "grid_bands", "load_elites", "walk_archive", "protocol_label",
           "series_of", "table_rows", "write_csv", "markdown", "plot", "save_walks", "write_reseated"]

DISTANCES = ("corner", "index")


class GradientSettings(NamedTuple):
    """How the tables are cut: ``band_width`` (cells of distance per band, > 0), ``threshold`` (fitness counted as
    easy, in (0, 1]), ``distance`` (the measure of the correlations and the main table: one of :data:`DISTANCES`)."""

    band_width: float = 10.0
    threshold: float = 0.9
    distance: str = "corner"


class GradientResult(NamedTuple):
    """What :func:`gradient` returns: ``bands`` (the rows of ``gradient.csv``: archive, series, distance measure,
    band), ``summary`` (the rows of ``gradient_summary.csv``: correlations, shares, cost per archive and series),
    ``walks`` (archive name -> :func:`walk_archive`'s dict, for the archives walked) and ``reseated`` (archive name
    -> ``qd.reseat``'s counts)."""

    bands: list
    summary: list
    walks: dict
    reseated: dict


def distance_from_origin(bins_: np.ndarray, measure: str = "corner") -> np.ndarray:
    """``[N, 2]`` bins -> ``[N]`` float32 distance from cell (0, 0): ``"corner"`` = ``bank.cell_distance`` (to the
    cell's far corner), ``"index"`` = ``hypot(b0, b1)``."""
    if measure == "corner":
        return cell_distance(bins_)
    if measure == "index":
        b = np.asarray(bins_, np.float32)
        return np.hypot(b[..., 0], b[..., 1]).astype(np.float32)
    raise ValueError(f"distance must be one of {DISTANCES}, got {measure!r}")



def band_table(distance: np.ndarray, fitness: np.ndarray, width: float = 10.0, threshold: float = 0.9,
               bands: int | None = None) -> dict[str, np.ndarray]:
    """Share of cells with ``fitness >= threshold`` per band of distance.

    ``distance`` [N] and ``fitness`` [N] (filled cells only; NaN fitness counts as below the threshold). Band ``k``
    holds ``k * width <= distance < (k + 1) * width``; there are ``bands`` of them (default: up to the largest
    distance). Returns ``{"lo", "hi"}`` [K] float band edges, ``"filled"`` [K] int cells, ``"share"`` [K] float
    fraction at or above ``threshold`` (NaN for an empty band) and ``"mean"`` [K] mean fitness (NaN if empty).
    """
    d = np.asarray(distance, np.float64).reshape(-1)
    f = np.asarray(fitness, np.float64).reshape(-1)
    if d.shape != f.shape:
        raise ValueError(f"distance and fitness must have the same length, got {d.shape[0]} and {f.shape[0]}")
    if not width > 0:
        raise ValueError(f"width must be > 0 (cells), got {width}")
    if not 0 < threshold <= 1:
        raise ValueError(f"threshold must lie in (0, 1], got {threshold}")
    if np.any(~np.isfinite(d)) or np.any(d < 0):
        raise ValueError("distance must be finite and >= 0")
    k = np.floor(d / width).astype(np.int64)
    n = int(k.max()) + 1 if bands is None and k.size else int(bands or 0)
    if bands is not None and (not isinstance(bands, int) or bands < 1):
        raise ValueError(f"bands must be an int >= 1 or None, got {bands!r}")
    inside = k < n
    filled = np.bincount(k[inside], minlength=n)
    easy = np.bincount(k[inside], weights=(np.nan_to_num(f, nan=-np.inf) >= threshold)[inside], minlength=n)
    total = np.bincount(k[inside], weights=np.nan_to_num(f, nan=0.0)[inside], minlength=n)
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(filled > 0, easy / np.maximum(filled, 1), np.nan)
        mean = np.where(filled > 0, total / np.maximum(filled, 1), np.nan)
    lo = np.arange(n, dtype=np.float64) * width
    return {"lo": lo, "hi": lo + width, "filled": filled.astype(np.int64), "share": share, "mean": mean}



def correlations(distance: np.ndarray, fitness: np.ndarray) -> tuple[float, float]:
    """``(pearson, spearman)`` of ``fitness`` against ``distance`` ([N] each; scipy.stats, ties at their average
    rank); NaN when N < 3 or one is constant."""
    from scipy import stats

    d, f = np.asarray(distance, np.float64), np.asarray(fitness, np.float64)
    if d.size < 3 or np.ptp(d) == 0 or np.ptp(f) == 0:
        return float("nan"), float("nan")
    return float(stats.pearsonr(d, f)[0]), float(stats.spearmanr(d, f)[0])



def spread_sample(distance: np.ndarray, n: int | None) -> np.ndarray:
    """Indices of ``n`` elites evenly spread over sorted ``distance`` [N] (all of them when ``n`` is None or >= N),
    in increasing index order."""
    size = np.asarray(distance).shape[0]
    if n is None or n >= size:
        return np.arange(size)
    if n < 1:
        raise ValueError(f"sample must be >= 1, got {n}")
    order = np.argsort(distance, kind="stable")
    return np.sort(order[np.unique(np.round(np.linspace(0, size - 1, n)).astype(np.int64))])



def grid_bands(elites: dict, measure: str, width: float) -> int:
    """Bands of ``width`` up to the grid's farthest cell (bins - 1, bins - 1), so every archive of one grid size has
    the same columns."""
    far = np.full((1, 2), int(elites["archive"].config.bins) - 1)
    return int(np.floor(distance_from_origin(far, measure)[0] / width)) + 1



def load_elites(path) -> dict:
    """The filled cells of an archive: ``{"archive", "name", "cells" [N], "bins" [N, 2], "fitness" [N]}``; a
    ``ValueError`` naming the file when it is not a readable archive or has no elite."""
    try:
        arch = load(path)
    except (OSError, ValueError) as err:
        raise ValueError(f"archive {path}: cannot read it: {str(err).splitlines()[0]}") from None
    cells = np.flatnonzero(np.asarray(arch.source) >= 0)
    if cells.size == 0:
        raise ValueError(f"archive {path} has no filled cell")
    return {"archive": arch, "name": Path(path).name.removesuffix(".npz"), "cells": cells,
            "bins": cell_bins(cells, int(arch.config.bins)), "fitness": np.asarray(arch.fitness, np.float32)[cells]}



def walk_archive(elites: dict, protocol, key, slots, chunk, sample) -> dict:
    """Render (``qd.from_archive``) and walk the elites of ``sample`` (:func:`spread_sample` by corner distance)
    under ``protocol``. Returns the ``difficulty.timed_distances`` dict plus ``"rows"`` [n] (indices into the filled cells),
    ``"fitness"`` [n] (the protocol's) and ``"heading0"`` [n] (heading 0's score alone)."""
    rows = spread_sample(distance_from_origin(elites["bins"]), sample)
    b = from_archive(elites["archive"])
    maps = np.asarray(b.heightmaps)[rows] / np.float32(1.0 * float(TerrainScale().height))
    estimates.announce("walks", f"{len(rows)} elites, {protocol.attempts} walks each")
    out = difficulty.timed_distances(np.clip(maps, 0.0, 1.0), protocol, key, slots, chunk)
    scores = np.asarray(difficulty.heading_scores(out["distances"], protocol))
    out.update(rows=rows, fitness=np.asarray(difficulty.aggregate(out["distances"], protocol)), heading0=scores[:, 0],
               heading_scores=scores)
    return out



def protocol_label(p) -> str:
    """Short description of a protocol, e.g. ``4 headings x 20 walks, best 5, mean``."""
    text = f"{p.headings} heading{'s' if p.headings > 1 else ''} x {p.per_heading} walks, best {p.best}"
    if p.headings > 1:
        text += f", {p.rule}"
    return text + (f", start +-{p.start_spread:g} m" if p.start_spread > 0 else "")



def series_of(elites: dict, walked: dict | None, protocol) -> list[dict]:
    """The fitness series of one archive: ``{"label", "rows", "fitness", "cost"}``; stored fitness over all filled
    cells, and with ``walked`` the stored fitness of the walked sample, the protocol's fitness and heading 0's."""
    out = [{"label": "stored", "rows": np.arange(elites["cells"].size), "fitness": elites["fitness"], "cost": None}]
    if walked is None:
        return out
    rows = walked["rows"]
    cost = {k: walked[k] for k in ("compile_s", "walk_s")}
    cost.update(rollouts=int(walked["distances"].size), env_steps=int(walked["lengths"].sum()))
    if rows.size < elites["cells"].size:
        out.append({"label": "stored (walked sample)", "rows": rows, "fitness": elites["fitness"][rows], "cost": None})
    out.append({"label": protocol_label(protocol), "rows": rows, "fitness": walked["fitness"], "cost": cost})
    if protocol.headings > 1:
        out.append({"label": f"heading 0 alone (+x, {protocol.per_heading} walks, best {protocol.best})",
                    "rows": rows, "fitness": walked["heading0"], "cost": None})
    return out



def table_rows(name: str, elites: dict, series: list[dict], settings: GradientSettings) -> tuple[list[dict], list[dict]]:
    """``(band rows, summary rows)`` of one archive for ``gradient.csv`` / ``gradient_summary.csv``."""
    bands, summary = [], []
    width, threshold = float(settings.band_width), float(settings.threshold)
    for s in series:
        for measure in DISTANCES:
            d = distance_from_origin(elites["bins"][s["rows"]], measure)
            n_bands = grid_bands(elites, measure, width)
            t = band_table(d, s["fitness"], width, threshold, bands=n_bands)
            for k in range(t["lo"].size):
                bands.append({"archive": name, "series": s["label"], "distance": measure, "band_lo": t["lo"][k],
                              "band_hi": t["hi"][k], "filled": int(t["filled"][k]), "share_easy": t["share"][k],
                              "mean_fitness": t["mean"][k]})
        d = distance_from_origin(elites["bins"][s["rows"]], settings.distance)
        pearson, spearman = correlations(d, s["fitness"])
        row = {"archive": name, "series": s["label"], "n": int(s["rows"].size), "pearson": pearson,
               "spearman": spearman, "share_easy": float(np.mean(s["fitness"] >= threshold)),
               "mean_fitness": float(np.mean(s["fitness"]))}
        c = s["cost"] or {}
        n = max(int(s["rows"].size), 1)
        row.update(rollouts=c.get("rollouts"), env_steps=c.get("env_steps"), compile_s=c.get("compile_s"),
                   walk_s=c.get("walk_s"), walk_s_per_terrain=None if not c else c["walk_s"] / n,
                   env_steps_per_terrain=None if not c else c["env_steps"] / n)
        summary.append(row)
    return bands, summary



def write_csv(path: Path, rows: list[dict]) -> None:
    """``rows`` (dicts of one set of keys) as a CSV file, floats to 6 significant digits, None empty; atomically."""
    buf = io.StringIO()
    if rows:
        w = csv.DictWriter(buf, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else ("" if v is None else v)) for k, v in r.items()})
    atomic_write_text(path, buf.getvalue())



def markdown(bands: list[dict], summary: list[dict], settings: GradientSettings, protocol) -> str:
    """``gradient.md``: per archive, one row per fitness series: n, correlations, shares per band, cost."""
    measure, threshold = settings.distance, float(settings.threshold)
    what = ("bank.cell_distance, to the far corner of the cell" if measure == "corner"
            else "hypot(b0, b1) between cell indices")
    lines = ["# Difficulty gradient: fitness against distance from cell (0, 0)", "",
             f"Distance: `{measure}` ({what}); bands of {settings.band_width:g} cells; share = % of the filled cells in"
             f" the band with fitness >= {threshold:g}. `stored` = the archive's fitness (the paper's protocol, as"
             " evolved)."
             + ("" if protocol is None else f" Walked again: {protocol_label(protocol)}."), ""]
    other = [m for m in DISTANCES if m != measure][0]
    for name in dict.fromkeys(r["archive"] for r in summary):
        rows = [r for r in summary if r["archive"] == name]
        lines += [f"## {name}", ""]
        for m in (measure, other):
            head = [b for b in bands
                    if b["archive"] == name and b["series"] == rows[0]["series"] and b["distance"] == m]
            cols = [f"[{b['band_lo']:g}, {b['band_hi']:g})" for b in head]
            corr = "Pearson r | Spearman rho | " if m == measure else ""
            lines += [f"Distance `{m}`:", "", f"| fitness | n | {corr}" + " | ".join(cols) + " |",
                      "| --- " * (2 + len(cols) + (2 if corr else 0)) + "|"]
            for r in rows:
                cells = [b for b in bands if b["archive"] == name and b["series"] == r["series"] and b["distance"] == m]
                shares = [("-" if b["filled"] == 0 else f"{100 * b['share_easy']:.0f} ({b['filled']})") for b in cells]
                values = f"{r['pearson']:.2f} | {r['spearman']:.2f} | " if corr else ""
                lines.append(f"| {r['series']} | {r['n']} | {values}" + " | ".join(shares) + " |")
            lines.append("")
        lines.append("Band cells: % of the cells at or above the threshold (cells in the band).")
        for r in rows:
            if r["rollouts"]:
                lines.append(f"Cost of `{r['series']}`: {r['rollouts']} rollouts, {r['env_steps']} env steps "
                             f"({r['env_steps_per_terrain']:.0f} per terrain), compile {r['compile_s']:.1f} s, walk "
                             f"{r['walk_s']:.1f} s ({r['walk_s_per_terrain']:.3f} s per terrain).")
        lines.append("")
    return "\n".join(lines)



def plot(path: Path, results: list[tuple[str, dict, list[dict]]], settings: GradientSettings) -> None:
    """One row per archive: fitness against distance (every series), and the share of easy cells per band."""
    from matplotlib.figure import Figure

    width, threshold, measure = float(settings.band_width), float(settings.threshold), settings.distance
    fig = Figure(figsize=(10, 3.2 * len(results)))
    axes = fig.subplots(len(results), 2, squeeze=False)
    for (name, elites, series), (ax0, ax1) in zip(results, axes):
        n_bands = grid_bands(elites, measure, width)
        for i, s in enumerate(series):
            d = distance_from_origin(elites["bins"][s["rows"]], measure)
            ax0.scatter(d, s["fitness"], s=4 if s["label"] == "stored" else 10, alpha=0.5, label=s["label"],
                        color=f"C{i}")
            t = band_table(d, s["fitness"], width, threshold, bands=n_bands)
            ax1.plot(t["lo"] + width / 2, 100 * t["share"], "o-", color=f"C{i}", label=s["label"])
        ax0.set(xlabel=f"distance from cell (0, 0) ({measure}), cells", ylabel="fitness", title=name,
                ylim=(-0.02, 1.02))
        ax1.set(xlabel="band centre, cells", ylabel=f"% cells with fitness >= {threshold:g}", ylim=(-2, 102),
                title=f"bands of {width:g} cells")
        ax0.legend(fontsize=6, loc="lower left")
        ax1.legend(fontsize=6, loc="upper right")
    fig.tight_layout()
    save_figure(fig, path, dpi=110)



def save_walks(path: Path, elites: dict, walked: dict, protocol) -> None:
    """Every walked elite's rollouts: cells, corner distance, stored fitness, distances / lengths [n, attempts]."""
    buf = io.BytesIO()
    rows = walked["rows"]
    np.savez_compressed(buf, cells=elites["cells"][rows], bins=elites["bins"][rows],
                        distance=distance_from_origin(elites["bins"][rows]), stored_fitness=elites["fitness"][rows],
                        fitness=walked["fitness"], distances=walked["distances"], lengths=walked["lengths"],
                        protocol=np.array(repr(tuple(protocol))), protocol_fields=np.array(protocol._fields))
    atomic_write_bytes(path, buf.getvalue())



def write_reseated(path: Path, elites: dict, walked: dict, protocol=None, say=print) -> dict:
    """``jaxterrain.qd.reseat`` of the walked archive (fitness = the walk's, per filled cell, under
    ``protocol`` and the walker's default spawn rule, which the archive then records) saved at ``path``; says and
    returns its counts."""
    arch = elites["archive"]
    fitness = np.full(arch.fitness.shape[0], np.nan, np.float32)
    fitness[elites["cells"][walked["rows"]]] = walked["fitness"]
    reseated, counts = reseat(arch, fitness, protocol=protocol, spawn=WalkerConfig().spawn)  # timed_distances' walks
    save(path, reseated)
    say(f"  reseated -> {path.name}: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    return counts



def gradient(archives: Sequence, folder=None, *, protocol: Optional[difficulty.Protocol] = None,
             settings: GradientSettings = GradientSettings(), seed: int = 0, slots: Optional[int] = None,
             chunk: Optional[int] = None, sample: Optional[int] = None, reseat_walked: bool = False,
             say: Callable[[str], None] = print) -> GradientResult:
    """The difficulty gradient of every archive file of ``archives``; with ``folder``, its files written there:
    ``gradient.csv``, ``gradient_summary.csv``, ``gradient.md``, ``gradient.png`` and, when walked (``protocol``),
    ``<archive>_walks.npz`` (:func:`save_walks`) and with ``reseat_walked`` ``<archive>_reseated.npz``.

    ``protocol`` (``difficulty.PAPER`` / ``HEADINGS`` or any validated Protocol): walk the elites again under it
    with the shipped base policy, archive ``i`` with key ``fold_in(key(seed), i)``; ``slots`` (the rollout pool,
    None: all at once), ``chunk`` (elites per compiled call), ``sample`` (walk only that many elites, spread over
    distance). ``say`` prints a progress line. A ``ValueError`` names a bad archive or setting."""
    if settings.distance not in DISTANCES:
        raise ValueError(f"distance must be one of {', '.join(DISTANCES)}; got {settings.distance!r}")
    if reseat_walked and (protocol is None or sample is not None):
        raise ValueError("reseat needs a protocol (every elite walked again) and no sample")
    key = jax.random.key(int(seed))
    all_bands, all_summary, results, walks, reseated = [], [], [], {}, {}
    folder = None if folder is None else Path(folder)
    for i, path in enumerate(archives):
        elites = load_elites(path)
        walked = None
        if protocol is not None:
            say(f"{elites['name']}: walking {min(sample or elites['cells'].size, elites['cells'].size)}"
                f" elites under {protocol_label(protocol)} (slots {slots or 'all'})")
            walked = walks[elites["name"]] = walk_archive(elites, protocol, jax.random.fold_in(key, i), slots, chunk,
                                                          sample)
            if folder is not None:
                save_walks(folder / f"{elites['name']}_walks.npz", elites, walked, protocol)
            say(f"  compile {walked['compile_s']:.1f} s, walk {walked['walk_s']:.1f} s")
            if reseat_walked and folder is not None:
                reseated[elites["name"]] = write_reseated(folder / f"{elites['name']}_reseated.npz", elites, walked,
                                                          protocol, say)
        series = series_of(elites, walked, protocol)
        bands, summary = table_rows(elites["name"], elites, series, settings)
        all_bands += bands
        all_summary += summary
        results.append((elites["name"], elites, series))
        for r in summary:
            say(f"  {r['series']}: n {r['n']}, pearson {r['pearson']:.2f}, spearman {r['spearman']:.2f}, "
                f"easy {100 * r['share_easy']:.0f} %")
    if folder is not None:
        write_csv(folder / "gradient.csv", all_bands)
        write_csv(folder / "gradient_summary.csv", all_summary)
        atomic_write_text(folder / "gradient.md", markdown(all_bands, all_summary, settings, protocol) + "\n")
        plot(folder / "gradient.png", results, settings)
    return GradientResult(all_bands, all_summary, walks, reseated)
