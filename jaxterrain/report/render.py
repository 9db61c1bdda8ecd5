"""Videos of the walker: an MJX rollout records the states, MuJoCo's own offscreen renderer replays them.

    from jaxterrain.report import render
    render.setup_gl()                                   # before mujoco is imported: osmesa on CPU, egl on GPU
    ok, why = render.gl_status()                        # (False, reason) when no GL backend works
    walks = render.record_walks(maps, jax.random.key(0), steps=400)   # maps [B, H, W] in [0, 1]
    frames = render.render_walk(walks[0], width=320, height=240, frames=60)   # [F, h, w, 3] uint8
    gif = render.gif_bytes(frames, fps=render.fps_of(walks[0], len(frames)))
    mp4 = render.mp4_bytes(frames, fps=render.fps_of(walks[0], len(frames)))   # needs jaxterrain[video]

Stage 1, :func:`record_walks`: the walker (:class:`jaxterrain.walker.WalkerEnv`, the env
:func:`jaxterrain.difficulty.evaluate` walks, with the policy's own solver options) steps the policy (default: the
shipped base policy) on every terrain at once (``vmap`` over terrains, ``lax.scan`` over ``steps`` env steps, one
compile per terrain shape / batch / steps, cached), and records ``qpos`` after every env step and the step at which
the episode ended (fall, far edge, or time limit).

Stage 2, :func:`render_walk`: a MuJoCo model of the same walker (:func:`jaxterrain.walker.build_spec` with the env's
shape, scale, solver and time step, plus a light from the side and a checker material on the terrain so that its
relief shows) gets the terrain written into ``hfield_data`` (:func:`jaxterrain.walker.metres_to_hfield`, as the
physics sees it), and ``mujoco.Renderer`` draws the recorded ``qpos`` (``mj_kinematics``) from a camera that follows
the torso from the side and a little behind.

OpenGL backend (``MUJOCO_GL``): MuJoCo chooses it when ``mujoco`` is first imported; :func:`setup_gl` sets it
before that (``osmesa`` on a machine without an NVIDIA device, ``egl`` with one, each only if its library loads:
``MUJOCO_GL=osmesa`` without libOSMesa breaks ``import mujoco`` itself; a value already set is kept), and
:func:`render_walk` passes the chosen backend's context class to ``mujoco.Renderer`` explicitly, so it works even
when mujoco was imported earlier under another setting. OSMesa is the Debian package ``libosmesa6``
(``apt-get install libosmesa6``); it cannot be installed with pip. Without a working backend :func:`gl_status`
returns ``(False, reason)``, and :func:`make_videos` returns that reason instead of videos.

Encoders (:mod:`jaxterrain.report.encode`, their names importable from here too): :func:`gif_bytes` (Pillow) and
:func:`mp4_bytes` (H.264 through imageio-ffmpeg: the optional extra ``pip install 'jaxterrain[video]'``).
"""

from __future__ import annotations

import contextlib
import functools
import os
import sys
from typing import Any, Callable, NamedTuple, Optional

import numpy as np

from jaxterrain import difficulty
from jaxterrain.report.encode import MP4_EXTRA, gif_bytes, mp4_bytes, mp4_encoder
from jaxterrain.rl import policy_fn
from jaxterrain.terrain import TerrainScale, validate_scale
from jaxterrain.walker.layout import make_env, sized_env, terrain_batch
from jaxterrain.walker.model import FLOOR_GEOM, build_spec, metres_to_hfield

__all__ = ["Walk", "Video", "make_videos", "setup_gl", "gl_backend", "gl_status", "backend_available",
           "record_walks", "render_model", "render_walk", "gif_bytes", "mp4_bytes", "mp4_encoder", "MP4_EXTRA",
           "fps_of"]

_BACKENDS = ("egl", "osmesa", "glfw")


def _has_nvidia() -> bool:
    return os.path.exists("/dev/nvidia0") or os.path.exists("/dev/nvidiactl")


def _loadable(*names: str) -> Optional[str]:
    """The first of the shared libraries ``names`` (as ``ctypes.util.find_library`` spells them, e.g. "OSMesa")
    that loads, or None."""
    import ctypes
    import ctypes.util

    for name in names:
        for candidate in filter(None, (ctypes.util.find_library(name), f"lib{name}.so")):
            try:
                ctypes.CDLL(candidate)
            except OSError:
                continue
            return candidate
    return None


