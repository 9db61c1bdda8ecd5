"""``python -m experiments shares --mixed A.npz --separate P.npz W.npz ...``: who holds an archive's cells.

For the mixed archive (``evolve --generator mixed``: one MAP-Elites run whose offspring of every generator compete
for the same cells) and, with ``--separate``, the combined archive of separate runs (``jaxterrain.qd.combine`` of
them: per cell the fitter elite, as ``coverage`` and the curriculum's ``combined`` treatment build it), this
command tabulates each generator's share of the filled cells per band of distance from cell (0, 0)
(``jaxterrain.qd.generator_shares``: bands of ``--band-width`` cells of ``qd.cell_distance``, as in
``docs/results/gradient.md``), with each band's coverage.

Writes into the run folder (``runs/shares-<time>/`` or ``--out``): ``config.json``, ``shares.csv`` (one row per
archive, band and generator: cells, filled, coverage %, count, share), ``shares.md`` (coverage and the shares per
band, the archives side by side) and ``shares.png`` (per archive: stacked bars of the shares per band, and the
coverage per band). ``--mixed`` and ``--separate`` take archive files or run folders holding ``archive.npz``; the
archives must share one grid (descriptors, ranges, bins).

Example (after the GPU runs of ``docs/results/mixed_archive.md``)::

    python -m experiments shares --mixed runs/mixed --separate runs/evolve-perlin runs/evolve-worley ... --out DIR
"""

from __future__ import annotations

import argparse
import csv
import io
from pathlib import Path

from experiments import common

PRESETS: dict[str, dict] = common.with_preset_names({
    "default": dict(mixed=None, separate=None, band_width=10.0),
}, {"smoke": "default", "gpu-short": "default", "gpu": "default", "paper": "default"})


def add_arguments(parser: argparse.ArgumentParser) -> None:
    common.add_run_arguments(parser, PRESETS, "default")
    parser.add_argument("--mixed", default=None, metavar="ARCHIVE",
                        help="the mixed archive: an archive.npz or the run folder of evolve --generator mixed")
    parser.add_argument("--separate", nargs="+", default=None, metavar="ARCHIVE",
                        help="archives of separate runs (files or run folders) to combine (qd.combine) and compare")
    parser.add_argument("--band-width", type=float, default=None, help="band width in cells (default 10)")


def overrides(args) -> dict:
    return dict(mixed=args.mixed, separate=args.separate, band_width=args.band_width)


def archive_path(path) -> Path:
    """``path`` itself, or ``path/archive.npz`` for a run folder."""
    p = Path(path)
    return p / "archive.npz" if p.is_dir() else p


def check_config(cfg: dict) -> None:
    """Before the run folder: an archive to read, each path an existing file; :class:`~experiments.common.UsageError`."""
    if not cfg.get("mixed") and not cfg.get("separate"):
        raise common.UsageError("--mixed or --separate: give at least one archive (a file or a run folder)")
    for flag, paths in (("--mixed", [cfg.get("mixed")] if cfg.get("mixed") else []),
                        ("--separate", cfg.get("separate") or [])):
        for p in paths:
            if not archive_path(p).is_file():
                raise common.UsageError(f"{flag} {p}: no archive there (an archive.npz, or a run folder holding one)")
    load_archives(cfg)  # unreadable files and grids that differ: refused before the run folder is made


def load_archives(cfg: dict) -> dict:
    """``{"mixed": Archive, "combined": Archive}`` (those given) of a config; :class:`~experiments.common.UsageError`
    for an unreadable file or archives of different grids."""
    from jaxterrain import qd as A

    def load(flag, p):
        try:
            return A.load(archive_path(p))
        except ValueError as err:
            raise common.UsageError(f"{flag} {p}: {err}") from None

    archives = {}
    if cfg.get("mixed"):
        archives["mixed"] = load("--mixed", cfg["mixed"])
    if cfg.get("separate"):
        members = [load("--separate", p) for p in cfg["separate"]]
        try:
            archives["combined"] = A.combine(members)
        except ValueError as err:
            raise common.UsageError(f"--separate: {err}") from None
    if len(archives) == 2:
        try:
            A.combine(list(archives.values()))  # the same grid, or combine's one-line refusal
        except ValueError as err:
            raise common.UsageError(f"--mixed and --separate must share one grid: {err}") from None
    return archives


def tables(archives: dict, width: float) -> tuple[list[dict], list[str]]:
    """``(rows, names)``: one row per (archive label, band, generator) of ``jaxterrain.qd.generator_shares`` (every
    archive counted over the union of their generator names, first seen first)."""
    from jaxterrain import qd as A

    names = list(dict.fromkeys(n for a in archives.values() for n in a.generator_names))
    rows = []
    for label, arch in archives.items():
        r = A.generator_shares(arch, width, names)
        for b in range(len(r["lo"])):
            for j, name in enumerate(names):
                rows.append({"archive": label, "band_lo": float(r["lo"][b]), "band_hi": float(r["hi"][b]),
                             "cells": int(r["cells"][b]), "filled": int(r["filled"][b]),
                             "coverage_percent": float(r["coverage"][b]), "generator": name,
                             "count": int(r["count"][b, j]), "share": float(r["share"][b, j])})
    return rows, names


def write_csv(path: Path, rows: list[dict]) -> None:
    from jaxterrain.runtime.io import atomic_write_text

    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(rows[0]) if rows else ["archive"])
    w.writeheader()
    for r in rows:
        w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    atomic_write_text(path, buf.getvalue())


