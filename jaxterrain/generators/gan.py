"""The GAN generator (paper 3.1.4): a DCGAN trained on real terrain; its genome is the 50-value latent.

    >>> gen = jaxterrain.generators.get("gan")             # loads jaxterrain/assets/gan/
    >>> z = gen.sample(key, 8)                              # [8, 50] float32 in [-3, 3]
    >>> maps = gen.render(z)                                # [8, 256, 256] float32 in [0, 1]

Architecture (flax linen, NHWC; :class:`GanConfig`, stored in ``config.json`` beside the weights):

* generator: latent ``[B, 50]`` -> Dense -> ``4 x 4 x C0`` -> BatchNorm -> ReLU, then per entry of
  ``channels[1:]`` one block "nearest-neighbour upsample x2 -> 3 x 3 conv -> BatchNorm -> ReLU" (4 -> 8 -> ... ->
  128 for the default ``channels=(256, 128, 64, 32, 16, 8)``), then an output layer "upsample x r -> 3 x 3 conv to
  one channel" (``r = size / 128``), so the costliest resolution, 256 x 256, has a single 8 -> 1 conv. Convs use
  reflect padding (zero padding gave bright / dark map borders in a first trial). The output map is min-max
  normalised to [0, 1] per terrain, exactly as every training patch is (``jaxterrain.terrain.dem``): with a sigmoid the
  generator would have to learn to hit 0 and 1 exactly (a first trial with a sigmoid stalled with every output
  inside [0, 0.5]). BatchNorm uses its running averages at inference, so each terrain depends on its own latent
  only. Default: 0.60 M parameters (2.4 MB float32), 0.199 GFLOPs per 256 x 256 sample (:func:`generator_flops`).
* discriminator: 4 x 4 stride-2 convs with LeakyReLU(0.2) (``disc_channels``), then a dense logit; no normalisation.

Genome: the 50 latent values, each in [-3, 3]. The GAN is trained on latents from N(0, 1) truncated to [-3, 3]
(99.7 % of N(0, 1) per value), so every genome in the range is one the generator has seen; ``sample`` draws from
that same truncated normal (not uniform: uniform latents would be far from the training distribution, with a norm
~1.7 x larger). ``mutate`` is the paper's: each value with probability 0.07 moves by N(0, (0.1 * 6)^2), clipped.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain.generators.base import Generator, spec, vector_generator
from jaxterrain.generators.registry import register
from jaxterrain.runtime.io import atomic_write_bytes, atomic_write_text

ASSET_DIR = Path(__file__).resolve().parent.parent / "assets" / "gan"
WEIGHTS_FILE = "generator.msgpack"
CONFIG_FILE = "config.json"
LATENT_RANGE = 3.0
MUTATION_PROB = 0.07
MUTATION_SIGMA = 0.1


class GanConfig(NamedTuple):
    """The DCGAN architecture (static, JSON-serialisable).

    Attributes:
      latent: latent (genome) length.
      size: side of the generated map; ``size / (base * 2 ** (len(channels) - 1))`` must be a power of 2 (>= 1),
        the factor of the final nearest-neighbour upsampling.
      base: side of the first feature map.
      channels: generator channels at ``base``, ``2 base``, ... (one upsampling block per entry after the first).
      disc_channels: discriminator channels of the stride-2 convs (input side / 2, / 4, ...).
    """

    latent: int = 50
    size: int = 256
    base: int = 4
    channels: tuple[int, ...] = (256, 128, 64, 32, 16, 8)
    disc_channels: tuple[int, ...] = (16, 32, 64, 128, 256, 256)

    @property
    def final_res(self) -> int:
        return self.base * 2 ** (len(self.channels) - 1)

    @property
    def shuffle(self) -> int:
        return self.size // self.final_res

    def check(self) -> "GanConfig":
        r = self.size / self.final_res
        if r < 1 or r != int(r) or (int(r) & (int(r) - 1)):
            raise ValueError(
                f"GanConfig: size={self.size} must be base * 2**(len(channels)-1) = {self.final_res} times a power "
                f"of 2"
            )
        if self.size % 2 ** len(self.disc_channels):
            raise ValueError(f"GanConfig: size={self.size} must be divisible by 2**len(disc_channels)")
        if self.latent < 1:
            raise ValueError(f"GanConfig: latent must be >= 1; got {self.latent}")
        return self

    def to_json(self) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in self._asdict().items()}

    @classmethod
    def from_json(cls, d: dict) -> "GanConfig":
        fields = {k: tuple(v) if isinstance(v, list) else v for k, v in d.items() if k in cls._fields}
        return cls(**fields).check()


def _nn():
    import flax.linen as nn

    return nn


def _upsample(x: jax.Array, r: int) -> jax.Array:
    """Nearest-neighbour x ``r`` of ``[B, H, W, C]``."""
    if r == 1:
        return x
    b, h, w, c = x.shape
    x = jnp.broadcast_to(x[:, :, None, :, None, :], (b, h, r, w, r, c))
    return x.reshape(b, r * h, r * w, c)


def _reflect_pad(x: jax.Array) -> jax.Array:
    """Reflect-pad ``[B, H, W, C]`` by one pixel (no zero border, hence no bright / dark map edges)."""
    return jnp.pad(x, ((0, 0), (1, 1), (1, 1), (0, 0)), mode="reflect")


def _minmax(x: jax.Array, eps: float = 1e-6) -> jax.Array:
    """Per-map min-max normalisation of ``[B, H, W]`` to [0, 1] (a flat map gives zeros), like the training patches."""
    lo = x.min(axis=(1, 2), keepdims=True)
    rng = x.max(axis=(1, 2), keepdims=True) - lo
    return jnp.where(rng > eps, (x - lo) / jnp.maximum(rng, eps), 0.0)


def make_modules(config: GanConfig):
    """The flax linen modules ``(generator, discriminator)`` for ``config``.

    ``generator.apply(variables, z[B, latent], train) -> [B, size, size]`` in [0, 1] (``variables`` has
    ``params`` and ``batch_stats``; pass ``mutable=["batch_stats"]`` when ``train``);
    ``discriminator.apply({"params": p}, x[B, size, size]) -> logits[B]``.
    """
    nn = _nn()
    config.check()

    class DCGANGenerator(nn.Module):
        cfg: GanConfig

        @nn.compact
        def __call__(self, z, train: bool = False):
            cfg = self.cfg
            bn = lambda: nn.BatchNorm(use_running_average=not train, momentum=0.9, epsilon=1e-5)  # noqa: E731
            x = nn.Dense(cfg.base * cfg.base * cfg.channels[0])(z)
            x = x.reshape(z.shape[0], cfg.base, cfg.base, cfg.channels[0])
            x = nn.relu(bn()(x))
            for c in cfg.channels[1:]:
                x = nn.Conv(c, (3, 3), padding="VALID", use_bias=False)(_reflect_pad(_upsample(x, 2)))
                x = nn.relu(bn()(x))
            x = nn.Conv(1, (3, 3), padding="VALID")(_reflect_pad(_upsample(x, cfg.shuffle)))
            return _minmax(x[..., 0])

    class DCGANDiscriminator(nn.Module):
        cfg: GanConfig

        @nn.compact
        def __call__(self, x):
            x = x[..., None]
            for c in self.cfg.disc_channels:
                x = nn.leaky_relu(nn.Conv(c, (4, 4), strides=(2, 2))(x), 0.2)
            return nn.Dense(1)(x.reshape(x.shape[0], -1))[:, 0]

    return DCGANGenerator(config), DCGANDiscriminator(config)


def generator_flops(config: GanConfig = GanConfig()) -> int:
    """Multiply-adds x 2 of one generator forward pass (convolutions and dense layers; elementwise ops excluded)."""
    flops = 2 * config.latent * config.base**2 * config.channels[0]
    res, cin = config.base, config.channels[0]
    for c in config.channels[1:]:
        res *= 2
        flops += 2 * res * res * 9 * cin * c
        cin = c
    res *= config.shuffle
    flops += 2 * res * res * 9 * cin
    return int(flops)


def init_variables(key: jax.Array, config: GanConfig) -> tuple[dict, dict]:
    """DCGAN initialisation (Radford et al. 2016): kernels N(0, 0.02), biases 0, BatchNorm scale 1 / shift 0.

    Returns ``(generator variables {"params", "batch_stats"}, discriminator variables {"params"})`` as float32
    arrays. Drawn with numpy from the key's bits: no XLA compilation (initialisers are slow to compile on CPU).
    """
    gen, disc = make_modules(config)
    seed = np.asarray(jax.random.key_data(key) if jnp.issubdtype(key.dtype, jax.dtypes.prng_key) else key)
    rng = np.random.default_rng(seed.astype(np.uint64).tolist())
    g_shapes = jax.eval_shape(lambda: gen.init(jax.random.PRNGKey(0), jnp.zeros((1, config.latent)), train=False))
    d_shapes = jax.eval_shape(lambda: disc.init(jax.random.PRNGKey(0), jnp.zeros((1, config.size, config.size))))

    def fill(path, leaf):
        name = getattr(path[-1], "key", str(path[-1]))
        if name == "kernel":
            value = rng.normal(0.0, 0.02, leaf.shape)
        elif name in ("scale", "var"):
            value = np.ones(leaf.shape)
        else:  # bias, mean
            value = np.zeros(leaf.shape)
        return jnp.asarray(value, jnp.float32)

    g = jax.tree_util.tree_map_with_path(fill, g_shapes)
    d = jax.tree_util.tree_map_with_path(fill, d_shapes)
    return dict(g), dict(d)


def count_params(tree: Any) -> int:
    """Number of scalars in a pytree of arrays (or shape structs)."""
    return int(sum(math.prod(x.shape) for x in jax.tree_util.tree_leaves(tree)))


# ----------------------------------------------------------------------------------------------------------------
# Weights on disk
# ----------------------------------------------------------------------------------------------------------------


def save_generator(directory: str | os.PathLike, config: GanConfig, variables: dict) -> Path:
    """Write ``generator.msgpack`` (flax msgpack of ``{"params", "batch_stats"}``, float32) and ``config.json``."""
    from flax import serialization


    directory = Path(directory)
    host = jax.tree_util.tree_map(lambda x: np.asarray(x, np.float32), dict(variables))
    atomic_write_bytes(directory / WEIGHTS_FILE, serialization.msgpack_serialize(host))
    atomic_write_text(directory / CONFIG_FILE, json.dumps(config.to_json(), indent=2) + "\n")
    return directory


def load_generator(weights: str | os.PathLike | None = None) -> tuple[GanConfig, dict]:
    """``(config, {"params", "batch_stats"})`` from a folder (or the ``.msgpack`` file, ``config.json`` beside it).

    ``weights=None`` reads the shipped ``jaxterrain/assets/gan/``. Raises ``FileNotFoundError`` saying how to make
    them when they are missing.
    """
    from flax import serialization

    path = Path(weights) if weights is not None else ASSET_DIR
    wfile = path if path.suffix == ".msgpack" else path / WEIGHTS_FILE
    cfile = wfile.parent / CONFIG_FILE
    if not wfile.is_file() or not cfile.is_file():
        where = "the shipped GAN weights" if weights is None else "GAN weights"
        raise FileNotFoundError(
            f"{where} are missing: need {wfile} and {cfile}. Train them with "
            f"`python -m experiments train-gan --preset gpu --export-assets` (writes jaxterrain/assets/gan/), or pass "
            f"weights=<run folder>/final from `python -m experiments train-gan`"
        )
    config = GanConfig.from_json(json.loads(cfile.read_text()))
    variables = serialization.msgpack_restore(wfile.read_bytes())
    if set(variables) != {"params", "batch_stats"}:
        raise ValueError(f"GAN weights {wfile}: expected 'params' and 'batch_stats', found {sorted(variables)}")
    return config, jax.tree_util.tree_map(lambda x: jnp.asarray(x, jnp.float32), variables)


# ----------------------------------------------------------------------------------------------------------------
# Generator factory
# ----------------------------------------------------------------------------------------------------------------


def latent_spec(latent: int = 50):
    """The genome: ``z0 .. z{latent-1}``, each in [-3, 3]."""
    return spec(*[(f"z{i}", -LATENT_RANGE, LATENT_RANGE, False) for i in range(latent)])


def sample_latents(key: jax.Array, n: int, latent: int = 50) -> jax.Array:
    """``[n, latent]`` float32 from N(0, 1) truncated to [-3, 3] (the training prior of the GAN)."""
    return jax.random.truncated_normal(key, -LATENT_RANGE, LATENT_RANGE, (n, latent), jnp.float32)


def make_render_one(config: GanConfig, variables: dict, size: int | None = None):
    """``latent[latent] -> [size, size]`` float32 in [0, 1], the inference forward pass (running BN averages).

    When ``size`` differs from ``config.size`` the output is resampled (linear, antialiased); either way it is
    clipped to [0, 1] (the normalisation may round one ulp past it).
    """
    generator, _ = make_modules(config)
    size = config.size if size is None else int(size)

    def render_one(z: jax.Array) -> jax.Array:
        out = generator.apply(variables, z[None].astype(jnp.float32), train=False)[0]
        if size != config.size:
            out = jax.image.resize(out, (size, size), "linear", antialias=True)
        # the per-terrain min-max normalisation can round one ulp past 1 on a GPU (seen on an H200, 2026-11-28)
        return jnp.clip(out, 0.0, 1.0)

    return render_one


@register("gan")
def gan(size: int = 256, weights: str | os.PathLike | None = None) -> Generator:
    """The DCGAN generator with the shipped weights (or ``weights``: a folder with generator.msgpack + config.json).

    Genome ``[B, 50]`` in [-3, 3]; ``sample`` draws truncated N(0, 1); mutation probability 0.07, sigma 10 % of the
    range (paper 3.3). Renders ``[B, size, size]`` float32 in [0, 1].
    """
    if int(size) < 1:
        raise ValueError(f"gan: size must be >= 1; got {size}")
    config, variables = load_generator(weights)
    gspec = latent_spec(config.latent)
    gen = vector_generator(
        "gan", gspec, make_render_one(config, variables, size), int(size), MUTATION_PROB, MUTATION_SIGMA
    )

    def sample(key: jax.Array, n: int) -> jax.Array:
        return sample_latents(key, n, config.latent)

    return gen._replace(sample=sample)


__all__ = [
    "ASSET_DIR",
    "GanConfig",
    "count_params",
    "gan",
    "generator_flops",
    "latent_spec",
    "load_generator",
    "make_modules",
    "make_render_one",
    "sample_latents",
    "save_generator",
]
