"""``python -m experiments export ARCHIVE.npz --cells 0,12 --format obj``: terrains of an archive as files.

Formats: ``obj`` and ``stl`` (triangle meshes through trimesh: one vertex per pixel, two triangles per cell, metres,
z up, centred on the origin as in MuJoCo; for Isaac Lab, Gazebo or Blender), ``png`` (16-bit grayscale, heightmap
units), ``npy`` (float32, heightmap units) and ``mjcf`` (a MuJoCo model with the terrain as an hfield, plus its
``.hfield.bin``). Every file is named ``cell<CELL>_<generator>.<ext>``; ``cells.csv`` lists cell, generator,
fitness, descriptors and file. Heightmaps come from the archive, or are rendered from its genomes when it stores
none.

Example::

    python -m experiments export runs/evolve-x/archive.npz --cells easy,hard,120 --format obj stl --out terrains/
"""

from __future__ import annotations

import argparse
from pathlib import Path

from experiments import common
from experiments.common import UsageError

FORMATS = ("obj", "stl", "png", "npy", "mjcf")
_EXT = {"obj": ".obj", "stl": ".stl", "png": ".png", "npy": ".npy", "mjcf": ".xml"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("archive", type=Path, metavar="ARCHIVE.npz", help="archive (jaxterrain.qd.save format)")
    parser.add_argument("--cells", default="easy,medium,hard",
                        help="comma-separated cell indices, 'easy' / 'medium' / 'hard' (highest, median, lowest "
                             "fitness) or 'all' (every filled cell)")
    parser.add_argument("--format", nargs="+", choices=FORMATS, default=["obj"], help="file format(s)")
    parser.add_argument("--out", type=Path, default=None, help="folder (default: <archive stem>_terrains beside it)")
    parser.add_argument("--cell-size", type=float, default=None,
                        help="metres between neighbouring pixels of the obj, stl and mjcf files (default 0.04)")
    parser.add_argument("--height", type=float, default=None,
                        help="metres for heightmap value 1.0 in the obj, stl and mjcf files (default 1.0)")


SCALED = ("obj", "stl", "mjcf")
"""The formats in metres (``--cell-size`` and ``--height`` apply); ``png`` and ``npy`` keep heightmap units."""


def parse_cells(text: str, arch) -> list[int]:
    """Cell indices from ``text`` (see ``--cells``); UsageError naming the problem."""
    import numpy as np

    from jaxterrain.report.archives import pick_cells

    filled = np.flatnonzero(arch.source >= 0)
    picks = pick_cells(arch.fitness[filled], filled)
    cells: list[int] = []
    for part in (p.strip() for p in text.split(",")):
        if not part:
            continue
        if part == "all":
            cells += filled.tolist()
        elif part in ("easy", "medium", "hard"):
            if part not in picks:
                raise UsageError(f"--cells {part}: the archive has too few elites ({filled.size})")
            cells.append(picks[part])
        else:
            try:
                c = int(part)
            except ValueError:
                raise UsageError(f"--cells: {part!r} is not a cell index, easy, medium, hard or all") from None
            if not 0 <= c < arch.fitness.shape[0]:
                raise UsageError(f"--cells: cell {c} is outside [0, {arch.fitness.shape[0] - 1}]")
            if arch.source[c] < 0:
                raise UsageError(f"--cells: cell {c} is empty")
            cells.append(c)
    if not cells:
        raise UsageError("--cells: no cell given")
    return list(dict.fromkeys(cells))  # unique, in order


def main(args: argparse.Namespace) -> int:
    import csv
    import io

    from jaxterrain import qd as A
    from jaxterrain import terrain as T
    from jaxterrain.runtime.io import atomic_write_text
    from jaxterrain.report.archives import elite_heightmaps

    if not set(args.format) & set(SCALED):  # png / npy only: the metres would be accepted and ignored
        common.refuse_given({"--cell-size": args.cell_size, "--height": args.height},
                            f"metres of the {', '.join(SCALED)} files; --format {' '.join(args.format)} writes "
                            f"heightmap units: drop it")
    try:
        scale = T.TerrainScale(0.04 if args.cell_size is None else args.cell_size,
                               1.0 if args.height is None else args.height)
    except ValueError as err:
        raise UsageError(str(err)) from None
    try:
        arch = A.load(args.archive)
    except (OSError, ValueError) as err:
        raise UsageError(f"cannot load {args.archive}: {err}") from None
    cells = parse_cells(args.cells, arch)
    out = args.out or args.archive.with_name(args.archive.stem + "_terrains")
    out.mkdir(parents=True, exist_ok=True)
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["cell", "generator", "fitness", *arch.config.descriptors, "file"])
    for s in range(0, len(cells), 64):
        part = cells[s:s + 64]
        for cell, hm in zip(part, elite_heightmaps(arch, part)):
            gen = arch.generator_names[int(arch.source[cell])]
            for fmt in args.format:
                path = out / f"cell{cell:04d}_{gen}{_EXT[fmt]}"
                if fmt == "obj":
                    T.save_obj(path, hm, scale)
                elif fmt == "stl":
                    T.save_stl(path, hm, scale)
                elif fmt == "png":
                    T.save_png(path, hm)
                elif fmt == "npy":
                    T.save_npy(path, hm)
                else:
                    T.save_mjcf(path, hm, scale, name=f"cell{cell}")
                w.writerow([cell, gen, f"{float(arch.fitness[cell]):.6g}",
                            *(f"{float(v):.6g}" for v in arch.descriptors[cell]), path.name])
    atomic_write_text(out / "cells.csv", buf.getvalue())
    print(f"wrote {len(cells)} terrain(s) x {len(args.format)} format(s) to {out} (cells.csv lists them)")
    return 0
