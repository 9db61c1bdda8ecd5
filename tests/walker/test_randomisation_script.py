"""``docs/results/randomisation/run.py``, the randomisation experiment: its arms are valid ``--randomise`` specs,
its stages refuse bad arguments, and its summary reads what the other stages write (the stages themselves ran end
to end at CPU size with ``all --tiny``: the report of the session that wrote it)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from jaxterrain.rl.checkpoint import BASE_POLICY_DIR
from jaxterrain.walker import parse_randomisation
from scripts import load_script

SCRIPT = Path(__file__).resolve().parents[2] / "docs" / "results" / "randomisation" / "run.py"


@pytest.fixture(scope="module")
def run():
    module = load_script(SCRIPT, "randomisation_run")
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
    assert out["legged-gym"]["suite_vs_base"] == [-0.5, -0.5, -0.5]  # one terrain: the interval is its value
    assert out["legged-gym"]["protocol_loss_vs_base"] == [-0.25, -0.25, -0.25]  # (0.25 - 0.5) - (1 - 1)


def test_terrain_intervals_resample_within_families_and_read_gzipped_results(run, tmp_path):
    """The page's intervals: terrains resampled within their family (a family's share of the mean is fixed), and
    the sim2sim gap |C - MJX| per terrain from a gzipped ``fitness.csv.gz`` (how the results ship)."""
    import gzip

    mean, lo, hi = run.terrain_interval({("a", 0): 0.0, ("a", 1): 1.0, ("b", 0): 10.0})
    assert mean == pytest.approx(11 / 3) and 10 / 3 <= lo < mean < hi <= 12 / 3
    (tmp_path / "sim2sim").mkdir()
    with gzip.open(tmp_path / "sim2sim" / "fitness.csv.gz", "wt", newline="") as f:
        w = csv.writer(f)
        w.writerow(["group", "policy", "robot", "family", "level", "terrain", "engine", "fitness", "mean_steps"])
        for policy, gaps in (("nominal", (0.1, 0.3)), ("full", (0.0, 0.1))):
            for terrain, gap in enumerate(gaps):
                w.writerow([f"humanoid {policy}", policy, "humanoid", "perlin", terrain, terrain, "mjx", 0.5, 100])
                w.writerow([f"humanoid {policy}", policy, "humanoid", "perlin", terrain, terrain, "mujoco",
                            0.5 - gap, 100])
    result = {"arms": {"nominal": {"policy": str(BASE_POLICY_DIR)}, "full": {"policy": str(tmp_path / "full" /
                                                                                            "policy")}}}
    run._intervals(tmp_path, result)
    assert result["arms"]["nominal"]["sim2sim_gap_ci"][0] == pytest.approx(0.2)
    assert result["arms"]["full"]["sim2sim_gap_ci"][0] == pytest.approx(0.05)
    diff = result["arms"]["full"]["sim2sim_vs_nominal"]
    assert diff[0] == pytest.approx(-0.15) and diff[1] <= -0.15 <= diff[2] and diff[2] < 0
