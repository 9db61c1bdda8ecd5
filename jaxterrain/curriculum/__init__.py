"""Curricula over a terrain archive, on device: Experiment 2's IT&E map-based curriculum and its baselines, and the
field's (domain randomisation, terrain levels), all behind one selector protocol (:mod:`.selectors`).

    from jaxterrain import curriculum as C
    config = C.validate_config(C.CurriculumConfig(selector="map"))          # every choice documented in .config
    states = C.init_trials(keys, bank, start, config=config, harness=harness)   # [T] trials
    run = C.make_runner(config, harness)                                    # one jitted block of chunks
    states = run(states, bank, 25)
    first = C.first_epochs(states.history.epoch, states.history.hardest)    # Table 2, per trial

Modules, in the order they build on each other: :mod:`.gp` (the IT&E Gaussian process), :mod:`.selectors` (a
curriculum as ``Selector(init, assign, update, summary)`` over its own state: map, roughness, random, dr, levels,
yours), :mod:`.config` (CurriculumConfig and the choices the paper leaves open), :mod:`.core` (state, init, step
of one trial: pure, whichever selector runs), :mod:`.population` (the loops over many trials, of one treatment or of
several in one program),
:mod:`.walker` (the PPO + walker harness), :mod:`.analysis` (Table 2, Figure 7), :mod:`.outputs` (a treatment's
files), :mod:`.presets` and :mod:`.run_config` (one run as a typed, nested ``LearnConfig``, its presets and its
``config.json`` form), :mod:`.progress` (metrics and progress lines inside compiled blocks),
:mod:`.own_terrains` (a run on a folder of your own heightmaps) and :mod:`.runner` (a treatment from a
``LearnConfig``: validation, compiled blocks, checkpoints, time limits; the ``learn`` command is a thin layer over
it), :mod:`.checkpoints` (a treatment's states back from its checkpoint) and :mod:`.batch` (treatments grouped into
populations, one compiled program each: the ``curriculum`` command's default).
"""

from jaxterrain.curriculum import (batch, checkpoints, gp, outputs, own_terrains, population, presets, progress,
                                   run_config, runner, selectors, walker)
from jaxterrain.curriculum.analysis import (
    MILESTONES,
    PAPER_TABLE2,
    first_epochs,
    format_milestone,
    hardest_curve,
    milestone_summary,
    terrain_runs,
)
from jaxterrain.curriculum.config import FINE_TUNING, RECIPES, CurriculumConfig, SELECTORS, recipe, validate_config
from jaxterrain.curriculum.selectors import (
    Assignment,
    Decision,
    Outcome,
    Selector,
    get_selector,
    register_selector,
    selector_names,
)
from jaxterrain.curriculum.core import (
    Harness,
    History,
    State,
    gp_params,
    init,
    init_trials,
    removal_mask,
    roughness_sequence,
    select,
    step,
    terrain_hardness,
)
from jaxterrain.curriculum.population import (
    live_rows,
    make_population_runner,
    make_runner,
    mesh_rows,
    run_live,
    run_population,
    run_trials,
    tile_moves,
)

__all__ = [
    "Assignment", "CurriculumConfig", "Decision", "FINE_TUNING", "Outcome", "RECIPES", "recipe", "Selector", "get_selector",
    "register_selector", "selector_names", "selectors", "Harness", "History", "MILESTONES", "PAPER_TABLE2", "SELECTORS", "State", "first_epochs",
    "format_milestone", "gp", "gp_params", "outputs", "own_terrains", "presets", "progress", "run_config", "runner", "walker", "hardest_curve", "init", "init_trials", "live_rows", "make_runner",
    "milestone_summary", "removal_mask", "roughness_sequence", "run_live", "run_trials", "select", "step",
    "run_population", "make_population_runner", "mesh_rows", "tile_moves", "population", "batch", "checkpoints",
    "terrain_hardness", "terrain_runs", "validate_config",
]
