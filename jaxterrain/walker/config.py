"""The walker's static configuration, :class:`WalkerConfig` (hashable; a field per physical choice), its checks
(:func:`resolve_config`: every field on the host, the robot's defaults filled in) and the observation sets
(:data:`OBSERVATIONS`, :func:`observation_fields`). :class:`~jaxterrain.walker.env.WalkerEnv` builds from it.

Physical choices (all in :class:`WalkerConfig`):

- Scale: ``terrain_shape`` samples at ``scale`` (default 256 x 256 at 0.04 m = a 10.2 m square, heights up to
  1.0 m). Heights outside ``[0, scale.height]`` metres are clipped, for the physics and for the samples alike.
- Spawn: torso at ``x_start = -radius_x + start_margin``, ``y = 0`` (or, with ``start_spread > 0`` m, ``y``
  uniform in ``[-start_spread, start_spread]``, drawn from the reset key; the default 0 draws nothing), facing +x,
  joints at the XML pose plus uniform noise of ``joint_noise`` rad (clipped into the joint ranges) and joint
  velocities with noise ``qvel_noise`` rad/s; the body is lowered so that its lowest foot sphere sits
  ``spawn_clearance`` above the highest terrain sample in a 0.5 m x 0.5 m patch under the start point and, with
  ``spawn="feet"`` (the default), so that every foot sphere's bottom is ``spawn_clearance`` above the highest terrain
  under it (its centre and four points a radius away); ``spawn="patch"``, the rule of every run before 2026-11-29
  (late), started the ant with a foot cut into rising ground on 28 % of suite v2's resets (its feet stand ~0.6 m
  from its torso; ``docs/results/suite_v2/spawn_check/``). Forward kinematics per reset.
- Termination (``done = 1``): a fall (torso height above the terrain under it outside ``healthy_z_range``, or the
  torso leaving the sides / the back of the heightfield), reaching ``x_goal = radius_x - goal_margin``, the time
  limit ``episode_length`` env steps, or invalid physics (non-finite state or ``|qvel| > max_qvel``) or a
  non-finite action. Invalid steps keep the previous (finite) physics state, give reward 0 and set
  ``failed = 1``; obs and reward are always finite. ``truncation = 1`` marks ends that are not failures
  (goal or time limit): bootstrap the value there.
- Reward (brax humanoid): ``forward_reward_weight * vx + healthy_reward - ctrl_cost_weight * |ctrl|^2`` with vx the
  torso's x velocity over the env step and ctrl = 0.4 * action (the XML's ctrlrange).
- Normalised distance ``clip((x - x_start) / (x_goal - x_start), 0, 1)`` of the torso's x, in ``state.distance``.
- One env step = ``n_frames`` (5) physics steps of ``timestep`` (0.003 s): dt = 0.015 s, as in brax.
- Physics randomisation (``randomisation``, :mod:`jaxterrain.walker.randomisation`; off by default): friction,
  masses, torso mass, motor strength, observation noise, action delay and pushes, drawn per env at reset (from the
  reset key's stream ``fold_in(key, 2)``) into ``state.random``; off, nothing is drawn and ``state.random`` is None.
- Solver: :data:`~jaxterrain.walker.model.SOLVER_SOUND` (Newton, iterations 4, ls_iterations 16, no Euler damping)
  by default: a walk under it is the same as under the XML's converged ``SOLVER_XML`` (8 / 50 / damping on).
  ``SOLVER_FAST`` (1 / 4, brax's MJX setting) is 2.2x faster but lets a policy exploit the unconverged contacts.
"""

from __future__ import annotations

from typing import NamedTuple, Optional

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain.terrain import hfield_size, validate_scale
from jaxterrain.walker import tiles as _tiles
from jaxterrain.walker.model import SOLVER_SOUND, SolverOptions, TerrainScale, check_terrain_shape
from jaxterrain.walker.randomisation import Randomisation, check_randomisation
from jaxterrain.walker.robots import ROBOT_FIELDS, get as get_robot

__all__ = ["BACKENDS", "OBSERVATIONS", "SPAWNS", "SCAN_FIELDS", "WalkerConfig", "with_observation",
           "observation_fields", "observation_label", "scan_size", "resolve_config", "check_config", "min_terrain_side",
           "check_real", "flat_terrain"]

BACKENDS = ("jax", "warp")
OBSERVATIONS = ("blind", "perceptive")
"""The observation sets: ``blind`` (torso height, orientation, joint angles and velocities: the paper's) and
``perceptive`` (the same, then a height scan: terrain heights minus torso z on a grid in the heading frame)."""
SPAWNS = ("feet", "patch")
"""The spawn rules (:class:`WalkerConfig` ``spawn``): ``feet`` (every foot clear of the terrain under it; default)
and ``patch`` (the lowest foot clear of the 0.5 m patch under the torso only: every run before 2026-11-29, late)."""
SCAN_FIELDS = ("observation", "scan_x", "scan_y", "scan_points")
"""The :class:`WalkerConfig` fields that define what a policy observes: a policy walks only an env with the same
values (:func:`observation_fields`); ``scan_noise`` changes the values, not their meaning, and may differ."""


