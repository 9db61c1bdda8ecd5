"""``jaxterrain.suite.batch``: many walkers on a suite, resumably. A run cut short by its time limit and run again
walks every job exactly once, each with the key ``evaluate`` gives it; a store refuses other settings and other
terrains; a group's results are written as ``evaluate`` writes an evaluation (``generalise`` reads them back); a
robot's base policy and all its walkers, whatever each was trained with, go through one program. The walks here are
a stand-in (``run``'s ``walk`` argument) that records its calls; the real walks are the slow test of
``docs/results/suite_v2/reevaluate.py`` (tests/suite/test_reevaluate_script.py)."""

from __future__ import annotations

import json
import shutil
import tarfile
from pathlib import Path

import jax
import numpy as np
import pytest

from jaxterrain import difficulty, rl, suite
from jaxterrain.suite import batch

RESULTS = Path(__file__).resolve().parents[2] / "docs" / "results"
EXP3_WALKER = RESULTS / "exp3_gpushort" / "cppn-map" / "policies" / "trial_0"   # the paper recipe's training config
WIDE_WALKER = RESULTS / "wide_gpushort" / "perlin-map" / "policies" / "trial_3"  # the wide recipe's


@pytest.fixture(scope="module")
def tiny():
    """v2's humanoid levels at 96 pixels: flat and boxes, one terrain a level (11 terrains)."""
    return suite.load("v2", robot="humanoid", size=96, seeds=1, families=["flat", "boxes"], generator_names=[])


def experiment(root: Path) -> Path:
    """``root/exp`` with two treatments of one shipped walker each (``a/policies/trial_0``, ``b/policies/trial_1``)."""
    for name, k, src in (("a", 0, EXP3_WALKER), ("b", 1, WIDE_WALKER)):
        shutil.copytree(src, root / "exp" / name / "policies" / f"trial_{k}")
    return root / "exp"


class FakeWalks:
    """``run``'s ``walk``: records each call, takes ``seconds`` on ``clock`` and returns a fitness that depends on
    the key and the policy's weights (so a test can tell which key and which walker walked)."""

    def __init__(self, seconds: float = 10.0):
        self.now, self.seconds, self.calls = 0.0, seconds, []

    def clock(self) -> float:
        return self.now

    def __call__(self, policies, heightmaps, key, protocol, backend, scale, slots, chunk):
        (p,) = policies
        self.calls.append((p, np.asarray(jax.random.key_data(key)), protocol, backend, slots, chunk))
        self.now += self.seconds
        w = float(np.abs(jax.tree.leaves(p.params["policy"])[0]).sum())
        u = jax.random.uniform(key, (heightmaps.shape[0],))
        return np.asarray((u + w) % 1.0, np.float32)[None]


def test_a_run_cut_short_resumes_and_walks_every_job_once_with_evaluates_keys(tmp_path, tiny):
    jobs = batch.base_jobs("humanoid", 3) + batch.walker_jobs([experiment(tmp_path)])
    assert [j.name for j in jobs[:3]] == ["base:humanoid", "base:humanoid:key1", "base:humanoid:key2"]
    assert [(Path(j.name).parent.parent.name, j.key, j.robot) for j in jobs[3:]] == [("a", 0, "humanoid"),
                                                                                   ("b", 0, "humanoid")]
    protocol = difficulty.Protocol(2, 1, 1)
    settings = batch.settings("v2", protocol, "jax", None, None, seed=0)
    store = batch.Store(tmp_path / "work", settings)
    walks = FakeWalks(seconds=10.0)
    builds = []

    def suites(robot):
        builds.append(robot)
        return tiny

    # 35 s: the first walk always runs; after it the next is predicted at 10 s (x MARGIN), 2 more fit, a 4th not
    first = batch.run(jobs, store, suites, time_limit_s=35.0, walk=walks, clock=walks.clock, log=lambda _: None)
    assert first["walked"] == [j.name for j in jobs[:3]] and first["left"] == [j.name for j in jobs[3:]]
    assert first["stopped"].startswith("time limit")
    again = batch.Store(tmp_path / "work", settings)   # a new process: the same folder
    second = batch.run(jobs, again, suites, time_limit_s=35.0, walk=walks, clock=walks.clock, log=lambda _: None)
    assert second["skipped"] == first["walked"] and second["walked"] == first["left"] and not second["stopped"]
    assert len(walks.calls) == len(jobs) and builds == ["humanoid", "humanoid"]  # one build per process
    third = batch.run(jobs, again, suites, walk=walks, clock=walks.clock, log=lambda _: None)
    assert third["walked"] == [] and len(walks.calls) == len(jobs)  # nothing walked twice
    keys = [c[1] for c in walks.calls]
    for call, job in zip(walks.calls, jobs):  # evaluate's keys: fold_in(key(seed), 3), then fold_in(., k)
        expected = jax.random.fold_in(jax.random.key(0), 3)
        expected = expected if job.key == 0 else jax.random.fold_in(expected, job.key)
        np.testing.assert_array_equal(call[1], jax.random.key_data(expected))
        assert call[2:] == (protocol, "jax", None, None)
    np.testing.assert_array_equal(keys[0], keys[3])  # a walker walks with the base policy's first key
    assert not np.array_equal(keys[0], keys[1])
    np.testing.assert_array_equal(walks.calls[3][0].params["policy"]["params"]["mlp"]["hidden_0"]["kernel"],
                                  rl.load_policy(EXP3_WALKER).params["policy"]["params"]["mlp"]["hidden_0"]["kernel"])
    fit, meta = again.read(jobs[3].name)
    assert fit.shape == (tiny.size,) and meta["name"] == jobs[3].name and meta["key"] == 0
    assert meta["compiled_before"] is False  # the first walk of that process, and of its program
    assert [again.read(j.name)[1]["compiled_before"] for j in jobs] == [False, True, True, False, True]
    record = again.suite_record("humanoid")
    assert record["terrains"] == tiny.size and record["family"] == tiny.family.tolist()


