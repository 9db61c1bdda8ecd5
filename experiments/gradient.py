"""``python -m experiments gradient ARCHIVE.npz [...]``: the difficulty gradient of MAP-Elites archives.

The map-based curriculum of Experiment 2 climbs an archive from cell (0, 0) outwards, so it needs fitness to FALL
with the distance from that cell (the paper's Figure 6). For every archive this command measures, over its filled
cells:

* fitness against the cell's distance from cell (0, 0): Pearson and Spearman correlations, a scatter figure;
* the share of filled cells with fitness >= ``threshold`` (0.9, the curriculum's "already easy") in bands of
  ``band_width`` (10) cells of distance (:func:`band_table`).

Distance: ``distance="corner"`` (default) is :func:`jaxterrain.qd.cell_distance`, from the grid's origin corner
to the cell's far corner (the curriculum's and Table 2's measure, 1.41 to 70.71 on 50 x 50); ``"index"`` is
``hypot(b0, b1)``, between the cells' indices (0 to 69.3), the measure issue 13 quoted its band shares in. Cell
``i * bins + j`` of an archive has descriptor-0 bin ``j`` and descriptor-1 bin ``i``.

The stored fitness is the paper's protocol (20 walks along +x, best 5), as the archive was evolved. With
``--protocol headings`` (or ``paper``) every elite is re-rendered (``jaxterrain.qd.from_archive``) and walked
again under that :class:`jaxterrain.difficulty.Protocol` (fields overridable: ``--attempts --best --headings
--start-spread --rule``), in ONE batched call over all elites on a rollout pool (``--rollout-slots``; ``auto`` = 16 384 on
a GPU, all at once on a CPU), and the tables show the protocols side by side: ``stored``, the protocol, and
``heading 0`` (the same rollouts' +x walks alone: with ``HEADINGS``, 20 walks best 5 = the paper's protocol
re-walked, free of the upward bias that MAP-Elites' selection leaves in stored fitness). ``--sample N`` walks
only N elites per archive, evenly spread over distance (a CPU-sized sample).

Writes into the run folder (``runs/gradient-<time>/`` or ``--out``): ``config.json``, ``gradient.csv`` (one row per
archive, protocol, distance measure and band), ``gradient_summary.csv`` (one row per archive and protocol:
correlations, shares, cost), ``gradient.md``, ``gradient.png`` and, when walked, ``<archive>_walks.npz`` (cells,
distances, stored fitness and every rollout's distance and length, heading-major), so other rules can be
computed without walking again. ``--reseat`` (with ``--protocol``, every elite) also writes
``<archive>_reseated.npz``: ``jaxterrain.qd.reseat`` with the fitness walked here, i.e. every genome its
generator accepts, in the cell its own terrain falls in, with its own fitness (for the archives evolved before the
fix of tied insertions, ``docs/results/insertion_bug.md``).

Example (GPU)::

    python -m experiments gradient docs/results/exp1b_gpu_sound_cppn_archive.npz --protocol headings --out DIR
"""

from __future__ import annotations

import argparse
import csv
import io
import time
from pathlib import Path

import numpy as np

from experiments import common

PRESETS: dict[str, dict] = common.with_preset_names({
    "default": dict(archives=[], protocol=None, attempts=None, best=None, headings=None, start_spread=None,
                    rule=None, slots="auto", chunk=None, sample=None, band_width=10.0, threshold=0.9,
                    distance="corner", reseat=False),
}, {"smoke": "default", "gpu-short": "default", "gpu": "default", "paper": "default"})
PROTOCOLS = ("paper", "headings")
DISTANCES = ("corner", "index")


# ----------------------------------------------------------------------------------------------------------------
# Pure functions (NumPy)
# ----------------------------------------------------------------------------------------------------------------
def distance_from_origin(bins_: np.ndarray, measure: str = "corner") -> np.ndarray:
    """``[N, 2]`` bins -> ``[N]`` float32 distance from cell (0, 0): ``"corner"`` = ``bank.cell_distance`` (to the
    cell's far corner), ``"index"`` = ``hypot(b0, b1)``."""
    from jaxterrain.qd import cell_distance

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


