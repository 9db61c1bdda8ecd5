"""A perceptive twin of a blind policy, by network surgery: the same walk, with a height scan it can learn to use.

    params, normaliser = widen_inputs(params, normaliser, extra=153, mean=m [153], var=v [153])
    twin = perceptive_twin(rl.load_policy(), env)          # env: a WalkerEnv with observation="perceptive"
    rl.save_policy(folder, twin.params, twin.normaliser, twin.config, env.observation_size, env.action_size, ...)

The perceptive observation is the blind one with the scan appended (``jaxterrain.walker.WalkerEnv``: its first
``O_blind`` entries are the blind observation, unchanged). :func:`widen_inputs` gives the first dense layer of every
network (policy and value) zero weights for the new inputs and the observation normaliser the scan's mean and
variance, so the widened networks compute what the blind ones computed, up to float rounding (the scan enters as ``(scan - mean) /
std`` times zero) and the twin walks like its blind policy until training moves those weights. The normaliser's
count is kept, so its running statistics go on as before; the scan's variance is floored (``std_floor``, metres)
because on flat ground it is only the torso's bob, and a step of the curriculum's terrain would otherwise be tens
of standard deviations.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain.rl import networks as nets
from jaxterrain.rl.config import PPOConfig

__all__ = ["PerceptiveTwin", "widen_inputs", "scan_statistics", "perceptive_twin"]


class PerceptiveTwin(NamedTuple):
    """A widened policy: ``params`` (as the blind policy's: ``{"policy"[, "value"]}``), ``normaliser``
    (:class:`~jaxterrain.rl.networks.RunningStats` of size ``O_blind + scan``), ``config`` (the blind policy's
    :class:`PPOConfig`), ``scan_mean`` / ``scan_std`` ([scan] float32, what the normaliser got) and
    ``samples`` (scan observations the statistics were measured on)."""

    params: Any
    normaliser: nets.RunningStats
    config: PPOConfig
    scan_mean: np.ndarray
    scan_std: np.ndarray
    samples: int


def widen_inputs(params: Any, normaliser: nets.RunningStats, extra: int, mean, var) -> tuple[Any, nets.RunningStats]:
    """``(params, normaliser)`` taking ``O + extra`` observations instead of ``O``: the new inputs appended last.

    ``params``: ``{"policy": ..., "value": ...}`` flax variables (either may be absent, e.g. an actor-only policy);
    every ``mlp/hidden_0/kernel [O, H]`` gets ``extra`` zero rows. ``normaliser``: the new entries get ``mean``
    and ``var`` (``[extra]``, var > 0) at the same ``count`` (``m2 = var * count``; a normaliser that has seen
    nothing stays the identity). The widened networks' outputs equal the old ones' on any observation whose first
    ``O`` entries are the old observation. ``ValueError`` for ``extra < 1``, a ``mean`` / ``var`` of another
    length, a non-positive variance or params without a first dense layer."""
    if not isinstance(extra, (int, np.integer)) or isinstance(extra, bool) or extra < 1:
        raise ValueError(f"extra must be an integer >= 1, got {extra!r}")
    mean, var = np.asarray(mean, np.float32), np.asarray(var, np.float32)
    if mean.shape != (extra,) or var.shape != (extra,):
        raise ValueError(f"mean and var must have shape ({extra},), got {mean.shape} and {var.shape}")
    if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(var)) and np.all(var > 0)):
        raise ValueError("mean must be finite and var finite and > 0")
    size = int(normaliser.mean.shape[-1])
    out = {}
    for net, variables in params.items():
        try:
            kernel = variables["params"]["mlp"]["hidden_0"]["kernel"]
        except (KeyError, TypeError):
            raise ValueError(f"params[{net!r}] has no params/mlp/hidden_0/kernel (not a jaxterrain.rl network)") \
                from None
        if kernel.shape[0] != size:
            raise ValueError(f"params[{net!r}]'s first layer takes {kernel.shape[0]} inputs, the normaliser {size}")
        wide = jnp.concatenate([kernel, jnp.zeros((extra, kernel.shape[1]), kernel.dtype)], axis=0)
        layer = dict(variables["params"]["mlp"]["hidden_0"], kernel=wide)
        mlp = dict(variables["params"]["mlp"], hidden_0=layer)
        out[net] = dict(variables, params=dict(variables["params"], mlp=mlp))
    count = jnp.asarray(normaliser.count, jnp.float32)
    wide_stats = nets.RunningStats(
        count=count,
        mean=jnp.concatenate([normaliser.mean, jnp.asarray(mean)]).astype(jnp.float32),
        m2=jnp.concatenate([normaliser.m2, jnp.asarray(var) * count]).astype(jnp.float32))
    return out, wide_stats


def scan_statistics(policy, env, terrain, key: jax.Array, envs: int = 16, steps: int = 200) -> tuple:
    """``(mean [S], var [S], samples)`` of the scan entries a blind ``policy`` (``rl.load_policy``'s, walking on the
    first ``policy.observation_size`` entries) sees in the perceptive ``env`` on ``terrain`` ([H, W] metres):
    ``envs`` walks of ``steps`` env steps, counting only the steps before each walk ends. One jitted program."""
    blind = int(policy.observation_size)
    scan = env.observation_size - blind
    if scan < 1:
        raise ValueError(f"env observes {env.observation_size} entries, the policy {blind}: not a perceptive env of "
                         f"this policy (observation={env.config.observation!r})")

    def run(key):
        states = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(key, envs), terrain)

        def body(carry, _):
            s, alive = carry
            x = s.obs[:, blind:]
            w = alive.astype(jnp.float32)[:, None]
            stats = (jnp.sum(w), jnp.sum(w * x, 0), jnp.sum(w * x * x, 0))
            s = jax.vmap(env.step, in_axes=(0, 0, None))(s, policy(s.obs[:, :blind]), terrain)
            return (s, alive & (s.done == 0)), stats

        _, (n, sx, sxx) = jax.lax.scan(body, (states, jnp.ones((envs,), bool)), None, length=steps)
        return jnp.sum(n), jnp.sum(sx, 0), jnp.sum(sxx, 0)

    n, sx, sxx = (np.asarray(v, np.float64) for v in jax.device_get(jax.jit(run)(key)))
    mean = sx / n
    var = np.maximum(sxx / n - mean ** 2, 0.0)
    return mean.astype(np.float32), var.astype(np.float32), int(n)


def perceptive_twin(policy, env, terrain=None, key: jax.Array | None = None, envs: int = 16, steps: int = 200,
                    std_floor: float = 0.1) -> PerceptiveTwin:
    """The perceptive twin of the blind ``policy`` for the perceptive ``env`` (a ``WalkerEnv`` with
    ``observation="perceptive"``, same robot): :func:`scan_statistics` on ``terrain`` (default flat ground at 0 m)
    with ``key`` (default ``PRNGKey(0)``), the standard deviations floored at ``std_floor`` metres, then
    :func:`widen_inputs`. Its deterministic actions equal the blind policy's on the same physics state, up to float
    rounding."""
    if not (isinstance(std_floor, (int, float)) and np.isfinite(std_floor) and std_floor > 0):
        raise ValueError(f"std_floor must be a finite number > 0 (metres), got {std_floor!r}")
    terrain = env.flat_terrain() if terrain is None else terrain
    key = jax.random.PRNGKey(0) if key is None else key
    mean, var, n = scan_statistics(policy, env, terrain, key, envs, steps)
    std = np.maximum(np.sqrt(var), np.float32(std_floor)).astype(np.float32)
    params, normaliser = widen_inputs(policy.params, policy.normaliser, int(mean.shape[0]), mean, std ** 2)
    return PerceptiveTwin(params, normaliser, policy.config, mean, std, n)
