"""A pure-function MJX environment: a robot (default brax's humanoid; :mod:`.robots`) walking along +x over a
heightfield passed as DATA.

    env = WalkerEnv(WalkerConfig())                 # builds the MjModel / mjx.Model once (host)
    state = env.reset(key, terrain)                 # terrain: [H, W] float32 metres, H = y rows, W = x columns
    state = env.step(state, action, terrain)        # action: [A] in [-1, 1] (the humanoid's A = 17)

Both are pure and vmappable: ``jax.vmap(env.step, in_axes=(0, 0, None))`` shares one terrain,
``in_axes=(0, 0, 0)`` gives every environment its own terrain. The terrain enters the physics through
``mjx_model.replace(hfield_data=...)`` inside the function (see :func:`jaxterrain.walker.model.metres_to_hfield`):
nothing about the terrain is baked into a closure, so a curriculum can switch terrains inside one jit-compiled loop.

Backends and tiled terrains (``WalkerConfig.backend``, ``WalkerConfig.tiles``):

    env = WalkerEnv(WalkerConfig(tiles=T, backend="warp"))  # backend "jax" (default) or "warp" (MJX-Warp)
    bank = env.make_bank(terrains)                         # [T, H, W] metres -> TileBank, a device-resident pytree
    state = env.reset(key, bank.at(i))                     # terrain = Tile(bank, index i): env on tile i
    state = env.step(state, action, bank.at(i))
    jax.vmap(env.step, in_axes=(0, 0, TILE_AXES))(states, actions, bank.at(idx))   # idx [N]: a tile per env
    bank = env.set_tile(bank, i, terrain)                  # jit-able; env.bank_terrains(bank) -> [T, H, W]
    states = env.select(done, reset_states, states)        # batched auto-reset / pools, for both backends

- ``tiles = 0`` (default, ``backend="jax"`` only): the classic API above, one ``[H, W]`` array per env.
- ``tiles = T >= 1``: the model's heightfield holds ``T`` tiles of ``terrain_shape`` on a near-square grid
  (:mod:`jaxterrain.walker.tiles`); the terrain argument is a :class:`~jaxterrain.walker.tiles.Tile`. Every env is
  spawned on its tile: ``qpos[:2]`` are world coordinates, ``env.tile_origin(index)`` the tile centre to subtract
  (``state.x_start`` is world x too, so ``distance`` is unchanged); heights, the side and back limits and the goal
  are tile-local, and the observation has no x / y, so a walk on tile ``i`` is the walk on that terrain alone (up to
  float32 rounding of the shifted coordinates). No model field is batched: all envs share one ``mjx.Model``.
- ``backend = "warp"``: ``mjx.put_model(impl="warp")`` and ``make_data(impl="warp")`` (needs ``tiles >= 1`` and
  ``pip install 'jaxterrain[warp]'``; then ``python -m experiments warp-patch``, :mod:`jaxterrain.walker.warp_patch`:
  building such an env warns once per process while MJX's vendored heightfield collision is the stock kernel).
  MJX-Warp's ``Data`` carries contact buffers shared by all envs
  (``naconmax = warp_contacts * warp_worlds``; set ``warp_worlds`` >= the number of envs stepped together, over all
  vmap axes): merge states with ``env.select`` or ``mjx.Data.where``, never with ``jax.tree.map(jnp.where, ...)``
  over ``state.data``. A step whose contacts or constraints overflowed those buffers is invalid (``failed = 1``).
  ``jax.vmap`` of ``reset`` / ``step`` (nested too) works unchanged; MJX-Warp batches the physics itself. States a
  program carries row by row from one compiled call to the next (a curriculum block's trials) take the form of
  :func:`~jaxterrain.walker.layout.carry_rows` (the shared buffers empty on the row axis) and step again once
  merged into a reset state.

See :mod:`jaxterrain.walker.config` for the physical choices (scale, spawn, termination, reward, distance,
time step, randomisation, solver): every one is a :class:`~jaxterrain.walker.config.WalkerConfig` field.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import contextlib
import importlib.util
import io

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

# MJX prints "Failed to import warp" / "Failed to import mujoco_warp" when warp-lang is not installed, to every user,
# Warp or not: quiet where warp-lang is absent (asking for backend="warp" then says why: tiles.warp_available);
# where it is installed, MJX's own messages stay.
with contextlib.redirect_stdout(io.StringIO()) if importlib.util.find_spec("warp") is None else contextlib.nullcontext():
    from mujoco import mjx

from jaxterrain.terrain import hfield_size
from jaxterrain.walker import randomisation as _rnd
from jaxterrain.walker import tiles as _tiles
from jaxterrain.walker import warp_patch as _warp_patch
from jaxterrain.walker.warp_model import quiet_solver_caps
from jaxterrain.walker.model import build_model, metres_to_hfield
from jaxterrain.walker.robots import get as get_robot
from jaxterrain.walker.tiles import Tile, TileBank
from jaxterrain.walker.config import (BACKENDS, OBSERVATIONS, SCAN_FIELDS, WalkerConfig, check_config, flat_terrain,
                                     min_terrain_side, observation_fields, observation_label, resolve_config,
                                     scan_size, with_observation)
from jaxterrain.walker.surface import sample_heights, state_key, yaw

__all__ = ["PARK_HEIGHT", "WalkerState", "WalkerEnv"]

PARK_HEIGHT = 100.0  # m above the terrain's top where WalkerEnv.park puts walkers whose outcome is recorded
# MuJoCo Warp overflow bits (mujoco_warp OverflowType) that mean dropped contacts or constraints: the step is invalid.
_WARP_DROPPED = (1 << 0) | (1 << 1) | (1 << 2) | (1 << 3)  # NEFC, NJMAX_NNZ, BROADPHASE, NARROWPHASE


class WalkerState(NamedTuple):
    """One environment's state (add leading axes under vmap).

    data: mjx.Data (physics). obs [O] float32. reward, done, truncation, failed: [] float32 (done = 1 when the
    episode ended this step; truncation = 1 when it ended at the goal or the time limit; failed = 1 for invalid
    physics or a non-finite action). steps: [] int32 env steps since reset. x_start: [] float32 torso x at reset.
    distance: [] float32 normalised distance in [0, 1]. metrics: dict of [] float32 (forward_reward,
    reward_alive, reward_quadctrl, x_velocity, torso_height, distance). random: this env's physics randomisation
    (:class:`~jaxterrain.walker.randomisation.Draws`, drawn at reset), or None when ``config.randomisation`` is off
    (then the state has the leaves it always had: checkpoints of unrandomised runs read the same).
    """

    data: Any
    obs: jax.Array
    reward: jax.Array
    done: jax.Array
    truncation: jax.Array
    failed: jax.Array
    steps: jax.Array
    x_start: jax.Array
    distance: jax.Array
    metrics: dict
    random: Any = None


class WalkerEnv:
    """A robot (``config.robot``, default brax's humanoid) on a heightfield; ``reset``/``step`` are pure functions of
    (key/state, terrain).

    Attributes: ``config``, ``mj_model`` (MuJoCo C model, flat terrain), ``mjx_model``, ``dt`` (s per env step),
    ``radius_x/radius_y/elevation_z`` (hfield size), ``x_start``, ``x_goal``, ``track_length`` (m),
    ``observation_size``, ``action_size`` (the robot's actuators: humanoid 17, ant 8; actions in [-1, 1]), ``robot``
    (its :class:`~jaxterrain.walker.robots.RobotSpec`).
    Observation: [torso height above terrain (1), torso quaternion (4), J joint angles, 6 + J qvel] (humanoid: J = 17)
    (+ ``scan_points[0] * scan_points[1]`` terrain heights minus torso z, x-major, for
    ``config.observation == "perceptive"``: :meth:`WalkerEnv._obs`).
    """

    def __init__(self, config: WalkerConfig = WalkerConfig()):
        config = resolve_config(config)
        check_config(config)
        self.config = config
        self.robot = get_robot(config.robot)
        h, w = config.terrain_shape
        self.tiles = int(config.tiles)
        self.grid = _tiles.grid(max(self.tiles, 1))  # (rows, cols) of the tile grid
        hfield_shape = (self.grid[0] * h, self.grid[1] * w) if self.tiles else (h, w)
        self.mj_model = build_model(hfield_shape, config.scale, config.solver, config.timestep, self.robot)
        self.backend = config.backend
        _warp_patch.warn_if_stock(config.backend)  # once per process: MuJoCo Warp's stock heightfield collision
        if config.backend == "warp":
            try:
                self.mjx_model = quiet_solver_caps(mjx.put_model(self.mj_model, impl="warp"))
                self._data0 = mjx.make_data(self.mj_model, impl="warp", naconmax=config.warp_contacts
                                            * config.warp_worlds, njmax=config.warp_njmax)
            except Exception as err:  # noqa: BLE001 - say what is missing
                raise RuntimeError(f"backend='warp' needs warp-lang and mujoco-warp (pip install "
                                   f"'jaxterrain[warp]'): {type(err).__name__}: {err}") from err
        else:
            self.mjx_model = mjx.put_model(self.mj_model, impl="jax")
            self._data0 = None
        m = self.mj_model
        self.dt = config.timestep * config.n_frames
        # one tile's (= one terrain's) heightfield size; the model's own hfield is the whole grid when tiled
        self.radius_x, self.radius_y, self.elevation_z, self.base_z = (
            float(v) for v in hfield_size((h, w), config.scale, float(m.hfield_size[0, 3])))
        self.x_start = -self.radius_x + config.start_margin
        self.x_goal = self.radius_x - config.goal_margin
        self.track_length = self.x_goal - self.x_start
        if self.track_length <= 0.5:
            raise ValueError(f"terrain too small for the margins: track length {self.track_length:.2f} m "
                             f"(terrain_shape={config.terrain_shape}, scale={config.scale})")
        if self.radius_y - config.side_margin <= 0.2:
            raise ValueError(f"terrain too narrow for side_margin={config.side_margin}")
        max_spread = self.radius_y - config.side_margin - 0.5
        if config.start_spread > max(max_spread, 0.0):
            raise ValueError(f"start_spread must lie in [0, {max(max_spread, 0.0):.3g}] m (0.5 m inside the side limit "
                             f"radius_y - side_margin), got {config.start_spread}")
        self._qpos0 = np.asarray(m.qpos0, np.float32)
        if self.robot.start_joints is not None:  # the robot's start pose (hinge joints after the free root)
            if len(self.robot.start_joints) != m.nq - 7:
                raise ValueError(f"robot {self.robot.name!r}: start_joints has {len(self.robot.start_joints)} angles, "
                                 f"the model {m.nq - 7} hinge joints")
            self._qpos0[7:] = np.asarray(self.robot.start_joints, np.float32)
        self._jnt_lo = np.asarray(m.jnt_range[1:, 0], np.float32)  # hinge joints (joint 0 = free root)
        self._jnt_hi = np.asarray(m.jnt_range[1:, 1], np.float32)
        self._ctrl_lo = np.asarray(m.actuator_ctrlrange[:, 0], np.float32)
        self._ctrl_hi = np.asarray(m.actuator_ctrlrange[:, 1], np.float32)
        torso = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, self.robot.torso_body)
        if m.njnt < 1 or m.jnt_type[0] != mujoco.mjtJoint.mjJNT_FREE or m.jnt_bodyid[0] != torso:
            raise ValueError(f"robot {self.robot.name!r}: the torso body {self.robot.torso_body!r} must carry the "
                             f"model's first joint, a free joint (the walker reads its position from qpos[:7])")
        if m.njnt > 1 and np.any(m.jnt_type[1:] != mujoco.mjtJoint.mjJNT_HINGE):
            raise ValueError(f"robot {self.robot.name!r}: every joint after the free root must be a hinge")
        self._feet = np.array([mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, n) for n in self.robot.foot_geoms])
        self._foot_radius = np.asarray(m.geom_size[self._feet, 0], np.float32)
        self._random = _rnd.is_active(config.randomisation)  # off: no draws, no state leaves, the shared model
        self._torso, self._torso_mass = int(torso), float(m.body_mass[torso])
        added = config.randomisation.added_mass
        if added is not None and self._torso_mass + added[0] <= 0:
            raise ValueError(f"randomisation.added_mass must be (low, high) kg with low > -{self._torso_mass:.3g} (the "
                             f"{self.robot.name}'s torso mass), got {added}")
        self.action_size = int(m.nu)
        self.observation_size = 1 + 4 + (m.nq - 7) + m.nv + scan_size(config)
        px, py = np.meshgrid(np.linspace(-0.25, 0.25, 5), np.linspace(-0.25, 0.25, 5))  # the 0.5 m spawn patch
        self._patch = (np.float32(self.x_start) + px.ravel().astype(np.float32), py.ravel().astype(np.float32))
        ring = ([0, 1, -1, 0, 0], [0, 0, 0, 1, -1])  # spawn="feet": under a foot, its centre and +-radius in x, y
        self._foot_ring = tuple(self._foot_radius[:, None] * np.float32(r) for r in ring)  # [feet, 5] x, y offsets
        sx, sy = np.meshgrid(np.linspace(*config.scan_x, config.scan_points[0]),
                             np.linspace(*config.scan_y, config.scan_points[1]), indexing="ij")
        self._scan = (sx.ravel().astype(np.float32), sy.ravel().astype(np.float32))

    # ----------------------------------------------------------------------------------------------------------
    def flat_terrain(self, height: float = 0.0) -> jax.Array:
        """A flat ``[H, W]`` float32 terrain at ``height`` metres."""
        return flat_terrain(self.config, height)

    def terrain_height(self, terrain, x: jax.Array, y: jax.Array) -> jax.Array:
        """Bilinear terrain height in metres under world points (see :func:`sample_heights`); ``terrain`` is an
        ``[H, W]`` array (``tiles = 0``) or a :class:`Tile` (its tile alone, as if it were a single terrain)."""
        if isinstance(terrain, Tile):
            x0, y0 = self.tile_origin(terrain.index)
            return self._tile_heights(terrain, x - x0, y - y0)
        return sample_heights(terrain, x, y, self.radius_x, self.radius_y, self.elevation_z)

    def model(self, terrain) -> mjx.Model:
        """The mjx.Model with ``terrain`` as its heightfield: an ``[H, W]`` array in metres (``tiles = 0``), or a
        :class:`TileBank` / :class:`Tile` (its whole bank)."""
        if isinstance(terrain, Tile):
            terrain = terrain.bank
        if isinstance(terrain, TileBank):
            return self.mjx_model.replace(hfield_data=self._check_bank(terrain).data.reshape(-1))
        if self.tiles:
            raise TypeError(f"this env is tiled (config.tiles={self.tiles}): pass a walker.Tile (bank.at(index)) "
                            "as the terrain, not an array; env.make_bank(terrains [T, H, W]) builds the bank")
        terrain = jnp.asarray(terrain, jnp.float32)
        if terrain.shape != tuple(self.config.terrain_shape):
            raise ValueError(f"terrain must have shape {tuple(self.config.terrain_shape)} (config.terrain_shape), "
                             f"got {terrain.shape}")
        return self.mjx_model.replace(hfield_data=metres_to_hfield(terrain, self.elevation_z))

    # ---- tile banks (config.tiles >= 1) ----------------------------------------------------------------------
    def make_bank(self, terrains: jax.Array) -> TileBank:
        """A :class:`TileBank` of ``terrains`` (``[T, H, W]`` metres, ``T = config.tiles``; heights clipped to
        ``[0, scale.height]`` like the physics). Jit-able."""
        self._need_tiles()
        terrains = jnp.asarray(terrains, jnp.float32)
        want = (self.tiles,) + tuple(self.config.terrain_shape)
        if terrains.shape != want:
            raise ValueError(f"terrains must have shape {want} ([config.tiles, *config.terrain_shape]), "
                             f"got {terrains.shape}")
        data = jnp.clip(terrains / self.elevation_z, 0.0, 1.0)
        return TileBank(_tiles.pack(data, *self.grid))

    def flat_bank(self, height: float = 0.0) -> TileBank:
        """A bank of ``config.tiles`` flat tiles at ``height`` metres."""
        self._need_tiles()
        return self.make_bank(jnp.full((self.tiles,) + tuple(self.config.terrain_shape), height, jnp.float32))

    def set_tile(self, bank: TileBank, index, terrain: jax.Array) -> TileBank:
        """``bank`` with tile ``index`` replaced by ``terrain`` ([H, W] metres). Pure and jit-able (``index`` may be
        traced); envs standing on that tile see the new terrain from their next step on."""
        self._need_tiles()
        h, w = self.config.terrain_shape
        terrain = jnp.asarray(terrain, jnp.float32)
        if terrain.shape != (h, w):
            raise ValueError(f"terrain must have shape {(h, w)}, got {terrain.shape}")
        row, col = _tiles.tile_grid_pos(index, self.grid[1])
        tile = jnp.clip(terrain / self.elevation_z, 0.0, 1.0).astype(bank.data.dtype)
        return TileBank(jax.lax.dynamic_update_slice(bank.data, tile, (row * h, col * w)))

    def bank_terrains(self, bank: TileBank) -> jax.Array:
        """The ``[T, H, W]`` terrains (metres, clipped) of ``bank``."""
        self._need_tiles()
        return _tiles.unpack(self._check_bank(bank).data, self.tiles, tuple(self.config.terrain_shape)) \
            * self.elevation_z

    def tile_origin(self, index) -> tuple[jax.Array, jax.Array]:
        """World ``(x, y)`` of the centre of tile ``index`` (``(0, 0)`` for an untiled env): a walker's tile-local
        position is its ``qpos[:2]`` minus this."""
        if not self.tiles:
            return jnp.zeros((), jnp.float32), jnp.zeros((), jnp.float32)
        h, w = self.config.terrain_shape
        rows, cols = self.grid
        row, col = _tiles.tile_grid_pos(index, cols)
        cell_x, cell_y = 2.0 * self.radius_x / (w - 1), 2.0 * self.radius_y / (h - 1)
        x0 = cell_x * w * (col.astype(jnp.float32) - 0.5 * (cols - 1))
        y0 = cell_y * h * (row.astype(jnp.float32) - 0.5 * (rows - 1))
        return x0.astype(jnp.float32), y0.astype(jnp.float32)

    def select(self, mask: jax.Array, new: WalkerState, old: WalkerState) -> WalkerState:
        """Batched states: ``new`` where ``mask`` (leading axes of the states, e.g. ``[N]``) else ``old``. Use this
        instead of ``jax.tree.map(jnp.where ...)`` (auto-reset, pools): MJX-Warp's ``Data`` holds contact buffers
        shared by all envs (``mjx.Data.where``), which a plain tree-map would turn into per-env copies."""
        mask = jnp.asarray(mask, bool)

        def one(m, a, b):
            data = a.data.where(~m, b.data)  # Data.where(done, other): other where done
            rest = jax.tree.map(lambda x, y: jnp.where(m, x, y), a._replace(data=None), b._replace(data=None))
            return rest._replace(data=data)

        for _ in range(mask.ndim):
            one = jax.vmap(one)
        return one(mask, new, old)

    def park(self, state: WalkerState, mask) -> WalkerState:
        """``state`` with the walkers where ``mask`` (``[]`` per env, or the states' leading axes) moved out of the
        way: ``PARK_HEIGHT`` above the terrain's top, upright in the rest pose, at rest. Nothing touches them there,
        so their next physics steps carry few constraint rows (a fallen walker lying on the terrain carries many), and
        MuJoCo Warp's solver work follows each world's rows (MJX-JAX's arrays are fixed-size). For loops that keep
        stepping envs whose outcome is already recorded (evaluation walks that ended before the longest one); what a
        parked env does next is meaningless and must stay unread. Only ``qpos`` / ``qvel`` change, so MJX-Warp's
        shared buffers stay shared."""
        mask = jnp.asarray(mask, bool)[..., None]
        d = state.data
        top = jnp.full(d.qpos.shape[:-1] + (1,), self.elevation_z + PARK_HEIGHT, d.qpos.dtype)
        rest = jnp.broadcast_to(jnp.asarray(self._qpos0[3:], d.qpos.dtype), d.qpos.shape[:-1] + (d.qpos.shape[-1] - 3,))
        up = jnp.concatenate([d.qpos[..., :2], top, rest], axis=-1)
        return state._replace(data=d.replace(qpos=jnp.where(mask, up, d.qpos), qvel=jnp.where(mask, 0.0, d.qvel)))

    def _need_tiles(self):
        if not self.tiles:
            raise ValueError("this env is not tiled: build it with WalkerConfig(tiles=T) to use tile banks")

    def _check_bank(self, bank: TileBank) -> TileBank:
        want = tuple(self.mj_model.hfield_nrow) + tuple(self.mj_model.hfield_ncol)
        if tuple(bank.data.shape) != want:
            raise ValueError(f"tile bank data must have shape {want} (config.tiles={self.tiles} tiles of "
                             f"{tuple(self.config.terrain_shape)}), got {tuple(bank.data.shape)}: build it with "
                             "env.make_bank")
        return bank

    def _terrain(self, terrain):
        """(model, heights(x_local, y_local), (x0, y0) tile origin) for a terrain argument."""
        heights, origin = self._surface(terrain)
        return self.model(terrain), heights, origin

    def _surface(self, terrain):
        """(heights(x_local, y_local) in metres, (x0, y0) world origin of the terrain) for a terrain argument."""
        if self.tiles:
            if not isinstance(terrain, Tile):
                raise TypeError(f"this env is tiled (config.tiles={self.tiles}): the terrain must be a walker.Tile "
                                f"(bank.at(index)), got {type(terrain).__name__}")
            return (lambda x, y: self._tile_heights(terrain, x, y)), self.tile_origin(terrain.index)
        if isinstance(terrain, (Tile, TileBank)):
            raise TypeError("this env is not tiled (config.tiles=0): pass an [H, W] terrain array")
        terrain = jnp.asarray(terrain, jnp.float32)
        zero = jnp.zeros((), jnp.float32)
        return (lambda x, y: sample_heights(terrain, x, y, self.radius_x, self.radius_y, self.elevation_z)), (zero,
                                                                                                            zero)

    def _tile_heights(self, tile: Tile, x, y):
        row, col = _tiles.tile_grid_pos(tile.index, self.grid[1])
        return _tiles.sample_tile_heights(tile.bank.data, row, col, x, y, tuple(self.config.terrain_shape),
                                          self.radius_x, self.radius_y, self.elevation_z)

    def _make_data(self):
        return mjx.make_data(self.mjx_model) if self._data0 is None else self._data0

    # ----------------------------------------------------------------------------------------------------------
    def reset(self, key: jax.Array, terrain) -> WalkerState:
        """Initial state at the start edge of ``terrain`` (an ``[H, W]`` array in metres, or a :class:`Tile` of a
        tiled env) with random joint angles/velocities (and a random lateral start when
        ``config.start_spread > 0``)."""
        c = self.config
        key_q, key_v = jax.random.split(key)
        key_r = key
        patch_y = self._patch[1]
        if c.start_spread > 0:  # a stream of its own: the joint noise stays that of the same key without a spread
            y0 = jax.random.uniform(jax.random.fold_in(key, 1), (), minval=-c.start_spread, maxval=c.start_spread)
            patch_y = patch_y + y0
        del key
        m, heights, (ox, oy) = self._terrain(terrain)
        nj = self._qpos0.shape[0] - 7
        joints = self._qpos0[7:] + jax.random.uniform(key_q, (nj,), minval=-c.joint_noise, maxval=c.joint_noise)
        joints = jnp.clip(joints, self._jnt_lo, self._jnt_hi)
        qpos = jnp.concatenate([jnp.stack([ox + self.x_start, oy, jnp.zeros((), jnp.float32)]), self._qpos0[3:7],
                                joints])
        if c.start_spread > 0:
            qpos = qpos.at[1].set(oy + y0)
        qvel = jnp.concatenate([jnp.zeros(6), jax.random.uniform(key_v, (self.mj_model.nv - 6,),
                                                                 minval=-c.qvel_noise, maxval=c.qvel_noise)])
        data = mjx.kinematics(m, self._make_data().replace(qpos=qpos, qvel=qvel))
        bottoms = data.geom_xpos[self._feet, 2] - self._foot_radius  # [feet], torso at z = 0
        lift = jnp.max(heights(self._patch[0], patch_y)) - jnp.min(bottoms)
        if c.spawn == "feet":  # every foot clear of the terrain under it (xy does not move when the body is lifted)
            g = data.geom_xpos[self._feet]  # [feet, 3] world; heights() takes tile-local x, y
            fx, fy = g[:, :1] - ox + self._foot_ring[0], g[:, 1:2] - oy + self._foot_ring[1]
            lift = jnp.maximum(lift, jnp.max(jnp.max(heights(fx.ravel(), fy.ravel()).reshape(fx.shape), 1) - bottoms))
        qpos = qpos.at[2].set(lift + c.spawn_clearance)
        data = mjx.kinematics(m, data.replace(qpos=qpos))
        zero = jnp.zeros((), jnp.float32)
        metrics = {"forward_reward": zero, "reward_alive": zero, "reward_quadctrl": zero, "x_velocity": zero,
                   "torso_height": qpos[2] - heights(qpos[0] - ox, qpos[1] - oy), "distance": zero}
        steps, obs, random = jnp.zeros((), jnp.int32), self._obs(data, terrain), None
        if self._random:  # a stream of its own (fold_in 2): the start pose of a key is that without randomisation
            r = c.randomisation
            random = _rnd.draw(jax.random.fold_in(key_r, 2), r, self.mj_model.nbody, self._torso, self._torso_mass,
                               self.action_size)
            obs = _rnd.noisy_obs(obs, random, steps, r)
        return WalkerState(data=data, obs=obs, reward=zero, done=zero,
                           truncation=zero, failed=zero, steps=steps,
                           x_start=jnp.asarray(qpos[0], jnp.float32), distance=zero, metrics=metrics, random=random)

    def step(self, state: WalkerState, action: jax.Array, terrain) -> WalkerState:
        """Advance ``n_frames`` physics steps with ``action`` [A] in [-1, 1] (clipped) on ``terrain`` (the one
        given to reset: an ``[H, W]`` array in metres, or a :class:`Tile` of a tiled env)."""
        c = self.config
        m = self.model(terrain)
        ctrl, action_ok = self.controls(action)
        random = state.random
        if self._random:  # the action of `delay` steps ago; this env's friction, masses and motors
            given, random = _rnd.delayed_action(random, jnp.nan_to_num(jnp.asarray(action, jnp.float32)))
            ctrl = self.controls(given)[0]
            m = _rnd.randomised_model(m, random, c.randomisation)
        d0 = state.data
        d = d0.replace(ctrl=ctrl)
        warp = self._data0 is not None
        if warp and d0._impl.contact__dist.shape[:1] != (d0._impl.naconmax,):  # static: refused while tracing
            raise ValueError(f"MuJoCo Warp contact buffers {d0._impl.contact__dist.shape[:1]}, not [naconmax="
                             f"{d0._impl.naconmax}]: a carried state (walker.carry_rows) steps once env.select merged "
                             f"it into a reset state")
        if warp:  # overflow bits of this env step only
            d = d.replace(_impl=d._impl.replace(overflow=jnp.zeros_like(d._impl.overflow)))
        d = jax.lax.fori_loop(0, c.n_frames, lambda _, d: mjx.step(m, d), d)
        physics_ok = (jnp.all(jnp.isfinite(d.qpos)) & jnp.all(jnp.isfinite(d.qvel))
                      & (jnp.max(jnp.abs(d.qvel)) <= c.max_qvel))
        if warp:  # dropped contacts / constraints (more envs than warp_worlds, or njmax too small): not physics
            physics_ok = physics_ok & jnp.all((d._impl.overflow & _WARP_DROPPED) == 0)
        invalid = ~(physics_ok & action_ok)
        d = d.where(invalid, d0)  # mjx.Data.where keeps MJX-Warp's shared contact buffers shared
        steps = state.steps + 1
        if self._random and c.randomisation.push_every:  # a kick after this step's physics
            d = d.replace(qvel=_rnd.push(d.qvel, random, steps, c.randomisation))

        done, truncation, distance, x_velocity, torso_height = self.outcome(d0.qpos, d.qpos, steps, state.x_start,
                                                                             invalid, terrain)
        forward_reward = c.forward_reward_weight * x_velocity
        ctrl_cost = c.ctrl_cost_weight * jnp.sum(jnp.square(ctrl))
        reward = jnp.where(invalid, 0.0, forward_reward + c.healthy_reward - ctrl_cost)
        f32 = lambda v: jnp.asarray(v, jnp.float32)  # noqa: E731
        metrics = {"forward_reward": f32(jnp.where(invalid, 0.0, forward_reward)), "reward_alive": f32(
            jnp.where(invalid, 0.0, c.healthy_reward)), "reward_quadctrl": f32(-ctrl_cost),
                   "x_velocity": f32(x_velocity), "torso_height": f32(torso_height), "distance": f32(distance)}
        obs = self._obs(d, terrain)
        if self._random:
            obs = _rnd.noisy_obs(obs, random, steps, c.randomisation)
        return WalkerState(data=d, obs=obs, reward=f32(reward), done=f32(done),
                           truncation=f32(truncation), failed=f32(invalid), steps=steps, x_start=state.x_start,
                           distance=f32(distance), metrics=metrics, random=random)

    # ---- the pieces of a step that do not touch the physics (shared with the MuJoCo C engine, walker.mujoco_c) --
    def controls(self, action: jax.Array) -> tuple[jax.Array, jax.Array]:
        """``action`` [A] in [-1, 1] -> ``(ctrl [A] float32, action_ok [] bool)``: the actuator controls (NaN -> 0,
        +-inf -> +-1, clipped to [-1, 1], then mapped linearly onto the actuators' ctrlrange) and whether every
        component was finite."""
        action = jnp.asarray(action, jnp.float32)
        action_ok = jnp.all(jnp.isfinite(action))
        a = jnp.clip(jnp.nan_to_num(action, nan=0.0, posinf=1.0, neginf=-1.0), -1.0, 1.0)
        return self._ctrl_lo + (a + 1.0) * (self._ctrl_hi - self._ctrl_lo) * 0.5, action_ok

    def outcome(self, qpos_before: jax.Array, qpos: jax.Array, steps: jax.Array, x_start: jax.Array,
                invalid: jax.Array, terrain) -> tuple[jax.Array, ...]:
        """How an env step ended, from the physics state alone: ``(done, truncation, distance, x_velocity,
        torso_height)`` ([] each; done / truncation bool) for the step from ``qpos_before`` [nq] to ``qpos`` [nq]
        (world coordinates; ``qpos`` is ``qpos_before`` again where ``invalid``, the physics having been rejected),
        ``steps`` env steps since reset counting this one, ``x_start`` the torso's x at reset, on ``terrain`` (as
        :meth:`step`'s). The termination rules are the module docstring's."""
        c = self.config
        heights, (ox, oy) = self._surface(terrain)
        x, y, z = qpos[0] - ox, qpos[1] - oy, qpos[2]  # tile-local
        x_velocity = jnp.where(invalid, 0.0, (qpos[0] - qpos_before[0]) / self.dt)
        torso_height = z - heights(x, y)
        lo, hi = c.healthy_z_range
        healthy = (torso_height > lo) & (torso_height < hi)
        in_bounds = (jnp.abs(y) < self.radius_y - c.side_margin) & (x > -self.radius_x + 0.5 * c.start_margin)
        fell = ~healthy | ~in_bounds | invalid
        reached = x >= self.x_goal
        timeout = steps >= c.episode_length
        done = fell | reached | timeout
        truncation = done & ~fell
        distance = jnp.clip((qpos[0] - x_start) / self.track_length, 0.0, 1.0)
        return done, truncation, distance, x_velocity, torso_height

    def observe(self, qpos: jax.Array, qvel: jax.Array, terrain, time=0.0) -> jax.Array:
        """The observation ``[observation_size]`` float32 of the physics state ``qpos`` [nq], ``qvel`` [nv] (world
        coordinates) at ``time`` (s) on ``terrain`` (as :meth:`step`'s); finite, clipped to +-1e4. One code path for
        MJX-JAX, MuJoCo Warp and the MuJoCo C engine, classic and tiled (heights from :meth:`_surface`, tile-local).

        Perceptive: the scan grid (``scan_x`` x ``scan_y``, ``scan_points``; x-major, x along the heading) is rotated
        by the torso's yaw (the heading frame: roll and pitch are ignored, so the grid stays level) about the torso's
        ground point; each entry is the terrain height there minus the torso's z, plus, when ``scan_noise > 0``,
        Gaussian noise of that std. The noise key is a hash of the physics state (``qpos``, ``qvel``, ``time``): the
        observation stays a pure function of the state (same state, same observation; no key in the state), and
        differs between envs and steps."""
        heights, (ox, oy) = self._surface(terrain)
        x, y = qpos[0] - ox, qpos[1] - oy
        z = qpos[2] - heights(x, y)
        parts = [z[None], qpos[3:], qvel]
        if self.config.observation == "perceptive":
            heading = yaw(qpos[3:7])
            cy, sy = jnp.cos(heading), jnp.sin(heading)
            px = x + cy * self._scan[0] - sy * self._scan[1]
            py = y + sy * self._scan[0] + cy * self._scan[1]
            scan = heights(px, py) - qpos[2]
            if self.config.scan_noise > 0:
                scan = scan + self.config.scan_noise * jax.random.normal(state_key(qpos, qvel, time), scan.shape,
                                                                         scan.dtype)
            parts.append(scan)
        obs = jnp.concatenate(parts).astype(jnp.float32)
        return jnp.clip(jnp.nan_to_num(obs, nan=0.0, posinf=1e4, neginf=-1e4), -1e4, 1e4)

    def _obs(self, data: mjx.Data, terrain) -> jax.Array:
        return self.observe(data.qpos, data.qvel, terrain, data.time)
