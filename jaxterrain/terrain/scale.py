"""Heightmap <-> physical terrain: scale to metres and MuJoCo hfield geometry (the exports are in
:mod:`jaxterrain.terrain.export`).

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

"""

from __future__ import annotations

import numbers
from typing import NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np

__all__ = [
    "TerrainScale",
    "validate_scale",
    "to_metres",
    "hfield_size",
]


class _TerrainScaleFields(NamedTuple):
    cell_size: float = 0.04
    height: float = 1.0


def _check_positive(name: str, value) -> None:
    # A length is a real scalar: a Python / NumPy number, a [] array, or a [] tracer inside jit / vmap (checked for
    # its shape only). JAX rebuilds the tuple from its leaves (pytree unflatten: tracers, placeholders) without
    # coming here (:func:`_unflatten`), so anything else given to the constructor is refused.
    what = f"TerrainScale.{name} must be a finite number of metres > 0"
    if isinstance(value, jax.core.Tracer):
        if np.ndim(value) != 0:
            raise ValueError(f"{what} (a scalar); got an array of shape {np.shape(value)}")
        return
    if isinstance(value, (str, bytes, bool, np.bool_)) or value is None:
        raise ValueError(f"{what}; got {value!r}")
    if isinstance(value, numbers.Real):
        v = float(value)
    elif isinstance(value, (np.ndarray, jax.Array)) and np.issubdtype(np.dtype(value.dtype), np.number):
        if np.ndim(value) != 0:
            raise ValueError(f"{what} (a scalar); got an array of shape {np.shape(value)}")
        v = float(np.asarray(value))
    else:
        raise ValueError(f"{what}; got {value!r}")
    if not (np.isfinite(v) and v > 0):
        raise ValueError(f"{what}; got {value!r}")


class TerrainScale(_TerrainScaleFields):
    """Physical scale of a heightmap (a NamedTuple, hence a pytree).

    Attributes:
      cell_size: metres between neighbouring pixels (> 0), default 0.04.
      height: metres for heightmap value 1.0 (> 0), default 1.0.

    Each must be a finite real scalar > 0 (a Python or NumPy number, a ``[]`` array; a ``[]`` tracer inside
    ``jit`` / ``vmap``): anything else (None, a string, an array of another shape) is a ``ValueError`` naming the
    field. JAX's own rebuilding of the tuple from its leaves (pytree unflatten: tracers, placeholders) is not
    checked, nor is ``TerrainScale._make(fields)`` (e.g. ``vmap``'s ``in_axes=TerrainScale._make((None, 0))``).
    """

    __slots__ = ()

    def __new__(cls, cell_size: float = 0.04, height: float = 1.0):
        _check_positive("cell_size", cell_size)
        _check_positive("height", height)
        return super().__new__(cls, cell_size, height)


def _unflatten(_, children) -> TerrainScale:
    """Pytree unflatten: the fields as JAX gives them (tracers, placeholders, sentinels), unchecked."""
    return tuple.__new__(TerrainScale, tuple(children))


jax.tree_util.register_pytree_with_keys(
    TerrainScale, lambda s: (((jax.tree_util.GetAttrKey("cell_size"), s.cell_size),
                              (jax.tree_util.GetAttrKey("height"), s.height)), None), _unflatten)


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
        if isinstance(value, jax.Array) and not isinstance(value, jax.core.Tracer):  # a concrete [] jax array
            _check_positive(name, np.asarray(value))
    _check_positive("cell_size", scale.cell_size)
    _check_positive("height", scale.height)
    return scale


def to_metres(heightmaps, scale: TerrainScale = TerrainScale()):
    """Heights in metres: ``heightmaps * scale.height``, same shape (``[B, H, W]`` or ``[H, W]``) float32.
    ``ValueError`` naming ``heightmaps`` for another rank or a non-real dtype."""
    validate_scale(scale)
    try:
        h = jnp.asarray(heightmaps)
    except (TypeError, ValueError):
        raise ValueError(f"heightmaps must be a real array [B, H, W] or [H, W]; got {type(heightmaps).__name__}") \
            from None
    if h.dtype.kind not in "biuf" or h.ndim not in (2, 3):
        raise ValueError(f"heightmaps must be a real array [B, H, W] or [H, W]; got shape {tuple(h.shape)}, "
                         f"dtype {h.dtype}")
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
    try:
        dims = tuple(shape)
    except TypeError:
        raise ValueError(f"shape must be [..., H, W] with H, W >= 2; got {shape!r}") from None
    whole = lambda d: (isinstance(d, numbers.Real) and not isinstance(d, bool)  # noqa: E731
                       and np.isfinite(d) and d == int(d))
    if len(dims) < 2 or not all(whole(d) for d in dims[-2:]) or int(dims[-1]) < 2 or int(dims[-2]) < 2:
        raise ValueError(f"shape must be [..., H, W] with H, W >= 2; got {dims}")
    if (isinstance(base, (bool, str, bytes)) or not isinstance(base, numbers.Real)
            or not (np.isfinite(base) and base > 0)):
        raise ValueError(f"base must be a finite number of metres > 0; got {base!r}")
    nrow, ncol = int(shape[-2]), int(shape[-1])
    return (
        (ncol - 1) * float(scale.cell_size) / 2.0,
        (nrow - 1) * float(scale.cell_size) / 2.0,
        float(scale.height),
        float(base),
    )
