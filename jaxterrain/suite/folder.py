"""Your own terrains: a folder of heightmap files read into the walker's terrains, for ``learn --terrains DIR`` (a
curriculum bank) and ``evaluate --terrains DIR`` (a suite with one family per file).

    from jaxterrain import suite
    folder = suite.load_folder("my_tiles/")               # TerrainFolder: names, heightmaps [N, 256, 256] m
    folder = suite.load_folder("my_pngs/", height=0.5)    # images: grey 0..1 -> 0..0.5 m
    s = suite.folder_suite(folder)                        # a Suite: family = file name, one level each
    bank = suite.folder_bank(folder, suite.name_order(folder))   # a qd.TerrainBank; hardness = rank in the order

Files (the folder itself, not its sub-folders; other extensions are not read, and said so by :func:`load_folder`'s
``skipped``): ``.png`` (8- or 16-bit greyscale: grey 0..1 of the full range, 255 or 65535), and what
:func:`jaxterrain.terrain.dem.read_elevation` reads: ``.tif`` / ``.tiff`` (GeoTIFF, metres), ``.npy`` (a 2-D array,
metres), ``.npz`` (the array ``elevation``, or its only grid; metres). Each file is one terrain, in file-name order.

From file to terrain (:func:`fit_terrain`), each step chosen so the walker sees the file's relief and starts on flat
ground:

1. heights: an image's grey ``g`` in [0, 1] becomes ``g x height`` metres (``height`` default 1.0 m); a metre file
   keeps its metres, or, with ``height`` given, is rescaled to span ``[0, height]`` (min to 0, max to ``height``: how
   a DEM with hundreds of metres of relief becomes a walkable 10 m tile). Then every terrain is shifted so that its
   lowest cell is 0 m (the walker's heights are clipped to ``[0, scale.height]``, 1 m).
2. shape: the largest centred square is cropped (the longer side loses equal margins) and resized to ``side x side``
   cells (default :data:`TERRAIN_SIDE`, 256: the archives' side, 10.2 m at 4 cm a cell) with Pillow's bilinear filter
   (antialiased when shrinking). The file's own cell size is not kept: the tile becomes the walker's 10.2 m square.
3. start strip: the walker starts 0.5 m from the edge (``WalkerConfig.start_margin``); as in the held-out suite
   (:data:`~jaxterrain.suite.families.START_STRIP`), the :data:`START_STRIP` metres along every edge are flat at 0 m
   and the relief fades in linearly over the next :data:`STRIP_FADE` metre (heights x ``clip((d - 1 m) / 1 m, 0,
   1)``, ``d`` a cell's distance to the nearest edge: :func:`~jaxterrain.suite.families.edge_distance`).

Refused with one line naming the file (``ValueError``; the command line exits 2 before any run folder): a missing or
empty folder, an unreadable file, an image that is not greyscale, an array that is not 2-D or has a side below 2
cells, NaN / infinite / no-data cells (fill them first), a terrain whose relief after step 1 exceeds the walker's
``scale.height`` (1 m: give ``height``), a ``height`` outside ``(0, scale.height]``.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import NamedTuple, Optional

import numpy as np

from jaxterrain.qd.bank import TerrainBank, from_heightmaps
from jaxterrain.suite.families import START_STRIP, edge_distance
from jaxterrain.suite.heldout import Suite
from jaxterrain.terrain import TerrainScale, validate_scale
from jaxterrain.terrain.dem import DEM_EXTENSIONS, read_elevation

__all__ = ["TERRAIN_SIDE", "STRIP_FADE", "IMAGE_HEIGHT", "EXTENSIONS", "TerrainFolder", "read_terrain",
           "fit_terrain", "load_folder", "folder_suite", "folder_bank", "name_order", "difficulty_order",
           "ORDERS"]

TERRAIN_SIDE = 256
"""Cells on a side of a folder's terrains (the archives' side: 10.2 m at 4 cm a cell)."""
STRIP_FADE = 1.0
"""Metres past the flat start strip over which a terrain's relief fades in (the suite's ``waves`` family's too)."""
IMAGE_HEIGHT = 1.0
"""Metres of an image's full grey (value 1) when no ``height`` is given: the walker's whole height range."""
EXTENSIONS = (".png",) + DEM_EXTENSIONS
"""The file types read: PNG images and what ``terrain.dem`` reads (GeoTIFF, .npy, .npz)."""
ORDERS = ("name", "difficulty")
"""How a folder's terrains are ranked by hardness: file-name order, or the base policy's fitness (hardest last)."""