class WalkerConfig(NamedTuple):
    """Static configuration of :class:`WalkerEnv` (hashable; lengths in metres, times in env steps). ``robot`` names
    a :class:`~jaxterrain.walker.robots.RobotSpec`; the fields of :data:`~jaxterrain.walker.robots.ROBOT_FIELDS`
    left None take its defaults (:func:`resolve_config`; ``WalkerEnv.config`` holds the resolved values)."""

    terrain_shape: tuple[int, int] = (256, 256)  # (nrow = y samples, ncol = x samples)
    scale: TerrainScale = TerrainScale()
    solver: SolverOptions = SOLVER_SOUND
    timestep: float = 0.003  # physics step, s
    n_frames: int = 5  # physics steps per env step
    episode_length: int = 1000  # env steps (15 s)
    # track
    start_margin: Optional[float] = None  # x_start = -radius_x + start_margin (humanoid: 0.5; the ant's legs: 1.0)
    goal_margin: Optional[float] = None  # x_goal = radius_x - goal_margin (humanoid: 0.5; the ant's reach: 1.3)
    side_margin: Optional[float] = None  # fall when |y| > radius_y - side_margin (humanoid: 0.3; the ant: 1.3)
    start_spread: float = 0.0  # start y uniform in [-start_spread, start_spread] m (0: y = 0, no key drawn)
    spawn_clearance: float = 0.01  # lowest foot this far above the highest terrain under the start
    spawn: str = "feet"  # SPAWNS: "feet" (each foot clear of the terrain under it too) | "patch" (before 2026-11-29)
    # termination
    healthy_z_range: Optional[tuple[float, float]] = None  # torso z minus terrain height under it (humanoid: 1, 2)
    max_qvel: float = 500.0  # |qvel| beyond this = exploding physics
    # reset noise (uniform, +-)
    joint_noise: Optional[float] = None  # rad on the hinge joints (humanoid: 0.1)
    qvel_noise: Optional[float] = None  # rad/s on the hinge joint velocities (humanoid: 0.1)
    # reward
    forward_reward_weight: Optional[float] = None  # humanoid: 1.25
    healthy_reward: Optional[float] = None  # humanoid: 5.0
    ctrl_cost_weight: Optional[float] = None  # humanoid: 0.1
    # the observation set (OBSERVATIONS): "blind" (the paper's) or "perceptive" (+ a height scan on the grid below)
    observation: str = "blind"
    scan_x: Optional[tuple[float, float]] = None  # m along the heading, torso at 0 (humanoid: -0.4, 1.2)
    scan_y: Optional[tuple[float, float]] = None  # m to the left of the heading (humanoid: -0.4, 0.4)
    scan_points: Optional[tuple[int, int]] = None  # grid points (along x, along y) (humanoid: 17, 9: 0.1 m apart)
    scan_noise: float = 0.0  # m: std of Gaussian noise on every scanned height (0: exact heights)
    # physics backend and terrain layout (see the module docstring)
    backend: str = "jax"  # "jax" (MJX-JAX) | "warp" (MJX-Warp, needs tiles >= 1 and warp-lang + mujoco-warp)
    tiles: int = 0  # 0: terrain = one [H, W] array per env; T >= 1: terrain = a Tile of a bank of T tiles
    warp_worlds: int = 8192  # warp: contacts are allocated for this many envs stepped together (all vmap axes)
    warp_contacts: Optional[int] = None  # warp: contacts per env (humanoid: 8, 2 feet x up to 4 hfield contacts)
    warp_njmax: Optional[int] = None  # warp: constraint rows per env (humanoid: 64; 8 contacts x 4 + 17 limits = 49)
    # the body (jaxterrain.walker.robots): every field above that is None takes this robot's default
    robot: str = "humanoid"
    # physics randomisation (jaxterrain.walker.randomisation; default: off, the paper's walker)
    randomisation: Randomisation = Randomisation()


def resolve_config(config: WalkerConfig) -> WalkerConfig:
    """``config`` with every :data:`~jaxterrain.walker.robots.ROBOT_FIELDS` field that is None set to its robot's
    default, after checking every field on the host (no model is built): ``ValueError`` naming the field and what
    it allows (an unknown robot, a terrain smaller than 4 x 4, a non-positive step count, a NaN length, ...). The
    checks that need the robot's model (the track length, ``start_spread`` against the map's width) are
    :class:`WalkerEnv`'s."""
    if not isinstance(config, WalkerConfig):
        raise ValueError(f"config must be a walker.WalkerConfig; got {type(config).__name__}")
    robot = get_robot(config.robot)
    config = config._replace(**{f: robot.default(f) for f in ROBOT_FIELDS if getattr(config, f) is None})
    check_config(config)
    return config._replace(randomisation=check_randomisation(config.randomisation))