# ----------------------------------------------------------------------------------------------------------------
# The command
# ----------------------------------------------------------------------------------------------------------------
def add_arguments(parser: argparse.ArgumentParser) -> None:
    common.add_run_arguments(parser, PRESETS, "default")
    parser.add_argument("archives", nargs="*", type=str, help="archive.npz files (jaxterrain.qd.save format)")
    parser.add_argument("--protocol", choices=PROTOCOLS, default=None,
                        help="also walk every elite again under this protocol (difficulty.PAPER or HEADINGS)")
    parser.add_argument("--attempts", type=int, default=None, help="override the protocol's attempts (in total)")
    parser.add_argument("--best", type=int, default=None, help="override the protocol's best (per heading)")
    parser.add_argument("--headings", type=int, choices=(1, 2, 4), default=None, help="override the headings")
    parser.add_argument("--start-spread", type=float, default=None, help="override the start spread (m)")
    parser.add_argument("--rule", choices=("mean", "min"), default=None, help="override the rule over headings")
    common.add_slots_argument(parser, "slots", "an int, 'all' or 'auto' (16384 on a GPU, all at once on a CPU)",
                              type=str, aliases=("--slots",))
    parser.add_argument("--chunk", type=int, default=None, help="elites per compiled call (bounds device memory)")
    parser.add_argument("--sample", type=int, default=None, help="walk only N elites per archive, spread over "
                        "distance")
    parser.add_argument("--band-width", type=float, default=None, help="band width in cells (default 10)")
    parser.add_argument("--threshold", type=float, default=None, help="'easy' fitness threshold (default 0.9)")
    parser.add_argument("--distance", choices=DISTANCES, default=None,
                        help="distance measure of the figure and summary (default corner; the CSV has both)")
    parser.add_argument("--reseat", action=argparse.BooleanOptionalAction, default=None,
                        help="with --protocol (no --sample): also write <archive>_reseated.npz, every valid genome "
                             "in its own terrain's cell with the fitness walked here (jaxterrain.qd.reseat)")


def overrides(args) -> dict:
    return dict(archives=list(args.archives) or None, protocol=args.protocol, attempts=args.attempts, best=args.best,
                headings=args.headings, start_spread=args.start_spread, rule=args.rule, slots=args.slots,
                chunk=args.chunk, sample=args.sample, band_width=args.band_width, threshold=args.threshold,
                distance=args.distance, reseat=args.reseat)


def resolve_protocol(cfg: dict):
    """The :class:`~jaxterrain.difficulty.Protocol` of the config (None when nothing is walked again)."""
    from jaxterrain import difficulty

    if cfg.get("protocol") is None:
        return None
    if cfg["protocol"] not in PROTOCOLS:
        raise common.UsageError(f"--protocol must be one of {', '.join(PROTOCOLS)}; got {cfg['protocol']!r}")
    base = difficulty.PAPER if cfg["protocol"] == "paper" else difficulty.HEADINGS
    fields = {k: cfg.get(k) for k in ("attempts", "best", "headings", "start_spread", "rule")}
    try:
        return base._replace(**{k: v for k, v in fields.items() if v is not None}).validate()
    except ValueError as err:
        raise common.UsageError(f"--protocol / --attempts / --best / --headings / --start-spread / --rule: "
                                f"{str(err).splitlines()[0]}") from None


def parse_slots(value) -> int | str | None:
    """``--rollout-slots``: None, ``"all"``, ``"auto"`` or an integer >= 1 (also as text); :class:`~experiments.common.UsageError`
    otherwise."""
    if value in (None, "all", "auto"):
        return value
    try:
        slots = int(value)
    except (TypeError, ValueError):
        slots = 0
    if isinstance(value, bool) or slots < 1 or (isinstance(value, float) and value != slots):
        raise common.UsageError(f"--rollout-slots must be an integer >= 1, 'all' or 'auto'; got {value!r}")
    return slots


