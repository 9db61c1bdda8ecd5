"""Heightmap <-> physical terrain: scale to metres, MuJoCo hfield geometry, and exports (PNG, .npy, MJCF, and triangle
meshes as OBJ / STL through trimesh, for Isaac Lab, Gazebo or Blender).

A heightmap is a float array ``[H, W]`` (``[B, H, W]`` for batches), generators give values in ``[0, 1]``.
:class:`TerrainScale` maps it to metres:

- ``cell_size`` (default 0.04 m): distance between neighbouring pixels. A 256-pixel map spans 255 * 0.04 = 10.20 m
  between its first and last sample (10.24 m counting each pixel as a 4 cm cell). Chosen so that a humanoid's foot
  (brax humanoid: sphere of radius 0.075 m) covers a few cells - MJX's hfield collision cost grows with the number
  of cells under a geom - and so that Algorithm 1's 26-pixel window is ~1 m (26 * 0.04 = 1.04 m), about one step.
- ``height`` (default 1.0 m): metres for heightmap value 1.0 (value 0 is z = 0). Calibrated against the shipped
  base policy (``python -m experiments difficulty-spread --heights 0.25 0.5 1.0 --n 12``, 2026-11-21, CPU; table in
  docs/calibration.md): the share of random terrains whose fitness falls in [0.1, 0.9], averaged over the five
  generators, was 27 % at 0.25 m, 55 % at 0.5 m and 72 % at 1.0 m. At 1.0 m, Perlin, GAN, diamond-square and Worley
  terrains all spread (medians 0.15, 0.18, 0.67, 0.70); random CPPN genomes are smooth at any height scale (their
  hard terrains come from evolution). At 1.0 m Algorithm 1 (threshold = humanoid height / 3 = 0.52 m within a
  1.04 m window) can reject terrains; at 0.5 m it never could.

Both are configurable and must be > 0.

MuJoCo mapping (single source of truth: :func:`hfield_size`): heightmap row ``i`` is hfield row ``i`` (MuJoCo's
row 0 lies at ``y = -radius_y``, rows go towards +y), column ``j`` is hfield column ``j`` (towards +x); the hfield is
centred on its geom's position. Writing ``heightmap`` (values in heightmap units) into ``model.hfield_data`` of an
hfield of size ``hfield_size(shape, scale)`` gives surface heights ``heightmap * scale.height`` metres above the
geom's z. Sample ``(i, j)`` lies at ``x = -radius_x + j * cell_size``, ``y = -radius_y + i * cell_size``.

Meshes (:func:`to_mesh`, :func:`save_obj`, :func:`save_stl`) use the same placement: one vertex per pixel at
``(x, y, heightmap * scale.height)`` metres (centred on the origin, as the hfield), two triangles per cell with normals
towards +z; the surface only (no skirt or bottom), as terrain importers expect.
"""

from __future__ import annotations

import io
import numbers
import os
from pathlib import Path
from typing import NamedTuple, Sequence

import jax.numpy as jnp
import numpy as np

from jaxterrain.io import atomic_write_bytes, atomic_write_text

__all__ = [
    "TerrainScale",
    "validate_scale",
    "to_metres",
    "hfield_size",
    "save_png",
    "load_png",
    "save_npy",
    "load_npy",
    "save_mjcf",
    "mesh_arrays",
    "to_mesh",
    "save_obj",
    "save_stl",
]

_PNG_MAX = 65535


class _TerrainScaleFields(NamedTuple):
    cell_size: float = 0.04
    height: float = 1.0


def _check_positive(name: str, value) -> None:
    # Only concrete numbers are checked: JAX may rebuild the tuple with tracers or placeholders (pytree unflatten).
    if isinstance(value, numbers.Real) or (isinstance(value, np.ndarray) and value.ndim == 0):
        v = float(value)
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"TerrainScale.{name} must be a finite number of metres > 0; got {value!r}")


class TerrainScale(_TerrainScaleFields):
    """Physical scale of a heightmap (a NamedTuple, hence a pytree).

    Attributes:
      cell_size: metres between neighbouring pixels (> 0), default 0.04.
      height: metres for heightmap value 1.0 (> 0), default 1.0.
    """

    __slots__ = ()

    def __new__(cls, cell_size: float = 0.04, height: float = 1.0):
        _check_positive("cell_size", cell_size)
        _check_positive("height", height)
        return super().__new__(cls, cell_size, height)