def with_observation(config: WalkerConfig, observation: str) -> WalkerConfig:
    """``config`` with the observation set ``observation`` (one of :data:`OBSERVATIONS`); the scan grid stays as
    set (None: the robot's default, :func:`resolve_config`). ``ValueError`` naming ``observation`` otherwise."""
    if not isinstance(observation, str) or observation not in OBSERVATIONS:
        raise ValueError(f"observation must be one of {', '.join(OBSERVATIONS)}, got {observation!r}")
    return config._replace(observation=observation)


def observation_fields(config) -> dict:
    """What a walker observes, as ``{field: value}`` of :data:`SCAN_FIELDS`, from a
    :class:`WalkerConfig` or a policy's recorded ``walker_config`` (a JSON dict). Blind sets carry no scan fields
    (the grid means nothing to them); perceptive ones the resolved grid as tuples. A dict without ``observation``
    (every policy saved before observation sets) is blind unless it says ``height_scan: true`` (the field's old
    name). Compare two with ``==``: a policy walks only an env of the same fields (the noise may differ)."""
    if isinstance(config, WalkerConfig):
        c = resolve_config(config)
        get = lambda f: getattr(c, f)  # noqa: E731
        robot_name = c.robot
    elif isinstance(config, dict):
        robot_name = config.get("robot") or "humanoid"
        get = config.get
    else:
        raise ValueError(f"config must be a walker.WalkerConfig or a walker_config dict; got {type(config).__name__}")
    observation = get("observation")
    if isinstance(config, dict) and observation is None:
        observation = "perceptive" if get("height_scan") else "blind"
    if observation not in OBSERVATIONS:
        raise ValueError(f"walker_config.observation must be one of {', '.join(OBSERVATIONS)}, got {observation!r}")
    if observation == "blind":
        return {"observation": "blind"}
    robot = get_robot(robot_name)
    out = {"observation": observation}
    for f in ("scan_x", "scan_y", "scan_points"):
        v = get(f)
        out[f] = tuple(robot.default(f) if v is None else v)
    return out


def observation_label(fields: dict) -> str:
    """One line for :func:`observation_fields`' dict: ``blind`` or ``perceptive (17 x 9 heights, x -0.4..1.2 m,
    y -0.4..0.4 m)``."""
    if fields.get("observation") != "perceptive":
        return str(fields.get("observation"))
    (x0, x1), (y0, y1), (nx, ny) = fields["scan_x"], fields["scan_y"], fields["scan_points"]
    return f"perceptive ({nx} x {ny} heights, x {x0:g}..{x1:g} m, y {y0:g}..{y1:g} m)"


def scan_size(config: WalkerConfig) -> int:
    """The height scan's entries in the observation (``scan_points[0] x scan_points[1]``; the humanoid's 17 x 9 =
    153) of a perceptive :class:`WalkerConfig` (its grid None: the robot's default), 0 for a blind one.
    :class:`~jaxterrain.walker.WalkerEnv` appends them last, after the blind observation."""
    fields = observation_fields(config)
    return 0 if fields["observation"] != "perceptive" else int(fields["scan_points"][0] * fields["scan_points"][1])


def min_terrain_side(config: WalkerConfig = WalkerConfig()) -> int:
    """The fewest samples per side of a square terrain that :class:`WalkerEnv` takes for ``config``'s robot at
    ``config.scale`` (its ``terrain_shape`` is ignored): a track longer than 0.5 m between ``start_margin`` and
    ``goal_margin``, and more than 0.2 m inside the two ``side_margin`` s (plus ``start_spread`` and 0.5 m when a
    spread is set). The humanoid at 4 cm: 39; the ant (1.0 / 1.3 / 1.3 m margins): 77."""
    c = resolve_config(config._replace(terrain_shape=(4, 4)))
    for n in range(4, 1 << 16):
        radius_x, radius_y = hfield_size((n, n), c.scale)[:2]
        track, width = 2 * radius_x - c.start_margin - c.goal_margin, radius_y - c.side_margin
        if track > 0.5 and width > 0.2 and (c.start_spread == 0 or c.start_spread <= width - 0.5):
            return n
    raise ValueError(f"no terrain up to {1 << 16} samples a side fits the margins of {c}")