def test_a_process_predicts_from_its_own_walks_once_it_has_them(tmp_path, tiny):
    """A walk recorded at 40 s by another process (two processes sharing a host walked that slowly) predicts only
    this process's first compiled walk: after that its own 10 s walks do, so a 60 s limit walks 5 jobs, not 2."""
    jobs = batch.base_jobs("humanoid", 6)
    settings = batch.settings("v2", difficulty.Protocol(2, 1, 1), "jax", None, None, seed=0)
    store = batch.Store(tmp_path / "work", settings)
    slow = batch.base_jobs("humanoid", 8)[7]
    store.write(slow, np.zeros(tiny.size, np.float32), seconds=40.0, compiled_before=True)
    walks = FakeWalks(seconds=10.0)
    out = batch.run(jobs, store, lambda robot: tiny, time_limit_s=60.0, walk=walks, clock=walks.clock,
                    log=lambda _: None)
    # t=10: next predicted from the store, 40 x MARGIN, fits; t=20 on: 10 x MARGIN; t=50: 61.5 > 60
    assert out["walked"] == [j.name for j in jobs[:5]] and out["left"] == [jobs[5].name]


def test_a_store_refuses_other_settings_and_other_terrains(tmp_path, tiny):
    protocol = difficulty.Protocol(2, 1, 1)
    store = batch.Store(tmp_path, batch.settings("v2", protocol, "jax", seed=0))
    with pytest.raises(batch.StoreMismatch, match="seed 0 there, 1 here"):
        batch.Store(tmp_path, batch.settings("v2", protocol, "jax", seed=1))
    with pytest.raises(batch.StoreMismatch, match="protocol"):
        batch.Store(tmp_path, batch.settings("v2", difficulty.Protocol(4, 1, 1), "jax", seed=0))
    store.check_suite("humanoid", tiny, 1.0)
    store.check_suite("humanoid", tiny._replace(heightmaps=tiny.heightmaps + 1e-9), 1.0)  # float rounding: the same
    other = tiny._replace(heightmaps=tiny.heightmaps.copy())
    other.heightmaps[5, 40:50, 40:50] += 0.05  # a box moved: another terrain
    with pytest.raises(batch.StoreMismatch, match="not the one its results were walked on"):
        store.check_suite("humanoid", other)
    assert store.build_seconds("humanoid") == [1.0, 1.0]
    with pytest.raises(batch.StoreMismatch, match="not a store"):
        batch.Store(tmp_path / "empty")
    with pytest.raises(ValueError, match="no policies/trial_K walker"):
        batch.walker_jobs([tmp_path])
    with pytest.raises(ValueError, match="keys must be an integer >= 1"):
        batch.base_jobs("humanoid", 0)


def test_a_groups_results_are_written_as_evaluate_writes_them_and_packed_into_one_file(tmp_path, tiny, monkeypatch):
    jobs = batch.base_jobs("humanoid", 2) + batch.walker_jobs([experiment(tmp_path)])
    store = batch.Store(tmp_path / "work", batch.settings("v2", difficulty.Protocol(2, 1, 1), "jax"))
    walks = FakeWalks()
    batch.run(jobs, store, lambda robot: tiny, walk=walks, clock=walks.clock, log=lambda _: None)
    names = [jobs[0].name, jobs[2].name]
    recorded = store.suite("humanoid")   # the terrains' table, no heightmaps: what a CPU writes from
    assert recorded.heightmaps.shape == (tiny.size, 0, 0) and recorded.rows() == tiny.rows()
    assert recorded.name == tiny.name and recorded.scale == tiny.scale and recorded.unit == tiny.unit
    out = batch.write_group(store, names, tmp_path / "exp" / "a" / "heldout_v2", recorded, ["base", jobs[2].name],
                            {"robot": "humanoid"})
    assert sorted(p.name for p in out.iterdir()) == ["config.json", "fitness.csv.gz", "levels.csv", "levels.png",
                                                     "summary.md", "timing.json"]
    ev = suite.read_fitness(out / "fitness.csv.gz")
    assert ev.policies == ["base", jobs[2].name]
    np.testing.assert_allclose(ev.fitness, store.fitness(names), atol=5e-5)  # 4 decimals in the CSV
    assert ev.family.tolist() == tiny.family.tolist() and ev.level.tolist() == tiny.level.tolist()
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["jobs"] == names and cfg["rows"] == ["base", jobs[2].name] and cfg["walked_with"] == store.settings
    with pytest.raises(ValueError, match="terrains"):
        batch.write_group(store, names, tmp_path / "x", tiny._replace(level=tiny.level[::-1].copy()))
    with pytest.raises(ValueError, match="suite_figure must be False"):
        batch.write_group(store, names, tmp_path / "x", recorded, suite_figure=True)
    monkeypatch.chdir(tmp_path)
    archive = batch.pack(["work", "exp/a/heldout_v2"], tmp_path / "out" / "v2eval.tar.gz")
    with tarfile.open(archive) as tar:
        members = tar.getnames()
    assert "work/settings.json" in members and "exp/a/heldout_v2/fitness.csv.gz" in members
    assert sum(m.startswith("work/results/") for m in members) == len(jobs)
    with pytest.raises(ValueError, match="is not under"):
        batch.pack([tmp_path.parent], tmp_path / "x.tar.gz")


