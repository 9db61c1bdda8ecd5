"""Robots as specs (``jaxterrain.walker.robots``): the humanoid walks as before the spec, the ant walks, and a spec
that does not match its MJCF is refused naming what is missing."""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from jaxterrain.runtime import xla
from jaxterrain.terrain import TerrainScale
from jaxterrain.walker import WalkerConfig, WalkerEnv
from jaxterrain.walker import robots
from jaxterrain.walker.model import build_model, build_spec, standing_offset
from scripts import load_script

DATA = Path(__file__).resolve().parents[1] / "data"


def _reference_module():
    module = load_script(DATA / "make_walker_reference.py", "make_walker_reference")
    return module


# A stored walk is compared with a tolerance, never bit for bit: float32 MJX physics over 30 steps with contacts
# differs in the last bits across CPUs, XLA builds and jax versions. Measured against the stored walk (2026-11-29,
# jax 0.10.2, Intel Xeon and AMD EPYC): qpos up to 1.0e-4, obs up to 1.7e-3 (velocities, |obs| up to 21), reward
# up to 8e-5, done equal. The tolerances are 10x that; a changed walker (reward weights, start pose, frame skip,
# observation layout) moves these by 1e-1 or more.
WALK_TOLERANCE = {"qpos": 1e-3, "obs": 2e-2, "reward": 1e-3}

# the ant's programs below are checked against bounds only: compiled cheaply (XLA's lowest backend optimisation, the
# classic emitter; as in test_walker.py), each reset and walk as one program (an eager MJX reset, op by op, costs more
# CPU than compiling it)
FAST_COMPILE = xla.known_options(xla.FAST_CPU_COMPILE)


def compiled(fn, *args):
    return jax.jit(fn).lower(*args).compile(FAST_COMPILE)(*args)


def test_the_humanoid_spec_walks_as_the_walker_before_robot_specs_within_float32_tolerance():
    ref = _reference_module()
    got = ref.walk(ref.CONFIG)
    want = np.load(DATA / "walker_reference.npz")
    for name, atol in WALK_TOLERANCE.items():
        np.testing.assert_allclose(got[name], want[name], atol=atol, rtol=0, err_msg=name)
    np.testing.assert_array_equal(got["done"], want["done"])
    # the walk moves far more than the tolerance, so the comparison can tell walks apart
    assert np.abs(want["qpos"][-1] - want["qpos"][0]).max() > 100 * WALK_TOLERANCE["qpos"]
    assert WalkerEnv(ref.CONFIG).config.healthy_z_range == (1.0, 2.0)  # the humanoid's defaults, resolved


def test_the_ant_stands_on_its_four_feet_and_walks_the_heightfield():
    config = WalkerConfig(terrain_shape=(32, 64), scale=TerrainScale(cell_size=0.2, height=0.5), robot="ant")
    env = WalkerEnv(config)
    assert (env.action_size, env.observation_size) == (8, 1 + 4 + 8 + 14)
    assert env.config.healthy_z_range == (0.2, 1.0) and env.config.ctrl_cost_weight == 0.5  # brax's Ant
    terrain = jnp.asarray(np.random.default_rng(3).uniform(0, 0.2, (32, 64)), jnp.float32)

    def step(s, _):
        s = env.step(s, jnp.zeros(8), terrain)
        return s, s.done

    def walk(key):  # the reset and the 60 steps in one program
        start = env.reset(key, terrain)
        return (start,) + jax.lax.scan(step, start, None, length=60)

    start, state, done = compiled(walk, jax.random.key(0))
    feet = start.data.geom_xpos[env._feet]
    bottoms = np.asarray(feet[:, 2]) - 0.08
    assert np.all(bottoms >= float(jnp.max(terrain)) - 0.2)  # spawned on its feet over the terrain
    assert 0.2 < float(start.metrics["torso_height"]) < 1.0
    assert not np.any(np.asarray(done)) and 0.2 < float(state.metrics["torso_height"]) < 1.0  # it stays up


