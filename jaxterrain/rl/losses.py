"""GAE and the clipped PPO objective as small pure functions (hand-checkable; see tests/rl/test_rl.py)."""

from __future__ import annotations

from typing import Optional

import jax
import jax.numpy as jnp

__all__ = ["gae", "batch_mean", "ppo_loss"]


def gae(rewards: jax.Array, values: jax.Array, dones: jax.Array, last_value: jax.Array, gamma: float,
        lam: float, truncations: Optional[jax.Array] = None):
    """Generalised advantage estimation over a time-major batch of segments.

    Args:
      rewards: [T, B] float32 reward of step t (already scaled).
      values: [T, B] float32 V(s_t).
      dones: [T, B] float32, 1.0 when the episode ended at step t (s_{t+1} is then a fresh episode's first state).
      last_value: [B] float32 V(s_T), the bootstrap after the segment.
      gamma, lam: discount and GAE lambda.
      truncations: optional [T, B] float32, 1.0 when the end at step t was a time limit, not a terminal state.
        Those steps get advantage 0 and target V(s_t) (brax's truncation mask: the true next state is lost to the
        auto-reset, so the step is left out rather than bootstrapped from the wrong state).

    Returns:
      (advantages [T, B], targets [T, B]) with
      ``delta_t = r_t + gamma (1 - term_t) V(s_{t+1}) - V(s_t)``, ``A_t = delta_t + gamma lam (1 - done_t) A_{t+1}``,
      ``target_t = A_t + V(s_t)``; gradients are stopped.
    """
    shape = tuple(jnp.shape(values))
    if len(shape) < 1:
        raise ValueError(f"values must have shape [T, B]; got shape {shape}")
    for name, a in (("rewards", rewards), ("dones", dones), ("truncations", truncations)):
        if a is not None and tuple(jnp.shape(a)) != shape:
            raise ValueError(f"{name} must have the shape of values [T, B] = {shape}; got shape {tuple(jnp.shape(a))}")
    if tuple(jnp.shape(last_value)) != shape[1:]:
        raise ValueError(f"last_value must have shape [B] = {shape[1:]} (values without its time axis); got shape "
                         f"{tuple(jnp.shape(last_value))}")
    if truncations is None:
        truncations = jnp.zeros_like(dones)
    keep = 1.0 - truncations
    terminal = dones * keep
    next_values = jnp.concatenate([values[1:], last_value[None]], axis=0)
    deltas = (rewards + gamma * (1.0 - terminal) * next_values - values) * keep

    def backward(acc, x):
        delta, done = x
        acc = delta + gamma * lam * (1.0 - done) * acc
        return acc, acc

    _, advantages = jax.lax.scan(backward, jnp.zeros_like(last_value), (deltas, dones), reverse=True)
    targets = advantages + values
    return jax.lax.stop_gradient(advantages), jax.lax.stop_gradient(targets)


def batch_mean(x: jax.Array, weight: Optional[jax.Array] = None, axis_name: Optional[str] = None) -> jax.Array:
    """``jnp.mean(x)``; with ``weight`` (x's shape, 1 for real entries, 0 for padding) and / or ``axis_name`` (a
    ``shard_map`` axis over which the batch is split), THIS device's share of the weighted mean of the whole batch,
    ``sum(weight * x) / psum(sum(weight))``: ``psum`` the shares for the mean. The total weight is a constant for
    gradients, so the gradient of a share is the device's share of the gradient of the mean."""
    if weight is None and axis_name is None:
        return jnp.mean(x)
    w = jnp.ones_like(x) if weight is None else jnp.broadcast_to(weight, x.shape).astype(x.dtype)
    total = jnp.sum(w)
    if axis_name is not None:
        total = jax.lax.psum(jax.lax.stop_gradient(total), axis_name)
    return jnp.sum(w * x) / total


def _all_mean(x, weight, axis_name):
    """The weighted mean of the whole batch (the shares summed over ``axis_name``)."""
    share = batch_mean(x, weight, axis_name)
    return share if axis_name is None else jax.lax.psum(share, axis_name)


def ppo_loss(log_prob: jax.Array, old_log_prob: jax.Array, advantages: jax.Array, values: jax.Array,
             targets: jax.Array, entropy: jax.Array, *, clip_eps: float, vf_coef: float, entropy_coef: float,
             normalize_advantage: bool = True, weight: Optional[jax.Array] = None,
             axis_name: Optional[str] = None):
    """Clipped PPO objective on a batch of any shape (all arrays the same shape, e.g. [T, B]).

    ``loss = policy_loss + value_loss + entropy_loss`` with
      ``ratio = exp(log_prob - old_log_prob)``, ``A`` the advantages (standardised over the batch,
      ``(A - mean) / (std + 1e-8)``, when ``normalize_advantage``),
      ``policy_loss = -mean(min(ratio A, clip(ratio, 1 - clip_eps, 1 + clip_eps) A))``,
      ``value_loss = vf_coef * 0.5 * mean((targets - values)^2)`` (brax's scaling),
      ``entropy_loss = -entropy_coef * mean(entropy)``.

    Returns ``(loss [], aux)`` where aux holds the three terms, ``approx_kl = mean((ratio - 1) - log ratio)``
    and ``clip_fraction = mean(|ratio - 1| > clip_eps)``.

    Data parallel (``rl.update(..., mesh=...)``): ``weight`` (the arrays' shape; 0 masks padding out) and
    ``axis_name`` (the ``shard_map`` axis the batch is split over) make every mean this device's share of the
    whole batch's mean (:func:`batch_mean`; the loss, its gradient and aux are then summed over the axis), and the
    advantages are standardised with the mean and std of the whole batch.
    """
    mean = lambda x: batch_mean(x, weight, axis_name)  # noqa: E731
    if normalize_advantage:
        if weight is None and axis_name is None:
            advantages = (advantages - jnp.mean(advantages)) / (jnp.std(advantages) + 1e-8)
        else:
            centre = _all_mean(advantages, weight, axis_name)
            std = jnp.sqrt(_all_mean(jnp.square(advantages - centre), weight, axis_name))
            advantages = (advantages - centre) / (std + 1e-8)
    log_ratio = log_prob - old_log_prob
    ratio = jnp.exp(log_ratio)
    surrogate = jnp.minimum(ratio * advantages, jnp.clip(ratio, 1.0 - clip_eps, 1.0 + clip_eps) * advantages)
    policy_loss = -mean(surrogate)
    value_loss = vf_coef * 0.5 * mean(jnp.square(targets - values))
    entropy_loss = -entropy_coef * mean(entropy)
    loss = policy_loss + value_loss + entropy_loss
    aux = {
        "policy_loss": policy_loss,
        "value_loss": value_loss,
        "entropy_loss": entropy_loss,
        "entropy": mean(entropy),
        "approx_kl": jax.lax.stop_gradient(mean((ratio - 1.0) - log_ratio)),
        "clip_fraction": jax.lax.stop_gradient(mean((jnp.abs(ratio - 1.0) > clip_eps).astype(jnp.float32))),
    }
    return loss, aux
