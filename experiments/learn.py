"""``python -m experiments learn``: one Experiment 2 treatment, PPO from the base policy on an archive curriculum.

    python -m experiments learn --archive docs/results/exp2_cppn_headings_archive.npz --curriculum map --trials 10 \\
        --preset gpu-short --out runs/learn-cppn --time-limit 9
    python -m experiments learn --resume runs/learn-cppn --time-limit 9          # until it says "done"

``--curriculum``: ``map`` (the paper's IT&E map-based curriculum), ``roughness`` (standard CL: the terrains sorted by
roughness, every fifth, in order), ``random`` (uniform over the archive), ``dr`` (domain randomisation: ``--terrains-per-chunk``
terrains a chunk, each env on one), ``levels`` (legged_gym's terrain levels over bands of the archive), ``plr``
(prioritised level replay over the archive's terrains; a curriculum's own flag, e.g. ``--plr-capacity``, with
another built-in one is refused), or
``module:object`` (your own :class:`jaxterrain.curriculum.Selector`; ``jaxterrain.curriculum.selectors``).

Your own terrains: ``--terrains DIR`` (a folder of PNG / GeoTIFF / .npy / .npz heightmaps, each one terrain:
``jaxterrain.suite.folder`` says how a file becomes a 256 x 256 terrain of 4 cm cells with flat start strips; images
at ``--terrain-height M`` metres for full grey, 1 m by default) instead of ``--archive``, with a curriculum that needs
no archive's grid: ``dr`` (without ``--curriculum``), ``plr``, ``levels`` or ``random`` (``map``, ``roughness`` and
``accel`` are refused). The
terrains rank by hardness in file-name order (``--terrain-order name``) or by the start policy's fitness on each
(``difficulty``, measured once before the run, in ``terrains.csv``); ``levels``' bands and the "hardest terrain
traversed" (then a rank, 0 to N - 1) read that rank. The folder's files' sha256 are checkpointed: ``--resume``
refuses a folder whose files changed. Evaluations walk under ``difficulty.HEADINGS`` (80 walks in 4 headings) unless
the preset or ``--protocol`` / ``--attempts`` say otherwise (smoke: 2 along +x). Every trial starts from the shipped base
policy (``--policy DIR`` for another), and the ``--trials`` trials run together (vmap) in one jitted function per
block of ``chunks_per_call`` chunks (a chunk = 40 epochs of 4 000 env steps + one evaluation; the curriculum's
choices: ``jaxterrain.curriculum.config``). The trials' env states ride from block to block and into every
checkpoint (about 10 MB per trial at 500 envs on MJX), so a run stopped after any chunk (``--time-limit``, whose first
block is one chunk that measures the rate) and resumed equals an uninterrupted one.
Once some trials have finished (the map curriculum can empty a trial's map long before the epoch budget), a block
computes only the trials still running, padded with finished ones to a power of two, each on its own tile
(``curriculum.run_live``; the same states, one compile per block size); ``--no-compact`` keeps every trial in every block (the smoke preset's
default, so that the CPU tests compile one block).

``--backend``: the walker's physics, ``auto`` (the default: ``warp`` on a GPU where MuJoCo Warp imports, else
``jax``; the two are compared in benchmarks/RESULTS.md), ``jax`` (MJX; every trial's envs on their own ``[H, W]``
heightfield) or ``warp`` (MuJoCo Warp, ``pip install 'jaxterrain[warp]'``; Warp shares one heightfield across all
envs, so the walker holds one tile per trial, ``WalkerConfig(tiles=trials)``, rebuilt from the trials' current
terrains at every chunk, and contact buffers for ``trials x max(num_envs, attempts)`` envs, ``trials x (num_envs +
attempts)`` with ``--overlap``; see
``jaxterrain.curriculum.walker``). It is saved in ``config.json``, so ``--resume`` keeps it.

Evaluation protocol: each evaluation walks under the protocol the archive's fitness was measured under (its
``EvolveConfig``'s ``attempts`` / ``best`` / ``headings``: 20 / 5 / 1 for the paper's, 80 / 5 / 4 for an archive evolved
or reseated under ``difficulty.HEADINGS``), so the GP's prior and its observations agree; ``--protocol paper|headings``
or ``--attempts`` / ``--best`` / ``--headings`` override it. With several headings the PPO envs also train in every
heading (``jaxterrain.curriculum.walker``).

Fine-tuning: the reward is the base policy's own (brax's humanoid: 1.25 x forward velocity + 5.0 per step for
staying up - control cost); ``--healthy-reward`` changes the per-step bonus for PPO only (evaluations measure
distance). The observation normaliser keeps merging the fine-tuning data, as brax's PPO does;
``--no-update-normaliser`` keeps the base policy's statistics. Why both exist: docs/results/exp2_headings.md.
``--scan-lr-scale C`` (with ``--observation perceptive`` or a perceptive ``--policy``; a blind walker is refused):
Adam's steps on the first-layer weights that read the height scan are C times every other weight's
(``rl.PPOConfig.scan_lr_scale``; the scan's size is the walker's; docs/results/exp4/scan_diag/).

Presets (``jaxterrain.curriculum.presets``; typed, ``jaxterrain.curriculum.run_config.PRESETS``): ``paper`` (30 000
epochs, the paper's budget), ``gpu-short`` (3 000 epochs, a tenth), ``smoke`` (CPU,
about a minute after compiling: 2 trials of 4 one-epoch chunks of 80 env steps on 4 envs, 2 walks per evaluation
along +x whatever the archive's protocol, 100-step episodes; the archive's terrains are used as they are). The
default archive is the CPPN's shipped paper-budget archive, reseated under ``difficulty.HEADINGS`` (``CPPN_ARCHIVE``).

``--resume RUN --report`` writes the outputs below from the last checkpoint without training (``summary_partial.json``
instead of ``summary.json``, which marks a finished run): the per-trial history survives a machine that is given
back with the checkpoint on it.

Writes into the run folder: ``config.json``, ``checkpoint.npz`` + ``tb/`` (the driver's, per block), ``metrics.csv``
(a row per chunk, written after every chunk, inside a block too; per block with ``--devices`` > 1),
``history.csv`` (one row per trial and chunk), ``sequences.csv`` (each trial's terrains in order), ``milestones.csv``
/ ``.md`` (Table 2's row), ``curve.png`` (hardest terrain traversed vs epoch, mean +- 1 standard error) and
``summary.json``, and every trial's walker in ``policies/trial_K/`` (``rl.load_policy`` reads it; ``python -m
experiments evaluate --policy RUN/policies/trial_0`` walks it on the held-out suite; ``--policy-every N`` adds
snapshots ``policies/chunk_CCCCC/trial_K/``; ``--resume RUN --export-policies`` writes them from the last checkpoint
of a run made before). This module is the command line only: the run is a ``jaxterrain.curriculum.run_config.LearnConfig`` (its
``config.json`` the flat form, ``--print-config`` its printout), run by :mod:`jaxterrain.curriculum.runner`.
"""

