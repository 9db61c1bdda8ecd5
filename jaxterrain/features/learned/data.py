"""Labelled walks for the learned traversability model: the base policy's walks on terrains, windows of them
labelled traversed / not, and the heightmap patches under them (the package docstring, :mod:`jaxterrain.features.learned`,
says why these choices)."""

from __future__ import annotations

import functools
from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from jaxterrain import difficulty
from jaxterrain.features.learned.model import PATCH
from jaxterrain.terrain import TerrainScale, validate_scale
from jaxterrain.walker import BACKENDS
from jaxterrain.walker.layout import make_env, sized_env, terrain_batch

__all__ = ["LabelConfig", "Walks", "walk_fn", "walk", "window_labels", "labelled_centres", "pixel_of",
           "extract_patches", "extract_patches_batch", "balanced_indices"]


class LabelConfig(NamedTuple):
    """How a walk becomes labelled windows (:func:`window_labels`).

    window: env steps per window (30 = 0.45 s). threshold: metres the torso must advance along +x within the
    window. every: env steps between window starts. warmup: windows start no earlier than this step (the walker
    starts from rest)."""

    window: int = 30
    threshold: float = 0.3
    every: int = 4
    warmup: int = 8


# ----------------------------------------------------------------------------------------------------------------
# Walks and labels


class Walks(NamedTuple):
    """Recorded walks of ``A`` attempts on each of ``B`` terrains, ``T`` = horizon env steps.

    xy: ``[B, A, T + 1, 2]`` float32 torso (x, y) in metres after each env step (index 0: after reset), frozen at
    the last position once the episode ended. end: ``[B, A]`` int32, the env step at which the episode ended
    (``T`` if it was still running). fell: ``[B, A]`` bool, it ended by a fall or failed physics (not the goal, the
    time limit or the horizon)."""

    xy: jax.Array
    end: jax.Array
    fell: jax.Array


def walk_fn(env, policy: Callable, attempts: int, horizon: int) -> Callable:
    """A pure ``rollout(terrains_m [B, H, W] metres, key) -> Walks`` (jit it) of ``attempts`` walks per terrain
    along +x, at most ``horizon`` env steps, the pattern of :func:`jaxterrain.walker.rollout.batched_distances`:
    vmap over terrains and attempts, a ``while_loop`` over time that stops once every walk has ended. ``env`` of
    either layout (:mod:`jaxterrain.walker.rollout`: a tiled env is sized to the call); ``Walks.xy`` are positions on the
    map either way (a tiled env's tile origin subtracted)."""

    act = jax.vmap(jax.vmap(policy))

    def rollout(terrains_m, key):
        b = terrains_m.shape[0]
        e = sized_env(env, b, b * attempts)
        world, axes = terrain_batch(e, terrains_m)
        reset = jax.vmap(jax.vmap(e.reset, in_axes=(0, None)), in_axes=(0, axes))
        step = jax.vmap(jax.vmap(e.step, in_axes=(0, 0, None)), in_axes=(0, 0, axes))
        if e.tiles:  # world -> map coordinates
            origin = jnp.stack(e.tile_origin(jnp.arange(b)), -1)[:, None, :]  # [B, 1, 2]
            local = lambda state: state.data.qpos[..., :2] - origin  # noqa: E731
        else:
            local = lambda state: state.data.qpos[..., :2]  # noqa: E731
        state = reset(jax.random.split(key, (b, attempts)), world)
        buf = jnp.zeros((horizon + 1, b, attempts, 2), jnp.float32).at[0].set(local(state))
        ended = jnp.zeros((b, attempts), bool)
        end = jnp.full((b, attempts), horizon, jnp.int32)

        def body(c):
            t, state, ended, end, fell, buf = c
            state = step(state, act(state.obs), world)
            xy = jnp.where(ended[..., None], buf[t], local(state))
            buf = lax.dynamic_update_index_in_dim(buf, xy, t + 1, 0)
            now = ~ended & (state.done > 0)
            fell = fell | (now & (state.truncation == 0))
            end = jnp.where(now, t + 1, end)
            return t + 1, e.park(state, ended | now), ended | now, end, fell, buf  # ended walks step on parked

        t, _, _, end, fell, buf = lax.while_loop(lambda c: (c[0] < horizon) & ~jnp.all(c[2]), body,
                                                 (jnp.int32(0), state, ended, end, ended, buf))
        steps = jnp.arange(horizon + 1)[:, None, None, None]
        buf = jnp.where(steps > t, buf[t], buf)  # the loop stopped early: every walk has ended, freeze them
        return Walks(xy=jnp.moveaxis(buf, 0, 2), end=end, fell=fell)

    return rollout


