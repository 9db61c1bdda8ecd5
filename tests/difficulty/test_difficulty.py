"""difficulty.evaluate on CPU: 32 x 32 heightmaps at 0.2 m cells, 300-step episodes, ONE compiled rollout per policy
kind shared by every test (MJX compiles slowly on a CPU: each distinct rollout program costs ~30 s): the linear policy
takes its parameters as data (NaN / huge / zero actions do not re-compile), and the shipped policy's four-heading walks
serve both the flat-ground and the wall tests (one module fixture)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxterrain import difficulty
from jaxterrain.terrain import TerrainScale
from jaxterrain.walker import WalkerConfig
from jaxterrain import walker
from jaxterrain.difficulty import evaluation
from jaxterrain.runtime import xla

SCALE = TerrainScale(cell_size=0.2, height=0.5)
# 300 steps = 4.5 s: the shipped policy walks ~2.9 m/s, the track is 5.2 m; walkers that fall end earlier
CFG = WalkerConfig(terrain_shape=(32, 32), scale=SCALE, episode_length=300)
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
    # the zero-torque walker collapses (the episode ends when it falls): it does not reach the far edge
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
    d_all, n_all = evaluation._compiled(CFG, ATTEMPTS, linear_policy, True, None)(terrains, key, params)  # shared
    env = walker.make_env(CFG)
    pooled = jax.jit(lambda t, k, p, needed, priority: walker.batched_distances(
        env, linear_policy, t, k, ATTEMPTS, p, slots=3, needed=needed, priority=priority)).lower(
        terrains, key, params, jnp.ones(2, bool), jnp.zeros(2)).compile(FAST_COMPILE)  # one compile, 3 calls
    d_pool, n_pool = pooled(terrains, key, params, jnp.array([False, True]), jnp.zeros(2))
    assert len(set(np.asarray(n_all[1]).tolist())) > 1  # the episodes really end at different steps
    np.testing.assert_array_equal(np.asarray(n_pool[1]), np.asarray(n_all[1]))
    np.testing.assert_allclose(np.asarray(d_pool[1]), np.asarray(d_all[1]), atol=1e-5)
    np.testing.assert_array_equal(np.asarray(n_pool[0]), 0)
    np.testing.assert_array_equal(np.asarray(d_pool[0]), 0.0)
    # both terrains walked, in two queue orders (terrain 1 first, then terrain 0 first): same rollouts either way
    both = jnp.array([True, True])
    d1, n1 = pooled(terrains, key, params, both, jnp.array([0.0, 1.0]))
    d0, n0 = pooled(terrains, key, params, both, walker.smoothness_priority(terrains))  # flat first
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
    queue, queued = walker.job_queue(needed, jnp.array([0.0, 2.0, 5.0, 2.0, jnp.nan, -1.0]))
    assert queue.tolist() == [1, 3, 0, 5, 4, 2] and int(queued) == 5
    queue, queued = walker.job_queue(needed)
    assert queue.tolist() == [0, 1, 3, 4, 5, 2] and int(queued) == 5
    ramp = jnp.broadcast_to(jnp.linspace(0.0, 1.0, 8), (8, 8))
    p = walker.smoothness_priority(jnp.stack([jnp.zeros((8, 8)), ramp, 2.0 * ramp]))
    np.testing.assert_allclose(np.asarray(p), [0.0, -1.0 / 7.0, -2.0 / 7.0], rtol=1e-6)


def test_shipped_base_policy_walks_across_flat_ground(wall_and_flat, flat_pair):
    """The shipped policy (the default of evaluate) crosses a flat 6.2 m map, along +x and in every other heading;
    standing still does not (same 300-step episodes)."""
    maps, d = wall_and_flat
    fitness = difficulty.evaluate(maps, jax.random.PRNGKey(0), protocol=HEADINGS4, env_config=CFG)  # fixture's program
    np.testing.assert_array_equal(np.asarray(fitness), np.asarray(difficulty.aggregate(d, HEADINGS4)))
    assert float(fitness[1]) >= 0.9
    assert float(difficulty.heading_scores(d, HEADINGS4)[1, 0]) >= 0.9  # +x (the paper's heading): both walks
    still = difficulty.evaluate(flat_pair, jax.random.PRNGKey(0), attempts=ATTEMPTS, best=BEST, env_config=CFG,
                                policy=linear_policy, policy_params=_params())  # the with-params program
    assert np.all(np.asarray(still) < 0.2)


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


# ----------------------------------------------------------------------------------------------------------------
# The protocol
# ----------------------------------------------------------------------------------------------------------------
def _wall_map():
    """32 x 32 map (0.2 m cells): flat, with a 0.5 m wall across x (every row) at x = 1.1 .. 1.5 m (columns 21-23)."""
    m = np.zeros((32, 32), np.float32)
    m[:, 21:24] = 1.0
    return m


HEADINGS4 = difficulty.Protocol(attempts=8, best=2, headings=4)


@pytest.fixture(scope="module")
def wall_and_flat():
    """``(maps, distances)``: the shipped policy's walks under :data:`HEADINGS4` on [wall map, flat map] (300-step
    episodes): one compiled program, shared by the flat-ground and the wall tests."""
    maps = jnp.stack([jnp.asarray(_wall_map()), jnp.zeros((32, 32))])
    return maps, difficulty.rollout_distances(maps, jax.random.PRNGKey(0), env_config=CFG, protocol=HEADINGS4)


def test_protocol_defaults_and_validation():
    assert difficulty.Protocol() == difficulty.PAPER == (20, 5, 1, 0.0, "mean")
    assert difficulty.Protocol().validate() == difficulty.PAPER and difficulty.HEADINGS.per_heading == 20
    bad = [(dict(attempts=0), "protocol.attempts"), (dict(attempts=2.0), "protocol.attempts"),
           (dict(headings=3), "protocol.headings"), (dict(attempts=10, best=2, headings=4), "protocol.attempts"),
           (dict(attempts=20, best=6, headings=4), "protocol.best"), (dict(best=0), "protocol.best"),
           (dict(start_spread=-1.0), "protocol.start_spread"), (dict(start_spread=float("inf")), "start_spread"),
           (dict(rule="max"), "protocol.rule")]
    for fields, match in bad:
        with pytest.raises(ValueError, match=match):
            difficulty.Protocol(**fields).validate()
    flat = jnp.zeros((1, 32, 32))
    with pytest.raises(ValueError, match="attempts=10 conflicts"):
        difficulty.evaluate(flat, jax.random.PRNGKey(0), attempts=10, protocol=difficulty.PAPER)
    with pytest.raises(ValueError, match="protocol.best"):
        difficulty.evaluate(flat, jax.random.PRNGKey(0), protocol=difficulty.Protocol(4, 5))
    with pytest.raises(ValueError, match="square"):
        difficulty.evaluate(jnp.zeros((1, 32, 48)), jax.random.PRNGKey(0), protocol=difficulty.Protocol(4, 1, 4))
    with pytest.raises(ValueError, match="size"):
        difficulty.fitness_fn(2)
    with pytest.raises(ValueError, match="start_spread"):  # an env's own spread must agree with the protocol's
        difficulty.protocol_env_config(CFG._replace(start_spread=1.0), difficulty.Protocol(start_spread=2.0))


def test_rotations():
    """Heading k walks the map turned by rot90(k): +x of the turned map is the original's +x, +y, -x, -y."""
    n = 8
    ramp_x = np.tile(np.arange(n, dtype=np.float32), (n, 1))  # [row = y, column = x]: rises along +x
    turned = np.asarray(difficulty.rotate_headings(jnp.stack([ramp_x, ramp_x.T]), 4)).reshape(2, 4, n, n)
    rises_x = lambda m: np.all(np.diff(m, axis=1) > 0)  # noqa: E731
    rises_y = lambda m: np.all(np.diff(m, axis=0) > 0)  # noqa: E731
    falls_x = lambda m: np.all(np.diff(m, axis=1) < 0)  # noqa: E731
    falls_y = lambda m: np.all(np.diff(m, axis=0) < 0)  # noqa: E731
    np.testing.assert_array_equal(turned[0, 0], ramp_x)
    assert falls_y(turned[0, 1]) and falls_x(turned[0, 2]) and rises_y(turned[0, 3])  # the +x ramp, turned
    assert rises_x(turned[1, 1]) and falls_x(turned[1, 3])  # the +y ramp: uphill when walking the original's +y
    assert rises_x(turned[0, 0]) and rises_y(turned[1, 0])
    two = np.asarray(difficulty.rotate_headings(jnp.asarray(ramp_x)[None], 2))
    np.testing.assert_array_equal(two, turned[0, :2])  # 2 headings: +x and +y
    # a wall across x lies on the walker's centre line (row H / 2) in headings 0 and 2 only
    walls = np.asarray(difficulty.rotate_headings(jnp.asarray(_wall_map())[None], 4))
    assert [bool(walls[k, 16].max() > 0) for k in range(4)] == [True, False, True, False]
    with pytest.raises(ValueError, match="square"):
        difficulty.rotate_headings(jnp.zeros((1, 4, 6)), 4)