class TerrainFolder(NamedTuple):
    """A folder's terrains, read and checked (host arrays).

    Attributes:
      path: the folder, as given.
      names: [N] file names, sorted (the terrains' order).
      heightmaps: [N, S, S] float32 metres in ``[0, scale.height]``, start strips flat at 0.
      relief: [N] float32 metres, each terrain's max - min after step 1 (before the strip).
      files_sha256: [N] sha256 (hex) of each file's bytes.
      digest: sha256 (hex) of the names, the files' digests, ``height`` and ``side``: what the terrains were made of.
      height: the ``height`` they were read with (None: images at :data:`IMAGE_HEIGHT`, metre files as they are).
      skipped: files in the folder of other extensions (not read).
    """

    path: str
    names: tuple
    heightmaps: np.ndarray
    relief: np.ndarray
    files_sha256: tuple
    digest: str
    height: Optional[float]
    skipped: tuple

    @property
    def size(self) -> int:
        """N, the number of terrains."""
        return len(self.names)


def _read_png(path: Path) -> np.ndarray:
    """[H, W] float32 grey in [0, 1] of an 8- or 16-bit greyscale PNG; ValueError naming the file otherwise."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            mode = im.mode
            a = np.asarray(im)
    except (OSError, UnidentifiedImageError) as err:
        raise ValueError(f"terrain {path}: unreadable .png file ({err})") from None
    if mode == "L":
        return a.astype(np.float32) / 255.0
    if mode in ("I;16", "I;16B", "I;16L", "I"):
        return a.astype(np.float32) / 65535.0
    raise ValueError(f"terrain {path}: a PNG heightmap must be 8- or 16-bit greyscale (mode L or I;16); got mode "
                     f"{mode}")


def read_terrain(path, height: Optional[float] = None) -> np.ndarray:
    """Step 1 of the module docstring: ``[H, W]`` float32 metres, lowest cell 0, of one file; ``ValueError`` naming
    the file (unreadable, not 2-D, a side below 2 cells, non-finite cells)."""
    path = Path(path)
    image = path.suffix.lower() == ".png"
    try:
        z = _read_png(path) if image else read_elevation(path)
    except ValueError as err:
        raise ValueError(str(err).replace("DEM ", "terrain ", 1)) from None
    z = np.asarray(z)
    if z.ndim != 2:
        z = np.squeeze(z)
    if z.ndim != 2:
        raise ValueError(f"terrain {path}: a heightmap is a 2-D array [H, W]; got shape {np.shape(z)}")
    if not np.issubdtype(z.dtype, np.number) or np.iscomplexobj(z):
        raise ValueError(f"terrain {path}: heights must be real numbers; got dtype {z.dtype}")
    if min(z.shape) < 2:
        raise ValueError(f"terrain {path}: {z.shape[0]} x {z.shape[1]} cells; each side must be >= 2")
    z = z.astype(np.float32)
    bad = int(np.sum(~np.isfinite(z)))
    if bad:
        raise ValueError(f"terrain {path}: {bad} NaN / infinite / no-data cells; fill them (e.g. with the lowest "
                         f"elevation) or crop them out")
    z = z - z.min()
    if image:
        return z * np.float32(IMAGE_HEIGHT if height is None else height)
    if height is not None:
        span = float(z.max())
        return z * np.float32(height / span) if span > 0 else z
    return z


def fit_terrain(z: np.ndarray, side: int = TERRAIN_SIDE, scale: TerrainScale = TerrainScale()) -> np.ndarray:
    """Steps 2 and 3 of the module docstring: ``[side, side]`` float32 metres of ``z`` [H, W] metres: the centred
    square, resized bilinearly, its edges' :data:`START_STRIP` flat at 0 and the relief faded in over
    :data:`STRIP_FADE`."""
    from PIL import Image

    h, w = z.shape
    n = min(h, w)
    top, left = (h - n) // 2, (w - n) // 2
    square = np.ascontiguousarray(z[top:top + n, left:left + n], np.float32)
    if n != side:
        square = np.asarray(Image.fromarray(square).resize((side, side), Image.Resampling.BILINEAR), np.float32)
    ramp = np.clip((edge_distance(side, scale) - START_STRIP) / STRIP_FADE, 0.0, 1.0).astype(np.float32)
    return np.maximum(square, 0.0) * ramp


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def load_folder(path, height: Optional[float] = None, side: int = TERRAIN_SIDE,
                scale: TerrainScale = TerrainScale()) -> TerrainFolder:
    """Every terrain file of folder ``path`` (module docstring) as a :class:`TerrainFolder` at ``side`` cells and
    ``scale`` (the walker's: 4 cm cells, heights clipped at ``scale.height``). ``ValueError``, one line naming the
    folder or file, for what the module docstring lists."""
    scale = validate_scale(scale)
    top = float(scale.height)
    if height is not None and (isinstance(height, bool) or not isinstance(height, (int, float))
                               or not np.isfinite(height) or not 0 < height <= top):
        raise ValueError(f"terrain height must be a number of metres in (0, {top:g}] (the walker's heights end at "
                         f"{top:g} m); got {height!r}")
    folder = Path(path)
    if not folder.is_dir():
        raise ValueError(f"terrains {path}: no such folder")
    files = sorted(p for p in folder.iterdir() if p.is_file())
    read = [p for p in files if p.suffix.lower() in EXTENSIONS]
    skipped = tuple(p.name for p in files if p.suffix.lower() not in EXTENSIONS)
    if not read:
        raise ValueError(f"terrains {path}: no heightmap files in it (it needs {', '.join(EXTENSIONS)} files)")
    maps, relief = [], []
    for p in read:
        z = read_terrain(p, height)
        span = float(z.max())
        if span > top + 1e-6:
            raise ValueError(f"terrain {p}: its relief is {span:.4g} m, more than the walker's {top:g} m (heights are "
                             f"clipped there); give a terrain height M <= {top:g} to rescale each terrain's relief "
                             f"to M metres")
        maps.append(fit_terrain(z, side, scale))
        relief.append(span)
    sums = tuple(_sha256(p) for p in read)
    names = tuple(p.name for p in read)
    digest = hashlib.sha256(json.dumps({"names": names, "files": sums, "height": height, "side": side,
                                        "scale": [float(scale.cell_size), top]}).encode()).hexdigest()
    return TerrainFolder(os.fspath(path), names, np.stack(maps), np.asarray(relief, np.float32), sums, digest, height,
                         skipped)


def folder_suite(folder: TerrainFolder, scale: TerrainScale = TerrainScale()) -> Suite:
    """The folder's terrains as a suite (``evaluate --terrains``): one family per file (its name), one level (0),
    one seed, ``value`` its relief in metres; heightmaps in [0, 1] at ``scale``."""
    n = folder.size
    maps = np.clip(folder.heightmaps / np.float32(scale.height), 0.0, 1.0).astype(np.float32)
    return Suite(f"terrains {folder.path} ({n} files)", maps, np.asarray(folder.names), np.zeros(n, np.int64),
                 np.zeros(n, np.int64), folder.relief.astype(np.float64), {name: "m relief" for name in folder.names},
                 scale, {}, {})


def name_order(folder: TerrainFolder) -> np.ndarray:
    """[N] float32 hardness: each terrain's rank in file-name order (0 = the first name, the easiest)."""
    return np.arange(folder.size, dtype=np.float32)


def difficulty_order(fitness) -> np.ndarray:
    """[N] float32 hardness from the base policy's fitness [N] (in [0, 1]): each terrain's rank by decreasing
    fitness (0 = the one it walks farthest on; ties in file-name order)."""
    f = np.asarray(fitness, np.float64)
    order = np.lexsort((np.arange(f.size), -f))
    rank = np.empty(f.size, np.float32)
    rank[order] = np.arange(f.size, dtype=np.float32)
    return rank


def folder_bank(folder: TerrainFolder, hardness, fitness=None) -> TerrainBank:
    """The folder's terrains as a curriculum bank (:func:`jaxterrain.qd.bank.from_heightmaps`): heightmaps in metres,
    ``distance`` = ``hardness`` [N] (the rank of :func:`name_order` or :func:`difficulty_order`: ``levels`` bands
    and the run's "hardest terrain traversed" read it), ``fitness`` the base policy's where measured (else zeros),
    ``source`` the file's index (``sequences.csv``'s ``generator`` column names the file)."""
    return from_heightmaps(folder.heightmaps, hardness, fitness)
