"""jaxterrain.curriculum.run_config: one curriculum run as a typed, nested LearnConfig; its presets beside it in the
library; config.json its serialised form, read back from every earlier version's run folders."""

from __future__ import annotations

import glob
import json

import numpy as np
import pytest

from jaxterrain.curriculum import run_config as R
from jaxterrain.curriculum import presets, runner, selectors as S
from jaxterrain.curriculum.config import CurriculumConfig


def test_the_presets_are_typed_and_serialise_to_their_flat_form():
    """``PRESETS`` (typed) and ``presets.FLAT_PRESETS`` (config.json's form) are one set: ``to_flat`` of each typed
    preset is its flat dict (with ``preset`` and ``seed``), and ``from_flat`` reads it back equal."""
    assert tuple(R.PRESETS) == ("smoke", "gpu-short", "gpu", "paper")
    for name, flat in presets.FLAT_PRESETS.items():
        typed = R.PRESETS[name]
        assert R.to_flat(typed) == {**flat, "preset": name, "seed": 0}, name
        assert R.from_flat(R.to_flat(typed)) == typed and hash(typed) == hash(R.from_flat(R.to_flat(typed)))
    smoke = R.PRESETS["smoke"]
    assert (smoke.trials, smoke.budget.compact, smoke.budget.fast_compile, smoke.walker.episode_length) == (
        2, False, True, 100)
    assert smoke.curriculum.params == S.MapParams() and smoke.curriculum.ppo.num_envs == 4
    assert smoke.protocol == R.ProtocolOverride(2, 1, 1) and R.PRESETS["paper"].protocol == R.ProtocolOverride()
    assert R.PRESETS["gpu-short"].curriculum.max_epochs == 3000 and R.PRESETS["paper"].recipe == "paper"


def test_every_flat_key_has_one_typed_field():
    """The one field -> flag table: every key of a preset is a typed field (``FLAT_FIELDS``, or a selector's
    params through its ``SelectorSpec.flat``), and no two keys name one field."""
    keys = set(presets.FLAT_PRESETS["paper"]) | {"seed"}
    fields = {k: R.field_of(k, s) for k in keys for s in ("map", "plr", "levels", "accel", "roughness", "dr")
              if R.field_of(k, s) != k or k in R.FLAT_FIELDS}
    assert keys == set(fields), keys ^ set(fields)
    assert R.field_of("threshold") == "curriculum.threshold" and R.field_of("backend") == "walker.backend"
    assert R.field_of("plr_capacity", "accel") == "curriculum.params.capacity"
    assert R.field_of("levels_init", "levels") == "curriculum.params.init"
    assert len(set(R.FLAT_FIELDS.values())) == len(R.FLAT_FIELDS)


def _treatment_configs() -> list[str]:
    """The shipped ``config.json`` of every curriculum treatment (not those of other commands)."""
    paths = sorted(glob.glob("docs/results/*/*/config.json") + glob.glob("docs/results/*/config.json"))
    return [p for p in paths if "curriculum" in (d := json.loads(open(p).read())) and d.get("command") in (None, "learn")]


TREATMENTS = _treatment_configs()


def test_the_shipped_treatments_include_experiment_3s():
    assert len(TREATMENTS) >= 40 and sum("exp3_gpushort" in p for p in TREATMENTS) == 8


@pytest.mark.parametrize("path", TREATMENTS)
def test_every_shipped_run_folders_config_reads_as_a_typed_run(path):
    """Old run folders still resume: every shipped treatment's ``config.json`` (written by every version since
    Experiment 2, e.g. ``docs/results/exp3_gpushort/*``) converts on read; written back, it keeps every value it
    had (keys it lacked take the values that version ran with: ``truncation`` mask, ``backend`` jax, ...; a key
    renamed since is read under its old name)."""
    d = json.loads(open(path).read())
    d.pop("paths_relative_to_this_folder", None)
    run = R.from_flat(d)
    back = R.to_flat(run, d.get("command"))
    own = S.selector_fields((run.curriculum.selector,)) if run.curriculum.selector in S.selector_names() else {}
    others = set(S.selector_fields()) - set(own)  # other selectors' keys: not part of this run
    renamed = {R.RENAMED.get(k, k): v for k, v in d.items()}
    assert {k: back[k] for k in renamed if k not in others} == {k: v for k, v in renamed.items() if k not in others}
    assert run.curriculum.ppo.truncation == d.get("truncation", "mask")
    assert run.curriculum.ppo.scan_lr_scale == d.get("scan_lr_scale", 1.0)
    assert run.walker.backend == d.get("backend", "jax")


