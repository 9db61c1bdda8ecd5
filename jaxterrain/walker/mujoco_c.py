"""MuJoCo's C engine (the ``mujoco`` bindings, on the CPU) stepping a :class:`~jaxterrain.walker.WalkerEnv`'s walks:
sim2sim, the same walk under another simulator.

    engine = CEngine(env)                                     # env: a classic (tiles = 0) WalkerEnv
    start = engine.starts(keys [R], terrains_m [R, H, W])     # MJX's own reset: qpos, qvel, x_start per walk
    out = engine.walk(act, terrains_m, start)                 # act(obs [R, O]) -> actions [R, A]
    out.distance, out.steps, out.failed                       # [R] each

What is shared with MJX, so that the two engines differ only in their physics:

- the model: a copy of ``env.mj_model`` (the very MjModel the ``mjx.Model`` was put from: robot, solver options,
  timestep, contact parameters) with the terrain written into its heightfield by
  :func:`~jaxterrain.walker.model.metres_to_hfield`;
- the start: :meth:`CEngine.starts` runs ``env.reset`` (MJX's forward kinematics, the same keys) and the C engine
  starts from its ``qpos`` / ``qvel`` (``mj_forward`` fills the rest; the reset's MJX data also starts from zeros);
- the observation, the action -> ctrl mapping, the termination rules and the normalised distance: ``env.observe``,
  ``env.controls`` and ``env.outcome``, jit-compiled on the CPU and vmapped over the walks;
- one env step = ``config.n_frames`` calls of ``mj_step``. A step is invalid (``failed``, distance 0, the walk ends)
  when the state is non-finite, ``|qvel| > max_qvel``, the action is non-finite, or MuJoCo itself flagged bad
  accelerations (``mjWARN_BADQACC``, after which C MuJoCo resets the data on its own).

What differs is the engine: float64 physics, C MuJoCo's collision (a sphere against a heightfield is a convex
collision with the heightfield's triangular prisms, where MJX-JAX has its own heightfield routine; MuJoCo issue
#1730), C MuJoCo's constraint solver and line search. ``docs/results/sim2sim.md`` measures the difference.

The walks step in lockstep (one ``act`` call per env step on the stacked observations; the physics of the live walks
in a Python loop over their ``MjData``); walks that have ended stay where they ended. Parallel processes are the
caller's (:mod:`jaxterrain.difficulty.replay` runs jobs of these on a process pool).
"""

from __future__ import annotations

from typing import Callable, NamedTuple, Optional

import copy

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from jaxterrain.walker.env import WalkerEnv
from jaxterrain.walker.model import HFIELD_NAME, metres_to_hfield
from jaxterrain.walker.randomisation import is_active

__all__ = ["Starts", "Walks", "CEngine", "cpu_device"]


class Starts(NamedTuple):
    """The start of ``R`` walks (host arrays): ``qpos`` [R, nq] float64, ``qvel`` [R, nv] float64, ``x_start`` [R]
    float32 (the torso's x at reset, the origin of the normalised distance)."""

    qpos: np.ndarray
    qvel: np.ndarray
    x_start: np.ndarray


class Walks(NamedTuple):
    """The end of ``R`` walks (host arrays): ``distance`` [R] float32 normalised distance at the first ``done``
    (0 where failed), ``steps`` [R] int32 env steps walked, ``failed`` [R] bool (invalid physics / action), and
    ``trace`` [T, R, nq] float64: ``qpos`` after each of the first ``T`` env steps (``T = record``; after its end
    a walk's qpos stays where it ended)."""

    distance: np.ndarray
    steps: np.ndarray
    failed: np.ndarray
    trace: np.ndarray


def cpu_device():
    """The first CPU device: the C engine's jitted observation / termination pieces run there."""
    return jax.devices("cpu")[0]


