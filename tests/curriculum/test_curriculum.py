"""jaxterrain.curriculum: the IT&E GP against NumPy, UCB choice and removal rule, the whole loop on toy banks with a
fake deterministic harness (terrain order, stop conditions, hardest record), the roughness baseline, Table 2
extraction, resume, vmapped trials, no re-trace on terrain switches, and the ``learn`` command end to end."""

from __future__ import annotations

import json
import re
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxterrain.runtime import driver
from jaxterrain.qd import TerrainBank, cell_distance
from jaxterrain import curriculum as C
from jaxterrain.curriculum import gp
from jaxterrain.curriculum import outputs, run_config, runner
from jaxterrain.curriculum.selectors import selector_params as S_params
from jaxterrain.curriculum.presets import CPPN_ARCHIVE, FLAT_PRESETS

from curriculum_archives import tiny_archive_file, tree_equal, validated




# ---------------------------------------------------------------------------------------------------------------
# Toy banks and a fake harness
# ---------------------------------------------------------------------------------------------------------------
def toy_bank(fitness_grid: np.ndarray, descriptor0=None) -> TerrainBank:
    """A bank of every cell of a B x B grid: ``fitness_grid[b1, b0]`` is the prior; each terrain is a constant
    2 x 2 map holding its difficulty ``1 - prior``; points = bins / (B - 1)."""
    b = fitness_grid.shape[0]
    b0, b1 = np.meshgrid(np.arange(b), np.arange(b))
    bins = np.stack([b0.ravel(), b1.ravel()], -1).astype(np.int32)  # cell order b1 * B + b0
    fitness = fitness_grid.ravel().astype(np.float32)
    points = (bins / max(b - 1, 1)).astype(np.float32)
    desc = points.copy() if descriptor0 is None else np.stack([descriptor0, points[:, 1]], -1).astype(np.float32)
    maps = np.broadcast_to((1.0 - fitness)[:, None, None], (fitness.size, 2, 2)).astype(np.float32)
    return TerrainBank(jnp.asarray(maps), jnp.asarray(fitness), jnp.asarray(desc), jnp.asarray(points),
                       jnp.asarray(bins), jnp.asarray(cell_distance(bins)), jnp.arange(fitness.size, dtype=jnp.int32),
                       jnp.zeros(fitness.size, jnp.int32))


TRACES = {"train": 0}


def fake_harness(gain: float = 0.1) -> C.Harness:
    """Policy state {"skill", "resets"}: each chunk adds ``gain`` to the skill; fitness on a terrain of difficulty d
    is ``clip(1 - d + skill, 0, 1)`` (deterministic, keys ignored); a reset counts."""

    def train(policy, key, terrain):
        TRACES["train"] += 1
        return {"skill": policy["skill"] + gain, "resets": policy["resets"]}

    def evaluate(policy, key, terrain):
        return jnp.clip(1.0 - jnp.mean(terrain) + policy["skill"], 0.0, 1.0)

    def reset(policy, key, terrain):
        return {"skill": policy["skill"], "resets": policy["resets"] + 1}

    return C.Harness(train, evaluate, reset)


START = {"skill": jnp.zeros((), jnp.float32), "resets": jnp.zeros((), jnp.int32)}


def run_one(bank, config, harness, chunks, key=0):
    states = C.init_trials(jax.random.split(jax.random.key(key), 1), bank, START, config=config, harness=harness)
    return jax.tree.map(lambda x: x[0], C.make_runner(config, harness)(states, bank, chunks))


def small(selector="map", **kw) -> C.CurriculumConfig:
    base = dict(selector=selector, epochs_per_chunk=1, steps_per_epoch=8, max_epochs=40, max_evals=3,
                num_envs=2, unroll_length=2, num_unrolls=2, num_minibatches=1)
    return C.validate_config(C.CurriculumConfig.from_json_dict({**base, **kw}))  # the PPO fields flat, as learn


# ---------------------------------------------------------------------------------------------------------------
# GP
# ---------------------------------------------------------------------------------------------------------------
def numpy_posterior(x, y, prior_obs, cells, prior, rho=0.4, sigma_f=1.0, noise=1e-3):
    def k(a, b):
        d = np.sqrt(((a[:, None] - b[None]) ** 2).sum(-1))
        r = np.sqrt(5) * d / rho
        return sigma_f * (1 + r + r * r / 3) * np.exp(-r)

    kk = k(x, x) + noise * np.eye(len(x))
    ks = k(cells, x)
    mean = prior + ks @ np.linalg.solve(kk, y - prior_obs)
    var = sigma_f - np.einsum("nm,nm->n", ks, np.linalg.solve(kk, ks.T).T)
    return mean, var


def test_gp_posterior_matches_numpy_on_the_unmasked_observations():
    rng = np.random.default_rng(0)
    m, n = 8, 30
    obs_x, cells = rng.uniform(size=(m, 2)), rng.uniform(size=(n, 2))
    obs_y, obs_prior, prior = rng.uniform(size=m), rng.uniform(size=m), rng.uniform(size=n)
    mask = np.array([1, 0, 1, 1, 0, 0, 1, 1], bool)
    obs_x[~mask] = 123.0  # padding values must not matter
    params = gp.GPParams(rho=0.4, sigma_f=1.0, noise=1e-3)
    posterior = jax.jit(gp.posterior)
    f32 = lambda a: jnp.asarray(a, jnp.float32)  # noqa: E731
    mean, var = posterior(f32(obs_x), f32(obs_y), jnp.asarray(mask), f32(obs_prior), f32(cells), f32(prior), params)
    ref_mean, ref_var = numpy_posterior(obs_x[mask], obs_y[mask], obs_prior[mask], cells, prior)
    np.testing.assert_allclose(np.asarray(mean), ref_mean, atol=2e-4)
    np.testing.assert_allclose(np.asarray(var), np.maximum(ref_var, 0), atol=2e-4)
    # at an observed point the mean is (almost) the observation and the variance about the noise
    at_obs = posterior(f32(obs_x), f32(obs_y), jnp.asarray(mask), f32(obs_prior), f32(obs_x[mask]),
                          f32(obs_prior[mask]), params)
    np.testing.assert_allclose(np.asarray(at_obs[0]), obs_y[mask], atol=5e-3)
    assert np.all(np.asarray(at_obs[1]) < 2e-3)
    # no observation: the prior, variance sigma_f
    mean0, var0 = posterior(f32(obs_x), f32(obs_y), jnp.zeros(m, bool), f32(obs_prior), f32(cells), f32(prior),
                            params)
    np.testing.assert_allclose(np.asarray(mean0), prior, rtol=1e-6)
    np.testing.assert_allclose(np.asarray(var0), 1.0)
    np.testing.assert_allclose(np.asarray(gp.ucb(jnp.array([0.5, 0.7]), jnp.array([4.0, 0.0]), 0.05)), [0.6, 0.7])