def test_the_spawn_rule_is_the_runs_own_and_old_runs_keep_the_old_one():
    """``walker.spawn`` reaches the env the run trains and evaluates on; a fresh run spawns by ``feet`` (every foot
    clear of the terrain under it), a ``config.json`` written before the field existed reads as ``patch`` (the rule
    it ran with), so resuming an old run continues it under its own rule."""
    assert R.PRESETS["gpu-short"].walker.spawn == "feet" and R.LEGACY["spawn"] == "patch"
    old = {k: v for k, v in R.to_flat(R.PRESETS["smoke"]).items() if k != "spawn"}
    assert R.from_flat(old).walker.spawn == "patch"
    for rule in ("feet", "patch"):
        run = R.PRESETS["smoke"]._replace(walker=R.PRESETS["smoke"].walker._replace(spawn=rule))
        assert runner.validate(run)[4].config.spawn == rule


def test_scan_lr_scale_is_saved_and_runs_saved_before_it_read_as_1():
    """``curriculum.ppo.scan_lr_scale`` is config.json's ``scan_lr_scale`` (``--scan-lr-scale``), read back equal;
    a config.json written before the key reads as 1.0 (``LEGACY``: Adam's steps as they were), so an old run
    resumes unchanged. ``scan_inputs`` is no key: the walker's scan size (``curriculum.walker.fine_tuning_ppo``)."""
    smoke = R.PRESETS["smoke"]
    assert R.LEGACY["scan_lr_scale"] == 1.0 and smoke.curriculum.ppo.scan_lr_scale == 1.0
    run = smoke._replace(curriculum=smoke.curriculum._replace(ppo=smoke.curriculum.ppo._replace(scan_lr_scale=0.1)))
    flat = json.loads(json.dumps(R.to_flat(run, "learn")))
    assert flat["scan_lr_scale"] == 0.1 and R.FLAT_FIELDS["scan_lr_scale"] == "curriculum.ppo.scan_lr_scale"
    assert R.from_flat(flat) == run and "scan_inputs" not in flat
    old = {k: v for k, v in flat.items() if k != "scan_lr_scale"}
    assert R.from_flat(old).curriculum.ppo.scan_lr_scale == 1.0


def test_from_flat_refuses_unknown_keys_and_validation_names_the_field(tmp_path):
    with pytest.raises(ValueError, match=r"LearnConfig: unknown config keys \['nope'\]"):
        R.from_flat({**presets.FLAT_PRESETS["smoke"], "nope": 1})
    bad = R.PRESETS["smoke"]._replace(trials=0)
    with pytest.raises(runner.BadInput, match=r"LearnConfig.trials must be an integer >= 1, got 0"):
        runner.validate(bad)
    bad = R.PRESETS["smoke"]._replace(budget=R.Budget(chunks_per_call=0))
    with pytest.raises(runner.BadInput, match=r"LearnConfig.budget.chunks_per_call must be an integer >= 1"):
        runner.validate(bad)
    with pytest.raises(runner.BadInput, match=r"LearnConfig.archive .*missing.npz"):
        runner.validate(R.PRESETS["smoke"]._replace(archive=str(tmp_path / "missing.npz")))


def test_maps_too_small_for_the_walker_are_refused_naming_the_archive():
    """A 32 x 32 archive (``evolve --preset smoke``'s size) cannot hold the walker's start and goal margins: one
    line naming the archive and the maps' size, not the env's ValueError from inside the run."""
    run, _, arch, policy, _ = runner.validate(R.PRESETS["smoke"])
    small = arch._replace(heightmaps=np.zeros((2, 32, 32), np.float32))
    with pytest.raises(runner.BadInput, match=r"LearnConfig.archive .*: its 32 x 32 maps cannot hold the walker: "
                                              r"terrain too small for the margins"):
        runner.make_env(run, small, policy)


def test_resolve_takes_the_protocol_and_accels_generator_from_the_archive():
    """Protocol fields left None come from the archive's config; given ones win; accel without a generator takes
    the archive's one generator."""
    from jaxterrain import qd as A

    arch = A.load(presets.CPPN_ARCHIVE)
    paper = R.PRESETS["paper"]
    assert runner.resolve(paper, arch).curriculum.protocol[:3] == (80, 5, 4)
    mine = paper._replace(protocol=R.ProtocolOverride(attempts=20, headings=1))
    assert runner.resolve(mine, arch).curriculum.protocol[:3] == (20, 5, 1)
    accel = paper._replace(curriculum=paper.curriculum._replace(selector="accel", params=None))
    assert runner.resolve(accel, arch).curriculum.params == S.AccelParams(generator="cppn")
    assert isinstance(runner.resolve(paper, arch).curriculum, CurriculumConfig)