def test_the_spawn_lifts_every_foot_clear_of_rising_ground_and_the_old_patch_rule_did_not():
    """The ant's front feet stand ~0.65 m ahead of its torso: on ground rising 0.4 m per m from 0.25 m ahead of the
    start, the 0.5 m patch under the torso (spawn="patch") sees little of the rise and starts two feet cut into the
    ramp; spawn="feet" (the default) lifts the body until every foot sphere clears the highest terrain under it."""
    config = WalkerConfig(terrain_shape=(96, 96), robot="ant")
    assert config.spawn == "feet"
    depth = {}
    for spawn in ("patch", "feet"):
        env = WalkerEnv(config._replace(spawn=spawn))
        xs = (np.arange(96) - 47.5) * env.config.scale.cell_size
        ramp = np.clip((xs - env.x_start - 0.25) * 0.4, 0.0, None)
        terrain = jnp.asarray(np.broadcast_to(ramp, (96, 96)), jnp.float32)
        xyz = np.asarray(compiled(env.reset, jax.random.key(0), terrain).data.geom_xpos[env._feet])
        r = env._foot_radius
        ring = [(0, 0), (1, 0), (-1, 0), (0, 1), (0, -1)]  # the foot's centre and four points a radius away
        under = np.array([max(float(env.terrain_height(terrain, x + a * rf, y + b * rf)) for a, b in ring)
                          for (x, y), rf in zip(xyz[:, :2], r)])
        depth[spawn] = under - (xyz[:, 2] - r)  # > 0: the sphere's bottom is below the ground under it
    assert (depth["patch"] > 0.05).sum() == 2  # the two front feet, 9-11 cm into the ramp
    np.testing.assert_allclose(depth["feet"].max(), -config.spawn_clearance, atol=1e-4)  # the highest just clears
    with pytest.raises(ValueError, match="spawn must be one of feet, patch"):
        WalkerEnv(config._replace(spawn="torso"))


def test_standing_offset_uses_the_robots_start_pose():
    ant = build_model((16, 16), robot="ant")
    # ankles at +-1 rad (brax's init_qpos): the 0.57 m shins reach 0.48 m down, + the 0.08 m foot spheres
    assert standing_offset(ant, "ant") == pytest.approx(0.556, abs=0.005)
    flat = robots.ANT._replace(name="ant_flat", start_joints=None)  # qpos0: the legs splayed level with the torso
    assert standing_offset(ant, flat) == pytest.approx(0.08, abs=0.005)
    assert standing_offset(build_model((16, 16))) == pytest.approx(1.4 - 0.107, abs=2e-3)


@pytest.mark.parametrize("change, message", [
    (dict(foot_geoms=("left_foot", "no_such_foot")), "has no geom 'no_such_foot'"),
    (dict(torso_body="no_such_torso"), "has no body 'no_such_torso'"),
    (dict(floor_geom="ground"), "has no geom 'ground'"),
])
def test_a_spec_naming_parts_its_mjcf_lacks_is_refused_naming_them(change, message):
    spec = robots.HUMANOID._replace(name="broken", **change)
    with pytest.raises(ValueError, match=message):
        build_spec((16, 16), robot=spec)


def test_a_foot_that_is_not_a_sphere_or_a_body_that_touches_the_ground_is_refused():
    with pytest.raises(ValueError, match="foot geom 'left_ankle_geom' must be a sphere"):
        _ant_with(foot="left_ankle_geom", contype=1)
    with pytest.raises(ValueError, match="geom 'torso_geom' touches the terrain"):
        _ant_with(foot=None, contype=1, geom="torso_geom")


def _ant_with(foot, contype, geom=None):
    text = robots.ANT.xml()
    name = geom or foot
    text = text.replace(f'name="{name}" ', f'name="{name}" contype="{contype}" ', 1)
    feet = robots.ANT.foot_geoms if foot is None else (foot,) + robots.ANT.foot_geoms[1:]
    return build_model((16, 16), robot=robots.ANT._replace(name="ant_edit", xml=lambda: text, foot_geoms=feet))


def test_robots_are_registered_by_name_and_unknown_names_are_refused(monkeypatch):
    monkeypatch.setattr(robots, "_REGISTRY", dict(robots._REGISTRY))
    assert robots.names()[:2] == ("humanoid", "ant")
    with pytest.raises(ValueError, match="robot must be one of humanoid, ant, got 'dog'"):
        WalkerEnv(WalkerConfig(terrain_shape=(16, 16), robot="dog"))
    with pytest.raises(ValueError, match="defaults lacks"):
        robots.register_robot(robots.ANT._replace(name="dog", defaults=()))
    robots.register_robot(robots.ANT._replace(name="dog"))
    assert robots.get("dog").foot_geoms == robots.ANT.foot_geoms
    with pytest.raises(ValueError, match="already registered"):
        robots.register_robot(robots.HUMANOID._replace(name="dog"))


