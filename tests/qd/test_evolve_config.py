"""The ``evolve`` / ``coverage`` runs as typed configs (``qd.run_config``), validated once by the library
(``qd.runs.validate_evolve``, ``qd.table1.validate_coverage``) with errors that name the field. Host only: nothing
compiles."""

from __future__ import annotations

from pathlib import Path

import pytest

from jaxterrain import difficulty
from jaxterrain.qd import run_config as R
from jaxterrain.qd import runs, table1
from jaxterrain.runtime import schema


def test_presets_round_trip_through_their_flat_form():
    for name, run in R.PRESETS.items():
        assert run.preset == name and R.from_flat(R.to_flat(run)) == run
        schema.check(run, R.EVOLVE_RULES, "EvolveRun")
    for name, run in R.COVERAGE_PRESETS.items():
        assert run.preset == name and R.coverage_from_flat(R.coverage_to_flat(run)) == run
    smoke = R.coverage_to_flat(R.COVERAGE_PRESETS["smoke"])
    assert smoke["ranges"] == {"roughness": [0.0, 1.0], "tpi": [-0.02, 0.02], "tri": [0.0, 0.5]}  # config.json's form
    assert R.COVERAGE_PRESETS["gpu"].map_elites == R.PRESETS["gpu"].map_elites  # coverage = evolve's treatments
    assert list(R._FITNESSES) == list(difficulty.FITNESSES)


def test_an_older_config_json_reads_with_the_values_its_run_had():
    """A config.json from before headings, robots, observation sets and mixtures: those keys take the values the
    run was made with (LEGACY), so the run resumes to the same archive."""
    old = {k: v for k, v in R.FLAT_PRESETS["gpu"].items()
           if k not in ("headings", "robot", "observation", "mix", "fresh", "rollout_backend", "store_heightmaps")}
    run = R.from_flat({**old, "command": "evolve"})
    assert run == R.PRESETS["gpu"]._replace(preset=None, mixture=R.Mixture(None, 1))
    assert runs.evolve_config(run).headings == 1 and runs.evolve_config(run).rollout_backend == "jax"


def test_the_spawn_rule_reaches_the_walker_fitness_and_older_files_keep_theirs():
    """``walks.spawn`` sets how the walker fitness sets every walker down (``feet`` by default): it reaches the
    :class:`~jaxterrain.qd.EvolveConfig` (which the archive records) and the env the fitness walks; an evolve or
    coverage ``config.json`` written before the key, and an archive header of then, read as ``patch``, the rule
    they were evolved with; a checkpoint of then resumes under the run's rule. Builds the env, compiles nothing."""
    from jaxterrain.qd import EvolveConfig, config_from_dict, config_to_dict, default_fitness, resolve_config
    from jaxterrain.qd.evolution import _check_meta, _resume_signature
    from jaxterrain.walker import SPAWNS

    assert R.SPAWNS == SPAWNS and R.PRESETS["gpu"].walks.spawn == "feet" and R.LEGACY["spawn"] == "patch"
    assert R.from_flat({k: v for k, v in R.to_flat(R.PRESETS["gpu"]).items() if k != "spawn"}).walks.spawn == "patch"
    old = {k: v for k, v in R.coverage_to_flat(R.COVERAGE_PRESETS["gpu"]).items() if k != "spawn"}
    assert R.coverage_from_flat(old).walks.spawn == "patch"
    walker = {"fitness": "difficulty", "size": 64, "map_elites.window": 8, "ranges": None}
    for rule in SPAWNS:
        run = runs.validate_evolve(schema.replace(R.PRESETS["smoke"], {**walker, "walks.spawn": rule}))
        config = resolve_config(runs.evolve_config(run))
        assert config.spawn == rule and config_from_dict(config_to_dict(config)) == config
        assert default_fitness(64, config).env.config.spawn == rule  # the walks' WalkerConfig
    header = config_to_dict(EvolveConfig())
    del header["spawn"]
    assert config_from_dict(header).spawn == "patch"  # an archive evolved before the field
    meta = {"generator": "perlin", "key": [0, 1], "config": _resume_signature(EvolveConfig(spawn="feet"))}
    before = {**meta, "config": {k: v for k, v in meta["config"].items() if k != "spawn"}}
    _check_meta(Path("run"), before, meta, 0, 10)  # a checkpoint of then: the run's config.json says which rule
    with pytest.raises(ValueError, match="was made with another config"):
        _check_meta(Path("run"), {**meta, "config": {**meta["config"], "spawn": "patch"}}, meta, 0, 10)
    with pytest.raises(ValueError, match="EvolveConfig.spawn must be one of feet, patch; got 'torso'"):
        resolve_config(EvolveConfig(spawn="torso"))
    with pytest.raises(ValueError, match="spawn must be one of feet, patch, got 'torso'"):
        difficulty.difficulty_fitness(64, spawn="torso")


