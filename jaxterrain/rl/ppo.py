"""PPO training as pure functions of (state, key, terrains) - purejaxrl style, brax's recipe.

The env is duck-typed (see :class:`EnvLike`): ``env.reset(key, terrain[H, W]) -> s``,
``env.step(s, action[A], terrain[H, W]) -> s`` with ``s.obs [O]``, ``s.reward []``, ``s.done []`` float32, and
optionally ``s.truncation []`` (1.0 when the end was a time limit) - the convention of
``jaxterrain.walker.WalkerEnv``. Terrains are DATA: ``terrains`` is either ``[num_envs, H, W]`` (one per env) or
``[H, W]`` (shared), passed on every call, so a curriculum can swap them between (or inside) jitted calls without
re-compiling. On a tiled walker (``WalkerConfig(tiles=T)``, the only layout MJX-Warp runs) ``terrains`` is a
:class:`~jaxterrain.walker.Tile` instead: ``bank.at(i)`` (index [], one tile shared by all envs) or ``bank.at(idx)``
(index [num_envs] int32, a tile per env; vmapped with ``walker.TILE_AXES``). Finished envs are replaced by fresh
ones with ``env.select(mask, new, old)`` when the env has it (MJX-Warp's states must be merged that way), else by a
``jnp.where`` per leaf; both give the same values.

Typical use::

    state = rl.init(key, env, config, terrains)
    state, metrics = rl.train(key, env, config, num_updates=100, terrains=terrains, state=state)

    update = functools.partial(rl.update, env=env, config=config)    # pure: (state, key, terrains)
    state, metrics = jax.jit(update)(state, key, terrains)
"""

from __future__ import annotations

import functools
from typing import Any, Optional

import jax
import jax.numpy as jnp
import optax

from jaxterrain.rl import networks as nets
from jaxterrain.rl.config import PPOConfig, validate_config
from jaxterrain.rl.collect import (batched_reset, collect_mode, collect_split, collect_steps, join_envs, one_terrain,
                                   part_envs, per_env_mask, split_envs, zero_episode)
from jaxterrain.rl.losses import batch_mean, gae, ppo_loss
from jaxterrain.rl.state import EnvLike, Ride, TrainState, Transition, raw_key
from jaxterrain.runtime import sharding
from jaxterrain.walker.layout import terrain_axis

__all__ = ["make_optimizer", "scale_scan_rows", "init", "reset_envs", "loss_fn", "update", "run_updates", "ride_updates",
           "make_train"]


def make_optimizer(config: PPOConfig) -> optax.GradientTransformation:
    """Adam(learning_rate), after global-norm clipping when ``max_grad_norm`` is set; with ``scan_inputs`` > 0 and
    ``scan_lr_scale`` != 1, Adam's updates of the first-layer kernel rows that read the last ``scan_inputs``
    observation entries (``mlp/hidden_0/kernel`` [O, H] of both networks) are multiplied by ``scan_lr_scale``."""
    steps = [optax.adam(config.learning_rate)]
    if config.max_grad_norm is not None:
        steps.insert(0, optax.clip_by_global_norm(config.max_grad_norm))
    if config.scan_inputs > 0 and config.scan_lr_scale != 1.0:
        steps.append(scale_scan_rows(config.scan_inputs, config.scan_lr_scale))
    return steps[0] if len(steps) == 1 else optax.chain(*steps)


def scale_scan_rows(scan_inputs: int, scale: float) -> optax.GradientTransformation:
    """Multiply the updates of every ``hidden_0/kernel`` ([O, H]) in its last ``scan_inputs`` rows by ``scale``;
    every other update passes unchanged. Stateless. ``ValueError`` (at ``init`` and ``update``) when the tree has
    no ``hidden_0/kernel``, or one with ``scan_inputs`` rows or fewer: the scan would not be the observation's last
    rows of a wider input, and its scale would be ignored or spread over the whole first layer."""

    def first_layer(path, u) -> bool:
        return [getattr(k, "key", None) for k in path][-2:] == ["hidden_0", "kernel"] and u.ndim == 2

    def check(tree) -> None:
        shapes = [tuple(u.shape) for path, u in jax.tree_util.tree_leaves_with_path(tree) if first_layer(path, u)]
        if not shapes or any(rows <= scan_inputs for rows, _ in shapes):
            raise ValueError(f"rl.scale_scan_rows: scan_inputs={scan_inputs} needs first-layer kernels "
                             f"(hidden_0/kernel, [observation, hidden]) of more than {scan_inputs} rows (the blind "
                             f"observation, then the scan); got {shapes or 'none'}")

    def scaled(path, u):
        if not first_layer(path, u):
            return u
        rows = jnp.arange(u.shape[0])[:, None] >= u.shape[0] - scan_inputs
        return jnp.where(rows, u * jnp.asarray(scale, u.dtype), u)

    def init(params):
        check(params)
        return optax.EmptyState()

    def update(updates, state, params=None):
        del params
        check(updates)
        return jax.tree_util.tree_map_with_path(scaled, updates), state

    return optax.GradientTransformation(init, update)


