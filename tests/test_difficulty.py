"""difficulty.evaluate on CPU: 32 x 32 heightmaps at 0.2 m cells, 60-step episodes, ONE compiled rollout shared by
every test (the policy takes its parameters as data: NaN / huge / zero actions do not re-compile)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxterrain import difficulty
from jaxterrain.terrain import TerrainScale
from jaxterrain.walker import WalkerConfig

SCALE = TerrainScale(cell_size=0.2, height=0.5)
CFG = WalkerConfig(terrain_shape=(32, 32), scale=SCALE, episode_length=60)
ATTEMPTS, BEST = 4, 2


def linear_policy(params, obs):
    """action = gain * joint angles + bias (env clips to [-1, 1]; NaN bias = NaN actions)."""
    return params["gain"] * obs[5:22] + params["bias"]


def _params(gain=0.0, bias=0.0):
    return {"gain": jnp.float32(gain), "bias": jnp.full(17, bias, jnp.float32)}


def _run(heightmaps, params, key=0, chunk=None):
    return difficulty.rollout_distances(jnp.asarray(heightmaps, jnp.float32), jax.random.PRNGKey(key), ATTEMPTS,
                                        policy=linear_policy, env_config=CFG, policy_params=params, chunk=chunk)


@pytest.fixture(scope="module")
def flat_pair():
    return jnp.stack([jnp.zeros((32, 32)), jnp.zeros((32, 32))])


def test_best_of_arithmetic():
    d = jnp.array([[0.1, 0.9, 0.5, 0.3, 0.7, 0.2], [0.0, 0.0, 0.0, 0.0, 1.0, 0.4], [jnp.nan, 0.2, 0.2, 0.1, 0, 0]])
    np.testing.assert_allclose(np.asarray(difficulty.best_of(d, 2)), [0.8, 0.7, 0.2], rtol=1e-6)
    np.testing.assert_allclose(np.asarray(difficulty.best_of(d, 6)), [2.7 / 6, 1.4 / 6, 0.5 / 6], rtol=1e-6)
    twenty = jnp.arange(20, dtype=jnp.float32)[None] / 20.0  # best 5 of 0.00..0.95 = mean(0.75..0.95)
    np.testing.assert_allclose(np.asarray(difficulty.best_of(twenty, 5)), [0.85], rtol=1e-6)


def test_validation_errors(flat_pair):
    key = jax.random.PRNGKey(0)
    kw = dict(policy=linear_policy, env_config=CFG, policy_params=_params())
    with pytest.raises(ValueError, match=r"\[B, H, W\]"):
        difficulty.evaluate(jnp.zeros((32, 32)), key, **kw)
    with pytest.raises(ValueError, match="NaN"):
        difficulty.evaluate(flat_pair.at[0, 3, 3].set(jnp.nan), key, **kw)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        difficulty.evaluate(flat_pair + 1.5, key, **kw)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        difficulty.evaluate(flat_pair - 0.1, key, **kw)
    with pytest.raises(ValueError, match="terrain_shape"):
        difficulty.evaluate(jnp.zeros((2, 16, 16)), key, **kw)
    with pytest.raises(ValueError, match="best"):
        difficulty.evaluate(flat_pair, key, attempts=4, best=5, **kw)
    with pytest.raises(ValueError, match="attempts"):
        difficulty.evaluate(flat_pair, key, attempts=0, best=1, **kw)
    with pytest.raises(ValueError, match="scale"):
        difficulty.evaluate(flat_pair, key, scale=TerrainScale(0.1, 0.5), **kw)


def test_nan_and_huge_actions_are_safe(flat_pair):
    d = _run(flat_pair, _params(bias=float("nan")))
    np.testing.assert_array_equal(np.asarray(d), 0.0)  # failed attempts count 0
    fit = difficulty.evaluate(flat_pair, jax.random.PRNGKey(0), ATTEMPTS, BEST, policy=linear_policy,
                              env_config=CFG, policy_params=_params(bias=float("nan")))
    np.testing.assert_array_equal(np.asarray(fit), 0.0)
    d = _run(flat_pair, _params(gain=1e6, bias=1e9))  # bang-bang torques
    assert d.shape == (2, ATTEMPTS) and np.all(np.isfinite(np.asarray(d)))
    assert np.all((np.asarray(d) >= 0) & (np.asarray(d) <= 1))


def test_distances_deterministic_and_terrain_height_invariant(flat_pair):
    """Flat ground at 0 m and at 0.5 m gives the same rollouts (spawn follows the terrain): the terrain is wired."""
    low = np.asarray(_run(flat_pair, _params()))
    again = np.asarray(_run(flat_pair, _params()))
    np.testing.assert_array_equal(low, again)
    high = np.asarray(_run(flat_pair + 1.0, _params()))
    np.testing.assert_allclose(high, low, atol=2e-3)
    assert np.all((low >= 0) & (low <= 1))
    # the zero-torque walker collapses within 60 steps: it does not reach the far edge
    assert np.all(low < 0.2)
    other = np.asarray(_run(flat_pair, _params(), key=1))
    assert not np.array_equal(other, low)  # random joint initialisations differ per key


def test_chunked_matches_compiled_shape(flat_pair):
    three = jnp.concatenate([flat_pair, flat_pair[:1]])
    d = _run(three, _params(), chunk=2)  # 2 calls of the batch-2 compile, the last one padded
    assert d.shape == (3, ATTEMPTS) and np.all(np.isfinite(np.asarray(d)))
    # Chunk i is the unchunked call on its terrains with the i-th split key; padding does not change real rows.
    keys = jax.random.split(jax.random.PRNGKey(0), 2)
    run = lambda h, k: difficulty.rollout_distances(h, k, ATTEMPTS, policy=linear_policy,  # noqa: E731
                                                    env_config=CFG, policy_params=_params())
    np.testing.assert_array_equal(d[:2], run(three[:2], keys[0]))
    np.testing.assert_array_equal(d[2], run(jnp.stack([three[2], three[2]]), keys[1])[0])


def test_pooled_slots_give_the_same_rollouts(flat_pair):
    """3 env slots fed from the queue of the needed rollouts (refills after episodes of different lengths) give each
    rollout's distance and length as the all-at-once call does; terrains not needed are never walked (0, 0)."""
    bumpy = jnp.asarray(np.random.default_rng(0).random((32, 32)), jnp.float32) * 0.6
    terrains = jnp.stack([flat_pair[0], bumpy]) * SCALE.height
    params = _params(gain=0.8, bias=0.05)
    key = jax.random.PRNGKey(3)
    d_all, n_all = difficulty._compiled(CFG, ATTEMPTS, linear_policy, True, None)(terrains, key, params)  # shared
    env = difficulty.make_env(CFG)
    pooled = jax.jit(lambda t, k, p, needed, priority: difficulty.batched_distances(
        env, linear_policy, t, k, ATTEMPTS, p, slots=3, needed=needed, priority=priority))
    d_pool, n_pool = pooled(terrains, key, params, jnp.array([False, True]), jnp.zeros(2))
    assert len(set(np.asarray(n_all[1]).tolist())) > 1  # the episodes really end at different steps
    np.testing.assert_array_equal(np.asarray(n_pool[1]), np.asarray(n_all[1]))
    np.testing.assert_allclose(np.asarray(d_pool[1]), np.asarray(d_all[1]), atol=1e-5)
    np.testing.assert_array_equal(np.asarray(n_pool[0]), 0)
    np.testing.assert_array_equal(np.asarray(d_pool[0]), 0.0)
    # both terrains walked, in two queue orders (terrain 1 first, then terrain 0 first): same rollouts either way
    both = jnp.array([True, True])
    d1, n1 = pooled(terrains, key, params, both, jnp.array([0.0, 1.0]))
    d0, n0 = pooled(terrains, key, params, both, difficulty.smoothness_priority(terrains))  # flat first
    for d, n in ((d1, n1), (d0, n0)):
        np.testing.assert_array_equal(np.asarray(n), np.asarray(n_all))
        np.testing.assert_allclose(np.asarray(d), np.asarray(d_all), atol=1e-5)
    with pytest.raises(ValueError, match="slots"):
        difficulty.rollout_distances(terrains, key, ATTEMPTS, policy=linear_policy, env_config=CFG,
                                     policy_params=params, slots=0)