# ---------------------------------------------------------------------------------------------------------------
# UCB choice and the removal rule (3 x 3)
# ---------------------------------------------------------------------------------------------------------------
GRID3 = np.array([[1.0, 0.9, 0.7],   # row b1 = 0: b0 = 0, 1, 2
                  [0.9, 0.8, 0.5],
                  [0.7, 0.5, 0.2]], np.float32)


def test_select_ties_go_to_the_nearest_then_the_lowest_index():
    hardness = jnp.array([3.0, 1.0, 2.0, 1.0])
    assert int(C.select(jnp.array([0.5, 0.9, 0.9, 0.9]), jnp.ones(4, bool), hardness)) == 1
    assert int(C.select(jnp.array([0.5, 0.9, 0.9, 0.9]), jnp.array([1, 0, 1, 1], bool), hardness)) == 3
    assert int(C.select(jnp.array([0.5, 0.9, 0.95, 0.9]), jnp.ones(4, bool), hardness)) == 2
    assert int(C.select(jnp.array([0.5, jnp.nan, 0.1, 0.9]), jnp.array([1, 1, 1, 0], bool), hardness)) == 0


def test_removal_rule_margin_and_ties_on_a_3x3_map():
    bank = toy_bank(GRID3)
    hardness = C.terrain_hardness(bank)
    mean = jnp.asarray([1.0, 0.9, 0.7, 0.9, 0.8, 0.5, 0.7, 0.5, 0.2])
    trained = 4  # cell (1, 1), predicted 0.8, distance hypot(2, 2)
    rm = lambda margin, ties: np.asarray(C.removal_mask(mean, trained, hardness, margin, ties))  # noqa: E731
    # margin 0.05: clearly easier = mean > 0.85 -> cells 0, 1, 3; no other tie; itself always
    np.testing.assert_array_equal(np.flatnonzero(rm(0.05, "nearer")), [0, 1, 3, 4])
    # margin 0.15: clearly easier > 0.95 -> 0; ties |mean - 0.8| <= 0.15: 1, 3 (nearer), 2, 6 (0.7, hypot(3, 1) =
    # 3.16 > 2.83: further, kept under "nearer")
    np.testing.assert_array_equal(np.flatnonzero(rm(0.15, "nearer")), [0, 1, 3, 4])
    np.testing.assert_array_equal(np.flatnonzero(rm(0.15, "remove")), [0, 1, 2, 3, 4, 6])
    np.testing.assert_array_equal(np.flatnonzero(rm(0.15, "keep")), [0, 4])
    # the literal rule (margin 0, ties removed) = every terrain predicted at least as easy
    np.testing.assert_array_equal(np.flatnonzero(rm(0.0, "remove")), np.flatnonzero(np.asarray(mean) >= 0.8))


def test_map_step_adds_the_observation_removes_and_picks_the_ucb_argmax():
    """First pick = prior argmax (cell (0, 0)); the fake evaluation there is 0.95 (< its prior 1.0): the GP
    observation, the removal and the next pick equal a NumPy computation."""
    bank = toy_bank(GRID3)
    config = small(threshold=0.9)
    harness = fake_harness(gain=-0.05)  # the policy gets a little worse: evaluation 1.0 - 0 - 0.05 = 0.95
    state = C.init(jax.random.key(0), bank, START, config=config, harness=harness)
    assert int(state.terrain) == 0 and bool(state.selector.available.all())
    state = jax.jit(lambda s, k: C.step(s, k, bank, config=config, harness=harness))(state, jax.random.key(1))
    assert int(state.selector.obs_count) == 1 and int(state.selector.obs_index[0]) == 0
    np.testing.assert_allclose(float(state.selector.obs_y[0]), 0.95, atol=1e-6)
    pts, prior = np.asarray(bank.points, np.float64), GRID3.ravel().astype(np.float64)
    mean, var = numpy_posterior(pts[:1], np.array([0.95]), prior[:1], pts, prior)
    hard = np.asarray(bank.distance)
    removed = (mean > mean[0] + 0.05) | ((np.abs(mean - mean[0]) <= 0.05) & (hard <= hard[0]))
    removed[0] = True
    np.testing.assert_array_equal(np.asarray(state.selector.available), ~removed)
    score = np.where(removed, -np.inf, mean + 0.05 * np.sqrt(np.maximum(var, 0)))
    best = np.flatnonzero(np.isclose(score, score.max(), atol=1e-6))
    expected = best[np.argmin(hard[best])]
    assert int(state.terrain) == expected == 1  # (1, 0) and (0, 1) tie: same distance, lower index
    assert int(state.policy["resets"]) == 1 and bool(state.restart)  # reset before the chunk; due on the switch
    assert float(state.hardest) == pytest.approx(float(hard[0]))  # 0.95 >= 0.9: credited