@functools.lru_cache(maxsize=8)
def _walk_program(shape: tuple[int, int], scale: TerrainScale, attempts: int, horizon: int, start_spread: float,
                  backend: str = "jax"):

    policy = difficulty.default_policy()
    config = difficulty.default_env_config(shape, scale, policy, backend)._replace(start_spread=float(start_spread))
    return jax.jit(walk_fn(make_env(config), policy, attempts, horizon))


def walk(key: jax.Array, heightmaps, attempts: int = 4, horizon: int = 300, scale: TerrainScale = TerrainScale(),
         start_spread: float = 0.0, backend: str = "jax") -> Walks:
    """The shipped base policy's walks on ``heightmaps`` ``[B, H, W]`` in [0, 1] (metres by ``scale``), along +x
    from the start edge, at lateral offsets uniform in ``[-start_spread, start_spread]`` m, under the physics
    ``backend`` (``"jax"`` or ``"warp"``: MuJoCo Warp on tiles, :func:`jaxterrain.difficulty.default_env_config`).
    One compiled program per (shape, scale, attempts, horizon, start_spread, backend), reused across calls. Returns
    :class:`Walks`."""

    h = difficulty.validate_heightmaps(heightmaps)
    for name, v in (("attempts", attempts), ("horizon", horizon)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise ValueError(f"{name} must be an int >= 1, got {v!r}")
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    scale = validate_scale(scale)
    fn = _walk_program(tuple(h.shape[1:]), scale, int(attempts), int(horizon), float(start_spread), backend)
    return fn(h * jnp.float32(scale.height), key)


def window_labels(walks: Walks, config: LabelConfig = LabelConfig()) -> tuple[jax.Array, jax.Array]:
    """Labels of the windows of every walk (rules in the module docstring).

    Args:
      walks: :class:`Walks` with ``xy [..., T + 1, 2]``, ``end [...]``, ``fell [...]`` (any leading shape).
      config: :class:`LabelConfig`.

    Returns:
      ``(starts [K] int32, labels [..., K] int32)``: window ``k`` starts at env step ``starts[k]`` (``warmup,
      warmup + every, ...`` below ``T``); its label is 1 (advanced more than ``threshold`` m and still up), 0
      (fell inside the window) or -1 (no label: the walk had ended before, or the window runs past the end of a
      walk that did not fall).
    """
    horizon = walks.xy.shape[-2] - 1
    if config.window < 1 or config.every < 1 or not 0 <= config.warmup < horizon:
        raise ValueError(f"config needs window >= 1, every >= 1, 0 <= warmup < horizon={horizon}; got {config}")
    starts = jnp.arange(config.warmup, horizon, config.every, dtype=jnp.int32)
    x = walks.xy[..., 0]
    stop = jnp.minimum(starts + config.window, horizon)
    advance = jnp.take(x, stop, axis=-1) - jnp.take(x, starts, axis=-1)
    end, fell = walks.end[..., None], walks.fell[..., None]
    alive = starts < end
    fell_in = alive & fell & (end <= starts + config.window)
    complete = alive & (starts + config.window <= end) & ~fell_in
    labels = jnp.where(fell_in, 0, jnp.where(complete, (advance > config.threshold).astype(jnp.int32), -1))
    return starts, labels.astype(jnp.int32)


def labelled_centres(walks: Walks, starts, labels, config: LabelConfig = LabelConfig()
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The labelled windows as flat host arrays ``(terrain [N] int, xy [N, 2] metres, label [N] int)``.

    ``terrain`` indexes the leading axis of ``walks`` (``[B, A, ...]``); ``xy`` is the patch centre: the torso at
    the window's middle, step ``start + window // 2`` (the position where the walk ended, if it ended before), so
    that the patch covers the ground walked in the window and a fall's patch is centred where the walker fell."""
    xy, labels, starts = np.asarray(walks.xy), np.asarray(labels), np.asarray(starts)
    b, a, k = labels.shape
    mid = np.minimum(starts + config.window // 2, xy.shape[-2] - 1)
    at = xy[:, :, mid]  # [B, A, K, 2]
    keep = labels >= 0
    terrain = np.broadcast_to(np.arange(b)[:, None, None], (b, a, k))
    return terrain[keep], at[keep].astype(np.float32), labels[keep]


# ----------------------------------------------------------------------------------------------------------------
# Patches


def pixel_of(xy, shape: tuple[int, int], cell_size: float) -> jax.Array:
    """Nearest pixel ``[..., 2]`` int32 (row, column) of world points ``xy [..., 2]`` (metres) on an ``[H, W]``
    MuJoCo heightfield centred at the origin (column ``j`` at ``x = -radius_x + j * cell_size``, rows along y)."""
    h, w = shape
    xy = jnp.asarray(xy, jnp.float32)
    col = (xy[..., 0] + (w - 1) * cell_size / 2) / cell_size
    row = (xy[..., 1] + (h - 1) * cell_size / 2) / cell_size
    return jnp.stack([jnp.round(row), jnp.round(col)], -1).astype(jnp.int32)


def extract_patches(terrain, xy, patch: int = PATCH, cell_size: float = TerrainScale().cell_size) -> jax.Array:
    """Patches of one terrain centred at world points, heights relative to the centre.

    Args:
      terrain: ``[H, W]`` heights (metres for the model).
      xy: ``[N, 2]`` world (x, y) in metres; the patch centre is their nearest pixel (:func:`pixel_of`).
      patch: side P in pixels; the centre is pixel ``(P // 2, P // 2)`` of the patch.
      cell_size: metres per pixel.

    Returns:
      ``[N, P, P]`` float32: ``terrain[r - P//2 + i, c - P//2 + j] - terrain[r, c]`` (rows along y, columns along
      +x), the terrain extended by its edge values outside the map.
    """
    t = jnp.asarray(terrain, jnp.float32)
    if t.ndim != 2:
        raise ValueError(f"terrain must be [H, W]; got shape {tuple(t.shape)}")
    xy = jnp.asarray(xy, jnp.float32).reshape(-1, 2)
    return extract_patches_batch(t[None], jnp.zeros(xy.shape[0], jnp.int32), xy, patch, cell_size)


def extract_patches_batch(terrains, index, xy, patch: int = PATCH,
                          cell_size: float = TerrainScale().cell_size) -> jax.Array:
    """:func:`extract_patches` over a batch: patch ``n`` is cut from ``terrains[index[n]]`` (``[B, H, W]``, ``index
    [N]`` int, ``xy [N, 2]`` metres) -> ``[N, P, P]``; one gather, no copy of whole maps per patch."""
    t = jnp.asarray(terrains, jnp.float32)
    if t.ndim != 3:
        raise ValueError(f"terrains must be [B, H, W]; got shape {tuple(t.shape)}")
    if patch < 2:
        raise ValueError(f"patch must be >= 2 pixels; got {patch}")
    return _cut(t, jnp.asarray(index, jnp.int32), jnp.asarray(xy, jnp.float32), int(patch), float(cell_size))


@functools.partial(jax.jit, static_argnames=("patch", "cell_size"))
def _cut(t, index, xy, patch: int, cell_size: float):
    padded = jnp.pad(t, ((0, 0), (patch, patch), (patch, patch)), mode="edge")
    corner = pixel_of(xy, t.shape[1:], cell_size) - patch // 2 + patch  # top-left in the padded maps
    corner = jnp.clip(corner, 0, jnp.array(padded.shape[1:]) - patch)

    def one(i, rc):
        p = lax.dynamic_slice(padded, (i, rc[0], rc[1]), (1, patch, patch))[0]
        return p - p[patch // 2, patch // 2]

    return jax.vmap(one)(index, corner)


def balanced_indices(key: jax.Array, labels) -> np.ndarray:
    """Indices ``[2 m]`` of a class-balanced subset of binary ``labels [N]``: all ``m`` of the rarer class and ``m``
    of the other drawn without replacement with ``key``, in random order."""
    labels = np.asarray(labels)
    pos, neg = np.flatnonzero(labels == 1), np.flatnonzero(labels == 0)
    m = min(len(pos), len(neg))
    k1, k2, k3 = jax.random.split(key, 3)
    pos = np.asarray(jax.random.permutation(k1, pos))[:m] if len(pos) else pos
    neg = np.asarray(jax.random.permutation(k2, neg))[:m] if len(neg) else neg
    both = np.concatenate([pos, neg])
    return both[np.asarray(jax.random.permutation(k3, len(both)))] if len(both) else both


