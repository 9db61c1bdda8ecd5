"""A bank of terrain tiles in ONE heightfield: per-env terrains without a batched model field.

MuJoCo Warp shares ``hfield_data`` across worlds, and MJX-Warp drops a batched ``geom_dataid``
(google-deepmind/mujoco_warp#1473, google-deepmind/mujoco#3258; MJX 3.17 refuses a per-world one on both backends,
``benchmarks/layouts.py``), so the per-env ``model.replace(hfield_data=...)``
of the classic walker cannot run under ``impl="warp"``. Instead (the legged_gym / Isaac Lab layout) the model holds
ONE large heightfield made of ``T`` tiles, each exactly a ``terrain_shape = (H, W)`` terrain at the same cell size,
and every environment is spawned on its own tile. Worlds never interact, so any number of environments may share a
tile (the attempts of a difficulty evaluation do).

Layout: the tiles lie on a near-square grid of ``rows x cols`` tiles (``cols = ceil(sqrt(T))``, ``rows =
ceil(T / cols)``; grid cells past ``T`` stay flat at 0 m), tile ``i`` at grid row ``i // cols`` (towards +y) and
column ``i % cols`` (towards +x). The heightfield is ``[rows * H, cols * W]`` samples, ``cell_size`` apart in both
directions with no gap rows, so tile ``i``'s samples sit on exactly the grid of a single ``H x W`` heightfield
shifted by the tile's centre ``tile_origin(i) = (cell_x * W * (col - (cols - 1) / 2), cell_y * H * (row - (rows -
1) / 2))``. A square grid rather than one strip keeps world coordinates small: float32 positions at ``|x| ~ 20 km``
(4096 strip tiles of 10 m) are only good to ~2 mm, on a 64 x 64 grid (~330 m) to ~0.03 mm.

Data: a :class:`TileBank` is the heightfield itself, ``data [rows * H, cols * W]`` float32 in ``[0, 1]`` (MuJoCo's
``hfield_data`` values, heights / ``elevation_z``), so ``mjx_model.replace(hfield_data=bank.data.reshape(-1))``
costs nothing inside a step; a :class:`Tile` is ``(bank, index)``. Build banks with ``WalkerEnv.make_bank``
(``[T, H, W]`` metres, one transpose), change one tile with ``WalkerEnv.set_tile`` (a ``dynamic_update_slice``,
jit-able), read them back with ``WalkerEnv.bank_terrains``.

Differences to a single-terrain heightfield, both outside a walk that is still running: between two neighbouring
tiles the surface spans one cell linearly from one tile's edge to the next (a single heightfield has no ground past
its edge), and MuJoCo's heightfield ``base_z`` box is one box under all tiles. The walker ends its episode when its
torso is ``side_margin`` from a side edge or ``goal_margin`` from the front edge, each the robot's reach (humanoid
0.3 / 0.5 m, ant 1.3 / 1.3 m: :data:`~jaxterrain.walker.robots.ROBOT_FIELDS`), so a foot walking forward never
touches a neighbouring tile. Backwards the episode ends ``start_margin / 2`` from the back edge: a walker that backs
up behind its start (the ant: by more than 0.2 m) may touch the tile behind.

Callers that walk on tiles (each also keeps the classic ``terrain [H, W]`` layout, ``tiles = 0``):

* ``difficulty`` / ``rollout`` (``batched_distances`` and the rollout pool): with ``env.config.tiles >= 1`` or
  ``backend="warp"`` the ``[B, H, W]`` terrains become one bank and each walk gets ``bank.at(i)`` (the pool keeps each
  slot's tile index and merges states with ``env.select``); the env is sized per call (tiles = terrains,
  ``warp_worlds`` = the envs stepped together).
* ``rl.ppo``: the terrain may be ``bank.at(i)`` shared by all envs or ``bank.at(idx)`` per env under ``TILE_AXES``;
  the auto-reset merges with ``env.select``; ``warp_worlds`` >= seeds x ``num_envs``.
* the curriculum (``curriculum.walker``): ``Harness.layout`` makes one bank of the trials' current terrains per
  chunk, trial i on tile i; ``tile_distances`` evaluates on a tile; ``warp_worlds`` >= trials x max(``num_envs``,
  ``attempts``).
* ``traversability.walk`` and ``report.render``: positions are read relative to ``env.tile_origin(index)``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

__all__ = ["TileBank", "Tile", "TILE_AXES", "grid", "tile_grid_pos", "pack", "unpack", "sample_tile_heights",
           "warp_available"]


class TileBank(NamedTuple):
    """``data``: ``[rows * H, cols * W]`` float32 in [0, 1], the tiled heightfield (``hfield_data`` values)."""

    data: jax.Array

    def at(self, index) -> "Tile":
        """The :class:`Tile` ``index`` of this bank."""
        return Tile(self, jnp.asarray(index, jnp.int32))


class Tile(NamedTuple):
    """Tile ``index`` ([] int32, in ``[0, T)``) of ``bank``: the terrain argument of a tiled ``WalkerEnv``.

    Under vmap map the index and share the bank: ``jax.vmap(env.step, in_axes=(0, 0, TILE_AXES))`` with
    ``TILE_AXES = Tile(None, 0)``, or close over the bank: ``jax.vmap(lambda s, a, i: env.step(s, a, bank.at(i)))``.
    """

    bank: TileBank
    index: jax.Array


TILE_AXES = Tile(None, 0)  # type: ignore[arg-type]
"""``in_axes`` of a :class:`Tile` argument under ``jax.vmap``: shared bank, one index per env."""


def grid(tiles: int) -> tuple[int, int]:
    """``(rows, cols)`` of the tile grid for ``tiles`` tiles (near square, ``cols = ceil(sqrt(tiles))``)."""
    t = int(tiles)
    if t < 1:
        raise ValueError(f"tiles must be >= 1, got {tiles!r}")
    cols = math.isqrt(t - 1) + 1 if t > 1 else 1
    rows = -(-t // cols)
    return rows, cols


def tile_grid_pos(index, cols: int):
    """(grid row, grid column) of tile ``index`` (int32 arrays)."""
    index = jnp.asarray(index, jnp.int32)
    return index // cols, index % cols


def pack(terrains_data: jax.Array, rows: int, cols: int) -> jax.Array:
    """``[T, H, W]`` hfield values -> the ``[rows * H, cols * W]`` heightfield (grid cells past T are 0)."""
    t, h, w = terrains_data.shape
    pad = rows * cols - t
    x = jnp.concatenate([terrains_data, jnp.zeros((pad, h, w), terrains_data.dtype)]) if pad else terrains_data
    return x.reshape(rows, cols, h, w).transpose(0, 2, 1, 3).reshape(rows * h, cols * w)


def unpack(data: jax.Array, tiles: int, tile_shape: tuple[int, int]) -> jax.Array:
    """Inverse of :func:`pack`: ``[rows * H, cols * W]`` -> ``[T, H, W]``."""
    h, w = tile_shape
    rows, cols = data.shape[0] // h, data.shape[1] // w
    return data.reshape(rows, h, cols, w).transpose(0, 2, 1, 3).reshape(rows * cols, h, w)[:tiles]


def sample_tile_heights(data: jax.Array, row, col, x: jax.Array, y: jax.Array, tile_shape: tuple[int, int],
                        radius_x: float, radius_y: float, elevation_z: float) -> jax.Array:
    """Bilinear height in metres at tile-local points ``x, y`` on the tile at grid ``(row, col)`` of the heightfield
    ``data`` (values in [0, 1]); the same grid and clamping as :func:`jaxterrain.walker.surface.sample_heights` on that
    tile alone (points outside are clamped to the tile's border)."""
    h, w = tile_shape
    u = jnp.clip((x + radius_x) / (2.0 * radius_x) * (w - 1), 0.0, w - 1.0)
    v = jnp.clip((y + radius_y) / (2.0 * radius_y) * (h - 1), 0.0, h - 1.0)
    j0 = jnp.clip(jnp.floor(u).astype(jnp.int32), 0, w - 2)
    i0 = jnp.clip(jnp.floor(v).astype(jnp.int32), 0, h - 2)
    fu, fv = u - j0, v - i0
    r0 = jnp.asarray(row, jnp.int32) * h + i0
    c0 = jnp.asarray(col, jnp.int32) * w + j0
    t = lambda i, j: jnp.clip(data[i, j], 0.0, 1.0) * elevation_z  # noqa: E731
    top = (1 - fu) * t(r0, c0) + fu * t(r0, c0 + 1)
    bot = (1 - fu) * t(r0 + 1, c0) + fu * t(r0 + 1, c0 + 1)
    return (1 - fv) * top + fv * bot


def warp_available() -> tuple[bool, str]:
    """(whether ``WalkerConfig(backend="warp")`` can run here, the reason when not): warp-lang and MJX's MuJoCo
    Warp must import (``pip install 'jaxterrain[warp]'``)."""
    try:
        import warp  # noqa: F401
        from mujoco.mjx.third_party import mujoco_warp  # noqa: F401
    except Exception as err:  # noqa: BLE001
        return False, f"MuJoCo Warp not importable ({type(err).__name__}: {err}); pip install 'jaxterrain[warp]'"
    return True, ""