# ---------------------------------------------------------------------------------------------------------------
# The whole loop with a fake harness
# ---------------------------------------------------------------------------------------------------------------
def reference_map_run(bank, config, gain, chunks):
    """A host-side NumPy re-implementation of the map curriculum with the fake harness: (terrains, evaluations,
    hardest) per chunk and whether it ended for lack of terrains."""
    pts, prior = np.asarray(bank.points, np.float64), np.asarray(bank.fitness, np.float64)
    hard, diff = np.asarray(bank.distance, np.float64), 1.0 - prior
    avail = np.ones(prior.size, bool)
    pick = lambda score: min(np.flatnonzero(avail & np.isclose(score, np.max(score[avail]), atol=1e-6)),  # noqa
                             key=lambda i: (hard[i], i))
    cur, skill, evals, hardest, obs_i, obs_y, out = pick(prior + S_params(config).kappa), 0.0, 0, 0.0, [], [], []
    for _ in range(chunks):
        skill += gain
        fit = float(np.clip(1.0 - diff[cur] + skill, 0, 1))
        evals += 1
        reached = fit >= config.threshold
        hardest = max(hardest, hard[cur]) if reached else hardest
        out.append((cur, fit, hardest))
        if not (reached or evals >= config.max_evals):
            continue
        obs_i.append(cur)
        obs_y.append(fit)
        mean, var = numpy_posterior(pts[obs_i], np.array(obs_y), prior[obs_i], pts, prior)
        tie = np.abs(mean - mean[cur]) <= S_params(config).removal_margin
        avail &= ~((mean > mean[cur] + S_params(config).removal_margin) | (tie & (hard <= hard[cur])))
        avail[cur], evals = False, 0
        if not avail.any():
            return out, True
        cur = pick(mean + S_params(config).kappa * np.sqrt(np.maximum(var, 0)))
    return out, False


def toy_grid(b=5):
    b0, b1 = np.meshgrid(np.arange(b), np.arange(b))
    return np.clip(1.0 - 0.12 * np.hypot(b0, b1) - 0.03 * b0, 0.0, 1.0).astype(np.float32)


def test_map_loop_matches_a_numpy_reference_and_stops_when_no_terrain_is_left():
    bank = toy_bank(toy_grid())
    config = small(max_epochs=200, max_evals=4)
    state = run_one(bank, config, fake_harness(0.08), 200)
    ref, emptied = reference_map_run(bank, config, 0.08, 200)
    assert emptied and bool(state.done)
    n = len(ref)
    assert int(state.chunk) == n < config.max_chunks  # ended by the empty map, not by max_epochs
    h = state.history
    np.testing.assert_array_equal(np.asarray(h.terrain[:n]), [r[0] for r in ref])
    np.testing.assert_allclose(np.asarray(h.evaluation[:n]), [r[1] for r in ref], atol=1e-5)
    np.testing.assert_allclose(np.asarray(h.hardest[:n]), [r[2] for r in ref], atol=1e-5)
    np.testing.assert_array_equal(np.asarray(h.epoch[:n]), np.arange(1, n + 1))
    assert np.all(np.asarray(h.terrain[n:]) == -1) and np.all(np.isnan(np.asarray(h.hardest[n:])))
    assert len(set(r[0] for r in ref)) > 2  # it went somewhere
    assert np.all(np.diff(np.asarray(h.hardest[:n])) >= 0)


def test_max_evals_and_max_epochs_stop_and_an_unreached_terrain_is_not_credited():
    bank = toy_bank(np.array([[0.5, 0.4], [0.4, 0.3]], np.float32))  # nothing is learnt (gain 0)
    config = small(max_epochs=7, max_evals=3)
    state = run_one(bank, config, fake_harness(0.0), 100)
    h = state.history
    assert bool(state.done) and int(state.chunk) == 7 == config.max_chunks and int(state.epoch) == 7
    terrains = np.asarray(h.terrain)
    assert len(set(terrains[:3])) == 1 and terrains[3] != terrains[0]  # left after 3 evaluations
    assert float(state.hardest) == 0.0 and np.all(np.asarray(h.hardest) == 0.0)  # never credited
    # crediting every finished terrain instead
    state = run_one(bank, config._replace(credit="finished"), fake_harness(0.0), 100)
    assert float(state.history.hardest[2]) == pytest.approx(float(bank.distance[int(terrains[0])]))


def test_roughness_baseline_trains_every_fifth_terrain_in_roughness_order():
    rng = np.random.default_rng(3)
    rough = rng.permutation(16).astype(np.float32)  # descriptor 0 of the 16 terrains of a 4 x 4 grid
    bank = toy_bank(np.full((4, 4), 0.95, np.float32), descriptor0=rough)
    config = small("roughness")
    state = run_one(bank, config, fake_harness(0.0), 50)  # 0.95 - 0.05 difficulty: every terrain at once
    expected = np.argsort(rough, stable=True)[::5]
    assert bool(state.done) and int(state.chunk) == len(expected) == 4
    np.testing.assert_array_equal(np.asarray(state.history.terrain[:4]), expected)
    np.testing.assert_allclose(float(state.hardest), float(np.max(np.asarray(bank.distance)[expected])))


def test_random_baseline_uses_every_terrain_once():
    bank = toy_bank(np.full((3, 3), 0.95, np.float32))
    state = run_one(bank, small("random"), fake_harness(0.0), 50, key=4)
    seq = np.asarray(state.history.terrain[:int(state.chunk)])
    assert int(state.chunk) == 9 and sorted(seq) == list(range(9)) and not np.all(seq == np.arange(9))


# ---------------------------------------------------------------------------------------------------------------
# Trials, resume, re-tracing
# ---------------------------------------------------------------------------------------------------------------
def test_vmapped_trials_equal_trials_run_one_by_one():
    bank = toy_bank(toy_grid(4))
    config, harness = small("random", max_evals=2), fake_harness(0.05)
    keys = jax.random.split(jax.random.key(7), 3)
    batched = C.make_runner(config, harness)(C.init_trials(keys, bank, START, config=config, harness=harness),
                                             bank, 40)
    run_single = C.make_runner(config, harness)  # one compile for the three single-trial runs
    for t in range(3):
        one = run_single(C.init_trials(keys[t:t + 1], bank, START, config=config,
                                                           harness=harness), bank, 40)
        assert tree_equal(jax.tree.map(lambda x: x[t], batched), jax.tree.map(lambda x: x[0], one))
    assert not np.array_equal(np.asarray(batched.history.terrain[0]), np.asarray(batched.history.terrain[1]))


