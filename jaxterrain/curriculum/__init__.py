"""Experiment 2's curricula over a terrain archive: the IT&E map-based curriculum and its baselines, on device.

    from jaxterrain import curriculum as C
    config = C.validate_config(C.CurriculumConfig(selector="map"))          # every choice documented in .config
    states = C.init_trials(keys, bank, start, config=config, harness=harness)   # [T] trials
    run = C.make_runner(config, harness)                                    # one jitted block of chunks
    states = run(states, bank, 25)
    first = C.first_epochs(states.history.epoch, states.history.hardest)    # Table 2, per trial

Modules, in the order they build on each other: :mod:`.gp` (the IT&E Gaussian process), :mod:`.config`
(CurriculumConfig and the choices the paper leaves open), :mod:`.core` (state, init, step, trials: pure),
:mod:`.walker` (the PPO + walker harness), :mod:`.analysis` (Table 2, Figure 7), :mod:`.outputs` (a treatment's
files) and :mod:`.runner` (a treatment from a flat config: validation, compiled blocks, checkpoints, time limits;
the ``learn`` command is a thin layer over it).
"""

from jaxterrain.curriculum import gp, outputs, runner, walker
from jaxterrain.curriculum.analysis import (
    MILESTONES,
    PAPER_TABLE2,
    first_epochs,
    format_milestone,
    hardest_curve,
    milestone_summary,
    terrain_runs,
)
from jaxterrain.curriculum.config import CurriculumConfig, SELECTORS, validate_config
from jaxterrain.curriculum.core import (
    Harness,
    History,
    State,
    gp_params,
    init,
    init_trials,
    live_rows,
    make_runner,
    removal_mask,
    roughness_sequence,
    run_live,
    run_trials,
    select,
    step,
    terrain_hardness,
)

__all__ = [
    "CurriculumConfig", "Harness", "History", "MILESTONES", "PAPER_TABLE2", "SELECTORS", "State", "first_epochs",
    "format_milestone", "gp", "gp_params", "outputs", "runner", "walker", "hardest_curve", "init", "init_trials", "live_rows", "make_runner",
    "milestone_summary", "removal_mask", "roughness_sequence", "run_live", "run_trials", "select", "step",
    "terrain_hardness", "terrain_runs", "validate_config",
]
