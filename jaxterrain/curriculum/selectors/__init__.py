"""Curricula as selectors: which terrains a trial trains on, as a pytree state and pure functions over it.

    selector = get_selector(config)                       # config.selector: map, roughness, random, dr, levels, plr, accel
    s = selector.init(key, bank)                          # the selector's state (rides in core.State.selector)
    a = selector.assign(s)                                # Assignment: the trial's K terrains, env -> terrain, evaluated
    s, decision = selector.update(s, key, bank, outcome)  # after a chunk: Outcome(terrain, fitness, progress)

The shape is optax's ``GradientTransformation`` and JaxUED's ``LevelSampler``: a :class:`Selector` is a NamedTuple of
pure functions, built once from the (static) :class:`~jaxterrain.curriculum.CurriculumConfig` and its ``params``; its state is any
pytree of arrays. The trial loop (:mod:`.core`, jitted and vmapped over trials) never knows which selector runs:
each chunk it trains the envs on the assignment, evaluates the policy on the assignment's ``evaluated`` terrain,
credits the hardest terrain traversed, and hands the selector the :class:`Outcome`; the selector's
:class:`Decision` says whether the envs restart (new terrains) and whether the trial has run out of terrains.

Two kinds ship:

- **Sequence selectors** (``slots = 1``: every env on one terrain until it is finished, the paper's Experiment 2):
  ``map`` (the IT&E GP: UCB choice and the removal rule), ``roughness`` (standard CL: every ``stride``-th
  terrain in order of roughness) and ``random`` (uniform among the terrains not yet trained). A terrain is finished
  at ``threshold x max_fitness`` or after ``max_evals`` evaluations (:class:`SequenceState`).
- **Per-env selectors** (``slots = K > 1``: the trial's envs spread over K terrains, each env on its own, new
  terrains every chunk and the envs restarted on them): ``dr`` (domain randomisation: K terrains drawn uniformly
  from the bank every chunk, envs dealt round-robin), ``levels`` (legged_gym's terrain curriculum: ``levels``
  difficulty levels, each env moved up or down by how far it walked, :class:`LevelsState`), ``plr``
  (prioritised level replay: JaxUED's level buffer over the bank's terrains, :class:`PLRState`) and ``accel``
  (PLR over a generator's genomes, rendered in the loop, the replayed levels edited by the generator's ``mutate``
  and re-inserted, :class:`AccelState`; ``Selector.maps`` gives the loop its maps).

Where ours differ from the field's (decisions, with reasons) is in each algorithm's module docstring. Common to the
per-env selectors: terrains are re-drawn and levels moved at chunk boundaries (every ``epochs_per_chunk x
steps_per_epoch`` env steps: 320 steps of each of the 500 envs at the paper's sizes, about 1.5 walks), not at each
env's own reset as in legged_gym (``_update_terrain_curriculum`` runs in ``reset_idx``): the terrains of a chunk are
one bank of tiles shared by every env on MuJoCo Warp, rebuilt once per chunk. Each evaluates (for the record of the
hardest terrain traversed, the paper's metric) one terrain a chunk: ``dr`` and ``plr`` their first slot, ``levels``
the terrain of the highest level an env stands on (so a ``levels`` trial whose envs reached the top band is
evaluated there, and credits nothing until it walks it), ``accel`` a uniform bank terrain in an extra slot.

The package: :mod:`.protocol` (the types above and the registry), :mod:`.base` (pure helpers), :mod:`.sequence`
(the one-terrain state and rule), then one module per algorithm, each owning its params (``CurriculumConfig.params``;
None = the defaults) and registering itself: :mod:`.map` (:class:`MapParams`), :mod:`.roughness`
(:class:`RoughnessParams`), :mod:`.random` (none), :mod:`.dr` (:class:`DRParams`), :mod:`.levels`
(:class:`LevelsParams`), :mod:`.plr` (:class:`PLRParams`) and :mod:`.accel` (:class:`AccelParams`).

A selector of your own: a function ``(config) -> Selector`` registered with :func:`register_selector` (with its
params type, their check and flat names if it has any: :class:`SelectorSpec`), or named as ``module:object`` in
``CurriculumConfig.selector``, e.g. from a plugin module.
"""

from jaxterrain.curriculum.selectors import base, protocol, sequence
from jaxterrain.curriculum.selectors import map, roughness, random, dr, levels, plr, accel  # noqa: A004 - registers
from jaxterrain.curriculum.selectors.accel import (ACCEL_EDIT, ACCEL_NEW, ACCEL_REPLAY, AccelParams, AccelState,
                                                   accel_generator, accel_selector)
from jaxterrain.curriculum.selectors.base import roughness_sequence, select, terrain_hardness
from jaxterrain.curriculum.selectors.dr import DRParams, DRState, dr_selector
from jaxterrain.curriculum.selectors.levels import LevelsParams, LevelsState, level_bands, levels_rule, levels_selector
from jaxterrain.curriculum.selectors.map import MapParams, gp_params, map_selector, removal_mask
from jaxterrain.curriculum.selectors.plr import (PLR_FILL_FRACTION, LevelBuffer, PLRParams, PLRState, learnability,
                                                 plr_buffer_capacity, plr_insert, plr_sample, plr_selector,
                                                 plr_weights)
from jaxterrain.curriculum.selectors.protocol import (Assignment, Decision, Outcome, Selector, SelectorSpec,
                                                      flat_name, get_selector, params_from_flat, register_selector,
                                                      resolve_factory, selector_fields, selector_names,
                                                      selector_params, selector_spec, validate_selector)
from jaxterrain.curriculum.selectors.random import random_selector
from jaxterrain.curriculum.selectors.roughness import RoughnessParams, roughness_selector
from jaxterrain.curriculum.selectors.sequence import SequenceState, sequence_selector

__all__ = ["Selector", "Assignment", "Outcome", "Decision", "SelectorSpec", "SequenceState", "DRState", "LevelsState",
           "PLRState", "AccelState", "LevelBuffer", "MapParams", "RoughnessParams", "DRParams", "LevelsParams",
           "PLRParams", "AccelParams", "get_selector", "register_selector", "selector_names", "selector_spec",
           "resolve_factory", "selector_params", "params_from_flat", "validate_selector", "selector_fields",
           "flat_name", "sequence_selector", "map_selector", "roughness_selector", "random_selector", "dr_selector",
           "levels_selector", "plr_selector", "accel_selector", "accel_generator", "ACCEL_NEW", "ACCEL_REPLAY",
           "ACCEL_EDIT", "plr_buffer_capacity", "PLR_FILL_FRACTION", "plr_weights", "plr_insert", "plr_sample",
           "learnability", "terrain_hardness", "roughness_sequence", "select", "removal_mask", "gp_params",
           "level_bands", "levels_rule", "base", "protocol", "sequence", "map", "roughness", "random", "dr", "levels",
           "plr", "accel"]