def test_resume_from_a_checkpoint_equals_an_uninterrupted_run(tmp_path):
    bank = toy_bank(toy_grid(4))
    config, harness = small("map", max_evals=2, max_epochs=30), fake_harness(0.05)
    run = C.make_runner(config, harness)
    init = lambda: C.init_trials(jax.random.split(jax.random.key(1), 2), bank, START, config=config,  # noqa
                                 harness=harness)
    whole = run(init(), bank, 12)

    def chunk(s, a, b):
        s = run(s, bank, b - a)
        return s, {"hardest": jnp.full((b - a,), jnp.mean(s.hardest))}

    driver.run_chunks(chunk, init(), total=12, every=5, run_dir=tmp_path, progress=False, time_limit_s=1e-9)
    restored, done, history, _ = driver.restore(tmp_path, like=init())
    assert done == 5
    state, done, _ = driver.run_chunks(chunk, restored, total=12, every=5, start=done, history=history,
                                       run_dir=tmp_path, progress=False)
    assert done == 12 and tree_equal(state, whole)


def test_live_rows_pad_the_running_trials_to_a_power_of_two_with_finished_ones():
    done = np.array([False, True, True, False, False, True, True, True, False, True])
    assert C.live_rows(done).tolist() == [0, 3, 4, 8]
    assert C.live_rows(np.r_[done[:9], False]).tolist() == [0, 1, 2, 3, 4, 5, 8, 9]  # 5 running -> 8 rows
    assert C.live_rows(np.ones(10, bool)).tolist() == [0] and C.live_rows(np.zeros(3, bool)).tolist() == [0, 1, 2]
    assert C.live_rows(np.array([True, True, False])).tolist() == [2]


@pytest.mark.parametrize("overlap", [False, True])
def test_run_live_equals_running_every_trial(overlap):
    """Blocks on the running trials only (5 trials that end at different times) give, block by block, the states
    of blocks on all five; the blocks did shrink."""
    bank = toy_bank(toy_grid(4))
    config = small("map", max_evals=3, max_epochs=60, overlap=overlap)
    harness = keyed_harness(0.03, overlap)
    run = C.make_runner(config, harness)
    whole, live = (C.init_trials(jax.random.split(jax.random.key(3), 5), bank, KEYED_START, config=config,
                                 harness=harness) for _ in range(2))  # two copies: the runner donates its states
    sizes = []
    while not np.all(np.asarray(whole.done)):
        sizes.append(C.live_rows(live.done).size)
        whole, live = run(whole, bank, 3), C.run_live(run, live, bank, 3)
        assert tree_equal(live, whole)
    assert sizes[0] == 5 and min(sizes) < 5, sizes


def test_no_retrace_when_the_terrain_changes():
    bank = toy_bank(toy_grid(4))
    config, harness = small("map", max_evals=2), fake_harness(0.05)
    run = C.make_runner(config, harness)
    states = C.init_trials(jax.random.split(jax.random.key(0), 2), bank, START, config=config, harness=harness)
    TRACES["train"] = 0
    seen = set()
    for block in (3, 4, 5):
        states = run(states, bank, block)
        seen |= set(np.asarray(states.terrain).tolist())
    assert len(seen) >= 3 and TRACES["train"] == 1


# ---------------------------------------------------------------------------------------------------------------
# Overlap: each chunk's evaluation rides along the next chunk's training
# ---------------------------------------------------------------------------------------------------------------
def keyed_harness(gain: float = 0.05, overlap: bool = True) -> C.Harness:
    """:func:`fake_harness` whose training and evaluation depend on their keys (a wrong key changes the result),
    with ``train_evaluate`` = (train, evaluate of the starting policy); ``steps`` counts the trainings kept."""

    def train(policy, key, terrain):
        return {**policy, "skill": policy["skill"] + gain * jax.random.uniform(key, (), minval=0.5, maxval=1.5),
                "steps": policy["steps"] + 1}

    def evaluate(policy, key, terrain):
        noise = 0.02 * jax.random.normal(key, ())
        return jnp.clip(1.0 - jnp.mean(terrain) + policy["skill"] + noise, 0.0, 1.0)

    def reset(policy, key, terrain):
        return {**policy, "resets": policy["resets"] + 1}

    both = (lambda p, k, t, ek: (train(p, k, t), evaluate(p, ek, t))) if overlap else None
    return C.Harness(train, evaluate, reset, train_evaluate=both)


KEYED_START = {**START, "steps": jnp.zeros((), jnp.int32)}


@pytest.mark.parametrize("selector", ["map", "random"])
def test_overlap_runs_the_same_curriculum_as_the_plain_loop(selector):
    """3 trials to the end: with ``overlap`` every record, GP observation, choice, policy and reset count equals the
    plain loop's (keys and starting policies match chunk by chunk; a training dropped on a terrain switch leaves
    no trace); in blocks of 4 every running trial does at least 4 chunks, at most one step more per switch."""
    bank = toy_bank(toy_grid(4))
    keys = jax.random.split(jax.random.key(5), 3)
    out = {}
    for overlap in (False, True):
        config, harness = small(selector, max_evals=3, max_epochs=30, overlap=overlap), keyed_harness(0.04, overlap)
        out[overlap] = C.make_runner(config, harness)(
            C.init_trials(keys, bank, KEYED_START, config=config, harness=harness), bank, 100)
    plain, over = out[False], out[True]
    assert plain.pending is None and not np.any(np.asarray(over.pending))
    assert tree_equal(over._replace(pending=None), plain)
    switches = int(np.sum(np.diff(np.asarray(plain.history.terrain), axis=1) != 0))
    assert switches >= 6 and np.all(np.asarray(plain.done))
    config, harness = small(selector, max_evals=3, max_epochs=30, overlap=True), keyed_harness(0.04)
    run, states = C.make_runner(config, harness), C.init_trials(keys, bank, KEYED_START, config=config,
                                                                  harness=harness)
    for block in range(1, 8):
        before = np.asarray(states.chunk)
        states = run(states, bank, 4)
        running = ~np.asarray(states.done)
        assert np.all(np.asarray(states.chunk)[running] >= 4 * block), (block, np.asarray(states.chunk))
        assert np.all(np.asarray(states.chunk) >= before)
    with pytest.raises(ValueError, match="train_evaluate"):
        C.make_runner(config, fake_harness())(C.init_trials(keys, bank, START, config=config,
                                                            harness=fake_harness()), bank, 1)


