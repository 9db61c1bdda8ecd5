"""Walker env on CPU: tiny 32 x 32 heightfields with 0.2 m cells (a 6.2 m square) so that MJX's hfield collision is
cheap; ONE jit-compiled vmapped reset and step shared by every test (MJX compiles slowly on CPU)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from jaxterrain.runtime import xla
from jaxterrain.terrain import TerrainScale
from jaxterrain.walker import (SOLVER_FAST, SOLVER_SOUND, SOLVER_XML, WalkerConfig, WalkerEnv, build_model,
                               flat_terrain, sample_heights, standing_offset)

CFG = WalkerConfig(terrain_shape=(32, 32), scale=TerrainScale(cell_size=0.2, height=0.5))


@pytest.fixture(scope="module")
def env():
    return WalkerEnv(CFG)


# cheaper XLA CPU compiles (these tiny runs need no optimised code): lowest backend optimisation and the classic
# elemental emitter instead of the fusion emitters, every program of this module compiled alike
FAST_COMPILE = xla.known_options({"xla_backend_optimization_level": 0, "xla_llvm_disable_expensive_passes": True,
                "xla_cpu_use_fusion_emitters": False})


@pytest.fixture(scope="module")
def fns(env):
    """(reset, step): vmapped over envs, every env its own terrain; compiled once (ahead of time) for batch 3."""
    terrains = _terrains(env)
    keys = jax.random.split(jax.random.PRNGKey(0), 3)
    reset = jax.jit(jax.vmap(env.reset)).lower(keys, terrains).compile(FAST_COMPILE)
    state = reset(keys, terrains)
    step = jax.jit(jax.vmap(env.step)).lower(state, jnp.zeros((3, env.action_size)), terrains).compile(FAST_COMPILE)
    return reset, step


def _terrains(env):
    h, w = CFG.terrain_shape
    step_terrain = np.full((h, w), 0.45, np.float32)
    step_terrain[:, : w // 4] = 0.10  # low strip along the start edge (small x = small column index)
    return jnp.stack([flat_terrain(CFG, 0.10), flat_terrain(CFG, 0.35), jnp.asarray(step_terrain)])


@pytest.fixture(scope="module")
def settled(env, fns):
    """3 walkers (flat 0.10 m, flat 0.35 m, step terrain low at the start) after 20 zero-action steps."""
    reset, step = fns
    terrains = _terrains(env)
    state0 = reset(jax.random.split(jax.random.PRNGKey(0), 3), terrains)
    state = state0
    for _ in range(20):
        state = step(state, jnp.zeros((3, env.action_size)), terrains)
    return terrains, state0, state


def test_model_contacts_and_solver():
    m = build_model((32, 32), CFG.scale, SOLVER_XML)
    assert (m.hfield_nrow[0], m.hfield_ncol[0]) == (32, 32)
    np.testing.assert_allclose(m.hfield_size[0], [3.1, 3.1, 0.5, 0.1])  # (W - 1) * 0.2 / 2
    assert (m.opt.iterations, m.opt.ls_iterations) == (8, 50)
    assert not m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_EULERDAMP
    m = build_model((32, 32), CFG.scale, SOLVER_FAST)
    assert (m.opt.iterations, m.opt.ls_iterations) == (1, 4)
    assert m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_EULERDAMP
    m = build_model((32, 32), CFG.scale)  # the default: SOLVER_SOUND
    assert (m.opt.iterations, m.opt.ls_iterations) == (4, 16) and CFG.solver == SOLVER_SOUND
    assert m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_EULERDAMP
    floor = m.geom("floor").id
    touching = [m.geom(g).name for g in range(m.ngeom) if g != floor and m.geom_contype[g] & m.geom_conaffinity[floor]]
    assert sorted(touching) == ["left_foot", "right_foot"]
    assert m.geom_type[floor] == mujoco.mjtGeom.mjGEOM_HFIELD
    # torso origin 1.4 m, foot sphere bottom 0.107 m in the XML pose
    assert standing_offset(m) == pytest.approx(1.4 - 0.107, abs=2e-3)


def test_sample_heights_bilinear():
    rng = np.random.default_rng(0)
    t = rng.uniform(0, 0.5, (5, 7)).astype(np.float32)
    rx, ry = 3.0, 2.0  # column j at x = -3 + j, row i at y = -2 + i
    xs = jnp.array([-3.0, 0.0, -2.5, 3.0, 10.0])
    ys = jnp.array([-2.0, 1.0, -1.5, 2.0, 0.0])
    got = np.asarray(sample_heights(jnp.asarray(t), xs, ys, rx, ry, 0.5))
    mid = 0.25 * (t[0, 0] + t[0, 1] + t[1, 0] + t[1, 1])
    np.testing.assert_allclose(got, [t[0, 0], t[3, 3], mid, t[4, 6], t[2, 6]], rtol=1e-6)
    # clipped into [0, max_height] like the physics
    assert float(sample_heights(jnp.full((5, 7), 0.9), jnp.zeros(()), jnp.zeros(()), rx, ry, 0.5)) == 0.5


def test_reset_spawn(env, settled):
    terrains, state0, _ = settled
    assert state0.obs.shape == (3, env.observation_size) and env.observation_size == 45
    qpos = np.asarray(state0.data.qpos)
    np.testing.assert_allclose(qpos[:, 0], env.x_start)  # start edge
    np.testing.assert_allclose(qpos[:, 1], 0.0)
    np.testing.assert_allclose(np.asarray(state0.x_start), env.x_start)
    # lowest foot sphere spawn_clearance above the terrain under the start patch
    feet = np.asarray(state0.data.geom_xpos)[:, env._feet, 2] - env._foot_radius
    np.testing.assert_allclose(feet.min(axis=1), np.array([0.10, 0.35, 0.10]) + CFG.spawn_clearance, atol=1e-4)
    # obs[0] is the torso height above the terrain: ~1.29 m standing, same on every terrain
    np.testing.assert_allclose(np.asarray(state0.obs[:, 0]), np.asarray(qpos[:, 2]) - [0.10, 0.35, 0.10], atol=1e-5)
    assert np.all(np.abs(np.asarray(state0.obs[:, 0]) - 1.30) < 0.03)
    assert np.all(np.asarray(state0.done) == 0) and np.all(np.asarray(state0.distance) == 0)


def test_per_env_terrains_rest_heights(env, settled):
    """Feet rest on each env's own terrain: sphere centres at terrain + radius (to ~1 mm), differences exact."""
    _, _, state = settled
    feet_z = np.asarray(state.data.geom_xpos)[:, env._feet, 2]  # [3, 2]
    radius = env._foot_radius
    np.testing.assert_allclose(feet_z - radius, np.broadcast_to([[0.10], [0.35], [0.10]], (3, 2)), atol=2e-3)
    np.testing.assert_allclose(feet_z[1] - feet_z[0], 0.25, atol=2e-3)
    # the step terrain (high at larger x) holds the walker at the low start strip: rows = y, columns = x
    np.testing.assert_allclose(feet_z[2], feet_z[0], atol=2e-3)
    assert np.all(np.asarray(state.done) == 0) and np.all(np.asarray(state.steps) == 20)


