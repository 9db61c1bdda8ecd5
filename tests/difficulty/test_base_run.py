"""The ``train-base-policy`` run as a typed config (``difficulty.run_config``), resolved and validated once by the
library (``difficulty.base_policy``). Host only: nothing compiles."""

from __future__ import annotations

import pytest

from jaxterrain.difficulty import base_policy
from jaxterrain.difficulty import run_config as R
from jaxterrain.runtime import schema
from jaxterrain.walker import SOLVER_SOUND, SolverOptions

SMOKE = R.PRESETS["smoke"]


def test_presets_round_trip_and_their_schedules_are_whole_updates():
    """smoke 4 updates, gpu 410 (41 chunks of 10); num_envs scales an update."""
    for name, run in R.PRESETS.items():
        assert run.preset == name and R.from_flat(R.to_flat(run)) == run
    for name, updates, chunk in (("smoke", 4, 2), ("gpu", 410, 10), ("gpu-short", 41, 10)):
        s = base_policy.validate_base_run(R.PRESETS[name])
        assert s.env_steps == updates * s.ppo_config.steps_per_update and s.num_updates == updates
        assert (s.updates_per_chunk, s.time_budget) == (chunk, None)
    s = base_policy.resolve_settings(schema.replace(SMOKE, {"ppo.num_envs": 16}))
    assert s.ppo_config.num_envs == 16 and s.num_updates == 2  # 160 env steps of 16 x 5 per update
    assert base_policy.shapes(None) == base_policy.shapes("smoke")  # a config.json without a preset ran smoke's
    assert base_policy.shapes("smoke")[0].terrain_shape == (16, 32)  # the humanoid's tiny flat ground
    ant = base_policy.validate_base_run(schema.replace(SMOKE, {"walker.robot": "ant"}))
    assert ant.env_config.terrain_shape == (17, 32)  # widened to the rows the ant's 1.3 m side margins take


def test_the_solver_is_read_and_a_bad_one_names_the_field():
    settings = base_policy.resolve_settings(schema.replace(SMOKE, {"walker.solver": "2,8,0"}))
    assert settings.env_config.solver == SolverOptions("newton", 2, 8, False)
    assert base_policy.resolve_settings(SMOKE).env_config.solver == SOLVER_SOUND
    with pytest.raises(ValueError, match="^BasePolicyRun.walker.solver: "):
        base_policy.resolve_settings(schema.replace(SMOKE, {"walker.solver": "4,16"}))


def test_the_spawn_rule_reaches_the_training_walker_and_older_files_keep_theirs():
    """``walker.spawn`` sets how the trained walker is set down at a reset (``feet`` by default): it reaches the
    walker config the run trains and evaluates in (and records with the policy); a ``config.json`` written before
    the key reads as ``patch``, the rule it ran with."""
    from jaxterrain.walker import SPAWNS

    assert R.SPAWNS == SPAWNS and R.PRESETS["gpu"].walker.spawn == "feet" and R.LEGACY["spawn"] == "patch"
    assert R.from_flat({k: v for k, v in R.to_flat(SMOKE).items() if k != "spawn"}).walker.spawn == "patch"
    for rule in SPAWNS:
        settings = base_policy.validate_base_run(schema.replace(SMOKE, {"walker.spawn": rule}))
        assert settings.env_config.spawn == rule and base_policy.walker_json(settings.env_config)["spawn"] == rule


@pytest.mark.parametrize("changes, message", [
    ({"walker.spawn": "torso"}, "BasePolicyRun.walker.spawn must be one of feet, patch; got 'torso'"),
    ({"walker.scan_noise": 0.1}, "BasePolicyRun.walker.scan_noise needs BasePolicyRun.walker.observation perceptive"),
    ({"walker.robot": "dog"}, "BasePolicyRun.walker.robot: robot must be one of"),
    ({"walker.randomise": "mass=0:1"}, "BasePolicyRun.walker.randomise: randomisation.mass"),
    ({"evaluation.best": 30}, "BasePolicyRun.evaluation.best must be <= BasePolicyRun.evaluation.attempts (20)"),
    ({"schedule.env_steps": -5}, "BasePolicyRun.schedule.env_steps must be a finite number > 0"),
    ({"ppo.num_envs": 0}, "BasePolicyRun.ppo.num_envs must be an integer >= 1"),
])
def test_validate_names_the_field(changes, message):
    with pytest.raises(ValueError) as err:
        base_policy.validate_base_run(schema.replace(SMOKE, changes))
    assert str(err.value).startswith(message), err.value