_LIBRARIES = {"osmesa": (("OSMesa",),), "egl": (("EGL",), ("OpenGL", "GL"))}
_NO_LIBRARY = ("no OpenGL library for MuJoCo's offscreen renderer: neither OSMesa (the Debian / Ubuntu package "
               "libosmesa6: apt-get install libosmesa6) nor EGL (libegl1, with the GPU driver's EGL library on a GPU "
               "machine) could be loaded")
_no_backend_reason = ""


def backend_available(backend: str) -> bool:
    """True when the shared libraries that MuJoCo's ``backend`` ("osmesa" or "egl") needs can be loaded."""
    return all(_loadable(*names) for names in _LIBRARIES.get(backend, ()))


def setup_gl(backend: Optional[str] = None) -> str:
    """Choose MuJoCo's OpenGL backend and return its name: ``backend`` if given, else ``$MUJOCO_GL`` if set, else
    on Linux the first whose libraries load of ``egl`` then ``osmesa`` with an NVIDIA device, ``osmesa`` then
    ``egl`` without one; "" when none loads (then :func:`gl_status` says why) and on macOS / Windows (MuJoCo's own
    default is right there).

    Sets ``MUJOCO_GL`` (and ``PYOPENGL_PLATFORM`` when unset) so that a later ``import mujoco`` picks it: call it
    before mujoco is imported (it is harmless after). It never sets a backend whose library is missing: with
    ``MUJOCO_GL=osmesa`` and no libOSMesa, ``import mujoco`` itself fails.
    """
    global _no_backend_reason
    if backend is None:
        backend = os.environ.get("MUJOCO_GL", "").strip().lower()
    if backend in _LIBRARIES and not backend_available(backend):  # set, but would break `import mujoco`
        os.environ.pop("MUJOCO_GL", None)
        _no_backend_reason = _reason(OSError(f"MUJOCO_GL={backend} was set, but its library cannot be loaded"),
                                     backend)
        return ""
    if not backend and sys.platform.startswith("linux"):
        order = ("egl", "osmesa") if _has_nvidia() else ("osmesa", "egl")
        backend = next((b for b in order if backend_available(b)), "")
        _no_backend_reason = "" if backend else _NO_LIBRARY
    if backend:
        os.environ["MUJOCO_GL"] = backend
        if backend in ("egl", "osmesa") and "OpenGL" not in sys.modules:
            os.environ.setdefault("PYOPENGL_PLATFORM", backend)
    return backend


def gl_backend() -> str:
    """The backend :func:`render_walk` uses (``$MUJOCO_GL`` after :func:`setup_gl`)."""
    return setup_gl()


def _context_class(backend: str):
    """The GLContext class of ``backend`` (imports ``mujoco.<backend>``); raises ImportError / OSError."""
    import importlib

    if backend in ("", "glfw", "enable", "enabled", "on", "true", "1"):
        backend = "glfw"
    if backend not in _BACKENDS:
        raise ImportError(f"unknown MUJOCO_GL backend {backend!r} (use egl, osmesa or glfw)")
    if backend in ("egl", "osmesa"):
        platform = os.environ.get("PYOPENGL_PLATFORM")
        if "OpenGL" in sys.modules and platform and platform != backend:
            raise ImportError(f"PyOpenGL was already loaded for PYOPENGL_PLATFORM={platform!r}; a {backend} "
                              f"context needs a fresh process with MUJOCO_GL={backend}")
        os.environ.setdefault("PYOPENGL_PLATFORM", backend)
    return importlib.import_module(f"mujoco.{backend}").GLContext


@contextlib.contextmanager
def _backend_context():
    """Make ``mujoco.Renderer`` create a context of the chosen backend, whatever mujoco chose at import."""
    from mujoco.rendering.classic import gl_context

    cls = _context_class(gl_backend())
    saved = getattr(gl_context, "GLContext", None)
    gl_context.GLContext = cls
    try:
        yield
    finally:
        gl_context.GLContext = saved


