"""The difficulty protocol walked by MuJoCo's C engine instead of MJX (sim2sim): the same terrains, starts, policy
and protocol as :func:`jaxterrain.difficulty.evaluate`, another simulator.

    fitness = replay.mujoco_evaluate(heightmaps, key, policy=pol, protocol=PAPER, workers=16)   # [B]
    d, n = replay.mujoco_distances(heightmaps, key, policy=pol, protocol=PAPER)                 # [B, attempts] each

Everything but the physics is MJX's evaluation, piece for piece:

- the env: ``default_env_config(shape, scale, policy)`` (the policy's robot and contact solver) plus the protocol's
  ``start_spread``, on the classic layout (``tiles = 0``); its ``mj_model`` is the model both engines step;
- the walks: the maps turned by :func:`~jaxterrain.difficulty.rotate_headings`, walk ``a`` of turned map ``i``
  reset from ``jax.random.split(key, (B * headings, per_heading))[i, a]``: the keys MJX's
  :func:`~jaxterrain.walker.rollout.batched_distances` uses (without ``chunk`` / ``mesh``), so walk for walk the two
  engines start from the same pose (``env.reset``, run on the CPU here);
- the fitness: :func:`~jaxterrain.difficulty.aggregate` of the ``[B, attempts]`` heading-major distances.

The physics is :class:`jaxterrain.walker.mujoco_c.CEngine`'s. ``workers > 1`` runs the turned maps as jobs on a pool of
that many processes (``spawn``; each runs JAX on the CPU alone, one thread, whatever the parent's platform), each
job one turned map's ``per_heading`` walks in lockstep. The policy reaches them as its weights (a policy loaded by
``rl.load_policy``) or pickled (any other callable ``obs [..., O] -> action [..., A]``: a JAX function, an ONNX
session wrapper; jit-compiled in each job, since each job unpickles its own copy); ``workers=1`` walks in this
process. The result does not depend on ``workers``.
"""

from __future__ import annotations

import contextlib
import functools
import multiprocessing
import os
import time
from typing import Callable, NamedTuple, Optional

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain.difficulty.evaluation import validate_heightmaps
from jaxterrain.difficulty.policies import default_env_config, default_policy
from jaxterrain.difficulty.protocol import Protocol, aggregate, protocol_env_config, protocol_from, rotate_headings
from jaxterrain.rl.checkpoint import policy_fn
from jaxterrain.terrain import TerrainScale, validate_scale
from jaxterrain.walker import WalkerConfig, WalkerEnv
from jaxterrain.walker.mujoco_c import CEngine, cpu_device

__all__ = ["ENGINES", "MujocoWalks", "mujoco_env_config", "mujoco_distances", "mujoco_evaluate", "make_pool",
           "submit_mujoco", "Pending", "worker_env"]

ENGINES = ("mjx", "mujoco")
"""Physics engines of an evaluation: ``"mjx"`` (MJX, on the accelerator: backend ``jax`` or ``warp``) and
``"mujoco"`` (MuJoCo's C engine on the CPU cores, this module)."""

_ONE_THREAD = "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"


def worker_env() -> dict:
    """The environment variables a pool worker starts with: JAX on the CPU alone, one thread (appended to this
    process's ``XLA_FLAGS``, whose other flags the workers keep), no GPU visible (MuJoCo Warp, where installed,
    then takes no device memory in them either)."""
    flags = os.environ.get("XLA_FLAGS", "")
    flags = flags if _ONE_THREAD in flags else f"{flags} {_ONE_THREAD}".strip()
    return {"JAX_PLATFORMS": "cpu", "XLA_FLAGS": flags, "OMP_NUM_THREADS": "1", "CUDA_VISIBLE_DEVICES": ""}


class MujocoWalks(NamedTuple):
    """``distances`` [B, attempts] float32 (heading-major, 0 where failed), ``steps`` [B, attempts] int32 env
    steps walked, ``failed`` [B, attempts] bool, ``seconds`` the processes' time spent on them in all (each job
    timed where it ran), and of them the steps and seconds of the jobs that ran compiled (not the first job of
    a process for its walker config and network, which compiles the jitted pieces): ``compiled_steps /
    compiled_seconds`` is the C engine's env steps per second per core."""

    distances: np.ndarray
    steps: np.ndarray
    failed: np.ndarray
    seconds: float
    compiled_steps: int = 0
    compiled_seconds: float = 0.0