def test_overlap_resumes_to_the_uninterrupted_run(tmp_path):
    bank = toy_bank(toy_grid(4))
    config, harness = small("map", max_evals=2, max_epochs=30, overlap=True), keyed_harness(0.05)
    run = C.make_runner(config, harness)
    init = lambda: C.init_trials(jax.random.split(jax.random.key(1), 2), bank, KEYED_START, config=config,  # noqa
                                 harness=harness)

    def chunk(s, a, b):
        s = run(s, bank, b - a)
        return s, {"hardest": jnp.full((b - a,), jnp.mean(s.hardest))}

    whole, _, _ = driver.run_chunks(chunk, init(), total=12, every=4, progress=False)
    driver.run_chunks(chunk, init(), total=12, every=4, run_dir=tmp_path, progress=False, time_limit_s=1e-9)
    restored, done, history, _ = driver.restore(tmp_path, like=init())
    assert done == 4 and restored.pending is not None
    state, done, _ = driver.run_chunks(chunk, restored, total=12, every=4, start=done, history=history,
                                       run_dir=tmp_path, progress=False)
    assert done == 12 and tree_equal(state, whole)


# ---------------------------------------------------------------------------------------------------------------
# eval_lag: the overlapped order without the step more per switch (the selector sees each evaluation a chunk late)
# ---------------------------------------------------------------------------------------------------------------
LAG_KEYS, LAG_GAIN = 5, 0.01  # slow learning: terrains take 1-4 chunks, blocks of 3 end with evaluations pending


@pytest.fixture(scope="module")
def lagged():
    """One compiled lagged runner (``overlap`` and ``eval_lag``, the keyed harness, 3 trials) shared by the tests
    below: ``(bank, config, harness, run, steps, states)``: ``run(states, n)`` (jitted; donates ``states``) appends
    one entry to ``steps`` per loop step; ``states`` the 3 trials run to the end from ``init()``."""
    bank = toy_bank(toy_grid(4))
    config = small("map", max_evals=3, max_epochs=30, overlap=True, eval_lag=True)
    harness, steps = keyed_harness(LAG_GAIN), []
    run = jax.jit(lambda s, n: C.run_trials(s, bank, n, config=config, harness=harness,
                                            on_chunk=lambda *a: steps.append(1)), donate_argnums=(0,))
    init = lambda: C.init_trials(jax.random.split(jax.random.key(LAG_KEYS), 3), bank, KEYED_START,  # noqa: E731
                                 config=config, harness=harness)
    states = run(init(), 100)
    total = len(steps)
    steps.clear()
    return bank, config, harness, run, init, states, total


def test_eval_lag_scores_each_chunks_terrain_with_its_own_policy_and_keys(lagged):
    """Each evaluated row c of a lagged run equals a direct evaluation of chunk c's policy (every chunk's training
    kept: the sum of the trainings of chunks 0..c with their keys) on chunk c's terrain with chunk c's evaluation key
    (within 1e-6: float32 sums against float64); after every terrain the trial trained one chunk more on it,
    unevaluated (NaN), and the next terrain's first chunk follows it; no loop step more per switch."""
    bank, config, _, _, _, states, steps = lagged
    h, gain = states.history, LAG_GAIN
    assert np.all(np.asarray(states.done)) and not np.any(np.asarray(states.pending))
    @jax.jit
    def draws(key):  # chunk c's training gain and evaluation noise, from its (train, eval, select, reset) keys
        keys = jax.vmap(lambda c: jax.random.split(jax.random.fold_in(jax.random.wrap_key_data(key), c), 4))(
            jnp.arange(config.max_chunks))
        return (jax.vmap(lambda k: jax.random.uniform(k, (), minval=0.5, maxval=1.5))(keys[:, 0]),
                jax.vmap(lambda k: jax.random.normal(k, ()))(keys[:, 1]))

    gains, noise = (np.asarray(x, np.float64) for x in jax.vmap(draws)(states.key))  # [3, C] each
    maps = np.asarray(bank.heightmaps, np.float64).mean((1, 2))
    switches_total = 0
    for t in range(3):
        n = int(states.chunk[t])
        terrain, ev = np.asarray(h.terrain[t, :n]), np.asarray(h.evaluation[t, :n])
        np.testing.assert_array_equal(np.asarray(h.epoch[t, :n]), np.arange(1, n + 1))
        skill = np.cumsum(gain * gains[t, :n])  # chunk c's policy: the trainings of chunks 0..c
        want = np.clip(1.0 - maps[terrain] + skill + 0.02 * noise[t, :n], 0, 1)
        scored = ~np.isnan(ev)
        np.testing.assert_allclose(ev[scored], want[scored], atol=1e-6)
        runs = C.terrain_runs(terrain, ev)
        unevaluated = np.flatnonzero(np.isnan(ev))
        ends = np.cumsum([r["chunks"] for r in runs]) - 1  # the last chunk of each terrain run
        # every switch leaves exactly one unevaluated chunk, the last one on the terrain left (also when the switch
        # came with the last epoch, the run's last row)
        assert unevaluated.tolist() == (ends if n == config.max_chunks and np.isnan(ev[-1]) else ends[:-1]).tolist()
        assert all(np.isfinite(r["final_evaluation"]) for r in runs)
        switches_total += len(runs) - 1
        assert int(states.policy["steps"][t]) == n  # every chunk's training kept (none trained twice)
    assert switches_total >= 6
    assert steps <= config.max_chunks + 1  # one step per chunk (and one more for the last evaluation)


def test_eval_lag_differs_from_the_plain_order_only_after_a_switch(lagged):
    """Up to each trial's first terrain switch a lagged run's records are the plain loop's (the same keys, policies
    and evaluations); at the switch the plain loop moves on, the lagged one trains a chunk more on the old terrain."""
    bank, _, _, _, _, lag_states, _ = lagged
    config, harness = small("map", max_evals=3, max_epochs=30), keyed_harness(LAG_GAIN, False)
    plain_states = C.make_runner(config, harness)(C.init_trials(jax.random.split(jax.random.key(LAG_KEYS), 3), bank,
                                                                KEYED_START, config=config, harness=harness), bank, 100)
    for t in range(3):
        plain, lag = (np.asarray(x.history.terrain[t]) for x in (plain_states, lag_states))
        first = int(np.flatnonzero(np.diff(plain) != 0)[0])  # the last chunk on the first terrain
        np.testing.assert_array_equal(lag[:first + 1], plain[:first + 1])
        np.testing.assert_array_equal(np.asarray(lag_states.history.evaluation[t, :first + 1]),
                                      np.asarray(plain_states.history.evaluation[t, :first + 1]))
        assert lag[first + 1] == lag[first] != plain[first + 1]
        assert np.isnan(float(lag_states.history.evaluation[t, first + 1]))


