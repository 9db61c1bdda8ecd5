"""Terrain difficulty by the base policy (paper 3.3): fitness = mean of the best ``best`` of ``attempts`` normalised
distances walked from random joint initialisations; difficulty = 1 - fitness.

    fitness = difficulty.evaluate(heightmaps, key)              # [B, H, W] in [0, 1] -> [B] float32 in [0, 1]

All ``B x attempts`` rollouts run in ONE batched, jit-compiled call: ``vmap`` over terrains (each its own
heightfield) of ``vmap`` over attempts (terrain shared), a ``lax.while_loop`` over time that stops as soon as every
rollout has ended (fall, far edge or ``env_config.episode_length``). A rollout's distance is
:attr:`jaxterrain.walker.WalkerState.distance` at its first ``done``; invalid physics or a non-finite action
(``state.failed``) counts as distance 0, so fitness is never NaN.

``policy`` is deterministic: ``policy(obs [O]) -> action [A]`` in [-1, 1]; or, with ``policy_params`` given,
``policy(policy_params, obs)`` - then new parameters do not re-compile (the curriculum's PPO can pass its own).
Without ``policy`` the shipped base policy (``jaxterrain.rl.load_policy()``) is used. Without ``env_config`` the env
is ``WalkerConfig(terrain_shape, scale)`` with the contact-solver options that the policy records it was trained with
(:func:`default_env_config`).

:func:`evaluate` and :func:`rollout_distances` are host-level entry points: they validate on the host and call a
cached jit-compiled function. Inside your own jit (e.g. a QDax scoring function) use the pure
:func:`batched_distances` / :func:`best_of`.

With ``slots=S`` the rollouts are jobs queued on ``S`` env slots that refill as episodes end, instead of all at once
(:func:`batched_distances`); the queue starts the smoothest terrains first (:func:`smoothness_priority`,
:func:`job_queue`), which shortens the tail in which the last long rollouts run on an otherwise idle pool.
"""

from __future__ import annotations

import functools
from typing import Any, Callable, NamedTuple, Optional

import jax
import jax.numpy as jnp

from jaxterrain.terrain import TerrainScale, validate_scale
from jaxterrain.walker import SolverOptions, WalkerConfig, WalkerEnv

__all__ = ["evaluate", "rollout_distances", "batched_distances", "best_of", "job_queue", "smoothness_priority",
           "validate_heightmaps", "default_policy", "default_env_config", "policy_solver", "make_env"]


# ----------------------------------------------------------------------------------------------------------------
# Pure functions (jit / vmap them yourself)
# ----------------------------------------------------------------------------------------------------------------
def best_of(distances: jax.Array, best: int) -> jax.Array:
    """``[B, attempts]`` -> ``[B]``: mean of the ``best`` largest distances per row (NaN counted as 0)."""
    d = jnp.nan_to_num(jnp.asarray(distances, jnp.float32), nan=0.0, posinf=0.0, neginf=0.0)
    return jnp.mean(jax.lax.top_k(d, best)[0], axis=-1)