def mujoco_env_config(shape, scale: Optional[TerrainScale], policy: Callable, protocol: Protocol,
                      env_config: Optional[WalkerConfig] = None) -> WalkerConfig:
    """The env the C engine walks: ``env_config`` or ``default_env_config(shape, scale, policy)``, plus the
    protocol's ``start_spread``. ``ValueError`` for a tiled or MuJoCo Warp config (the C engine walks one terrain per
    model) or a shape that is not the heightmaps'."""
    if env_config is None:
        env_config = default_env_config(tuple(shape), validate_scale(TerrainScale() if scale is None else scale),
                                        policy)
    else:
        if not isinstance(env_config, WalkerConfig):
            raise ValueError(f"env_config must be a walker.WalkerConfig, got {type(env_config).__name__}")
        if env_config.backend != "jax" or env_config.tiles:
            raise ValueError(f"engine 'mujoco' walks the classic layout: env_config must have backend='jax' and "
                             f"tiles=0 (got backend={env_config.backend!r}, tiles={env_config.tiles})")
        if tuple(env_config.terrain_shape) != tuple(shape):
            raise ValueError(f"heightmaps are {tuple(shape)} but env_config.terrain_shape is "
                             f"{tuple(env_config.terrain_shape)}")
    return protocol_env_config(env_config, protocol)


def _payload(policy: Callable):
    """What a worker needs to rebuild ``policy``: its weights (``rl.load_policy`` policies) or itself."""
    if all(hasattr(policy, a) for a in ("config", "action_size", "params", "normaliser")):
        weights = jax.device_get((policy.params, policy.normaliser))
        return ("weights", policy.config, int(policy.action_size), weights)
    return ("callable", policy)


_RAN: set = set()  # (config, network, walks) of the jobs this process has run: their programs are compiled


@functools.lru_cache(maxsize=8)
def _engine(config: WalkerConfig) -> CEngine:
    return CEngine(WalkerEnv(config))


@functools.lru_cache(maxsize=8)
def _jit_weights_policy(config, action_size: int):
    return jax.jit(policy_fn(config, action_size))


def _actor(payload) -> Callable:
    """``act(obs [R, O]) -> actions [R, A]`` (numpy) on the CPU device from a :func:`_payload`."""
    cpu = cpu_device()
    if payload[0] == "weights":
        _, config, action_size, weights = payload
        fn = _jit_weights_policy(config, action_size)
        weights = jax.device_put(weights, cpu)
        return lambda obs: np.asarray(fn(weights, jax.device_put(obs, cpu)))
    fn = jax.jit(payload[1])
    return lambda obs: np.asarray(fn(jax.device_put(obs, cpu)))


def _job(args) -> tuple:
    """One turned map's walks: ``(config, payload, terrain_m [H, W], key_data [per, ...])`` -> ``(distance, steps,
    failed)`` [per] each, the seconds they took here and whether they ran compiled (not this process's first job
    of their kind)."""
    t0 = time.perf_counter()
    config, payload, terrain, key_data = args
    program = (config, payload[1:3] if payload[0] == "weights" else id(payload[1]), key_data.shape[0])
    compiled = program in _RAN
    _RAN.add(program)
    engine = _engine(config)
    act = _actor(payload)
    keys = jax.random.wrap_key_data(jax.device_put(key_data, cpu_device()))
    per = key_data.shape[0]
    terrains = np.broadcast_to(terrain, (per,) + terrain.shape)
    with jax.default_device(cpu_device()):
        start = engine.starts(keys, terrains)
    walks = engine.walk(act, terrain[None], start, terrain_of=np.zeros(per, np.int64))
    return walks.distance, walks.steps, walks.failed, time.perf_counter() - t0, compiled