def _reason(err: BaseException, backend: Optional[str] = None) -> str:
    text = f"{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}".strip()
    backend = os.environ.get("MUJOCO_GL", "") if backend is None else backend
    hint = ""
    if backend == "osmesa":
        hint = " (OSMesa is the Debian package libosmesa6: apt-get install libosmesa6)"
    elif backend == "egl":
        hint = " (EGL needs libegl1 and the GPU driver's EGL vendor library)"
    return f"no OpenGL backend for MuJoCo's renderer (MUJOCO_GL={backend or 'unset'}): {text}{hint}"


@functools.lru_cache(maxsize=None)
def _probe(backend: str) -> tuple[bool, str]:
    if not backend and sys.platform.startswith("linux"):
        return False, _no_backend_reason or _NO_LIBRARY
    if backend in _LIBRARIES and not backend_available(backend):
        return False, _reason(OSError(f"the {backend} library cannot be loaded"), backend)
    import mujoco

    try:
        model = mujoco.MjModel.from_xml_string("<mujoco><worldbody><geom size='1 1 0.1' type='plane'/>"
                                               "</worldbody></mujoco>")
        with _backend_context():
            renderer = mujoco.Renderer(model, 16, 16)
        try:
            renderer.update_scene(mujoco.MjData(model))
            renderer.render()
        finally:
            renderer.close()
    except Exception as err:  # noqa: BLE001 - any failure means: no renders, say why
        return False, _reason(err)
    return True, f"MuJoCo's renderer through {backend or 'its default backend'}"


def gl_status() -> tuple[bool, str]:
    """``(True, backend text)`` when ``mujoco.Renderer`` can draw offscreen here, else ``(False, reason)``
    (tried once per backend and cached)."""
    return _probe(gl_backend())


# ----------------------------------------------------------------------------------------------------------------
# Stage 1: record a rollout
# ----------------------------------------------------------------------------------------------------------------
class Walk(NamedTuple):
    """One recorded walk.

    Attributes:
      terrain: [H, W] float32 metres (what the physics saw).
      qpos: [T + 1, nq] float32, the state at reset and after each of the ``T`` recorded env steps.
      length: env steps until the episode ended (fall, far edge or time limit), <= T.
      distance: normalised distance at the end, in [0, 1].
      fell: True when it ended by a fall (or invalid physics), False at the goal / time limit / end of recording.
      env_config: the :class:`jaxterrain.walker.WalkerConfig` it walked under.
      dt: seconds per env step.
    """

    terrain: np.ndarray
    qpos: np.ndarray
    length: int
    distance: float
    fell: bool
    env_config: Any
    dt: float


@functools.lru_cache(maxsize=8)
def _compiled_walk(env_config, steps: int, policy: Callable, with_params: bool):
    import jax
    import jax.numpy as jnp

    env = make_env(env_config)

    def walks(keys, terrains, params):  # a tiled env (jaxterrain.walker.rollout) walks terrain b on tile b
        e = sized_env(env, terrains.shape[0], terrains.shape[0])
        world, axes = terrain_batch(e, terrains)

        def one(key, terrain):
            state = e.reset(key, terrain)
            ox, oy = e.tile_origin(terrain.index) if e.tiles else (0.0, 0.0)

            def body(carry, _):
                state, ended, length, dist, fell = carry
                action = policy(params, state.obs) if with_params else policy(state.obs)
                nxt = e.step(state, action, terrain)
                done = nxt.done > 0
                dist = jnp.where(ended, dist, jnp.where(nxt.failed > 0, 0.0, nxt.distance))
                fell = jnp.where(ended, fell, done & (nxt.truncation <= 0))
                length = jnp.where(ended, length, nxt.steps)
                ended = ended | done
                if e.tiles:  # freeze after the end (env.select keeps MuJoCo Warp's shared buffers shared)
                    nxt = e.select(ended & ~done, state, nxt)
                else:
                    nxt = jax.tree.map(lambda a, b: jnp.where(ended & ~done, a, b), state, nxt)
                return (nxt, ended, length, dist, fell), nxt.data.qpos

            carry = (state, jnp.bool_(False), jnp.int32(0), jnp.float32(0.0), jnp.bool_(False))
            (_, _, length, dist, fell), qpos = jax.lax.scan(body, carry, None, length=steps)
            qpos = jnp.concatenate([state.data.qpos[None], qpos])
            if e.tiles:  # positions on the map, as the single-terrain render model draws them
                qpos = qpos.at[:, 0].add(-ox).at[:, 1].add(-oy)
            return qpos, length, dist, fell

        return jax.vmap(one, in_axes=(0, axes))(keys, world)

    return env, jax.jit(walks)