def test_job_queue_and_smoothness_priority():
    """The pool's queue: needed jobs first, higher priority first, ties in job order, NaN priority last among the
    needed; smoother terrains get higher priority."""
    needed = jnp.array([True, True, False, True, True, True])
    queue, queued = difficulty.job_queue(needed, jnp.array([0.0, 2.0, 5.0, 2.0, jnp.nan, -1.0]))
    assert queue.tolist() == [1, 3, 0, 5, 4, 2] and int(queued) == 5
    queue, queued = difficulty.job_queue(needed)
    assert queue.tolist() == [0, 1, 3, 4, 5, 2] and int(queued) == 5
    ramp = jnp.broadcast_to(jnp.linspace(0.0, 1.0, 8), (8, 8))
    p = difficulty.smoothness_priority(jnp.stack([jnp.zeros((8, 8)), ramp, 2.0 * ramp]))
    np.testing.assert_allclose(np.asarray(p), [0.0, -1.0 / 7.0, -2.0 / 7.0], rtol=1e-6)


def test_shipped_base_policy_walks_across_flat_ground():
    """The shipped policy (the default of evaluate) crosses a flat 6.2 m map; standing still does not."""
    cfg = CFG._replace(episode_length=300)  # 4.5 s: the policy walks ~2.9 m/s, the track is 5.2 m
    flat = jnp.zeros((1, 32, 32))
    fitness = difficulty.evaluate(flat, jax.random.PRNGKey(0), attempts=ATTEMPTS, best=BEST, env_config=cfg)
    assert float(fitness[0]) >= 0.9
    still = difficulty.evaluate(flat, jax.random.PRNGKey(0), attempts=ATTEMPTS, best=BEST, env_config=cfg,
                                policy=linear_policy, policy_params=_params())
    assert float(still[0]) < 0.2

