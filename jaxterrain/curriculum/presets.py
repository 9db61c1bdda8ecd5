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

__all__ = ["CPPN_ARCHIVE", "FLAT_PRESETS", "PRESET_NAMES", "RECIPE_NAMES", "BACKENDS", "RULES", "HELP", "SELECTOR_HELP",
           "FINE_TUNING_HELP"]

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
              truncation="bootstrap", scan_lr_scale=1.0, overlap=False, eval_lag=False, compact=True, policy_every=None,
              terrains_per_chunk=8, levels=10, levels_init=None, levels_promote=None, levels_demote=0.5,
              plr_capacity=None, plr_replay_prob=0.8, plr_staleness=0.3, plr_temperature=0.3, plr_min_fill=0.5, accel_generator=None, accel_edits=1,
              robot=None, recipe="paper", observation=None, randomise=None, spawn="feet", terrains=None,
              terrain_height=None, terrain_order="name")

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
SPAWNS = ("feet", "patch")
"""How the walker is set down at a reset (``jaxterrain.walker.SPAWNS``; a literal, a test keeps them equal)."""

RULES = {
    **{k: at_least(1) for k in ("trials", "max_epochs", "epochs_per_chunk", "steps_per_epoch", "chunks_per_call",
                                "num_envs", "max_evals", "policy_every", "episode_length", "attempts",
                                "terrains_per_chunk", "levels", "plr_capacity", "accel_edits")},
    "best": (at_least(1), at_most("attempts")), "headings": walks("attempts", "best"),
    "threshold": unit(), "levels_init": at_least(0), "levels_promote": unit(), "levels_demote": fraction(),
    "plr_replay_prob": fraction(), "plr_staleness": fraction(), "plr_temperature": positive(),
    "plr_min_fill": fraction(), "healthy_reward": non_negative(), "learning_rate": positive(),
    "scan_lr_scale": positive(),
    "terrain_order": one_of(("name", "difficulty")), "observation": one_of(("blind", "perceptive")),
    "spawn": one_of(SPAWNS),
    "recipe": one_of(RECIPE_NAMES), "truncation": one_of(("mask", "bootstrap")), "backend": one_of(BACKENDS),
    **{k: one_of((True, False)) for k in ("update_normaliser", "overlap", "eval_lag", "compact", "fast_compile")},
}
"""The checks of single keys of a flat curriculum run, by flat key (``schema`` rules; the command line checks a
resolved config with them before any run folder is made, and makes each flag's type, choices and range from them:
``experiments.cli_gen``). ``jaxterrain.curriculum.runner.validate`` checks the typed run again, deeper (the
archive, the selector's params against it, the PPO shape); a test checks that every value these rules refuse the
library refuses too."""

SELECTOR_HELP: dict[str, str] = {
    "terrains_per_chunk": "dr, plr: terrains per trial and chunk, the envs dealt round-robin over them, {range}",
    "levels": "levels: difficulty levels (bands of the archive by distance from (0, 0)), {range} (legged_gym's 10)",
    "levels_init": "levels: envs start at random levels 0 .. N, {range} and at most levels - 1 (default levels // 2)",
    "levels_promote": "levels: an env moves up when its furthest normalised distance in a chunk is at least this, "
                      "{range} (default: the threshold)",
    "levels_demote": "levels: ... and down when it is below this, {range} (default 0.5: half the course)",
    "plr_capacity": "plr, accel: level buffer entries, {range} (plr: at most the archive's terrains; default: sized to "
                    "fill to --plr-min-fill in the run's first tenth of chunks; 4000); JaxUED's maze_plr.py default "
                    "in brackets",
    "plr_replay_prob": "plr, accel: the chance a chunk replays buffer terrains, {range} (0.8); JaxUED's maze_plr.py "
                       "default in brackets",
    "plr_staleness": "plr, accel: staleness coefficient, {range} (0.3); JaxUED's maze_plr.py default in brackets",
    "plr_temperature": "plr, accel: rank prioritisation temperature, {range} (0.3); JaxUED's maze_plr.py default in "
                       "brackets",
    "plr_min_fill": "plr, accel: buffer fill before any replay, {range} (0.5); JaxUED's maze_plr.py default in "
                    "brackets",
    "accel_generator": "accel: the generator whose genomes are the levels (its sample and mutate); default: the "
                       "archive's generator",
    "accel_edits": "accel: the generator's mutations per edit of a replayed level, {range}",
}
"""The per-env curricula's flags' help (each selector's params: ``dr``, ``levels``, ``plr``, ``accel``) (``experiments.cli_gen`` adds the type, the choices, the allowed range of the key's rule in :data:`RULES`
where the text says ``{range}`` or at its end, and every preset's value; ``{backend}``, ``{randomise}`` and
``{selectors}`` are phrases the command line fills in, ``{scope}`` what ``curriculum`` adds: ", in every
treatment")."""

