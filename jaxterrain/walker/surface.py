"""Terrain heights under the walker and two small pure helpers of its observation: :func:`sample_heights`
(bilinear, on MuJoCo's heightfield grid), :func:`yaw` (of a quaternion) and :func:`state_key` (a PRNG key hashed
from the physics state: the scan noise's)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

__all__ = ["sample_heights", "state_key", "yaw"]


def sample_heights(terrain: jax.Array, x: jax.Array, y: jax.Array, radius_x: float, radius_y: float,
                   max_height: float) -> jax.Array:
    """Bilinear terrain height (metres) at world points ``x, y`` (same shape) on a ``[H, W]`` terrain.

    Uses MuJoCo's hfield grid (column j at x = -radius_x + j * 2 radius_x / (W - 1), row i likewise in y);
    points outside are clamped to the border. Sample values are clipped to [0, max_height] like the physics.
    """
    if len(jnp.shape(terrain)) != 2:
        raise ValueError(f"terrain must have shape [H, W]; got shape {tuple(jnp.shape(terrain))}")
    h, w = terrain.shape
    u = jnp.clip((x + radius_x) / (2.0 * radius_x) * (w - 1), 0.0, w - 1.0)
    v = jnp.clip((y + radius_y) / (2.0 * radius_y) * (h - 1), 0.0, h - 1.0)
    j0 = jnp.clip(jnp.floor(u).astype(jnp.int32), 0, w - 2)
    i0 = jnp.clip(jnp.floor(v).astype(jnp.int32), 0, h - 2)
    fu, fv = u - j0, v - i0
    t = lambda i, j: jnp.clip(terrain[i, j], 0.0, max_height)  # noqa: E731
    top = (1 - fu) * t(i0, j0) + fu * t(i0, j0 + 1)
    bot = (1 - fu) * t(i0 + 1, j0) + fu * t(i0 + 1, j0 + 1)
    return (1 - fv) * top + fv * bot


def state_key(qpos, qvel, time) -> jax.Array:
    """A PRNG key that is a hash of the physics state (``qpos``, ``qvel``, ``time``): the scan noise's."""
    time = jnp.asarray(time, jnp.float32)
    bits = jax.lax.bitcast_convert_type(jnp.concatenate([qpos.astype(jnp.float32), qvel.astype(jnp.float32),
                                                         jnp.reshape(time, (1,))])
                                        .astype(jnp.float32), jnp.uint32)
    mult = (jnp.arange(bits.shape[0], dtype=jnp.uint32) * jnp.uint32(2654435761)) | jnp.uint32(1)
    h = jnp.sum(bits * mult, dtype=jnp.uint32) ^ jnp.sum((bits >> 16) * (mult + jnp.uint32(0x9E3779B9)),
                                                         dtype=jnp.uint32)
    return jax.random.fold_in(jax.random.PRNGKey(0x5CA7), h)


def yaw(quat: jax.Array) -> jax.Array:
    w, x, y, z = quat[0], quat[1], quat[2], quat[3]
    return jnp.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