def test_the_robot_tutorial_runs_as_written(monkeypatch, capsys):
    """docs/tutorials/robot.md's Python block: a registered variant of the ant builds its walker."""
    import re

    monkeypatch.setattr(robots, "_REGISTRY", dict(robots._REGISTRY))
    text = (Path(__file__).resolve().parents[2] / "docs" / "tutorials" / "robot.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert len(blocks) == 1
    exec(compile(blocks[0], "robot.md", "exec"), {})
    assert capsys.readouterr().out.split() == ["8", "27", "(0.2,", "1.0)"]
    assert robots.get("low_ant").start_joints[1] == 0.8


def test_the_walker_fitness_and_evolve_take_a_robot_and_refuse_one_without_a_base_policy(monkeypatch):
    """``EvolveConfig.robot`` (recorded in archives) chooses whose base policy the fitness walks; the humanoid's is
    the same function as before; a robot without a shipped base policy is refused naming how to train one (``evolve
    --robot``: tests/integration/test_stage_commands.py)."""
    from jaxterrain import difficulty, qd

    assert qd.EvolveConfig().robot == "humanoid"
    assert qd.config.config_from_dict(qd.config.config_to_dict(qd.EvolveConfig(robot="ant"))).robot == "ant"
    with pytest.raises(ValueError, match="EvolveConfig.robot must be one of humanoid, ant; got 'dog'"):
        qd.config.resolve_config(qd.EvolveConfig(robot="dog"))
    assert difficulty.fitness_fn(128) is difficulty.fitness_fn(128, robot="humanoid")  # one cached function
    monkeypatch.setattr(robots, "_REGISTRY", dict(robots._REGISTRY))
    robots.register_robot(robots.ANT._replace(name="dog"))  # a robot nobody trained
    with pytest.raises(ValueError, match="robot 'dog': no base policy is shipped .* train-base-policy --robot dog"):
        difficulty.fitness_fn(128, robot="dog")


def test_the_ant_ships_a_base_policy_that_records_its_robot_and_passed_the_bar():
    """``jaxterrain/assets/base_policy_ant/``: the ant's policy (27 observations, 8 actions), its walker config and
    its flat-ground evaluation (best 5 of 20 >= 0.95), loaded by ``difficulty.robot_base_policy("ant")``."""
    import json

    from jaxterrain import difficulty, rl

    folder = rl.base_policy_dir("ant")
    policy = difficulty.robot_base_policy("ant")
    assert difficulty.policy_robot(policy) == "ant"
    assert (policy.observation_size, policy.action_size) == (27, 8)
    result = json.loads((folder / "eval.json").read_text())
    assert result["attempts"] == 20 and result["best"] == 5 and result["best_mean"] >= 0.95
    assert "train-base-policy --robot ant --preset gpu" in (folder / "PROVENANCE.md").read_text()


@pytest.mark.slow  # 10-70 s on 2 CPU cores; the default suite keeps under 15 min (2026-11-29)
def test_the_ants_walk_on_a_tile_does_not_touch_its_neighbour_tile():
    """The ant's feet reach 1.2 m from its torso, so its goal and side margins are its reach (1.3 m): walking a flat
    tile whose +x neighbour is a tall Perlin tile, it reaches the goal as on the classic layout (with the humanoid's
    0.5 / 0.3 m margins it stepped onto the neighbour: 0.65 against 1.00 here, measured 2026-11-28)."""
    from jaxterrain import difficulty, generators

    size = 96  # 3.84 m: the smallest square whose track (3.84 - 1.0 - 1.3 = 1.54 m) passes the env's checks
    gen = generators.get("perlin", size=size)
    tall = jnp.clip(jnp.asarray(gen.render(gen.sample(jax.random.PRNGKey(11), 1)), jnp.float32), 0.0, 1.0)
    terrains = jnp.concatenate([jnp.zeros((1, size, size)), tall])  # tile 0 flat, tile 1 (its +x neighbour) tall
    config = WalkerConfig(terrain_shape=(size, size), robot="ant", episode_length=120, tiles=2, warp_worlds=8)
    assert (robots.ANT.default("goal_margin"), robots.ANT.default("side_margin")) == (1.3, 1.3)
    d = np.asarray(difficulty.rollout_distances(terrains, jax.random.PRNGKey(5), 4, policy=difficulty.robot_base_policy("ant"),
                                                env_config=config))
    np.testing.assert_array_equal(d[0], 1.0)  # the flat tile walked to its goal, every attempt


def test_min_terrain_side_is_the_smallest_terrain_the_env_takes():
    """``walker.min_terrain_side``: the humanoid's 0.5 / 0.5 / 0.3 m margins need 39 samples at 4 cm, the ant's 1.0
    / 1.3 / 1.3 m 77; the env takes that side and refuses one less."""
    from jaxterrain.walker import min_terrain_side

    for robot, side in (("humanoid", 39), ("ant", 77)):
        assert min_terrain_side(WalkerConfig(robot=robot)) == side
        WalkerEnv(WalkerConfig(robot=robot, terrain_shape=(side, side)))
        with pytest.raises(ValueError, match="terrain too"):
            WalkerEnv(WalkerConfig(robot=robot, terrain_shape=(side - 1, side - 1)))
