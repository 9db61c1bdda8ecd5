"""jaxterrain.curriculum.population: several treatments' trials in one compiled program. Each member's states equal
its solo run's (``run_trials``) bit for bit: same keys, terrains, starting policies and choices, the physics batched
over all members' trials (here a fake harness whose training and evaluation depend on their keys and terrains, so a
wrong key, terrain or trial order changes the result). Toy banks of different sizes (a map curriculum's GP over each
member's own archive), members with their own selectors and budgets, the running-rows block, per-member block
lengths and a population stopped between blocks and resumed from each member's checkpoint."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxterrain import curriculum as C
from jaxterrain.curriculum import population as P
from jaxterrain.curriculum.checkpoints import restore_states
from jaxterrain.qd import TerrainBank, cell_distance
from jaxterrain.runtime import driver

from curriculum_archives import tree_equal


def toy_bank(b: int, tilt: float = 0.03) -> TerrainBank:
    """A bank of every cell of a b x b grid: prior ``1 - 0.12 |cell| - tilt b0``; terrain = a constant 2 x 2 map of
    its difficulty ``1 - prior``."""
    b0, b1 = np.meshgrid(np.arange(b), np.arange(b))
    fitness = np.clip(1.0 - 0.12 * np.hypot(b0, b1) - tilt * b0, 0.0, 1.0).astype(np.float32).ravel()
    bins = np.stack([b0.ravel(), b1.ravel()], -1).astype(np.int32)
    points = (bins / max(b - 1, 1)).astype(np.float32)
    maps = np.broadcast_to((1.0 - fitness)[:, None, None], (fitness.size, 2, 2)).astype(np.float32)
    return TerrainBank(jnp.asarray(maps), jnp.asarray(fitness), jnp.asarray(points), jnp.asarray(points),
                       jnp.asarray(bins), jnp.asarray(cell_distance(bins)), jnp.arange(fitness.size, dtype=jnp.int32),
                       jnp.zeros(fitness.size, jnp.int32))


def keyed_harness(gain: float = 0.05, overlap: bool = False) -> C.Harness:
    """Training adds ``gain x U(0.5, 1.5)`` (its key) to the skill; fitness = ``clip(1 - mean(terrain) + skill +
    0.02 N(0, 1), 0, 1)`` (its key); a reset counts."""

    def train(policy, key, terrain):
        return {**policy, "skill": policy["skill"] + gain * jax.random.uniform(key, (), minval=0.5, maxval=1.5),
                "steps": policy["steps"] + 1}

    def evaluate(policy, key, terrain):
        return jnp.clip(1.0 - jnp.mean(terrain) + policy["skill"] + 0.02 * jax.random.normal(key, ()), 0.0, 1.0)

    def reset(policy, key, terrain):
        return {**policy, "resets": policy["resets"] + 1}

    both = (lambda p, k, t, ek: (train(p, k, t), evaluate(p, ek, t))) if overlap else None
    return C.Harness(train, evaluate, reset, train_evaluate=both)


START = {"skill": jnp.zeros((), jnp.float32), "resets": jnp.zeros((), jnp.int32), "steps": jnp.zeros((), jnp.int32)}


def small(selector="map", **kw) -> C.CurriculumConfig:
    base = dict(selector=selector, epochs_per_chunk=1, steps_per_epoch=8, max_epochs=30, max_evals=3, num_envs=2,
                unroll_length=2, num_unrolls=2, num_minibatches=1)
    return C.validate_config(C.CurriculumConfig.from_json_dict({**base, **kw}))


def members(overlap=False, max_epochs=(30, 24), selectors=("map", "map")):
    """Two treatments of 2 trials each: a 4 x 4 and a 3 x 3 toy bank (other priors), their own seeds."""
    banks = (toy_bank(4), toy_bank(3, tilt=0.1))
    configs = tuple(small(s, max_epochs=e, overlap=overlap) for s, e in zip(selectors, max_epochs))
    harness = keyed_harness(0.04, overlap)
    keys = (jax.random.split(jax.random.key(1), 2), jax.random.split(jax.random.key(2), 2))

    def init():
        return tuple(C.init_trials(k, b, START, config=c, harness=harness) for k, b, c in zip(keys, banks, configs))

    return banks, configs, harness, init


def solo(banks, configs, harness, init, chunks):
    return tuple(C.make_runner(c, harness)(s, b, chunks) for s, b, c in zip(init(), banks, configs))


@pytest.mark.parametrize("overlap", [False, pytest.param(True, marks=pytest.mark.slow)])
def test_a_population_equals_each_treatment_run_alone(overlap):
    """Two map treatments (banks of 16 and 9 terrains, budgets of 30 and 24 epochs) in one program, to the end:
    every leaf of each member's states (histories, GP observations, policies, keys) equals its solo run's, bit for
    bit. With overlap, in blocks of 4 on the running rows only, the same."""
    banks, configs, harness, init = members(overlap)
    alone = solo(banks, configs, harness, init, 100)
    run = C.make_population_runner(configs, harness)
    together = run(init(), banks, 100)
    assert all(tree_equal(a, b) for a, b in zip(together, alone))
    assert all(np.all(np.asarray(s.done)) for s in alone)
    terrains = [np.asarray(s.history.terrain) for s in alone]
    assert not np.array_equal(terrains[0][:, :24], terrains[1][:, :24])  # two curricula, not one copied
    if not overlap:
        return  # the running rows: below, and in the killed population's test
    states, sizes = init(), []
    while not all(np.all(np.asarray(s.done)) for s in states):
        rows = P.population_rows([s.done for s in states])
        sizes.append(4 if rows is None else rows.size)
        states = run(states, banks, np.array([4, 4], np.int32), None if rows is None else jnp.asarray(rows))
    assert all(tree_equal(a, b) for a, b in zip(states, alone))
    assert sizes[0] == 4 and min(sizes) < 4, sizes


def test_members_run_their_own_blocks_and_selectors():
    """A member's block length is its own (n = [3, 0]: the second does not move), and members with other selectors
    (map and random, one slot each) share a program, each running its own selector's code."""
    banks, configs, harness, init = members(selectors=("map", "random"))
    run = C.make_population_runner(configs, harness)
    a, b = run(init(), banks, np.array([3, 0], np.int32))
    assert np.asarray(a.chunk).tolist() == [3, 3] and np.asarray(b.chunk).tolist() == [0, 0]
    alone = solo(banks, configs, harness, init, 100)
    states = init()
    for n in ([3, 0], [5, 9], [100, 100]):
        states = run(states, banks, np.array(n, np.int32))
    assert all(tree_equal(x, y) for x, y in zip(states, alone))
    with pytest.raises(ValueError, match="Selector.slots"):
        C.make_population_runner((configs[0], small("dr", terrains_per_chunk=2)), harness)
    with pytest.raises(ValueError, match="CurriculumConfig.steps_per_chunk"):
        C.make_population_runner((configs[0], small(steps_per_epoch=16)), harness)


