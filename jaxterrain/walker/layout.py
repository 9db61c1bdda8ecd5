"""The walker's terrain layouts, their one home: which layout a config walks on, the env sized to a call, the terrain
arguments of a batch of envs and their ``vmap`` axes, and the physics backend ``"auto"`` resolves to.

- classic (``config.tiles = 0``, ``backend="jax"``): every env carries its own ``[H, W]`` heightfield in a batched
  model field (vmap ``in_axes=0``), or all share one (``in_axes=None``);
- tiled (``config.tiles >= 1``, required by ``backend="warp"``): the terrains are tiles of ONE heightfield
  (:class:`~jaxterrain.walker.TileBank`), each env walks on ``bank.at(index)`` (vmap ``in_axes=TILE_AXES``).

A tiled env's ``tiles`` and ``warp_worlds`` are sized to each call by :func:`sized_env` (:mod:`jaxterrain.walker.rollout`
says why). States carried row by row from one compiled call to the next take the form of :func:`carry_rows` (MuJoCo
Warp's buffers shared by every env empty on the row axis).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from jaxterrain.walker import tiles
from jaxterrain.walker.config import WalkerConfig
from jaxterrain.walker.env import WalkerEnv
from jaxterrain.walker.tiles import TILE_AXES, Tile

__all__ = ["BACKEND_CHOICES", "make_env", "is_tiled", "env_for", "sized_env", "world", "terrain_batch",
           "check_worlds", "terrain_axis", "resolve_backend", "carry_rows"]

BACKEND_CHOICES = ("auto", "jax", "warp")
"""Physics backends a user may name: ``auto`` (:func:`resolve_backend`), ``jax`` (MJX) or ``warp`` (MuJoCo Warp)."""


@functools.lru_cache(maxsize=32)
def make_env(config: WalkerConfig) -> WalkerEnv:
    """A cached :class:`WalkerEnv` per config (building one compiles the MuJoCo model)."""
    return WalkerEnv(config)


def is_tiled(config: WalkerConfig) -> bool:
    """Whether ``config`` walks on tiles: ``tiles >= 1``, or ``backend="warp"`` (which has no other layout)."""
    return int(config.tiles) >= 1 or config.backend == "warp"


def env_for(config: WalkerConfig, terrains: int, envs: int) -> WalkerEnv:
    """The cached env of ``config`` for a call that walks ``terrains`` maps with ``envs`` envs stepped together:
    ``make_env(config)`` for the classic layout; for a tiled one (:func:`is_tiled`) the env of ``config`` with
    ``tiles=terrains`` and, under ``backend="warp"``, ``warp_worlds=envs``. Safe to call while a ``jit`` traces
    (the env's arrays are made outside the trace, ``jax.ensure_compile_time_eval``)."""
    if not is_tiled(config):
        return make_env(config)
    if int(terrains) < 1 or int(envs) < 1:
        raise ValueError(f"terrains and envs must be >= 1, got {terrains}, {envs}")
    config = config._replace(tiles=int(terrains))
    if config.backend == "warp":
        config = config._replace(warp_worlds=int(envs))
    with jax.ensure_compile_time_eval():
        return make_env(config)


def sized_env(env: WalkerEnv, terrains: int, envs: int) -> WalkerEnv:
    """``env`` itself when it can walk ``terrains`` maps with ``envs`` envs stepped together as they are (classic
    layout; or ``env.tiles == terrains`` and, under warp, ``warp_worlds >= envs``), else :func:`env_for` of its
    config (the module docstring says why)."""
    if not env.tiles:
        return env
    if env.tiles == int(terrains) and (env.backend != "warp" or env.config.warp_worlds >= int(envs)):
        return env
    return env_for(env.config, terrains, envs)


def world(env: WalkerEnv, terrains: jax.Array):
    """``(bank, axes)``: ``(None, 0)`` for the classic layout (the terrains go to the envs as they are), or the
    :class:`~jaxterrain.walker.TileBank` of ``terrains`` [B, H, W] (``env.tiles == B``) and ``TILE_AXES``."""
    if not env.tiles:
        return None, 0
    if env.tiles != terrains.shape[0]:
        raise ValueError(f"a tiled env walks one tile per terrain: env.tiles={env.tiles} but {terrains.shape[0]} "
                         "terrains (size it with walker.layout.sized_env)")
    return env.make_bank(terrains), TILE_AXES


def terrain_batch(env: WalkerEnv, terrains: jax.Array):
    """``(world, axes)``: the terrain arguments of ``B`` envs, one per map of ``terrains`` [B, H, W] metres, and
    their ``in_axes`` for ``jax.vmap(env.reset, in_axes=(0, axes))`` / ``jax.vmap(env.step, in_axes=(0, 0, axes))``:
    ``(terrains, 0)`` for the classic layout, ``(bank.at(arange(B)), TILE_AXES)`` for a tiled env with
    ``env.tiles == B`` (:func:`sized_env`). Under a tiled env ``qpos[..., :2]`` are world coordinates: subtract
    ``env.tile_origin(index)`` for positions on the map."""
    bank, axes = world(env, terrains)
    return (terrains, axes) if bank is None else (bank.at(jnp.arange(terrains.shape[0], dtype=jnp.int32)), axes)


def check_worlds(env: WalkerEnv, envs: int) -> None:
    """MuJoCo Warp drops the contacts of envs beyond ``warp_worlds`` (their steps fail): refuse such a call."""
    if env.backend == "warp" and envs > env.config.warp_worlds:
        raise ValueError(f"{envs} envs stepped together but warp_worlds={env.config.warp_worlds}: build the env "
                         "with warp_worlds >= the envs of every vmap axis (walker.layout.sized_env sizes it per call)")


def terrain_axis(terrains, num_envs: int):
    """The ``in_axes`` of ``terrains`` over the envs: 0 for per-env terrains [N, H, W], None for a shared [H, W]
    or a shared ``Tile`` (index []), ``TILE_AXES`` for a ``Tile`` per env (index [N]); ValueError otherwise
    (host-side: static shapes)."""
    if isinstance(terrains, Tile):
        shape = tuple(jnp.shape(terrains.index))
        if shape == ():
            return None
        if shape == (num_envs,):
            return Tile(None, 0)  # walker.TILE_AXES: the bank shared, one index per env
        raise ValueError(f"terrains: a walker.Tile's index must be [] (shared) or [num_envs={num_envs}], "
                         f"got shape {shape}")
    if terrains.ndim == 2:
        return None
    if terrains.ndim == 3:
        if terrains.shape[0] != num_envs:
            raise ValueError(
                f"terrains: per-env terrains must have shape [num_envs={num_envs}, H, W], got {terrains.shape}"
            )
        return 0
    raise ValueError(f"terrains must be [H, W] (shared) or [num_envs, H, W], got shape {terrains.shape}")


def resolve_backend(backend: str) -> str:
    """``auto`` -> ``warp`` where JAX runs on a GPU and MuJoCo Warp imports (2.1x MJX-JAX per curriculum chunk on an
    H100), else ``jax``; other values unchanged."""
    if backend != "auto":
        return backend
    return "warp" if jax.default_backend() == "gpu" and tiles.warp_available()[0] else "jax"


def carry_rows(state, rows: int):
    """``rows`` copies of ``state`` (one env's state, or a batch of them: any pytree) on a new leading axis, in the
    form a state carried from one compiled call to the next keeps: ``jax.vmap``'s broadcast of it, except that every
    leaf the broadcast leaves unbatched becomes an empty ``[rows, 0, *shape[1:]]`` (zero bytes, the leaf's dtype).

    Those leaves are MuJoCo Warp's buffers shared by every env of a physics call (``mjx.Data._impl``'s contacts
    ``[naconmax, ...]``, ``nacon``, ``ncollision``, ``cdof_tri_*``; MJX-JAX states have none, so there this is exactly
    the broadcast). Left whole, they would not follow the rows: a program that concatenates, gathers or slices its
    carried states row by row (a curriculum block: ``run_population``) returns them cut to ``[rows, ...]`` and the
    next call of the same compiled program is refused. In this form every leaf has the row axis, so the state keeps
    one structure and shape in and out. The empty leaves are no physics: such a state enters the physics only merged
    into a fresh ``reset`` state by :meth:`WalkerEnv.select` (``mjx.Data.where`` keeps the reset's shared buffers,
    and every step's collision rebuilds the contacts), as every curriculum chunk does (``core.chunk_physics``'s
    restart); :meth:`WalkerEnv.step` refuses it as it is (``ValueError`` while tracing). Pure; jit / eval_shape
    it."""
    stacked = jax.vmap(lambda _: state)(jnp.arange(rows))

    def row(out, one):
        if jnp.ndim(out) > jnp.ndim(one):
            return out
        return jnp.zeros((rows, 0) + tuple(jnp.shape(one))[1:], jnp.result_type(one))

    return jax.tree.map(row, stacked, state)
