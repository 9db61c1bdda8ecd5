"""Pure helpers of several selectors over a terrain bank: a terrain's hardness, the roughness order, the choice of
the best available terrain, and pytree selection of levels."""

from __future__ import annotations

import math
import numbers
from typing import Optional

import jax
import jax.numpy as jnp

from jaxterrain.qd import GRID_BINS, MAX_DISTANCE_50, TerrainBank

__all__ = ["terrain_hardness", "roughness_sequence", "select", "take_levels", "where_levels", "float_in"]


def terrain_hardness(bank: TerrainBank, origin: str = "origin") -> jax.Array:
    """``[N]`` float32 hardness of each terrain in cells: ``bank.distance`` (from cell (0, 0)) for ``"origin"``,
    ``70.71 - hypot(50 - b0, 50 - b1)`` for ``"top_right"`` (see :mod:`jaxterrain.curriculum.config`)."""
    if origin == "origin":
        return jnp.asarray(bank.distance, jnp.float32)
    b = jnp.asarray(bank.bins, jnp.float32)
    return MAX_DISTANCE_50 - jnp.hypot(GRID_BINS - b[:, 0], GRID_BINS - b[:, 1])


def roughness_sequence(bank: TerrainBank, stride: int) -> tuple[jax.Array, jax.Array]:
    """Standard CL's terrains: ``(rank [N] int32, member [N] bool)``. ``rank`` is each terrain's position in the
    order of increasing descriptor 0 (roughness; ties by index); ``member`` marks every ``stride``-th of that order
    (positions 0, stride, 2 stride, ...)."""
    order = jnp.argsort(jnp.asarray(bank.descriptors)[:, 0], stable=True)
    rank = jnp.zeros(order.shape[0], jnp.int32).at[order].set(jnp.arange(order.shape[0], dtype=jnp.int32))
    return rank, (rank % stride) == 0


def select(score: jax.Array, available: jax.Array, hardness: jax.Array) -> jax.Array:
    """``[] int32``: the available terrain of highest ``score`` [N]; ties to the smallest ``hardness``, then the lowest
    index. 0 when none is available (check ``available.any()``)."""
    s = jnp.where(available, jnp.nan_to_num(score, nan=-jnp.inf), -jnp.inf)
    cand = available & (s == jnp.max(s))
    return jnp.argmin(jnp.where(cand, hardness, jnp.inf)).astype(jnp.int32)


def take_levels(levels, index):
    """Entry ``index`` of every leaf of a pytree of levels (leading axis C)."""
    return jax.tree.map(lambda a: a[index], levels)


def where_levels(pred, a, b):
    """``jnp.where(pred, a, b)`` leaf by leaf over two pytrees of one structure."""
    return jax.tree.map(lambda x, y: jnp.where(pred, x, y), a, b)


def float_in(owner: str, params, name: str, lo: float, hi: Optional[float], lo_open: bool,
             hi_open: bool = False) -> None:
    """``params.name`` must be a real number (not a bool or a string) in the interval; ``ValueError`` naming
    ``owner.name`` and the interval otherwise."""
    v = getattr(params, name)
    if isinstance(v, bool) or not isinstance(v, numbers.Real):  # not a string that float() would read
        raise ValueError(f"{owner}.{name} must be a number, got {v!r}")
    f = float(v)
    ok = math.isfinite(f) and (f > lo if lo_open else f >= lo) and (hi is None or (f < hi if hi_open else f <= hi))
    if not ok:
        left, right = "(" if lo_open else "[", ")" if (hi is None or hi_open) else "]"
        raise ValueError(f"{owner}.{name} must be in {left}{lo}, {'inf' if hi is None else hi}{right}, got {v!r}")