def test_eval_lag_resumes_to_the_uninterrupted_run(lagged, tmp_path):
    """Stopped by the time limit with evaluations pending, a lagged run resumes to the uninterrupted one."""
    _, _, _, run, init, whole, _ = lagged

    def chunk(s, a, b):
        s = run(s, b - a)
        return s, {"hardest": jnp.full((b - a,), jnp.mean(s.hardest))}

    driver.run_chunks(chunk, init(), total=30, every=3, run_dir=tmp_path, progress=False, time_limit_s=1e-9)
    restored, done, history, _ = driver.restore(tmp_path, like=init())
    assert done == 3 and np.all(np.asarray(restored.pending))
    state, done, _ = driver.run_chunks(chunk, restored, total=30, every=3, start=done, history=history,
                                       run_dir=tmp_path, progress=False)
    assert tree_equal(state, whole)


def test_unevaluated_chunks_stay_out_of_the_evaluations_of_metrics_sequences_and_history_csv():
    """A lagged history (chunk 2 of trial 0 trained, not evaluated): the metrics' mean evaluation of that chunk is
    trial 1's alone, the terrain's final evaluation is its last one, and ``seen_epoch`` is one chunk on (-1 there)."""
    h = C.History(epoch=np.array([[1, 2, 3, 4], [1, 2, 3, -1]]), terrain=np.array([[5, 5, 5, 7], [5, 6, 6, -1]]),
                  evaluation=np.array([[0.5, 0.95, np.nan, 0.2], [0.4, 0.6, 0.7, np.nan]], np.float32),
                  hardest=np.zeros((2, 4), np.float32))
    from jaxterrain.curriculum import progress

    m = progress.history_metrics(h, 0, 4)
    np.testing.assert_allclose(m["evaluation"], [0.45, 0.775, 0.7, 0.2], rtol=1e-6)
    assert m["trials_running"].tolist() == [2, 2, 2, 1]
    runs = C.terrain_runs(h.terrain[0], h.evaluation[0], h.epoch[0])
    assert [(r["terrain"], r["chunks"], r["end_epoch"]) for r in runs] == [(5, 3, 3), (7, 1, 4)]
    assert runs[0]["final_evaluation"] == pytest.approx(0.95) and runs[0]["best_evaluation"] == pytest.approx(0.95)
    hist = outputs.histories(C.State(*([None] * 10), history=h))
    lagged = small("map", overlap=True, eval_lag=True)
    assert outputs.seen_epochs(hist, lagged).tolist() == [[2, 3, -1, 5], [2, 3, 4, -1]]
    # a finished trial's last evaluation: the chunk that rode along it was dropped
    assert outputs.seen_epochs(hist, lagged, np.array([True, False])).tolist() == [[2, 3, -1, 4], [2, 3, 4, -1]]
    assert outputs.seen_epochs(hist, small("map")).tolist() == [[1, 2, -1, 4], [1, 2, 3, -1]]


def test_eval_lag_is_refused_without_overlap_or_as_a_non_bool():
    with pytest.raises(ValueError, match=r"^CurriculumConfig.eval_lag needs CurriculumConfig.overlap "):
        C.validate_config(C.CurriculumConfig(eval_lag=True))
    with pytest.raises(ValueError, match=r"^CurriculumConfig.eval_lag must be True or False"):
        C.validate_config(C.CurriculumConfig(overlap=True, eval_lag="yes"))
    assert C.validate_config(C.CurriculumConfig(overlap=True, eval_lag=True)).eval_lag


# ---------------------------------------------------------------------------------------------------------------
# Table 2 / Figure 7
# ---------------------------------------------------------------------------------------------------------------
def test_milestones_and_curves_from_hand_made_histories():
    d = 70.71
    epoch = np.array([[40, 80, 120, 160], [40, 80, -1, -1]])
    hardest = np.array([[0.06 * d, 0.06 * d, 0.21 * d, 0.21 * d], [0.0, 0.11 * d, np.nan, np.nan]])
    first = C.first_epochs(epoch, hardest)
    np.testing.assert_array_equal(first[0, :4], [40, 120, 120, 120])
    assert np.isnan(first[0, 4:]).all()
    np.testing.assert_array_equal(first[1, :2], [80, 80])
    assert np.isnan(first[1, 2:]).all()
    mean, reached = C.milestone_summary(first)
    np.testing.assert_allclose(mean[:4], [60, 100, 120, 120])
    np.testing.assert_array_equal(reached[:5], [2, 2, 1, 1, 0])
    cells = [C.format_milestone(m, r, 2) for m, r in zip(mean, reached)]
    assert cells[:5] == ["60", "100", "120 (1/2)", "120 (1/2)", "-"]
    grid, mean_c, se = C.hardest_curve(epoch, hardest)
    np.testing.assert_array_equal(grid, [0, 40, 80, 120, 160])
    trial1 = np.array([0, 0, 0.11 * d, 0.11 * d, 0.11 * d])  # carried forward after its end
    trial0 = np.array([0, 0.06 * d, 0.06 * d, 0.21 * d, 0.21 * d])
    np.testing.assert_allclose(mean_c, (trial0 + trial1) / 2)
    np.testing.assert_allclose(se, np.abs(trial0 - trial1) / 2)  # std(ddof 1) / sqrt(2) of two values
    runs = C.terrain_runs([3, 3, 5, -1], [0.2, 0.95, 0.5, np.nan])
    assert [(r["terrain"], r["chunks"], r["final_evaluation"]) for r in runs] == [(3, 2, 0.95), (5, 1, 0.5)]


