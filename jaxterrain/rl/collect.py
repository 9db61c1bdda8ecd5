"""How PPO gathers experience: ``num_unrolls x unroll_length`` steps of a batch of envs with auto-reset
(:func:`collect_steps`), the batched env helpers it needs (resets, per-env selection, riders joined to the batch), and,
over several devices, how the steps are split (:func:`collect_mode`: ``shard_map``, each device its own envs, or
``partition``, XLA partitions the batched steps from sharding constraints). :mod:`jaxterrain.rl.ppo` calls it; the
choice of mode is the caller's argument, never an environment variable."""

from __future__ import annotations

from typing import Any, Optional

import jax
import jax.numpy as jnp

from jaxterrain.rl import networks as nets
from jaxterrain.rl.config import PPOConfig
from jaxterrain.rl.state import EpisodeStats, Ride, TrainState, Transition
from jaxterrain.runtime import sharding
from jaxterrain.walker.layout import terrain_axis
from jaxterrain.walker.tiles import Tile

__all__ = ["COLLECT_MODES", "batched_reset", "truncation_of", "select", "select_envs", "one_terrain", "per_env_mask",
           "join_envs", "part_envs", "join_terrains", "zero_episode", "collect_steps", "collect_mode", "collect_split",
           "env_specs", "split_envs"]


def batched_reset(env, key, terrains, num_envs, rows=None):
    """``num_envs`` reset envs keyed ``split(key, num_envs)``; ``rows = (start, total)``: envs ``start ..
    start + num_envs`` of a batch of ``total`` (keys ``split(key, total)[start:start + num_envs]``)."""
    axis = terrain_axis(terrains, num_envs)
    if rows is None:
        keys = jax.random.split(key, num_envs)
    else:
        keys = jax.lax.dynamic_slice_in_dim(jax.random.split(key, rows[1]), rows[0], num_envs)
    return jax.vmap(env.reset, in_axes=(0, axis))(keys, terrains)


def truncation_of(env_state) -> jax.Array:
    trunc = getattr(env_state, "truncation", None)
    if trunc is None:
        info = getattr(env_state, "info", None)
        if isinstance(info, dict):
            trunc = info.get("truncation")
    if trunc is None:
        return jnp.zeros_like(env_state.done)
    return jnp.asarray(trunc, jnp.float32)


def select(mask: jax.Array, on_true, on_false):
    """Per-env ``where`` over two batched pytrees (mask [N])."""

    def sel(a, b):
        m = jnp.reshape(mask, mask.shape + (1,) * (a.ndim - mask.ndim))
        return jnp.where(m, a, b)

    return jax.tree_util.tree_map(sel, on_true, on_false)


def select_envs(env, mask: jax.Array, on_true, on_false):
    """Batched env states: ``env.select(mask, on_true, on_false)`` when the env has it (the walker: MJX-Warp's
    ``Data`` holds contact buffers shared by all envs, which a per-leaf ``where`` would split), else :func:`select`
    (the same values)."""
    own = getattr(env, "select", None)
    return select(mask, on_true, on_false) if own is None else own(mask, on_true, on_false)


def one_terrain(terrains, axis):
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
        return jax.eval_shape(lambda k, t: batched_reset(env, k, t, n), jax.random.PRNGKey(0), terrain)

    return jax.tree_util.tree_map(lambda a, b: a.shape[:1] != b.shape[:1], shapes(2), shapes(3))


def join_envs(per_env, a, b):
    """Batched env states ``a`` [N] and ``b`` [R] as one batch [N + R] (shared leaves: ``a``'s)."""
    return jax.tree_util.tree_map(lambda p, x, y: jnp.concatenate([x, y]) if p else x, per_env, a, b)


def part_envs(per_env, states, n: int):
    """:func:`join_envs` undone: ``(states[:n], states[n:])`` (shared leaves in both)."""
    head = jax.tree_util.tree_map(lambda p, x: x[:n] if p else x, per_env, states)
    tail = jax.tree_util.tree_map(lambda p, x: x[n:] if p else x, per_env, states)
    return head, tail


def join_terrains(terrains, axis, ride_terrains, n: int, r: int):
    """The terrain argument of ``n`` PPO envs (``terrains`` with vmap ``axis``) and ``r`` riders, as one per-env
    argument of ``n + r`` envs: arrays ``[n + r, H, W]`` or a Tile with index ``[n + r]`` (the PPO envs' bank)."""
    if isinstance(terrains, Tile):
        own = jnp.broadcast_to(jnp.asarray(terrains.index, jnp.int32), (n,))
        ride = jnp.broadcast_to(jnp.asarray(ride_terrains.index, jnp.int32), (r,))
        return terrains._replace(index=jnp.concatenate([own, ride]))
    own = terrains if axis == 0 else jnp.broadcast_to(terrains, (n,) + terrains.shape)
    ride = ride_terrains if ride_terrains.ndim == 3 else jnp.broadcast_to(ride_terrains, (r,) + ride_terrains.shape)
    return jnp.concatenate([own, ride])


def zero_episode(num_envs: int) -> EpisodeStats:
    z = jnp.zeros((num_envs,), jnp.float32)
    return EpisodeStats(z, z, z, z, z, z)