def resolve_slots(value) -> int | None:
    """``"auto"`` -> 16 384 on a GPU / TPU, None (all at once) on a CPU; ``"all"`` / None -> None; else an int."""
    import jax

    value = parse_slots(value)
    if value in (None, "all"):
        return None
    if value == "auto":
        return None if jax.default_backend() == "cpu" else 16384
    return value


def load_elites(path: str) -> dict:
    """The filled cells of an archive: ``{"archive", "name", "cells" [N], "bins" [N, 2], "fitness" [N]}``; a
    :class:`~experiments.common.UsageError` naming the file when it is not a readable archive or has no elite."""
    from jaxterrain import qd as A

    try:
        arch = A.load(path)
    except (OSError, ValueError) as err:
        raise common.UsageError(f"archive {path}: cannot read it: {str(err).splitlines()[0]}") from None
    cells = np.flatnonzero(np.asarray(arch.source) >= 0)
    if cells.size == 0:
        raise common.UsageError(f"archive {path} has no filled cell")
    return {"archive": arch, "name": Path(path).name.removesuffix(".npz"), "cells": cells,
            "bins": A.cell_bins(cells, int(arch.config.bins)), "fitness": np.asarray(arch.fitness, np.float32)[cells]}


def walk(heightmaps, protocol, key, slots: int | None, chunk: int | None) -> dict:
    """Walk ``heightmaps`` [N, H, W] in [0, 1] under ``protocol`` with the shipped base policy.

    The same program as ``difficulty.rollout_distances(..., protocol=protocol, slots=slots, chunk=chunk)``, compiled
    ahead of time so that compiling and walking are timed apart. Returns ``{"distances", "lengths"}`` [N, attempts]
    (heading-major), ``"compile_s"`` and ``"walk_s"``.
    """
    import jax
    import jax.numpy as jnp


    from jaxterrain.difficulty import evaluation

    terrains_m, env_config, policy = evaluation._resolve(heightmaps, protocol, None, None, None)
    apply, params, with_params = evaluation._policy_program(policy, None)
    fn = evaluation._program(env_config, protocol.attempts, protocol.headings, apply, with_params, slots, True)
    n = terrains_m.shape[0]
    size = n if chunk is None else min(int(chunk), n)
    parts = -(-n // size)
    keys = [key] if parts == 1 else list(jax.random.split(key, parts))
    pad = lambda t: jnp.concatenate([t, jnp.repeat(t[-1:], size - t.shape[0], axis=0)])  # noqa: E731
    t0 = time.perf_counter()
    compiled = fn.lower(terrains_m[:size], keys[0], params).compile()
    t1 = time.perf_counter()
    dist, length = [], []
    for i, k in enumerate(keys):
        part = terrains_m[i * size:(i + 1) * size]
        d, s = compiled(pad(part) if part.shape[0] < size else part, k, params)
        dist.append(np.asarray(d)[:part.shape[0]])
        length.append(np.asarray(s)[:part.shape[0]])
    t2 = time.perf_counter()
    return {"distances": np.concatenate(dist), "lengths": np.concatenate(length), "compile_s": t1 - t0,
            "walk_s": t2 - t1}


def walk_archive(elites: dict, protocol, key, slots, chunk, sample) -> dict:
    """Render (``qd.from_archive``) and walk the elites of ``sample`` (:func:`spread_sample` by corner distance)
    under ``protocol``. Returns the :func:`walk` dict plus ``"rows"`` [n] (indices into the filled cells),
    ``"fitness"`` [n] (the protocol's) and ``"heading0"`` [n] (heading 0's score alone)."""
    from jaxterrain.qd import bank
    from jaxterrain import difficulty

    rows = spread_sample(distance_from_origin(elites["bins"]), sample)
    b = bank.from_archive(elites["archive"])
    maps = np.asarray(b.heightmaps)[rows] / np.float32(1.0 * _scale_height())
    from jaxterrain.runtime import estimates

    estimates.announce("walks", f"{len(rows)} elites, {protocol.attempts} walks each")
    out = walk(np.clip(maps, 0.0, 1.0), protocol, key, slots, chunk)
    scores = np.asarray(difficulty.heading_scores(out["distances"], protocol))
    out.update(rows=rows, fitness=np.asarray(difficulty.aggregate(out["distances"], protocol)), heading0=scores[:, 0],
               heading_scores=scores)
    return out


def _scale_height() -> float:
    from jaxterrain.terrain import TerrainScale

    return float(TerrainScale().height)


def protocol_label(p) -> str:
    """Short description of a protocol, e.g. ``4 headings x 20 walks, best 5, mean``."""
    text = f"{p.headings} heading{'s' if p.headings > 1 else ''} x {p.per_heading} walks, best {p.best}"
    if p.headings > 1:
        text += f", {p.rule}"
    return text + (f", start +-{p.start_spread:g} m" if p.start_spread > 0 else "")


def grid_bands(elites: dict, measure: str, width: float) -> int:
    """Bands of ``width`` up to the grid's farthest cell (bins - 1, bins - 1), so every archive of one grid size has
    the same columns."""
    far = np.full((1, 2), int(elites["archive"].config.bins) - 1)
    return int(np.floor(distance_from_origin(far, measure)[0] / width)) + 1


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


def table_rows(name: str, elites: dict, series: list[dict], cfg: dict) -> tuple[list[dict], list[dict]]:
    """``(band rows, summary rows)`` of one archive for ``gradient.csv`` / ``gradient_summary.csv``."""
    bands, summary = [], []
    width, threshold = float(cfg["band_width"]), float(cfg["threshold"])
    for s in series:
        for measure in DISTANCES:
            d = distance_from_origin(elites["bins"][s["rows"]], measure)
            n_bands = grid_bands(elites, measure, width)
            t = band_table(d, s["fitness"], width, threshold, bands=n_bands)
            for k in range(t["lo"].size):
                bands.append({"archive": name, "series": s["label"], "distance": measure, "band_lo": t["lo"][k],
                              "band_hi": t["hi"][k], "filled": int(t["filled"][k]), "share_easy": t["share"][k],
                              "mean_fitness": t["mean"][k]})
        d = distance_from_origin(elites["bins"][s["rows"]], cfg["distance"])
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
    from jaxterrain.runtime.io import atomic_write_text

    buf = io.StringIO()
    if rows:
        w = csv.DictWriter(buf, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else ("" if v is None else v)) for k, v in r.items()})
    atomic_write_text(path, buf.getvalue())


