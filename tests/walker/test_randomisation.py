"""Physics randomisation (``WalkerConfig.randomisation``, :mod:`jaxterrain.walker.randomisation`): off changes
nothing; each randomisation reaches what it should and only that; the same key gives the same walk.

The plumbing tests step the walker with a stand-in for ``mjx.step`` that records the model it is given (its masses,
friction and motor gains) in the data and leaves the state as it was (and without ``mjx.kinematics``): what the
physics would see, without compiling the physics (seconds, not minutes, on a CPU). The real physics is the slow test at the end."""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxterrain.walker import (RANDOMISATION_PRESETS, Randomisation, TerrainScale, WalkerConfig, WalkerEnv,
                               parse_randomisation, randomisation_from_json, randomisation_json, randomisation_label,
                               resolve_config)
from jaxterrain.walker import env as env_module
from jaxterrain.walker import randomisation as rnd

TINY = WalkerConfig(terrain_shape=(16, 32), scale=TerrainScale(cell_size=0.2, height=0.5), episode_length=30)
ALL = "friction=0.5:1.25,mass=0.9:1.1,added-mass=-1:1,motor=0.8:1.2,obs-noise=0.01,delay=1:2,push=3:0.5"


def test_specs_presets_and_labels():
    r = parse_randomisation("friction=0.5:1.25,mass=0.9:1.1,motor=0.9:1.1,obs-noise=0.01,delay=1,push=200:0.5")
    assert r == Randomisation(friction=(0.5, 1.25), mass=(0.9, 1.1), motor=(0.9, 1.1), obs_noise=0.01, delay=(1, 1),
                              push_every=200, push_velocity=0.5)
    assert parse_randomisation("legged-gym") == RANDOMISATION_PRESETS["legged-gym"] == Randomisation(
        friction=(0.5, 1.25), added_mass=(-1.0, 1.0), push_every=1000, push_velocity=1.0)
    assert parse_randomisation("legged-gym,friction=0.8,obs-noise=0.02") == RANDOMISATION_PRESETS[
        "legged-gym"]._replace(friction=(0.8, 0.8), obs_noise=0.02)  # later items override; one value = both ends
    assert parse_randomisation("friction=0.5:1,off") == parse_randomisation(None) == Randomisation()
    assert not rnd.is_active(Randomisation()) and rnd.is_active(parse_randomisation("delay=0:1"))
    assert randomisation_label(Randomisation()) == "off"
    assert randomisation_label(parse_randomisation("legged-gym")) == ("friction 0.5-1.25, added mass -1-1 kg, push "
                                                                      "every 1000 steps at 1 m/s")


@pytest.mark.parametrize("spec, message", [
    ("friction=0:1", "randomisation.friction must be (low, high) with 0 < low <= high"),
    ("friction=1.2:0.5", "randomisation.friction must be (low, high) with 0 < low <= high"),
    ("mass=-1:1", "randomisation.mass must be (low, high) with 0 < low <= high"),
    ("motor=0.5:nan", "randomisation.motor must be"),
    ("obs-noise=-0.1", "randomisation.obs_noise must be a finite number >= 0"),
    ("delay=0.5", "item delay=0.5: env steps are integers"),
    ("delay=2:1", "randomisation.delay must be (low, high) env steps, integers with 0 <= low <= high <= 100"),
    ("delay=101", "randomisation.delay must be"),
    ("push=10", "item push=10: give EVERY:VELOCITY"),
    ("push=10:0", "randomisation.push_every and push_velocity must both be > 0"),
    ("push=-5:1", "randomisation.push_every must be an integer >= 0"),
    ("fiction=1:2", "unknown item 'fiction=1:2'"),
    ("friction=a:b", "item friction=a:b: 'a' is not a number"),
    ("", "a randomisation spec is a preset"),
])
def test_bad_specs_name_the_field_and_its_range(spec, message):
    with pytest.raises(ValueError) as err:
        parse_randomisation(spec)
    assert str(err.value).startswith(message) and "\n" not in str(err.value)


def test_config_checks_the_randomisation_and_the_torso_mass():
    with pytest.raises(ValueError, match=r"^randomisation\.mass must be"):
        resolve_config(TINY._replace(randomisation=Randomisation(mass=(0.0, 1.0))))
    with pytest.raises(ValueError, match=r"^randomisation\.added_mass must be \(low, high\) kg with low > -8\.91"):
        WalkerEnv(TINY._replace(randomisation=Randomisation(added_mass=(-9.0, 1.0))))
    # resolved configs hold floats (hashable, and equal however they were written)
    assert resolve_config(TINY._replace(randomisation=Randomisation(friction=(1, 2)))).randomisation.friction == (1.0,
                                                                                                                  2.0)