def collect_steps(state: TrainState, key, terrains, env, config, rows=None, ride: Optional[Ride] = None, carry=None,
             per_env=None):
    """``num_unrolls`` x ``unroll_length`` steps of all envs with auto-reset.

    Returns (env_state, episode, data: Transition [K, T, N, ...], bootstrap_obs [K, N, O], carry).
    Envs that finish reset into a pool of fresh ``env.reset`` states drawn once per update (one reset per env
    per update instead of one per step). Non-finite observations end the episode (NaN-safety). ``rows = (start,
    total)``: these N envs are rows ``start .. start + N`` of a batch of ``total`` (one device's share, see
    :func:`collect_split`), and every random draw is that slice of the whole batch's draw.

    ``ride`` (a :class:`Ride`): ``state.env_state`` holds ``N + R`` envs, the PPO envs then the ``R`` riders (see
    :func:`ride_updates`); all are stepped together, the riders by ``ride.act`` and never reset, ``carry`` goes
    through ``ride.record`` after every step, and ``data`` / the episode statistics are the PPO envs' alone.
    ``per_env``: :func:`per_env_mask` of the batch if the caller has it (else traced here: two reset traces).
    """
    n, dist = config.num_envs, config.action_distribution
    axis = terrain_axis(terrains, n)
    pool_key, unroll_key = jax.random.split(key)
    del key
    pool = batched_reset(env, pool_key, terrains, n, rows)
    if ride is None:  # the PPO envs alone: nothing sliced or widened
        step_terrains, own, widen = terrains, (lambda x: x), (lambda mask: mask)
    else:
        r = state.env_state.obs.shape[0] - n
        step_terrains = join_terrains(terrains, axis, ride.terrains, n, r)
        own = lambda x: x[:n]  # noqa: E731 - the PPO envs' rows
        widen = lambda mask: jnp.concatenate([mask, jnp.zeros((r,), bool)])  # noqa: E731 - riders never reset
        if per_env is None:
            per_env = per_env_mask(env, one_terrain(terrains, axis))
        pool = join_envs(per_env, pool, part_envs(per_env, state.env_state, n)[1])  # rider rows: never taken
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
        trunc = own(truncation_of(next_state)) * finite
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
        next_state = select_envs(env, widen(ended), pool, next_state)
        return (next_state, ep, ride_carry), Transition(obs, raw, logp, reward, done, trunc, boot)

    def unroll(carry, unroll_key):
        carry, data = jax.lax.scan(env_step, carry, jax.random.split(unroll_key, config.unroll_length))
        return carry, (data, own(carry[0].obs))

    (env_state, episode, carry), (data, bootstrap_obs) = jax.lax.scan(
        unroll, (state.env_state, state.episode, carry), jax.random.split(unroll_key, config.num_unrolls))
    return env_state, episode, data, bootstrap_obs, carry


COLLECT_MODES = ("shard_map", "partition")


def collect_mode(mesh, config: PPOConfig, env=None, collect: Optional[str] = None) -> str:
    """How a data-parallel update splits its env steps: ``"shard_map"`` (:func:`collect_split`, each device its
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


def collect_split(state: TrainState, key, terrains, env, config: PPOConfig, mesh):
    """:func:`collect_steps` with the envs split over ``mesh``'s devices under ``jax.shard_map``: each device steps its
    own ``num_envs / devices`` envs (an opaque physics call such as MuJoCo Warp's runs per device, which XLA's
    partitioner cannot split) with its slice of the one-device random draws, so the data equal :func:`collect_steps`'s
    up to float rounding. ``num_envs`` must divide over the devices. Outputs split along their env axis."""
    from jax.sharding import PartitionSpec as P


    d, n = mesh.devices.size, config.num_envs
    local = n // d
    axis = terrain_axis(terrains, n)
    rows_spec = P(sharding.AXIS)
    whole = jax.tree_util.tree_map(lambda _: P(), state)
    state_spec = whole._replace(env_state=env_specs(env, terrains, axis, rows_spec),
                                episode=jax.tree_util.tree_map(lambda _: rows_spec, state.episode))
    if axis is None:
        terrain_spec = jax.tree_util.tree_map(lambda _: P(), terrains)
    elif axis == 0:
        terrain_spec = rows_spec
    else:  # a Tile per env: the bank whole on every device, the indices split
        terrain_spec = terrains._replace(bank=jax.tree_util.tree_map(lambda _: P(), terrains.bank), index=rows_spec)

    def local_steps(state, key, terrains):
        start = jax.lax.axis_index(sharding.AXIS) * local
        return collect_steps(state, key, terrains, env, config._replace(num_envs=local), rows=(start, n))[:4]

    out_specs = (state_spec.env_state, rows_spec, P(None, None, sharding.AXIS), P(None, sharding.AXIS))
    return jax.shard_map(local_steps, mesh=mesh, in_specs=(state_spec, P(), terrain_spec), out_specs=out_specs,
                         check_vma=False)(state, key, terrains)


def env_specs(env, terrains, axis, rows_spec):
    """The ``PartitionSpec`` of every leaf of a batched env state: ``rows_spec`` for per-env leaves, ``P()`` for
    leaves the batch shares (MuJoCo Warp's contact counters and buffers, whose values each step recomputes). Told
    apart by their shapes (``jax.eval_shape``, nothing runs) at two batch sizes."""
    from jax.sharding import PartitionSpec as P

    return jax.tree_util.tree_map(lambda p: rows_spec if p else P(), per_env_mask(env, one_terrain(terrains, axis)))


def split_envs(state: TrainState, terrains: jax.Array, config: PPOConfig, mesh):
    """``state``'s envs (and per-env ``terrains``) constrained to be split over ``mesh``'s devices (inside jit)."""

    rows = lambda tree: jax.lax.with_sharding_constraint(tree, sharding.rows(mesh))  # noqa: E731
    state = state._replace(env_state=rows(state.env_state), episode=rows(state.episode))
    axis = terrain_axis(terrains, config.num_envs)
    if axis == 0:
        return state, rows(terrains)
    return state, (terrains._replace(index=rows(terrains.index)) if axis is not None else terrains)  # per-env tiles
