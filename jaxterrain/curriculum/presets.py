"""The presets of a curriculum run (``learn``; ``curriculum`` runs each treatment under one) in their serialised
form: the flat ``config.json`` dict, ``{key: value}``, that :func:`jaxterrain.curriculum.run_config.from_flat` turns
into the typed :class:`~jaxterrain.curriculum.run_config.LearnConfig` (``run_config.PRESETS`` holds them typed).

This module imports nothing but the standard library, so that ``python -m experiments learn --help`` (which shows
every preset's values) reads it without importing JAX (``experiments.common.library_file``).

- ``paper``: the paper's budget, 30 000 epochs a trial, 10 trials; the fine-tuning recipe ``paper``.
- ``gpu``: the same (the paper's protocol at GPU batch sizes is the paper's own here).
- ``gpu-short``: a tenth of the budget, 3 000 epochs.
- ``smoke``: a CPU, about a minute after compiling: 2 trials of 4 one-epoch chunks of 80 env steps on 4 envs, 2
  walks per evaluation along +x whatever the archive's protocol, 100-step episodes, its own tiny update (4 envs x 10
  x 2), no recipe's.
"""

from __future__ import annotations

from pathlib import Path

from jaxterrain.runtime.schema import at_least, at_most, fraction, non_negative, one_of, positive, unit, walks

__all__ = ["CPPN_ARCHIVE", "FLAT_PRESETS", "PRESET_NAMES", "RECIPE_NAMES", "BACKENDS", "RULES"]

CPPN_ARCHIVE = str(Path(__file__).parents[1] / "assets" / "archives" / "cppn_headings.npz")
"""The default archive: the CPPN's paper-budget roughness x TPI archive (evolved after the fix of tied insertion),
reseated under ``difficulty.HEADINGS``; package data (``jaxterrain/assets/archives/``, a copy of
``docs/results/exp2_cppn_headings_archive.npz``), so a run starts from any folder."""

_PAPER = dict(archive=CPPN_ARCHIVE, curriculum="map", trials=10, descriptors=["roughness", "tpi"], policy=None,
              epochs_per_chunk=40, steps_per_epoch=4000, max_epochs=30000, threshold=0.9, max_fitness=1.0,
              max_evals=100, attempts=None, best=None, headings=None, kappa=0.05, rho=0.4, sigma_f=1.0, noise=0.001,
              gp_evaluation="final", removal_margin=0.05, removal_ties="nearer", credit="threshold",
              distance_origin="origin", roughness_stride=5, max_observations=None, num_envs=500, unroll_length=10,
              num_unrolls=8, num_minibatches=8, update_epochs=8, learning_rate=3e-4, episode_length=1000,
              chunks_per_call=25, fast_compile=False, backend="auto", healthy_reward=None, update_normaliser=True,
              truncation="bootstrap", overlap=False, compact=True, policy_every=None, terrains_per_chunk=8, levels=10,
              levels_init=None, levels_promote=None, levels_demote=0.5, plr_capacity=None, plr_replay_prob=0.8,
              plr_staleness=0.3, plr_temperature=0.3, plr_min_fill=0.5, accel_generator=None, accel_edits=1,
              robot=None, recipe="paper", observation=None, randomise=None, terrains=None, terrain_height=None,
              terrain_order="name")

FLAT_PRESETS: dict[str, dict] = {
    "smoke": {**_PAPER, "trials": 2, "epochs_per_chunk": 1, "steps_per_epoch": 80, "max_epochs": 4, "max_evals": 2,
              "attempts": 2, "best": 1, "headings": 1, "num_envs": 4, "num_unrolls": 2, "num_minibatches": 2,
              "update_epochs": 1, "episode_length": 100, "chunks_per_call": 2, "fast_compile": True,
              "compact": False, "recipe": None},  # its own tiny update (4 envs x 10 x 2), no recipe's
    "gpu-short": {**_PAPER, "max_epochs": 3000},
    "gpu": dict(_PAPER),
    "paper": dict(_PAPER),
}
"""Every preset's flat config (a fresh run's ``config.json`` adds ``preset``, ``seed`` and ``command``)."""
PRESET_NAMES = tuple(FLAT_PRESETS)

RECIPE_NAMES = ("paper", "wide")
"""The fine-tuning recipes' names (``jaxterrain.curriculum.RECIPES``; a literal here, a test keeps them equal)."""
BACKENDS = ("auto", "jax", "warp")
"""The walker's physics (``jaxterrain.walker.layout.BACKEND_CHOICES``; a literal, a test keeps them equal)."""

RULES = {
    **{k: at_least(1) for k in ("trials", "max_epochs", "epochs_per_chunk", "steps_per_epoch", "chunks_per_call",
                                "num_envs", "max_evals", "policy_every", "episode_length", "attempts",
                                "terrains_per_chunk", "levels", "plr_capacity", "accel_edits")},
    "best": (at_least(1), at_most("attempts")), "headings": walks("attempts", "best"),
    "threshold": unit(), "levels_init": at_least(0), "levels_promote": unit(), "levels_demote": fraction(),
    "plr_replay_prob": fraction(), "plr_staleness": fraction(), "plr_temperature": positive(),
    "plr_min_fill": fraction(), "healthy_reward": non_negative(), "learning_rate": positive(),
    "terrain_order": one_of(("name", "difficulty")), "observation": one_of(("blind", "perceptive")),
    "recipe": one_of(RECIPE_NAMES), "truncation": one_of(("mask", "bootstrap")), "backend": one_of(BACKENDS),
    **{k: one_of((True, False)) for k in ("update_normaliser", "overlap", "compact", "fast_compile")},
}
"""The checks of single keys of a flat curriculum run, by flat key (``schema`` rules; the command line checks a
resolved config with them before any run folder is made, and makes each flag's type, choices and range from them:
``experiments.cli_gen``). ``jaxterrain.curriculum.runner.validate`` checks the typed run again, deeper (the
archive, the selector's params against it, the PPO shape); a test checks that every value these rules refuse the
library refuses too."""
