"""Learned traversability (paper 3.2, item 4): a CNN patch classifier trained on the base policy's own walks.

The paper's fourth descriptor is the mean output of the traversability model of Chavez-Garcia et al. (RA-L 2018): a
small CNN that reads a heightmap patch (heights relative to the patch centre, turned to the robot's heading) and
outputs the probability that the robot advances across it. Their weights are not available; ours is trained the
same way, on our walker's simulated outcomes::

    walks = traversability.walk(key, heightmaps, attempts=4, horizon=300)      # Walks: torso x, y per env step
    starts, labels = traversability.window_labels(walks)                        # [B, A, K]: 1 / 0 / -1 (none)
    patches = traversability.extract_patches(terrain_m, xy)                     # [N, 32, 32] m, relative to centre
    params = traversability.train(key, patches, labels)                        # flax params of PatchCNN
    tmap = traversability.traversability_map(params, heightmaps)                # [B, 29, 29] probabilities
    d = features.descriptors(heightmaps, ("traversability",))                   # [B, 1]: the map's mean

Choices (:class:`LabelConfig`, :data:`PATCH`, :data:`MAP_STRIDE`):

- Patch: ``PATCH = 32`` pixels = 1.28 m at 0.04 m per pixel, the paper's 1.2 m (60 px at 2 cm) at our resolution;
  about two strides of the humanoid. Heights in metres relative to the centre pixel ``(16, 16)``
  (:func:`jaxterrain.features.window_centre`), rows along y, columns along +x: the walking direction, orientation 0
  as in the paper. The patch of a window is centred on the torso's (x, y) at the window's middle
  (:func:`labelled_centres`), so it covers the ground walked during the window, and a fall's patch is centred where
  the walker fell.
- Label (:func:`window_labels`): windows of ``window = 30`` env steps (0.45 s) start every ``every = 4`` steps from
  step ``warmup = 8``. A window is positive when the walker is still up at its end and its torso advanced more
  than ``threshold = 0.3`` m along +x, negative when the walker fell (or its physics failed) inside the window or
  advanced less; windows that run past the end of a walk that did not fall (goal, time limit, horizon) are not
  labelled. Why these numbers: the base policy runs at about 3.5 m/s on flat ground (2.1 m per 40 steps), so a
  30-step window at speed covers about 1.6 m, a bit more than one patch; it starts from rest and needs about 1 s to
  reach that speed, and the slowest flat-ground advance of a window starting at step 8 is 0.43 m, so 0.3 m passes
  every flat-ground window (a walker that does not fall) while a stumble that loses most of its speed fails it.
  The humanoid's failure mode is falling, not getting stuck (the paper's robot), so most negatives are falls.
- Model (:class:`PatchCNN`): VALID convolutions 4x4/2, 3x3/2, 3x3/2, 3x3/1 and a 1x1 logit, whose receptive field
  is exactly one 32 x 32 patch and whose total stride is 8. Applied to a whole ``[H, W]`` map it gives the logit of
  every patch whose top-left corner is at ``(8 i, 8 j)``: a ``[(H - 32) // 8 + 1, (W - 32) // 8 + 1]`` map (29 x 29
  at 256 x 256) in one pass of convolutions, no loop over patches. The first convolution's kernels are made to sum
  to zero (:class:`ZeroSumConv`), so the network cannot see a height offset: its output on a patch equals its output
  on the same patch relative to its centre, which is why the strided map equals the model applied patch by patch
  (``tests/test_traversability.py``).

The shipped model (``jaxterrain/assets/traversability/``, see its ``PROVENANCE.md``) is loaded on the first call of
:func:`descriptor` (never at import). Importing this module registers the ``"traversability"`` descriptor in
:mod:`jaxterrain.features`.
"""

from __future__ import annotations

import functools
import json
import os
from pathlib import Path
from typing import Any, Callable, NamedTuple, Optional

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from jaxterrain import features
from jaxterrain.terrain import TerrainScale, validate_scale

