"""Randomised physics end to end on the CPU (MJX and PPO compile: minutes on 2 cores): ``train-base-policy --preset
smoke --randomise ...`` trains and saves a policy whose ``walker_config`` records the randomisation, ``evaluate
--randomise`` walks it under a randomised protocol, and ``learn --preset smoke --randomise`` fine-tunes under it and
records it in every trial's walker."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from jaxterrain import rl
from jaxterrain.walker import parse_randomisation, randomisation_json

SPEC = "friction=0.5:1.25,mass=0.9:1.1,motor=0.9:1.1,obs-noise=0.01,delay=1,push=10:0.5"


def cli(*argv):
    from experiments.__main__ import main

    return main(list(argv))


@pytest.mark.slow
def test_randomised_smoke_training_records_the_randomisation_and_evaluates_randomised(tmp_path):
    run = tmp_path / "train"
    assert cli("train-base-policy", "--preset", "smoke", "--randomise", SPEC, "--eval-attempts", "2", "--eval-best",
               "1", "--no-progress", "--out", str(run)) == 0
    meta = json.loads((run / "policy" / "config.json").read_text())
    assert meta["walker_config"]["randomisation"] == randomisation_json(parse_randomisation(SPEC))
    assert json.loads((run / "config.json").read_text())["randomise"] == SPEC
    assert json.loads((run / "run.json").read_text())["walker_config"]["randomisation"]["push_every"] == 10
    assert 0.0 <= json.loads((run / "eval.json").read_text())["best_mean"] <= 1.0  # nominal physics
    rl.load_policy(run / "policy")  # loads as any policy

    out = tmp_path / "evaluate"
    assert cli("evaluate", "--preset", "smoke", "--families", "flat", "--generators", "--randomise", "legged-gym",
               "--policy", str(run / "policy"), "--out", str(out)) == 0
    with open(out / "fitness.csv") as f:
        fit = np.array([float(r["fitness"]) for r in csv.DictReader(f)])
    assert fit.shape == (2,) and np.all((0.0 <= fit) & (fit <= 1.0))
    assert json.loads((out / "config.json").read_text())["randomise"] == "legged-gym"


@pytest.mark.slow
def test_learn_smoke_fine_tunes_under_randomised_physics(tmp_path):
    out = tmp_path / "learn"
    assert cli("learn", "--preset", "smoke", "--randomise", "legged-gym", "--no-progress", "--out", str(out)) == 0
    for trial in (0, 1):
        meta = json.loads((out / "policies" / f"trial_{trial}" / "config.json").read_text())
        assert meta["walker_config"]["randomisation"] == randomisation_json(parse_randomisation("legged-gym"))