def validate_scale(scale) -> TerrainScale:
    """Raise ``ValueError`` unless ``scale`` is a :class:`TerrainScale` with positive (concrete) fields."""
    if not isinstance(scale, _TerrainScaleFields):
        raise ValueError(f"scale must be a jaxterrain.terrain.TerrainScale; got {type(scale).__name__}")
    for name in ("cell_size", "height"):
        value = getattr(scale, name)
        numeric = isinstance(value, numbers.Real) or (hasattr(value, "dtype") and getattr(value, "ndim", 1) == 0
                                                     and np.issubdtype(np.dtype(value.dtype), np.number))
        if not numeric or isinstance(value, bool):
            raise ValueError(f"TerrainScale.{name} must be a finite number of metres > 0; got {value!r}")
    _check_positive("cell_size", scale.cell_size)
    _check_positive("height", scale.height)
    return scale


def to_metres(heightmaps, scale: TerrainScale = TerrainScale()):
    """Heights in metres: ``heightmaps * scale.height``, same shape (``[B, H, W]`` or ``[H, W]``) float32."""
    validate_scale(scale)
    return jnp.asarray(heightmaps, jnp.float32) * jnp.float32(scale.height)


def hfield_size(shape: Sequence[int], scale: TerrainScale = TerrainScale(), base: float = 0.1):
    """MuJoCo ``<hfield size="radius_x radius_y elevation_z base_z">`` for a heightmap of ``shape`` (``[..., H, W]``).

    ``nrow = H``, ``ncol = W``; ``radius_x = (W - 1) * cell_size / 2`` and ``radius_y = (H - 1) * cell_size / 2`` so
    that neighbouring samples are exactly ``cell_size`` apart; ``elevation_z = scale.height`` so hfield data in
    heightmap units (``[0, 1]``) become metres; ``base_z = base`` (metres of solid box below z = 0, > 0).

    Returns:
      ``(radius_x, radius_y, elevation_z, base_z)`` Python floats.
    """
    validate_scale(scale)
    if len(shape) < 2 or int(shape[-1]) < 2 or int(shape[-2]) < 2:
        raise ValueError(f"shape must be [..., H, W] with H, W >= 2; got {tuple(shape)}")
    if not (np.isfinite(base) and base > 0):
        raise ValueError(f"base must be a finite number of metres > 0; got {base!r}")
    nrow, ncol = int(shape[-2]), int(shape[-1])
    return (
        (ncol - 1) * float(scale.cell_size) / 2.0,
        (nrow - 1) * float(scale.cell_size) / 2.0,
        float(scale.height),
        float(base),
    )


def _single_map(heightmap, name: str = "heightmap") -> np.ndarray:
    h = np.asarray(heightmap, dtype=np.float64)
    if h.ndim != 2 or h.shape[0] < 2 or h.shape[1] < 2:
        raise ValueError(f"{name} must be one [H, W] map with H, W >= 2; got shape {h.shape}")
    if not np.all(np.isfinite(h)):
        raise ValueError(f"{name} must be finite (no NaN / inf)")
    return h


# ----------------------------------------------------------------------------------------------------------------
# PNG / npy


def save_png(path: str | os.PathLike, heightmap) -> Path:
    """Write one ``[H, W]`` heightmap with values in ``[0, 1]`` as a 16-bit grayscale PNG (Pillow mode ``I;16``):
    pixel = ``round(value * 65535)``. Atomic. Returns the path."""
    from PIL import Image

    h = _single_map(heightmap)
    if h.min() < 0.0 or h.max() > 1.0:
        raise ValueError(
            f"heightmap values must be in [0, 1] for a 16-bit PNG; got [{h.min():.6g}, {h.max():.6g}] "
            "(save_npy keeps any float range)"
        )
    u16 = np.round(h * _PNG_MAX).astype(np.uint16)
    img = Image.fromarray(u16)
    if img.mode != "I;16":
        img = img.convert("I;16")
    buf = io.BytesIO()
    img.save(buf, format="PNG")
    return atomic_write_bytes(path, buf.getvalue())