from __future__ import annotations

import argparse
import shutil
import sys

from experiments import cli_gen, common

_PRESETS = common.library_file("curriculum.presets")  # jaxterrain.curriculum.presets, read without JAX
CPPN_ARCHIVE = _PRESETS.CPPN_ARCHIVE
"""The default archive (``jaxterrain.curriculum.presets.CPPN_ARCHIVE``): the CPPN's shipped paper-budget archive."""
PRESETS: dict[str, dict] = common.with_preset_names({n: dict(p) for n, p in _PRESETS.FLAT_PRESETS.items()})
"""The presets in their flat (``config.json``) form, defined in the library: ``jaxterrain.curriculum.presets``
(typed: ``jaxterrain.curriculum.run_config.PRESETS``)."""
RULES = cli_gen.rules_by_key(_PRESETS.RULES, {})
"""The declared checks of the flat keys (``jaxterrain.curriculum.presets.RULES``), from which the flags are made."""
UPDATE_SHAPE = "--recipe / --num-envs (the update's shape)"
"""How a message names ``LearnConfig.curriculum.ppo``: the flags that shape an update."""

SELECTOR_HELP = _PRESETS.SELECTOR_HELP
"""The per-env curricula's flags (``dr``, ``levels``, ``plr``, ``accel``: each selector's params,
``CurriculumConfig.SELECTOR_FIELDS``); one given with a built-in curriculum that does not read it is refused
(:func:`check_selector_flags`)."""
FINE_TUNING_HELP = _PRESETS.FINE_TUNING_HELP
"""The fine-tuning flags, shared with ``curriculum``."""
PHRASES = {"selectors": ", ".join(common.SELECTOR_NAMES), "scope": ""}
"""What ``learn``'s help texts (``jaxterrain.curriculum.presets.HELP``) leave to the command line."""

ARGPARSE = {"curriculum": {"type": common.selector_name, "metavar": "NAME"}, "robot": {"metavar": "NAME"},
            "terrains": {"metavar": "DIR"}, "terrain_height": {"type": float, "metavar": "M"},
            "randomise": {"metavar": "SPEC"}, "accel_generator": {"metavar": "NAME"}}
