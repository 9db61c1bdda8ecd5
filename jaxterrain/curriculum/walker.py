"""The real harness: PPO (``jaxterrain.rl``) on the MJX walker, evaluated by the difficulty protocol.

    policy = rl.load_policy()                                    # the shipped base policy (or a file)
    env = walker_env(policy, bank.heightmaps.shape[1:], scale)   # the walker it was trained on, on the bank's terrains
    check_policy(policy, env)                                    # ValueError naming the file on a mismatch
    ppo = config.ppo_config(policy.config)                       # fine-tuning PPO (CurriculumConfig.ppo_config)
    harness = walker_harness(env, ppo, config)
    start = start_state(env, ppo, policy, bank.heightmaps.shape[1:])   # the policy's params, value net, normaliser

``harness.train`` runs ``config.updates_per_chunk`` PPO updates (``rl.run_updates``, one chunk =
``epochs_per_chunk x steps_per_epoch`` env steps) with all ``num_envs`` envs on the current terrain;
``harness.evaluate`` walks the updated deterministic policy ``attempts`` times on it
(``difficulty.batched_distances``) and returns the mean of the ``best`` distances; ``harness.reset`` restarts the envs
on a new terrain (``rl.reset_envs``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Optional

import jax
import jax.numpy as jnp

from jaxterrain import difficulty, rl
from jaxterrain.curriculum.config import CurriculumConfig
from jaxterrain.curriculum.core import Harness
from jaxterrain.terrain import TerrainScale

__all__ = ["walker_env_config", "walker_env", "check_policy", "walker_harness", "start_state"]


def walker_env_config(policy, shape: tuple[int, int], scale: TerrainScale, episode_length: Optional[int] = None):
    """The :class:`~jaxterrain.walker.WalkerConfig` of the curriculum: the bank's terrain shape and scale, the
    contact solver the policy was trained with, and (optionally) a shorter ``episode_length``."""
    config = difficulty.default_env_config(tuple(shape), scale, policy)
    return config if episode_length is None else config._replace(episode_length=int(episode_length))


def walker_env(policy, shape: tuple[int, int], scale: TerrainScale, episode_length: Optional[int] = None):
    """The cached :class:`~jaxterrain.walker.WalkerEnv` of :func:`walker_env_config` (builds the MuJoCo model;
    compiles nothing)."""
    return difficulty.make_env(walker_env_config(policy, shape, scale, episode_length))


def check_policy(policy, env) -> None:
    """``ValueError`` naming the policy's file when it does not fit the walker: observation / action sizes, or
    parameters that are not those of its own PPOConfig's networks. Uses shapes only (nothing is compiled)."""
    where = str(getattr(policy, "path", None) or "the policy")
    obs, act = getattr(policy, "observation_size", None), getattr(policy, "action_size", None)
    if obs != env.observation_size or act != env.action_size:
        raise ValueError(f"{where}: policy for observations {obs} / actions {act}, but the walker has "
                         f"{env.observation_size} / {env.action_size} (height_scan={env.config.height_scan})")
    from jaxterrain.rl import networks as nets

    like = jax.eval_shape(lambda k: nets.init_params(k, policy.config, obs, act), jax.random.key(0))
    shapes = lambda t: jax.tree.map(lambda x: tuple(x.shape), t)  # noqa: E731
    try:
        same = shapes(like) == shapes(policy.params)
    except Exception:  # noqa: BLE001 - any structural difference is a mismatch
        same = False
    if not same:
        raise ValueError(f"{where}: its parameters do not match the networks of its own config.json "
                         f"(policy_hidden={policy.config.policy_hidden}, value_hidden={policy.config.value_hidden})")
    if tuple(policy.normaliser.mean.shape) != (obs,):
        raise ValueError(f"{where}: normaliser of size {policy.normaliser.mean.shape}, expected ({obs},)")


def walker_harness(env, ppo: rl.PPOConfig, config: CurriculumConfig) -> Harness:
    """The :class:`~jaxterrain.curriculum.core.Harness` of PPO fine-tuning on ``env`` (pure functions; the policy
    state is an ``rl.TrainState``)."""
    rl.validate_config(ppo)
    updates = config.steps_per_chunk // ppo.steps_per_update
    if updates * ppo.steps_per_update != config.steps_per_chunk:
        raise ValueError(f"PPO's {ppo.steps_per_update} env steps per update must divide a chunk's "
                         f"{config.steps_per_chunk}")
    act = rl.policy_fn(ppo, env.action_size)
    attempts, best = config.attempts, config.best

    def train(state: rl.TrainState, key, terrain):
        state = state._replace(key=jax.random.key_data(key) if jnp.issubdtype(key.dtype, jax.dtypes.prng_key)
                               else key)
        return rl.run_updates(state, terrain, env=env, config=ppo, num_updates=updates)[0]

    def evaluate(state: rl.TrainState, key, terrain):
        d, _ = difficulty.batched_distances(env, act, terrain[None], key, attempts,
                                            policy_params=(state.params, state.normaliser))
        return difficulty.best_of(d, best)[0]

    def reset(state: rl.TrainState, key, terrain):
        return rl.reset_envs(state, key, terrain, env=env, config=ppo)

    return Harness(train=train, evaluate=evaluate, reset=reset)


def start_state(env, ppo: rl.PPOConfig, policy, shape: tuple[int, int]) -> rl.TrainState:
    """The starting ``rl.TrainState``: the policy's params (policy AND value net) and normaliser, a fresh Adam state,
    and zeros for the ``ppo.num_envs`` env states (only their structure counts: the curriculum restarts the envs on
    its first terrain before training). Traces the env once (``jax.eval_shape``); compiles nothing."""
    like = jax.eval_shape(lambda k, t: rl.init(k, env, ppo, t), jax.random.key(0),
                          jax.ShapeDtypeStruct(tuple(shape), jnp.float32))
    zeros = jax.tree.map(lambda x: jnp.zeros(x.shape, x.dtype), like)
    params = jax.tree.map(jnp.asarray, policy.params)
    return zeros._replace(params=params, normaliser=policy.normaliser,
                          opt_state=rl.make_optimizer(ppo).init(params))


def load_policy(path: Optional[str | Path]) -> Any:
    """``rl.load_policy(path)`` with every failure as ``ValueError`` naming the file (None: the base policy)."""
    try:
        return rl.load_policy(path)
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise ValueError(f"policy {path or rl.BASE_POLICY_DIR}: cannot be loaded ({type(err).__name__}: "
                         f"{str(err).splitlines()[0] if str(err) else ''})") from err
    except Exception as err:  # noqa: BLE001 - msgpack raises its own exception types on a corrupt file
        raise ValueError(f"policy {path}: not a readable policy ({type(err).__name__})") from err
