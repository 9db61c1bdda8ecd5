"""The ``evaluate`` run as a typed config (``suite.run_config``), validated once by the library
(``suite.runs.validate_evaluate``) with errors that name the field. Host only: nothing compiles."""

from __future__ import annotations

import sys

import pytest

from jaxterrain.runtime import schema
from jaxterrain.suite import run_config as R
from jaxterrain.suite import runs

SMOKE = R.PRESETS["smoke"]


def test_presets_round_trip_and_older_files_read():
    for name, run in R.PRESETS.items():
        assert run.preset == name and R.from_flat(R.to_flat(run)) == run
    flat = R.to_flat(SMOKE)
    assert flat["families"] == ["flat", "stairs_up", "gaps"] and flat["policy"] == []  # config.json's keys
    old = {k: v for k, v in flat.items() if not k.startswith("video") and k not in ("engine", "workers", "keys")}
    assert R.from_flat(old) == SMOKE  # before videos, engines and keys: the values those runs had


def test_the_spawn_rule_reaches_every_walker_and_older_files_keep_theirs():
    """``physics.spawn`` sets how every walker is set down (``feet`` by default); an evaluation's ``config.json``
    written before the key reads as ``patch``, the rule it was walked with."""
    from jaxterrain.suite.evaluation import check_policies
    from jaxterrain.terrain import TerrainScale

    assert SMOKE.physics.spawn == "feet" and R.LEGACY["spawn"] == "patch"
    assert R.from_flat({k: v for k, v in R.to_flat(SMOKE).items() if k != "spawn"}).physics.spawn == "patch"
    policies = runs.validate_evaluate(SMOKE).policies
    for rule in ("feet", "patch"):
        assert [c.spawn for c in check_policies(policies, (128, 128), TerrainScale(), spawn=rule)] == [rule]


def test_validate_loads_the_base_policy_and_keeps_the_run():
    ready = runs.validate_evaluate(SMOKE)
    assert ready.run == SMOKE and len(ready.policies) == 1 and ready.suite is None  # built when walked
    assert runs.base_names(3) == ["base", "base:key1", "base:key2"] and runs.is_base("base:key2")
    assert not runs.is_base("runs/x/policies/trial_0")


@pytest.mark.parametrize("changes, message", [
    ({"terrains.suite": "v9"}, "EvaluateRun.terrains.suite must be one of v1, v2; got 'v9'"),
    ({"base.keys": 0}, "EvaluateRun.base.keys must be an integer >= 1; got 0"),
    ({"policies": ("missing-policy",)}, "EvaluateRun.policies missing-policy: no policy.msgpack in missing-policy"),
    ({"physics.engine": "mujoco", "physics.backend": "warp"}, "EvaluateRun.physics.backend warp is an MJX backend"),
    ({"physics.workers": 4}, "EvaluateRun.physics.workers sets the CPU processes of EvaluateRun.physics.engine"),
    ({"physics.spawn": "nope"}, "EvaluateRun.physics.spawn must be one of feet, patch; got 'nope'"),
    ({"videos.on": True, "physics.spawn": "patch"}, "EvaluateRun.videos.on sets the walkers down by the default spawn"),
    ({"videos.terrains": "flat:0"}, "EvaluateRun.videos.terrains chooses the terrains of EvaluateRun.videos.on"),
    ({"videos.on": True, "videos.terrains": "gaps:10"}, "EvaluateRun.videos.terrains: gaps has levels 0 to 9"),
    ({"videos.format": "mp4"}, "EvaluateRun.videos.format chooses the files of EvaluateRun.videos.on"),
    ({"videos.on": True, "videos.format": "webm"}, "EvaluateRun.videos.format must be one of gif, mp4, both; got "
                                                   "'webm'"),
    ({"terrains.families": ("nope",)}, "EvaluateRun.terrains.families: unknown 'nope'"),
    ({"terrains.height": 0.5}, "EvaluateRun.terrains.height applies to EvaluateRun.terrains.folder"),
    ({"physics.randomise": "push=10"}, "EvaluateRun.physics.randomise: item push=10"),
])
def test_validate_names_the_field(changes, message):
    with pytest.raises(ValueError) as err:
        runs.validate_evaluate(schema.replace(SMOKE, changes))
    assert str(err.value).startswith(message), err.value


def test_mp4_without_the_video_extra_is_refused_in_one_line_before_the_policies_load(monkeypatch):
    """``videos.format`` ``mp4`` / ``both`` where imageio-ffmpeg does not import (``sys.modules`` entry None: the
    import raises): one line naming the extra; GIF needs nothing more."""
    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)
    monkeypatch.setattr(runs, "load_policies", lambda run: pytest.fail("policies loaded before the extra was checked"))
    for fmt in ("mp4", "both"):
        with pytest.raises(ValueError) as err:
            runs.validate_evaluate(schema.replace(SMOKE, {"videos.on": True, "videos.format": fmt}))
        assert str(err.value) == (f"EvaluateRun.videos.format {fmt} writes MP4 with imageio-ffmpeg, which is not "
                                  "installed: pip install 'jaxterrain[video]'")
    runs.check_video_format(schema.replace(SMOKE, {"videos.on": True}))  # gif: no extra needed
