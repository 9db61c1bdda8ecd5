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
(:func:`~jaxterrain.difficulty.policies.default_env_config`).

:func:`evaluate` and :func:`rollout_distances` are host-level entry points: they validate on the host and call a
cached jit-compiled function. Inside your own jit (e.g. a QDax scoring function) use the pure
:func:`batched_distances` / :func:`best_of`.

With ``slots=S`` the rollouts are jobs queued on ``S`` env slots that refill as episodes end, instead of all at once
(:func:`batched_distances`); the queue starts the smoothest terrains first (:func:`smoothness_priority`,
:func:`job_queue`), which shortens the tail in which the last long rollouts run on an otherwise idle pool.

Physics backend: the env config's ``backend`` (MJX-JAX by default; ``"warp"``: MuJoCo Warp, whose envs walk on the
tiles of one heightfield, sized to each call). The rollout loops live in :mod:`jaxterrain.walker.rollout`::

    cfg = difficulty.default_env_config((256, 256), backend="warp")
    fitness = difficulty.evaluate(heightmaps, key, env_config=cfg)
    fit_fn = difficulty.fitness_fn(256, slots=16384, backend="warp")

The protocol (how many walks, which of them count, in which directions, from where) is one typed config,
:class:`Protocol`; ``Protocol()`` is the paper's (20 attempts along +x from the centre of the start edge, mean of the
best 5), and every entry point takes ``protocol=`` (it and the pure :func:`aggregate` / :func:`best_of` are defined
in :mod:`jaxterrain.difficulty.protocol`)::

    fitness = difficulty.evaluate(heightmaps, key, protocol=difficulty.HEADINGS)   # 4 headings, see Protocol
    fit_fn = difficulty.fitness_fn(256, difficulty.HEADINGS, slots=16384)         # pure, for archive.evolve

