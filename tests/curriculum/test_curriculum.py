"""jaxterrain.curriculum: the IT&E GP against NumPy, UCB choice and removal rule, the whole loop on toy banks with a
fake deterministic harness (terrain order, stop conditions, hardest record), the roughness baseline, Table 2
extraction, resume, vmapped trials, no re-trace on terrain switches, and the ``learn`` command end to end."""

from __future__ import annotations

import argparse
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


def validated(cfg: dict):
    """``(CurriculumConfig, archive, policy, env)`` of a flat (``config.json``) run config."""
    return runner.validate(run_config.from_flat(cfg))[1:]
from experiments import common


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


def tree_equal(a, b) -> bool:
    la, lb = jax.tree.leaves(a), jax.tree.leaves(b)
    return len(la) == len(lb) and all(np.array_equal(np.asarray(x), np.asarray(y), equal_nan=True)
                                      for x, y in zip(la, lb))


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
    """The fine-tuning PPO is ``CurriculumConfig.ppo`` (a PPOConfig): its eight FINE_TUNED fields replace the base
    policy's, nothing else may be set there (not silently ignored), and the JSON reads nested or flat (configs written
    without ``truncation`` take the default: ``experiments learn`` reads its own old configs as ``mask``)."""
    from jaxterrain import rl
    from jaxterrain.curriculum.config import FINE_TUNED

    config = C.CurriculumConfig()
    assert FINE_TUNED == ("num_envs", "unroll_length", "num_unrolls", "num_minibatches", "update_epochs",
                          "learning_rate", "update_normaliser", "truncation")
    assert [getattr(config.ppo, k) for k in FINE_TUNED] == [500, 10, 8, 8, 8, 3e-4, True, "bootstrap"]
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
    small_ppo = config._replace(selector="random", ppo=config.ppo._replace(num_envs=4, update_epochs=1))
    d = json.loads(json.dumps(small_ppo.to_json_dict()))
    assert d["ppo"] == {"num_envs": 4, "unroll_length": 10, "num_unrolls": 8, "num_minibatches": 8,
                        "update_epochs": 1, "learning_rate": 3e-4, "update_normaliser": True, "truncation": "bootstrap"}
    assert C.CurriculumConfig.from_json_dict(d) == small_ppo
    flat = {**{k: v for k, v in d.items() if k != "ppo"}, **d["ppo"]}  # learn's config.json layout
    assert C.CurriculumConfig.from_json_dict(flat) == small_ppo
    assert C.CurriculumConfig.from_json_dict({"num_envs": 4, "update_epochs": 1, "selector": "random"}) == small_ppo
    with pytest.raises(ValueError, match=r"CurriculumConfig\.ppo: unknown fields \['gamma'\]"):
        C.CurriculumConfig.from_json_dict({"ppo": {"gamma": 0.9}})
    with pytest.raises(ValueError, match=r"CurriculumConfig: unknown fields \['kapa'\]"):
        C.CurriculumConfig.from_json_dict({"kapa": 0.1})


# ---------------------------------------------------------------------------------------------------------------
# The learn command: bad input (no compile) and the smoke preset end to end
# ---------------------------------------------------------------------------------------------------------------
CPPN = "docs/results/exp1b_gpu_sound_cppn_archive.npz"


@pytest.fixture(scope="module")
def tiny_archive(tmp_path_factory):
    """The CPPN archive cut to its first ``k`` filled cells, with stored heightmaps (gentle bumps: no rendering)."""
    folder = tmp_path_factory.mktemp("arch")
    return lambda k, name, **config: tiny_archive_file(folder, k, name, **config)


def tiny_archive_file(folder, k: int, name: str, **config) -> str:
    """:func:`tiny_archive`'s file ``folder/name``: the CPPN archive's first ``k`` filled cells, gentle bumps."""
    from jaxterrain import qd as A

    arch = A.load(CPPN)
    filled = np.flatnonzero(arch.filled)
    keep = np.zeros_like(arch.filled)
    keep[filled[:k]] = True
    x = np.linspace(0, 4 * np.pi, 256, dtype=np.float32)
    bumps = (0.02 * (1 + np.sin(x)[None, :] * np.cos(x)[:, None]) * 65535).astype(np.uint16)
    maps = np.where(keep[:, None, None], bumps[None], np.uint16(0))
    tiny = arch._replace(source=np.where(keep, arch.source, -1).astype(np.int32),
                         fitness=np.where(keep, arch.fitness, -np.inf).astype(np.float32), heightmaps=maps,
                         config=arch.config._replace(**config))
    return str(A.save(Path(folder) / name, tiny))


def cli(*argv):
    from experiments.__main__ import main

    return main(list(argv))