__all__ = ["PATCH", "MAP_STRIDE", "ASSET_DIR", "LabelConfig", "ModelConfig", "TrainConfig", "Walks", "PatchCNN",
           "ZeroSumConv", "walk", "walk_fn", "window_labels", "labelled_centres", "extract_patches",
           "extract_patches_batch", "pixel_of", "balanced_indices", "init_params", "apply_patches", "logit_map",
           "traversability_map", "descriptor", "make_descriptor", "train", "roc_auc", "accuracy", "save", "load", "shipped", "Model"]

PATCH = 32  # pixels (1.28 m at 0.04 m per pixel)
MAP_STRIDE = 8  # pixels between neighbouring patches of a traversability map (the network's total stride)
ASSET_DIR = Path(__file__).resolve().parent / "assets" / "traversability"
WEIGHTS_NAME, CONFIG_NAME = "weights.msgpack", "config.json"
FORMAT = "jaxterrain-traversability-v1"


# ----------------------------------------------------------------------------------------------------------------
# Configs


class LabelConfig(NamedTuple):
    """How a walk becomes labelled windows (:func:`window_labels`).

    window: env steps per window (30 = 0.45 s). threshold: metres the torso must advance along +x within the
    window. every: env steps between window starts. warmup: windows start no earlier than this step (the walker
    starts from rest)."""

    window: int = 30
    threshold: float = 0.3
    every: int = 4
    warmup: int = 8


class ModelConfig(NamedTuple):
    """:class:`PatchCNN` architecture: ``channels`` of its four convolutions; ``input_scale`` multiplies heights
    in metres (so a 0.1 m step is an input of 1)."""

    channels: tuple[int, int, int, int] = (16, 32, 32, 64)
    input_scale: float = 10.0