"""What argparse is given beyond what the declaration says (``cli_gen.add_flags``' ``argparse_kwargs``)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    common.add_run_arguments(parser, PRESETS, "smoke")
    common.add_devices_argument(parser)  # the trials are split over the devices (curriculum.make_runner)
    cli_gen.add_flags(parser, PRESETS, RULES, _PRESETS.HELP, ARGPARSE, phrases=PHRASES)
    common.add_deprecated_alias(parser, "--freeze-normaliser", "--no-update-normaliser", "update_normaliser",
                                const=False)
    parser.add_argument("--export-policies", action="store_true",
                        help="with --resume: write every trial's walker of the last checkpoint as policies/trial_K/ "
                             "(for runs made before learn wrote them, or stopped by a time limit), and stop")
    parser.add_argument("--report", action="store_true",
                        help="with --resume: write the outputs of the last checkpoint (history, sequences, "
                             "milestones, curve, summary_partial.json) without training, and stop")
    common.add_protocol_argument(parser)
    common.add_progress_argument(parser)


def flags_in(text: str, selector: str) -> str:
    """A library message with its fields (``LearnConfig.<path>``: ``jaxterrain.curriculum.run_config``) named as
    this command's flags (``common.flags_in`` over ``run_config.FLAT_FIELDS`` and the selector's params' flat keys):
    ``LearnConfig.curriculum.threshold`` -> ``--threshold``, ``LearnConfig.walker.backend`` -> ``--backend``, a
    selector's ``LearnConfig.curriculum.params.capacity`` -> ``--plr-capacity``, ``LearnConfig.curriculum.ppo`` ->
    :data:`UPDATE_SHAPE`."""
    from jaxterrain.curriculum import run_config, selectors

    try:
        params = selectors.selector_spec(selector).flat
    except ValueError:
        params = {}
    fields = {**run_config.FLAT_FIELDS, **{k: f"curriculum.params.{f}" for k, f in params.items()}}
    typed = common.Typed("LearnConfig", fields, run_config.from_flat, run_config.to_flat)
    return common.flags_in(text, typed, lambda key: UPDATE_SHAPE if key == "ppo" else common.flag(key))


def run_of(cfg: dict):
    """The typed run (``run_config.from_flat``) of a flat config; :class:`~experiments.common.UsageError` naming
    the keys it does not know."""
    from jaxterrain.curriculum import run_config

    try:
        return run_config.from_flat(cfg)
    except (ValueError, TypeError) as err:
        raise common.UsageError(str(err)) from None


def selector_overrides(args) -> dict:
    """The per-env curricula's flags as given (None: not given)."""
    return cli_gen.given(args, SELECTOR_HELP)


def check_selector_flags(args, curricula, option: str = "--curriculum") -> None:
    """A curriculum's own flag (``--plr-capacity``, ``--levels``, ...: ``CurriculumConfig.SELECTOR_FIELDS``) given
    on the command line must belong to one of ``curricula`` (the run's built-in selectors), else it would be
    accepted and ignored: :class:`~experiments.common.UsageError` naming the curricula it belongs to. Only flags the
    user typed count (a preset or ``--config`` sets every key); a registered or ``module:object`` curriculum may
    read any field, so with one nothing is refused."""
    from jaxterrain.curriculum.config import SELECTOR_FIELDS, SELECTORS

    if any(c not in SELECTORS for c in curricula):
        return
    for key, value in selector_overrides(args).items():
        owners = SELECTOR_FIELDS.get(key, ())
        if value is not None and owners and not set(owners) & set(curricula):
            raise common.UsageError(f"{common.flag(key)} belongs to {option} {' or '.join(owners)}; this run's "
                                    f"{'curricula are' if len(curricula) > 1 else option + ' is'} "
                                    f"{', '.join(curricula)}")


def fine_tuning_overrides(args) -> dict:
    """The config values of the fine-tuning flags (None = not given); ``--recipe NAME`` sets ``recipe`` and the
    update's shape (``num_envs``, ``unroll_length``, ``num_unrolls``, ``num_minibatches``, ``update_epochs``:
    ``jaxterrain.curriculum.RECIPES[NAME]``)."""
    out = cli_gen.given(args, FINE_TUNING_HELP)
    if args.recipe is not None:
        from jaxterrain.curriculum.config import recipe

        out.update(recipe(args.recipe))
    return out


def overrides(args) -> dict:
    """The config values given on the command line (None: not given): every generated flag's, ``--recipe``'s
    update shape (``--num-envs`` over its envs), ``--protocol``'s walks, and the curriculum ``dr`` by default with
    ``--terrains``."""
    out = {**cli_gen.given(args, _PRESETS.HELP), **fine_tuning_overrides(args), **common.protocol_overrides(args)}
    if args.num_envs is not None:  # --num-envs over --recipe's envs
        out["num_envs"] = args.num_envs
    out["curriculum"] = args.curriculum or ("dr" if args.terrains is not None else None)
    return out