def test_learn_rejects_bad_input_with_one_line_naming_it(tmp_path, tiny_archive, capsys):
    good = tiny_archive(4, "good.npz")
    corrupt = tmp_path / "corrupt.npz"
    corrupt.write_bytes(b"PK\x03\x04 not a zip")
    policy_dir = tmp_path / "policy"
    policy_dir.mkdir()
    from jaxterrain import rl

    meta = json.loads((rl.BASE_POLICY_DIR / "config.json").read_text())
    (policy_dir / "policy.msgpack").write_bytes((rl.BASE_POLICY_DIR / "policy.msgpack").read_bytes())
    (policy_dir / "config.json").write_text(json.dumps({**meta, "observation_size": 53}))
    cases = [
        (["--archive", good, "--trials", "0"], "--trials"),
        (["--archive", good, "--threshold", "1.5"], "threshold"),
        (["--archive", good, "--threshold", "0"], "threshold"),
        (["--archive", str(corrupt)], "corrupt.npz"),
        (["--archive", str(tmp_path / "missing.npz")], "missing.npz"),
        (["--archive", tiny_archive(1, "one.npz")], "one.npz: 1 filled cell"),
        (["--archive", tiny_archive(0, "empty.npz")], "empty.npz: 0 filled cell"),
        (["--archive", tiny_archive(4, "tri.npz", descriptors=("tri", "tpi"))], "tri.npz: descriptors"),
        (["--archive", good, "--policy", str(policy_dir)], "policy"),
    ]
    for i, (argv, needle) in enumerate(cases):
        out = tmp_path / f"run{i}"
        try:  # the runner's checks return 2; the flag checks before it (experiments.common) exit with 2
            code = cli("learn", "--preset", "smoke", "--out", str(out), *argv)
        except SystemExit as stop:
            code = stop.code
        assert code == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and needle in err[0], (argv, err)
        assert not out.exists()  # nothing left behind
    assert "observations 53" in err[0]
    for value in ("-1", "nan"):  # flag values: argparse's exit status 2, before the run folder exists
        with pytest.raises(SystemExit) as stop:
            cli("learn", "--preset", "smoke", "--out", str(tmp_path / "h"), "--archive", good,
                "--healthy-reward", value)
        assert stop.value.code == 2 and "--healthy-reward must be a finite number >= 0" in capsys.readouterr().err
        assert not (tmp_path / "h").exists()
    for value in ("0", "-1e-4", "inf"):
        with pytest.raises(SystemExit) as stop:
            cli("learn", "--preset", "smoke", "--out", str(tmp_path / "h"), "--archive", good,
                f"--learning-rate={value}")
        assert stop.value.code == 2 and "--learning-rate must be a finite number > 0" in capsys.readouterr().err
        assert not (tmp_path / "h").exists()


def test_learn_fine_tuning_knobs_reach_the_walker_and_ppo(tiny_archive):
    """``--healthy-reward`` (config ``healthy_reward``) sets the walker's per-step bonus for staying up, which only
    PPO's reward uses; None keeps the walker's (and the base policy's) 5.0. ``--freeze-normaliser`` (config
    ``update_normaliser: false``), ``--learning-rate`` and ``--truncation`` reach the fine-tuning PPOConfig,
    ``--max-evals`` the CurriculumConfig. Builds the env only, compiles nothing."""
    from experiments import learn
    from jaxterrain import rl

    cfg = {**learn.PRESETS["smoke"], "archive": tiny_archive(4, "four.npz")}
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
    parser = argparse.ArgumentParser()
    learn.add_fine_tuning_arguments(parser)
    assert learn.fine_tuning_overrides(parser.parse_args(["--learning-rate", "1e-4"]))["learning_rate"] == 1e-4
    assert learn.fine_tuning_overrides(parser.parse_args(["--truncation", "mask"]))["truncation"] == "mask"


def test_learn_time_limit_counts_set_up_and_compilation(tmp_path, tiny_archive, monkeypatch):
    """``run_treatment(time_limit_s=T)`` gives the chunk loop what is left of T after its set-up (compilation), so a
    command under ``timeout`` stops in time. The set-up and the loop are stand-ins: nothing compiles."""
    import time
    from types import SimpleNamespace

    from experiments import learn
    from jaxterrain.runtime import driver

    cfg = {**learn.PRESETS["smoke"], "archive": tiny_archive(4, "four.npz")}
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


