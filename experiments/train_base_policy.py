"""``python -m experiments train-base-policy``: train the flat-ground base walker with PPO (``jaxterrain.rl``).

The walker (``jaxterrain.walker.WalkerEnv``) learns on FLAT ground (an all-zero heightfield of the env's shape).
Presets:

- ``smoke``: CPU, seconds to a minute: a tiny heightfield, short episodes, tiny networks, a few updates. Checks the
  plumbing (training, checkpoints, resume, export, evaluation), not the walking.
- ``gpu``: the real run on one H100/H200: brax's MJX-humanoid PPO recipe (``PPOConfig()`` defaults: 3072 envs,
  122 880 env steps per update, see ``jaxterrain.rl.config``), the paper-sized env (``WalkerConfig()``: 256 x 256
  flat hfield, 1000-step episodes), 410 updates = 50.4 M env steps (``--env-steps``), stopping after the chunk in
  which ``--time-budget`` seconds (default 480, less a minute kept for the evaluation) pass. The loop is
  ``jaxterrain.runtime.driver.run_chunks``, as in ``evolve``: after every chunk of 10 updates it writes ``checkpoint.npz``
  (the whole PPO state, env states included, so a resumed run is bit-identical to an uninterrupted one),
  ``metrics.csv`` and TensorBoard events (``tb/``); a run stopped by its budget (or ``--time-limit MIN``) or
  killed (exit code 3 after a time-limit stop, as ``evolve``) continues with ``--resume RUN_DIR`` and the settings
  saved in its ``config.json`` (``jaxterrain.difficulty.run_config.EXTENDABLE``: ``--env-steps``, ``--time-budget``,
  ``--updates-per-chunk``, ``--eval-attempts`` and ``--eval-best`` given with it replace the saved ones).
  Measured on one H100 (2026-11-21) under the default solver (``SOLVER_SOUND``, Newton 4 / 16): ~140 k env
  steps/s, 50.4 M env steps in about 6.5 min over two commands (the first stopped by its budget at 46.7 M);
  best-5 / all-20 flat distance 1.00 / 0.98. Under ``--solver fast`` (brax's Newton 1 / 4) an H200 did ~315 k env
  steps/s, 50 M in 218 s, but that policy walks only under the fast solver (``jaxterrain.walker.SOLVER_SOUND``).

``--randomise SPEC`` trains under physics randomisation (``jaxterrain.walker.parse_randomisation``: friction, masses,
motors, observation noise, action delay, pushes, or ``legged-gym``); the policy records it in its ``walker_config``,
and ``eval.json`` walks the nominal physics. ``--spawn feet|patch`` sets how the walker is set down at a reset,
recorded with the policy too; on the flat ground it trains on, both rules set it down at the same height.

Writes into ``--out RUN_DIR``: ``config.json`` (the settings, as in every command: ``--config RUN/config.json``
re-runs them), ``run.json`` (the command lines that started and resumed it, the updates, the walker and PPO
configs), ``checkpoint.npz``, ``metrics.csv``, ``tb/``, ``policy/`` (``policy.msgpack`` + ``config.json``, loadable with
``jaxterrain.rl.load_policy``) and, once training is complete, ``eval.json``: the normalised distance of the
deterministic policy on flat ground over 20 attempts (random joint initialisations; ``jaxterrain.difficulty``'s
rollouts): mean of the best 5 and mean of all 20 (bar for shipping: >= 0.9 and >= 0.7). ``--export-assets`` copies
the policy to ``jaxterrain/assets/base_policy/`` with ``PROVENANCE.md`` (command, steps, commit, device, date, eval).

This module is the command line only: the run is a ``jaxterrain.difficulty.run_config.BasePolicyRun`` (its presets
there, ``config.json`` its flat form, ``--print-config`` its printout), validated and trained by
``jaxterrain.difficulty.base_policy.train_base_policy``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from experiments import cli_gen, common

_CONFIG = common.library_file("difficulty.run_config")  # jaxterrain.difficulty.run_config, read without JAX
PRESETS: dict[str, dict] = _CONFIG.FLAT_PRESETS
"""The presets in their flat (``config.json``) form, defined in the library:
``jaxterrain.difficulty.run_config.PRESETS``."""
EXTENDABLE = _CONFIG.EXTENDABLE
TYPED = common.Typed("BasePolicyRun", _CONFIG.FIELDS, _CONFIG.from_flat, _CONFIG.to_flat, _CONFIG.RULES)



def add_arguments(parser: argparse.ArgumentParser) -> None:
    common.add_run_arguments(parser, PRESETS, "smoke")
    common.add_devices_argument(parser)  # data parallel: envs split over the devices, gradients summed
    cli_gen.add_typed_flags(parser, TYPED, PRESETS, _CONFIG.HELP, {
        "time_budget": {"help": argparse.SUPPRESS}, "robot": {"metavar": "NAME"}, "scan_noise": {"metavar": "M"},
        "randomise": {"metavar": "SPEC"}})
    common.add_progress_argument(parser)
    parser.add_argument("--skip-eval", action="store_true",
                        help="skip the flat-ground evaluation of the trained walker at the end")
    parser.add_argument("--export-assets", action="store_true",
                        help="write the trained policy to --assets-dir with PROVENANCE.md")
    parser.add_argument("--assets-dir", default=None,
                        help="where --export-assets writes (default jaxterrain/assets/base_policy/; another robot's: "
                             "jaxterrain/assets/base_policy_ROBOT/)")


def overrides(args: argparse.Namespace) -> dict:
    """The config values given on the command line (None: not given)."""
    return common.flag_values(args, TYPED)


def command_line() -> str:
    """This process's command as ``python -m experiments train-base-policy ...``."""
    return "python -m experiments train-base-policy " + " ".join(sys.argv[2:] if sys.argv[1:2] == [
        "train-base-policy"] else sys.argv[1:])


