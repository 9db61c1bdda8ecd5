"""``python -m experiments shares --mixed A.npz --separate P.npz W.npz ...``: who holds an archive's cells.

For the mixed archive (``evolve --generator mixed``: one MAP-Elites run whose offspring of every generator compete
for the same cells) and, with ``--separate``, the combined archive of separate runs (``jaxterrain.qd.combine`` of
them: per cell the fitter elite, as ``coverage`` and the curriculum's ``combined`` treatment build it), this
command tabulates each generator's share of the filled cells per band of distance from cell (0, 0)
(``jaxterrain.qd.generator_shares``: bands of ``--band-width`` cells of ``qd.cell_distance``, as in
``docs/results/gradient.md``), with each band's coverage (the tables and the figure: ``jaxterrain.qd.shares``).

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
from pathlib import Path

from experiments import common

PRESETS: dict[str, dict] = common.with_preset_names({
    "default": dict(mixed=None, separate=None, band_width=10.0),
}, {"smoke": "default", "gpu-short": "default", "gpu": "default", "paper": "default"})


def add_arguments(parser: argparse.ArgumentParser) -> None:
    common.add_run_arguments(parser, PRESETS, "default", time_limit=False, seed=False)
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


def main(args) -> int:
    from jaxterrain.qd import shares

    folder, cfg = common.setup_run("shares", args, PRESETS, "default", overrides(args), check=check_config)
    shares.write_all(folder, load_archives(cfg), float(cfg["band_width"]))
    print(f"done -> {folder}", flush=True)
    return 0