def test_config_validation_names_the_field():
    with pytest.raises(ValueError, match="threshold"):
        C.validate_config(C.CurriculumConfig(threshold=1.5))
    with pytest.raises(ValueError, match="threshold"):
        C.validate_config(C.CurriculumConfig(threshold=0.0))
    with pytest.raises(ValueError, match="selector"):
        C.validate_config(C.CurriculumConfig(selector="easy"))
    with pytest.raises(ValueError, match="must divide"):
        C.validate_config(C.CurriculumConfig(ppo=C.CurriculumConfig().ppo._replace(num_envs=3000)))
    assert C.validate_config(C.CurriculumConfig()).updates_per_chunk == 4


def test_config_fine_tuning_ppo_is_one_ppo_config():
    """The fine-tuning PPO is ``CurriculumConfig.ppo`` (a PPOConfig): its nine FINE_TUNED fields replace the base
    policy's, nothing else may be set there (not silently ignored; ``scan_inputs`` is the walker's, set by
    ``ppo_config``), and the JSON reads nested or flat (configs written without ``truncation`` take the default:
    ``experiments learn`` reads its own old configs as ``mask``)."""
    from jaxterrain import rl
    from jaxterrain.curriculum.config import FINE_TUNED

    config = C.CurriculumConfig()
    assert FINE_TUNED == ("num_envs", "unroll_length", "num_unrolls", "num_minibatches", "update_epochs",
                          "learning_rate", "update_normaliser", "truncation", "scan_lr_scale")
    assert [getattr(config.ppo, k) for k in FINE_TUNED] == [500, 10, 8, 8, 8, 3e-4, True, "bootstrap", 1.0]
    assert config.steps_per_update == 40_000 and config.updates_per_chunk == 4
    base = rl.PPOConfig(gamma=0.99, policy_hidden=(8,), num_envs=7, learning_rate=1.0)
    assert config.ppo_config(base) == base._replace(num_envs=500, unroll_length=10, num_unrolls=8, num_minibatches=8,
                                                    update_epochs=8, learning_rate=3e-4, truncation="bootstrap")
    with pytest.raises(ValueError, match=r"CurriculumConfig\.ppo\.gamma must keep PPOConfig's default"):
        C.validate_config(config._replace(ppo=config.ppo._replace(gamma=0.9)))
    with pytest.raises(ValueError, match=r"CurriculumConfig\.ppo: PPOConfig\.num_minibatches"):
        C.validate_config(config._replace(ppo=config.ppo._replace(num_minibatches=3)))
    with pytest.raises(ValueError, match=r"CurriculumConfig\.ppo: PPOConfig\.learning_rate"):
        C.validate_config(config._replace(ppo=config.ppo._replace(learning_rate=float("inf"))))
    with pytest.raises(ValueError, match="must be a jaxterrain.rl.PPOConfig"):
        C.validate_config(config._replace(ppo={"num_envs": 4}))
    with pytest.raises(ValueError, match=r"CurriculumConfig\.ppo\.scan_inputs must keep PPOConfig's default"):
        C.validate_config(config._replace(ppo=config.ppo._replace(scan_inputs=153)))  # the walker's, not a setting
    with pytest.raises(ValueError, match=r"CurriculumConfig\.ppo: PPOConfig\.scan_lr_scale must be a finite number"):
        C.validate_config(config._replace(ppo=config.ppo._replace(scan_lr_scale=0.0)))
    scaled = config._replace(ppo=config.ppo._replace(scan_lr_scale=0.1))
    tuned = scaled.ppo_config(base, scan_inputs=153)
    assert (tuned.scan_inputs, tuned.scan_lr_scale, tuned.gamma) == (153, 0.1, 0.99)
    assert config.ppo_config(base._replace(scan_inputs=7)).scan_inputs == 0  # the walker's scan, not the base's
    with pytest.raises(ValueError, match=r"^CurriculumConfig\.ppo\.scan_lr_scale 0\.1: .* this walker has none"):
        scaled.ppo_config(base)  # no scan: the scale would be ignored
    small_ppo = config._replace(selector="random", ppo=config.ppo._replace(num_envs=4, update_epochs=1))
    d = json.loads(json.dumps(small_ppo.to_json_dict()))
    assert d["ppo"] == {"num_envs": 4, "unroll_length": 10, "num_unrolls": 8, "num_minibatches": 8,
                        "update_epochs": 1, "learning_rate": 3e-4, "update_normaliser": True, "truncation": "bootstrap",
                        "scan_lr_scale": 1.0}
    assert C.CurriculumConfig.from_json_dict(d) == small_ppo
    flat = {**{k: v for k, v in d.items() if k != "ppo"}, **d["ppo"]}  # learn's config.json layout
    assert C.CurriculumConfig.from_json_dict(flat) == small_ppo
    assert C.CurriculumConfig.from_json_dict({"num_envs": 4, "update_epochs": 1, "selector": "random"}) == small_ppo
    with pytest.raises(ValueError, match=r"CurriculumConfig\.ppo: unknown fields \['gamma'\]"):
        C.CurriculumConfig.from_json_dict({"ppo": {"gamma": 0.9}})
    with pytest.raises(ValueError, match=r"CurriculumConfig: unknown fields \['kapa'\]"):
        C.CurriculumConfig.from_json_dict({"kapa": 0.1})


# ---------------------------------------------------------------------------------------------------------------
# A treatment's run config: fine-tuning knobs, the time limit, the default archives (the learn command:
# tests/integration/test_learn_command.py)
# ---------------------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def tiny_archive(tmp_path_factory):
    """The CPPN archive cut to its first ``k`` filled cells, with stored heightmaps (gentle bumps: no rendering)."""
    folder = tmp_path_factory.mktemp("arch")
    return lambda k, name, **config: tiny_archive_file(folder, k, name, **config)