@pytest.fixture(scope="module")
def learn_smoke(tmp_path_factory, tiny_archive):
    """``(archive, run folder)``: ONE uninterrupted ``learn --preset smoke`` run on the 4-terrain archive, shared by
    the end-to-end test and the time-limit test (its uninterrupted reference)."""
    import contextlib
    import io

    from jaxterrain.runtime import driver

    from jaxterrain.curriculum import runner

    archive = tiny_archive(4, "four.npz")
    out = tmp_path_factory.mktemp("learn") / "whole"
    err = io.StringIO()  # not a terminal: plain progress lines (every one: PLAIN_EVERY_S = 0)
    seen = []  # metrics.csv as the per-chunk callback left it, after every chunk
    listen = runner.ChunkMetrics.__call__

    def snapshot(self, *args):
        listen(self, *args)
        seen.append((out / "metrics.csv").read_text() if (out / "metrics.csv").exists() else "")

    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stderr(err):
        mp.setattr(driver, "PLAIN_EVERY_S", 0.0)
        mp.setattr(runner.ChunkMetrics, "__call__", snapshot)
        assert cli("learn", "--preset", "smoke", "--archive", archive, "--out", str(out)) == 0
    (out.parent / "stderr.txt").write_text(err.getvalue())
    (out.parent / "metrics_seen.json").write_text(json.dumps(seen))
    return archive, out


def test_learn_reports_progress_after_every_chunk_inside_a_compiled_block(learn_smoke):
    """The smoke run's blocks are 2 chunks long (``--chunks-per-call 2``): a line after chunk 1 and after chunk 3
    comes from inside a block (the block's per-chunk host callback), not from between blocks."""
    _, out = learn_smoke
    lines = (out.parent / "stderr.txt").read_text().splitlines()
    chunks = [int(m.group(1)) for m in map(re.compile(r"^map: chunk (\d+) of 4, hardest").match, lines) if m]
    assert chunks == [1, 2, 3, 4], lines


def test_learn_writes_metrics_csv_after_every_chunk_inside_a_compiled_block(learn_smoke):
    """metrics.csv gains a row after every chunk, inside a block too (after chunks 1 and 3 of the smoke run's 2-chunk
    blocks), and each of those files is the start of the run's final metrics.csv: the driver's rows at a block's
    end are the ones the callback wrote."""
    _, out = learn_smoke
    seen = json.loads((out.parent / "metrics_seen.json").read_text())
    final = (out / "metrics.csv").read_text().splitlines()
    assert final[0] == "step,evaluation,hardest,trials_running" and len(final) == 1 + 4
    assert [len(text.splitlines()) for text in seen] == [2, 3, 4, 5]
    assert all(text.splitlines() == final[:len(text.splitlines())] for text in seen)


def test_learn_smoke_end_to_end(learn_smoke):
    _, out = learn_smoke
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["trials"] == 2 and cfg["curriculum"] == "map" and cfg["command"] == "learn"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["trials"] == 2 and summary["epochs_max"] <= 4 and summary["bank_terrains"] == 4
    rows = (out / "history.csv").read_text().splitlines()
    assert rows[0].startswith("trial,chunk,epoch") and len(rows) == 1 + sum(summary["epochs"])
    evals = np.array([float(r.split(",")[9]) for r in rows[1:]])
    assert np.all((evals >= 0) & (evals <= 1)) and evals.max() > 0  # the policy walked
    seq = (out / "sequences.csv").read_text().splitlines()
    assert seq[0].startswith("trial,order,terrain") and len(seq) >= 3
    assert seq[0].endswith(",end_epoch,generator") and all(r.endswith(",cppn") for r in seq[1:])
    gens = summary["generators"]
    assert set(gens) == {"cppn"} and gens["cppn"]["terrains"] == len(seq) - 1
    assert gens["cppn"]["chunks"] == sum(summary["epochs"]) and 0 <= gens["cppn"]["finished"] <= len(seq) - 1
    assert (out / "curve.png").stat().st_size > 0 and (out / "milestones.md").read_text().count("|") > 10
    assert (out / "checkpoint.npz").exists()
    assert cli("learn", "--resume", str(out)) == 0  # a finished run reports its summary again


@pytest.mark.parametrize("curriculum", ["levels", pytest.param("dr", marks=pytest.mark.slow),
                                        pytest.param("plr", marks=pytest.mark.slow),
                                        pytest.param("accel", marks=pytest.mark.slow)])
