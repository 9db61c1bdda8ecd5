"""The shipped results pages compare with one base evaluation per robot (issue 61, item 2): every held-out aggregate
under ``docs/results`` (Experiment 3, 3b, 3c, the wide recipe, the ant) was made with ``generalise --base`` pointing
at the robot's 10-key evaluation, so its base-policy row is those 10 runs, recomputed here from the raw file; and
``docs/results/trial_unit.py``'s comparison of the ant with its base policy is the arithmetic it says it is."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from experiments.generalise import load_base, load_treatment
from jaxterrain import suite
from jaxterrain.runtime import statistics
from scripts import load_script

RESULTS = Path(__file__).resolve().parents[2] / "docs" / "results"
KEYS = RESULTS / "base_v1_keys_h200_2026-11-29"
PAGES = {  # the aggregate folder of each page: (a treatment folder it read, the robot)
    "exp3_gpushort/generalisation": ("exp3_gpushort/cppn-map", "humanoid"),
    "exp3b_gpushort/generalisation": ("exp3b_gpushort/cppn-dr", "humanoid"),
    "exp3c_gpushort/generalisation": ("exp3c_gpushort/cppn-plr", "humanoid"),
    "wide_gpushort/generalisation": ("wide_gpushort/cppn-map", "humanoid"),
    "ant_gpushort/learn/generalisation": ("ant_gpushort/learn", "ant"),
}


@pytest.mark.parametrize("aggregate", sorted(PAGES))
def test_every_shipped_aggregate_compares_with_its_robots_10_key_base_evaluation(aggregate):
    folder, robot = PAGES[aggregate]
    t = load_treatment(RESULTS / folder)
    runs = suite.cell_scores(load_base(KEYS / robot, t["family"], t["level"]), t["family"], t["level"])[1]
    assert runs.shape == (10, 127)
    row = next(r for r in csv.DictReader((RESULTS / aggregate / "intervals.csv").open())
               if r["treatment"] == "base policy" and r["scope"] == "all")
    assert row["runs"] == "10"
    # the file holds 4 decimals: a stored reference, compared within its rounding
    assert float(row["mean"]) == pytest.approx(runs.mean(), abs=6e-5)
    assert float(row["iqm"]) == pytest.approx(statistics.iqm(runs), abs=6e-5)
    assert float(row["trial_iqm"]) == pytest.approx(statistics.trial_iqm(runs), abs=6e-5)
    assert f"base_v1_keys_h200_2026-11-29/{robot}" in (RESULTS / aggregate / "generalisation.md").read_text()


def test_trial_unit_ant_gain_trims_each_run_over_its_own_cells():
    module = load_script(RESULTS / "trial_unit.py", "trial_unit")
    cells = np.linspace(0.0, 1.0, 8)                       # a run's IQM over these 8 cells: the middle 4's mean
    walkers = np.stack([cells + 0.1, cells + 0.3])         # [2 trials, 8 cells]
    base = np.stack([cells, cells, cells])                 # [3 runs, 8 cells]
    g = module.ant_gain(walkers, base)
    middle = cells[2:6].mean()
    assert g["base_evaluations"] == 3
    assert g["trial_iqm"] == pytest.approx(middle + 0.2, abs=1e-4)
    assert g["base_trial_iqm"] == pytest.approx(middle, abs=1e-4)
    assert g["gain_trial_iqm"] == pytest.approx(0.2, abs=1e-4)
    assert g["walkers_above_base_mean"] == 2