def check_real(name: str, value, lo: float | None = None, lo_open: bool = False) -> float:
    """``value`` as a finite float (>= ``lo``, or > it when ``lo_open``), or ``ValueError`` naming ``name``."""
    bound = "" if lo is None else f" {'>' if lo_open else '>='} {lo:g}"
    try:
        if isinstance(value, (bool, str, bytes)):
            raise TypeError
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a finite number{bound}, got {value!r}") from None
    if not np.isfinite(v) or (lo is not None and (v <= lo if lo_open else v < lo)):
        raise ValueError(f"{name} must be a finite number{bound}, got {value!r}")
    return v


def _int(name: str, value, lo: int) -> int:
    if not isinstance(value, (int, np.integer)) or isinstance(value, (bool, np.bool_)) or value < lo:
        raise ValueError(f"{name} must be an integer >= {lo}, got {value!r}")
    return int(value)


def _pair(name: str, value) -> tuple:
    try:
        if isinstance(value, (str, bytes)) or len(value) != 2:
            raise TypeError
    except TypeError:
        raise ValueError(f"{name} must be a pair (low, high), got {value!r}") from None
    return tuple(value)


def check_config(c: WalkerConfig) -> None:
    check_terrain_shape(c.terrain_shape)
    try:
        validate_scale(c.scale)
    except ValueError as err:
        raise ValueError(f"scale.cell_size and scale.height must be > 0: {err}") from None
    if not isinstance(c.solver, SolverOptions):
        raise ValueError(f"solver must be a walker.SolverOptions (see walker.parse_solver), got {c.solver!r}")
    check_real("timestep", c.timestep, 0.0, lo_open=True)
    _int("n_frames", c.n_frames, 1)
    _int("episode_length", c.episode_length, 1)
    for name in ("start_margin", "goal_margin", "side_margin", "spawn_clearance"):
        check_real(name, getattr(c, name), 0.0)
    check_real("max_qvel", c.max_qvel, 0.0, lo_open=True)
    for name in ("forward_reward_weight", "healthy_reward", "ctrl_cost_weight"):
        check_real(name, getattr(c, name))
    lo, hi = _pair("healthy_z_range", c.healthy_z_range)
    if not check_real("healthy_z_range", lo) < check_real("healthy_z_range", hi):
        raise ValueError(f"healthy_z_range must be (low, high) with low < high, got {c.healthy_z_range}")
    for name in ("joint_noise", "qvel_noise"):
        check_real(name, getattr(c, name), 0.0)
    check_real("start_spread (metres)", c.start_spread, 0.0)
    if not isinstance(c.observation, str) or c.observation not in OBSERVATIONS:
        raise ValueError(f"observation must be one of {', '.join(OBSERVATIONS)}, got {c.observation!r}")
    if not isinstance(c.spawn, str) or c.spawn not in SPAWNS:
        raise ValueError(f"spawn must be one of {', '.join(SPAWNS)}, got {c.spawn!r}")
    for name in ("scan_x", "scan_y"):
        lo, hi = _pair(name, getattr(c, name))
        if not check_real(name, lo) <= check_real(name, hi):
            raise ValueError(f"{name} must be (low, high) metres with low <= high, got {getattr(c, name)}")
    points = _pair("scan_points", c.scan_points)
    if not all(isinstance(p, (int, np.integer)) and not isinstance(p, bool) for p in points) or min(points) < 1:
        raise ValueError(f"scan_points must be >= 1 each, got {c.scan_points}")
    check_real("scan_noise (metres)", c.scan_noise, 0.0)
    if c.backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {c.backend!r}")
    _int("tiles", c.tiles, 0)
    if c.backend == "warp" and c.tiles < 1:
        raise ValueError("backend='warp' needs tiles >= 1: MuJoCo Warp shares one heightfield across all envs, so "
                         "per-env terrains come from a bank of tiles (WalkerConfig(tiles=T), env.make_bank)")
    for name in ("warp_worlds", "warp_contacts", "warp_njmax"):
        _int(name, getattr(c, name), 1)
    check_randomisation(c.randomisation)
    h, w = check_terrain_shape(c.terrain_shape)
    rows, cols = _tiles.grid(max(c.tiles, 1))
    if c.tiles and rows * h * cols * w >= 2 ** 31:
        raise ValueError(f"{c.tiles} tiles of {h} x {w} exceed MuJoCo's int32 heightfield size")


def flat_terrain(config: WalkerConfig = WalkerConfig(), height: float = 0.0) -> jax.Array:
    """A flat ``config.terrain_shape`` float32 terrain at ``height`` metres (a finite number)."""
    if not isinstance(config, WalkerConfig):
        raise ValueError(f"config must be a walker.WalkerConfig; got {type(config).__name__}")
    check_terrain_shape(config.terrain_shape)
    if not isinstance(height, jax.core.Tracer):
        check_real("height", height)
    return jnp.full(tuple(config.terrain_shape), height, jnp.float32)
