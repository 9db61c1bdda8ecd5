"""PPO's data types: the duck-typed env it trains (:class:`EnvLike`), its state (:class:`TrainState`, with
:class:`EpisodeStats`), one step of experience (:class:`Transition`), and the envs that may ride along
(:class:`Ride`). Pytrees all; batch them for several seeds."""

from __future__ import annotations

from typing import Any, NamedTuple, Protocol

import jax
import jax.numpy as jnp

from jaxterrain.rl import networks as nets

__all__ = ["EnvLike", "EpisodeStats", "TrainState", "Transition", "Ride", "raw_key"]


class EnvLike(Protocol):
    observation_size: int
    action_size: int

    def reset(self, key, terrain): ...

    def step(self, state, action, terrain): ...


class EpisodeStats(NamedTuple):
    """Per-env episode bookkeeping, all [N]: running ``ret``/``length`` of the current episode (unscaled reward),
    ``last_return``/``last_length`` of the most recent finished one, ``count`` of finished episodes, ``progress``
    the furthest ``env_state.distance`` (the walker's normalised distance; 0 for an env without one) reached since
    the envs were last (re)started (:func:`~jaxterrain.rl.ppo.init`, :func:`~jaxterrain.rl.ppo.reset_envs`), over all its episodes."""

    ret: jax.Array
    length: jax.Array
    last_return: jax.Array
    last_length: jax.Array
    count: jax.Array
    progress: jax.Array


class TrainState(NamedTuple):
    """Everything PPO carries between updates; a pytree (batch it for several seeds).

    params: ``{"policy": ..., "value": ...}`` flax variables. opt_state: optax state. normaliser:
    :class:`~jaxterrain.rl.networks.RunningStats`. env_state: the env's state batched over ``num_envs``.
    episode: :class:`EpisodeStats`. key: [2] uint32, the stream :func:`~jaxterrain.rl.ppo.run_updates` splits per update.
    update_step: [] int32 updates done. env_steps: [] int32 env steps collected.
    """

    params: Any
    opt_state: Any
    normaliser: nets.RunningStats
    env_state: Any
    episode: EpisodeStats
    key: jax.Array
    update_step: jax.Array
    env_steps: jax.Array


class Transition(NamedTuple):
    """One env step of all envs: obs [N, O] (raw), raw_action [N, A], log_prob [N], reward [N] (unscaled),
    done [N], truncation [N], bootstrap [N] (``gamma * V(final obs)`` in the loss's scaled units where a
    time-limit end is bootstrapped, ``PPOConfig.truncation == "bootstrap"``; 0 elsewhere)."""

    obs: jax.Array
    raw_action: jax.Array
    log_prob: jax.Array
    reward: jax.Array
    done: jax.Array
    truncation: jax.Array
    bootstrap: jax.Array


class Ride(NamedTuple):
    """Envs that ride along PPO's rollouts (:func:`~jaxterrain.rl.ppo.ride_updates`): ``R`` extra envs stepped in the SAME batched
    ``env.step`` call as the ``num_envs`` PPO envs, by a fixed policy, never reset, not learned from. Where a physics
    step costs about the same for a few hundred more envs (a GPU stepping thousands), they walk nearly free: the
    curriculum evaluates one chunk's policy while the next chunk trains (``CurriculumConfig.overlap``).

    act: ``obs [R, O] -> actions [R, A]``, the riders' policy (a closure over its params).
    terrains: the riders' terrains, ``[R, H, W]`` / ``[H, W]`` arrays or a ``walker.Tile`` (index [] or [R]) of the
      SAME bank as the PPO envs' Tile.
    record: ``(carry, states, start) -> carry`` after every step; ``states`` are all ``num_envs + R`` env states,
      the riders' are rows ``start ..`` (``start = num_envs``) of their per-env fields (e.g. ``states.done[start:]``).
    park: optional ``(carry, states, start) -> states`` after ``record``: the env states with riders whose outcome
      is recorded moved out of the way (e.g. ``WalkerEnv.park``), so that they cost the physics less; it must leave
      the PPO envs' rows as they are. None: the riders step on as they are.
    """

    act: Any
    terrains: Any
    record: Any
    park: Any = None


def raw_key(key: jax.Array) -> jax.Array:
    """``key`` as raw ``[2]`` uint32 data (``TrainState.key``'s form): a typed key's ``key_data``, a raw one as is."""
    if jnp.issubdtype(key.dtype, jax.dtypes.prng_key):
        return jax.random.key_data(key)
    return key