def resume_command(command: str, run: Path) -> str:
    """``command`` without its ``--out`` / ``--resume [FOLDER]``, plus ``--resume run``: how to continue the run."""
    tokens, again = command.split(), []
    while tokens:
        tok = tokens.pop(0)
        if tok in ("--out", "--resume") and tokens and (tok == "--out" or not tokens[0].startswith("--")):
            tokens.pop(0)
        elif tok != "--resume" and not tok.startswith(("--out=", "--resume=")):
            again.append(tok)
    return f"{' '.join(again)} --resume {run}"


def check_flags(args: argparse.Namespace) -> None:
    """Flags that would be accepted and ignored: ``--assets-dir`` without ``--export-assets``, ``--eval-attempts`` /
    ``--eval-best`` with ``--skip-eval``; :class:`~experiments.common.UsageError`."""
    if not args.export_assets:
        common.refuse_given({"--assets-dir": args.assets_dir}, "where --export-assets writes; give --export-assets "
                                                               "too, or drop it")
    if args.skip_eval:
        common.refuse_given({"--eval-attempts": args.eval_attempts, "--eval-best": args.eval_best},
                            "sets the flat-ground evaluation, which --skip-eval skips: drop one of them")


def main(args: argparse.Namespace) -> int:
    """Resolve, validate, train (checkpointed, budgeted, resumable), save the policy, evaluate it, optionally export
    it: ``jaxterrain.difficulty.base_policy.train_base_policy``."""
    started = time.perf_counter()
    check_flags(args)
    from jaxterrain import rl
    from jaxterrain.difficulty import base_policy

    mesh = common.device_mesh(args.devices)
    folder, run = common.setup_typed("train-base-policy", args, PRESETS, "smoke", TYPED, overrides(args),
                                     lambda r: (base_policy.validate_base_run(r), r)[1], EXTENDABLE)
    export = None
    if args.export_assets:
        export = Path(args.assets_dir) if args.assets_dir else rl.base_policy_dir(run.walker.robot or "humanoid")
    command = command_line()
    try:
        result = base_policy.train_base_policy(run, folder, common.minutes_to_seconds(args.time_limit),
                                               resume=args.resume is not None, evaluate=not args.skip_eval,
                                               export_to=export, mesh=mesh, progress=args.progress,
                                               command_line=command, started=started)
    except base_policy.ResumeMismatch as err:  # run.json's walker / PPO configs are not the code's: resume with that
        raise SystemExit(f"--{err}") from None
    if result.stopped:
        print(f"time limit reached at {result.env_steps:,d} / {result.target_env_steps:,d} env steps "
              f"({time.perf_counter() - started:.0f} s); "
              f"continue with: {resume_command(command, folder)}", flush=True)
        return 3  # as evolve: stopped by the time limit, resumable
    return 0
