"""The walker's MuJoCo model: a robot (:mod:`.robots`; default brax's humanoid) on a heightfield, edited in code with
``mujoco.MjSpec``.

The XML is read at runtime from the robot's spec (the shipped ones: the installed brax package,
``brax/envs/assets/humanoid.xml`` and ``ant.xml``); it is never copied into this repository. Edits (see
:func:`build_spec`):

- the floor plane becomes an ``<hfield>`` of ``terrain_shape = (nrow, ncol)`` samples whose size comes from
  :func:`jaxterrain.terrain.hfield_size` (``radius_x, radius_y, elevation_z, base_z``); the hfield geom sits at
  the world origin, so the surface height at a sample is ``hfield_data * elevation_z`` metres;
- only the foot spheres collide with the terrain (brax's humanoid and ant already give every other geom
  ``contype = conaffinity = 0``; we check it), so there are no cylinder/ellipsoid-hfield pairs (MJX has none);
- solver options come from the :class:`~jaxterrain.walker.config.WalkerConfig` (see ``SOLVER_SOUND``, the
  default, ``SOLVER_FAST`` and ``SOLVER_XML``).

MuJoCo's heightfield layout (checked against ``mujoco/mjx/_src/mesh.py`` and by tests): ``hfield_data`` is
row-major ``[nrow, ncol]``; row ``i`` lies at ``y = -radius_y + i * 2 radius_y / (nrow - 1)`` and column ``j`` at
``x = -radius_x + j * 2 radius_x / (ncol - 1)``. So a terrain array ``[H, W]`` maps ``H`` to y and ``W`` to x, and the
walker walks along +x, i.e. along the columns.
"""

from __future__ import annotations

from typing import NamedTuple

import mujoco
import numpy as np

from jaxterrain.runtime.validation import positive
from jaxterrain.terrain import TerrainScale, hfield_size
from jaxterrain.walker.robots import HUMANOID, RobotSpec, get as get_robot

__all__ = ["HFIELD_NAME", "FLOOR_GEOM", "FOOT_GEOMS", "TORSO_BODY", "SolverOptions", "SOLVER_SOUND", "SOLVER_FAST",
           "SOLVER_XML", "NAMED_SOLVERS", "parse_solver", "solver_label", "humanoid_xml", "check_terrain_shape",
           "build_spec", "build_model", "metres_to_hfield", "standing_offset"]

HFIELD_NAME = "terrain"
FLOOR_GEOM = "floor"  # the heightfield geom's name (the robot's floor plane is replaced by it, under this name)
FOOT_GEOMS = HUMANOID.foot_geoms  # the humanoid's (robots.HUMANOID); other robots: RobotSpec.foot_geoms
TORSO_BODY = HUMANOID.torso_body


class SolverOptions(NamedTuple):
    """MuJoCo solver options the walker is simulated with (``mjOption`` fields)."""

    solver: str = "newton"  # "newton" | "cg"
    iterations: int = 4
    ls_iterations: int = 16
    eulerdamp: bool = False


# The default: the cheapest options measured under which a walk does not change against the XML's converged solve.
# The shipped base policy, trained under them, covers 1.000 / 0.960 (best 5 / all) of a flat track under them and
# 1.000 / 0.959 under SOLVER_XML; 3 / 12 already gives 1.000 / 0.917 and 2 / 8 0.976 / 0.857. About 0.45x the
# physics rate of SOLVER_FAST on an H200 (benchmarks/RESULTS.md).
SOLVER_SOUND = SolverOptions("newton", 4, 16, False)
# brax's own settings for this humanoid on the MJX backend (brax/envs/humanoid.py); about 4x faster than the XML's,
# but a policy trained under them exploits the unconverged contact solve and walks a third as far under SOLVER_XML.
SOLVER_FAST = SolverOptions("newton", 1, 4, False)
# What humanoid.xml itself says (iterations=8) plus MuJoCo's defaults (ls_iterations=50, Euler damping on).
SOLVER_XML = SolverOptions("newton", 8, 50, True)

_SOLVERS = {"newton": mujoco.mjtSolver.mjSOL_NEWTON, "cg": mujoco.mjtSolver.mjSOL_CG}


NAMED_SOLVERS = {"sound": SOLVER_SOUND, "fast": SOLVER_FAST, "xml": SOLVER_XML}
"""The solver options :func:`parse_solver` knows by name."""