def _key_batch(key, b: int) -> bool:
    """Whether ``key`` is a batch of ``b`` PRNG keys: typed keys ``[b]``, or raw ``uint32`` keys ``[b, 2]`` (one raw
    key ``[2]`` is ONE key, also when ``b`` is 2)."""
    import jax

    shape, dtype = tuple(getattr(key, "shape", ())), getattr(key, "dtype", None)
    typed = dtype is not None and jax.dtypes.issubdtype(dtype, jax.dtypes.prng_key)
    return shape[:1] == (b,) and len(shape) == (1 if typed else 2)


def record_walks(heightmaps, key, steps: int = 1000, policy: Optional[Callable] = None, scale=None,
                 env_config=None) -> list[Walk]:
    """Walk the policy once on each of ``heightmaps`` [B, H, W] (values in [0, 1]) for up to ``steps`` env steps.

    ``policy`` (default: the shipped base policy) maps one observation to one action; ``scale`` (default
    ``TerrainScale()``) turns heights into metres; ``env_config`` defaults to the one
    :func:`jaxterrain.difficulty.evaluate` uses for this shape (the policy's own solver options); a tiled or MuJoCo
    Warp one (``difficulty.default_env_config(shape, backend="warp")``) walks terrain ``b`` on tile ``b`` and records
    ``qpos`` on the map (the tile's origin subtracted). One reset key per terrain: ``split(key, B)``, or ``key``
    itself when it is a batch of ``B`` keys (so two policies can start on a terrain from the same pose whatever
    else they walk). A policy loaded by :func:`jaxterrain.rl.load_policy` walks with its weights as data
    (:func:`jaxterrain.rl.policy_fn`): policies of one network config and walker config share one compiled program.
    Returns one :class:`Walk` per terrain.
    """
    import jax
    import jax.numpy as jnp

    maps = np.asarray(heightmaps, np.float32)
    if maps.ndim == 2:
        maps = maps[None]
    if maps.ndim != 3 or maps.shape[0] < 1:
        raise ValueError(f"heightmaps must be [B, H, W]; got shape {maps.shape}")
    if not isinstance(steps, int) or steps < 1:
        raise ValueError(f"steps must be an int >= 1; got {steps!r}")
    policy = difficulty.default_policy() if policy is None else policy
    if env_config is None:
        scale = validate_scale(TerrainScale() if scale is None else scale)
        env_config = difficulty.default_env_config(maps.shape[1:], scale, policy)
    steps = min(steps, int(env_config.episode_length))
    if env_config.backend == "warp" and not env_config.tiles:  # MuJoCo Warp walks on tiles, sized per call
        env_config = env_config._replace(tiles=1)
    if all(hasattr(policy, a) for a in ("params", "normaliser", "config", "action_size")):
        fn_policy, params, with_params = policy_fn(policy.config, int(policy.action_size)), \
            (policy.params, policy.normaliser), True
    else:
        fn_policy, params, with_params = policy, None, False
    env, fn = _compiled_walk(env_config, steps, fn_policy, with_params)
    terrains = maps * np.float32(env_config.scale.height)
    keys = key if _key_batch(key, maps.shape[0]) else jax.random.split(key, maps.shape[0])
    qpos, length, dist, fell = jax.device_get(fn(keys, jnp.asarray(terrains), params))
    out = []
    for i in range(maps.shape[0]):
        n = int(length[i]) if int(length[i]) > 0 else steps  # 0: still walking when the recording stopped
        out.append(Walk(terrain=terrains[i], qpos=np.asarray(qpos[i, :n + 1], np.float32), length=n,
                        distance=float(dist[i]), fell=bool(fell[i]), env_config=env_config, dt=float(env.dt)))
    return out


