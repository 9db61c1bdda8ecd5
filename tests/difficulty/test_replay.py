"""Sim2sim: MuJoCo's C engine walks the walker's walks from MJX's own starts (``walker.mujoco_c``,
``difficulty.replay``). On flat ground the two engines share the model, the start and the policy, so their first
steps agree to within the engines' arithmetic (C MuJoCo in float64, MJX-JAX in float32, the same solver settings but
not the same solver code): the torso within 5 mm over the first 10 env steps (measured 2026-11-29 on a CPU: 1.3 mm
after 10 steps, 0.07 mm after one)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxterrain import difficulty, rl
from jaxterrain.difficulty import replay
from jaxterrain.walker import WalkerConfig, WalkerEnv
from jaxterrain.walker.mujoco_c import CEngine

SIDE = 48  # the smallest square map the humanoid walks is 39 pixels
STEPS = 10


@pytest.fixture(scope="module")
def setup():
    pol = rl.load_policy()
    cfg = difficulty.default_env_config((SIDE, SIDE), policy=pol)._replace(episode_length=STEPS)
    return pol, cfg, WalkerEnv(cfg)


@pytest.mark.slow  # 10-70 s on 2 CPU cores; the default suite keeps under 15 min (2026-11-29)
def test_mujoco_c_starts_where_mjx_starts_and_keeps_close_on_flat_ground(setup):
    pol, cfg, env = setup
    engine = CEngine(env)
    flat = np.zeros((2, SIDE, SIDE), np.float32)
    keys = jax.random.split(jax.random.key(3), 2)
    start = engine.starts(keys, flat)
    act = jax.jit(pol)
    walks = engine.walk(lambda obs: act(obs), flat, start, record=STEPS)

    state = jax.jit(jax.vmap(env.reset))(keys, jnp.asarray(flat))
    np.testing.assert_allclose(start.qpos, np.asarray(state.data.qpos), atol=1e-6)  # the same start, walk for walk
    step = jax.jit(jax.vmap(env.step))
    torso = []
    for _ in range(STEPS):
        state = step(state, act(state.obs), jnp.asarray(flat))
        torso.append(np.asarray(state.data.qpos[:, :3]))
    gap = np.abs(np.stack(torso) - walks.trace[:, :, :3]).max()
    assert gap < 5e-3, f"MuJoCo C and MJX torsos {gap:.2e} m apart within {STEPS} steps on flat ground"
    assert gap > 0  # two engines, not one run twice
    # the same termination and distance: the walks lasted the episode, and went as far within 1 %
    assert walks.steps.tolist() == [STEPS, STEPS] and not walks.failed.any()
    np.testing.assert_allclose(walks.distance, np.asarray(state.distance), atol=0.01)


def test_protocol_walks_are_the_turned_maps_walked_from_the_protocols_keys(setup):
    pol, cfg, _ = setup
    h = np.zeros((1, SIDE, SIDE), np.float32)
    h[0, :, SIDE // 2:] = 0.05  # a 5 cm step half way
    protocol = difficulty.Protocol(4, 2, headings=2)
    key = jax.random.key(1)
    here = replay.mujoco_distances(h, key, pol, protocol, env_config=cfg)
    assert here.distances.shape == here.steps.shape == (1, 4) and here.seconds > 0
    assert np.all((here.distances >= 0) & (here.distances <= 1)) and np.all(here.steps == STEPS)
    fit = replay.mujoco_evaluate(h, key, pol, protocol, env_config=cfg)
    np.testing.assert_array_equal(fit, np.asarray(difficulty.aggregate(here.distances, protocol)))


@pytest.mark.slow  # two spawned processes import JAX and compile (~35 s on a loaded 2-core CPU)
def test_protocol_walks_on_a_process_pool_are_those_of_this_process(setup):
    pol, cfg, _ = setup
    h = np.zeros((1, SIDE, SIDE), np.float32)
    h[0, :, SIDE // 2:] = 0.05
    protocol = difficulty.Protocol(4, 2, headings=2)
    key = jax.random.key(1)
    here = replay.mujoco_distances(h, key, pol, protocol, env_config=cfg)
    pooled = replay.mujoco_distances(h, key, pol, protocol, env_config=cfg, workers=2)
    np.testing.assert_allclose(pooled.distances, here.distances, atol=1e-4)  # the same walks, other processes
    assert pooled.seconds > 0 and pooled.steps.sum() == here.steps.sum()


def test_the_c_engine_refuses_what_it_cannot_walk(setup):
    pol, cfg, _ = setup
    h = np.zeros((1, SIDE, SIDE), np.float32)
    with pytest.raises(ValueError, match="backend='jax' and tiles=0"):
        replay.mujoco_distances(h, jax.random.key(0), pol, env_config=cfg._replace(backend="warp", tiles=1))
    with pytest.raises(ValueError, match="workers must be an int >= 1"):
        replay.mujoco_distances(h, jax.random.key(0), pol, env_config=cfg, workers=0)
    with pytest.raises(ValueError, match="tiles=0"):
        CEngine(WalkerEnv(WalkerConfig(terrain_shape=(SIDE, SIDE), tiles=1)))