Several devices: ``evaluate(..., mesh=sharding.make_mesh())`` splits the terrains over the mesh's devices (padded
to a multiple of the device count; the padding is never walked) and walks each terrain with its own key,
``split(key, B)[b]`` (:func:`keyed_distances`), so the fitness does not depend on the number of devices (up to
float rounding: XLA compiles another program per local batch). ``fitness_fn(...).keyed`` is the same per-row-key
form for the sharded MAP-Elites scoring (:mod:`jaxterrain.qd.scoring`), with one rollout pool of ``slots`` per device.
"""

from __future__ import annotations

import functools
from typing import Any, Callable, Optional

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain.difficulty.protocol import (  # the protocol and its pure aggregation, re-exported (they lived here)
    PAPER,
    Protocol,
    protocol_from,
    aggregate,
    protocol_env_config,
    rotate_headings,
)
from jaxterrain.walker.layout import is_tiled, make_env
from jaxterrain.walker.rollout import batched_distances, job_queue, pooled_distances, smoothness_priority
from jaxterrain.terrain import TerrainScale, validate_scale
from jaxterrain.walker import BACKENDS, SPAWNS, WalkerConfig, WalkerEnv
from jaxterrain.difficulty.policies import check_observation, default_env_config, default_policy, robot_base_policy
from jaxterrain.runtime import sharding

__all__ = ["evaluate", "rollout_distances", "timed_distances", "fitness_fn", "protocol_distances", "keyed_distances",
           "validate_heightmaps"]


# ----------------------------------------------------------------------------------------------------------------
# Pure functions (jit / vmap them yourself)
# ----------------------------------------------------------------------------------------------------------------
def protocol_distances(env: WalkerEnv, policy: Callable, terrains: jax.Array, key: jax.Array, protocol: Protocol,
                       policy_params: Any = None, slots: Optional[int] = None, refill_every: int = 8,
                       needed: Optional[jax.Array] = None,
                       priority: Optional[jax.Array] = None) -> tuple[jax.Array, jax.Array]:
    """:func:`batched_distances` under a :class:`Protocol`: ``(distances, steps)``, each ``[B, attempts]``,
    heading-major (attempt ``a`` walks heading ``a // protocol.per_heading``; feed them to :func:`aggregate`).

    ``terrains`` [B, H, W] metres. One heading is exactly ``batched_distances(..., protocol.attempts, ...)``. With
    more, the ``B * headings`` turned maps (:func:`rotate_headings`) are walked ``per_heading`` times each in the
    same batched call (one rollout pool with ``slots``); ``needed`` / ``priority`` [B] apply to every heading of a
    terrain. ``env.config.start_spread`` must equal ``protocol.start_spread`` (:func:`protocol_env_config`).
    """
    if float(env.config.start_spread) != float(protocol.start_spread):
        raise ValueError(f"env.config.start_spread={env.config.start_spread} but protocol.start_spread="
                         f"{protocol.start_spread}: build the env from protocol_env_config(config, protocol)")
    if protocol.headings == 1:
        return batched_distances(env, policy, terrains, key, protocol.attempts, policy_params, slots, refill_every,
                                 needed, priority)
    b, h = terrains.shape[0], protocol.headings
    rep = lambda v: None if v is None else jnp.repeat(jnp.asarray(v).reshape(b), h)  # noqa: E731
    d, n = batched_distances(env, policy, rotate_headings(terrains, h), key, protocol.per_heading, policy_params,
                             slots, refill_every, rep(needed), rep(priority))
    return d.reshape(b, protocol.attempts), n.reshape(b, protocol.attempts)


def keyed_distances(env: WalkerEnv, policy: Callable, terrains: jax.Array, keys: jax.Array, protocol: Protocol,
                    policy_params: Any = None, slots: Optional[int] = None, refill_every: int = 8,
                    needed: Optional[jax.Array] = None,
                    priority: Optional[jax.Array] = None) -> tuple[jax.Array, jax.Array]:
    """:func:`protocol_distances` with ONE KEY PER TERRAIN: ``(distances, steps)``, each ``[B, attempts]``,
    heading-major.

    ``keys`` [B] (typed, or raw [B, 2]): terrain ``b``'s walks reset from ``split(keys[b], protocol.attempts)``, so
    they do not depend on which other terrains share the call - the same walks whether a batch runs on one device
    or is split over many (draw ``keys`` for the whole batch first: ``sharding.row_keys``). Every walk is a job of
    one rollout pool (:func:`batched_distances` with ``slots``; ``slots=None``: one slot per walk, all at once):
    ``needed`` [B] bool terrains are walked, the others never (distance and length 0); ``priority`` [B] orders the
    queue (speed only). ``env.config.start_spread`` must equal ``protocol.start_spread``.
    """
    if float(env.config.start_spread) != float(protocol.start_spread):
        raise ValueError(f"env.config.start_spread={env.config.start_spread} but protocol.start_spread="
                         f"{protocol.start_spread}: build the env from protocol_env_config(config, protocol)")
    if not refill_every >= 1:
        raise ValueError(f"refill_every must be >= 1, got {refill_every}")
    b, attempts = terrains.shape[0], protocol.attempts
    jobs = b * attempts
    job_keys = jax.vmap(lambda k: jax.random.split(k, attempts))(keys)  # [B, attempts]: job b * attempts + a
    job_keys = job_keys.reshape((jobs,) + job_keys.shape[2:])
    per_job = lambda v: jnp.repeat(jnp.asarray(v).reshape(b), attempts)  # noqa: E731
    needed = jnp.ones(b, bool) if needed is None else jnp.asarray(needed, bool)
    queue, queued = job_queue(per_job(needed), None if priority is None else per_job(priority))
    act = (lambda obs: policy(obs)) if policy_params is None else (lambda obs: policy(policy_params, obs))
    # job j walks turned map j // per_heading (terrain b, heading a // per_heading): rotate_headings' row order
    d, n = pooled_distances(env, act, rotate_headings(terrains, protocol.headings), job_keys, protocol.per_heading,
                             jobs if slots is None else min(int(slots), jobs), int(refill_every), queue, queued)
    return d.reshape(b, attempts), n.reshape(b, attempts)


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
    dtype = getattr(heightmaps, "dtype", None)
    if dtype is None or np.dtype(dtype).kind not in "biuf":
        raise ValueError(f"{name} must be a real-valued (float) array [B, H, W], got dtype {dtype}")
    h = jnp.asarray(heightmaps, jnp.float32)
    finite, lo, hi = (v.item() for v in jax.device_get((jnp.all(jnp.isfinite(h)), jnp.min(h), jnp.max(h))))
    if not finite:
        raise ValueError(f"{name} contains NaN or inf")
    if lo < 0.0 or hi > 1.0:
        raise ValueError(f"{name} values must lie in [0, 1] (heightmap units), got min {lo:.4g}, max {hi:.4g}")
    return h


def _compiled(config: WalkerConfig, attempts: int, policy: Callable, with_params: bool, slots: Optional[int] = None,
              smooth_first: bool = True):
    """The jitted ``(terrains_m, key, params) -> (distances, lengths)`` of ``attempts`` walks along +x (the paper's
    heading), cached per normalised arguments; ``policy(obs)`` or, with ``with_params``, ``policy(params, obs)``."""
    return _program(config, attempts, 1, policy, with_params, slots, smooth_first)


def _program(config: WalkerConfig, attempts: int, headings: int, apply: Callable, with_params: bool,
             slots: Optional[int], smooth_first: bool):
    """The jitted ``(terrains_m [B, H, W], key, params) -> (distances, lengths)`` [B, attempts], heading-major.

    Cached by what determines the program: the env config, the rollout counts, the policy (for a loaded policy its
    network config and weights, :func:`_policy_program`, never the object), the pool. ``best`` and
    ``rule`` are applied outside (:func:`aggregate`), so they share one program."""
    return _program_cached(config, int(attempts), int(headings), apply, bool(with_params),
                           None if slots is None else int(slots), bool(smooth_first) and slots is not None)


@functools.lru_cache(maxsize=32)
def _program_cached(config, attempts, headings, apply, with_params, slots, smooth_first):
    env = make_env(config)
    protocol = Protocol(attempts=attempts, best=1, headings=headings, start_spread=config.start_spread)

    def run(terrains_m, key, params):
        priority = smoothness_priority(terrains_m) if smooth_first else None
        return protocol_distances(env, apply, terrains_m, key, protocol, params if with_params else None, slots,
                                  priority=priority)

    return jax.jit(run)


_CONST_POLICIES: dict = {}


def _policy_digest(policy) -> tuple:
    """What determines a loaded policy's program: its network config, action size and a digest of its weights."""
    import hashlib

    h = hashlib.sha256()
    for leaf in jax.tree.leaves((policy.params, policy.normaliser)):
        a = jax.device_get(leaf)
        h.update(f"{getattr(a, 'shape', ())}{getattr(a, 'dtype', type(a))}".encode())
        h.update(memoryview(np.ascontiguousarray(a)).cast("B"))
    return policy.config, int(policy.action_size), h.hexdigest()


def _policy_program(policy: Callable, policy_params: Any) -> tuple[Callable, Any, bool]:
    """``(apply, params, with_params)`` for the compiled program.

    A policy loaded by :func:`jaxterrain.rl.load_policy` (it carries ``config``, ``action_size``, ``params``,
    ``normaliser``) is keyed by :func:`_policy_digest`, not by the object: loading the same weights again reuses the
    compiled program (its weights stay compile-time constants, as they always were, so fitness is the same number
    for the same key). A ``policy(params, obs)`` with ``policy_params`` takes its weights as data; a bare
    ``policy(obs)`` callable is its own program."""
    if policy_params is not None:
        return policy, policy_params, True
    if all(hasattr(policy, a) for a in ("config", "action_size", "params", "normaliser")):
        key = _policy_digest(policy)
        if key not in _CONST_POLICIES:
            if len(_CONST_POLICIES) >= 8:
                _CONST_POLICIES.pop(next(iter(_CONST_POLICIES)))
            _CONST_POLICIES[key] = policy
        return _CONST_POLICIES[key], None, False
    return policy, None, False


@functools.lru_cache(maxsize=16)
def _keyed_program(config: WalkerConfig, attempts: int, headings: int, apply: Callable, with_params: bool,
                   slots: Optional[int], smooth_first: bool, mesh, split: Optional[str] = None):
    """``(terrains_m [B, H, W], keys [B], params) -> distances [B, attempts]`` of :func:`keyed_distances`, the rows
    split over ``mesh`` (``sharding.map_rows``: padded, the padding never walked); cached like :func:`_program`."""

    env = make_env(config)
    protocol = Protocol(attempts=attempts, best=1, headings=headings, start_spread=config.start_spread)

    def rows(terrains_m, keys, params, mask):
        priority = smoothness_priority(terrains_m) if smooth_first else None
        return keyed_distances(env, apply, terrains_m, keys, protocol, params if with_params else None, slots,
                               needed=mask, priority=priority)[0]

    return sharding.map_rows(rows, mesh, replicated=(2,), mask=True, split=split)


def _keyed_rollouts(terrains_m, key, env_config, protocol, apply, params, with_params, chunk, slots, smooth_first,
                    mesh, split=None) -> jax.Array:
    """:func:`rollout_distances` over a mesh: per-row keys ``split(key, B)``, ``chunk`` rows per call."""

    fn = _keyed_program(env_config, protocol.attempts, protocol.headings, apply, bool(with_params),
                        None if slots is None else int(slots), bool(smooth_first) and slots is not None, mesh, split)
    b = terrains_m.shape[0]
    keys = sharding.row_keys(key, b)
    params = params if with_params else jnp.zeros((), jnp.float32)
    step = b if chunk is None else min(chunk, b)
    outs = []
    for i in range(0, b, step):
        n = min(step, b - i)
        part = sharding.pad_rows((terrains_m[i:i + n], keys[i:i + n]), step)  # one compiled shape
        outs.append(fn(part[0], part[1], params)[:n])
    return jnp.concatenate(outs)


def _resolve(heightmaps, protocol: Protocol, policy, scale, env_config):
    h = validate_heightmaps(heightmaps)
    shape = tuple(h.shape[1:])
    if protocol.headings > 1 and shape[0] != shape[1]:
        raise ValueError(f"protocol.headings={protocol.headings} needs square heightmaps, got {shape}")
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
    env_config = protocol_env_config(env_config, protocol)
    if is_tiled(env_config) and not env_config.tiles:  # WalkerConfig(backend="warp"): tiles, sized per call
        env_config = env_config._replace(tiles=1)
    check_observation(policy, env_config)
    obs_size = getattr(policy, "observation_size", None)
    env = make_env(env_config)
    if obs_size is not None and int(obs_size) != env.observation_size:
        raise ValueError(f"policy expects observations of size {obs_size}, the env gives {env.observation_size} "
                         f"(observation {env_config.observation})")
    terrains_m = h * jnp.float32(env_config.scale.height)
    return terrains_m, env_config, policy


def _check_attempts(attempts) -> None:
    """``attempts`` given without a protocol: None or an int >= 1, else ``ValueError``."""
    if attempts is not None and (not isinstance(attempts, int) or attempts < 1):
        raise ValueError(f"attempts must be an int >= 1, got {attempts!r}")


def rollout_distances(heightmaps, key: jax.Array, attempts: Optional[int] = None, policy: Optional[Callable] = None,
                      scale: Optional[TerrainScale] = None, env_config: Optional[WalkerConfig] = None,
                      policy_params: Any = None, chunk: Optional[int] = None,
                      slots: Optional[int] = None, smooth_first: bool = True,
                      protocol: Optional[Protocol] = None, mesh=None, split: Optional[str] = None,
                      with_steps: bool = False) -> jax.Array:
    """Normalised distances ``[B, attempts]`` float32 in [0, 1] of the policy on ``heightmaps`` [B, H, W] in [0, 1]
    (with ``with_steps``: ``(distances, steps [B, attempts] int32)``, the env steps each walk lasted; not with
    ``mesh``).

    ``attempts`` (default 20) walks along +x, or the walks of ``protocol`` (:class:`Protocol`; its ``attempts``,
    heading-major: attempt ``a`` on heading ``a // protocol.per_heading``; ``attempts`` must then be None or equal).
    Heightmaps become metres by ``scale`` (default :class:`~jaxterrain.terrain.TerrainScale`); the env is
    ``env_config`` (default ``WalkerConfig(terrain_shape=(H, W), scale=scale)`` with the policy's solver) plus the
    protocol's ``start_spread``; its ``backend`` / ``tiles`` choose the physics and the terrain layout
    (``default_env_config(shape, backend="warp")``: MuJoCo Warp on tiles; :mod:`jaxterrain.walker.rollout`). All
    ``B x attempts`` rollouts are one jit-compiled batched call (cached per env
    config / rollout counts / policy function, :func:`_program`); ``chunk`` (terrains per call) splits very large
    batches to bound device memory; ``slots`` (env slots fed from a queue of the rollouts, see
    :func:`batched_distances`) saves the slot-steps that ended rollouts would idle, and with ``smooth_first`` the
    pool starts the rollouts of the smoothest terrains first (:func:`smoothness_priority`; speed only). Failed
    rollouts (invalid physics, NaN action) count 0. ``mesh`` (a ``jax.sharding.Mesh``): the terrains split over its
    devices, each walked with its own key ``split(key, B)[b]`` (:func:`keyed_distances`; ``slots`` per device;
    a batch that does not divide is padded, the padding never walked), so the result does not depend on the number
    of devices, nor on ``chunk``; without a mesh the batch's one key is split as before. ``split``: how the rows go
    over the mesh (``sharding.map_rows``; None: ``sharding.default_split``, GPUs dispatch one program per device).
    """
    for name, value in (("chunk", chunk), ("slots", slots)):  # cheap checks before the env is built
        if value is not None and (not isinstance(value, int) or value < 1):
            raise ValueError(f"{name} must be an int >= 1 or None, got {value!r}")
    if protocol is None:
        _check_attempts(attempts)
        protocol = Protocol(20 if attempts is None else attempts, 1)
    protocol = protocol_from(protocol, attempts, None)
    if with_steps and mesh is not None:
        raise ValueError("with_steps=True is not available with a mesh (the sharded walks return distances only)")
    terrains_m, env_config, policy = _resolve(heightmaps, protocol, policy, scale, env_config)
    apply, params, with_params = _policy_program(policy, policy_params)
    if mesh is not None:
        return _keyed_rollouts(terrains_m, key, env_config, protocol, apply, params, with_params, chunk, slots,
                               smooth_first, mesh, split)
    fn = _program(env_config, protocol.attempts, protocol.headings, apply, with_params, slots, smooth_first)
    b = terrains_m.shape[0]
    if chunk is None or chunk >= b:
        out = fn(terrains_m, key, params)
        return out if with_steps else out[0]
    keys = jax.random.split(key, -(-b // chunk))
    del key
    outs = []
    for i, k in enumerate(keys):
        part = terrains_m[i * chunk:(i + 1) * chunk]
        n = part.shape[0]
        if n < chunk:  # pad to the compiled shape
            part = jnp.concatenate([part, jnp.repeat(part[-1:], chunk - n, axis=0)])
        outs.append(tuple(o[:n] for o in fn(part, k, params)))
    d, steps = (jnp.concatenate([o[j] for o in outs]) for j in range(2))
    return (d, steps) if with_steps else d


def evaluate(heightmaps, key: jax.Array, attempts: Optional[int] = None, best: Optional[int] = None,
             policy: Optional[Callable] = None, scale: Optional[TerrainScale] = None,
             env_config: Optional[WalkerConfig] = None, policy_params: Any = None, chunk: Optional[int] = None,
             slots: Optional[int] = None, smooth_first: bool = True, protocol: Optional[Protocol] = None,
             mesh=None, split: Optional[str] = None) -> jax.Array:
    """Fitness ``[B]`` float32 in [0, 1] of ``heightmaps`` [B, H, W] (values in [0, 1]) under ``protocol``
    (default: the paper's, ``Protocol(attempts or 20, best or 5)``; with ``protocol`` given, ``attempts`` / ``best``
    must be None or equal to its fields): :func:`aggregate` of :func:`rollout_distances`. Difficulty = 1 - fitness.
    ``mesh`` / ``split``: the terrains split over its devices with per-row keys (:func:`rollout_distances`).
    """
    if protocol is None:
        _check_attempts(attempts)
        if best is not None and (not isinstance(best, int) or not 1 <= best <= (attempts or 20)):
            raise ValueError(f"best must be an int in [1, attempts={attempts or 20}], got {best!r}")
    protocol = protocol_from(protocol, attempts, best)
    d = rollout_distances(heightmaps, key, None, policy, scale, env_config, policy_params, chunk, slots,
                          smooth_first, protocol, mesh, split)
    return aggregate(d, protocol)


def fitness_fn(size: int, protocol: Protocol = PAPER, scale: Optional[TerrainScale] = None,
               slots: Optional[int] = None, smooth_first: bool = True, backend: str = "jax",
               robot: str = "humanoid", observation: str = "blind", spawn: str = "feet") -> Callable:
    """Terrain fitness as a pure function, for use inside jit / scan (e.g. ``qd.evolve(fitness_fn=...)``):
    ``fitness(heightmaps [B, size, size] in [0, 1], key, needed=None) -> [B]`` float32 in [0, 1].

    The shipped base policy walks under ``protocol`` (:func:`protocol_distances`, then :func:`aggregate`), in
    ``default_env_config((size, size), scale, policy)`` plus the protocol's ``start_spread``; ``slots``: env slots of
    a rollout pool (None = all at once); ``smooth_first``: the pool starts the smoothest terrains' rollouts first
    (speed only); ``needed`` [B] bool: terrains to walk (the others get 0 and, with ``slots``, are never walked).
    For ``Protocol()`` this is the paper's computation, the one ``difficulty.difficulty_fitness`` had. The env and
    policy are built here on the host, once per arguments (cached: the same arguments give the same function).
    ``backend``: ``"jax"`` (MJX-JAX, one heightfield per env, as always) or ``"warp"`` (MuJoCo Warp on a bank of
    tiles, :func:`default_env_config`; the same walks up to Warp's solver arithmetic, fitness within 0.03).

    The function's ``keyed`` attribute is its per-row-key form, ``(heightmaps [B, size, size], keys [B], needed=None)
    -> [B]`` (:func:`keyed_distances`: terrain ``b`` walks from ``keys[b]``, one pool of ``slots`` per call), which
    the sharded MAP-Elites scoring calls on each device's rows (``scoring.keyed_fitness``); its ``env`` attribute
    is the :class:`~jaxterrain.walker.WalkerEnv` it walks.

    ``robot``: whose shipped base policy walks (:func:`robot_base_policy`; the humanoid's by default);
    ``observation``: its blind (default, the paper's) or perceptive twin, in an env of its observation set;
    ``spawn``: how each walker is set down at a reset (``walker.SPAWNS``: ``feet``, the default, or ``patch``).
    """
    if not isinstance(size, int) or size < 4:
        raise ValueError(f"size must be an int >= 4 (heightmap side in pixels), got {size!r}")
    if slots is not None and (not isinstance(slots, int) or slots < 1):
        raise ValueError(f"slots must be an int >= 1 or None, got {slots!r}")
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    if spawn not in SPAWNS:
        raise ValueError(f"spawn must be one of {', '.join(SPAWNS)}, got {spawn!r}")
    protocol = protocol_from(protocol, None, None)
    scale = validate_scale(TerrainScale() if scale is None else scale)
    robot_base_policy(robot, observation)  # unknown, or without a shipped base policy: ValueError here
    return _fitness_fn_cached(size, protocol, scale, slots, bool(smooth_first) and slots is not None, backend, robot,
                              observation, spawn)


@functools.lru_cache(maxsize=16)
def _fitness_fn_cached(size: int, protocol: Protocol, scale: TerrainScale, slots, smooth_first: bool,
                       backend: str = "jax", robot: str = "humanoid", observation: str = "blind",
                       spawn: str = "feet") -> Callable:
    policy = robot_base_policy(robot, observation)
    config = default_env_config((size, size), scale, policy, backend)._replace(spawn=spawn)
    env = make_env(protocol_env_config(config, protocol))

    def walk(distances_fn, heightmaps, keys, needed):
        terrains = jnp.asarray(heightmaps, jnp.float32) * jnp.float32(scale.height)
        priority = smoothness_priority(terrains) if smooth_first else None
        distances, _ = distances_fn(env, policy, terrains, keys, protocol, slots=slots, needed=needed,
                                    priority=priority)
        return aggregate(distances, protocol)

    def fitness(heightmaps, key, needed=None):
        return walk(protocol_distances, heightmaps, key, needed)

    def keyed(heightmaps, keys, needed=None):
        return walk(keyed_distances, heightmaps, keys, needed)

    fitness.keyed, fitness.env = keyed, env
    return fitness


def timed_distances(heightmaps, protocol: Protocol, key: jax.Array, slots: Optional[int] = None,
                    chunk: Optional[int] = None) -> dict:
    """:func:`rollout_distances` of ``heightmaps`` [N, H, W] in [0, 1] under ``protocol`` with the shipped base
    policy, compiled ahead of time so that compiling and walking are timed apart (the same program; ``chunk``
    terrains per call, the last call padded). Returns ``{"distances", "lengths"}`` [N, attempts] (heading-major),
    ``"compile_s"`` and ``"walk_s"``."""
    import time

    terrains_m, env_config, policy = _resolve(heightmaps, protocol, None, None, None)
    apply, params, with_params = _policy_program(policy, None)
    fn = _program(env_config, protocol.attempts, protocol.headings, apply, with_params, slots, True)
    n = terrains_m.shape[0]
    size = n if chunk is None else min(int(chunk), n)
    parts = -(-n // size)
    keys = [key] if parts == 1 else list(jax.random.split(key, parts))
    pad = lambda t: jnp.concatenate([t, jnp.repeat(t[-1:], size - t.shape[0], axis=0)])  # noqa: E731
    t0 = time.perf_counter()
    compiled = fn.lower(terrains_m[:size], keys[0], params).compile()
    t1 = time.perf_counter()
    dist, length = [], []
    for i, k in enumerate(keys):
        part = terrains_m[i * size:(i + 1) * size]
        d, s = compiled(pad(part) if part.shape[0] < size else part, k, params)
        dist.append(np.asarray(d)[:part.shape[0]])
        length.append(np.asarray(s)[:part.shape[0]])
    t2 = time.perf_counter()
    return {"distances": np.concatenate(dist), "lengths": np.concatenate(length), "compile_s": t1 - t0,
            "walk_s": t2 - t1}
