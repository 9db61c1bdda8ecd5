"""``docs/results/suite_v2/reevaluate.py``: every shipped walker on suite v2 in commands that fit a GPU call. At a
tiny size on the CPU: cut short by its time limit, each call walks what fits and the next skips what is done; a
group's evaluation (a treatment's ``heldout_v2/``, a robot's base folder) is written when its last walk ends, and
``--pack`` puts the work and every written folder into one tar. Bad flags are one line. The real walks (slow):
tests/integration/test_reevaluate_v2.py."""

from __future__ import annotations

import json
import tarfile
import time

import jax
import numpy as np
import pytest

from jaxterrain import suite
from jaxterrain.runtime.io import atomic_save_npz
from jaxterrain.suite import batch
from reevaluate_v2 import args, exp, load_script, RESULTS, ROOT  # exp: a fixture


@pytest.fixture(scope="module")
def script():
    return load_script()


def test_bad_flags_are_one_line_naming_them(script, exp, capsys):
    for argv, text in ((["--time-limit", "0"], "--time-limit must be a number of minutes > 0"),
                       (["--keys", "0"], "--keys must be an integer >= 1"),
                       (["--heldout-name", "heldout"], "--heldout-name must be a new folder name"),
                       (["--pack", "x.zip"], "--pack must name a .tar.gz"),
                       (["--best", "3"], "--best must be <= attempts / headings = 2")):
        with pytest.raises(SystemExit) as stop:
            script.main(args(*argv))
        assert stop.value.code == 2 and text in capsys.readouterr().err
    (exp / "empty").mkdir()
    with pytest.raises(SystemExit) as stop:
        script.main(["empty", "--work", "work"])
    assert stop.value.code == 2 and "no policies/trial_K walker" in capsys.readouterr().err
    assert not (exp / "work").exists()


def test_each_call_walks_what_fits_the_next_skips_it_and_write_makes_each_whole_group_an_evaluation(script, exp, capsys,
                                                                                                  monkeypatch):
    walked = []

    def walk(policies, heightmaps, key, *rest):   # a stand-in for the walks (the slow test walks for real)
        time.sleep(0.2)
        walked.append(str(getattr(policies[0], "path", "base")))
        return np.asarray(jax.random.uniform(key, (1, heightmaps.shape[0])), np.float32)

    monkeypatch.setattr(batch, "evaluate_policies", walk)
    # 0.005 min = 0.3 s: the first walk of a call always runs (0.2 s); a second (predicted 0.23 s) does not fit
    calls, written = [], []
    for k in range(5):
        monkeypatch.setattr(script, "STARTED", time.perf_counter())
        assert script.main(args("--time-limit", "0.005", "--pack", f"out/v2eval{k}.tar.gz")) == 0
        calls.append(capsys.readouterr().out)
        with tarfile.open(f"out/v2eval{k}.tar.gz") as tar:
            assert all(m == "work" or m.startswith("work/") for m in tar.getnames())  # the work folder alone
            assert sum(m.startswith("work/results/") for m in tar.getnames()) == min(k + 1, 4)
        assert script.main(args("--write")) == 0
        written.append(sorted(str(p.parent.relative_to(exp)) for p in exp.rglob("fitness.csv.gz")))
    assert len(walked) == 4 and [c.count("mean fitness") for c in calls] == [1, 1, 1, 1, 0]
    assert "stopped: time limit" in calls[0] and "0 walked, 4 done before, 0 left" in calls[4]
    assert written == [[], ["base/humanoid"], ["base/humanoid", "exp/a/heldout_v2"],
                       ["base/humanoid", "exp/a/heldout_v2", "exp/b/heldout_v2"],
                       ["base/humanoid", "exp/a/heldout_v2", "exp/b/heldout_v2"]]
    base = suite.read_fitness(exp / "base" / "humanoid" / "fitness.csv.gz")
    a = suite.read_fitness(exp / "exp" / "a" / "heldout_v2" / "fitness.csv.gz")
    assert base.policies == ["base", "base:key1"] and a.policies == ["base", "exp/a/policies/trial_0"]
    np.testing.assert_array_equal(a.fitness[0], base.fitness[0])  # the treatment's base row: the key-0 walk
    tiny = suite.load("v2", robot="humanoid", size=96, seeds=1, families=["flat", "boxes"], generator_names=[])
    assert a.family.tolist() == tiny.family.tolist() and a.level.tolist() == tiny.level.tolist()
    assert not list(exp.rglob("suite.png"))
    cfg = json.loads((exp / "exp" / "a" / "heldout_v2" / "config.json").read_text())
    assert cfg["suite"] == "v2" and cfg["robot"] == "humanoid" and cfg["policy"] == ["exp/a/policies/trial_0"]
    assert cfg["walked_with"]["protocol"]["attempts"] == 2 and cfg["size"] == 96 and cfg["suite_name"] == tiny.name
    capsys.readouterr()
    assert script.main(args("--plan")) == 0
    plan = capsys.readouterr().out
    assert "base:humanoid: 2/2 walked written" in plan and "exp/a: 1/1 walked written" in plan
    assert "4 of 4 walks done" in plan
    with pytest.raises(SystemExit) as stop:  # the work folder holds another protocol's walks
        script.main(args("--attempts", "4"))
    assert stop.value.code == 2 and "made with other settings" in capsys.readouterr().err
    with pytest.raises(SystemExit) as stop:
        script.main(args("--write", "--work", "elsewhere"))
    assert stop.value.code == 2 and "no walks here yet" in capsys.readouterr().err


