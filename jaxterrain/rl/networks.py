"""Policy / value MLPs, the running observation normaliser and the action distribution, as pure functions."""

from __future__ import annotations

import math
from typing import NamedTuple, Sequence

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain.rl.config import PPOConfig

__all__ = ["RunningStats", "init_stats", "update_stats", "stats_std", "normalize", "MLP", "PolicyNet", "ValueNet",
           "policy_net", "value_net", "init_params", "policy_apply", "value_apply", "sample_raw", "log_prob",
           "entropy", "postprocess", "deterministic_action"]

_ACT = {"swish": nn.swish, "relu": nn.relu, "tanh": nn.tanh, "elu": nn.elu}


# ----------------------------------------------------------------------------------------------------------------
# Running observation statistics (Welford / Chan parallel merge), a pytree.
# ----------------------------------------------------------------------------------------------------------------
class RunningStats(NamedTuple):
    """Running mean / variance of observations.

    count: [] float32 number of observations seen; mean: [O] float32; m2: [O] float32 sum of squared deviations.
    """

    count: jax.Array
    mean: jax.Array
    m2: jax.Array


def init_stats(observation_size: int) -> RunningStats:
    """Empty statistics: normalisation is the identity until the first update. ``observation_size``: an integer
    >= 1."""
    if not isinstance(observation_size, (int, np.integer)) or isinstance(observation_size, bool) \
            or observation_size < 1:
        raise ValueError(f"observation_size must be an integer >= 1; got {observation_size!r}")
    z = jnp.zeros((observation_size,), jnp.float32)
    return RunningStats(jnp.zeros((), jnp.float32), z, z)


def update_stats(stats: RunningStats, obs: jax.Array) -> RunningStats:
    """Merge a batch ``obs [..., O]`` into ``stats`` (Chan et al. parallel Welford update)."""
    _check_obs(stats, obs)
    x = jnp.reshape(obs, (-1, obs.shape[-1])).astype(jnp.float32)
    n_b = jnp.asarray(x.shape[0], jnp.float32)
    mean_b = jnp.mean(x, axis=0)
    m2_b = jnp.sum(jnp.square(x - mean_b), axis=0)
    n = stats.count + n_b
    delta = mean_b - stats.mean
    mean = stats.mean + delta * (n_b / n)
    m2 = stats.m2 + m2_b + jnp.square(delta) * (stats.count * n_b / n)
    return RunningStats(n, mean, m2)


def stats_std(stats: RunningStats) -> jax.Array:
    """[O] standard deviation, clipped to [1e-6, 1e6] as brax; 1 before any data."""
    var = stats.m2 / jnp.maximum(stats.count, 1.0)
    return jnp.where(stats.count > 0, jnp.clip(jnp.sqrt(var), 1e-6, 1e6), 1.0)


def normalize(stats: RunningStats, obs: jax.Array) -> jax.Array:
    """``(obs - mean) / std`` for ``obs [..., O]``."""
    _check_obs(stats, obs)
    return (obs - stats.mean) / stats_std(stats)


def _check_obs(stats: RunningStats, obs) -> None:
    """``obs`` must be ``[..., O]`` with the statistics' ``O`` (static shapes: a trace-time check under jit)."""
    shape, size = tuple(getattr(obs, "shape", ())), tuple(getattr(stats.mean, "shape", ()))[-1:]
    if len(shape) < 1 or shape[-1:] != size:
        raise ValueError(f"obs must have shape [..., O] with O = {size[0] if size else '?'} (the statistics' "
                         f"observation size); got shape {shape}")


# ----------------------------------------------------------------------------------------------------------------
# Networks
# ----------------------------------------------------------------------------------------------------------------
class MLP(nn.Module):
    """Dense layers ``layer_sizes`` with ``activation`` between them (none after the last); LeCun-uniform init."""

    layer_sizes: Sequence[int]
    activation: str = "swish"

    @nn.compact
    def __call__(self, x):
        for i, size in enumerate(self.layer_sizes):
            x = nn.Dense(size, kernel_init=nn.initializers.lecun_uniform(), name=f"hidden_{i}")(x)
            if i < len(self.layer_sizes) - 1:
                x = _ACT[self.activation](x)
        return x


class PolicyNet(nn.Module):
    """obs [..., O] -> (loc [..., A], scale [..., A]) of the pre-squash Gaussian."""

    action_size: int
    hidden: Sequence[int]
    activation: str
    distribution: str
    min_std: float
    init_std: float

    @nn.compact
    def __call__(self, x):
        if self.distribution == "tanh_normal":
            out = MLP(tuple(self.hidden) + (2 * self.action_size,), self.activation, name="mlp")(x)
            loc, raw_scale = jnp.split(out, 2, axis=-1)
            return loc, jax.nn.softplus(raw_scale) + self.min_std
        loc = MLP(tuple(self.hidden) + (self.action_size,), self.activation, name="mlp")(x)
        log_std = self.param("log_std", nn.initializers.constant(math.log(self.init_std)), (self.action_size,))
        return loc, jnp.broadcast_to(jnp.exp(log_std), loc.shape)