def test_learn_runs_the_per_env_curricula_end_to_end(tmp_path, tiny_archive, curriculum):
    """``learn --curriculum levels|dr|plr|accel --preset smoke``: each env on its own terrain through the real walker and PPO
    (each env's progress read from PPO's episode record), the selector's own summary, every trial's walker."""
    archive = tiny_archive(4, "four.npz")
    out = tmp_path / curriculum
    own = ["--levels", "2"] if curriculum == "levels" else ["--terrains-per-chunk", "3"]  # another's is refused
    assert cli("learn", "--preset", "smoke", "--archive", archive, "--curriculum", curriculum, *own,
               "--out", str(out)) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["epochs"] == [4, 4] and summary["ended_without_terrains"] == [False, False]
    if curriculum == "levels":
        assert all(0 <= v <= 1 for v in summary["max_level"]) and all(m >= 0 for m in summary["level_moves"])
    elif curriculum == "dr":
        assert summary["terrains_drawn"] == [15, 15]  # 3 at the start and after each of the 4 chunks
    elif curriculum == "plr":
        assert all(1 <= n <= 4 for n in summary["buffer_size"]) and all(0 <= r <= 4 for r in summary["replay_chunks"])
    else:  # accel: CPPN genomes (the archive's generator) rendered in the loop, the buffer not bound by the archive
        assert all(3 <= n <= 12 for n in summary["buffer_size"]) and all(0 <= r <= 4 for r in summary["edit_chunks"])
        assert json.loads((out / "config.json").read_text()).get("accel_generator") in (None, "cppn")
    rows = (out / "history.csv").read_text().splitlines()
    assert len(rows) == 1 + 8 and all(0 <= float(r.split(",")[9]) <= 1 for r in rows[1:])
    assert sorted(p.name for p in (out / "policies").iterdir()) == ["trial_0", "trial_1"]
    assert json.loads((out / "config.json").read_text())["curriculum"] == curriculum


def test_curriculum_sequences_take_every_treatments_columns(tmp_path):
    """curriculum's sequences.csv joins the treatments' files under the union of their columns: one written before
    the generator column existed keeps its rows, with that cell empty."""
    from experiments import curriculum as exp

    old, new = tmp_path / "old", tmp_path / "new"
    old.mkdir(), new.mkdir()
    (old / "sequences.csv").write_text("trial,order,terrain\n0,0,5\n")
    (new / "sequences.csv").write_text("trial,order,terrain,generator\n1,0,7,perlin\n1,1,9,cppn\n")
    exp.write_sequences(tmp_path, [("cppn roughness", old), ("combined map", new)])
    assert (tmp_path / "sequences.csv").read_text().splitlines() == [
        "treatment,trial,order,terrain,generator", "cppn roughness,0,0,5,", "combined map,1,0,7,perlin",
        "combined map,1,1,9,cppn"]


def test_curriculum_tables_put_the_papers_numbers_beside_ours(tmp_path):
    from experiments import curriculum as exp

    def summary(first_two, reached):
        return {"milestone_epochs": list(first_two) + [None] * 8, "milestone_trials": list(reached) + [0] * 8,
                "curve": {"epoch": [0, 40, 80], "mean": [0.0, 4.0, 8.0], "se": [0.0, 1.0, 0.5]}}

    rows = [("cppn map", summary([40.0, 120.0], [2, 1])), ("cppn roughness", summary([80.0, None], [2, 0]))]
    exp.write_table(tmp_path, rows, trials=2)
    exp.write_figures(tmp_path, rows, "roughness")
    md = (tmp_path / "table2.md").read_text().splitlines()
    assert md[2] == "| cppn map (ours) | 40 | 120 (1/2) | - | - | - | - | - | - | - | - |"
    assert md[3] == "| cppn map (paper) | 40 | 80 | 120 | 240 | 960 | 4720 | 7000 | 9880 | 13280 | - |"
    assert md[4].startswith("| cppn roughness (ours) | 80 | - |") and len(md) == 5
    table = (tmp_path / "table2.csv").read_text().splitlines()
    assert table[1].startswith("cppn map,ours,40.0,120.0,,") and table[2].startswith("cppn map,paper,40,80,120")
    assert (tmp_path / "figure7a.png").stat().st_size > 0 and (tmp_path / "figure7b.png").stat().st_size > 0
    partial = {**summary([40.0, None], [1, 0]), "partial": True, "epochs_max": 80}  # learn --report of a checkpoint
    (tmp_path / "p").mkdir()
    exp.write_table(tmp_path / "p", [("cppn map", partial)], trials=2)
    md = (tmp_path / "p" / "table2.md").read_text().splitlines()
    assert md[2].startswith("| cppn map [partial: 80 epochs] (ours) | 40 (1/2) |") and "(paper)" in md[3]
    (tmp_path / "b").mkdir()  # only the baseline so far (shards still running): no empty Figure 7a, no warning
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        exp.write_figures(tmp_path / "b", [("cppn roughness", summary([80.0, None], [2, 0]))], "roughness")
    assert not (tmp_path / "b" / "figure7a.png").exists() and not (tmp_path / "b" / "figure7b.png").exists()