def test_aggregate_rules():
    d = jnp.array([[1.0, 0.8, 0.2, 0.4, 1.0, 1.0, 0.0, 0.1]])  # 4 headings x 2 walks, heading-major
    p = difficulty.Protocol(8, 1, 4)
    np.testing.assert_allclose(np.asarray(difficulty.heading_scores(d, p)), [[1.0, 0.4, 1.0, 0.1]])
    np.testing.assert_allclose(np.asarray(difficulty.aggregate(d, p)), [0.625], rtol=1e-6)
    np.testing.assert_allclose(np.asarray(difficulty.aggregate(d, p._replace(rule="min"))), [0.1])
    np.testing.assert_allclose(np.asarray(difficulty.aggregate(d, p._replace(best=2))), [(0.9 + 0.3 + 1 + 0.05) / 4],
                               rtol=1e-6)
    one = difficulty.Protocol(8, 3)
    np.testing.assert_array_equal(np.asarray(difficulty.aggregate(d, one)), np.asarray(difficulty.best_of(d, 3)))


def test_default_protocol_is_the_existing_computation(flat_pair):
    """evaluate(protocol=Protocol(4, 2)) and evaluate(4, 2) give exactly the existing pure computation
    (batched_distances, then best_of) on the same key; the program is the one the other tests compile."""
    params = _params(gain=0.8, bias=0.05)
    bumpy = jnp.stack([flat_pair[0], jnp.asarray(np.random.default_rng(1).random((32, 32)) * 0.5, jnp.float32)])
    key = jax.random.PRNGKey(11)
    d, _ = evaluation._compiled(CFG, ATTEMPTS, linear_policy, True, None)(bumpy * SCALE.height, key, params)
    want = np.asarray(difficulty.best_of(d, BEST))
    kw = dict(policy=linear_policy, env_config=CFG, policy_params=params)
    got = difficulty.evaluate(bumpy, key, protocol=difficulty.Protocol(ATTEMPTS, BEST), **kw)
    np.testing.assert_array_equal(np.asarray(got), want)
    np.testing.assert_array_equal(np.asarray(difficulty.evaluate(bumpy, key, ATTEMPTS, BEST, **kw)), want)


