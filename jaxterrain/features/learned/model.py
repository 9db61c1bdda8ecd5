"""The learned traversability model: :class:`PatchCNN` (a strided CNN over heightmap patches), its weights on disk,
and the ``"traversability"`` descriptor of the shipped model (registered in :mod:`jaxterrain.features` on import)."""

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

from jaxterrain.features import registry
from jaxterrain.runtime.io import atomic_write_bytes, atomic_write_text
from jaxterrain.terrain import TerrainScale

__all__ = ["PATCH", "MAP_STRIDE", "ASSET_DIR", "ModelConfig", "PatchCNN", "ZeroSumConv", "init_params",
           "apply_patches", "logit_map", "traversability_map", "Model", "save", "load", "shipped", "make_descriptor",
           "descriptor"]

PATCH = 32  # pixels (1.28 m at 0.04 m per pixel)
MAP_STRIDE = 8  # pixels between neighbouring patches of a traversability map (the network's total stride)
ASSET_DIR = Path(__file__).resolve().parents[2] / "assets" / "traversability"
WEIGHTS_NAME, CONFIG_NAME = "weights.msgpack", "config.json"
FORMAT = "jaxterrain-traversability-v1"


class ModelConfig(NamedTuple):
    """:class:`PatchCNN` architecture: ``channels`` of its four convolutions; ``input_scale`` multiplies heights
    in metres (so a 0.1 m step is an input of 1)."""

    channels: tuple[int, int, int, int] = (16, 32, 32, 64)
    input_scale: float = 10.0


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


registry.register_descriptor("traversability", descriptor, windowed=False, overwrite=True)


