"""Stage 1 of a report: find what a run folder holds, by file type, whatever command wrote it.

    run = collect.scan("runs/evolve-20261122-101500")
    run.config, run.tables, run.figures, run.archives, run.texts, run.others

Every command writes ``config.json``, tables (CSV and Markdown), figures (PNG) and, for MAP-Elites runs,
archives (``.npz`` in the :mod:`jaxterrain.qd.archive` format) into its run folder, in sub-folders too (``coverage``
keeps one per treatment). Nothing here knows the commands: files are sorted by suffix, an ``.npz`` counts as an
archive when its header says so (a checkpoint does not), and the folder of an earlier report (marked by
:data:`MARKER`) is skipped, so a new run type shows up in a report without changes here.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import NamedTuple

from jaxterrain.qd import FORMAT

__all__ = ["RunFiles", "scan", "is_archive", "MARKER", "TABLE_SUFFIXES", "FIGURE_SUFFIXES", "TEXT_SUFFIXES"]

MARKER = ".jaxterrain-report"
"""File that marks a report's own output folder (skipped when scanning)."""

TABLE_SUFFIXES = (".csv", ".tsv", ".md")
FIGURE_SUFFIXES = (".png", ".jpg", ".jpeg", ".gif", ".svg", ".webp")
TEXT_SUFFIXES = (".json", ".txt", ".log", ".yaml", ".yml", ".toml")
TEXT_LIMIT = 64 * 1024  # larger text files are listed, not shown


class RunFiles(NamedTuple):
    """The files of one run folder (paths sorted, relative names via ``path.relative_to(root)``).

    Attributes:
      root: the run folder.
      config: the parsed ``config.json`` at its top (None if absent or unreadable).
      tables: CSV / TSV / Markdown files.
      figures: PNG / JPEG / GIF / SVG / WebP files.
      archives: ``.npz`` files in the jaxterrain archive format.
      texts: small text files (JSON other than the top config, logs, ...) shown verbatim.
      others: everything else (checkpoints, large files, binary data, the files of a policy folder), listed with
        sizes.
    """

    root: Path
    config: dict | None
    tables: list[Path]
    figures: list[Path]
    archives: list[Path]
    texts: list[Path]
    others: list[Path]

    @property
    def name(self) -> str:
        return self.root.name

    def rel(self, path: Path) -> str:
        return path.relative_to(self.root).as_posix()


def is_archive(path: Path) -> bool:
    """True when ``path`` is an ``.npz`` whose header names the jaxterrain archive format (only the header is
    read)."""
    import numpy as np

    try:
        with np.load(path, allow_pickle=False) as z:
            if "header" not in z.files:
                return False
            header = json.loads(bytes(z["header"]).decode("utf-8"))
    except Exception:  # noqa: BLE001 - not an npz, corrupt, not JSON: not an archive
        return False
    return isinstance(header, dict) and header.get("format") == FORMAT


def _skipped(path: Path, root: Path) -> bool:
    parts = path.relative_to(root).parts
    return any(p.startswith(".") or p == "__pycache__" for p in parts)


def scan(root: str | Path, exclude: tuple[str | Path, ...] = ()) -> RunFiles:
    """Sort the files under ``root`` (recursively) into a :class:`RunFiles`.

    Hidden files and folders, report folders (holding :data:`MARKER`) and the paths in ``exclude`` (e.g. the
    report being written) are skipped. Raises ``FileNotFoundError`` when ``root`` is not a folder.
    """
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"run folder not found: {root}")
    excluded = {Path(p).resolve() for p in exclude}
    report_dirs = {m.parent.resolve() for m in root.rglob(MARKER)}
    tables, figures, archives, texts, others = [], [], [], [], []
    config = None
    for path in sorted(root.rglob("*")):
        if not path.is_file() or _skipped(path, root):
            continue
        resolved = path.resolve()
        if any(d == resolved or d in resolved.parents for d in excluded | report_dirs):
            continue
        suffix = path.suffix.lower()
        if path.parent == root and path.name == "config.json":
            try:
                config = json.loads(path.read_text())
            except (OSError, json.JSONDecodeError, UnicodeDecodeError):
                texts.append(path)
            continue
        if (path.parent / "policy.msgpack").is_file():  # a walker's folder (policies/trial_K/): listed, not shown
            others.append(path)
        elif suffix in TABLE_SUFFIXES:
            tables.append(path)
        elif suffix in FIGURE_SUFFIXES:
            figures.append(path)
        elif suffix == ".npz" and is_archive(path):
            archives.append(path)
        elif suffix in TEXT_SUFFIXES and path.stat().st_size <= TEXT_LIMIT:
            texts.append(path)
        else:
            others.append(path)
    return RunFiles(root, config if isinstance(config, dict) else None, tables, figures, archives, texts, others)