def test_a_robots_base_policy_and_its_walkers_of_every_recipe_go_through_one_program(monkeypatch, tiny):
    """The walkers were fine-tuned with other envs and minibatches than the base policy (and the wide recipe's with
    others again) and carry no value network: ``evaluate_policies`` hands ``difficulty`` the same policy function,
    the same env config and weights of the same structure for all of them, so its program cache (keyed on the
    function and config) compiles one program and jit does not retrace. Nothing is compiled here: the walks are
    caught."""
    from jaxterrain.suite import evaluation

    seen = []

    def caught(h, key, policy, policy_params, env_config, protocol, slots, chunk):
        seen.append((policy, env_config, jax.tree.structure(policy_params),
                     [(a.shape, a.dtype) for a in jax.tree.leaves(policy_params)]))
        return np.zeros(h.shape[0], np.float32)

    monkeypatch.setattr(evaluation.difficulty, "evaluate", caught)
    base = difficulty.robot_base_policy("humanoid")
    walkers = [rl.load_policy(EXP3_WALKER), rl.load_policy(WIDE_WALKER)]
    assert base.config != walkers[0].config != walkers[1].config and "value" in base.params
    suite.evaluate_policies([base, *walkers], tiny.heightmaps, jax.random.key(0), difficulty.Protocol(2, 1, 1))
    assert len(seen) == 3 and all(s == seen[0] for s in seen[1:])
    ant = [difficulty.robot_base_policy("ant"), rl.load_policy(RESULTS / "ant_gpushort/learn/policies/trial_0")]
    assert ant[0].config != ant[1].config
    assert rl.policy_fn(ant[0].config, int(ant[0].action_size)) is rl.policy_fn(ant[1].config, int(ant[1].action_size))
    other = rl.policy_fn(base.config._replace(policy_hidden=(8,)), 17)
    assert other is not rl.policy_fn(base.config, 17)
    fresh = rl.policy_fn.__wrapped__(base.config, 17)   # the uncached builder (benchmarks' peer)
    assert fresh is not rl.policy_fn(base.config, 17)


def test_the_shipped_experiments_hold_170_walkers():
    found = {}
    for folder in ("exp3_gpushort", "exp3b_gpushort", "exp3c_gpushort", "wide_gpushort", "ant_gpushort/learn"):
        for t in batch.treatment_folders(RESULTS / folder):
            found[str(t.relative_to(RESULTS))] = len(list((t / "policies").glob("trial_*")))
    assert sum(found.values()) == 170 and set(found.values()) == {10} and len(found) == 17


def test_a_robots_perceptive_base_policy_walks_as_its_own_group():
    """``base_jobs(robot, keys, "perceptive")``: the shipped perceptive twin as a policy folder, keys 0 .. keys - 1,
    in a group of its own beside the blind one's (whose names are unchanged); an unknown set is one ValueError."""
    from jaxterrain import rl

    jobs = batch.base_jobs("ant", 2, "perceptive")
    folder = str(rl.base_policy_dir("ant", "perceptive"))
    assert jobs == [batch.Job("base:ant:perceptive", "ant", folder, 0, "base:ant:perceptive"),
                    batch.Job("base:ant:perceptive:key1", "ant", folder, 1, "base:ant:perceptive")]
    assert [j.name for j in batch.base_jobs("humanoid", 2)] == ["base:humanoid", "base:humanoid:key1"]
    from jaxterrain.difficulty import policy_observation

    assert policy_observation(rl.load_policy(jobs[0].policy))["observation"] == "perceptive"
    assert batch.base_jobs("humanoid", 1, "perceptive")[0].policy == str(rl.base_policy_dir("humanoid", "perceptive"))
    with pytest.raises(ValueError, match="observation must be one of"):
        batch.base_jobs("humanoid", 1, "sonar")