# ----------------------------------------------------------------------------------------------------------------
# Stage 2: render it
# ----------------------------------------------------------------------------------------------------------------
def render_model(env_config, terrain_m):
    """The walker's ``mujoco.MjModel`` for rendering: :func:`jaxterrain.walker.build_spec` of ``env_config`` (same
    bodies, joints and hfield as the physics), a checker material on the terrain, a low sun from the side, no fog,
    and ``terrain_m`` ([H, W] metres) in its hfield."""
    import mujoco


    c = env_config
    spec = build_spec(c.terrain_shape, c.scale, c.solver, c.timestep, getattr(c, "robot", "humanoid"))
    tex = spec.add_texture(name="terrain_checker", type=mujoco.mjtTexture.mjTEXTURE_2D,
                           builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER, width=64, height=64,
                           rgb1=[0.78, 0.72, 0.6], rgb2=[0.62, 0.56, 0.46])
    mat = spec.add_material(name="terrain_mat", texrepeat=[1.0, 1.0], texuniform=True, specular=0.1,
                            shininess=0.1, reflectance=0.0)
    mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = tex.name
    floor = spec.geom(FLOOR_GEOM)
    floor.material = mat.name
    floor.rgba = [1.0, 1.0, 1.0, 1.0]
    spec.worldbody.add_light(name="sun", type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL, pos=[0, 0, 5],
                             dir=[0.45, 0.6, -0.66],
                             diffuse=[0.55, 0.55, 0.55], specular=[0.05, 0.05, 0.05], castshadow=True)
    for t in spec.textures:  # a light sky instead of the XML's dark gradient
        if t.type == mujoco.mjtTexture.mjTEXTURE_SKYBOX:
            t.rgb1, t.rgb2 = [0.75, 0.85, 0.95], [0.45, 0.6, 0.8]
    spec.visual.headlight.ambient = [0.35, 0.35, 0.35]
    spec.visual.headlight.diffuse = [0.45, 0.45, 0.45]
    spec.visual.map.fogstart = 50.0
    spec.visual.map.fogend = 100.0
    spec.visual.quality.shadowsize = 2048
    model = spec.compile()
    elevation = float(model.hfield_size[0, 2])
    model.hfield_data[:] = np.asarray(metres_to_hfield(np.asarray(terrain_m, np.float32), elevation))
    return model


def _camera(model, distance: float, azimuth: float, elevation: float):
    import mujoco

    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_TRACKING
    cam.trackbodyid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "torso")
    cam.distance, cam.azimuth, cam.elevation = distance, azimuth, elevation
    return cam


def frame_indices(length: int, frames: int) -> np.ndarray:
    """Which of the ``length + 1`` recorded states to draw: ``frames`` (at most ``length + 1``) evenly spaced,
    first and last included."""
    n = max(1, min(int(frames), length + 1))
    return np.unique(np.round(np.linspace(0, length, n)).astype(int))


def fps_of(walk: Walk, n_frames: int) -> float:
    """Frames per second that play ``walk`` in real time with ``n_frames`` frames."""
    seconds = max(walk.length, 1) * walk.dt
    return max(n_frames - 1, 1) / seconds


def render_walk(walk: Walk, width: int = 320, height: int = 240, frames: int = 60, distance: float = 3.5,
                azimuth: float = 120.0, elevation: float = -18.0, shadows: bool = False,
                at=None) -> np.ndarray:
    """``[F, height, width, 3]`` uint8 frames of ``walk`` (``F <= frames``, evenly spaced over the walk) drawn by
    ``mujoco.Renderer`` from a camera tracking the torso (``distance`` m, ``azimuth`` / ``elevation`` degrees; the
    default looks from the walker's left and a little behind). ``shadows`` costs about 4x the time under OSMesa
    (0.6 s instead of 0.14 s a frame on a 256 x 256 terrain). ``at``: the recorded states to draw instead ([F] ints,
    env steps from 0; a step past the walk's end draws its last state, so walks of different lengths stay in step
    frame by frame). Raises on a GL failure (check :func:`gl_status` first)."""
    import mujoco

    model = render_model(walk.env_config, walk.terrain)
    model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), int(width))
    model.vis.global_.offheight = max(int(model.vis.global_.offheight), int(height))
    data = mujoco.MjData(model)
    cam = _camera(model, distance, azimuth, elevation)
    with _backend_context():
        renderer = mujoco.Renderer(model, int(height), int(width))
    try:
        out = []
        steps = frame_indices(walk.length, frames) if at is None else np.minimum(np.asarray(at, int), walk.length)
        for i in steps:
            data.qpos[:] = walk.qpos[i]
            mujoco.mj_kinematics(model, data)
            mujoco.mj_comPos(model, data)  # subtree centres of mass: the tracking camera's target
            renderer.update_scene(data, camera=cam)
            renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = int(shadows)
            renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
            out.append(renderer.render().copy())
    finally:
        renderer.close()
    return np.stack(out)


