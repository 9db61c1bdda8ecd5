"""Robots: what the walker needs to know about a body, as one spec per robot, and a registry of them.

    spec = robots.get("ant")                               # or register_robot(RobotSpec(...)) for your own
    env = WalkerEnv(WalkerConfig(robot="ant"))             # the heightfield, tiles, both backends: any spec

A :class:`RobotSpec` names the MJCF (a function returning its text: a package resource, or a file you ship; nothing
is downloaded), the geoms that touch the terrain (spheres: MJX's heightfield collisions; every other geom must not
collide with the floor or with each other, :func:`jaxterrain.walker.model.build_model` checks), the torso body
(its height above the terrain is the health test, its x the distance walked), the start pose of the hinge joints,
and the defaults of the :class:`~jaxterrain.walker.WalkerConfig` fields that depend on the body (healthy height
range, reward weights, reset noise, MuJoCo Warp's contact and constraint rows per env). Every walker is driven
along +x over the heightfield with ``forward_reward_weight x vx + healthy_reward - ctrl_cost_weight x |ctrl|^2``
(brax's locomotion reward); actions in [-1, 1] are mapped onto the actuators' ctrlrange.

Shipped: ``humanoid`` (brax's ``humanoid.xml``, the paper's walker; the defaults every result so far used) and
``ant`` (brax's ``ant.xml``, a quadruped of 8 hinge joints with a sphere at each foot; its start pose is brax's
``init_qpos``, its reward weights brax's ``Ant`` environment's). Both XML files are read from the installed brax
package; they are not copied into this repository.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path
from typing import Callable, NamedTuple, Optional

__all__ = ["RobotSpec", "HUMANOID", "ANT", "ROBOT_FIELDS", "SCAN_DEFAULTS", "register_robot", "get", "names", "brax_asset"]

ROBOT_FIELDS = ("start_margin", "goal_margin", "side_margin", "healthy_z_range", "forward_reward_weight", "healthy_reward", "ctrl_cost_weight", "joint_noise",
                "qvel_noise", "warp_contacts", "warp_njmax", "scan_x", "scan_y", "scan_points")
"""The :class:`~jaxterrain.walker.WalkerConfig` fields whose default (None) is the robot's (``RobotSpec.defaults``)."""
SCAN_DEFAULTS = (("scan_x", (-0.4, 1.2)), ("scan_y", (-0.4, 0.4)), ("scan_points", (17, 9)))
"""The height scan's grid for a spec whose ``defaults`` leave it out (specs written before observation sets): the
humanoid's, 1.6 m x 0.8 m from 0.4 m behind the torso to 1.2 m ahead, 0.1 m apart."""


class RobotSpec(NamedTuple):
    """One robot (static, hashable).

    name: registry name (``WalkerConfig(robot=name)``, ``--robot name``). xml: ``() -> str``, the MJCF text, with a
    plane geom named ``floor_geom`` that the walker replaces by its heightfield. foot_geoms: the sphere geoms that
    touch the terrain (at least one). torso_body: the body whose height above the terrain decides a fall and whose
    x is the distance walked. start_joints: hinge joint angles (rad) of the start pose, one per joint after the
    free root; None: the model's ``qpos0``. defaults: ``((field, value), ...)`` for the :data:`ROBOT_FIELDS`.
    description: one line for ``--help`` and the docs."""

    name: str
    xml: Callable[[], str]
    foot_geoms: tuple[str, ...]
    torso_body: str
    defaults: tuple[tuple[str, object], ...]
    start_joints: Optional[tuple[float, ...]] = None
    floor_geom: str = "floor"
    description: str = ""

    def default(self, field: str):
        """The robot's default of a :data:`ROBOT_FIELDS` field (the scan grid's: :data:`SCAN_DEFAULTS` where the
        spec leaves it out)."""
        return {**dict(SCAN_DEFAULTS), **dict(self.defaults)}[field]


def brax_asset(filename: str) -> Callable[[], str]:
    """``() -> str``: the text of ``brax/envs/assets/<filename>`` from the installed brax package (located
    without importing brax, whose imports are heavy)."""

    def read() -> str:
        spec = importlib.util.find_spec("brax")
        if spec is None or not spec.submodule_search_locations:
            raise RuntimeError(f"brax is not installed: the walker reads brax/envs/assets/{filename} from it")
        return (Path(list(spec.submodule_search_locations)[0]) / "envs" / "assets" / filename).read_text()

    read.__name__ = read.__qualname__ = f"brax_asset({filename!r})"
    return read


