"""Heightmap exports: 16-bit PNG, ``.npy``, MJCF (a MuJoCo scene with the terrain as its hfield) and triangle meshes
as OBJ / STL through trimesh, for Isaac Lab, Gazebo or Blender.

Meshes (:func:`to_mesh`, :func:`save_obj`, :func:`save_stl`) use the placement of :func:`~jaxterrain.terrain.scale.hfield_size`:
one vertex per pixel at ``(x, y, heightmap * scale.height)`` metres (centred on the origin, as the hfield), two
triangles per cell with normals towards +z; the surface only (no skirt or bottom), as terrain importers expect.
"""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from jaxterrain.runtime.io import atomic_write_bytes, atomic_write_text
from jaxterrain.terrain.scale import TerrainScale, hfield_size, validate_scale

__all__ = [
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
    """Read a heightmap written by :func:`save_npy` -> float32 ``[H, W]`` (or ``[B, H, W]``); ``ValueError`` naming
    the file when it is not a ``.npy`` array of real numbers (``FileNotFoundError`` when it is missing)."""
    with open(path, "rb") as f:  # FileNotFoundError names the file
        magic = f.read(6)
    if magic != b"\x93NUMPY":  # np.load would try to unpickle it and say so
        raise ValueError(f"{path}: not a .npy heightmap (the file does not start with NumPy's .npy header)")
    try:
        h = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError) as err:
        raise ValueError(f"{path}: not a readable .npy heightmap ({type(err).__name__}: "
                         f"{str(err).splitlines()[0] if str(err) else 'truncated'})") from None
    if h.dtype.kind not in "biuf":
        raise ValueError(f"{path}: expected an array of real numbers; got dtype {h.dtype}")
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
