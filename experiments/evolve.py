"""``python -m experiments evolve``: one MAP-Elites archive for one generator and one descriptor pair.

Presets (``--preset``):

* ``paper``: the paper's treatment: 100 initial genomes + 5 000 generations x 20 offspring (100 100 evaluations),
  fitness from the walker (20 attempts, best 5), 256 x 256 terrains, 50 x 50 cells.
* ``gpu``: the same evaluation budget in larger batches (25 generations x 4 000 offspring), to fill a GPU; the
  80 000 rollouts of a generation run on a pool of 16 384 env slots (``rollout_slots``); a checkpoint after every
  generation (tens of seconds), so ``--time-limit`` stops close to its limit. A generation lasts as long
  as its longest walk (about 380 env steps), so a GPU needs thousands of terrains per generation to stay busy: on
  one H100, 1 000 offspring per generation gave 135 terrains/s at best (4 096 slots; 117 at 8 192, 91 at 16 384),
  which is 12.3 min for the budget; 25 x 4 000 took 9 min 37 s (``benchmarks/RESULTS.md``), both with the previous
  base policy under ``SOLVER_FAST``. Under the default ``SOLVER_SOUND`` the preset took 13.2 min on an H200 (150-160
  terrains/s), so it needs two 10-minute commands (``--time-limit`` then ``--resume``).
* ``gpu-short``: a tenth of that budget (100 + 5 generations x 2 000 offspring = 10 100 terrains, a checkpoint
  every generation, a pool of 8 192 slots, no elite heightmaps kept): one treatment in a few minutes, so that
  ``python -m experiments coverage --preset gpu-short`` gives all of Table 1 within a session's GPU time.
* ``smoke``: a tiny CPU run (32 x 32 terrains, 10 x 10 cells, cheap slope fitness), seconds.

``--generator mixed`` evolves ONE archive whose offspring of several generators (``--mix``, default all six)
compete for the same cells (``jaxterrain.generators.mixture``): parents are drawn uniformly over the filled cells and
mutated by their own generator, ``--fresh`` random genomes of each generator join every generation, all offspring
are scored by one fitness call, and each elite records its generator (``archive.npz`` is an ordinary archive of
several generators, like ``qd.combine``'s). ``initial_population`` is the run's total, in equal blocks per
generator. The run also writes ``shares.csv`` / ``shares.md`` / ``shares.png``: each generator's share of the cells
per distance band (``python -m experiments shares`` compares it with the combined archive of separate runs).

Writes into the run folder: ``config.json``, ``checkpoint/checkpoint.npz`` (every ``checkpoint_every`` generations),
``archive.npz`` (``jaxterrain.qd.save`` format), ``metrics.csv`` (one row per generation) and ``archive.png``.
Re-run with ``--config <run>/config.json``; continue a killed or time-limited run with ``--resume <run>``. A mixed
run writes ``shares.*`` too (above). This module is the command line only: the run is a
``jaxterrain.qd.run_config.EvolveRun`` (its presets there, ``config.json`` its flat form, ``--print-config`` its
printout), validated and evolved by ``jaxterrain.qd.runs.evolve_run``.

``--devices N`` (default: every visible device) splits each generation's offspring over N devices (render,
descriptors, Algorithm 1, walks; the repertoire replicated; ``jaxterrain.qd.evolution``): the same seed gives the same
archive on any N, and a run may resume on another N. ``rollout_slots`` is the pool of EACH device. Several hosts:
the same command in one process per host with the ``JAXTERRAIN_*`` variables (README, "Several devices").

Example (GPU machine, one 10-minute command at a time)::

    python -m experiments evolve --preset gpu --generator perlin --descriptors roughness tpi \\
        --out runs/evolve-perlin --time-limit 8
    python -m experiments evolve --resume runs/evolve-perlin --time-limit 8     # until it says "done"
"""

from __future__ import annotations

import argparse

from experiments import cli_gen, common

_CONFIG = common.library_file("qd.run_config")  # jaxterrain.qd.run_config, read without JAX
PRESETS: dict[str, dict] = _CONFIG.FLAT_PRESETS
"""The presets in their flat (``config.json``) form, defined in the library: ``jaxterrain.qd.run_config.PRESETS``."""
MIX_DEFAULT = _CONFIG.MIX_DEFAULT
TYPED = common.Typed("EvolveRun", _CONFIG.EVOLVE_FIELDS, _CONFIG.from_flat, _CONFIG.to_flat, _CONFIG.EVOLVE_RULES)



def add_arguments(parser: argparse.ArgumentParser) -> None:
    common.add_run_arguments(parser, PRESETS, "smoke")
    common.add_devices_argument(parser)
    cli_gen.add_typed_flags(parser, TYPED, PRESETS, _CONFIG.EVOLVE_HELP, {
        "mix": {"metavar": "NAME"}, "descriptors": {"nargs": 2, "metavar": ("D0", "D1")},
        "rollout_slots": {"metavar": "SLOTS"}, "robot": {"metavar": "NAME"}})
    common.add_protocol_argument(parser)
    common.add_deprecated_alias(parser, "--rollout-backend", "--backend", "rollout_backend",
                                choices=common.BACKEND_NAMES)
    common.add_deprecated_alias(parser, "--no-heightmaps", "--no-store-heightmaps", "store_heightmaps", const=False)


def overrides(args) -> dict:
    """The config values given on the command line (None: not given)."""
    return common.flag_values(args, TYPED)


def check_flags(args, run) -> None:
    """Flags that this run would accept and ignore: ``--mix`` / ``--fresh`` without ``--generator mixed``,
    ``--robot`` / ``--observation`` / ``--spawn`` and the walks' flags (``--protocol``, ``--attempts``, ``--best``,
    ``--headings``, ``--rollout-slots``, ``--backend``) with a fitness that walks no robot;
    :class:`~experiments.common.UsageError`."""
    if run.generator != "mixed":
        for flag, value in (("--mix", args.mix), ("--fresh", args.fresh)):
            if value is not None:
                raise common.UsageError(f"{flag}: only with --generator mixed (this run's generator is "
                                        f"{run.generator!r})")
    if run.fitness != "difficulty":
        if args.robot is not None:
            raise common.UsageError(f"--robot {args.robot}: only the walker fitness walks a robot (--fitness "
                                    f"difficulty); this run's fitness is {run.fitness!r}, which walks none")
        for flag, value in (("--observation", args.observation), ("--spawn", args.spawn)):
            if value is not None:
                raise common.UsageError(f"{flag} {value}: only the walker fitness walks a policy (--fitness "
                                        f"difficulty); this run's fitness is {run.fitness!r}")
        common.refuse_given({"--protocol": args.protocol, "--attempts": args.attempts, "--best": args.best,
                             "--headings": args.headings, "--rollout-slots": args.rollout_slots,
                             "--backend": args.rollout_backend},
                            f"sets the walks of the walker fitness (--fitness difficulty); this run's fitness is "
                            f"{run.fitness!r}, which walks none")


def main(args) -> int:
    from jaxterrain.qd import runs

    mesh = common.device_mesh(args.devices)
    folder, run = common.setup_typed("evolve", args, PRESETS, "smoke", TYPED, overrides(args), runs.validate_evolve,
                                     check=lambda r: check_flags(args, r))
    arch = runs.evolve_run(run, folder, common.minutes_to_seconds(args.time_limit), mesh=mesh)
    if arch is None:
        print(f"time limit reached; continue with: python -m experiments evolve --resume {folder}", flush=True)
        return 3
    print(f"done: {runs.summary_line(arch)}  -> {folder}", flush=True)
    return 0