# ---------------------------------------------------------------------------------------------------------------
# The host loop of a population (jaxterrain.curriculum.batch): per-member checkpoints, time limit, resume
# ---------------------------------------------------------------------------------------------------------------
def test_plan_groups_keeps_equal_keys_together_under_the_env_cap():
    from jaxterrain.curriculum.batch import plan_groups

    keys = ["map", "map", "dr", "map", "dr"]
    assert plan_groups(keys, [10, 10, 10, 10, 10], 100) == [[0, 1, 3], [2, 4]]
    assert plan_groups(keys, [10, 10, 10, 10, 10], 20) == [[0, 1], [2, 4], [3]]
    assert plan_groups(keys, [50, 10, 10, 10, 10], 20) == [[0], [1, 3], [2, 4]]  # one over the cap: alone


def test_shards_keep_populations_whole_and_balance_them():
    """``curriculum --shard I/N`` with populations: each population on one process, longest first to the least
    loaded (a population costs ``FIXED_TRIALS + trials``); fewer populations than processes: the costliest is
    halved, its treatments alternately (the six map treatments over two GPUs: ``t % 2``)."""
    from jaxterrain.curriculum.batch import shard_groups

    exp4 = ["map", "map", "dr", "dr", "levels"]  # Experiment 4: steps-map, mixed-map, mixed-dr, mixed-plr, levels
    assert shard_groups(exp4, [5000] * 5, [10] * 5, 2) == [0, 0, 1, 1, 0]
    assert shard_groups(exp4, [5000] * 5, [10] * 5, 3) == [0, 0, 1, 1, 2]
    assert shard_groups(exp4, [5000] * 5, [10] * 5, 1) == [0] * 5
    assert shard_groups(["map"] * 6, [5000] * 6, [10] * 6, 2) == [0, 1, 0, 1, 0, 1]
    assert shard_groups(["map"] * 6, [5000] * 6, [10] * 6, 4) == [0, 1, 2, 3, 0, 1]  # halved twice, then placed
    assert shard_groups(["map"], [5000], [10], 3) == [0]  # one treatment: the other processes get none
    # the env cap splits a group first (plan_groups), and a bigger population goes first
    assert shard_groups(["map"] * 3 + ["dr"], [5000] * 4, [10, 10, 10, 40], 2, max_envs=10_000) == [1, 1, 1, 0]
    with pytest.raises(ValueError, match="count"):
        shard_groups(exp4, [1] * 5, [1] * 5, 0)


