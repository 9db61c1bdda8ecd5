"""Real terrain: digital elevation models (DEMs) and random training patches cut from them.

    >>> from jaxterrain.terrain import dem
    >>> tiles = dem.load_tiles()                          # the built-in matplotlib DEMs
    >>> tiles = dem.load_tiles("my_dem_folder/")          # or your own GeoTIFF / .npy / .npz tiles
    >>> patches = dem.random_patches(key, tiles, 64)      # [64, 256, 256] float32, each in [0, 1]

Files (:func:`read_dem`): ``.tif`` / ``.tiff`` (GeoTIFF, read with ``tifffile``; the ``GDAL_NODATA`` value and
non-finite values are no-data), ``.npy`` (one 2-D array) and ``.npz`` (the array named ``elevation`` if there is
one, else the only array of 2 or more non-singleton dimensions in it). Singleton axes are dropped (a one-band
GeoTIFF read as ``[1, H, W]`` is fine); anything else that is not 2-D is refused. No-data cells are filled with the
tile's lowest valid elevation. Units do not matter (every patch is normalised on its own), but the cells should be
square.

The built-in data set (:func:`builtin_dems`) is the real DEM that ships with matplotlib, so it works offline:
``jacksboro_fault_dem.npz`` (344 x 403 cells, int16 metres, ~90 m cells) and the land part of ``topobathy.npz``
(91 x 120; the sea floor, elevation <= 0, is set to sea level 0 m). It is SMALL - two tiles, against the paper's
30 000 OpenTopography patches - and both tiles are smaller than the 256 x 256 output: patches are crops of 64 to
256 cells (only the crop sizes that fit in the tile are used) resampled to ``size x size``; crops smaller than the
output are upsampled (smooth, no new detail). Train on your own tiles with
``python -m experiments train-gan --data DIR``.

Patches (:func:`random_patches`) are pure JAX and jit-able (the tiles are data, not constants): a tile is drawn
with probability proportional to its area, a crop side uniformly among ``scales`` that fit in that tile, a crop
position uniformly; the crop is resampled with ``jax.image.scale_and_translate`` (the function behind
``jax.image.resize``; linear, antialiased) to ``size x size``, flipped with probability 1/2 and rotated by a random
multiple of 90 degrees (the 8 symmetries of the square), and then min-max normalised to [0, 1] PER PATCH:
``(z - min) / (max - min)``. This keeps the shape of the relief and discards its absolute height range (metres); a
flat patch (range < 1e-6 of the tile's units) becomes all zeros.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Iterable, NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np

DEFAULT_SCALES: tuple[int, ...] = (64, 96, 128, 192, 256)
DEM_EXTENSIONS: tuple[str, ...] = (".tif", ".tiff", ".npy", ".npz")


class DemTiles(NamedTuple):
    """A stack of DEM tiles of different sizes, padded to a common shape (a pytree of two arrays).

    Attributes:
      data: ``[T, Hmax, Wmax]`` float32 elevations; tile ``t`` occupies ``data[t, :H_t, :W_t]``, the rest is
        edge padding (never sampled).
      sizes: ``[T, 2]`` int32, ``(H_t, W_t)`` of each tile.
    """

    data: jax.Array
    sizes: jax.Array


# ----------------------------------------------------------------------------------------------------------------
# Reading and checking files
# ----------------------------------------------------------------------------------------------------------------


def check_dem(z: np.ndarray, name: str, min_size: int = 1) -> np.ndarray:
    """Validate one elevation array and return it as float32 ``[H, W]`` with no-data (NaN/inf) filled.

    Raises ``ValueError`` naming ``name`` when it is not 2-D (after dropping singleton axes), has no finite value,
    is constant, or is smaller than ``min_size`` cells on a side.
    """
    z = np.asarray(z)
    if z.ndim != 2:
        z = np.squeeze(z)
    if z.ndim != 2:
        raise ValueError(f"DEM {name}: elevation must be a 2-D array [H, W]; got shape {tuple(np.shape(z))}")
    if not (np.issubdtype(z.dtype, np.number) or z.dtype == bool) or np.iscomplexobj(z):
        raise ValueError(f"DEM {name}: elevation must be real numbers; got dtype {z.dtype}")
    z = z.astype(np.float32)
    h, w = z.shape
    if min(h, w) < min_size:
        raise ValueError(
            f"DEM {name}: {h} x {w} cells is too small; every side must be >= {min_size} cells "
            f"(the smallest crop size)"
        )
    finite = np.isfinite(z)
    if not finite.any():
        raise ValueError(f"DEM {name}: every cell is NaN / no-data; there is no elevation to learn from")
    lo, hi = float(z[finite].min()), float(z[finite].max())
    if not hi > lo:
        raise ValueError(f"DEM {name}: elevation is constant ({lo:g} everywhere); it has no relief")
    if not finite.all():
        z = np.where(finite, z, lo).astype(np.float32)
    return z


def _read_tiff(path: Path) -> np.ndarray:
    import tifffile

    with tifffile.TiffFile(path) as tif:
        z = tif.asarray()
        nodata = None
        tag = tif.pages[0].tags.get("GDAL_NODATA")
        if tag is not None:
            try:
                nodata = float(str(tag.value).strip().strip("\x00"))
            except ValueError:
                nodata = None
    if nodata is not None and np.issubdtype(np.asarray(z).dtype, np.number):
        z = np.asarray(z, np.float32)
        z = np.where(z == np.float32(nodata), np.nan, z)
    return z


def _read_npz(path: Path) -> np.ndarray:
    with np.load(path, allow_pickle=False) as f:
        keys = list(f.keys())
        if "elevation" in keys:
            return f["elevation"]
        grids = [k for k in keys if np.squeeze(f[k]).ndim >= 2]
        if len(grids) == 1:
            return f[grids[0]]
    raise ValueError(
        f"DEM {path}: cannot tell which array is the elevation; name it 'elevation' or keep exactly one "
        f"grid (array of >= 2 non-singleton dimensions) in the .npz (arrays: {', '.join(keys) or 'none'})"
    )


def read_elevation(path: str | os.PathLike) -> np.ndarray:
    """Read one DEM file (``.tif``/``.tiff``, ``.npy``, ``.npz``) as it is stored, unchecked: the array (any shape and
    dtype; a GeoTIFF's ``GDAL_NODATA`` cells as NaN). :func:`read_dem` checks it; ``suite.folder`` reads terrains
    with it. Raises ``ValueError`` naming the file for an unknown extension, a missing or unreadable file."""
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in DEM_EXTENSIONS:
        raise ValueError(f"DEM {path}: unknown extension {ext or '(none)'!r}; use one of {', '.join(DEM_EXTENSIONS)}")
    if not path.is_file():
        raise ValueError(f"DEM {path}: no such file")
    try:
        if ext in (".tif", ".tiff"):
            return _read_tiff(path)
        if ext == ".npy":
            return np.load(path, allow_pickle=False)
        return _read_npz(path)
    except ValueError as err:
        if str(err).startswith(f"DEM {path}"):
            raise
        raise ValueError(f"DEM {path}: unreadable {ext} file ({err})") from err
    except Exception as err:  # corrupt file: tifffile / zipfile / numpy raise many different types
        raise ValueError(f"DEM {path}: unreadable {ext} file ({type(err).__name__}: {err})") from err


def read_dem(path: str | os.PathLike, min_size: int = 1) -> np.ndarray:
    """Read one DEM file (``.tif``/``.tiff``, ``.npy``, ``.npz``) as float32 ``[H, W]``, checked by :func:`check_dem`.

    Raises ``ValueError`` naming the file for an unknown extension, an unreadable file or bad content.
    """
    return check_dem(read_elevation(path), str(Path(path)), min_size)


def builtin_dems() -> list[tuple[str, np.ndarray]]:
    """The real DEMs that ship with matplotlib, as ``(name, [H, W] float32 metres)``.

    ``jacksboro_fault_dem.npz`` (key ``elevation``, 344 x 403) and the land part of ``topobathy.npz`` (key
    ``topo``, 91 x 120; cells at or below sea level set to 0 m).
    """
    from matplotlib import cbook

    jacksboro = cbook.get_sample_data("jacksboro_fault_dem.npz")["elevation"]
    topo = cbook.get_sample_data("topobathy.npz")["topo"]
    land = np.maximum(np.asarray(topo, np.float32), 0.0)
    return [
        ("matplotlib:jacksboro_fault_dem.npz", check_dem(jacksboro, "jacksboro_fault_dem.npz")),
        ("matplotlib:topobathy.npz[land]", check_dem(land, "topobathy.npz (land)")),
    ]


def _expand_sources(source: str | os.PathLike | Iterable) -> list:
    if isinstance(source, (str, os.PathLike)):
        path = Path(source)
        if path.is_dir():
            files = sorted(p for p in path.rglob("*") if p.is_file() and p.suffix.lower() in DEM_EXTENSIONS)
            if not files:
                raise ValueError(f"DEM folder {path}: no {', '.join(DEM_EXTENSIONS)} files in it")
            return files
        return [path]
    return list(source)


def load_dems(
    source: str | os.PathLike | Iterable | None = None, min_size: int = DEFAULT_SCALES[0]
) -> list[tuple[str, np.ndarray]]:
    """DEM arrays ``[(name, [H, W] float32), ...]`` from ``source``.

    Args:
      source: ``None`` for the built-in matplotlib DEMs; a folder (searched recursively for .tif/.tiff/.npy/.npz);
        one file; or a list of files and/or 2-D arrays.
      min_size: the smallest allowed side in cells (the smallest crop); smaller tiles raise ``ValueError``.
    """
    if source is None:
        out = builtin_dems()
        for name, z in out:
            check_dem(z, name, min_size)
        return out
    out = []
    for i, item in enumerate(_expand_sources(source)):
        if isinstance(item, (str, os.PathLike)):
            out.append((str(item), read_dem(item, min_size)))
        else:
            out.append((f"array #{i}", check_dem(item, f"array #{i}", min_size)))
    if not out:
        raise ValueError("DEM source: the list of tiles is empty")
    return out


def stack_tiles(arrays: Sequence[np.ndarray]) -> DemTiles:
    """Pad 2-D arrays (edge mode) to a common shape and stack them into :class:`DemTiles`."""
    if len(arrays) == 0:
        raise ValueError("tiles: need at least one 2-D array")
    arrays = [check_dem(a, f"tile #{i}") for i, a in enumerate(arrays)]
    hmax = max(a.shape[0] for a in arrays)
    wmax = max(a.shape[1] for a in arrays)
    data = np.stack([np.pad(a, ((0, hmax - a.shape[0]), (0, wmax - a.shape[1])), mode="edge") for a in arrays])
    sizes = np.array([a.shape for a in arrays], np.int32)
    return DemTiles(jnp.asarray(data, jnp.float32), jnp.asarray(sizes))


def load_tiles(source: str | os.PathLike | Iterable | None = None, min_size: int = DEFAULT_SCALES[0]) -> DemTiles:
    """:func:`load_dems` then :func:`stack_tiles`: the tiles as device arrays, ready for :func:`random_patches`."""
    return stack_tiles([z for _, z in load_dems(source, min_size)])


# ----------------------------------------------------------------------------------------------------------------
# Random patches
# ----------------------------------------------------------------------------------------------------------------


def normalise(patches: jax.Array, eps: float = 1e-6) -> jax.Array:
    """Min-max normalise each map of ``[..., H, W]`` to [0, 1]; a flat map (range < ``eps``) becomes zeros."""
    lo = patches.min(axis=(-2, -1), keepdims=True)
    hi = patches.max(axis=(-2, -1), keepdims=True)
    rng = hi - lo
    return jnp.where(rng > eps, (patches - lo) / jnp.maximum(rng, eps), 0.0)


def dihedral(image: jax.Array, flip: jax.Array, turns: jax.Array) -> jax.Array:
    """One of the 8 symmetries of a square ``[S, S]`` map: a left-right flip (if ``flip``) then ``turns`` x 90 deg."""
    image = jnp.where(flip, image[:, ::-1], image)
    rotations = jnp.stack([jnp.rot90(image, k) for k in range(4)])
    return rotations[turns % 4]


def _one_patch(key, data, sizes, size, scales, augment):
    tile_key, scale_key, y_key, x_key, flip_key, turn_key = jax.random.split(key, 6)
    del key
    hw = sizes.astype(jnp.float32)
    area = hw[:, 0] * hw[:, 1]
    t = jax.random.categorical(tile_key, jnp.log(area))
    h, w = hw[t, 0], hw[t, 1]
    scales_arr = jnp.asarray(scales, jnp.float32)
    fits = scales_arr <= jnp.minimum(h, w)
    # at least the smallest scale fits (checked on the host when loading)
    c = scales_arr[jax.random.categorical(scale_key, jnp.where(fits, 0.0, -jnp.inf))]
    y0 = jnp.floor(jax.random.uniform(y_key) * (h - c + 1.0))
    x0 = jnp.floor(jax.random.uniform(x_key) * (w - c + 1.0))
    s = size / c
    patch = jax.image.scale_and_translate(
        data[t], (size, size), (0, 1), jnp.stack([s, s]), jnp.stack([-y0 * s, -x0 * s]), "linear", antialias=True
    )
    if augment:
        patch = dihedral(patch, jax.random.bernoulli(flip_key), jax.random.randint(turn_key, (), 0, 4))
    return normalise(patch)


def random_patches(
    key: jax.Array,
    tiles: DemTiles | Sequence[np.ndarray],
    n: int,
    size: int = 256,
    scales: Sequence[int] = DEFAULT_SCALES,
    augment: bool = True,
) -> jax.Array:
    """``n`` random training patches ``[n, size, size]`` float32, each min-max normalised to [0, 1].

    Args:
      key: PRNG key.
      tiles: :class:`DemTiles` (from :func:`load_tiles`) or a list of 2-D arrays.
      n, size: number of patches and their side in pixels (static).
      scales: crop sides in tile cells (static); for each patch one of those that fit in its tile is drawn
        uniformly, so crops of several scales are mixed. Every tile must fit the smallest.
      augment: random flips and 90-degree rotations (the 8 symmetries of the square).

    Pure and jit-able (``n``, ``size``, ``scales``, ``augment`` static); host-side checks run on concrete tiles.
    """
    if not isinstance(tiles, DemTiles):
        tiles = stack_tiles(tiles)
    if int(n) < 1 or int(size) < 1:
        raise ValueError(f"random_patches: n and size must be >= 1; got n={n}, size={size}")
    scales = tuple(int(s) for s in scales)
    if not scales or min(scales) < 2:
        raise ValueError(f"random_patches: scales must be crop sides >= 2 cells; got {scales}")
    if not isinstance(tiles.sizes, jax.core.Tracer):
        smallest = int(np.asarray(tiles.sizes).min())
        if smallest < min(scales):
            raise ValueError(
                f"random_patches: a tile has a side of {smallest} cells, smaller than the smallest crop "
                f"scales={scales}; pass smaller scales or drop the tile"
            )
    keys = jax.random.split(key, int(n))
    del key
    return jax.vmap(lambda k: _one_patch(k, tiles.data, tiles.sizes, int(size), scales, bool(augment)))(keys)


__all__ = [
    "read_elevation",
    "DEFAULT_SCALES",
    "DemTiles",
    "builtin_dems",
    "check_dem",
    "dihedral",
    "load_dems",
    "load_tiles",
    "normalise",
    "random_patches",
    "read_dem",
    "stack_tiles",
]