def load_png(path: str | os.PathLike) -> np.ndarray:
    """Read a grayscale PNG written by :func:`save_png` (or any 8/16-bit grayscale PNG) -> ``[H, W]`` float32 in
    ``[0, 1]`` (16-bit: value / 65535; 8-bit: value / 255)."""
    from PIL import Image

    with Image.open(path) as img:
        mode = img.mode
        arr = np.array(img)
    if mode == "L":
        return (arr.astype(np.float64) / 255.0).astype(np.float32)
    if mode in ("I;16", "I;16B", "I;16L", "I"):
        return (arr.astype(np.float64) / _PNG_MAX).astype(np.float32)
    raise ValueError(f"{path}: expected a grayscale PNG (mode 'I;16' or 'L'); got mode {mode!r}")


def save_npy(path: str | os.PathLike, heightmap) -> Path:
    """Write a heightmap (``[H, W]`` or ``[B, H, W]``, any float range) as float32 ``.npy``. Atomic."""
    h = np.asarray(heightmap, dtype=np.float32)
    if h.ndim not in (2, 3):
        raise ValueError(f"heightmap must have shape [H, W] or [B, H, W]; got {h.shape}")
    buf = io.BytesIO()
    np.save(buf, h, allow_pickle=False)
    return atomic_write_bytes(path, buf.getvalue())


def load_npy(path: str | os.PathLike) -> np.ndarray:
    """Read a heightmap written by :func:`save_npy` -> float32 ``[H, W]`` (or ``[B, H, W]``)."""
    h = np.load(path, allow_pickle=False)
    if h.ndim not in (2, 3):
        raise ValueError(f"{path}: expected an [H, W] or [B, H, W] array; got shape {h.shape}")
    return h.astype(np.float32)


# ----------------------------------------------------------------------------------------------------------------
# MJCF


def save_mjcf(
    path: str | os.PathLike,
    heightmap,
    scale: TerrainScale = TerrainScale(),
    *,
    name: str = "terrain",
    base: float = 0.1,
    inline: bool = False,
) -> Path:
    """Write an MJCF model with the terrain as an ``<hfield>`` and a floor geom using it (loads with
    ``mujoco.MjModel.from_xml_path``).

    Geometry per :func:`hfield_size` (centred on the origin, row ``i`` towards +y, column ``j`` towards +x). MuJoCo
    renormalises elevation data read from XML or files to ``[0, 1]`` (min -> 0, max -> 1), so the file stores
    ``(h - min) / (max - min)`` with ``size[2] = (max - min) * scale.height`` and puts the geom at
    ``z = min * scale.height``: the loaded surface is at ``heightmap * scale.height`` metres, as with
    :func:`hfield_size` at run time. (A flat map gets ``size[2] = scale.height`` and all-zero data.)

    Args:
      path: the ``.xml`` to write.
      heightmap: ``[H, W]`` float heightmap (any finite range, heightmap units).
      scale: :class:`TerrainScale`.
      name: hfield / geom name.
      base: metres of solid box under the lowest point (> 0).
      inline: ``False`` (default) writes the heights as MuJoCo's binary hfield format (int32 nrow, int32 ncol,
        float32 data, row 0 = -y) to ``<stem>.hfield.bin`` beside the XML; ``True`` puts them in the XML's
        ``elevation`` attribute (a self-contained file, ~10 bytes per sample).

    Returns:
      The path of the XML. Both files are written atomically (the data file first).
    """
    from xml.sax.saxutils import quoteattr

    validate_scale(scale)
    h = _single_map(heightmap)
    path = Path(path)
    nrow, ncol = h.shape
    rx, ry, _, base_z = hfield_size(h.shape, scale, base)
    lo, hi = float(h.min()), float(h.max())
    span = hi - lo
    data = (h - lo) / span if span > 0 else np.zeros_like(h)
    elevation_z = span * float(scale.height) if span > 0 else float(scale.height)
    z0 = lo * float(scale.height)

    if inline:
        # MuJoCo reads the elevation attribute top row first (image order: its first row lands at +y), so the rows
        # are written last-to-first to keep heightmap row 0 at -y.
        values = " ".join(f"{v:.9g}" for v in np.flipud(data).astype(np.float32).ravel())
        source = f'elevation="{values}"'
    else:
        bin_path = path.with_name(path.stem + ".hfield.bin")
        payload = np.array([nrow, ncol], "<i4").tobytes() + data.astype("<f4").tobytes()
        atomic_write_bytes(bin_path, payload)
        source = f"file={quoteattr(bin_path.name)}"

    xml = f"""<mujoco model={quoteattr(name)}>
  <!-- jaxterrain.terrain.save_mjcf: {nrow} x {ncol} heightmap, cell_size={float(scale.cell_size):g} m,
       height={float(scale.height):g} m per heightmap unit; surface z = heightmap * height. -->
  <compiler meshdir="." texturedir="." assetdir="."/>
  <asset>
    <hfield name={quoteattr(name)} nrow="{nrow}" ncol="{ncol}" size="{rx:.9g} {ry:.9g} {elevation_z:.9g} {base_z:.9g}"
            {source}/>
  </asset>
  <worldbody>
    <light pos="0 0 10" dir="0 0 -1" directional="true"/>
    <geom name={quoteattr(name)} type="hfield" hfield={quoteattr(name)} pos="0 0 {z0:.9g}" condim="3"
          friction="1 0.1 0.1" rgba="0.55 0.5 0.45 1"/>
  </worldbody>
</mujoco>
"""
    return atomic_write_text(path, xml)