def batched_distances(env: WalkerEnv, policy: Callable, terrains: jax.Array, key: jax.Array, attempts: int,
                      policy_params: Any = None, slots: Optional[int] = None, refill_every: int = 8,
                      needed: Optional[jax.Array] = None,
                      priority: Optional[jax.Array] = None) -> tuple[jax.Array, jax.Array]:
    """Roll out ``attempts`` episodes on each of ``terrains`` [B, H, W] (metres) until all have ended.

    ``policy(obs)`` (or ``policy(policy_params, obs)`` when ``policy_params`` is not None) maps one observation
    [O] to one action [A]. Returns ``(distances [B, attempts] float32 in [0, 1], steps [B, attempts] int32)``:
    the normalised distance at each rollout's end (0 where the rollout failed: invalid physics / action) and its
    length in env steps.

    ``slots=None`` (or ``>= B * attempts``) runs every rollout at once until the longest has ended: a rollout that
    ended early keeps its slot idle until then. With ``slots=S`` the ``B * attempts`` rollouts are jobs queued on
    ``S`` env slots: every ``refill_every`` env steps the slots whose episode ended take the next jobs (in job
    order, terrain-major). The rollouts are the same (same keys, terrains and policy) up to the floating-point
    effects of another batch size, which the walker's chaotic dynamics can grow into a different outcome of a single
    rollout: fitness is then the same in distribution, not bit for bit (a given ``slots`` is deterministic). Pooling
    saves the slot-steps that ended rollouts would idle, worth it when episode lengths vary a lot, at the cost of a
    smaller batch.

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
        return _pooled_distances(env, act, terrains, reset_keys.reshape(jobs, *reset_keys.shape[2:]), attempts,
                                 int(slots), int(refill_every), queue, queued)
    reset = jax.vmap(jax.vmap(env.reset, in_axes=(0, None)), in_axes=(0, 0))
    step = jax.vmap(jax.vmap(env.step, in_axes=(0, 0, None)), in_axes=(0, 0, 0))
    act = jax.vmap(jax.vmap(act))
    horizon = env.config.episode_length

    state = reset(reset_keys, terrains)
    ended = jnp.broadcast_to(~needed[:, None], (b, attempts))
    final = jnp.zeros((b, attempts), jnp.float32)
    length = jnp.zeros((b, attempts), jnp.int32)

    def cond(carry):
        t, _, ended, _, _ = carry
        return (t < horizon) & ~jnp.all(ended)

    def body(carry):
        t, state, ended, final, length = carry
        state = step(state, act(state.obs), terrains)
        dist = jnp.where(state.failed > 0, 0.0, state.distance)
        final = jnp.where(ended, final, dist)
        length = jnp.where(ended, length, state.steps)
        ended = ended | (state.done > 0)
        return t + 1, state, ended, final, length

    _, _, _, final, length = jax.lax.while_loop(cond, body, (jnp.int32(0), state, ended, final, length))
    return final, length


class _Pool(NamedTuple):
    """Loop carry of :func:`_pooled_distances` (S slots, J jobs)."""

    state: Any  # WalkerState with leading [S]
    terrain: jax.Array  # [S, H, W] metres, the terrain of each slot's job
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


def _pooled_distances(env, act, terrains, keys, attempts: int, slots: int, refill_every: int, queue, queued):
    """:func:`batched_distances` with ``slots`` env slots fed from a queue of ``J = B * attempts`` jobs.

    ``keys`` [J] (job ``j`` is attempt ``j % attempts`` on terrain ``j // attempts``); ``queue`` [J] / ``queued``
    from :func:`job_queue`: jobs ``queue[:queued]`` are started in that order, the others never. An outer ``while_loop``
    (until no slot is active and no job waits) runs ``refill_every`` env steps (a ``fori_loop``; a slot's result is
    written when its episode ends) and then refills the ended slots (a ``cond``, skipped when nothing changes).
    """
    jobs = keys.shape[0]
    reset = jax.vmap(env.reset)
    step = jax.vmap(env.step)
    act = jax.vmap(act)

    def start(job):  # [S] job ids (J = none) -> (state, terrain) of their first step
        j = jnp.minimum(job, jobs - 1)
        terrain = terrains[j // attempts]
        return reset(keys[j], terrain), terrain

    def run_steps(p: _Pool) -> _Pool:
        def one(_, p: _Pool) -> _Pool:
            state = step(p.state, act(p.state.obs), p.terrain)
            ended = p.active & (state.done > 0)
            where = jnp.where(ended, p.job, jobs)  # out of range -> dropped
            distance = p.distance.at[where].set(jnp.where(state.failed > 0, 0.0, state.distance), mode="drop")
            length = p.length.at[where].set(state.steps, mode="drop")
            return p._replace(state=state, active=p.active & ~ended, distance=distance, length=length)

        return jax.lax.fori_loop(0, refill_every, one, p)

    def refill(p: _Pool) -> _Pool:
        free = ~p.active
        position = p.next_job + jnp.cumsum(free, dtype=jnp.int32) - 1
        take = free & (position < queued)
        new_job = jnp.where(take, queue[jnp.minimum(position, jobs - 1)], jobs)
        state, terrain = start(new_job)
        pick = lambda new, old: jnp.where(take.reshape((-1,) + (1,) * (new.ndim - 1)), new, old)  # noqa: E731
        return p._replace(state=jax.tree.map(pick, state, p.state), terrain=pick(terrain, p.terrain),
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


# ----------------------------------------------------------------------------------------------------------------
# Host-level entry points
# ----------------------------------------------------------------------------------------------------------------
def validate_heightmaps(heightmaps, name: str = "heightmaps") -> jax.Array:
    """``[B, H, W]`` float array, finite, values in [0, 1], H, W >= 4 -> float32 jax array; else ``ValueError``."""
    shape = getattr(heightmaps, "shape", None)
    if shape is None:
        raise ValueError(f"{name} must be an array [B, H, W], got {type(heightmaps).__name__}")
    if len(shape) != 3 or shape[0] < 1 or shape[1] < 4 or shape[2] < 4:
        raise ValueError(f"{name} must have shape [B, H, W] with B >= 1 and H, W >= 4, got {tuple(shape)}")
    h = jnp.asarray(heightmaps, jnp.float32)
    finite, lo, hi = (v.item() for v in jax.device_get((jnp.all(jnp.isfinite(h)), jnp.min(h), jnp.max(h))))
    if not finite:
        raise ValueError(f"{name} contains NaN or inf")
    if lo < 0.0 or hi > 1.0:
        raise ValueError(f"{name} values must lie in [0, 1] (heightmap units), got min {lo:.4g}, max {hi:.4g}")
    return h


@functools.lru_cache(maxsize=16)
def make_env(config: WalkerConfig) -> WalkerEnv:
    """A cached :class:`WalkerEnv` per config (building one compiles the MuJoCo model)."""
    return WalkerEnv(config)


@functools.lru_cache(maxsize=1)
def default_policy() -> Callable:
    """The shipped base policy (``jaxterrain.rl.load_policy()``), loaded once."""
    try:
        from jaxterrain.rl import load_policy
    except ImportError as err:  # pragma: no cover
        raise RuntimeError("policy=None needs jaxterrain.rl.load_policy (the shipped base policy); "
                           "pass policy= explicitly") from err
    try:
        return load_policy()
    except FileNotFoundError as err:
        raise RuntimeError(f"policy=None needs the shipped base policy, which is missing ({err}); "
                           "pass policy= explicitly") from err


def _compiled(config: WalkerConfig, attempts: int, policy: Callable, with_params: bool, slots: Optional[int] = None,
              smooth_first: bool = True):
    """The jitted ``(terrains_m, key, params) -> (distances, lengths)``, cached per normalised arguments."""
    smooth_first = bool(smooth_first) and slots is not None
    return _compiled_cached(config, attempts, policy, with_params, slots, smooth_first)


@functools.lru_cache(maxsize=32)
def _compiled_cached(config, attempts, policy, with_params, slots, smooth_first):
    env = make_env(config)

    def run(terrains_m, key, params):
        priority = smoothness_priority(terrains_m) if smooth_first else None
        return batched_distances(env, policy, terrains_m, key, attempts, params if with_params else None, slots,
                                 priority=priority)

    return jax.jit(run)


def policy_solver(policy: Callable) -> Optional[SolverOptions]:
    """The solver options a policy was trained with, when it records them (``policy.meta["walker_config"]
    ["solver"]``, as :func:`jaxterrain.rl.load_policy` policies do), else None. A policy walks as trained only
    under the same contact solver (benchmarks/RESULTS.md), so the default env of :func:`evaluate` uses them."""
    solver = ((getattr(policy, "meta", None) or {}).get("walker_config") or {}).get("solver")
    return None if solver is None else SolverOptions(**solver)


def default_env_config(shape: tuple[int, int], scale: TerrainScale, policy: Callable) -> WalkerConfig:
    """``WalkerConfig(terrain_shape=shape, scale=scale)`` with the policy's own solver options when it records them."""
    solver = policy_solver(policy)
    config = WalkerConfig(terrain_shape=tuple(shape), scale=scale)
    return config if solver is None else config._replace(solver=solver)


def _resolve(heightmaps, attempts: int, policy, scale, env_config):
    if not isinstance(attempts, int) or attempts < 1:
        raise ValueError(f"attempts must be an int >= 1, got {attempts!r}")
    h = validate_heightmaps(heightmaps)
    shape = tuple(h.shape[1:])
    if policy is None:
        policy = default_policy()
    if not callable(policy):
        raise ValueError(f"policy must be callable (obs) -> action, got {type(policy).__name__}")
    if env_config is None:
        scale = validate_scale(TerrainScale() if scale is None else scale)
        env_config = default_env_config(shape, scale, policy)
    else:
        if tuple(env_config.terrain_shape) != shape:
            raise ValueError(f"heightmaps are {shape} but env_config.terrain_shape is "
                             f"{tuple(env_config.terrain_shape)}")
        if scale is not None and tuple(scale) != tuple(env_config.scale):
            raise ValueError(f"scale {scale} differs from env_config.scale {env_config.scale}; pass one of them")
    obs_size = getattr(policy, "observation_size", None)
    env = make_env(env_config)
    if obs_size is not None and int(obs_size) != env.observation_size:
        raise ValueError(f"policy expects observations of size {obs_size}, the env gives {env.observation_size} "
                         f"(height_scan={env_config.height_scan})")
    terrains_m = h * jnp.float32(env_config.scale.height)
    return terrains_m, env_config, policy


def rollout_distances(heightmaps, key: jax.Array, attempts: int = 20, policy: Optional[Callable] = None,
                      scale: Optional[TerrainScale] = None, env_config: Optional[WalkerConfig] = None,
                      policy_params: Any = None, chunk: Optional[int] = None,
                      slots: Optional[int] = None, smooth_first: bool = True) -> jax.Array:
    """Normalised distances ``[B, attempts]`` float32 in [0, 1] of the policy on ``heightmaps`` [B, H, W] in [0, 1].

    Heightmaps become metres by ``scale`` (default :class:`~jaxterrain.terrain.TerrainScale`); the env is
    ``env_config`` (default ``WalkerConfig(terrain_shape=(H, W), scale=scale)``). All ``B x attempts`` rollouts are
    one jit-compiled batched call (cached per config / attempts / policy); ``chunk`` (terrains per call) splits
    very large batches to bound device memory; ``slots`` (env slots fed from a queue of the rollouts, see
    :func:`batched_distances`) saves the slot-steps that ended rollouts would idle, and with ``smooth_first`` the
    pool starts the rollouts of the smoothest terrains first (:func:`smoothness_priority`; speed only). Failed
    rollouts (invalid physics, NaN action) count 0.
    """
    for name, value in (("chunk", chunk), ("slots", slots)):  # cheap checks before the env is built
        if value is not None and (not isinstance(value, int) or value < 1):
            raise ValueError(f"{name} must be an int >= 1 or None, got {value!r}")
    terrains_m, env_config, policy = _resolve(heightmaps, attempts, policy, scale, env_config)
    fn = _compiled(env_config, attempts, policy, policy_params is not None, slots, smooth_first)
    b = terrains_m.shape[0]
    if chunk is None or chunk >= b:
        return fn(terrains_m, key, policy_params)[0]
    keys = jax.random.split(key, -(-b // chunk))
    del key
    outs = []
    for i, k in enumerate(keys):
        part = terrains_m[i * chunk:(i + 1) * chunk]
        n = part.shape[0]
        if n < chunk:  # pad to the compiled shape
            part = jnp.concatenate([part, jnp.repeat(part[-1:], chunk - n, axis=0)])
        outs.append(fn(part, k, policy_params)[0][:n])
    return jnp.concatenate(outs)


def evaluate(heightmaps, key: jax.Array, attempts: int = 20, best: int = 5, policy: Optional[Callable] = None,
             scale: Optional[TerrainScale] = None, env_config: Optional[WalkerConfig] = None,
             policy_params: Any = None, chunk: Optional[int] = None, slots: Optional[int] = None,
             smooth_first: bool = True) -> jax.Array:
    """Fitness ``[B]`` float32 in [0, 1] of ``heightmaps`` [B, H, W] (values in [0, 1]): the mean of the ``best``
    largest of ``attempts`` normalised distances (see :func:`rollout_distances`). Difficulty = 1 - fitness."""
    if not isinstance(best, int) or not 1 <= best <= (attempts if isinstance(attempts, int) else best):
        raise ValueError(f"best must be an int in [1, attempts={attempts}], got {best!r}")
    d = rollout_distances(heightmaps, key, attempts, policy, scale, env_config, policy_params, chunk, slots,
                          smooth_first)
    return best_of(d, best)
