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
from typing import Any, NamedTuple, Optional, Protocol

import jax
import jax.numpy as jnp
import optax

from jaxterrain.rl import networks as nets
from jaxterrain.rl.config import PPOConfig, validate_config
from jaxterrain.rl.losses import batch_mean, gae, ppo_loss
from jaxterrain.runtime import sharding
from jaxterrain.walker.layout import terrain_axis
from jaxterrain.walker.tiles import Tile

__all__ = ["EnvLike", "EpisodeStats", "TrainState", "Transition", "Ride", "COLLECT_MODES", "collect_mode", "raw_key",
           "make_optimizer", "per_env_mask", "init", "reset_envs", "loss_fn", "update", "run_updates",
           "ride_updates", "make_train"]


class EnvLike(Protocol):
    observation_size: int
    action_size: int

    def reset(self, key, terrain): ...

    def step(self, state, action, terrain): ...


class EpisodeStats(NamedTuple):
    """Per-env episode bookkeeping, all [N]: running ``ret``/``length`` of the current episode (unscaled reward),
    ``last_return``/``last_length`` of the most recent finished one, ``count`` of finished episodes, ``progress``
    the furthest ``env_state.distance`` (the walker's normalised distance; 0 for an env without one) reached since
    the envs were last (re)started (:func:`init`, :func:`reset_envs`), over all its episodes."""

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
    episode: :class:`EpisodeStats`. key: [2] uint32, the stream :func:`run_updates` splits per update.
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
    """Envs that ride along PPO's rollouts (:func:`ride_updates`): ``R`` extra envs stepped in the SAME batched
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


# ----------------------------------------------------------------------------------------------------------------
# Helpers
# ----------------------------------------------------------------------------------------------------------------
def raw_key(key: jax.Array) -> jax.Array:
    """``key`` as raw ``[2]`` uint32 data (``TrainState.key``'s form): a typed key's ``key_data``, a raw one as is."""
    if jnp.issubdtype(key.dtype, jax.dtypes.prng_key):
        return jax.random.key_data(key)
    return key


def make_optimizer(config: PPOConfig) -> optax.GradientTransformation:
    """Adam(learning_rate), after global-norm clipping when ``max_grad_norm`` is set."""
    adam = optax.adam(config.learning_rate)
    if config.max_grad_norm is None:
        return adam
    return optax.chain(optax.clip_by_global_norm(config.max_grad_norm), adam)


def _batched_reset(env, key, terrains, num_envs, rows=None):
    """``num_envs`` reset envs keyed ``split(key, num_envs)``; ``rows = (start, total)``: envs ``start ..
    start + num_envs`` of a batch of ``total`` (keys ``split(key, total)[start:start + num_envs]``)."""
    axis = terrain_axis(terrains, num_envs)
    if rows is None:
        keys = jax.random.split(key, num_envs)
    else:
        keys = jax.lax.dynamic_slice_in_dim(jax.random.split(key, rows[1]), rows[0], num_envs)
    return jax.vmap(env.reset, in_axes=(0, axis))(keys, terrains)


def _truncation(env_state) -> jax.Array:
    trunc = getattr(env_state, "truncation", None)
    if trunc is None:
        info = getattr(env_state, "info", None)
        if isinstance(info, dict):
            trunc = info.get("truncation")
    if trunc is None:
        return jnp.zeros_like(env_state.done)
    return jnp.asarray(trunc, jnp.float32)


def _select(mask: jax.Array, on_true, on_false):
    """Per-env ``where`` over two batched pytrees (mask [N])."""

    def sel(a, b):
        m = jnp.reshape(mask, mask.shape + (1,) * (a.ndim - mask.ndim))
        return jnp.where(m, a, b)

    return jax.tree_util.tree_map(sel, on_true, on_false)


def _select_envs(env, mask: jax.Array, on_true, on_false):
    """Batched env states: ``env.select(mask, on_true, on_false)`` when the env has it (the walker: MJX-Warp's
    ``Data`` holds contact buffers shared by all envs, which a per-leaf ``where`` would split), else :func:`_select`
    (the same values)."""
    select = getattr(env, "select", None)
    return _select(mask, on_true, on_false) if select is None else select(mask, on_true, on_false)


def _one_terrain(terrains, axis):
    """One env's terrain argument of ``terrains`` with vmap ``axis`` (None, 0 or a Tile's axes)."""
    if axis is None:
        return terrains
    if axis == 0:
        return terrains[0]
    return terrains._replace(index=terrains.index[0])


def per_env_mask(env, terrain) -> Any:
    """A pytree of bools over a batched env state: True for per-env leaves, False for leaves the batch shares
    (MuJoCo Warp's contact counters and buffers, whose values every step recomputes). Told apart by their shapes at
    two batch sizes (``jax.eval_shape``: nothing runs); ``terrain`` is one env's terrain argument."""

    def shapes(n):
        return jax.eval_shape(lambda k, t: _batched_reset(env, k, t, n), jax.random.PRNGKey(0), terrain)

    return jax.tree_util.tree_map(lambda a, b: a.shape[:1] != b.shape[:1], shapes(2), shapes(3))


def _join_envs(per_env, a, b):
    """Batched env states ``a`` [N] and ``b`` [R] as one batch [N + R] (shared leaves: ``a``'s)."""
    return jax.tree_util.tree_map(lambda p, x, y: jnp.concatenate([x, y]) if p else x, per_env, a, b)


def _part_envs(per_env, states, n: int):
    """:func:`_join_envs` undone: ``(states[:n], states[n:])`` (shared leaves in both)."""
    head = jax.tree_util.tree_map(lambda p, x: x[:n] if p else x, per_env, states)
    tail = jax.tree_util.tree_map(lambda p, x: x[n:] if p else x, per_env, states)
    return head, tail


def _join_terrains(terrains, axis, ride_terrains, n: int, r: int):
    """The terrain argument of ``n`` PPO envs (``terrains`` with vmap ``axis``) and ``r`` riders, as one per-env
    argument of ``n + r`` envs: arrays ``[n + r, H, W]`` or a Tile with index ``[n + r]`` (the PPO envs' bank)."""
    if isinstance(terrains, Tile):
        own = jnp.broadcast_to(jnp.asarray(terrains.index, jnp.int32), (n,))
        ride = jnp.broadcast_to(jnp.asarray(ride_terrains.index, jnp.int32), (r,))
        return terrains._replace(index=jnp.concatenate([own, ride]))
    own = terrains if axis == 0 else jnp.broadcast_to(terrains, (n,) + terrains.shape)
    ride = ride_terrains if ride_terrains.ndim == 3 else jnp.broadcast_to(ride_terrains, (r,) + ride_terrains.shape)
    return jnp.concatenate([own, ride])


def _zero_episode(num_envs: int) -> EpisodeStats:
    z = jnp.zeros((num_envs,), jnp.float32)
    return EpisodeStats(z, z, z, z, z, z)


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
    env_state = _batched_reset(env, env_key, terrains, config.num_envs)
    return TrainState(
        params=params,
        opt_state=make_optimizer(config).init(params),
        normaliser=normaliser,
        env_state=env_state,
        episode=_zero_episode(config.num_envs),
        key=run_key,
        update_step=jnp.zeros((), jnp.int32),
        env_steps=jnp.zeros((), jnp.int32),
    )


def reset_envs(state: TrainState, key: jax.Array, terrains: jax.Array, *, env: EnvLike,
               config: PPOConfig) -> TrainState:
    """Restart every env on ``terrains`` (as in :func:`init`: arrays or a ``walker.Tile``; e.g. after a curriculum
    switch) and clear running episode counters."""
    env_state = _batched_reset(env, raw_key(key), terrains, config.num_envs)
    ep = state.episode
    zero = jnp.zeros_like(ep.ret)
    return state._replace(env_state=env_state, episode=ep._replace(ret=zero, length=zero, progress=zero))


# ----------------------------------------------------------------------------------------------------------------
# update = collect + GAE + epochs of minibatch SGD
# ----------------------------------------------------------------------------------------------------------------
def _collect(state: TrainState, key, terrains, env, config, rows=None, ride: Optional[Ride] = None, carry=None,
             per_env=None):
    """``num_unrolls`` x ``unroll_length`` steps of all envs with auto-reset.

    Returns (env_state, episode, data: Transition [K, T, N, ...], bootstrap_obs [K, N, O], carry).
    Envs that finish reset into a pool of fresh ``env.reset`` states drawn once per update (one reset per env
    per update instead of one per step). Non-finite observations end the episode (NaN-safety). ``rows = (start,
    total)``: these N envs are rows ``start .. start + N`` of a batch of ``total`` (one device's share, see
    :func:`_collect_split`), and every random draw is that slice of the whole batch's draw.

    ``ride`` (a :class:`Ride`): ``state.env_state`` holds ``N + R`` envs, the PPO envs then the ``R`` riders (see
    :func:`ride_updates`); all are stepped together, the riders by ``ride.act`` and never reset, ``carry`` goes
    through ``ride.record`` after every step, and ``data`` / the episode statistics are the PPO envs' alone.
    ``per_env``: :func:`per_env_mask` of the batch if the caller has it (else traced here: two reset traces).
    """
    n, dist = config.num_envs, config.action_distribution
    axis = terrain_axis(terrains, n)
    pool_key, unroll_key = jax.random.split(key)
    del key
    pool = _batched_reset(env, pool_key, terrains, n, rows)
    if ride is None:  # the PPO envs alone: nothing sliced or widened
        step_terrains, own, widen = terrains, (lambda x: x), (lambda mask: mask)
    else:
        r = state.env_state.obs.shape[0] - n
        step_terrains = _join_terrains(terrains, axis, ride.terrains, n, r)
        own = lambda x: x[:n]  # noqa: E731 - the PPO envs' rows
        widen = lambda mask: jnp.concatenate([mask, jnp.zeros((r,), bool)])  # noqa: E731 - riders never reset
        if per_env is None:
            per_env = per_env_mask(env, _one_terrain(terrains, axis))
        pool = _join_envs(per_env, pool, _part_envs(per_env, state.env_state, n)[1])  # rider rows: never taken
    v_step = jax.vmap(env.step, in_axes=(0, 0, terrain_axis(step_terrains, pool.obs.shape[0])))

    def env_step(carry, step_key):
        env_state, ep, ride_carry = carry
        obs = own(env_state.obs)
        loc, scale = nets.policy_apply(config, env.action_size, state.params, state.normaliser, obs)
        if rows is None:
            raw = nets.sample_raw(step_key, loc, scale)
        else:  # this device's rows of the whole batch's normal draw
            noise = jax.random.normal(step_key, (rows[1],) + loc.shape[1:], loc.dtype)
            raw = loc + scale * jax.lax.dynamic_slice_in_dim(noise, rows[0], n)
        logp = nets.log_prob(dist, loc, scale, raw)
        action = nets.postprocess(dist, raw)
        if ride is not None:
            action = jnp.concatenate([action, jnp.asarray(ride.act(env_state.obs[n:]), action.dtype)])
        next_state = v_step(env_state, action, step_terrains)
        if ride is not None:
            ride_carry = ride.record(ride_carry, next_state, n)
            if ride.park is not None:
                next_state = ride.park(ride_carry, next_state, n)
        finite = jnp.all(jnp.isfinite(own(next_state.obs)), axis=-1)
        reward = own(next_state.reward)
        reward = jnp.where(jnp.isfinite(reward), reward, 0.0).astype(jnp.float32)
        done = jnp.maximum(own(next_state.done).astype(jnp.float32), 1.0 - finite.astype(jnp.float32))
        trunc = own(_truncation(next_state)) * finite
        boot = jnp.zeros_like(reward)
        if config.truncation == "bootstrap":  # SB3's time-limit bootstrap: a terminal step worth r + gamma V(final)
            final_value = nets.value_apply(config, state.params, state.normaliser, own(next_state.obs))
            boot = jnp.where(trunc > 0, config.gamma * final_value, 0.0)
            trunc = jnp.zeros_like(trunc)
        ret, length = ep.ret + reward, ep.length + 1.0
        ended = done > 0
        distance = getattr(next_state, "distance", None)
        reached = ep.progress if distance is None else jnp.maximum(
            ep.progress, jnp.where(finite, jnp.nan_to_num(own(distance).astype(jnp.float32)), 0.0))
        ep = EpisodeStats(
            ret=jnp.where(ended, 0.0, ret),
            length=jnp.where(ended, 0.0, length),
            last_return=jnp.where(ended, ret, ep.last_return),
            last_length=jnp.where(ended, length, ep.last_length),
            count=ep.count + done,
            progress=reached,
        )
        next_state = _select_envs(env, widen(ended), pool, next_state)
        return (next_state, ep, ride_carry), Transition(obs, raw, logp, reward, done, trunc, boot)

    def unroll(carry, unroll_key):
        carry, data = jax.lax.scan(env_step, carry, jax.random.split(unroll_key, config.unroll_length))
        return carry, (data, own(carry[0].obs))

    (env_state, episode, carry), (data, bootstrap_obs) = jax.lax.scan(
        unroll, (state.env_state, state.episode, carry), jax.random.split(unroll_key, config.num_unrolls))
    return env_state, episode, data, bootstrap_obs, carry


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
    """:func:`update` -> ``((state, metrics), carry)``; with ``ride`` the riders step along (:func:`_collect`)."""
    key = raw_key(key)
    collect_key, sgd_key = jax.random.split(key)
    del key
    if mesh is not None and collect_mode(mesh, config, env, collect) == "shard_map":
        env_state, episode, data, bootstrap_obs = _collect_split(state, collect_key, terrains, env, config, mesh)
    else:
        if mesh is not None:  # envs that do not divide over the devices: XLA partitions the batched steps
            state, terrains = _split_envs(state, terrains, config, mesh)
        env_state, episode, data, bootstrap_obs, carry = _collect(state, collect_key, terrains, env, config,
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


COLLECT_MODES = ("shard_map", "partition")


def collect_mode(mesh, config: PPOConfig, env=None, collect: Optional[str] = None) -> str:
    """How a data-parallel update splits its env steps: ``"shard_map"`` (:func:`_collect_split`, each device its
    own envs) or ``"partition"`` (sharding constraints; XLA partitions the batched steps). ``collect`` (one of
    :data:`COLLECT_MODES`) when given and ``num_envs`` divides over the devices; else ``"partition"`` when it does
    not divide or on GPUs (JAX 0.11.2's CUDA plugin crashes compiling the walker's step inside ``shard_map``:
    ``sharding.default_split``), else ``"shard_map"``. MuJoCo Warp's step is one opaque call that XLA cannot
    partition, so a Warp env on GPUs is a ``ValueError`` unless ``collect="shard_map"`` asks for the path that JAX
    0.11.2 fails to compile (segfault, measured on 2 H200s, 2026-11-23). No environment variable changes it (the
    ``JAXTERRAIN_PPO_COLLECT`` of earlier versions is gone)."""
    if collect not in (None, *COLLECT_MODES):
        raise ValueError(f"collect must be one of {COLLECT_MODES} or None (automatic), got {collect!r}")
    if config.num_envs % mesh.devices.size:
        return "partition"
    if collect:
        return collect
    if sharding.default_split(mesh) != "dispatch":
        return "shard_map"
    if getattr(env, "backend", None) == "warp":
        raise ValueError("data-parallel PPO (mesh=) on MuJoCo Warp over several GPUs needs shard_map, which JAX "
                         "0.11.2's CUDA plugin fails to compile; train on one device, or use backend='jax', or pass "
                         "collect='shard_map' to try this JAX")
    return "partition"


def _collect_split(state: TrainState, key, terrains, env, config: PPOConfig, mesh):
    """:func:`_collect` with the envs split over ``mesh``'s devices under ``jax.shard_map``: each device steps its
    own ``num_envs / devices`` envs (an opaque physics call such as MuJoCo Warp's runs per device, which XLA's
    partitioner cannot split) with its slice of the one-device random draws, so the data equal :func:`_collect`'s
    up to float rounding. ``num_envs`` must divide over the devices. Outputs split along their env axis."""
    from jax.sharding import PartitionSpec as P


    d, n = mesh.devices.size, config.num_envs
    local = n // d
    axis = terrain_axis(terrains, n)
    rows_spec = P(sharding.AXIS)
    whole = jax.tree_util.tree_map(lambda _: P(), state)
    state_spec = whole._replace(env_state=_env_specs(env, terrains, axis, rows_spec),
                                episode=jax.tree_util.tree_map(lambda _: rows_spec, state.episode))
    if axis is None:
        terrain_spec = jax.tree_util.tree_map(lambda _: P(), terrains)
    elif axis == 0:
        terrain_spec = rows_spec
    else:  # a Tile per env: the bank whole on every device, the indices split
        terrain_spec = terrains._replace(bank=jax.tree_util.tree_map(lambda _: P(), terrains.bank), index=rows_spec)

    def collect(state, key, terrains):
        start = jax.lax.axis_index(sharding.AXIS) * local
        return _collect(state, key, terrains, env, config._replace(num_envs=local), rows=(start, n))[:4]

    out_specs = (state_spec.env_state, rows_spec, P(None, None, sharding.AXIS), P(None, sharding.AXIS))
    return jax.shard_map(collect, mesh=mesh, in_specs=(state_spec, P(), terrain_spec), out_specs=out_specs,
                         check_vma=False)(state, key, terrains)


def _env_specs(env, terrains, axis, rows_spec):
    """The ``PartitionSpec`` of every leaf of a batched env state: ``rows_spec`` for per-env leaves, ``P()`` for
    leaves the batch shares (MuJoCo Warp's contact counters and buffers, whose values each step recomputes). Told
    apart by their shapes (``jax.eval_shape``, nothing runs) at two batch sizes."""
    from jax.sharding import PartitionSpec as P

    return jax.tree_util.tree_map(lambda p: rows_spec if p else P(), per_env_mask(env, _one_terrain(terrains, axis)))


def _split_envs(state: TrainState, terrains: jax.Array, config: PPOConfig, mesh):
    """``state``'s envs (and per-env ``terrains``) constrained to be split over ``mesh``'s devices (inside jit)."""

    rows = lambda tree: jax.lax.with_sharding_constraint(tree, sharding.rows(mesh))  # noqa: E731
    state = state._replace(env_state=rows(state.env_state), episode=rows(state.episode))
    axis = terrain_axis(terrains, config.num_envs)
    if axis == 0:
        return state, rows(terrains)
    return state, (terrains._replace(index=rows(terrains.index)) if axis is not None else terrains)  # per-env tiles


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
        per_env = per_env_mask(env, _one_terrain(terrains, terrain_axis(terrains, n)))
    both = state._replace(env_state=_join_envs(per_env, state.env_state, riders))

    def body(c, _):
        s, rc = c
        next_key, update_key = jax.random.split(s.key)
        (s, metrics), rc = _update(s._replace(key=next_key), update_key, terrains, env, config, ride=ride, carry=rc,
                                   per_env=per_env)
        return (s, rc), metrics

    (state, carry), metrics = jax.lax.scan(body, (both, carry), None, length=num_updates)
    envs, riders = _part_envs(per_env, state.env_state, n)
    return state._replace(env_state=envs), riders, carry, metrics


def make_train(env: EnvLike, config: PPOConfig, num_updates: int):
    """purejaxrl-style ``train_fn(key, terrains) -> (state, metrics [num_updates])``: init + updates, one pure
    function of the key; ``jax.jit(jax.vmap(train_fn, in_axes=(0, None)))(keys, terrains)`` trains many seeds."""

    def train_fn(key, terrains):
        state = init(key, env, config, terrains)
        return run_updates(state, terrains, env=env, config=config, num_updates=num_updates)

    return train_fn