def test_json_round_trip_and_off_records_nothing():
    r = parse_randomisation(ALL)
    assert randomisation_from_json(json.loads(json.dumps(randomisation_json(r)))) == r
    assert randomisation_json(Randomisation()) is None and randomisation_from_json(None) == Randomisation()
    with pytest.raises(ValueError, match="unknown field"):
        randomisation_from_json({"gravity": [0.9, 1.1]})


# ----------------------------------------------------------------------------------------------------------------
# The env, with mjx.step replaced by a recorder of the model it gets
# ----------------------------------------------------------------------------------------------------------------
class _Recorder:
    """``mjx`` with ``step`` recording the model: ``xfrc_applied[:, 0]`` body masses, ``[:, 1]`` the first
    inertia column, ``[:, 2]`` the first 14 geoms' sliding friction, ``qfrc_applied[:nu]`` the motor gains; the
    state is left as it was (time advances). ``kinematics`` is left out too (the spawn height is then not the
    robot's: these tests are about the plumbing)."""

    def __getattr__(self, name):
        return getattr(_REAL_MJX, name)

    @staticmethod
    def kinematics(m, d):
        return d

    @staticmethod
    def step(m, d):
        nb = m.body_mass.shape[0]
        rec = jnp.zeros_like(d.xfrc_applied)
        rec = rec.at[:, 0].set(m.body_mass).at[:, 1].set(m.body_inertia[:, 0]).at[:, 2].set(m.geom_friction[:nb, 0])
        gains = d.qfrc_applied.at[:m.actuator_gainprm.shape[0]].set(m.actuator_gainprm[:, 0])
        return d.replace(xfrc_applied=rec, qfrc_applied=gains, time=d.time + m.opt.timestep)


_REAL_MJX = env_module.mjx


def _walk(env, keys, actions):
    """Reset ``len(keys)`` envs on flat ground and step them with ``actions`` [T, N, A]: the states [T + 1]."""
    terrain = env.flat_terrain()
    reset = jax.jit(jax.vmap(env.reset, in_axes=(0, None)))
    step = jax.jit(jax.vmap(env.step, in_axes=(0, 0, None)))
    states = [reset(keys, terrain)]
    for a in actions:
        states.append(step(states[-1], a, terrain))
    return states


@pytest.fixture(scope="module")
def recorded():
    """(env off, env with every randomisation, their walks with the same keys and actions), under the recorder."""
    mp = pytest.MonkeyPatch()
    mp.setattr(env_module, "mjx", _Recorder())
    try:
        off = WalkerEnv(TINY)
        on = WalkerEnv(TINY._replace(randomisation=parse_randomisation(ALL)))
        keys = jax.random.split(jax.random.PRNGKey(3), 4)
        actions = jax.random.uniform(jax.random.PRNGKey(4), (7, 4, off.action_size), minval=-1.0, maxval=1.0)
        yield off, on, actions, _walk(off, keys, actions), _walk(on, keys, actions), _walk(on, keys, actions)
    finally:
        mp.undo()


def test_off_state_has_no_randomisation_and_steps_the_shared_model(recorded):
    off, _, actions, walk, _, _ = recorded
    assert all(s.random is None for s in walk)
    assert len(jax.tree.leaves(walk[0])) == len(jax.tree.leaves(walk[0]._replace(random=None)))
    m = off.mj_model
    rec = np.asarray(walk[-1].data.xfrc_applied)
    np.testing.assert_array_equal(rec[..., 0], np.broadcast_to(m.body_mass.astype(np.float32), rec.shape[:2]))
    np.testing.assert_array_equal(np.asarray(walk[-1].data.qfrc_applied)[:, :m.nu], 1.0)
    np.testing.assert_allclose(np.asarray(walk[-1].data.ctrl), np.asarray(actions[-1]) * 0.4, atol=1e-6)  # now
    np.testing.assert_array_equal(np.asarray(walk[3].data.qvel), np.asarray(walk[0].data.qvel))  # no push


def test_friction_masses_and_motors_reach_the_model_the_step_uses(recorded):
    off, on, _, _, walk, _ = recorded
    m, d = on.mj_model, walk[-1].random
    rec, gains = np.asarray(walk[-1].data.xfrc_applied), np.asarray(walk[-1].data.qfrc_applied)[:, :m.nu]
    mass = np.asarray(d.mass)
    np.testing.assert_allclose(rec[..., 0], m.body_mass[None] * mass, rtol=1e-6)
    np.testing.assert_allclose(rec[..., 1], m.body_inertia[None, :, 0] * mass, rtol=1e-6)
    np.testing.assert_allclose(rec[..., 2], np.asarray(d.friction)[:, None] * m.geom_friction[None, :m.nbody, 0],
                               rtol=1e-6)
    np.testing.assert_allclose(gains, np.broadcast_to(np.asarray(d.motor)[:, None], gains.shape), rtol=1e-6)
    friction, motor = np.asarray(d.friction), np.asarray(d.motor)
    assert np.all((0.5 <= friction) & (friction <= 1.25)) and len(set(friction.tolist())) == 4  # one draw per env
    assert np.all((0.8 <= motor) & (motor <= 1.2))
    # mass: a draw per body in [0.9, 1.1], the torso's times (1 + U(-1, 1) kg / its 8.91 kg)
    others = np.delete(mass, on._torso, axis=1)
    assert np.all((0.9 <= others) & (others <= 1.1)) and len(set(others[0].tolist())) == others.shape[1]
    torso = mass[:, on._torso]
    assert np.all((0.9 * (1 - 1 / 8.91) - 1e-6 <= torso) & (torso <= 1.1 * (1 + 1 / 8.91) + 1e-6))