class ValueNet(nn.Module):
    """obs [..., O] -> value [...]."""

    hidden: Sequence[int]
    activation: str

    @nn.compact
    def __call__(self, x):
        return MLP(tuple(self.hidden) + (1,), self.activation, name="mlp")(x)[..., 0]


def policy_net(config: PPOConfig, action_size: int) -> PolicyNet:
    return PolicyNet(action_size, tuple(config.policy_hidden), config.activation, config.action_distribution,
                     float(config.min_std), float(config.init_std))


def value_net(config: PPOConfig) -> ValueNet:
    return ValueNet(tuple(config.value_hidden), config.activation)


def init_params(key: jax.Array, config: PPOConfig, observation_size: int, action_size: int) -> dict:
    """``{"policy": ..., "value": ...}`` flax variable dicts."""
    policy_key, value_key = jax.random.split(key)
    del key
    dummy = jnp.zeros((1, observation_size), jnp.float32)
    return {
        "policy": policy_net(config, action_size).init(policy_key, dummy),
        "value": value_net(config).init(value_key, dummy),
    }


def policy_apply(config: PPOConfig, action_size: int, params: dict, stats: RunningStats, obs: jax.Array):
    """obs [..., O] (raw) -> (loc, scale) [..., A]; ``params`` is the full ``{"policy", "value"}`` dict."""
    x = normalize(stats, obs) if config.normalize_observations else obs
    return policy_net(config, action_size).apply(params["policy"], x)


def value_apply(config: PPOConfig, params: dict, stats: RunningStats, obs: jax.Array) -> jax.Array:
    """obs [..., O] (raw) -> value [...]."""
    x = normalize(stats, obs) if config.normalize_observations else obs
    return value_net(config).apply(params["value"], x)


# ----------------------------------------------------------------------------------------------------------------
# Action distribution over "raw" (pre-squash) actions; the env gets postprocess(raw) in [-1, 1].
# ----------------------------------------------------------------------------------------------------------------
_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)


def _tanh_log_det_jacobian(raw: jax.Array) -> jax.Array:
    """log |d tanh(x) / dx| elementwise, numerically stable (as brax's TanhBijector)."""
    return 2.0 * (math.log(2.0) - raw - jax.nn.softplus(-2.0 * raw))


def sample_raw(key: jax.Array, loc: jax.Array, scale: jax.Array) -> jax.Array:
    """One Gaussian sample ``[..., A]`` of the raw action."""
    return loc + scale * jax.random.normal(key, loc.shape, loc.dtype)


def log_prob(distribution: str, loc: jax.Array, scale: jax.Array, raw: jax.Array) -> jax.Array:
    """log-density [...] of the (squashed, for tanh_normal) action whose raw value is ``raw [..., A]``."""
    lp = -0.5 * jnp.square((raw - loc) / scale) - jnp.log(scale) - _LOG_SQRT_2PI
    if distribution == "tanh_normal":
        lp = lp - _tanh_log_det_jacobian(raw)
    return jnp.sum(lp, axis=-1)


def entropy(distribution: str, key: jax.Array, loc: jax.Array, scale: jax.Array,
            noise: jax.Array | None = None) -> jax.Array:
    """Entropy [...]: exact for ``normal``; for ``tanh_normal`` the Gaussian entropy plus the log-Jacobian at one
    sample (brax's single-sample estimate), ``sample_raw(key, loc, scale)``, or ``loc + scale * noise`` when the
    standard normal ``noise`` (loc's shape) is given (a data-parallel device's slice of the batch's draw)."""
    ent = 0.5 + _LOG_SQRT_2PI + jnp.log(scale)
    if distribution == "tanh_normal":
        raw = sample_raw(key, loc, scale) if noise is None else loc + scale * noise
        ent = ent + _tanh_log_det_jacobian(raw)
    return jnp.sum(ent, axis=-1)


def postprocess(distribution: str, raw: jax.Array) -> jax.Array:
    """Raw action -> env action in [-1, 1] (tanh or clip)."""
    return jnp.tanh(raw) if distribution == "tanh_normal" else jnp.clip(raw, -1.0, 1.0)


def deterministic_action(config: PPOConfig, action_size: int, params: dict, stats: RunningStats,
                         obs: jax.Array) -> jax.Array:
    """Mean (mode) action [..., A] in [-1, 1] for obs [..., O]."""
    loc, _ = policy_apply(config, action_size, params, stats, obs)
    return postprocess(config.action_distribution, loc)