def test_curriculum_shards_share_one_run_folder_and_resume_writes_the_tables(tmp_path, tiny_archive, capsys):
    """``curriculum --shard I/N`` runs only treatments ``t % N == I``; ``--resume`` without it reuses the finished
    treatments (here finished by hand, so nothing compiles) and writes Table 2 and the figures."""
    from experiments import curriculum as exp

    archive = tiny_archive(4, "four.npz")
    run = tmp_path / "exp2"
    fake = {"milestone_epochs": [40.0] + [None] * 9, "milestone_trials": [2] + [0] * 9, "hardest_mean": 3.0,
            "hardest": [2.5, 3.5], "curve": {"epoch": [0, 40], "mean": [0.0, 3.0], "se": [0.0, 0.5]}}
    for sub in ("cppn-map", "cppn-roughness"):  # the plan of one cppn archive: map (t = 0), then the baseline
        (run / sub).mkdir(parents=True)
        (run / sub / "summary.json").write_text(json.dumps(fake))
        (run / sub / "sequences.csv").write_text("trial,order,terrain\n0,0,1\n")
    base = ("curriculum", "--preset", "smoke", "--archives", f"cppn={archive}")
    assert cli(*base, "--out", str(run), "--shard", "1/2") == 0
    out = capsys.readouterr().out
    assert "shard 1/2 done (1 of 2 treatments)" in out and not (run / "table2.md").exists()
    with pytest.raises(SystemExit):
        cli(*base, "--out", str(run / "bad"), "--shard", "2/2")
    assert cli("curriculum", "--resume", str(run), "--report") == 0  # as they stand: here both finished
    assert "| cppn map (ours) | 40 |" in (run / "table2.md").read_text()
    (run / "table2.md").unlink()
    assert cli("curriculum", "--resume", str(run)) == 0
    md = (run / "table2.md").read_text()
    assert "| cppn map (ours) | 40 |" in md and "| cppn roughness (ours) | 40 |" in md
    assert (run / "figure7b.png").exists() and (run / "sequences.csv").read_text().count("cppn") == 2
    hardest = (run / "hardest.md").read_text()  # rliable's intervals beside mean +- s.e.
    assert "| cppn map | 2 | 3.00 +- 0.50 | 3.00 [2.50, 3.50] |" in hardest and "| cppn roughness | 0.50 | - |" in hardest
    # the plan follows the archives' names, not the order given: a fresh shard and a resumed one (config.json has
    # sorted keys) must agree on which treatment is t
    one = exp.treatments({"archives": {"perlin": archive, "cppn": archive}, "descriptors": ["roughness", "tpi"],
                          "baseline": "roughness"}, tmp_path / "p1")
    two = exp.treatments({"archives": {"cppn": archive, "perlin": archive}, "descriptors": ["roughness", "tpi"],
                          "baseline": "roughness"}, tmp_path / "p2")
    assert [t[0] for t in one] == [t[0] for t in two] == ["cppn", "perlin", "combined", "cppn"]
    eight = exp.treatments({"archives": {"perlin": archive, "cppn": archive}, "descriptors": ["roughness", "tpi"],
                            "baseline": ["roughness", "random"]}, tmp_path / "p1")  # Experiment 3's baselines
    assert [(t[0], t[2]) for t in eight] == [("cppn", "map"), ("perlin", "map"), ("combined", "map"),
                                             ("cppn", "roughness"), ("cppn", "random")]
    with pytest.raises(SystemExit):  # a baseline twice would be two treatments in one folder
        cli(*base, "--out", str(tmp_path / "twice"), "--baseline", "random", "random")
    assert not (tmp_path / "twice").exists()