def check_scan_lr(cfg: dict) -> None:
    """``--scan-lr-scale`` other than 1 on a blind walker (the start policy's observation set: ``--observation``, a
    ``--policy``'s, or the blind base policy) would be accepted and ignored: refused before the run folder is made
    (``runner.check_scan_lr``); :class:`~experiments.common.UsageError` naming the flag."""
    if cfg.get("scan_lr_scale", 1.0) == 1.0:
        return
    from jaxterrain.curriculum import runner

    run = run_of(cfg)
    try:
        runner.check_scan_lr(run, runner.start_policy(run))
    except runner.BadInput as err:
        raise common.UsageError(flags_in(str(err), run.curriculum.selector)) from None


def check_terrain_flags(args, cfg: dict) -> None:
    """``--terrains DIR`` read and checked before the run folder is made (``own_terrains.check_terrains``: the
    folder and its files, the height, the order, a curriculum that needs no archive), and not given with
    ``--archive``; :class:`~experiments.common.UsageError` naming the flag."""
    from jaxterrain.curriculum import own_terrains

    if args.terrains is not None and args.archive is not None:
        raise common.UsageError("--terrains DIR trains on a folder of heightmaps instead of --archive: give one")
    try:
        own_terrains.check_terrains(run_of(cfg))
    except ValueError as err:
        raise common.UsageError(flags_in(str(err), cfg.get("curriculum") or "map")) from None


def report(summary: dict | None, folder) -> int:
    """``--report``'s line (``runner.report_treatment``'s summary; None: no checkpoint yet, exit 2)."""
    if summary is None:
        print(f"learn: {folder} has no checkpoint yet: nothing to report", file=sys.stderr)
        return 2
    state = f"partial, {summary['chunks_done']} chunks" if summary.get("partial") else "finished"
    print(f"report ({state}): hardest traversed {summary['hardest_mean']:.2f} +- {summary['hardest_se']:.2f} "
          f"cells -> {folder}", flush=True)
    return 0


def main(args) -> int:
    from jaxterrain.curriculum import runner

    if args.report and args.resume is None:
        raise common.UsageError("--report needs --resume RUN (the run to report on)")
    if args.export_policies and args.resume is None:
        raise common.UsageError("--export-policies needs --resume RUN (the run whose walkers to write)")
    if args.export_policies and args.report:
        raise common.UsageError("--export-policies and --report each write from the last checkpoint and stop; give "
                                "one of them")
    if args.export_policies or args.report:
        common.refuse_given({"--time-limit": args.time_limit, "--devices": args.devices},
                            f"{'--report' if args.report else '--export-policies'} trains nothing: drop one of them")
    mesh = common.device_mesh(args.devices)
    folder, cfg = common.setup_run("learn", args, PRESETS, "smoke", overrides(args), rules=RULES,
                                   check=lambda c: (check_selector_flags(args, [c["curriculum"]]), run_of(c),
                                                    check_terrain_flags(args, c), check_scan_lr(c)))
    run = run_of(cfg)
    try:  # the library validates the run once, before anything compiles (runner.validate)
        if args.export_policies:
            paths = runner.export_treatment(run, folder)
            print(f"wrote {len(paths)} policies -> {folder / 'policies'}", flush=True)
            return 0
        if args.report:
            return report(runner.report_treatment(run, folder), folder)
        limit = None if args.time_limit is None else 60.0 * args.time_limit
        summary = runner.run_treatment(run, folder, limit, mesh=mesh, progress=common.progress_mode(args))
    except runner.BadInput as err:
        print(f"learn: {flags_in(str(err), run.curriculum.selector)}", file=sys.stderr)
        if args.resume is None and {p.name for p in folder.iterdir()} <= {common.CONFIG_NAME,
                                                                          common.PROVENANCE_NAME}:
            shutil.rmtree(folder)  # nothing of a run in it yet
        return 2
    if summary is None:
        print(f"time limit reached; continue with: python -m experiments learn --resume {folder}", flush=True)
        return 3
    of = (f"rank (of {summary['bank_terrains'] - 1}, the hardest of the terrains)" if run.terrains else
          "cells (of 70.71)")
    print(f"done: hardest traversed {summary['hardest_mean']:.2f} +- {summary['hardest_se']:.2f} {of} after "
          f"{summary['epochs_max']} epochs -> {folder}; walkers in {folder / 'policies'}", flush=True)
    return 0