def _hosted(folders, restore=False):
    """The members of :func:`members` as host members of ``batch.drive`` in ``folders``, fresh or each restored
    from its own checkpoint; and the population's block."""
    from jaxterrain.curriculum import batch

    banks, configs, harness, init = members()
    run = C.make_population_runner(configs, harness)
    out = []
    for m, (s, c, folder) in enumerate(zip(init(), configs, folders)):
        got = restore_states(folder, s, {"trials": 4, "offset": 2 * m}, tiled=False) if restore else None
        s, done, history = (s, 0, None) if got is None else got[:3]
        out.append(batch.Member(f"m{m}", folder, s, c.max_chunks, done=done, history=history))
    return out, (lambda states, n, rows: run(states, banks, n, rows))


def test_a_killed_population_resumes_each_member_to_the_uninterrupted_run(tmp_path, monkeypatch):
    """``batch.drive`` writes each member's checkpoint and metrics after every block. Killed while writing the
    second block's checkpoints (member 0's written, member 1's not: the members restore at different chunks), and
    resumed from the checkpoints, every member ends with the states, metrics.csv and metric history of the
    uninterrupted run (which computes every trial in every block; the others the running trials only); under a
    time limit the first block is one chunk."""
    from jaxterrain.curriculum import batch

    whole, block = _hosted([tmp_path / "whole" / f"m{m}" for m in range(2)])
    assert batch.drive(whole, block, every=4, progress=False, compact=False)
    assert [m.summary for m in whole] == [{"chunks": 30}, {"chunks": 24}]
    folders = [tmp_path / "part" / f"m{m}" for m in range(2)]
    part, block = _hosted(folders)
    assert not batch.drive(part, block, every=4, time_limit_s=1e-9, progress=False)  # the probe: one chunk
    assert [m.done for m in part] == [1, 1]
    part, block = _hosted(folders, restore=True)
    written, real = [], driver.write_checkpoint

    def kill(folder, *args):
        if len(written) == 3:  # block 2: member 0 written, then the process dies
            raise KeyboardInterrupt
        written.append(folder)
        real(folder, *args)

    monkeypatch.setattr(driver, "write_checkpoint", kill)
    with pytest.raises(KeyboardInterrupt):
        batch.drive(part, block, every=4, progress=False)
    monkeypatch.setattr(driver, "write_checkpoint", real)
    part, block = _hosted(folders, restore=True)
    assert [m.done for m in part] == [9, 5]
    assert batch.drive(part, block, every=4, progress=False)
    for a, b in zip(part, whole):
        assert tree_equal(a.states, b.states) and sorted(a.history) == sorted(b.history)
        assert all(np.array_equal(a.history[k], b.history[k], equal_nan=True) for k in a.history)
        assert (a.folder / "metrics.csv").read_text() == (b.folder / "metrics.csv").read_text()