def test_learn_writes_every_trials_walker_as_a_loadable_policy(tmp_path, learn_smoke):
    """``learn`` ends by writing ``policies/trial_K/``: ``rl.load_policy`` reads each, its parameters and normaliser
    are trial K's in the run's last checkpoint, they moved away from the base policy (PPO trained them), and
    ``config.json`` keeps the base policy's walker config (its solver) and records the trial's curriculum (epochs,
    env steps, the terrains in the order ``sequences.csv`` lists them). ``--resume RUN --export-policies`` writes the
    same weights from the checkpoint."""
    import hashlib
    import os
    import shutil
    from pathlib import Path

    from jaxterrain import rl

    _, out = learn_smoke
    cfg = common.load_config(out)  # its paths as this machine reads them
    states = runner.restored(run_config.from_flat(cfg), out)[6]
    base = rl.load_policy()
    seq = [r.split(",") for r in (out / "sequences.csv").read_text().splitlines()[1:]]
    for t in range(2):
        policy = rl.load_policy(out / "policies" / f"trial_{t}")
        params, normaliser = outputs.trial_policy(states, t)
        assert tree_equal(policy.params, params) and tree_equal(policy.normaliser, normaliser)
        moved = [float(np.max(np.abs(np.asarray(a) - np.asarray(b))))
                 for a, b in zip(jax.tree.leaves(policy.params["policy"]), jax.tree.leaves(base.params["policy"]))]
        assert max(moved) > 0.0, "the trained walker equals the base policy"
        assert (policy.observation_size, policy.action_size) == (base.observation_size, base.action_size)
        assert policy.meta["walker_config"] == base.meta["walker_config"]
        c = policy.meta["curriculum"]
        assert c["trial"] == t and c["selector"] == "map" and c["epochs"] == int(np.asarray(states.epoch)[t])
        assert c["env_steps"] == c["epochs"] * cfg["steps_per_epoch"] and c["epochs"] > 0
        assert c["terrains"] == [int(r[2]) for r in seq if int(r[0]) == t]
        assert c["hardest"] == pytest.approx(float(np.asarray(states.hardest)[t]))
        # no machine's absolute path: the archive relative to the run folder, the shipped base policy by package
        assert c["start_policy"] == "<jaxterrain>/assets/base_policy"
        assert c["archive"] == os.path.relpath(cfg["archive"], out) and not os.path.isabs(c["archive"])
        assert c["archive_file_sha256"] == hashlib.sha256(Path(cfg["archive"]).read_bytes()).hexdigest()
    saved = json.loads((out / "config.json").read_text())
    assert saved["archive"] == os.path.relpath(cfg["archive"], out) and str(out.parent) not in json.dumps(saved)
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    shutil.rmtree(copy / "policies")
    assert cli("learn", "--resume", str(copy), "--export-policies") == 0
    for t in range(2):
        assert ((copy / "policies" / f"trial_{t}" / "policy.msgpack").read_bytes()
                == (out / "policies" / f"trial_{t}" / "policy.msgpack").read_bytes())


def test_learn_killed_by_its_time_limit_resumes_to_the_uninterrupted_curves(tmp_path, learn_smoke, tiny_archive,
                                                                            capsys, monkeypatch):
    """Issues 13 and 59: a treatment stopped by ``--time-limit`` after its first chunk, INSIDE the uninterrupted
    run's first 2-chunk block (the env states ride in the checkpoint), and resumed ends with the same history,
    sequences and milestones as the uninterrupted one, bit for bit (same device, same seed: the module's smoke
    run). The compiled block is shared with the other smoke runs of this module. A resume whose archive file was replaced meanwhile, or whose `auto` backend would now pick other physics
    than the checkpoint's, is refused in one line, before anything compiles."""
    import shutil

    from jaxterrain import qd as A
    from jaxterrain.runtime import driver

    shared, whole = learn_smoke
    archive = str(shutil.copy(shared, tmp_path / "four.npz"))  # its label names the file; replaced, put back below
    parts = tmp_path / "parts"
    assert cli("learn", "--preset", "smoke", "--archive", archive, "--out", str(parts), "--time-limit", "1e-6") == 3
    assert not (parts / "summary.json").exists() and (parts / "checkpoint.npz").exists()
    digest = runner.archive_digest(A.load(archive))
    meta = driver.read_meta(parts)
    assert meta["archive_sha256"] == digest != runner.archive_digest(A.load(tiny_archive(3, "3.npz")))
    assert meta["backend"] == "jax"  # auto, resolved on this CPU machine; a resume must run on the same physics
    cfg = common.load_config(parts)
    runner.check_resumable(parts, run_config.from_flat(cfg), A.load(archive))
    with monkeypatch.context() as m:  # as if checkpointed on a GPU with MuJoCo Warp: auto must not switch to MJX
        m.setattr(driver, "read_meta", lambda folder: {**meta, "backend": "warp"})
        with pytest.raises(runner.BadInput, match=r"LearnConfig.walker.backend auto: it runs the walker on jax here, but .* on warp"):
            runner.check_resumable(parts, run_config.from_flat(cfg | {"backend": "auto"}), A.load(archive))
        runner.check_resumable(parts, run_config.from_flat(cfg), A.load(archive), physics=False)  # a report reads it on any machine
    shutil.copy(tiny_archive(3, "three.npz"), archive)  # another archive under the run's path
    for extra in ((), ("--report",)):
        capsys.readouterr()
        assert cli("learn", "--resume", str(parts), *extra) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and f"--archive {archive}: it is not the archive" in err[0], err
    shutil.copy(shared, archive)
    with monkeypatch.context() as m:  # a GPU run on MuJoCo Warp, reported where Warp does not import
        from jaxterrain import walker

        m.setattr(walker.tiles, "warp_available", lambda: (False, "MuJoCo Warp is not installed"))
        (parts / "config.json").write_text(json.dumps({**cfg, "backend": "warp"}))
        capsys.readouterr()
        assert cli("learn", "--resume", str(parts)) == 2  # training needs Warp: one line
        assert "--backend warp: MuJoCo Warp is not installed" in capsys.readouterr().err
        assert cli("learn", "--resume", str(parts), "--report") == 0  # the checkpoint's outputs, nothing trained
        (parts / "config.json").write_text(json.dumps(cfg))
    partial = json.loads((parts / "summary_partial.json").read_text())
    assert partial["partial"] and partial["chunks_done"] == 1 and not (parts / "summary.json").exists()
    assert partial["seconds"] > 0  # the wall time so far (checkpoint meta), set-up and compilation included
    rows = (parts / "history.csv").read_text().splitlines()[1:]
    assert rows and all(r.split(",")[1] == "0" for r in rows)  # the probe chunk, half of the first block
    assert any(k.startswith("leaf:" + runner.ENV_STATES + ".") for k in np.load(parts / "checkpoint.npz").files)
    with pytest.raises(SystemExit):
        cli("learn", "--preset", "smoke", "--report", "--out", str(tmp_path / "nothing"))
    assert not (tmp_path / "nothing").exists()
    assert cli("learn", "--resume", str(parts)) == 0
    assert (parts / "summary.json").exists() and not (parts / "summary_partial.json").exists()  # none out of date
    assert json.loads((parts / "summary.json").read_text())["seconds"] > partial["seconds"]  # summed over commands
    for name in ("history.csv", "sequences.csv", "milestones.csv"):
        assert (parts / name).read_text() == (whole / name).read_text(), name
    finished = json.loads((parts / "summary.json").read_text())
    for name in ("summary.json", "history.csv"):  # stopped after its last checkpoint, before its outputs (a crash)
        (parts / name).unlink()
    assert cli("learn", "--resume", str(parts), "--report") == 0  # the finished outputs, from the checkpoint
    assert not (parts / "summary_partial.json").exists()
    again = json.loads((parts / "summary.json").read_text())
    assert again == finished | {"seconds": again["seconds"]} and "partial" not in again
    assert (parts / "history.csv").read_text() == (whole / "history.csv").read_text()