def test_parts_of_the_jobs_walk_them_all_once_between_them(script, exp, capsys, monkeypatch):
    """``--part K/N`` (what ``--gpus N`` gives process k): every N-th job from the K-th; two parts into one work
    folder walk every job once; ``--gpus`` with ``--part`` is refused."""
    walked = {}

    def walk(policies, heightmaps, key, *rest):
        walked.setdefault(part, []).append(str(getattr(policies[0], "path", "base")))
        return np.asarray(jax.random.uniform(key, (1, heightmaps.shape[0])), np.float32)

    monkeypatch.setattr(batch, "evaluate_policies", walk)
    for part in ("1/2", "0/2"):
        assert script.main(args("--part", part)) == 0
    out = capsys.readouterr().out
    assert [len(walked[k]) for k in ("0/2", "1/2")] == [2, 2] and "4 of 4" not in out
    assert script.main(args("--part", "0/2")) == 0 and "0 walked, 2 done before, 0 left" in capsys.readouterr().out
    store = batch.Store(exp / "work")
    names = ["base:humanoid", "base:humanoid:key1", "exp/a/policies/trial_0", "exp/b/policies/trial_0"]
    assert all(map(store.has, names)) and len(list((exp / "work" / "results").iterdir())) == 4
    for argv, text in ((["--part", "2/2"], "--part must be K/N"), (["--gpus", "2", "--part", "0/2"], "--gpus must"),
                       (["--gpu", "2"], "unrecognized arguments")):
        with pytest.raises(SystemExit) as stop:
            script.main(args(*argv))
        assert stop.value.code == 2 and text in capsys.readouterr().err


def test_the_shipped_experiments_walk_in_the_issues_order(script):
    """Base policies first (every walker's robot), then Experiment 3, 3b, 3c, the wide recipe and the ant, so that a
    run cut short leaves whole experiments (the plan itself, which loads all 170 walkers: the slow test below)."""
    treatments = [t for f in script.EXPERIMENTS for t in batch.treatment_folders(ROOT / f)]
    assert [t.relative_to(RESULTS).parts[0] for t in treatments] == ["exp3_gpushort"] * 8 + ["exp3b_gpushort"] * 4 + \
        ["exp3c_gpushort"] * 2 + ["wide_gpushort"] * 2 + ["ant_gpushort"]
    assert script.ROBOT_ORDER == ("humanoid", "ant")