FINE_TUNING_HELP: dict[str, str] = {
    "observation": "start from the robot's blind base policy (the default, the paper's) or its perceptive "
                   "twin{scope}; the walker observes what the start policy records (a --policy of another set "
                   "is refused)",
    "recipe": "how fine-tuning PPO collects each 40 000-step update{scope}: paper (500 envs per trial x 8 x 10 "
              "steps; every preset but smoke) or wide (4 000 envs x 10 steps: 8x fewer sequential steps, 8x "
              "the envs; 1.35x faster on an H200 but lower held-out scores: docs/results/wide_recipe.md); "
              "jaxterrain.curriculum.RECIPES (--num-envs overrides its envs)",
    "update_normaliser": "fine-tuning keeps merging its data into the observation normaliser's statistics, as "
                         "brax's PPO does{scope}; --no-update-normaliser keeps the base policy's statistics "
                         "fixed",
    "randomise": "physics randomisation of fine-tuning's walker{scope} (its curriculum's evaluations too) {randomise}",
    "spawn": "how the walker is set down at each reset{scope}: feet (default: the body lifted until every foot clears "
             "the terrain under it) or patch (only the lowest foot clear of a 0.5 m patch under the torso: every run "
             "before 2026-11-29, which cut the ant's feet into rising ground; a run saved before reads as patch)",
    "healthy_reward": "fine-tuning reward per step for staying up, {range}{scope} (default: the walker's 5.0, "
                      "the base policy's; evaluations measure distance and do not use it)",
    "learning_rate": "fine-tuning PPO's Adam learning rate, {range}{scope}",
    "scan_lr_scale": "a perceptive walker's Adam steps on the first-layer weights that read its height scan, as a "
                     "multiple of every other weight's, {range}{scope} (1: no difference; about 0.1 evens out the "
                     "scan's 153 correlated inputs, docs/results/exp4/scan_diag/); a blind walker takes only 1",
    "truncation": "what fine-tuning PPO learns from a walk that ends at the goal or the time limit{scope}: "
                  "bootstrap (default: r + gamma V(final observation); keeps the value net from diverging and "
                  "standard CL learning, docs/results/exp2_paper.md) or mask (brax's: nothing; the runs before "
                  "2026-11-27)",
    "max_evals": "evaluations (chunks) spent on one terrain before it is left anyway, {range}{scope} (the "
                 "paper's 100; gpu-short keeps it, so one terrain that never reaches the threshold can take all "
                 "75 of its chunks)",
    "overlap": "evaluate each chunk's policy while the next chunk trains, in the same physics calls{scope} (the "
               "same curriculum; the walker on one tile per trial, on either backend; "
               "CurriculumConfig.overlap)",
    "eval_lag": "with --overlap: keep the chunk trained while a terrain's last evaluation was walked instead of "
                "training it again on the next terrain{scope} (no loop step more per switch; the selector sees each "
                "evaluation one chunk late, the kept chunk is not evaluated: NaN in history.csv; "
                "CurriculumConfig.eval_lag)",
    "compact": "once some trials have finished, compute only the running ones in each block (the same results; "
               "one compile per block size){scope}",
}
"""The fine-tuning flags' help, shared by ``learn`` and ``curriculum`` (``experiments.cli_gen`` adds the type, the choices, the allowed range of the key's rule in :data:`RULES`
where the text says ``{range}`` or at its end, and every preset's value; ``{backend}``, ``{randomise}`` and
``{selectors}`` are phrases the command line fills in, ``{scope}`` what ``curriculum`` adds: ", in every
treatment")."""

HELP: dict[str, str] = {
    "archive": "archive .npz (default: the shipped CPPN archive, jaxterrain/assets/archives/cppn_headings.npz)",
    "terrains": "DIR, a folder of your own heightmaps, trained on instead of an archive: .png (8/16-bit grey), "
                ".tif/.tiff (GeoTIFF, metres), .npy/.npz (metres), one terrain each, cropped to a centred square, "
                "resized to 256 x 256 cells of 4 cm, flat 1 m start strips (jaxterrain.suite.folder); curricula dr "
                "(the default with it), plr, levels, random",
    "terrain_height": "--terrains: metres of an image's full grey (default 1.0), and the relief every metre file is "
                      "rescaled to (default: its own metres), in (0, 1]",
    "terrain_order": "--terrains: how the terrains rank by hardness (levels' bands, the hardest traversed): name "
                     "(file-name order, the default; free) or difficulty (the start policy walked on each before "
                     "the run under its protocol, hardest last; one more compile)",
    "curriculum": "{selectors} or module:object (a factory config -> jaxterrain.curriculum.Selector); "
                  "jaxterrain.curriculum.selectors",
    **SELECTOR_HELP,
    "trials": "trials run together",
    "threshold": "fraction of the maximum fitness",
    "max_epochs": "each trial's epoch budget (an epoch: 4 000 env steps; the paper: 30 000)",
    "policy": "policy folder to start from (default: the base policy)",
    "robot": "start from this robot's shipped base policy (humanoid, the default, or one a --plugin registered; "
             "jaxterrain.walker.robots); a --policy walks the robot it was trained on",
    "chunks_per_call": "chunks per jitted call / checkpoint",
    "num_envs": "PPO envs per trial (all on its terrain)",
    **FINE_TUNING_HELP,
    "policy_every": "also write every trial's walker every N chunks, policies/chunk_CCCCC/trial_K/ (at the end of "
                    "the first block at or after each multiple of N; default: only the final policies/trial_K/)",
    "attempts": "evaluation walks in total (default: the archive's protocol, e.g. 20)",
    "best": "best walks averaged per heading (default: archive's)",
    "headings": "evaluation headings (default: the archive's protocol: 1 = the paper's +x)",
    "backend": "walker physics: {backend}; warp holds one tile per trial",
}
"""``learn``'s flags' help, each flat key's documentation, in ``--help``'s order (``experiments.cli_gen`` adds the type, the choices, the allowed range of the key's rule in :data:`RULES`
where the text says ``{range}`` or at its end, and every preset's value; ``{backend}``, ``{randomise}`` and
``{selectors}`` are phrases the command line fills in, ``{scope}`` what ``curriculum`` adds: ", in every
treatment")."""