class CEngine:
    """MuJoCo C steps of the walks of ``env`` (a classic ``WalkerEnv``: ``tiles = 0``, any backend name; its MjModel
    is the one MJX runs). See the module docstring."""

    def __init__(self, env: WalkerEnv):
        if not isinstance(env, WalkerEnv):
            raise ValueError(f"env must be a walker.WalkerEnv, got {type(env).__name__}")
        if env.tiles:
            raise ValueError(f"the MuJoCo C engine walks one terrain per model: build the env with tiles=0 "
                             f"(got config.tiles={env.tiles})")
        if is_active(env.config.randomisation):
            raise ValueError("the MuJoCo C engine walks the nominal physics: build the env without "
                             "config.randomisation (walker.Randomisation())")
        self.env = env
        self.config = env.config
        self._hfield = mujoco.mj_name2id(env.mj_model, mujoco.mjtObj.mjOBJ_HFIELD, HFIELD_NAME)
        self._cpu = cpu_device()
        vm = jax.vmap
        self._controls = jax.jit(vm(env.controls))
        self._observe = jax.jit(vm(env.observe))
        self._outcome = jax.jit(vm(env.outcome))
        self._reset = jax.jit(vm(env.reset))

    # ---- models and starts ------------------------------------------------------------------------------------
    def model(self, terrain_m) -> mujoco.MjModel:
        """A copy of ``env.mj_model`` whose heightfield is ``terrain_m`` ([H, W] metres, ``config.terrain_shape``;
        clipped to ``[0, scale.height]`` like MJX's)."""
        t = np.asarray(terrain_m, np.float32)
        if t.shape != tuple(self.config.terrain_shape):
            raise ValueError(f"terrain_m must have shape {tuple(self.config.terrain_shape)} (config.terrain_shape), "
                             f"got {t.shape}")
        m = copy.copy(self.env.mj_model)  # MjModel's copy is a full mj_copyModel
        adr = int(m.hfield_adr[self._hfield])
        m.hfield_data[adr:adr + t.size] = np.asarray(metres_to_hfield(t, self.env.elevation_z), np.float64)
        return m

    def starts(self, keys: jax.Array, terrains_m) -> Starts:
        """MJX's reset of ``R`` walks (``env.reset(keys[r], terrains_m[r])``, the same function and keys as the MJX
        rollouts), as host arrays. ``keys`` [R], ``terrains_m`` [R, H, W] metres."""
        state = self._reset(keys, jnp.asarray(terrains_m, jnp.float32))
        qpos, qvel, x0 = jax.device_get((state.data.qpos, state.data.qvel, state.x_start))
        return Starts(np.asarray(qpos, np.float64), np.asarray(qvel, np.float64), np.asarray(x0, np.float32))

    # ---- walking ----------------------------------------------------------------------------------------------
    def walk(self, act: Callable, terrains_m, start: Starts, terrain_of: Optional[np.ndarray] = None,
             record: int = 0) -> Walks:
        """Walk ``R`` walks to their ends (fall, goal, ``episode_length``, invalid physics) in lockstep.

        ``act(obs [R, O] float32) -> actions [R, A]`` (a batched policy: a jitted JAX function, an ONNX session's
        run, ...); ``terrains_m`` [T, H, W] metres and ``terrain_of`` [R] int (the terrain of each walk; default:
        ``T == R``, walk ``r`` on terrain ``r``); ``start`` from :meth:`starts` (or any ``qpos`` / ``qvel``);
        ``record``: keep the ``qpos`` of the first ``record`` env steps (:class:`Walks`.trace)."""
        c, env = self.config, self.env
        terrains = np.asarray(terrains_m, np.float32)
        if terrains.ndim != 3:
            raise ValueError(f"terrains_m must have shape [T, H, W]; got {terrains.shape}")
        r = start.qpos.shape[0]
        terrain_of = np.arange(r) if terrain_of is None else np.asarray(terrain_of, np.int64)
        if terrain_of.shape != (r,) or terrain_of.min(initial=0) < 0 or terrain_of.max(initial=0) >= len(terrains):
            raise ValueError(f"terrain_of must be [R] = ({r},) indices into the {len(terrains)} terrains")
        models = [self.model(t) for t in terrains]
        datas = []
        for i in range(r):
            m = models[terrain_of[i]]
            d = mujoco.MjData(m)
            d.qpos[:], d.qvel[:] = start.qpos[i], start.qvel[i]
            mujoco.mj_forward(m, d)
            datas.append(d)
        # the per-walk terrain arrays for the jitted pieces, on the CPU device once
        terr = jax.device_put(jnp.asarray(terrains[terrain_of]), self._cpu)
        x_start = jax.device_put(np.asarray(start.x_start, np.float32), self._cpu)
        qpos = np.stack([d.qpos.copy() for d in datas])
        qvel = np.stack([d.qvel.copy() for d in datas])
        obs = np.asarray(self._observe(_f32(qpos, self._cpu), _f32(qvel, self._cpu), terr))
        live = np.ones(r, bool)
        distance = np.zeros(r, np.float32)
        steps = np.zeros(r, np.int32)
        failed = np.zeros(r, bool)
        trace = np.zeros((max(int(record), 0), r, qpos.shape[1]))
        bad = int(mujoco.mjtWarning.mjWARN_BADQACC)
        for t in range(c.episode_length):
            if not live.any() and t >= record:
                break
            action = np.asarray(act(obs), np.float32)
            if action.shape != (r, env.action_size):
                raise ValueError(f"act must map obs [R, O] to actions [R, A] = ({r}, {env.action_size}); got "
                                 f"{action.shape}")
            ctrl, action_ok = (np.asarray(v) for v in self._controls(jax.device_put(action, self._cpu)))
            before = qpos.copy()
            invalid = np.zeros(r, bool)
            for i in np.flatnonzero(live):
                m, d = models[terrain_of[i]], datas[i]
                warned = d.warning[bad].number
                d.ctrl[:] = ctrl[i]
                mujoco.mj_step(m, d, nstep=c.n_frames)
                ok = (np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel))
                      and np.max(np.abs(d.qvel)) <= c.max_qvel and d.warning[bad].number == warned)
                if ok and action_ok[i]:
                    qpos[i], qvel[i] = d.qpos, d.qvel
                else:
                    invalid[i] = True  # the state stays the step's start (env.step keeps the previous state)
            done, _, dist, _, _ = self._outcome(_f32(before, self._cpu), _f32(qpos, self._cpu),
                                                jax.device_put(np.full(r, t + 1, np.int32), self._cpu), x_start,
                                                jax.device_put(invalid, self._cpu), terr)
            done, dist = np.asarray(done), np.asarray(dist)
            ended = live & done
            distance[ended] = np.where(invalid[ended], 0.0, dist[ended])
            failed[ended] = invalid[ended]
            steps[ended] = t + 1
            live &= ~done
            if t < record:
                trace[t] = qpos
            if live.any():
                obs = np.asarray(self._observe(_f32(qpos, self._cpu), _f32(qvel, self._cpu), terr))
        return Walks(distance, steps, failed, trace)


def _f32(x, device):
    return jax.device_put(np.asarray(x, np.float32), device)