# ----------------------------------------------------------------------------------------------------------------
# Both stages for a report
# ----------------------------------------------------------------------------------------------------------------
class Video(NamedTuple):
    """One video of a report: ``gif`` (bytes of an animated GIF) or None with ``reason`` saying why not.
    ``label`` (e.g. "easy"), ``caption`` (what the terrain is), ``outcome`` (how the walk went)."""

    label: str
    caption: str
    gif: Optional[bytes]
    reason: str = ""
    outcome: str = ""


def _outcome(walk: Walk) -> str:
    end = "fell" if walk.fell else ("reached the far edge" if walk.distance >= 0.999 else "still walking")
    return (f"walked {walk.distance:.2f} of the track in {walk.length * walk.dt:.1f} s "
            f"({walk.length} steps), then {end}")


def make_videos(terrains: list[tuple[str, str, np.ndarray]], key=None, steps: int = 1000, frames: int = 60,
                width: int = 320, height: int = 240, policy: Optional[Callable] = None, scale=None,
                progress: Callable[[str], None] = lambda s: None) -> list[Video]:
    """Walk and render each ``(label, caption, heightmap [H, W] in [0, 1])``; never raises.

    Checks :func:`gl_status` first (no rollout without a renderer), walks all terrains of one shape in one
    :func:`record_walks` call (one compile per shape), renders each walk with :func:`render_walk` and encodes it
    with :func:`gif_bytes` at real-time speed. Any failure (no GL backend, no shipped policy, a terrain too small
    for the walker's margins, ...) gives that video ``gif=None`` and the reason.
    """
    import time

    if not terrains:
        return []
    ok, why = gl_status()
    if not ok:
        return [Video(label, caption, None, f"renders skipped: {why}") for label, caption, _ in terrains]
    import jax

    key = jax.random.key(0) if key is None else key
    walks: dict[int, Any] = {}
    by_shape: dict[tuple, list[int]] = {}
    for i, (_, _, hm) in enumerate(terrains):
        by_shape.setdefault(tuple(np.shape(hm)), []).append(i)
    for shape, idx in by_shape.items():
        t0 = time.perf_counter()
        try:
            got = record_walks(np.stack([terrains[i][2] for i in idx]), jax.random.fold_in(key, len(walks)),
                               steps=steps, policy=policy, scale=scale)
        except Exception as err:  # noqa: BLE001 - the report goes on without these videos
            for i in idx:
                walks[i] = f"walk not recorded: {type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}"
            continue
        walks.update(zip(idx, got))
        progress(f"recorded {len(idx)} walk(s) on {shape[0]} x {shape[1]} terrains in "
                 f"{time.perf_counter() - t0:.1f} s (MJX, compile included)")
    out = []
    for i, (label, caption, _) in enumerate(terrains):
        walk = walks[i]
        if isinstance(walk, str):
            out.append(Video(label, caption, None, walk))
            continue
        t0 = time.perf_counter()
        try:
            clip = render_walk(walk, width=width, height=height, frames=frames)
            gif = gif_bytes(clip, fps_of(walk, len(clip)))
        except Exception as err:  # noqa: BLE001
            out.append(Video(label, caption, None, _reason(err), _outcome(walk)))
            continue
        progress(f"rendered {label}: {len(clip)} frames in {time.perf_counter() - t0:.1f} s")
        out.append(Video(label, caption, gif, "", _outcome(walk)))
    return out