class TrainConfig(NamedTuple):
    """:func:`train`: Adam at ``learning_rate`` (cosine decay to 0), ``steps`` minibatches of ``batch`` patches,
    L2 ``weight_decay``; ``flip_y`` adds the patches mirrored across the walking line (the humanoid is symmetric)."""

    steps: int = 2000
    batch: int = 128
    learning_rate: float = 2e-3
    weight_decay: float = 1e-4
    flip_y: bool = True


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
    along +x, at most ``horizon`` env steps, the pattern of :func:`jaxterrain.difficulty.batched_distances`:
    vmap over terrains and attempts, a ``while_loop`` over time that stops once every walk has ended. ``env`` of
    either layout (:mod:`jaxterrain.rollout`: a tiled env is sized to the call); ``Walks.xy`` are positions on the
    map either way (a tiled env's tile origin subtracted)."""
    from jaxterrain.rollout import sized_env, terrain_batch

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
    from jaxterrain import difficulty

    policy = difficulty.default_policy()
    config = difficulty.default_env_config(shape, scale, policy, backend)._replace(start_spread=float(start_spread))
    return jax.jit(walk_fn(difficulty.make_env(config), policy, attempts, horizon))


def walk(key: jax.Array, heightmaps, attempts: int = 4, horizon: int = 300, scale: TerrainScale = TerrainScale(),
         start_spread: float = 0.0, backend: str = "jax") -> Walks:
    """The shipped base policy's walks on ``heightmaps`` ``[B, H, W]`` in [0, 1] (metres by ``scale``), along +x
    from the start edge, at lateral offsets uniform in ``[-start_spread, start_spread]`` m, under the physics
    ``backend`` (``"jax"`` or ``"warp"``: MuJoCo Warp on tiles, :func:`jaxterrain.difficulty.default_env_config`).
    One compiled program per (shape, scale, attempts, horizon, start_spread, backend), reused across calls. Returns
    :class:`Walks`."""
    from jaxterrain import difficulty
    from jaxterrain.walker import BACKENDS

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


# ----------------------------------------------------------------------------------------------------------------
# The model


class ZeroSumConv(nn.Module):
    """A VALID convolution whose every kernel sums to zero (over its window and input channels): it responds to
    height differences only, so adding a constant to its input changes nothing. ``[..., H, W, C] -> [..., H', W',
    features]``."""

    features: int
    kernel_size: tuple[int, int]
    strides: tuple[int, int]

    @nn.compact
    def __call__(self, x):
        kernel = self.param("kernel", nn.initializers.lecun_normal(), (*self.kernel_size, x.shape[-1], self.features))
        bias = self.param("bias", nn.initializers.zeros, (self.features,))
        kernel = kernel - jnp.mean(kernel, axis=(0, 1, 2), keepdims=True)
        lead = x.shape[:-3]
        y = lax.conv_general_dilated(x.reshape(-1, *x.shape[-3:]), kernel, self.strides, "VALID",
                                     dimension_numbers=("NHWC", "HWIO", "NHWC"))
        return y.reshape(*lead, *y.shape[1:]) + bias


class PatchCNN(nn.Module):
    """Traversability logits: ``[..., H, W]`` heights in metres -> ``[..., (H - 32) // 8 + 1, (W - 32) // 8 + 1]``
    (``[..., 1, 1]`` for one 32 x 32 patch). Receptive field 32 x 32, stride 8 (module docstring)."""

    channels: tuple[int, int, int, int] = ModelConfig().channels
    input_scale: float = ModelConfig().input_scale

    @nn.compact
    def __call__(self, heights):
        c = self.channels
        x = heights[..., None] * self.input_scale
        x = nn.relu(ZeroSumConv(c[0], (4, 4), (2, 2), name="conv0")(x))
        x = nn.relu(nn.Conv(c[1], (3, 3), (2, 2), padding="VALID", name="conv1")(x))
        x = nn.relu(nn.Conv(c[2], (3, 3), (2, 2), padding="VALID", name="conv2")(x))
        x = nn.relu(nn.Conv(c[3], (3, 3), (1, 1), padding="VALID", name="conv3")(x))
        return nn.Conv(1, (1, 1), name="logit")(x)[..., 0]


def _module(config: ModelConfig) -> PatchCNN:
    return PatchCNN(channels=tuple(int(c) for c in config.channels), input_scale=float(config.input_scale))


def init_params(key: jax.Array, config: ModelConfig = ModelConfig()) -> Any:
    """Fresh parameters (a flax variables dict) of :class:`PatchCNN` with ``config``."""
    return _module(config).init(key, jnp.zeros((1, PATCH, PATCH), jnp.float32))


def apply_patches(params, patches, config: ModelConfig = ModelConfig()) -> jax.Array:
    """Logits ``[N]`` of patches ``[N, 32, 32]`` (metres; any offset, e.g. relative to the centre)."""
    p = jnp.asarray(patches, jnp.float32)
    if p.shape[-2:] != (PATCH, PATCH):
        raise ValueError(f"patches must be [N, {PATCH}, {PATCH}]; got shape {tuple(p.shape)}")
    return _module(config).apply(params, p)[..., 0, 0]


def logit_map(params, terrains_m, config: ModelConfig = ModelConfig()) -> jax.Array:
    """Logits of every patch at stride 8: ``[..., H, W]`` metres -> ``[..., H', W']``; entry ``(i, j)`` is the
    patch with top-left pixel ``(8 i, 8 j)`` (centre ``(8 i + 16, 8 j + 16)``)."""
    t = jnp.asarray(terrains_m, jnp.float32)
    if t.ndim < 2 or min(t.shape[-2:]) < PATCH:
        raise ValueError(f"terrains must be [..., H, W] with H, W >= {PATCH}; got shape {tuple(t.shape)}")
    return _module(config).apply(params, t)


def traversability_map(params, heightmaps, config: ModelConfig = ModelConfig(),
                       scale: TerrainScale = TerrainScale()) -> jax.Array:
    """Traversability probabilities ``[..., (H - 32) // 8 + 1, (W - 32) // 8 + 1]`` in (0, 1) of heightmaps
    ``[..., H, W]`` in heightmap units (metres by ``scale.height``; the model assumes ``scale.cell_size`` 0.04 m)."""
    return jax.nn.sigmoid(logit_map(params, jnp.asarray(heightmaps, jnp.float32) * scale.height, config))


# ----------------------------------------------------------------------------------------------------------------
# Weights on disk


class Model(NamedTuple):
    """A loaded model: ``params`` (flax variables), ``config`` (:class:`ModelConfig`), ``meta`` (config.json)."""

    params: Any
    config: ModelConfig
    meta: dict


def save(folder: str | os.PathLike, params, config: ModelConfig = ModelConfig(),
         extra: Optional[dict] = None) -> Path:
    """Write ``folder/weights.msgpack`` (flax.serialization) and ``folder/config.json`` (``config`` and ``extra``),
    atomically. Returns the folder."""
    from flax import serialization

    from jaxterrain.io import atomic_write_bytes, atomic_write_text

    folder = Path(folder)
    host = jax.tree.map(lambda a: np.asarray(jax.device_get(a)), params)
    atomic_write_bytes(folder / WEIGHTS_NAME, serialization.msgpack_serialize(host))
    meta = {"format": FORMAT, "patch": PATCH, "map_stride": MAP_STRIDE,
            "model": {"channels": list(config.channels), "input_scale": float(config.input_scale)}, **(extra or {})}
    atomic_write_text(folder / CONFIG_NAME, json.dumps(meta, indent=2) + "\n")
    return folder


def _read_config(path: Path) -> tuple[ModelConfig, dict]:
    try:
        meta = json.loads(path.read_text())
        if meta.get("format") != FORMAT:
            raise ValueError(f"format is {meta.get('format')!r}, expected {FORMAT!r}")
        model = meta["model"]
        return ModelConfig(tuple(int(c) for c in model["channels"]), float(model["input_scale"])), meta
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as err:
        raise ValueError(f"{path}: not a readable traversability model config ({err})") from err


def load(folder: str | os.PathLike | None = None) -> Model:
    """Load a model saved by :func:`save` (default: the shipped one, :data:`ASSET_DIR`).

    Raises ``FileNotFoundError`` when a file is missing and ``ValueError`` naming the file when it is corrupt or
    its weights do not have the shapes of its config's architecture."""
    from flax import serialization

    folder = Path(folder) if folder is not None else ASSET_DIR
    weights, cfg_path = folder / WEIGHTS_NAME, folder / CONFIG_NAME
    for p in (cfg_path, weights):
        if not p.is_file():
            raise FileNotFoundError(f"traversability model file missing: {p}")
    config, meta = _read_config(cfg_path)
    try:
        stored = serialization.msgpack_restore(weights.read_bytes())
    except Exception as err:  # msgpack raises several unrelated types on corrupt bytes
        raise ValueError(f"{weights}: corrupt traversability weights, cannot be decoded ({err})") from err
    like = jax.eval_shape(lambda: init_params(jax.random.key(0), config))
    flat_like = dict(jax.tree_util.tree_flatten_with_path(like)[0])
    try:
        flat = jax.tree_util.tree_flatten_with_path(stored)[0]
    except Exception as err:  # pragma: no cover
        raise ValueError(f"{weights}: not a parameter tree ({err})") from err
    got = {p: np.asarray(v) for p, v in flat}
    if set(got) != set(flat_like):
        raise ValueError(f"{weights}: parameters {sorted(map(jax.tree_util.keystr, got))} do not match the "
                         f"architecture of {cfg_path} ({sorted(map(jax.tree_util.keystr, flat_like))})")
    for p, spec in flat_like.items():
        if got[p].shape != spec.shape:
            raise ValueError(f"{weights}: parameter {jax.tree_util.keystr(p)} has shape {got[p].shape}, the "
                             f"architecture in {cfg_path} needs {spec.shape}")
    # numpy leaves: a first load inside a jit trace (the descriptor called by a jitted features.descriptors) must
    # not turn the cached weights into that trace's tracers
    params = jax.tree_util.tree_unflatten(jax.tree.structure(like),
                                          [np.asarray(got[p], np.float32) for p in flat_like])
    return Model(params=params, config=config, meta=meta)


@functools.lru_cache(maxsize=1)
def shipped() -> Model:
    """The shipped model (``jaxterrain/assets/traversability/``), loaded once on first use."""
    return load(None)


# ----------------------------------------------------------------------------------------------------------------
# The descriptor


def make_descriptor(model: Model, scale: TerrainScale = TerrainScale()) -> Callable:
    """``fn(heightmaps [B, H, W] in [0, 1]) -> [B]``: the mean of :func:`traversability_map` (jit / vmap-able)."""

    @jax.jit
    def fn(heightmaps):
        return jnp.mean(traversability_map(model.params, heightmaps, model.config, scale), axis=(-2, -1))

    return fn


@functools.lru_cache(maxsize=1)
def _shipped_descriptor() -> Callable:
    return make_descriptor(shipped())


def descriptor(heightmaps) -> jax.Array:
    """The ``"traversability"`` descriptor: mean traversability probability of the shipped model over the strided
    map, ``[B, H, W]`` (heightmap units, H, W >= 32) -> ``[B]`` float32 in (0, 1); ``[H, W]`` -> ``[]``. The
    weights are loaded on the first call."""
    return _shipped_descriptor()(heightmaps)


features.register_descriptor("traversability", descriptor, windowed=False, overwrite=True)


# ----------------------------------------------------------------------------------------------------------------
# Training and metrics


def _loss(params, patches, labels, config: ModelConfig, weight_decay: float):
    logits = apply_patches(params, patches, config)
    bce = jnp.mean(jnp.maximum(logits, 0) - logits * labels + jnp.log1p(jnp.exp(-jnp.abs(logits))))
    l2 = sum(jnp.sum(jnp.square(w)) for p, w in jax.tree_util.tree_leaves_with_path(params)
             if jax.tree_util.keystr(p).endswith("['kernel']"))
    return bce + weight_decay * l2


def train(key: jax.Array, patches, labels, config: TrainConfig = TrainConfig(),
          model_config: ModelConfig = ModelConfig(), log: Optional[Callable[[int, float], None]] = None) -> Any:
    """Fit :class:`PatchCNN` to binary ``labels [N]`` of ``patches [N, 32, 32]`` (metres) by minibatch Adam on
    the logistic loss. Returns the params. ``log(step, loss)`` is called every 200 steps and at the end."""
    import optax

    p = jnp.asarray(patches, jnp.float32)
    y = jnp.asarray(labels, jnp.float32)
    if p.ndim != 3 or p.shape[0] != y.shape[0] or p.shape[0] < 2:
        raise ValueError(f"patches [N, {PATCH}, {PATCH}] and labels [N] need the same N >= 2; got "
                         f"{tuple(p.shape)} and {tuple(y.shape)}")
    if config.flip_y:
        p, y = jnp.concatenate([p, p[:, ::-1, :]]), jnp.concatenate([y, y])
    k_init, k_data = jax.random.split(key)
    params = init_params(k_init, model_config)
    opt = optax.adam(optax.cosine_decay_schedule(config.learning_rate, config.steps))
    batch = min(int(config.batch), p.shape[0])

    @jax.jit
    def update(params, opt_state, k):
        idx = jax.random.choice(k, p.shape[0], (batch,), replace=False)
        loss, grads = jax.value_and_grad(_loss)(params, p[idx], y[idx], model_config, config.weight_decay)
        updates, opt_state = opt.update(grads, opt_state, params)
        return optax.apply_updates(params, updates), opt_state, loss

    opt_state = opt.init(params)
    for s in range(int(config.steps)):
        params, opt_state, loss = update(params, opt_state, jax.random.fold_in(k_data, s))
        if log is not None and ((s + 1) % 200 == 0 or s + 1 == config.steps):
            log(s + 1, float(loss))
    return params


def roc_auc(scores, labels) -> float:
    """Area under the ROC curve of ``scores [N]`` for binary ``labels [N]`` (Mann-Whitney U, ties counted 1/2);
    NaN when a class is missing."""
    from scipy.stats import rankdata

    s, y = np.asarray(scores, np.float64), np.asarray(labels).astype(bool)
    n1, n0 = int(y.sum()), int((~y).sum())
    if n1 == 0 or n0 == 0:
        return float("nan")
    ranks = rankdata(s)
    return float((ranks[y].sum() - n1 * (n1 + 1) / 2) / (n1 * n0))


def accuracy(scores, labels, threshold: float = 0.0) -> float:
    """Fraction of ``scores > threshold`` (logits: 0) that equal binary ``labels``."""
    return float(np.mean((np.asarray(scores) > threshold) == np.asarray(labels).astype(bool)))