HUMANOID = RobotSpec(
    name="humanoid", xml=brax_asset("humanoid.xml"), foot_geoms=("left_foot", "right_foot"), torso_body="torso",
    defaults=(("start_margin", 0.5), ("goal_margin", 0.5), ("side_margin", 0.3), ("healthy_z_range", (1.0, 2.0)), ("forward_reward_weight", 1.25), ("healthy_reward", 5.0),
              ("ctrl_cost_weight", 0.1), ("joint_noise", 0.1), ("qvel_noise", 0.1),
              # 2 feet x up to 4 hfield contacts; 8 contacts x 4 rows + 17 joint limits = 49 rows at most
              ("warp_contacts", 8), ("warp_njmax", 64),
              # height scan (observation="perceptive"): 1.6 m x 0.8 m, 0.4 m behind to 1.2 m ahead, 0.1 m apart
              ("scan_x", (-0.4, 1.2)), ("scan_y", (-0.4, 0.4)), ("scan_points", (17, 9))),
    description="brax's humanoid (17 hinge joints, 2 sphere feet): the paper's walker")

ANT = RobotSpec(
    name="ant", xml=brax_asset("ant.xml"),
    foot_geoms=("left_foot_geom", "right_foot_geom", "third_foot_geom", "fourth_foot_geom"), torso_body="torso",
    # brax's init_qpos (ant.xml's custom numeric): hips 0, ankles +-1 rad, the legs reaching down
    start_joints=(0.0, 1.0, 0.0, -1.0, 0.0, -1.0, 0.0, 1.0),
    # start 1 m in from the edge: its back feet reach 0.6 m behind the torso (0.5 m would put them off the terrain);
    # goal and side margins 1.3 m: a foot sphere reaches 1.21 m from the torso's centre (hip 0.28 + leg 0.28 + ankle
    # 0.57 + foot radius 0.08), plus one cell of the seam between tiles, so it never touches a neighbouring tile
    defaults=(("start_margin", 1.0), ("goal_margin", 1.3), ("side_margin", 1.3), ("healthy_z_range", (0.2, 1.0)), ("forward_reward_weight", 1.0), ("healthy_reward", 1.0),
              ("ctrl_cost_weight", 0.5), ("joint_noise", 0.1), ("qvel_noise", 0.1),
              # 4 feet x up to 4 hfield contacts; 16 contacts x 4 rows + 8 joint limits = 72 rows at most
              ("warp_contacts", 16), ("warp_njmax", 96),
              # height scan: 2.4 m x 1.6 m, 0.15 / 0.16 m apart: the feet reach 1.2 m from the torso; 0.8 m behind it
              ("scan_x", (-0.8, 1.6)), ("scan_y", (-0.8, 0.8)), ("scan_points", (17, 11))),
    description="brax's ant (8 hinge joints, 4 sphere feet): a quadruped; brax's Ant reward weights")

_REGISTRY: dict[str, RobotSpec] = {HUMANOID.name: HUMANOID, ANT.name: ANT}


def register_robot(spec: RobotSpec) -> None:
    """Make ``WalkerConfig(robot=spec.name)`` (and ``--robot NAME``) walk ``spec``. A name already taken by another
    spec is refused."""
    if not isinstance(spec, RobotSpec):
        raise ValueError(f"register_robot takes a jaxterrain.walker.RobotSpec, got {type(spec).__name__}")
    if not isinstance(spec.name, str) or not spec.name.isidentifier():
        raise ValueError(f"RobotSpec.name must be an identifier, got {spec.name!r}")
    if spec.name in _REGISTRY and _REGISTRY[spec.name] != spec:
        raise ValueError(f"a robot named {spec.name!r} is already registered")
    missing = [f for f in ROBOT_FIELDS if f not in dict(spec.defaults) and f not in dict(SCAN_DEFAULTS)]
    if missing:
        raise ValueError(f"RobotSpec {spec.name!r}: defaults lacks {', '.join(missing)}")
    if not spec.foot_geoms:
        raise ValueError(f"RobotSpec {spec.name!r}: foot_geoms must name at least one sphere geom")
    _REGISTRY[spec.name] = spec


def names() -> tuple[str, ...]:
    """The registered robot names (the shipped ones first)."""
    return tuple(_REGISTRY)


def get(name: str) -> RobotSpec:
    """The :class:`RobotSpec` registered as ``name``; ``ValueError`` naming the choices."""
    if name not in _REGISTRY:
        raise ValueError(f"robot must be one of {', '.join(_REGISTRY)}, got {name!r}")
    return _REGISTRY[name]