# ----------------------------------------------------------------------------------------------------------------
# init / reset
# ----------------------------------------------------------------------------------------------------------------
def init(key: jax.Array, env: EnvLike, config: PPOConfig, terrains: jax.Array, params: Any = None,
         normaliser: Optional[nets.RunningStats] = None) -> TrainState:
    """A fresh :class:`TrainState`: new (or given) params and normaliser, Adam state, ``num_envs`` reset envs.

    Args:
      key: PRNG key (raw [2] uint32 or typed).
      env: duck-typed env (see module docstring).
      config: :class:`PPOConfig` (validated here, ``ValueError`` on bad fields).
      terrains: [num_envs, H, W] or [H, W] float32 heightfields in metres, or a ``walker.Tile`` of a tiled env
        (index [] shared, or [num_envs]: see the module docstring).
      params: optional ``{"policy", "value"}`` params to continue from (e.g. ``load_policy().params``).
      normaliser: optional :class:`RunningStats` matching ``params`` (e.g. ``load_policy().normaliser``).

    Not jitted here (library style); for an MJX env wrap it: ``jax.jit(lambda k, t: init(k, env, config, t))``
    (:func:`train` does).
    """
    validate_config(config)
    key = raw_key(key)
    param_key, env_key, run_key = jax.random.split(key, 3)
    del key
    if params is None:
        params = nets.init_params(param_key, config, env.observation_size, env.action_size)
    if normaliser is None:
        normaliser = nets.init_stats(env.observation_size)
    env_state = batched_reset(env, env_key, terrains, config.num_envs)
    return TrainState(
        params=params,
        opt_state=make_optimizer(config).init(params),
        normaliser=normaliser,
        env_state=env_state,
        episode=zero_episode(config.num_envs),
        key=run_key,
        update_step=jnp.zeros((), jnp.int32),
        env_steps=jnp.zeros((), jnp.int32),
    )


def reset_envs(state: TrainState, key: jax.Array, terrains: jax.Array, *, env: EnvLike,
               config: PPOConfig) -> TrainState:
    """Restart every env on ``terrains`` (as in :func:`init`: arrays or a ``walker.Tile``; e.g. after a curriculum
    switch) and clear running episode counters."""
    env_state = batched_reset(env, raw_key(key), terrains, config.num_envs)
    ep = state.episode
    zero = jnp.zeros_like(ep.ret)
    return state._replace(env_state=env_state, episode=ep._replace(ret=zero, length=zero, progress=zero))