def test_reset_step_deterministic(env, fns):
    reset, step = fns
    terrains = _terrains(env)
    keys = jax.random.split(jax.random.PRNGKey(3), 3)
    a = reset(keys, terrains)
    b = reset(keys, terrains)
    np.testing.assert_array_equal(np.asarray(a.data.qpos), np.asarray(b.data.qpos))
    np.testing.assert_array_equal(np.asarray(a.obs), np.asarray(b.obs))
    c = reset(jax.random.split(jax.random.PRNGKey(4), 3), terrains)
    assert np.abs(np.asarray(a.data.qpos[:, 7:]) - np.asarray(c.data.qpos[:, 7:])).max() > 1e-3  # joint noise
    assert np.abs(np.asarray(a.data.qpos[:, 7:]) - env._qpos0[7:]).max() <= env.config.joint_noise + 1e-6
    action = jnp.tile(jnp.linspace(-1, 1, env.action_size), (3, 1))
    s1, s2 = step(a, action, terrains), step(b, action, terrains)
    np.testing.assert_array_equal(np.asarray(s1.data.qpos), np.asarray(s2.data.qpos))
    np.testing.assert_array_equal(np.asarray(s1.reward), np.asarray(s2.reward))
    # brax reward: 1.25 vx + 5 - 0.1 |0.4 a|^2
    ctrl_cost = 0.1 * np.sum((0.4 * np.linspace(-1, 1, env.action_size)) ** 2)
    vx = (np.asarray(s1.data.qpos[:, 0]) - np.asarray(a.data.qpos[:, 0])) / env.dt
    np.testing.assert_allclose(np.asarray(s1.reward), 1.25 * vx + 5.0 - ctrl_cost, rtol=1e-4, atol=1e-4)