def parse_solver(text: str) -> SolverOptions:
    """Solver options from text: ``"sound"`` (:data:`SOLVER_SOUND`), ``"fast"`` (:data:`SOLVER_FAST`), ``"xml"``
    (:data:`SOLVER_XML`) or ``"ITERATIONS,LS_ITERATIONS,EULERDAMP"`` for Newton (e.g. ``"4,16,0"``). Raises
    ``ValueError``."""
    if text in NAMED_SOLVERS:
        return NAMED_SOLVERS[text]
    parts = text.split(",")
    try:
        it, ls, ed = (int(v) for v in parts)
    except ValueError:
        raise ValueError(f"solver must be 'sound', 'fast', 'xml' or 'ITERATIONS,LS_ITERATIONS,EULERDAMP' "
                         f"(e.g. '4,16,0'), got {text!r}") from None
    if it < 1 or ls < 1 or ed not in (0, 1):
        raise ValueError(f"solver {text!r}: iterations and ls_iterations must be >= 1 and EULERDAMP 0 or 1")
    return SolverOptions("newton", it, ls, bool(ed))


def solver_label(solver: SolverOptions) -> str:
    """Short text of solver options, e.g. ``"newton 4/16"`` or ``"newton 8/50 eulerdamp"``."""
    return f"{solver.solver} {solver.iterations}/{solver.ls_iterations}{' eulerdamp' if solver.eulerdamp else ''}"


def humanoid_xml() -> str:
    """The text of brax's ``envs/assets/humanoid.xml`` from the installed brax package (``robots.HUMANOID.xml``)."""
    return HUMANOID.xml()


def _robot(robot) -> RobotSpec:
    return get_robot(robot) if isinstance(robot, str) else robot


def check_terrain_shape(terrain_shape) -> tuple[int, int]:
    """``terrain_shape`` as ``(nrow, ncol)`` Python ints, each a whole number >= 4; ``ValueError`` naming it
    otherwise (a fraction, a string, a bool, another length)."""
    def whole(s):
        return (isinstance(s, (int, float, np.integer, np.floating)) and not isinstance(s, (bool, np.bool_))
                and np.isfinite(s) and s == int(s))

    try:
        dims = tuple(terrain_shape)
    except TypeError:
        dims = ()
    if len(dims) != 2 or not all(whole(s) for s in dims) or min(int(s) for s in dims) < 4:
        raise ValueError(f"terrain_shape must be (nrow, ncol) with both >= 4, got {terrain_shape!r}")
    return tuple(int(s) for s in dims)  # type: ignore[return-value]


def build_spec(terrain_shape=(256, 256), scale: TerrainScale = TerrainScale(),
               solver: SolverOptions = SOLVER_SOUND, timestep: float = 0.003,
               robot: RobotSpec | str = HUMANOID) -> mujoco.MjSpec:
    """The robot's MJCF (default brax's humanoid; a :class:`~jaxterrain.walker.robots.RobotSpec` or its name) with
    its floor replaced by a flat (all-zero) ``terrain_shape`` hfield at ``scale``. ``ValueError`` naming the floor
    geom, feet or torso the spec names but the MJCF lacks."""
    robot = _robot(robot)
    nrow, ncol = check_terrain_shape(terrain_shape)
    if solver.solver not in _SOLVERS:
        raise ValueError(f"solver must be one of {sorted(_SOLVERS)}, got {solver.solver!r}")
    if solver.iterations < 1 or solver.ls_iterations < 1:
        raise ValueError(f"solver iterations and ls_iterations must be >= 1, got {solver}")
    if not timestep > 0:
        raise ValueError(f"timestep must be > 0 seconds, got {timestep}")
    spec = mujoco.MjSpec.from_string(robot.xml())
    geoms, bodies = {g.name for g in spec.geoms}, {b.name for b in spec.bodies}
    missing = [f"geom {n!r}" for n in (robot.floor_geom, *robot.foot_geoms) if n not in geoms]
    missing += [f"body {robot.torso_body!r}"] if robot.torso_body not in bodies else []
    if missing:
        raise ValueError(f"robot {robot.name!r}: its MJCF has no {', '.join(missing)} (RobotSpec.floor_geom / "
                         f"foot_geoms / torso_body)")
    floor = spec.geom(robot.floor_geom)
    friction = np.array(floor.friction).copy()
    spec.delete(floor)
    size = [float(v) for v in hfield_size((nrow, ncol), scale)]
    # all-zero elevation data as MuJoCo's binary hfield format (int32 nrow, int32 ncol, float32 data) in the spec's
    # assets: a copy of bytes, where ``userdata = [0.0] * n`` converts n Python floats (seconds for tile banks)
    spec.assets = {**spec.assets, "terrain.bin": np.array([nrow, ncol], np.int32).tobytes()
                   + bytes(4 * nrow * ncol)}
    hfield = spec.add_hfield(name=HFIELD_NAME, file="terrain.bin", size=size)
    geom = spec.worldbody.add_geom(name=FLOOR_GEOM, type=mujoco.mjtGeom.mjGEOM_HFIELD, hfieldname=HFIELD_NAME,
                                   contype=0, conaffinity=1, condim=3)
    geom.friction = friction
    geom.rgba = [0.5, 0.5, 0.5, 1.0]

    spec.option.timestep = timestep
    spec.option.solver = _SOLVERS[solver.solver]
    spec.option.iterations = solver.iterations
    spec.option.ls_iterations = solver.ls_iterations
    if solver.eulerdamp:
        spec.option.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_EULERDAMP)
    else:
        spec.option.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_EULERDAMP)
    return spec