# ----------------------------------------------------------------------------------------------------------------
# update = collect + GAE + epochs of minibatch SGD
# ----------------------------------------------------------------------------------------------------------------
def loss_fn(params, normaliser, batch: Transition, bootstrap_obs, key, *, config: PPOConfig, action_size: int,
            weight=None, rows=None, axis_name=None):
    """PPO loss on a minibatch of segments: ``batch`` fields [b, T, ...], ``bootstrap_obs`` [b, O].

    GAE is recomputed with the current value network per minibatch (as brax). Returns ``(loss, aux)``.

    Data parallel (inside :func:`update`'s ``shard_map``): ``batch`` is this device's slice of the minibatch,
    ``weight`` [b] (0 on padding), ``rows = (start, total)`` its place in the minibatch of ``total`` segments (the
    entropy's one-sample estimate takes its slice of the whole minibatch's normal draw) and ``axis_name`` the mesh
    axis: the loss and aux are then this device's shares of the minibatch means (:func:`~jaxterrain.rl.losses.
    batch_mean`; sum them over the axis).
    """
    batch = jax.tree_util.tree_map(lambda x: jnp.swapaxes(x, 0, 1), batch)  # [T, b, ...]
    loc, scale = nets.policy_apply(config, action_size, params, normaliser, batch.obs)
    values = nets.value_apply(config, params, normaliser, batch.obs)
    last_value = nets.value_apply(config, params, normaliser, bootstrap_obs)
    rewards = batch.reward * config.reward_scaling
    if config.truncation == "bootstrap":  # mask: batch.bootstrap is all zeros, left out of the default's loss
        rewards = rewards + batch.bootstrap
    advantages, targets = gae(rewards, jax.lax.stop_gradient(values), batch.done, jax.lax.stop_gradient(last_value),
                              config.gamma, config.gae_lambda, batch.truncation)
    logp = nets.log_prob(config.action_distribution, loc, scale, batch.raw_action)
    noise = None
    if rows is not None:  # this device's columns of the whole minibatch's draw [T, total, A]
        start, total = rows
        t, b = loc.shape[:2]
        draw = jax.random.normal(key, (t, total) + loc.shape[2:], loc.dtype)
        draw = jnp.concatenate([draw, jnp.zeros((t, b) + loc.shape[2:], loc.dtype)], axis=1)  # padding rows
        noise = jax.lax.dynamic_slice_in_dim(draw, start, b, axis=1)
    ent = nets.entropy(config.action_distribution, key, loc, scale, noise)
    w = None if weight is None else jnp.broadcast_to(weight[None, :], logp.shape)
    loss, aux = ppo_loss(logp, batch.log_prob, advantages, values, targets, ent, clip_eps=config.clip_eps,
                         vf_coef=config.vf_coef, entropy_coef=config.entropy_coef,
                         normalize_advantage=config.normalize_advantage, weight=w, axis_name=axis_name)
    if w is None and axis_name is None:
        return loss, dict(aux, mean_std=jnp.mean(scale), value_target=jnp.mean(targets))
    return loss, dict(aux, mean_std=batch_mean(jnp.mean(scale, axis=-1), w, axis_name),
                      value_target=batch_mean(targets, w, axis_name))


def update(state: TrainState, key: jax.Array, terrains: jax.Array, *, env: EnvLike,
           config: PPOConfig, mesh=None, collect: Optional[str] = None):
    """One PPO iteration: collect ``config.steps_per_update`` transitions, update the normaliser, then
    ``update_epochs`` x ``num_minibatches`` Adam steps on the clipped objective.

    A pure function of ``(state, key, terrains)`` (bind ``env``/``config`` with ``functools.partial``); jit it,
    scan it, vmap it over seeds. ``terrains``: [num_envs, H, W] or [H, W] float32, or a ``walker.Tile`` (index []
    or [num_envs]) of a tiled env; new values of the same shape (another bank, other indices)
    do not re-compile. Returns ``(state, metrics)``, metrics a dict of [] float32 (losses averaged over all
    minibatch steps; ``episode_return``: mean over envs of the last finished episode's return, unscaled, over envs
    that finished one; ``episodes``: episodes finished during this update).

    ``mesh`` (a ``jax.sharding.Mesh``, data parallel): the envs (and per-env terrains) are split over its devices,
    each device steps its own (:func:`collect_mode`, ``collect`` None: automatic; under ``jax.shard_map`` on CPUs when ``num_envs`` divides
    over the devices, so that an opaque physics call such as MuJoCo Warp's runs per device; else XLA partitions
    the batched steps); the policy, value net, normaliser and optimiser state are replicated. Every epoch
    draws the same permutation as without a mesh, and each minibatch is split over the devices (padded to a
    multiple of the device count, the padding weighted 0): every device computes the gradient of its share of the
    minibatch loss, the gradients are summed (``psum``: their mean over the devices weighted by their rows) and
    every device applies the same Adam step. Advantage standardisation uses the whole minibatch's statistics, and
    the random draws are the ones of the one-device update, so the result equals :func:`update` without a mesh up
    to float rounding (tested on 4 CPU devices and on two processes).
    """
    return _update(state, key, terrains, env, config, mesh, collect=collect)[0]