# cheaper XLA CPU compiles for a program only compared with itself (as in test_walker.py): lowest backend
# optimisation, and the classic elemental emitter instead of the fusion emitters
FAST_COMPILE = xla.known_options({"xla_backend_optimization_level": 0, "xla_llvm_disable_expensive_passes": True,
                "xla_cpu_use_fusion_emitters": False})


@pytest.mark.slow
def test_fitness_fn_is_the_paper_computation():
    """fitness_fn(size, Protocol(2, 1)) inside a jit is bit for bit the computation archive.difficulty_fitness had
    (the shipped policy, batched_distances, best_of) on the same key. Slow: its own MJX compile, 66 s on 2 CPU
    cores; ``evolve``'s smoke tests run fitness_fn end to end in the default suite."""
    maps = jnp.stack([jnp.zeros((32, 32)), jnp.asarray(np.random.default_rng(2).random((32, 32)) * 0.6)])
    fit = difficulty.fitness_fn(32, difficulty.Protocol(2, 1), scale=SCALE)
    assert difficulty.fitness_fn(32, difficulty.Protocol(2, 1), scale=SCALE) is fit  # cached per arguments
    policy = difficulty.default_policy()
    env = walker.make_env(difficulty.default_env_config((32, 32), SCALE, policy))

    def old(h, key):
        return difficulty.best_of(walker.batched_distances(env, policy, h * SCALE.height, key, 2)[0], 1)

    key = jax.random.PRNGKey(4)
    both = jax.jit(lambda h, k: (fit(h, k), old(h, k))).lower(maps, key).compile(FAST_COMPILE)  # one compile
    new, want = both(maps, key)
    np.testing.assert_array_equal(np.asarray(new), np.asarray(want))
    assert float(new[0]) > 0.9 and float(new[1]) < float(new[0])


def test_four_headings_see_a_wall_across_x(wall_and_flat):
    """The shipped policy under 4 headings: the wall across x stops the walks of headings 0 (+x) and 2 (-x), not
    those along y; flat ground is easy in every heading."""
    protocol = HEADINGS4
    _, d = wall_and_flat
    scores = np.asarray(difficulty.heading_scores(d, protocol))  # [2 maps, 4 headings]
    assert np.all(scores[0, [0, 2]] < 0.8) and np.all(scores[0, [1, 3]] >= 0.9), scores  # the wall is at 0.71-0.79
    assert scores[0, 2] < scores[0, 0]  # the wall is 1.1 m after the start going -x, 3.7 m going +x
    assert np.all(scores[1] >= 0.9), scores
    fit = np.asarray(difficulty.aggregate(d, protocol))
    np.testing.assert_allclose(fit, scores.mean(axis=1), rtol=1e-6)
    assert fit[0] < 0.8 <= 0.9 <= fit[1]