def build_model(terrain_shape=(256, 256), scale: TerrainScale = TerrainScale(),
                solver: SolverOptions = SOLVER_SOUND, timestep: float = 0.003,
                robot: RobotSpec | str = HUMANOID) -> mujoco.MjModel:
    """Compiled :func:`build_spec`; checks that only the feet can touch the terrain, that they are spheres and that
    no two geoms of the robot collide (``ValueError`` naming the geom)."""
    robot = _robot(robot)
    model = build_spec(terrain_shape, scale, solver, timestep, robot).compile()
    floor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, FLOOR_GEOM)
    feet = {mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n) for n in robot.foot_geoms}
    for g in range(model.ngeom):
        if g == floor:
            continue
        touches = (model.geom_contype[g] & model.geom_conaffinity[floor]) or (
            model.geom_conaffinity[g] & model.geom_contype[floor])
        if bool(touches) != (g in feet):
            raise ValueError(f"robot {robot.name!r}: geom {model.geom(g).name!r} "
                             f"{'cannot touch' if g in feet else 'touches'} the terrain; only the feet "
                             f"({', '.join(robot.foot_geoms)}) may (contype / conaffinity)")
        if g in feet and model.geom_type[g] != mujoco.mjtGeom.mjGEOM_SPHERE:
            raise ValueError(f"robot {robot.name!r}: foot geom {model.geom(g).name!r} must be a sphere (MJX's "
                             f"heightfield collisions)")
        for g2 in range(model.ngeom):  # no self collisions either
            if g2 != floor and g2 != g and (model.geom_contype[g] & model.geom_conaffinity[g2]):
                raise ValueError(f"robot {robot.name!r}: geoms {model.geom(g).name!r} and {model.geom(g2).name!r} "
                                 f"collide with each other (the walker has no self-collisions)")
    return model


def metres_to_hfield(terrain_m, elevation_z):
    """Terrain heights in metres ``[..., H, W]`` -> MuJoCo ``hfield_data`` values ``[..., H * W]``.

    MuJoCo draws the surface at ``hfield_data * size[2]`` above the hfield geom (at z = 0 here), and expects data in
    [0, 1]; so ``data = clip(terrain / elevation_z, 0, 1)`` row-major (row = y, column = x). Heights outside
    ``[0, elevation_z]`` are clipped.
    """
    import jax.numpy as jnp

    positive("elevation_z (metres)", elevation_z)  # concrete values only: traced ones pass unchecked
    t = jnp.asarray(terrain_m, jnp.float32)
    if t.ndim < 2:
        raise ValueError(f"terrain_m must have shape [..., H, W]; got shape {tuple(t.shape)}")
    data = jnp.clip(t / elevation_z, 0.0, 1.0)
    return data.reshape(t.shape[:-2] + (t.shape[-2] * t.shape[-1],))


def standing_offset(model: mujoco.MjModel, robot: RobotSpec | str = HUMANOID) -> float:
    """Height of the torso origin above the lowest foot-sphere bottom in the robot's start pose (its
    ``start_joints``, else the XML's default pose)."""
    robot = _robot(robot)
    data = mujoco.MjData(model)
    if robot.start_joints is not None:
        data.qpos[7:] = robot.start_joints
    mujoco.mj_kinematics(model, data)
    torso = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, robot.torso_body)
    bottoms = []
    for name in robot.foot_geoms:
        g = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name)
        bottoms.append(data.geom_xpos[g, 2] - model.geom_size[g, 0])
    return float(data.xpos[torso, 2] - min(bottoms))
