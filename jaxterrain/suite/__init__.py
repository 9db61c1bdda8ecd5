"""The held-out terrain suite and the evaluation of walkers on it (Experiment 3: do curricula generalise?).

- :mod:`~jaxterrain.suite.families`: the field's sub-terrains (slopes, stairs, boxes, obstacles, stepping stones,
  gaps, waves, roughness, flat), each at graded levels of one physical parameter;
- :mod:`~jaxterrain.suite.heldout`: versioned suites (:func:`load`, ``"v1"``, and ``"v2"`` calibrated per robot:
  ``load("v2", robot="ant")``): every family at every level and fresh random samples of each generator binned by
  descriptor distance, deterministic from :data:`SEED`;
- :mod:`~jaxterrain.suite.calibration`: the checks of a level curve (level 0 >= 0.8, level 9 <= 0.3, rises <= 0.03)
  and the choice of levels from a measured grid;
- :mod:`~jaxterrain.suite.evaluation`: :func:`evaluate_policies` (``[P, N]`` fitness) and :func:`passed_levels` (the
  highest level of each family passed with every level below it passed);
- :mod:`~jaxterrain.suite.passing`: levels passed with the trial as the unit (:func:`levels_passed_gain`: how many
  more levels of each family a treatment's walkers pass than the base policy, with a bootstrap interval);
- :mod:`~jaxterrain.suite.outputs`: an evaluation's files (CSV, Markdown, figures);
- :mod:`~jaxterrain.suite.batch`: many walkers on a suite resumably (one result file per walker, written when it is
  walked; a time limit; a rerun skips what is done): the re-evaluation of every shipped walker on v2;
- :mod:`~jaxterrain.suite.folder`: your own terrains, a folder of PNG / GeoTIFF / .npy / .npz heightmaps
  (:func:`load_folder`), as a suite (:func:`folder_suite`) or a curriculum bank (:func:`folder_bank`).

    from jaxterrain import rl, suite
    s = suite.load("v1")
    fitness = suite.evaluate_policies([rl.load_policy()], s.heightmaps, jax.random.key(0))   # [1, N]
    suite.passed_levels(fitness[0], s)
"""

from jaxterrain.suite import batch
from jaxterrain.suite.calibration import check_curve, decreasing_fit, propose_values, select_levels
from jaxterrain.suite.evaluation import (CVAR_ALPHA, THRESHOLD, cell_scores, check_policies, evaluate_policies,
                                        generator_robustness, highest_level_passed, level_fitness, passed_levels)
from jaxterrain.suite.families import (FAMILIES, FAMILIES_V2, Family, START_STRIP, TABLES, build_terrain, edge_distance,
                                      family_names, family_table, misfit, room)
from jaxterrain.suite.folder import (EXTENSIONS, ORDERS, TERRAIN_SIDE, TerrainFolder, difficulty_order, fit_terrain,
                                    folder_bank, folder_suite, load_folder, name_order, read_terrain)
from jaxterrain.suite.heldout import (GENERATORS, LEVELS, ROBOTS, SEED, Suite, V2_LEVELS, VERSIONS, archive_suite,
                                     descriptor_levels, load, v2_terrain)
from jaxterrain.suite.passing import highest_passed, levels_passed, levels_passed_gain
from jaxterrain.suite.outputs import (Evaluation, level_table, read_fitness, plot_levels, plot_suite, short_names,
                                     write_evaluation)
from jaxterrain.suite import run_config, runs  # the evaluate run
from jaxterrain.suite.run_config import EvaluateRun
from jaxterrain.suite.runs import EvaluationResult, evaluate_run, validate_evaluate

__all__ = [
    "batch",
    "EXTENSIONS", "ORDERS", "TERRAIN_SIDE", "TerrainFolder", "difficulty_order", "fit_terrain", "folder_bank",
    "folder_suite", "load_folder", "name_order", "read_terrain",
    "check_curve",
    "decreasing_fit",
    "propose_values",
    "select_levels",
    "FAMILIES",
    "FAMILIES_V2",
    "TABLES",
    "family_table",
    "START_STRIP",
    "Family",
    "build_terrain",
    "edge_distance",
    "family_names",
    "misfit",
    "room",
    "GENERATORS",
    "LEVELS",
    "SEED",
    "VERSIONS",
    "ROBOTS",
    "V2_LEVELS",
    "v2_terrain",
    "Suite",
    "descriptor_levels",
    "load",
    "archive_suite",
    "Evaluation",
    "read_fitness",
    "write_evaluation",
    "level_table",
    "plot_levels",
    "plot_suite",
    "short_names",
    "THRESHOLD",
    "CVAR_ALPHA",
    "generator_robustness",
    "cell_scores",
    "check_policies",
    "evaluate_policies",
    "highest_level_passed",
    "level_fitness",
    "passed_levels",
    "highest_passed",
    "levels_passed",
    "levels_passed_gain",
    "run_config",
    "runs",
    "EvaluateRun",
    "EvaluationResult",
    "evaluate_run",
    "validate_evaluate",
]