@contextlib.contextmanager
def _environment(values: dict):
    """``os.environ`` with ``values`` set inside the block (the pool's workers inherit it at start)."""
    old = {k: os.environ.get(k) for k in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


class Pending(NamedTuple):
    """Walks submitted to a pool (:func:`submit_mujoco`): ``get()`` waits for them -> :class:`MujocoWalks`;
    ``ready()`` says whether they have all ended."""

    results: list
    shape: tuple

    def ready(self) -> bool:
        return all(r.ready() for r in self.results)

    def get(self) -> MujocoWalks:
        out = [r.get() if hasattr(r, "get") else r for r in self.results]
        d, n, f = (np.stack([o[k] for o in out]).reshape(self.shape) for k in range(3))
        warm = [o for o in out if o[4]]
        return MujocoWalks(d.astype(np.float32), n.astype(np.int32), f.astype(bool), float(sum(o[3] for o in out)),
                           int(sum(o[1].sum() for o in warm)), float(sum(o[3] for o in warm)))


def _jobs(heightmaps, key, policy, protocol, scale, env_config) -> tuple[list, tuple]:
    """The pool jobs of :func:`mujoco_distances` (one per turned map) and the ``[B, attempts]`` result shape."""
    protocol = protocol_from(protocol, None, None)
    h = validate_heightmaps(heightmaps)
    if protocol.headings > 1 and h.shape[1] != h.shape[2]:
        raise ValueError(f"protocol.headings={protocol.headings} needs square heightmaps, got {tuple(h.shape[1:])}")
    policy = default_policy() if policy is None else policy
    if not callable(policy):
        raise ValueError(f"policy must be callable (obs) -> action, got {type(policy).__name__}")
    config = mujoco_env_config(tuple(h.shape[1:]), scale, policy, protocol, env_config)
    b, heads, per = h.shape[0], protocol.headings, protocol.per_heading
    turned = np.asarray(rotate_headings(h * jnp.float32(config.scale.height), heads))  # [B * headings, H, W]
    keys = np.asarray(jax.device_get(jax.random.key_data(jax.random.split(key, (b * heads, per)))))
    payload = _payload(policy)
    return [(config, payload, turned[i], keys[i]) for i in range(b * heads)], (b, protocol.attempts)


def submit_mujoco(pool, heightmaps, key: jax.Array, policy: Optional[Callable] = None,
                  protocol: Optional[Protocol] = None, scale: Optional[TerrainScale] = None,
                  env_config: Optional[WalkerConfig] = None) -> Pending:
    """:func:`mujoco_distances`'s jobs queued on ``pool`` (:func:`make_pool`) without waiting: the caller does
    other work (MJX on the accelerator) meanwhile and collects them with ``.get()``. Checks as
    :func:`mujoco_distances` (``ValueError`` before anything is queued)."""
    jobs, shape = _jobs(heightmaps, key, policy, protocol, scale, env_config)
    return Pending([pool.apply_async(_job, (j,)) for j in jobs], shape)


def mujoco_distances(heightmaps, key: jax.Array, policy: Optional[Callable] = None,
                     protocol: Optional[Protocol] = None, scale: Optional[TerrainScale] = None,
                     env_config: Optional[WalkerConfig] = None, workers: int = 1, pool=None) -> MujocoWalks:
    """The protocol's walks of ``policy`` (default the shipped base policy) on ``heightmaps`` [B, H, W] in [0, 1]
    under MuJoCo's C engine: :class:`MujocoWalks`, heading-major like
    :func:`~jaxterrain.difficulty.rollout_distances` (``protocol`` default: the paper's). ``workers``: processes
    (module docstring); ``pool``: a pool of :func:`make_pool` to reuse instead (``workers`` is then ignored)."""
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be an int >= 1, got {workers!r}")
    jobs, shape = _jobs(heightmaps, key, policy, protocol, scale, env_config)
    if pool is not None:
        return Pending([pool.apply_async(_job, (j,)) for j in jobs], shape).get()
    if workers == 1:
        return Pending([_job(j) for j in jobs], shape).get()
    with make_pool(min(workers, len(jobs))) as p:
        return Pending([p.apply_async(_job, (j,)) for j in jobs], shape).get()


def make_pool(workers: int):
    """A ``spawn`` process pool of ``workers`` processes for :func:`mujoco_distances` (``pool=``), each JAX on the
    CPU alone with one thread (:func:`worker_env`). Close it when done (it is a context manager)."""
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be an int >= 1, got {workers!r}")
    with _environment(worker_env()):  # spawned children copy the environment when they start, here
        return multiprocessing.get_context("spawn").Pool(workers)


def mujoco_evaluate(heightmaps, key: jax.Array, policy: Optional[Callable] = None,
                    protocol: Optional[Protocol] = None, scale: Optional[TerrainScale] = None,
                    env_config: Optional[WalkerConfig] = None, workers: int = 1, pool=None) -> np.ndarray:
    """Fitness ``[B]`` float32 of ``heightmaps`` [B, H, W] in [0, 1] under MuJoCo's C engine:
    :func:`~jaxterrain.difficulty.aggregate` of :func:`mujoco_distances` (the MJX counterpart is
    :func:`~jaxterrain.difficulty.evaluate`, walk for walk from the same starts)."""
    protocol = protocol_from(protocol, None, None)
    walks = mujoco_distances(heightmaps, key, policy, protocol, scale, env_config, workers, pool)
    return np.asarray(aggregate(walks.distances, protocol), np.float32)

