"""``docs/results/suite_v2/reevaluate.py``: every shipped walker on suite v2 in commands that fit a GPU call. At a
tiny size on the CPU: cut short by its time limit, each call walks what fits and the next skips what is done; a
group's evaluation (a treatment's ``heldout_v2/``, a robot's base folder) is written when its last walk ends, and
``--pack`` puts the work and every written folder into one tar. Bad flags are one line. The real walks (slow):
tests/integration/test_reevaluate_v2.py."""

from __future__ import annotations

import importlib.util
import json
import shutil
import tarfile
import time
from pathlib import Path

import jax
import numpy as np
import pytest

from jaxterrain import suite
from jaxterrain.suite import batch

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "docs" / "results" / "suite_v2" / "reevaluate.py"
RESULTS = ROOT / "docs" / "results"
TINY = ["--size", "96", "--seeds", "1", "--families", "flat", "boxes", "--generators", "--attempts", "2", "--best",
        "1", "--headings", "1", "--backend", "jax", "--slots", "0", "--keys", "2"]


@pytest.fixture(scope="module")
def script():
    spec = importlib.util.spec_from_file_location("suite_v2_reevaluate", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def exp(tmp_path, monkeypatch):
    """``tmp_path/exp``: treatments ``a`` (a paper-recipe walker) and ``b`` (a wide-recipe walker); cwd tmp_path."""
    for name, src in (("a", "exp3_gpushort/cppn-map/policies/trial_0"), ("b", "wide_gpushort/perlin-map/policies/trial_3")):
        shutil.copytree(RESULTS / src, tmp_path / "exp" / name / "policies" / "trial_0")
    monkeypatch.chdir(tmp_path)
    return tmp_path


def args(*extra):
    return ["exp", "--work", "work", "--base-out", "base", *TINY, *extra]


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


def test_each_call_walks_what_fits_and_the_next_skips_it_writing_each_group_when_it_is_whole(script, exp, capsys,
                                                                                          monkeypatch):
    walked = []

    def walk(policies, heightmaps, key, *rest):   # a stand-in for the walks (the slow test below walks for real)
        time.sleep(0.2)
        walked.append(str(getattr(policies[0], "path", "base")))
        return np.asarray(jax.random.uniform(key, (1, heightmaps.shape[0])), np.float32)

    monkeypatch.setattr(batch, "evaluate_policies", walk)
    # 0.005 min = 0.3 s: the first walk of a call always runs (0.2 s); a second (predicted 0.23 s) does not fit
    calls = []
    for k in range(5):
        monkeypatch.setattr(script, "STARTED", time.perf_counter())
        assert script.main(args("--time-limit", "0.005", "--pack", f"out/v2eval{k}.tar.gz")) == 0
        calls.append(capsys.readouterr().out)
    assert len(walked) == 4 and [c.count("mean fitness") for c in calls] == [1, 1, 1, 1, 0]
    assert "stopped: time limit" in calls[0] and "0 walked, 4 done before, 0 left" in calls[4]
    written = lambda k: sorted(m[:-len("/fitness.csv.gz")] for m in tarfile.open(f"out/v2eval{k}.tar.gz").getnames()  # noqa: E731
                               if m.endswith("fitness.csv.gz"))
    assert [written(k) for k in range(5)] == [[], ["base/humanoid"], ["base/humanoid", "exp/a/heldout_v2"],
                                              ["base/humanoid", "exp/a/heldout_v2", "exp/b/heldout_v2"],
                                              ["base/humanoid", "exp/a/heldout_v2", "exp/b/heldout_v2"]]
    base = suite.read_fitness(exp / "base" / "humanoid" / "fitness.csv.gz")
    a = suite.read_fitness(exp / "exp" / "a" / "heldout_v2" / "fitness.csv.gz")
    assert base.policies == ["base", "base:key1"] and a.policies == ["base", "exp/a/policies/trial_0"]
    np.testing.assert_array_equal(a.fitness[0], base.fitness[0])  # the treatment's base row: the key-0 walk
    assert (exp / "base" / "humanoid" / "suite.png").is_file() and not (exp / "exp/a/heldout_v2/suite.png").exists()
    cfg = json.loads((exp / "exp" / "a" / "heldout_v2" / "config.json").read_text())
    assert cfg["suite"] == "v2" and cfg["robot"] == "humanoid" and cfg["policy"] == ["exp/a/policies/trial_0"]
    assert cfg["walked_with"]["protocol"]["attempts"] == 2 and cfg["size"] == 96
    capsys.readouterr()
    assert script.main(args("--plan")) == 0
    plan = capsys.readouterr().out
    assert "base:humanoid: 2/2 walked written" in plan and "4 of 4 walks done" in plan
    with pytest.raises(SystemExit) as stop:  # the work folder holds another protocol's walks
        script.main(args("--attempts", "4"))
    assert stop.value.code == 2 and "made with other settings" in capsys.readouterr().err
