"""``docs/results/randomisation/run.py``, the randomisation experiment: its arms are valid ``--randomise`` specs,
its stages refuse bad arguments, and its summary reads what the other stages write (the stages themselves ran end
to end at CPU size with ``all --tiny``: the report of the session that wrote it)."""

from __future__ import annotations

import csv
import importlib.util
import json
from pathlib import Path

import pytest

from jaxterrain.rl.checkpoint import BASE_POLICY_DIR
from jaxterrain.walker import parse_randomisation

SCRIPT = Path(__file__).resolve().parents[2] / "docs" / "results" / "randomisation" / "run.py"


@pytest.fixture(scope="module")
def run():
    spec = importlib.util.spec_from_file_location("randomisation_run", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_arms_are_valid_specs_and_bad_arguments_are_refused(run, capsys):
    assert run.ARMS["nominal"] is None
    full = parse_randomisation(run.ARMS["full"])
    assert full.friction == (0.5, 1.25) and full.motor == (0.9, 1.1) and full.delay == (0, 1)
    assert parse_randomisation(run.ARMS["legged-gym"]).push_every == 1000
    for argv in (["train", "--out", "x"], ["evaluate", "full", "--out", "x"], ["train", "full", "--out", "x",
                                                                              "--time-limit", "0"]):
        with pytest.raises(SystemExit) as err:
            run.parse(argv)
        assert err.value.code == 2


def test_the_summary_reads_the_stages_outputs(run, tmp_path):
    arm = tmp_path / "legged-gym"
    (arm / "policy").mkdir(parents=True)
    (arm / "eval.json").write_text(json.dumps({"best_mean": 0.95, "all_mean": 0.8}))
    (tmp_path / "legged-gym.log").write_text("update      2/4      1,000 env steps/s  return\n"
                                             "update      4/4    120,000 env steps/s  return\n")
    for name, value in (("suite", 0.5), ("suite_randomised", 0.25)):
        (tmp_path / name).mkdir()
        with open(tmp_path / name / "fitness.csv", "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["policy", "family", "level", "seed", "value", "unit", "fitness"])
            w.writerow(["base", "flat", 0, 0, 0, "m", 1.0])
            w.writerow([str(arm / "policy"), "flat", 0, 0, 0, "m", value])
    (tmp_path / "sim2sim").mkdir()
    (tmp_path / "sim2sim" / "summary.json").write_text(json.dumps({"pairs": {"mujoco-mjx": {
        "humanoid legged-gym|all": {"mean_abs": 0.03, "mean": 0.01, "n": 73}}}}))
    assert run.main(["summary", "--out", str(tmp_path)]) == 0
    out = json.loads((tmp_path / "summary.json").read_text())["arms"]
    assert out["nominal"]["policy"] == str(BASE_POLICY_DIR) and out["nominal"]["suite"]["mean"] == 1.0
    assert out["legged-gym"]["flat_best"] == 0.95 and out["legged-gym"]["env_steps_per_s"] == 120000.0
    assert out["legged-gym"]["suite"]["mean"] == 0.5 and out["legged-gym"]["suite_randomised"]["mean"] == 0.25
    assert out["legged-gym"]["sim2sim_gap"] == 0.03 and "sim2sim_gap" not in out["nominal"]
    assert "| legged-gym | 0.950 / 0.800 | 0.500 | 0.250 | 0.030 | 120,000 |" in (tmp_path / "summary.md").read_text()
