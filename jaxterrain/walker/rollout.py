"""The walker's batched rollout loops (the core of :mod:`jaxterrain.difficulty`), on either terrain layout.

    d, n = rollout.batched_distances(env, policy, terrains, key, attempts)           # [B, attempts] each
    d, n = rollout.batched_distances(env, policy, terrains, key, attempts, slots=S)  # a pool of S env slots

``terrains`` is ``[B, H, W]`` metres for every env. What the env does with them is its layout
(:mod:`jaxterrain.walker.env`):

- classic (``config.tiles = 0``, ``backend="jax"``): every env carries its own ``[H, W]`` heightfield in a batched
  model field (vmap ``in_axes=0``). The programs are exactly those :mod:`jaxterrain.difficulty` always had.
- tiled (``config.tiles >= 1``, required by ``backend="warp"``): the ``B`` terrains become ONE
  :class:`~jaxterrain.walker.TileBank` (``env.make_bank``) and terrain ``b``'s walks run on ``bank.at(b)``
  (vmap ``in_axes=TILE_AXES``); a pool's refill merges states with ``env.select`` (MuJoCo Warp's shared contact
  buffers). The walks are those of the classic layout up to float32 rounding of the shifted world coordinates
  (``tests/difficulty/test_tiles_difficulty.py`` measures it), and, under ``backend="warp"``, up to MuJoCo Warp's own solver
  arithmetic.

A tiled env's ``tiles`` and ``warp_worlds`` are sized to each call by :func:`sized_env`: ``tiles`` = the call's
terrains, ``warp_worlds`` = the envs it steps together (``B * attempts``, or ``slots``), so any tiled env (e.g.
``WalkerConfig(tiles=1, backend="warp")``, :func:`jaxterrain.difficulty.default_env_config` with
``backend="warp"``) serves every batch size; the sized envs are built once per size (:func:`make_env`'s cache),
also while a caller's ``jit`` traces. An env whose ``tiles`` already equal the call's terrains (and, warp, whose
``warp_worlds`` is at least the envs stepped) is used as it is: build one so when you ``vmap`` these functions
yourself, since MuJoCo Warp counts the envs over ALL vmap axes (``warp_worlds`` >= the total).

:mod:`jaxterrain.difficulty`'s docstring describes the protocol these loops serve; the layouts and the env sizing
are :mod:`jaxterrain.walker.layout`'s.
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple, Optional

import jax
import jax.numpy as jnp

from jaxterrain.walker.env import WalkerEnv
from jaxterrain.walker.layout import check_worlds, sized_env, terrain_batch, world

__all__ = ["batched_distances", "pooled_distances", "job_queue", "smoothness_priority"]




# ----------------------------------------------------------------------------------------------------------------
# All rollouts at once, or a pool
# ----------------------------------------------------------------------------------------------------------------
def batched_distances(env: WalkerEnv, policy: Callable, terrains: jax.Array, key: jax.Array, attempts: int,
                      policy_params: Any = None, slots: Optional[int] = None, refill_every: int = 8,
                      needed: Optional[jax.Array] = None,
                      priority: Optional[jax.Array] = None) -> tuple[jax.Array, jax.Array]:
    """Roll out ``attempts`` episodes on each of ``terrains`` [B, H, W] (metres) until all have ended.

    ``policy(obs)`` (or ``policy(policy_params, obs)`` when ``policy_params`` is not None) maps one observation
    [O] to one action [A]. Returns ``(distances [B, attempts] float32 in [0, 1], steps [B, attempts] int32)``:
    the normalised distance at each rollout's end (0 where the rollout failed: invalid physics / action) and its
    length in env steps. ``env`` of either layout (module docstring); a tiled one is sized to the call.

    ``slots=None`` (or ``>= B * attempts``) runs every rollout at once until the longest has ended: a rollout that
    ended early keeps its slot idle until then. With ``slots=S`` the ``B * attempts`` rollouts are jobs queued on
    ``S`` env slots: every ``refill_every`` env steps the slots whose episode ended take the next jobs (in job
    order, terrain-major). The rollouts are the same (same keys, terrains and policy) up to the floating-point
    effects of another batch size, which the walker's chaotic dynamics can grow into a different outcome of a single
    rollout: fitness is then the same in distribution, not bit for bit (a given ``slots`` is deterministic). Pooling
    saves the slot-steps that ended rollouts would idle, worth it when episode lengths vary a lot, at the cost of a
    smaller batch. Either way an ended rollout (or an idle slot) steps on parked (``WalkerEnv.park``): out of
    contact, so on MuJoCo Warp it costs the solver next to nothing until the loop ends (or the slot is refilled).

    ``needed`` [B] bool (optional): terrains whose distances are wanted; the others get distance 0 and length 0.
    With ``slots`` their rollouts are never started (MAP-Elites passes Algorithm 1's verdict: a rejected terrain
    never enters the archive, so walking it is wasted); without, they run but end the loop no later.

    ``priority`` [B] float (optional, only with ``slots``): the queue takes the rollouts of higher-priority terrains
    first (ties in job order). The loop lasts until the last-started rollout ends, so starting the long rollouts
    first shortens it (longest-first scheduling): :func:`smoothness_priority` ranks terrains the walker is likely
    to walk far (smooth ones) first. The results do not depend on the order, only the time does.
    """
    b = terrains.shape[0]
    jobs = b * attempts
    reset_keys = jax.random.split(key, (b, attempts))
    del key
    act = (lambda obs: policy(obs)) if policy_params is None else (lambda obs: policy(policy_params, obs))
    needed = jnp.ones(b, bool) if needed is None else jnp.asarray(needed, bool).reshape(b)
    if slots is not None and slots < jobs:
        if not refill_every >= 1:
            raise ValueError(f"refill_every must be >= 1, got {refill_every}")
        queue, queued = job_queue(jnp.repeat(needed, attempts),
                                  None if priority is None else jnp.repeat(jnp.asarray(priority).reshape(b), attempts))
        return pooled_distances(env, act, terrains, reset_keys.reshape(jobs, *reset_keys.shape[2:]), attempts,
                                 int(slots), int(refill_every), queue, queued)
    env = sized_env(env, b, jobs)
    check_worlds(env, jobs)
    world, axes = terrain_batch(env, terrains)
    reset = jax.vmap(jax.vmap(env.reset, in_axes=(0, None)), in_axes=(0, axes))
    step = jax.vmap(jax.vmap(env.step, in_axes=(0, 0, None)), in_axes=(0, 0, axes))
    act = jax.vmap(jax.vmap(act))
    horizon = env.config.episode_length

    state = reset(reset_keys, world)
    ended = jnp.broadcast_to(~needed[:, None], (b, attempts))
    final = jnp.zeros((b, attempts), jnp.float32)
    length = jnp.zeros((b, attempts), jnp.int32)

    def cond(carry):
        t, _, ended, _, _ = carry
        return (t < horizon) & ~jnp.all(ended)

    def body(carry):
        t, state, ended, final, length = carry
        state = step(state, act(state.obs), world)
        dist = jnp.where(state.failed > 0, 0.0, state.distance)
        final = jnp.where(ended, final, dist)
        length = jnp.where(ended, length, state.steps)
        ended = ended | (state.done > 0)
        return t + 1, env.park(state, ended), ended, final, length  # an ended rollout steps on out of the way

    _, _, _, final, length = jax.lax.while_loop(cond, body, (jnp.int32(0), state, ended, final, length))
    return final, length


class _Pool(NamedTuple):
    """Loop carry of :func:`pooled_distances` (S slots, J jobs)."""

    state: Any  # WalkerState with leading [S]
    terrain: jax.Array  # the terrain of each slot's job: [S, H, W] metres (classic), [S] int32 tile index (tiled)
    job: jax.Array  # [S] int32, the job in the slot (J when none)
    active: jax.Array  # [S] bool, the slot's episode has not ended yet
    next_job: jax.Array  # [] int32, queue position of the first job not started yet
    distance: jax.Array  # [J] float32 results
    length: jax.Array  # [J] int32 results


def job_queue(needed: jax.Array, priority: Optional[jax.Array] = None) -> tuple[jax.Array, jax.Array]:
    """The order in which a rollout pool starts ``J`` jobs: ``(queue [J] int32, queued [] int32)``.

    ``needed`` [J] bool; ``priority`` [J] float or None. ``queue[:queued]`` are the needed jobs, highest priority
    first, ties (and ``priority=None``) in job order; the rest of ``queue`` are the jobs never started. NaN
    priority counts as lowest.
    """
    needed = jnp.asarray(needed, bool)
    if needed.ndim != 1:
        raise ValueError(f"needed must have shape [J]; got shape {tuple(needed.shape)}")
    if priority is not None and tuple(jnp.shape(priority)) != tuple(needed.shape):
        raise ValueError(f"priority must have the shape of needed [J] = {tuple(needed.shape)}; got shape "
                         f"{tuple(jnp.shape(priority))}")
    if priority is None:
        queue = jnp.argsort(~needed, stable=True)
    else:
        p = jnp.nan_to_num(jnp.asarray(priority, jnp.float32), nan=-jnp.inf)
        queue = jnp.lexsort((-p, ~needed))  # primary key last: needed first, then descending priority (stable)
    return queue.astype(jnp.int32), jnp.sum(needed, dtype=jnp.int32)


def smoothness_priority(terrains: jax.Array) -> jax.Array:
    """``[B, H, W]`` -> ``[B]`` float32: minus the mean absolute height step between neighbouring cells.

    A cheap guess at which terrains the walker will walk longest (smooth ones), to start their rollouts first
    (``batched_distances(priority=...)``); only the speed of a pooled evaluation depends on it.
    """
    t = jnp.asarray(terrains, jnp.float32)
    dx = jnp.mean(jnp.abs(jnp.diff(t, axis=-1)), axis=(-2, -1))
    dy = jnp.mean(jnp.abs(jnp.diff(t, axis=-2)), axis=(-2, -1))
    return -(dx + dy)


def pooled_distances(env, act, terrains, keys, attempts: int, slots: int, refill_every: int, queue, queued):
    """:func:`batched_distances` with ``slots`` env slots fed from a queue of ``J = B * attempts`` jobs.

    ``keys`` [J] (job ``j`` is attempt ``j % attempts`` on terrain ``j // attempts``); ``queue`` [J] / ``queued``
    from :func:`job_queue`: jobs ``queue[:queued]`` are started in that order, the others never. An outer ``while_loop``
    (until no slot is active and no job waits) runs ``refill_every`` env steps (a ``fori_loop``; a slot's result is
    written when its episode ends) and then refills the ended slots (a ``cond``, skipped when nothing changes).
    A tiled env (sized to ``B`` tiles and ``slots`` envs) keeps each slot's tile index; the refill merges states
    with ``env.select``.
    """
    jobs = keys.shape[0]
    env = sized_env(env, terrains.shape[0], slots)
    check_worlds(env, slots)
    bank, axes = world(env, terrains)
    reset = jax.vmap(env.reset, in_axes=(0, axes))
    step = jax.vmap(env.step, in_axes=(0, 0, axes))
    act = jax.vmap(act)
    world_of = (lambda terrain: terrain) if bank is None else bank.at  # noqa: E731 - a slot's terrain argument

    def start(job):  # [S] job ids (J = none) -> (state, terrain) of their first step
        j = jnp.minimum(job, jobs - 1)
        terrain = terrains[j // attempts] if bank is None else (j // attempts).astype(jnp.int32)
        return reset(keys[j], world_of(terrain)), terrain

    def run_steps(p: _Pool) -> _Pool:
        def one(_, p: _Pool) -> _Pool:
            state = step(p.state, act(p.state.obs), world_of(p.terrain))
            ended = p.active & (state.done > 0)
            where = jnp.where(ended, p.job, jobs)  # out of range -> dropped
            distance = p.distance.at[where].set(jnp.where(state.failed > 0, 0.0, state.distance), mode="drop")
            length = p.length.at[where].set(state.steps, mode="drop")
            active = p.active & ~ended
            return p._replace(state=env.park(state, ~active), active=active, distance=distance, length=length)

        return jax.lax.fori_loop(0, refill_every, one, p)

    def refill(p: _Pool) -> _Pool:
        free = ~p.active
        position = p.next_job + jnp.cumsum(free, dtype=jnp.int32) - 1
        take = free & (position < queued)
        new_job = jnp.where(take, queue[jnp.minimum(position, jobs - 1)], jobs)
        state, terrain = start(new_job)
        pick = lambda new, old: jnp.where(take.reshape((-1,) + (1,) * (new.ndim - 1)), new, old)  # noqa: E731
        state = jax.tree.map(pick, state, p.state) if bank is None else env.select(take, state, p.state)
        return p._replace(state=state, terrain=pick(terrain, p.terrain),
                          job=jnp.where(take, new_job, jnp.where(p.active, p.job, jobs)), active=p.active | take,
                          next_job=p.next_job + jnp.sum(take, dtype=jnp.int32))

    def body(p: _Pool) -> _Pool:
        p = run_steps(p)
        can_start = jnp.any(~p.active) & (p.next_job < queued)
        return jax.lax.cond(can_start, refill, lambda p: p, p)

    position0 = jnp.arange(slots, dtype=jnp.int32)
    take0 = position0 < queued
    job0 = jnp.where(take0, queue[position0], jobs)
    state, terrain = start(job0)
    pool = _Pool(state=state, terrain=terrain, job=job0, active=take0, next_job=jnp.minimum(jnp.int32(slots), queued),
                 distance=jnp.zeros(jobs, jnp.float32), length=jnp.zeros(jobs, jnp.int32))
    pool = jax.lax.while_loop(lambda p: jnp.any(p.active), body, pool)
    return pool.distance.reshape(-1, attempts), pool.length.reshape(-1, attempts)