def test_the_start_pose_of_a_key_is_the_same_with_randomisation(recorded):
    _, _, _, off_walk, on_walk, _ = recorded
    np.testing.assert_array_equal(np.asarray(on_walk[0].data.qpos), np.asarray(off_walk[0].data.qpos))
    np.testing.assert_array_equal(np.asarray(on_walk[0].data.qvel), np.asarray(off_walk[0].data.qvel))


def test_delay_applies_the_action_of_delay_steps_before(recorded):
    _, on, actions, _, walk, _ = recorded
    delay = np.asarray(walk[0].random.delay)
    assert set(delay.tolist()) <= {1, 2}
    acts = np.concatenate([np.zeros((2,) + actions.shape[1:], np.float32), np.asarray(actions)])  # zeros before
    for t in range(1, len(walk)):
        ctrl = np.asarray(walk[t].data.ctrl)
        for n in range(ctrl.shape[0]):
            np.testing.assert_allclose(ctrl[n], acts[t + 1 - delay[n], n] * 0.4, atol=1e-6)


def test_a_push_changes_the_torso_velocity_at_the_push_step_only(recorded):
    _, on, _, _, walk, _ = recorded
    phase = np.asarray(walk[0].random.push_phase)
    assert np.all((0 <= phase) & (phase < 3))
    for t in range(1, len(walk)):
        before, after = np.asarray(walk[t - 1].data.qvel), np.asarray(walk[t].data.qvel)  # the stand-in keeps qvel
        np.testing.assert_array_equal(after[:, 2:], before[:, 2:])
        kicked = (t + phase) % 3 == 0
        change = after[:, :2] - before[:, :2]
        assert np.all(np.abs(change[kicked]) > 0) and np.all(np.abs(change[kicked]) <= 0.5 + 1e-6)
        np.testing.assert_array_equal(change[~kicked], 0.0)


def test_observation_noise_is_gaussian_fresh_each_step_and_only_on_the_observation(recorded):
    _, on, _, off_walk, walk, _ = recorded
    terrain = on.flat_terrain()
    clean = jax.vmap(on._obs, in_axes=(0, None))
    noise = [np.asarray(s.obs) - np.asarray(clean(s.data, terrain)) for s in walk]
    allnoise = np.concatenate([n.ravel() for n in noise])
    assert 0.007 < allnoise.std() < 0.013 and abs(allnoise.mean()) < 0.002
    assert not np.array_equal(noise[1], noise[2])
    np.testing.assert_array_equal(np.asarray(off_walk[0].obs), np.asarray(clean(off_walk[0].data, terrain)))


def test_the_same_key_gives_the_same_randomised_walk(recorded):
    _, _, _, _, walk, again = recorded
    for a, b in zip(walk, again):
        jax.tree.map(np.testing.assert_array_equal, a, b)
    assert not np.array_equal(np.asarray(walk[0].random.seed[0]), np.asarray(walk[0].random.seed[1]))


# ----------------------------------------------------------------------------------------------------------------
# The real physics (compiles MJX twice: minutes on a CPU)
# ----------------------------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_physics_identity_randomisation_is_the_nominal_walk_and_friction_changes_it():
    """Randomisation at scale 1 everywhere (draws in the state, model fields replaced) steps exactly the nominal
    walker; a low friction walks differently from the same key."""
    keys = jax.random.split(jax.random.PRNGKey(0), 2)
    actions = jax.random.uniform(jax.random.PRNGKey(1), (6, 2, 17), minval=-1.0, maxval=1.0)
    nominal = _walk(WalkerEnv(TINY), keys, actions)
    identity = _walk(WalkerEnv(TINY._replace(randomisation=parse_randomisation(
        "friction=1:1,mass=1:1,motor=1:1,delay=0"))), keys, actions)
    for a, b in zip(nominal, identity):
        jax.tree.map(np.testing.assert_array_equal, a._replace(random=None), b._replace(random=None))
    slippery = _walk(WalkerEnv(TINY._replace(randomisation=parse_randomisation("friction=0.05:0.05"))), keys, actions)
    assert not np.array_equal(np.asarray(slippery[-1].data.qpos), np.asarray(nominal[-1].data.qpos))