def _update(state: TrainState, key, terrains, env, config: PPOConfig, mesh=None, ride: Optional[Ride] = None,
            carry=None, per_env=None, collect: Optional[str] = None):
    """:func:`update` -> ``((state, metrics), carry)``; with ``ride`` the riders step along (:func:`~jaxterrain.rl.collect.collect_steps`)."""
    key = raw_key(key)
    collect_key, sgd_key = jax.random.split(key)
    del key
    if mesh is not None and collect_mode(mesh, config, env, collect) == "shard_map":
        env_state, episode, data, bootstrap_obs = collect_split(state, collect_key, terrains, env, config, mesh)
    else:
        if mesh is not None:  # envs that do not divide over the devices: XLA partitions the batched steps
            state, terrains = split_envs(state, terrains, config, mesh)
        env_state, episode, data, bootstrap_obs, carry = collect_steps(state, collect_key, terrains, env, config,
                                                                  ride=ride, carry=carry, per_env=per_env)

    normaliser = state.normaliser
    if config.normalize_observations and config.update_normaliser:
        normaliser = nets.update_stats(normaliser, data.obs)

    # [K, T, N, ...] -> segments [K * N, T, ...]; bootstrap [K, N, O] -> [K * N, O]
    k, t, n = config.num_unrolls, config.unroll_length, config.num_envs
    segments = jax.tree_util.tree_map(lambda x: jnp.reshape(jnp.swapaxes(x, 1, 2), (k * n, t) + x.shape[3:]), data)
    boots = jnp.reshape(bootstrap_obs, (k * n, bootstrap_obs.shape[-1]))
    params, opt_state, sgd_metrics = _sgd(state.params, state.opt_state, normaliser, segments, boots, sgd_key,
                                          config=config, action_size=env.action_size, mesh=mesh)

    finished = episode.count > 0
    metrics = {name: jnp.mean(v) for name, v in sgd_metrics.items()}
    metrics.update(
        episode_return=jnp.sum(jnp.where(finished, episode.last_return, 0.0)) / jnp.maximum(jnp.sum(finished), 1),
        episode_length=jnp.sum(jnp.where(finished, episode.last_length, 0.0)) / jnp.maximum(jnp.sum(finished), 1),
        episodes=jnp.sum(data.done),
        reward=jnp.mean(data.reward),
    )
    new_state = TrainState(
        params=params,
        opt_state=opt_state,
        normaliser=normaliser,
        env_state=env_state,
        episode=episode,
        key=state.key,
        update_step=state.update_step + 1,
        env_steps=state.env_steps + config.steps_per_update,
    )
    metrics["env_steps"] = new_state.env_steps.astype(jnp.float32)
    return (new_state, metrics), carry