def markdown(bands: list[dict], summary: list[dict], cfg: dict, protocol) -> str:
    """``gradient.md``: per archive, one row per fitness series: n, correlations, shares per band, cost."""
    measure, threshold = cfg["distance"], float(cfg["threshold"])
    what = ("bank.cell_distance, to the far corner of the cell" if measure == "corner"
            else "hypot(b0, b1) between cell indices")
    lines = ["# Difficulty gradient: fitness against distance from cell (0, 0)", "",
             f"Distance: `{measure}` ({what}); bands of {cfg['band_width']:g} cells; share = % of the filled cells in"
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


def plot(path: Path, results: list[tuple[str, dict, list[dict]]], cfg: dict) -> None:
    """One row per archive: fitness against distance (every series), and the share of easy cells per band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    width, threshold, measure = float(cfg["band_width"]), float(cfg["threshold"]), cfg["distance"]
    fig, axes = plt.subplots(len(results), 2, figsize=(10, 3.2 * len(results)), squeeze=False)
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
    common.save_figure(fig, path, dpi=110)


def check_config(cfg: dict) -> None:
    """Before a run folder: at least one archive, each an existing file that reads as an archive with elites
    (:func:`load_elites`; read again when walked, not kept); ``--slots``, ``--distance``, the protocol's fields
    and ``--reseat``'s needs."""
    if not cfg.get("archives"):
        raise common.UsageError("give at least one archive.npz (ARCHIVE ...)")
    for path in cfg["archives"]:
        if not Path(path).is_file():
            raise common.UsageError(f"archive {path}: no such file")
    parse_slots(cfg.get("slots"))
    if cfg.get("distance") not in DISTANCES:
        raise common.UsageError(f"--distance must be one of {', '.join(DISTANCES)}; got {cfg.get('distance')!r}")
    protocol = resolve_protocol(cfg)
    if cfg.get("reseat") and (protocol is None or cfg.get("sample") is not None):
        raise common.UsageError("--reseat needs --protocol (every elite walked again) and no --sample")
    if cfg.get("reseat") and (protocol.start_spread != 0.0 or protocol.rule != "mean"):
        raise common.UsageError("--reseat: an archive records the protocol's attempts, best and headings only; not "
                                "with --start-spread or --rule min")
    for path in cfg["archives"]:
        load_elites(path)


def main(args) -> int:
    import jax

    folder, cfg = common.setup_run("gradient", args, PRESETS, "default", overrides(args), check=check_config)
    protocol = resolve_protocol(cfg)
    slots = resolve_slots(cfg.get("slots"))
    key = jax.random.key(int(cfg["seed"]))
    all_bands, all_summary, results = [], [], []
    for i, path in enumerate(cfg["archives"]):
        elites = load_elites(path)
        walked = None
        if protocol is not None:
            print(f"{elites['name']}: walking {min(cfg.get('sample') or elites['cells'].size, elites['cells'].size)}"
                  f" elites under {protocol_label(protocol)} (slots {slots or 'all'})", flush=True)
            walked = walk_archive(elites, protocol, jax.random.fold_in(key, i), slots, cfg.get("chunk"),
                                  cfg.get("sample"))
            save_walks(folder / f"{elites['name']}_walks.npz", elites, walked, protocol)
            print(f"  compile {walked['compile_s']:.1f} s, walk {walked['walk_s']:.1f} s", flush=True)
            if cfg.get("reseat"):
                write_reseated(folder / f"{elites['name']}_reseated.npz", elites, walked, protocol)
        series = series_of(elites, walked, protocol)
        bands, summary = table_rows(elites["name"], elites, series, cfg)
        all_bands += bands
        all_summary += summary
        results.append((elites["name"], elites, series))
        for r in summary:
            print(f"  {r['series']}: n {r['n']}, pearson {r['pearson']:.2f}, spearman {r['spearman']:.2f}, "
                  f"easy {100 * r['share_easy']:.0f} %", flush=True)
    write_csv(folder / "gradient.csv", all_bands)
    write_csv(folder / "gradient_summary.csv", all_summary)
    from jaxterrain.runtime.io import atomic_write_text

    atomic_write_text(folder / "gradient.md", markdown(all_bands, all_summary, cfg, protocol) + "\n")
    plot(folder / "gradient.png", results, cfg)
    print(f"done -> {folder}", flush=True)
    return 0


def write_reseated(path: Path, elites: dict, walked: dict, protocol=None) -> dict:
    """``jaxterrain.qd.reseat`` of the walked archive (fitness = the walk's, per filled cell, under
    ``protocol``, which the archive then records) saved at ``path``; prints and returns its counts."""
    from jaxterrain import qd as A

    arch = elites["archive"]
    fitness = np.full(arch.fitness.shape[0], np.nan, np.float32)
    fitness[elites["cells"][walked["rows"]]] = walked["fitness"]
    reseated, counts = A.reseat(arch, fitness, protocol=protocol)
    A.save(path, reseated)
    print(f"  reseated -> {path.name}: " + ", ".join(f"{k} {v}" for k, v in counts.items()), flush=True)
    return counts


def save_walks(path: Path, elites: dict, walked: dict, protocol) -> None:
    """Every walked elite's rollouts: cells, corner distance, stored fitness, distances / lengths [n, attempts]."""
    from jaxterrain.runtime.io import atomic_write_bytes

    buf = io.BytesIO()
    rows = walked["rows"]
    np.savez_compressed(buf, cells=elites["cells"][rows], bins=elites["bins"][rows],
                        distance=distance_from_origin(elites["bins"][rows]), stored_fitness=elites["fitness"][rows],
                        fitness=walked["fitness"], distances=walked["distances"], lengths=walked["lengths"],
                        protocol=np.array(repr(tuple(protocol))), protocol_fields=np.array(protocol._fields))
    atomic_write_bytes(path, buf.getvalue())