@pytest.mark.slow
def test_the_plan_of_the_shipped_experiments_is_190_walks_in_the_issues_order(script, capsys, monkeypatch):
    monkeypatch.chdir(ROOT)
    assert script.main(["--plan", "--work", "runs/v2eval-none-here"]) == 0
    out = capsys.readouterr().out.splitlines()
    groups = [line.split(":")[0] if line.startswith("base:") else line.split(": ")[0] for line in out[:-1]]
    assert groups[:2] == ["base", "base"] and out[0].startswith("base:humanoid: 0/10") and out[1].startswith("base:ant")
    assert [g.split("/")[2] for g in groups[2:]] == ["exp3_gpushort"] * 8 + ["exp3b_gpushort"] * 4 + \
        ["exp3c_gpushort"] * 2 + ["wide_gpushort"] * 2 + ["ant_gpushort"]
    assert out[-1].startswith("0 of 190 walks done") and not (ROOT / "runs" / "v2eval-none-here").exists()


def test_write_refuses_a_group_walked_on_two_heightfield_kernels(script, exp, capsys, monkeypatch):
    """Under Warp each walk records its heightfield kernel (``provenance.warp_hfield``); ``--write`` writes a group
    whose walks agree (its ``config.json`` names the kernel) and refuses, in one line and exit status 1, one whose
    walks ran on the stock and the patched kernel; ``--plan`` counts each group's walks per kernel."""
    from jaxterrain.runtime import provenance

    def walk(policies, heightmaps, key, *rest):
        return np.asarray(jax.random.uniform(key, (1, heightmaps.shape[0])), np.float32)

    monkeypatch.setattr(batch, "evaluate_policies", walk)
    warp = args("--backend", "warp")
    monkeypatch.setattr(provenance, "warp_hfield", lambda: "stock")
    assert script.main(warp) == 0
    a = batch.Store(exp / "work")
    a.path("exp/a/policies/trial_0").unlink()  # walked again on the patched kernel
    monkeypatch.setattr(provenance, "warp_hfield", lambda: "local-origin patch")
    assert script.main(warp) == 0
    capsys.readouterr()
    assert script.main([*warp, "--write"]) == 1
    out, err = capsys.readouterr()
    assert "2 evaluations written" in out and err.strip().splitlines() == [
        "not written, walks on different MuJoCo Warp heightfield kernels or spawn rules: exp/a (1 kernel local-origin "
        "patch, 1 kernel stock, 2 spawn feet); walk them again on one (runs/v2eval/results/<walk>.npz: remove the odd "
        "ones)"]
    assert not (exp / "exp" / "a" / "heldout_v2").exists()
    assert json.loads((exp / "exp" / "b" / "heldout_v2" / "config.json").read_text())["warp_hfield"] == "stock"
    assert script.main([*warp, "--plan"]) == 0
    plan = capsys.readouterr().out
    assert "exp/a: 1/1 walked [1 local-origin patch]" in plan and "base:humanoid: 2/2 walked written [2 stock]" in plan
    # a walk recorded before the spawn rule was (the patch rule) beside one spawned by the default rule ("feet")
    assert batch.Store(exp / "work").read("exp/b/policies/trial_0")[1]["spawn"] == "feet"
    path = a.path("exp/a/policies/trial_0")
    with np.load(path) as z:
        fitness, meta = z["fitness"], json.loads(str(z["meta"]))
    meta.pop("spawn")
    meta["warp_hfield"] = "stock"
    atomic_save_npz(path, fitness=fitness, meta=np.array(json.dumps(meta)))
    capsys.readouterr()
    assert script.main([*warp, "--write"]) == 1
    assert "exp/a (2 kernel stock, 1 spawn feet, 1 spawn patch (not recorded))" in capsys.readouterr().err