def _sgd(params, opt_state, normaliser, segments: Transition, boots, key, *, config: PPOConfig, action_size: int,
         mesh=None):
    """``update_epochs`` passes of ``num_minibatches`` Adam steps over the segments [K * N, T, ...] (bootstrap
    observations [K * N, O]), shuffled per epoch. Returns ``(params, opt_state, metrics [epochs, minibatches])``.
    With ``mesh`` every minibatch is split over its devices (see :func:`update`)."""
    optimizer = make_optimizer(config)
    m, total = config.num_minibatches, boots.shape[0]
    size = total // m  # segments per minibatch
    if mesh is None:
        local, axis_name = size, None
    else:
        local, axis_name = -(-size // mesh.devices.size), sharding.AXIS  # segments per device, padded
    grad_fn = jax.value_and_grad(functools.partial(loss_fn, config=config, action_size=action_size,
                                                   axis_name=axis_name), has_aux=True)

    def minibatch_step(carry, mb):
        params, opt_state = carry
        batch, boot, mb_key = mb
        if mesh is None:
            (loss, aux), grads = grad_fn(params, normaliser, batch, boot, mb_key)
        else:  # this device's rows of the minibatch (padded with weight 0); shares summed over the devices
            start = jax.lax.axis_index(axis_name) * local
            padded = sharding.pad_rows((batch, boot), local * mesh.devices.size)
            mine = jax.tree_util.tree_map(lambda x: jax.lax.dynamic_slice_in_dim(x, start, local), padded)
            weight = (start + jnp.arange(local) < size).astype(jnp.float32)
            (loss, aux), grads = grad_fn(params, normaliser, mine[0], mine[1], mb_key, weight=weight,
                                         rows=(start, size))
            loss, aux, grads = jax.lax.psum((loss, aux, grads), axis_name)
        updates, opt_state = optimizer.update(grads, opt_state, params)
        params = optax.apply_updates(params, updates)
        return (params, opt_state), dict(aux, loss=loss, grad_norm=optax.global_norm(grads))

    def epochs(params, opt_state, segments, boots, key):
        def epoch(carry, epoch_key):
            perm_key, mb_key = jax.random.split(epoch_key)
            perm = jax.random.permutation(perm_key, total)
            shuffle = lambda x: jnp.reshape(x[perm], (m, -1) + x.shape[1:])
            mbs = (jax.tree_util.tree_map(shuffle, segments), shuffle(boots), jax.random.split(mb_key, m))
            return jax.lax.scan(minibatch_step, carry, mbs)

        (params, opt_state), metrics = jax.lax.scan(epoch, (params, opt_state),
                                                    jax.random.split(key, config.update_epochs))
        return params, opt_state, metrics

    if mesh is None:
        return epochs(params, opt_state, segments, boots, key)
    from jax.sharding import PartitionSpec as P  # every device holds the whole batch, computes on its rows

    return jax.shard_map(epochs, mesh=mesh, in_specs=P(), out_specs=P(), check_vma=False)(
        params, opt_state, segments, boots, key)


def run_updates(state: TrainState, terrains: jax.Array, *, env: EnvLike, config: PPOConfig, num_updates: int,
                mesh=None, collect: Optional[str] = None):
    """``num_updates`` updates in one ``lax.scan``; each splits its key off ``state.key``. Pure (jit/vmap it).
    ``mesh``: data parallel over its devices; ``collect``: how (:func:`update`, :func:`collect_mode`).

    Returns ``(state, metrics)`` with metrics [num_updates] per name.
    """

    def body(s, _):
        next_key, update_key = jax.random.split(s.key)
        return update(s._replace(key=next_key), update_key, terrains, env=env, config=config, mesh=mesh,
                      collect=collect)

    return jax.lax.scan(body, state, None, length=num_updates)


def ride_updates(state: TrainState, terrains: jax.Array, riders: Any, ride: Ride, carry: Any, *, env: EnvLike,
                 config: PPOConfig, num_updates: int, per_env: Any = None):
    """:func:`run_updates` with ``R`` envs riding along (a :class:`Ride`): ``riders`` (their env states, batched
    [R]) are stepped in the same batched ``env.step`` calls as the PPO envs, ``num_updates x num_unrolls x
    unroll_length`` steps by ``ride.act``, never reset; ``carry`` (any pytree) goes through ``ride.record`` after
    every step. The PPO envs, their random draws and the update are those of :func:`run_updates` (the riders take
    no key; per-env physics does not see the other envs). Pure; one data-parallel device only. ``per_env``: the
    batch's :func:`per_env_mask` where the caller has it already (else traced here, two traces of ``env.reset``).

    Returns ``(state, riders, carry, metrics)`` with metrics [num_updates] per name.
    """
    n = config.num_envs
    if per_env is None:
        per_env = per_env_mask(env, one_terrain(terrains, terrain_axis(terrains, n)))
    both = state._replace(env_state=join_envs(per_env, state.env_state, riders))

    def body(c, _):
        s, rc = c
        next_key, update_key = jax.random.split(s.key)
        (s, metrics), rc = _update(s._replace(key=next_key), update_key, terrains, env, config, ride=ride, carry=rc,
                                   per_env=per_env)
        return (s, rc), metrics

    (state, carry), metrics = jax.lax.scan(body, (both, carry), None, length=num_updates)
    envs, riders = part_envs(per_env, state.env_state, n)
    return state._replace(env_state=envs), riders, carry, metrics


def make_train(env: EnvLike, config: PPOConfig, num_updates: int):
    """purejaxrl-style ``train_fn(key, terrains) -> (state, metrics [num_updates])``: init + updates, one pure
    function of the key; ``jax.jit(jax.vmap(train_fn, in_axes=(0, None)))(keys, terrains)`` trains many seeds."""

    def train_fn(key, terrains):
        state = init(key, env, config, terrains)
        return run_updates(state, terrains, env=env, config=config, num_updates=num_updates)

    return train_fn