@pytest.mark.parametrize("changes, message", [
    ({"map_elites.bins": 0}, "EvolveRun.map_elites.bins must be an integer >= 1; got 0"),
    ({"walks.spawn": "torso"}, "EvolveRun.walks.spawn must be one of feet, patch; got 'torso'"),
    ({"walks.best": 30}, "EvolveRun.walks.best must be <= EvolveRun.walks.attempts (2); got 30"),
    ({"descriptors": ("foo", "tpi")}, "EvolveRun.descriptors: unknown descriptor 'foo'; choose from"),
    ({"generator": "nope"}, "EvolveRun.generator: unknown generator 'nope'; choose from"),
    ({"generator": "diamond_square", "size": 100}, "EvolveRun.size 100 does not suit generator 'diamond_square' "
                                                   "(EvolveRun.generator): size must be a power of two"),
    ({"fitness": "difficulty"}, "EvolveRun.size must be >= 39 pixels for the walker fitness of robot humanoid"),
    ({"walks.robot": "dog"}, "EvolveRun.walks.robot: robot must be one of"),
    ({"generator": "mixed", "mixture.generators": ("perlin", "worley"), "mixture.fresh": 4},
     "EvolveRun.map_elites.batch_size must be > 8 with EvolveRun.generator mixed (EvolveRun.mixture.fresh 4 of "
     "each of 2"),
    ({"ranges": ((0.5, 0.0), (0.0, 1.0))}, "EvolveRun.ranges must be two finite (lo, hi) pairs with hi > lo"),
])
def test_validate_evolve_names_the_field(changes, message):
    with pytest.raises(ValueError) as err:
        runs.validate_evolve(schema.replace(R.PRESETS["smoke"], changes))
    assert str(err.value).startswith(message), err.value


def test_validate_coverage_names_the_field_and_derives_each_treatment():
    run = table1.validate_coverage(R.COVERAGE_PRESETS["smoke"])
    one = table1.treatment_run(run, ("tri", "tpi"), "perlin")
    assert (one.generator, one.descriptors, one.ranges) == ("perlin", ("tri", "tpi"), ((0.0, 0.5), (-0.02, 0.02)))
    assert one.map_elites == run.map_elites and runs.validate_evolve(one) == one
    assert [t[1:] for t in table1.treatments(run.pairs, ["perlin", "cppn"])][:3] == [
        (("tri", "tpi"), "perlin"), (("tri", "tpi"), "cppn"), (("tri", "roughness"), "perlin")]
    for changes, message in ((({"generators": ("perlin", "nope")}), "CoverageRun.generators: unknown generator"),
                             ({"pairs": (("tri", "faces"),)}, "CoverageRun.ranges: no range for descriptor(s) "
                                                              "['faces']"),
                             ({"map_elites.window": 64}, "CoverageRun.map_elites.window must be <= CoverageRun.size")):
        with pytest.raises(ValueError) as err:
            table1.validate_coverage(schema.replace(run, changes))
        assert str(err.value).startswith(message), err.value
