"""Who holds an archive's cells: each generator's share of the filled cells per band of distance from cell (0, 0)
(:func:`jaxterrain.qd.generator_shares`), as tables and a figure, for one archive or several side by side (the
mixed archive of ``evolve --generator mixed`` beside the combined archive of separate runs).

    rows = shares.write_all(folder, {"mixed": mixed, "combined": qd.combine(separate)}, width=10.0)
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np
from matplotlib import colormaps
from matplotlib.figure import Figure

from jaxterrain.qd.archive import coverage, generator_shares
from jaxterrain.runtime.io import atomic_write_text, save_figure

__all__ = ["tables", "write_csv", "markdown", "overlap", "plot", "write_all"]


def tables(archives: dict, width: float) -> tuple[list[dict], list[str]]:
    """``(rows, names)``: one row per (archive label, band, generator) of ``jaxterrain.qd.generator_shares`` (every
    archive counted over the union of their generator names, first seen first)."""
    names = list(dict.fromkeys(n for a in archives.values() for n in a.generator_names))
    rows = []
    for label, arch in archives.items():
        r = generator_shares(arch, width, names)
        for b in range(len(r["lo"])):
            for j, name in enumerate(names):
                rows.append({"archive": label, "band_lo": float(r["lo"][b]), "band_hi": float(r["hi"][b]),
                             "cells": int(r["cells"][b]), "filled": int(r["filled"][b]),
                             "coverage_percent": float(r["coverage"][b]), "generator": name,
                             "count": int(r["count"][b, j]), "share": float(r["share"][b, j])})
    return rows, names


def write_csv(path: Path, rows: list[dict]) -> None:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(rows[0]) if rows else ["archive"])
    w.writeheader()
    for r in rows:
        w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    atomic_write_text(path, buf.getvalue())


def markdown(archives: dict, rows: list[dict], names: list[str]) -> str:
    """Overall coverage per archive, then per band: each archive's coverage and each generator's share (% of the
    band's filled cells)."""
    lines = ["| archive | coverage | elites | " + " | ".join(names) + " |", "| --- | --- | --- |" + " --- |" * len(names)]
    for label, arch in archives.items():
        total = generator_shares(arch, 1e9, names)["total"]
        n = int(arch.filled.sum())
        lines.append(f"| {label} | {coverage(arch):.2f}% | {n} | "
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
    both = a.filled & b.filled
    name_a = np.array(a.generator_names + ("",), dtype=object)[np.where(a.filled, a.source, -1)]
    name_b = np.array(b.generator_names + ("",), dtype=object)[np.where(b.filled, b.source, -1)]
    return {"both": int(both.sum()), "same": int((both & (name_a == name_b)).sum()),
            "only_a": int((a.filled & ~b.filled).sum()), "only_b": int((b.filled & ~a.filled).sum())}


def plot(path: Path, archives: dict, rows: list[dict], names: list[str], title: str = "") -> None:
    """Per archive (columns): each generator's share per band as stacked bars (top) and the band's coverage
    (bottom)."""
    labels = list(archives)
    fig = Figure(figsize=(4.2 * len(labels), 5.2), layout="constrained")
    axes = fig.subplots(2, len(labels), squeeze=False, sharex=True, sharey="row")
    colors = colormaps["tab10"]
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
    save_figure(fig, path, dpi=130)


def write_all(folder: Path, archives: dict, width: float, title: str = "", say=print) -> list[dict]:
    """``shares.csv``, ``shares.md`` and ``shares.png`` of ``archives`` ({label: Archive}) in ``folder``; the rows.
    ``say`` receives the Markdown table (None: silent)."""
    rows, names = tables(archives, width)
    write_csv(folder / "shares.csv", rows)
    text = markdown(archives, rows, names)
    atomic_write_text(folder / "shares.md", (f"{title}\n\n" if title else "") + text)
    plot(folder / "shares.png", archives, rows, names, title)
    if say is not None:
        say(text)
    return rows
