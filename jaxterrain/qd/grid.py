"""The archive's grid, its one home: centroids over the descriptor ranges, flat cell <-> (bin0, bin1), and the
distance of a cell from the grid's origin corner (the curriculum's and the paper's measure of how far a terrain is).

A flat cell index ``i * bins + j`` has descriptor 0 in bin ``j`` and descriptor 1 in bin ``i`` (QDax's meshgrid
order), so ``bins(cell) = (cell % bins, cell // bins)``.
"""

from __future__ import annotations

import numbers

import jax
import numpy as np
from qdax.core.containers.mapelites_repertoire import compute_euclidean_centroids

from jaxterrain.qd.config import EvolveConfig, resolve_config

__all__ = ["GRID_BINS", "MAX_DISTANCE_50", "centroids_for", "cell_bins", "cell_of", "cell_distance"]

GRID_BINS = 50
"""The paper's grid: 50 x 50 cells."""

MAX_DISTANCE_50 = float(np.hypot(50.0, 50.0))
"""70.71: the paper's "maximum possible map distance" on a 50 x 50 grid (Table 2's 100 %)."""


def centroids_for(config: EvolveConfig) -> jax.Array:
    """[bins * bins, 2] float32 grid centroids over the config's ranges (QDax ``compute_euclidean_centroids``), cell
    ``i * bins + j`` at (bin ``j`` of descriptor 0, bin ``i`` of descriptor 1)."""
    config = resolve_config(config)
    (lo0, hi0), (lo1, hi1) = config.ranges
    return compute_euclidean_centroids((config.bins, config.bins), minval=[lo0, lo1], maxval=[hi0, hi1])


def _check_bins(bins) -> int:
    """``bins`` (cells per descriptor) as an int >= 1, or ``ValueError`` naming it."""
    if not isinstance(bins, numbers.Integral) or isinstance(bins, bool) or bins < 1:
        raise ValueError(f"bins must be an integer >= 1 (cells per descriptor); got {bins!r}")
    return int(bins)


def _int_array(values, name: str, shape: str) -> np.ndarray:
    """``values`` as an int64 array; ``ValueError`` naming ``name`` for anything but whole numbers."""
    try:
        a = np.asarray(values)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be an integer array {shape}; got {type(values).__name__}") from None
    if a.dtype.kind not in "iuf" or (a.dtype.kind == "f" and not np.all(np.isfinite(a) & (a == np.round(a)))):
        raise ValueError(f"{name} must be an integer array {shape}; got dtype {a.dtype}"
                         + (" with fractional or non-finite values" if a.dtype.kind == "f" else ""))
    return a.astype(np.int64)


def cell_bins(cells, bins: int) -> np.ndarray:
    """``[...]`` int flat cell indices -> ``[..., 2]`` int32 ``(bin of descriptor 0, bin of descriptor 1)``. Each
    cell must be in ``[0, bins * bins)`` (``ValueError`` naming ``cells`` otherwise)."""
    bins = _check_bins(bins)
    c = _int_array(cells, "cells", "[...] of flat cell indices")
    if c.size and (c.min() < 0 or c.max() >= bins * bins):
        raise ValueError(f"cells must be in [0, bins * bins = {bins * bins}); got values in [{c.min()}, {c.max()}]")
    return np.stack([c % bins, c // bins], axis=-1).astype(np.int32)


def cell_of(cell_bins_: np.ndarray, bins: int) -> np.ndarray:
    """:func:`cell_bins` undone: ``[..., 2]`` int bins -> ``[...]`` int32 flat cell indices. Each bin must be in
    ``[0, bins)`` (``ValueError`` naming ``cell_bins_`` otherwise)."""
    bins = _check_bins(bins)
    b = _int_array(cell_bins_, "cell_bins_", "[..., 2] of (bin0, bin1)")
    if b.ndim < 1 or b.shape[-1] != 2:
        raise ValueError(f"cell_bins_ must have shape [..., 2] (bin0, bin1); got shape {b.shape}")
    if b.size and (b.min() < 0 or b.max() >= bins):
        raise ValueError(f"cell_bins_ must be in [0, bins = {bins}); got values in [{b.min()}, {b.max()}]")
    return (b[..., 1] * bins + b[..., 0]).astype(np.int32)


def cell_distance(bins: np.ndarray) -> np.ndarray:
    """``[..., 2]`` int bins -> ``[...]`` float32: Euclidean distance from the grid's origin corner (0, 0) to the
    FAR corner of the cell, ``hypot(b0 + 1, b1 + 1)``, so the top-right cell of a 50 x 50 grid is at 70.71, the
    paper's "maximum possible map distance" (Table 2), and the origin cell at 1.41. Bins must be >= 0
    (``ValueError`` naming ``bins`` otherwise)."""
    raw = _int_array(bins, "bins", "[..., 2] of (bin0, bin1)")
    if raw.ndim < 1 or raw.shape[-1] != 2:
        raise ValueError(f"bins must have shape [..., 2] (bin0, bin1); got shape {raw.shape}")
    if raw.size and raw.min() < 0:
        raise ValueError(f"bins must be >= 0; got a minimum of {raw.min()}")
    b = np.asarray(bins, np.float32) + 1.0
    return np.hypot(b[..., 0], b[..., 1]).astype(np.float32)
