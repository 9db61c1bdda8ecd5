"""``docs/results/population/heldout.py``: one ``evaluate`` run of the population's and the run alone's walkers,
split into the per-treatment ``heldout/fitness.csv`` + ``summary.json`` folders that ``generalise`` reads."""

from __future__ import annotations

import csv
import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
POP = ROOT / "docs" / "results" / "population"


def script():
    spec = importlib.util.spec_from_file_location("population_heldout", POP / "heldout.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def write_evaluation(folder: Path, policies: list[str]) -> None:
    folder.mkdir()
    with open(folder / "fitness.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["policy", "family", "level", "seed", "value", "unit", "fitness"])
        for i, p in enumerate(["base", *policies]):
            for lv in range(2):
                w.writerow([p, "flat", lv, 0, 0, "-", f"{0.5 + 0.01 * i:.4f}"])


def test_each_treatment_gets_the_base_rows_and_its_own_walkers(tmp_path):
    walkers = [f"/somewhere/docs/results/population/{run}/{t}/policies/trial_{k}"
               for run, t in (("six", "cppn-map"), ("six", "worley-map"), ("alone", "cppn-map")) for k in range(2)]
    write_evaluation(tmp_path / "eval", walkers)
    got = script().split(tmp_path / "eval", tmp_path / "out")
    assert got == {("alone", "cppn-map"): 2, ("six", "cppn-map"): 2, ("six", "worley-map"): 2}
    with open(tmp_path / "out" / "six" / "worley-map" / "heldout" / "fitness.csv") as f:
        rows = list(csv.DictReader(f))
    assert [r["policy"] for r in rows] == ["base"] * 2 + [walkers[2]] * 2 + [walkers[3]] * 2
    assert [r["fitness"] for r in rows] == ["0.5000"] * 2 + ["0.5300"] * 2 + ["0.5400"] * 2
    summary = json.loads((tmp_path / "out" / "six" / "worley-map" / "summary.json").read_text())
    assert summary == json.loads((POP / "six" / "worley-map" / "summary.json").read_text())


def test_a_walker_of_an_unknown_treatment_is_refused(tmp_path):
    write_evaluation(tmp_path / "eval", ["x/six/nope-map/policies/trial_0"])
    with pytest.raises(ValueError, match="walkers of six/nope-map, but .*summary.json does not exist"):
        script().split(tmp_path / "eval", tmp_path / "out")