def test_the_default_archives_are_the_five_shipped_headings_archives():
    """Without ``--archive(s)``, ``learn`` and ``curriculum`` run on the shipped paper-budget archives reseated under
    HEADINGS (80 walks, best 5, 4 headings, taken from each archive); ``smoke`` walks 2 along +x on any of them."""
    from experiments import curriculum as exp
    from experiments import learn

    assert sorted(exp.DEFAULT_ARCHIVES) == ["cppn", "diamond_square", "gan", "perlin", "worley"]
    assert exp.DEFAULT_ARCHIVES["cppn"] == learn.CPPN_ARCHIVE
    for name, path in exp.DEFAULT_ARCHIVES.items():
        arch = runner.load_archive(path, ["roughness", "tpi"])
        cfg = runner.resolve(run_config.PRESETS["gpu-short"], arch).curriculum
        assert (cfg.attempts, cfg.best, cfg.headings) == (80, 5, 4), name
        assert int(arch.filled.sum()) >= 100 and arch.config.generations == 25, name  # the paper's budget
    config, *_ = validated(dict(learn.PRESETS["smoke"]))
    assert (config.attempts, config.best, config.headings) == (2, 1, 1)


@pytest.mark.slow
def test_a_warp_checkpoint_is_reported_through_the_mjx_layout(tmp_path, monkeypatch):
    """A `learn --backend warp` run's checkpoint (one block of the smoke preset on MuJoCo Warp's CPU device) is read
    by `--report` into the MJX-JAX layout's states (`runner.report_run`): every leaf has the shape it had on Warp, so
    a GPU run reports on a machine without Warp; resuming it there is refused (the checkpoint records warp)."""
    from jaxterrain.walker import warp_available

    if not warp_available()[0]:
        pytest.skip(warp_available()[1])
    run = tmp_path / "warp"
    assert cli("learn", "--preset", "smoke", "--backend", "warp", "--out", str(run), "--time-limit", "1e-6") == 3
    assert driver.read_meta(run)["backend"] == "warp"
    from jaxterrain import walker

    monkeypatch.setattr(walker.tiles, "warp_available", lambda: (False, "MuJoCo Warp is not installed"))
    assert cli("learn", "--resume", str(run), "--report") == 0
    assert json.loads((run / "summary_partial.json").read_text())["chunks_done"] == 1  # the time limit's probe
    cfg = json.loads((run / "config.json").read_text())
    (run / "config.json").write_text(json.dumps({**cfg, "backend": "auto"}))
    assert cli("learn", "--resume", str(run)) == 2  # auto -> jax here; the checkpoint was written on warp