# ----------------------------------------------------------------------------------------------------------------
# Triangle meshes (trimesh)


def mesh_arrays(heightmap, scale: TerrainScale = TerrainScale()) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices [H * W, 3] float64 metres, faces [2 (H - 1) (W - 1), 3] int64)`` of a ``[H, W]`` heightmap.

    Vertex ``i * W + j`` is sample ``(i, j)`` at ``x = -radius_x + j * cell_size``, ``y = -radius_y + i *
    cell_size`` (:func:`hfield_size`: centred on the origin, rows towards +y, columns towards +x) and
    ``z = heightmap[i, j] * scale.height``. Each cell gives two counter-clockwise triangles seen from above, so
    face normals point up (+z).
    """
    validate_scale(scale)
    h = _single_map(heightmap)
    nrow, ncol = h.shape
    rx, ry, _, _ = hfield_size(h.shape, scale)
    cell = float(scale.cell_size)
    x = -rx + np.arange(ncol) * cell
    y = -ry + np.arange(nrow) * cell
    xx, yy = np.meshgrid(x, y)  # [H, W]
    vertices = np.stack([xx.ravel(), yy.ravel(), (h * float(scale.height)).ravel()], axis=-1)
    idx = np.arange(nrow * ncol, dtype=np.int64).reshape(nrow, ncol)
    v00, v01 = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    v10, v11 = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    faces = np.concatenate([np.stack([v00, v01, v11], -1), np.stack([v00, v11, v10], -1)])
    return vertices, faces


def to_mesh(heightmap, scale: TerrainScale = TerrainScale()):
    """A ``trimesh.Trimesh`` of a ``[H, W]`` heightmap: ``H * W`` vertices (one per pixel, in metres) and
    ``2 (H - 1) (W - 1)`` triangles (:func:`mesh_arrays`; vertices are kept as given, never merged)."""
    import trimesh

    vertices, faces = mesh_arrays(heightmap, scale)
    return trimesh.Trimesh(vertices=vertices, faces=faces, process=False, validate=False)


def save_obj(path: str | os.PathLike, heightmap, scale: TerrainScale = TerrainScale()) -> Path:
    """Write a ``[H, W]`` heightmap as a Wavefront OBJ triangle mesh (:func:`to_mesh`, metres, z up). Atomic.
    Returns the path."""
    text = to_mesh(heightmap, scale).export(file_type="obj", include_normals=False, include_texture=False,
                                            digits=6)
    return atomic_write_text(path, text)


def save_stl(path: str | os.PathLike, heightmap, scale: TerrainScale = TerrainScale()) -> Path:
    """Write a ``[H, W]`` heightmap as a binary STL triangle mesh (:func:`to_mesh`, metres, z up; STL stores
    float32 triangles, so vertices are shared only after a reader merges them). Atomic. Returns the path."""
    return atomic_write_bytes(path, to_mesh(heightmap, scale).export(file_type="stl"))