def test_fall_terminates(env, fns, settled):
    """With zero torques the humanoid collapses: done = 1, not a truncation, torso low, obs finite."""
    _, step = fns
    terrains, _, state = settled
    done_at = np.full(3, -1)
    for t in range(150):
        state = step(state, jnp.zeros((3, env.action_size)), terrains)
        d = np.asarray(state.done)
        for i in range(3):
            if d[i] and done_at[i] < 0:
                done_at[i] = t
                assert float(state.truncation[i]) == 0.0 and float(state.failed[i]) == 0.0
                assert float(state.metrics["torso_height"][i]) <= env.config.healthy_z_range[0]
        if np.all(done_at >= 0):
            break
    assert np.all(done_at >= 0), done_at
    assert np.all(np.isfinite(np.asarray(state.obs)))


def test_park_moves_only_the_masked_walkers_out_of_contact(env, fns, settled):
    """``env.park``: the masked walker goes PARK_HEIGHT above the terrain's top, upright in the rest pose, at rest,
    and steps on touching nothing; the other walkers' states and next steps are bit for bit those without it."""
    from jaxterrain.walker.env import PARK_HEIGHT

    _, step = fns
    terrains, _, state = settled
    zeros = jnp.zeros((3, env.action_size))
    mask = jnp.array([False, True, False])
    parked = env.park(state, mask)
    q, v = np.asarray(parked.data.qpos), np.asarray(parked.data.qvel)
    np.testing.assert_array_equal(q[[0, 2]], np.asarray(state.data.qpos)[[0, 2]])
    np.testing.assert_array_equal(v[[0, 2]], np.asarray(state.data.qvel)[[0, 2]])
    np.testing.assert_array_equal(q[1, :2], np.asarray(state.data.qpos)[1, :2])  # it stays above its place
    assert q[1, 2] == pytest.approx(env.elevation_z + PARK_HEIGHT)
    np.testing.assert_array_equal(q[1, 3:], env._qpos0[3:])
    assert not v[1].any()
    same = env.park(state, jnp.zeros(3, bool))
    np.testing.assert_array_equal(np.asarray(same.data.qpos), np.asarray(state.data.qpos))
    a, b = step(state, zeros, terrains), step(parked, zeros, terrains)
    for x, y in ((a.data.qpos, b.data.qpos), (a.data.qvel, b.data.qvel), (a.obs, b.obs), (a.reward, b.reward)):
        np.testing.assert_array_equal(np.asarray(x)[[0, 2]], np.asarray(y)[[0, 2]])
    dist_a, dist_b = np.asarray(a.data._impl.contact.dist), np.asarray(b.data._impl.contact.dist)
    assert dist_a[1].min() < 0 < dist_b[1].min()  # feet in contact (dist < 0), then none
    assert np.abs(np.asarray(b.data.qvel)[1]).max() < 1.0  # free fall for one env step, nothing else


def test_goal_time_limit_and_invalid(env, fns, settled):
    _, step = fns
    terrains, state0, _ = settled
    zeros = jnp.zeros((3, env.action_size))
    # far edge: distance 1, truncation (not a fall)
    qpos = state0.data.qpos.at[:, 0].set(env.x_goal + 0.05).at[2, 2].add(0.35)  # env 2: onto the high part
    s = step(state0._replace(data=state0.data.replace(qpos=qpos)), zeros, terrains)
    np.testing.assert_array_equal(np.asarray(s.done), 1.0)
    np.testing.assert_array_equal(np.asarray(s.truncation), 1.0)
    np.testing.assert_allclose(np.asarray(s.distance), 1.0)
    # time limit
    s = step(state0._replace(steps=jnp.full(3, CFG.episode_length - 1, jnp.int32)), zeros, terrains)
    np.testing.assert_array_equal(np.asarray(s.done), 1.0)
    np.testing.assert_array_equal(np.asarray(s.truncation), 1.0)
    s = step(state0._replace(steps=jnp.full(3, CFG.episode_length - 2, jnp.int32)), zeros, terrains)
    np.testing.assert_array_equal(np.asarray(s.done), 0.0)
    # NaN action in env 0, exploding velocity in env 1: failed, previous physics kept, all finite
    action = zeros.at[0, 3].set(jnp.nan)
    qvel = state0.data.qvel.at[1, 8].set(1e5)
    s = step(state0._replace(data=state0.data.replace(qvel=qvel)), action, terrains)
    np.testing.assert_array_equal(np.asarray(s.failed), [1.0, 1.0, 0.0])
    np.testing.assert_array_equal(np.asarray(s.done), [1.0, 1.0, 0.0])
    np.testing.assert_array_equal(np.asarray(s.reward[:2]), 0.0)
    np.testing.assert_array_equal(np.asarray(s.data.qpos[0]), np.asarray(state0.data.qpos[0]))
    for leaf in jax.tree.leaves(s):
        if jnp.issubdtype(jnp.asarray(leaf).dtype, jnp.floating):
            assert np.all(np.isfinite(np.asarray(leaf)))


