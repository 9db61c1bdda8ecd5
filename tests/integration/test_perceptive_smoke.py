"""A perceptive walker end to end on the CPU: ``train-base-policy --preset smoke --observation perceptive`` trains
and exports it, ``rl.load_policy`` reads its observation set back, and ``evaluate --preset smoke`` walks it beside
the shipped perceptive base policy, each in the env of its own set (MJX compiles: minutes on 2 CPU cores)."""

from __future__ import annotations

import argparse
import csv
import json

import numpy as np
import pytest

from jaxterrain import difficulty, rl


def cli(*argv):
    from experiments.__main__ import main

    return main(list(argv))


@pytest.mark.slow
def test_a_perceptive_smoke_policy_trains_exports_loads_and_is_evaluated(tmp_path):
    from experiments import train_base_policy as tbp

    parser = argparse.ArgumentParser()
    tbp.add_arguments(parser)
    run = tmp_path / "train"
    assert tbp.main(parser.parse_args(["--preset", "smoke", "--observation", "perceptive", "--scan-noise", "0.01",
                                       "--skip-eval", "--no-progress", "--out", str(run)])) == 0
    policy = rl.load_policy(run / "policy")
    assert policy.observation_size == 45 + 17 * 9
    assert difficulty.policy_observation(policy) == {"observation": "perceptive", "scan_x": (-0.4, 1.2),
                                                     "scan_y": (-0.4, 0.4), "scan_points": (17, 9)}
    assert difficulty.policy_scan_noise(policy) == pytest.approx(0.01)
    cfg = difficulty.default_env_config((128, 128), None, policy)
    assert cfg.observation == "perceptive" and cfg.scan_noise == pytest.approx(0.01)

    out = tmp_path / "evaluate"
    assert cli("evaluate", "--preset", "smoke", "--families", "flat", "--generators", "--observation", "perceptive",
               "--policy", str(run / "policy"), "--out", str(out)) == 0
    with open(out / "fitness.csv") as f:
        rows = list(csv.DictReader(f))
    assert [r["policy"] for r in rows] == ["base", str(run / "policy")]
    fit = np.array([float(r["fitness"]) for r in rows])
    assert fit[0] == pytest.approx(1.0)  # the perceptive base policy walks flat ground as the blind one does
    assert np.all(np.isfinite(fit)) and 0.0 <= fit[1] <= 1.0
    config = json.loads((out / "config.json").read_text())
    assert config["observation"] == "perceptive"