@pytest.mark.slow
def test_learn_overlap_with_bootstrap_truncation_runs_to_the_end(tmp_path, learn_smoke):
    """``learn --overlap --truncation bootstrap`` (the paper-budget baseline's flags; the bootstrap values come from
    the PPO envs' own rows of a batch the evaluation walks ride in): the run ends with the plain run's chunks and
    epochs, every evaluation in [0, 1], and config.json keeps both flags."""
    import csv

    archive, whole = learn_smoke
    out = tmp_path / "boot"
    assert cli("learn", "--preset", "smoke", "--archive", archive, "--overlap", "--truncation", "bootstrap",
               "--out", str(out)) == 0
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["overlap"] is True and cfg["truncation"] == "bootstrap"

    def rows(folder):
        with open(folder / "history.csv") as f:
            return list(csv.DictReader(f))

    a, b = rows(whole), rows(out)
    assert [(r["trial"], r["chunk"], r["epoch"]) for r in a] == [(r["trial"], r["chunk"], r["epoch"]) for r in b]
    assert all(0.0 <= float(r["evaluation"]) <= 1.0 for r in b)


@pytest.mark.slow
def test_learn_overlap_smoke_makes_the_plain_choices_and_resumes(tmp_path, learn_smoke):
    """``learn --overlap`` (MJX on one tile per trial, the evaluation walks riding along PPO): stopped after its
    first block and resumed, it ends with the uninterrupted plain run's terrain sequences and epochs (evaluations up
    to the float rounding of other batches; each block restarts the envs at another chunk, so the two runs' PPO
    data differ after the first block); config.json keeps overlap. Two more smoke programs: minutes of CPU."""
    import csv

    archive, whole = learn_smoke
    out = tmp_path / "over"
    assert cli("learn", "--preset", "smoke", "--archive", archive, "--overlap", "--out", str(out),
               "--time-limit", "1e-6") == 3
    assert json.loads((out / "config.json").read_text())["overlap"] is True
    assert cli("learn", "--resume", str(out)) == 0

    def rows(folder):
        with open(folder / "history.csv") as f:
            return list(csv.DictReader(f))

    a, b = rows(whole), rows(out)
    assert [(r["trial"], r["chunk"], r["epoch"], r["terrain"]) for r in a] == \
        [(r["trial"], r["chunk"], r["epoch"], r["terrain"]) for r in b]
    np.testing.assert_allclose([float(r["evaluation"]) for r in b], [float(r["evaluation"]) for r in a], atol=0.05)


@pytest.mark.slow
def test_learn_compact_blocks_run_the_same_treatment(tmp_path, learn_smoke):
    """``learn --compact`` (on in the GPU presets): a 3-trial smoke run whose trials end at different chunks (a
    threshold the smoke walker passes on some evaluations only) runs its later blocks on the running trials only
    and writes the history of the run that keeps every trial in every block (CPU: exactly); ``--policy-every 4``
    adds snapshots of the walkers at chunks 4 and 8 and changes nothing else. Minutes of CPU."""

    archive, _ = learn_smoke
    runs = {}
    for flag in ("--no-compact", "--compact"):
        out = runs[flag] = tmp_path / flag
        before = {sig: set(blocks) for sig, (_, _, blocks) in runner.PROGRAMS.items()}
        every = ["--policy-every", "4"] if flag == "--compact" else []  # snapshots: no effect on the run
        assert cli("learn", "--preset", "smoke", "--archive", archive, "--trials", "3", "--threshold", "0.348",
                   "--max-epochs", "8", flag, "--out", str(out), *every) == 0
        assert json.loads((out / "config.json").read_text())["compact"] is (flag == "--compact")
        sizes = set().union(*(set(b) - before.get(sig, set()) for sig, (_, _, b) in runner.PROGRAMS.items()))
    epochs = json.loads((runs["--compact"] / "summary.json").read_text())["epochs"]
    assert min(epochs) < max(epochs) and min(sizes, default=3) < 3, (epochs, sizes)  # smaller blocks compiled, ran
    assert (runs["--compact"] / "history.csv").read_text() == (runs["--no-compact"] / "history.csv").read_text()
    pol = runs["--compact"] / "policies"
    assert sorted(p.name for p in pol.iterdir()) == ["chunk_00004", "chunk_00008", "trial_0", "trial_1", "trial_2"]
    assert sorted(p.name for p in (pol / "chunk_00004").iterdir()) == ["trial_0", "trial_1", "trial_2"]
    assert not (runs["--no-compact"] / "policies" / "chunk_00004").exists()
    for k in range(3):  # the last snapshot is the final walker
        assert ((pol / "chunk_00008" / f"trial_{k}" / "policy.msgpack").read_bytes()
                == (pol / f"trial_{k}" / "policy.msgpack").read_bytes())
