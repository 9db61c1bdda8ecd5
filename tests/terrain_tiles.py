"""A folder of small heightmaps of every kind ``jaxterrain.suite.folder`` reads, for the tests of your own terrains
(``tests/suite/test_folder.py``, ``tests/curriculum/test_terrains.py``)."""

from pathlib import Path

import numpy as np
import tifffile
from PIL import Image


def write_tiles(folder: Path) -> Path:
    """Four small heightmaps of every kind, none square: a .npy ramp in metres (0.3 m), an 8-bit PNG, a 16-bit PNG
    and a GeoTIFF in metres with 40 m of relief (a DEM: it needs a terrain height). Returns ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    y, x = np.mgrid[0:40, 0:50].astype(np.float32)
    np.save(folder / "a_ramp.npy", 0.3 * x / 49.0)
    Image.fromarray((255 * (x / 49.0)).astype(np.uint8)).save(folder / "b_grey8.png")
    Image.fromarray((65535 * (y / 39.0)).astype(np.uint16)).save(folder / "c_grey16.png")
    tifffile.imwrite(folder / "d_dem.tif", (100.0 + 20.0 * np.sin(x / 8.0) * np.cos(y / 8.0)).astype(np.float32))
    return folder