def test_config_validation():
    with pytest.raises(ValueError, match="terrain_shape"):
        WalkerEnv(WalkerConfig(terrain_shape=(2, 32)))
    with pytest.raises(ValueError, match="healthy_z_range"):
        WalkerEnv(CFG._replace(healthy_z_range=(1.0, 0.5)))
    with pytest.raises(ValueError, match="track length"):
        WalkerEnv(CFG._replace(scale=TerrainScale(cell_size=0.02, height=0.5)))


def test_height_scan_observation(settled):
    """Perceptive: terrain heights on a grid around and ahead of the torso (heading frame), minus torso z, after the
    blind observation, which is unchanged."""
    terrains, _, state = settled
    env_scan = WalkerEnv(CFG._replace(observation="perceptive"))
    nx, ny = env_scan.config.scan_points
    assert (nx, ny) == (17, 9) and env_scan.config.scan_x == (-0.4, 1.2)  # the humanoid's default grid
    assert env_scan.observation_size == 45 + nx * ny
    data = jax.tree.map(lambda a: a[2], state.data)  # the step terrain: 0.10 m up to x = -1.7 m, 0.45 m from -1.5 m
    obs = np.asarray(jax.jit(env_scan._obs)(data, terrains[2]))  # one compile, not one per operation
    assert obs.shape == (env_scan.observation_size,)
    z = float(data.qpos[2])
    scan = obs[45:].reshape(nx, ny)  # [along x, along y]; x from 0.4 m behind to 1.2 m ahead of x ~ -2.6 m
    np.testing.assert_allclose(scan[0], 0.10 - z, atol=1e-3)
    np.testing.assert_allclose(scan[-1], 0.45 - z, atol=1e-3)
    assert np.all(np.diff(scan[:, ny // 2]) >= -1e-6)  # the step rises ahead
    np.testing.assert_allclose(obs[:45], np.asarray(state.obs[2]), atol=1e-6)


def test_height_scan_turns_with_the_heading_noise_is_a_pure_function_of_the_state_and_tiles_agree(settled):
    """The grid turns with the torso's yaw (a walker facing +y sees the step to its right); scan noise has the
    std asked for, is the same for the same state and differs between states, and leaves the blind part alone; a
    tiled env's perceptive observation on tile i is the classic one on that terrain (the warp backend shares this
    ``_obs``)."""
    terrains, _, state = settled
    env_scan = WalkerEnv(CFG._replace(observation="perceptive"))
    nx, ny = env_scan.config.scan_points
    data = jax.tree.map(lambda a: a[2], state.data)
    obs_fn = jax.jit(env_scan._obs)
    turned = data.replace(qpos=data.qpos.at[3:7].set(jnp.array([np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)])))
    scan = np.asarray(obs_fn(turned, terrains[2]))[45:].reshape(nx, ny)  # x ahead = world +y: constant in x
    z = float(data.qpos[2])
    np.testing.assert_allclose(scan, np.broadcast_to(scan[:1], scan.shape), atol=1e-5)
    np.testing.assert_allclose(scan[0, 0], 0.10 - z, atol=1e-3)  # scan y = -0.4 (right of +y) is world x + 0.4: low

    noisy_env = WalkerEnv(CFG._replace(observation="perceptive", scan_noise=0.05))
    noisy = jax.jit(jax.vmap(noisy_env._obs, in_axes=(0, 0)))
    clean = np.asarray(jax.vmap(obs_fn)(state.data, terrains))
    a, b = np.asarray(noisy(state.data, terrains)), np.asarray(noisy(state.data, terrains))
    np.testing.assert_array_equal(a, b)  # a pure function of the state
    np.testing.assert_allclose(a[:, :45], clean[:, :45], atol=0)
    err = a[:, 45:] - clean[:, 45:]
    assert 0.035 < err.std() < 0.065 and abs(err.mean()) < 0.015  # 3 x 153 draws of N(0, 0.05)
    assert not np.allclose(err[0], err[1])  # another state, other noise

    tiled = WalkerEnv(CFG._replace(observation="perceptive", tiles=3))
    bank = tiled.make_bank(terrains)
    for i in (0, 2):
        x0, y0 = tiled.tile_origin(i)
        d = jax.tree.map(lambda v: v[i], state.data)
        moved = d.replace(qpos=d.qpos.at[0].add(x0).at[1].add(y0))
        np.testing.assert_allclose(np.asarray(jax.jit(tiled._obs)(moved, bank.at(i))), clean[i], atol=2e-5)


def test_observation_fields_and_old_records():
    """What a walker observes, from a config or a policy's recorded walker_config: blind carries no grid, a record
    without the field is blind (or perceptive where it said height_scan: true), the robot's grid fills in;
    ``scan_size``: the scan's entries at the end of the observation (0 blind)."""
    from jaxterrain.walker import observation_fields, observation_label, scan_size, with_observation

    assert observation_fields(CFG) == {"observation": "blind"}
    seeing = observation_fields(with_observation(CFG, "perceptive"))
    assert seeing == {"observation": "perceptive", "scan_x": (-0.4, 1.2), "scan_y": (-0.4, 0.4), "scan_points": (17, 9)}
    assert observation_fields({"height_scan": False, "scan_x": [0.0, 1.4]}) == {"observation": "blind"}
    assert observation_fields({"observation": "perceptive", "scan_points": [17, 9]}) == seeing
    assert observation_fields({"height_scan": True, "robot": "ant"})["scan_points"] == (17, 11)
    assert observation_label(seeing) == "perceptive (17 x 9 heights, x -0.4..1.2 m, y -0.4..0.4 m)"
    assert scan_size(CFG) == 0 and scan_size(with_observation(CFG, "perceptive")) == 153
    assert scan_size(with_observation(CFG, "perceptive")._replace(robot="ant")) == 17 * 11
    with pytest.raises(ValueError, match="^observation must be one of blind, perceptive"):
        with_observation(CFG, "sighted")


def test_start_spread(fns):
    """start_spread > 0: the start y is uniform in +-spread from the reset key, the joint noise is that of the same key
    without a spread, and the spawn height follows the terrain under the shifted start; bad values name the field."""
    spread = 2.0
    env_s = WalkerEnv(CFG._replace(start_spread=spread))
    h, w = CFG.terrain_shape
    y = np.linspace(-3.1, 3.1, h, dtype=np.float32)
    ramp = jnp.asarray(np.repeat((0.1 + 0.05 * (y + 3.1))[:, None], w, axis=1))  # rises along +y (rows)
    keys = jax.random.split(jax.random.PRNGKey(5), 8)
    reset = jax.jit(jax.vmap(env_s.reset, in_axes=(0, None))).lower(keys, ramp).compile(FAST_COMPILE)
    state = reset(keys, ramp)
    y0 = np.asarray(state.data.qpos[:, 1])
    assert np.all(np.abs(y0) <= spread) and np.ptp(y0) > 1.0  # spread out, different per key
    np.testing.assert_allclose(np.asarray(state.data.qpos[:, 0]), env_s.x_start)
    feet = np.asarray(state.data.geom_xpos)[:, env_s._feet, 2] - env_s._foot_radius
    highest = 0.1 + 0.05 * (y0 + 0.25 + 3.1)  # the spawn patch reaches 0.25 m up the ramp
    np.testing.assert_allclose(feet.min(axis=1), highest + CFG.spawn_clearance, atol=2e-3)
    plain = fns[0](keys[:3], jnp.stack([ramp] * 3))  # the default env (compiled once for the module): y = 0
    np.testing.assert_array_equal(np.asarray(plain.data.qpos[:, 7:]), np.asarray(state.data.qpos[:3, 7:]))
    np.testing.assert_array_equal(np.asarray(plain.data.qpos[:, 1]), 0.0)
    for bad in (-0.5, float("nan"), 2.5):  # 2.5 > radius_y - side_margin - 0.5 = 2.3
        with pytest.raises(ValueError, match="start_spread"):
            WalkerEnv(CFG._replace(start_spread=bad))