def test_learn_fine_tuning_knobs_reach_the_walker_and_ppo(tiny_archive):
    """``--healthy-reward`` (config ``healthy_reward``) sets the walker's per-step bonus for staying up, which only
    PPO's reward uses; None keeps the walker's (and the base policy's) 5.0. ``--freeze-normaliser`` (config
    ``update_normaliser: false``), ``--learning-rate`` and ``--truncation`` reach the fine-tuning PPOConfig,
    ``--max-evals`` the CurriculumConfig. Builds the env only, compiles nothing."""
    from jaxterrain import rl

    cfg = {**FLAT_PRESETS["smoke"], "archive": tiny_archive(4, "four.npz")}
    config, _, _, env = validated(cfg)
    assert env.config.healthy_reward == 5.0 and config.ppo.update_normaliser
    config, _, _, env = validated({**cfg, "healthy_reward": 0.5, "update_normaliser": False, "max_evals": 7,
                                        "learning_rate": 3e-5, "truncation": "mask"})
    assert env.config.healthy_reward == 0.5 and not config.ppo.update_normaliser and config.max_evals == 7
    assert not config.ppo_config(rl.PPOConfig()).update_normaliser
    assert config.ppo_config(rl.PPOConfig()).learning_rate == 3e-5
    assert config.ppo_config(rl.PPOConfig()).truncation == "mask"
    assert validated(cfg)[0].ppo_config(rl.PPOConfig()).truncation == "bootstrap"  # every preset's
    legacy = {k: v for k, v in cfg.items() if k != "truncation"}  # a config.json saved before the key existed
    assert validated(legacy)[0].ppo_config(rl.PPOConfig()).truncation == "mask"
    with pytest.raises(runner.BadInput, match="truncation"):
        validated({**cfg, "truncation": "drop"})


def test_scan_lr_scale_reaches_the_fine_tuning_ppo_with_the_walkers_scan_size(tiny_archive, tmp_path):
    """``--scan-lr-scale`` (config ``scan_lr_scale``) reaches the fine-tuning PPOConfig of a perceptive run, whose
    ``scan_inputs`` is the walker's scan (17 x 9 = 153, the last entries of its observation; not a setting): its
    optimiser steps the start policy's first-layer scan rows 0.1 times as far as the blind rows, in both networks.
    The trials' policy files record both (``outputs.export_policies`` saves that PPOConfig). A blind walker has no
    scan (``scan_inputs`` 0) and refuses any other scale, naming the field. Builds the envs and takes one Adam step;
    no physics compiles."""
    from jaxterrain import rl
    from jaxterrain.curriculum import walker as W

    cfg = {**FLAT_PRESETS["smoke"], "archive": tiny_archive(4, "four.npz")}
    config, _, policy, env = validated({**cfg, "observation": "perceptive", "scan_lr_scale": 0.1})
    ppo = W.fine_tuning_ppo(config, policy, env)
    blind = rl.load_policy().observation_size
    assert (ppo.scan_inputs, ppo.scan_lr_scale) == (153, 0.1) and env.observation_size == blind + 153
    opt = rl.make_optimizer(ppo)
    updates, _ = opt.update(jax.tree.map(jnp.ones_like, policy.params), opt.init(policy.params), policy.params)
    for net in ("policy", "value"):
        kernel = np.asarray(updates[net]["params"]["mlp"]["hidden_0"]["kernel"])
        np.testing.assert_allclose(kernel[blind:], np.full_like(kernel[blind:], 0.1 * kernel[:blind].mean()), rtol=1e-5)
    rl.save_policy(tmp_path / "trial_0", policy.params, policy.normaliser, ppo, env.observation_size, env.action_size)
    assert rl.load_policy(tmp_path / "trial_0").config == ppo
    config, _, policy, env = validated(cfg)
    assert W.fine_tuning_ppo(config, policy, env).scan_inputs == 0 and config.ppo.scan_lr_scale == 1.0
    with pytest.raises(runner.BadInput, match=r"^LearnConfig\.curriculum\.ppo\.scan_lr_scale 0\.5 must be 1\.0 for a "
                                              r"blind walker"):
        validated({**cfg, "scan_lr_scale": 0.5})


def test_learn_time_limit_counts_set_up_and_compilation(tmp_path, tiny_archive, monkeypatch):
    """``run_treatment(time_limit_s=T)`` gives the chunk loop what is left of T after its set-up (compilation), so a
    command under ``timeout`` stops in time. The set-up and the loop are stand-ins: nothing compiles."""
    import time
    from types import SimpleNamespace

    cfg = {**FLAT_PRESETS["smoke"], "archive": tiny_archive(4, "four.npz")}
    seen = {}

    def slow_setup(*args, **kwargs):
        time.sleep(0.5)
        return None, None, SimpleNamespace(done=np.zeros(2, bool))

    def loop(chunk_fn, states, **kw):
        seen["limit"] = kw["time_limit_s"]
        return states, kw["start"], {}

    monkeypatch.setattr(runner, "setup", slow_setup)
    monkeypatch.setattr(driver, "run_chunks", loop)
    assert runner.run_treatment(run_config.from_flat(cfg), tmp_path / "run", time_limit_s=10.0) is None
    assert 9.0 < seen["limit"] <= 9.5
    assert runner.run_treatment(run_config.from_flat(cfg), tmp_path / "run", time_limit_s=0.1) is None
    assert 0 < seen["limit"] <= 1e-3  # spent in set-up: one chunk, then stop


def test_the_default_archives_are_the_five_shipped_headings_archives():
    """The shipped paper-budget archives (the default of ``learn`` and ``curriculum``: CPPN_ARCHIVE is the CPPN's)
    are reseated under HEADINGS (80 walks, best 5, 4 headings, taken from each archive); ``smoke`` walks 2 along +x
    on any of them."""
    shipped = Path(CPPN_ARCHIVE).parent
    archives = {p.name.removesuffix("_headings.npz"): str(p) for p in sorted(shipped.glob("*_headings.npz"))}
    assert sorted(archives) == ["cppn", "diamond_square", "gan", "perlin", "worley"]
    assert archives["cppn"] == CPPN_ARCHIVE
    for name, path in archives.items():
        arch = runner.load_archive(path, ["roughness", "tpi"])
        cfg = runner.resolve(run_config.PRESETS["gpu-short"], arch).curriculum
        assert (cfg.attempts, cfg.best, cfg.headings) == (80, 5, 4), name
        assert int(arch.filled.sum()) >= 100 and arch.config.generations == 25, name  # the paper's budget
    config, *_ = validated(dict(FLAT_PRESETS["smoke"]))
    assert (config.attempts, config.best, config.headings) == (2, 1, 1)