def test_default_env_uses_the_policys_solver():
    from jaxterrain.walker import SOLVER_FAST, SOLVER_SOUND, SOLVER_XML, SolverOptions, parse_solver

    assert parse_solver("fast") == SOLVER_FAST and parse_solver("xml") == SOLVER_XML
    assert parse_solver("sound") == SOLVER_SOUND == SolverOptions("newton", 4, 16, False)
    assert parse_solver("4,16,0") == SolverOptions("newton", 4, 16, False)
    for bad in ("4,16", "a,b,c", "0,4,0", "4,16,2"):
        with pytest.raises(ValueError, match="solver"):
            parse_solver(bad)

    def policy(obs):
        return jnp.zeros(17)

    assert difficulty.policy_solver(policy) is None
    assert difficulty.default_env_config((32, 32), SCALE, policy).solver == SOLVER_SOUND
    policy.meta = {"walker_config": {"solver": SolverOptions("newton", 2, 8, False)._asdict()}}
    cfg = difficulty.default_env_config((32, 32), SCALE, policy)
    assert cfg.solver == SolverOptions("newton", 2, 8, False)
    assert cfg._replace(solver=SOLVER_SOUND) == WalkerConfig(terrain_shape=(32, 32), scale=SCALE)
    # the shipped base policy records the solver it was trained with
    assert difficulty.policy_solver(difficulty.default_policy()) == SOLVER_SOUND
