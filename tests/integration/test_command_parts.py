"""The command-line parts of features whose library lives in stage tests: the randomisation's flag list and
policy-file record (`tests/walker/test_randomisation.py`), and `evaluate`'s suite v2 (`tests/suite/test_suite_v2.py`)."""

from __future__ import annotations

import json

import numpy as np

from jaxterrain import suite
from jaxterrain.terrain import TerrainScale
from jaxterrain.walker import WalkerConfig, resolve_config
from jaxterrain.walker import RANDOMISATION_PRESETS, parse_randomisation, randomisation_json

TINY = WalkerConfig(terrain_shape=(16, 32), scale=TerrainScale(cell_size=0.2, height=0.5), episode_length=30)
ALL = "friction=0.5:1.25,mass=0.9:1.1,added-mass=-1:1,motor=0.8:1.2,obs-noise=0.01,delay=1:2,push=3:0.5"


def test_the_randomise_flag_lists_the_presets():
    from experiments import common

    assert common.RANDOMISATION_PRESET_NAMES == tuple(RANDOMISATION_PRESETS)  # --help's literal list


def test_policy_files_record_the_randomisation_only_when_on():
    from jaxterrain.difficulty.base_policy import walker_json as _to_jsonable
    from jaxterrain.rl.onnx import walker_config_of

    r = parse_randomisation(ALL)
    assert "randomisation" not in _to_jsonable(TINY)  # policy files of unrandomised runs read as before
    assert _to_jsonable(TINY._replace(randomisation=r))["randomisation"] == randomisation_json(r)
    recorded = _to_jsonable(resolve_config(TINY._replace(randomisation=r)))
    assert walker_config_of({"walker_config": json.loads(json.dumps(recorded))}).randomisation == r


def test_evaluate_builds_v2_with_the_levels_of_its_robot_and_v1_without_one():
    from jaxterrain.runtime import schema
    from jaxterrain.suite.run_config import EvaluateRun
    from jaxterrain.suite.runs import terrains_of

    run = schema.replace(EvaluateRun(), {"terrains.suite": "v2", "base.robot": "ant", "terrains.size": 128,
                                         "terrains.seeds": 1, "terrains.samples": 1, "terrains.families": ("boxes",),
                                         "terrains.generators": ()})
    s = terrains_of(run)
    assert s.robot == "ant" and s.value.tolist() == list(suite.V2_LEVELS["ant"]["boxes"])
    assert terrains_of(schema.replace(run, {"base.robot": None})).robot == "humanoid"
    v1 = terrains_of(schema.replace(run, {"terrains.suite": "v1"}))  # one geometry: the robot does not choose it
    assert v1.robot is None and np.allclose(v1.value, suite.FAMILIES["boxes"].values())