def markdown(archives: dict, rows: list[dict], names: list[str]) -> str:
    """Overall coverage per archive, then per band: each archive's coverage and each generator's share (% of the
    band's filled cells)."""
    from jaxterrain import qd as A

    lines = ["| archive | coverage | elites | " + " | ".join(names) + " |", "| --- | --- | --- |" + " --- |" * len(names)]
    for label, arch in archives.items():
        total = A.generator_shares(arch, 1e9, names)["total"]
        n = int(arch.filled.sum())
        lines.append(f"| {label} | {A.coverage(arch):.2f}% | {n} | "
                     + " | ".join(f"{100 * c / max(n, 1):.1f}%" for c in total) + " |")
    if {"mixed", "combined"} <= set(archives):
        o = overlap(archives["mixed"], archives["combined"])
        lines += ["", f"Cells filled in both: {o['both']}, held by the same generator in both: {o['same']} "
                  f"({100 * o['same'] / max(o['both'], 1):.0f}%); filled only in the mixed archive: {o['only_a']}, "
                  f"only in the combined one: {o['only_b']}."]
    lines += ["", "Per band of distance from cell (0, 0) (`qd.cell_distance`, in cells): the band's coverage, then each "
              "generator's share of its filled cells.", "",
              "| band | archive | cells | filled | coverage | " + " | ".join(names) + " |",
              "| --- | --- | --- | --- | --- |" + " --- |" * len(names)]
    for lo, hi in sorted({(r["band_lo"], r["band_hi"]) for r in rows}):
        for lab in archives:
            mine = {r["generator"]: r for r in rows if r["archive"] == lab and r["band_lo"] == lo}
            first = next(iter(mine.values()))
            lines.append(f"| [{lo:g}, {hi:g}) | {lab} | {first['cells']} | {first['filled']} | "
                         f"{first['coverage_percent']:.1f}% | "
                         + " | ".join("-" if first["filled"] == 0 else f"{100 * mine[n]['share']:.0f}%" for n in names)
                         + " |")
    return "\n".join(lines) + "\n"


def overlap(a, b) -> dict:
    """Cells of two archives of one grid: ``{"both", "same", "only_a", "only_b"}``: filled in both, of those held by
    the same generator (by name) in both, filled only in ``a``, only in ``b``."""
    import numpy as np

    both = a.filled & b.filled
    name_a = np.array(a.generator_names + ("",), dtype=object)[np.where(a.filled, a.source, -1)]
    name_b = np.array(b.generator_names + ("",), dtype=object)[np.where(b.filled, b.source, -1)]
    return {"both": int(both.sum()), "same": int((both & (name_a == name_b)).sum()),
            "only_a": int((a.filled & ~b.filled).sum()), "only_b": int((b.filled & ~a.filled).sum())}


def plot(path: Path, archives: dict, rows: list[dict], names: list[str], title: str = "") -> None:
    """Per archive (columns): each generator's share per band as stacked bars (top) and the band's coverage
    (bottom)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    labels = list(archives)
    fig, axes = plt.subplots(2, len(labels), figsize=(4.2 * len(labels), 5.2), squeeze=False, sharex=True, sharey="row",
                             layout="constrained")
    colors = plt.get_cmap("tab10")
    for j, lab in enumerate(labels):
        mine = [r for r in rows if r["archive"] == lab]
        bands = sorted({r["band_lo"] for r in mine})
        x = np.arange(len(bands))
        bottom = np.zeros(len(bands))
        for k, n in enumerate(names):
            v = np.array([100 * next(r["share"] for r in mine if r["band_lo"] == b and r["generator"] == n)
                          for b in bands])
            v = np.nan_to_num(v)
            axes[0, j].bar(x, v, bottom=bottom, color=colors(k % 10), label=n)
            bottom += v
        cov = [next(r["coverage_percent"] for r in mine if r["band_lo"] == b) for b in bands]
        axes[1, j].bar(x, cov, color="0.4")
        axes[0, j].set_title(f"{lab}", fontsize=9)
        axes[0, j].set_ylabel("share of filled cells (%)", fontsize=8)
        axes[1, j].set_ylabel("band coverage (%)", fontsize=8)
        width = mine[0]["band_hi"] - mine[0]["band_lo"] if mine else 10
        axes[1, j].set_xticks(x, [f"{b:g}-{b + width:g}" for b in bands], rotation=30, fontsize=7)
        axes[1, j].set_xlabel("distance from cell (0, 0), cells", fontsize=8)
    axes[0, -1].legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    if title:
        fig.suptitle(title, fontsize=9)
    common.save_figure(fig, path, dpi=130)


def write_all(folder: Path, archives: dict, width: float, title: str = "") -> list[dict]:
    """``shares.csv``, ``shares.md`` and ``shares.png`` of ``archives`` ({label: Archive}) in ``folder``; the rows."""
    from jaxterrain.runtime.io import atomic_write_text

    rows, names = tables(archives, width)
    write_csv(folder / "shares.csv", rows)
    text = markdown(archives, rows, names)
    atomic_write_text(folder / "shares.md", (f"{title}\n\n" if title else "") + text)
    plot(folder / "shares.png", archives, rows, names, title)
    print(text, flush=True)
    return rows


def main(args) -> int:
    folder, cfg = common.setup_run("shares", args, PRESETS, "default", overrides(args), check=check_config)
    write_all(folder, load_archives(cfg), float(cfg["band_width"]))
    print(f"done -> {folder}", flush=True)
    return 0
