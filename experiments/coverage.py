"""``python -m experiments coverage``: Experiment 1b (paper Table 1, Figures 5 and 6).

Evolves one MAP-Elites archive per (descriptor pair, generator): the pairs TPI/TRI, roughness/TRI, roughness/TPI
x the generators (default: diamond_square, perlin, worley, gan, cppn), then the combined archive of each pair
(``jaxterrain.qd.combine``). A generator that cannot be built here (e.g. the GAN without trained weights) is
reported as skipped and left out of the combined archive.

Writes into the run folder:

* ``config.json``; ``archives/<generator>__<d0>-<d1>/`` with ``archive.npz``, ``metrics.csv`` and the checkpoint
  (a finished treatment is reused by ``--resume``); ``archives/combined__<d0>-<d1>.npz``;
* ``coverage.csv`` (generator, pair, coverage %, QD score, max / mean fitness, rejected by Algorithm 1) and
  ``coverage.md`` (Table 1: rows generators + Combined, columns the pairs; skipped generators listed);
* ``coverage.png`` (Figure 5: bars per generator and pair) and ``archives.png`` (Figure 6: one fitness heatmap per
  pair x generator, plus the combined archive).

Presets: ``paper`` and ``gpu`` (the paper's budget per treatment, see ``experiments/evolve.py``), ``gpu-short`` (a
tenth of it: all 15 treatments in about 15 x 3 GPU-minutes), ``paper-batched`` (the paper's 5 000 generations x 20
per treatment with every treatment at once: ``--batched``, below) and ``smoke`` (CPU, seconds).

``--batched`` evolves all treatments in one process at once (``jaxterrain.qd.evolve_many``): one jitted
generation mutates every treatment's 20 offspring and scores all 15 x 20 = 300 terrains with ONE walker call, so the
paper's deep lineages (5 000 mutations) cost 5 000 batched generations instead of 15 x 5 000 latency-bound ones. Its
checkpoint (all treatments) is ``batched/checkpoint.npz``; ``--resume`` continues it.

Several devices: ``--devices N`` (default: every visible device) splits each generation's offspring over N
devices in one process (``jaxterrain.qd.evolution``; with ``--batched``, the offspring of all treatments), so one
command uses every GPU of a host, or of several hosts (README, "Several devices"); the archives are the same for any
N. ``--shard I/N`` still runs only the treatments ``t % N == I`` of the fixed order of ``jaxterrain.qd.table1.treatments`` (every
treatment keeps the key it has in an unsharded run), to split Experiment 1b over independent jobs on the same run
folder; ``--resume`` without ``--shard`` then reuses the finished archives and writes the tables.

This module is the command line only: the run is a ``jaxterrain.qd.run_config.CoverageRun`` (its presets there,
``config.json`` its flat form, ``--print-config`` its printout), validated and run by
``jaxterrain.qd.table1.coverage_run``.
"""

from __future__ import annotations

import argparse

from experiments import cli_gen, common

_CONFIG = common.library_file("qd.run_config")  # jaxterrain.qd.run_config, read without JAX
PRESETS: dict[str, dict] = _CONFIG.COVERAGE_FLAT_PRESETS
"""The presets in their flat (``config.json``) form, defined in the library:
``jaxterrain.qd.run_config.COVERAGE_PRESETS``."""
GENERATORS = list(_CONFIG.GENERATORS)
TYPED = common.Typed("CoverageRun", _CONFIG.COVERAGE_FIELDS, _CONFIG.coverage_from_flat, _CONFIG.coverage_to_flat,
                     _CONFIG.COVERAGE_RULES)



def add_arguments(parser: argparse.ArgumentParser) -> None:
    common.add_run_arguments(parser, PRESETS, "smoke", {"paper-batched": "the paper's 5 000 generations of 20 per "
                                                                         "treatment, every treatment at once "
                                                                         "(--batched)"})
    common.add_devices_argument(parser)
    cli_gen.add_typed_flags(parser, TYPED, PRESETS, _CONFIG.COVERAGE_HELP)
    common.add_protocol_argument(parser)
    parser.add_argument("--shard", type=common.parse_shard, default=None, metavar="I/N",
                        help="run only the treatments t with t %% N == I (independent jobs sharing one --out; see "
                             "the module docstring); then --resume without --shard writes the tables")


def overrides(args) -> dict:
    """The config values given on the command line (None: not given)."""
    return common.flag_values(args, TYPED)


def check_shard(args, run) -> None:
    """``--shard`` splits the treatments over processes; ``--batched`` runs them all in one."""
    if run.batched and args.shard is not None:
        raise common.UsageError("--batched runs every treatment in one process; it cannot be combined with --shard")


def check_flags(args, run) -> None:
    """A new run's flags that it would accept and ignore: ``--shard`` with ``--batched`` (:func:`check_shard`),
    ``--protocol`` with a fitness that walks no robot; :class:`~experiments.common.UsageError`."""
    check_shard(args, run)
    if run.fitness != "difficulty":
        common.refuse_given({"--protocol": args.protocol}, f"sets the walks of the walker fitness (--fitness "
                                                            f"difficulty); this run's fitness is {run.fitness!r}, "
                                                            f"which walks none")


def main(args) -> int:
    from jaxterrain.qd import table1

    mesh = common.device_mesh(args.devices)
    folder, run = common.setup_typed("coverage", args, PRESETS, "smoke", TYPED, overrides(args),
                                     table1.validate_coverage, check=lambda r: check_flags(args, r))
    if args.resume is not None:  # a resumed run's --shard against its saved --batched, before anything compiles
        check_shard(args, run)
    result = table1.coverage_run(run, folder, common.minutes_to_seconds(args.time_limit), mesh=mesh, shard=args.shard)
    resume_hint = f"python -m experiments coverage --resume {folder}"
    if result is None:
        shard = "" if args.shard is None else f" --shard {args.shard[0]}/{args.shard[1]}"
        print(f"time limit reached; continue with: {resume_hint}{shard}", flush=True)
        return 3
    if args.shard is not None:
        print(f"shard {args.shard[0]}/{args.shard[1]} done ({result.done} of {result.total} treatments); once every "
              f"shard is done, write the tables with: {resume_hint}", flush=True)
        return 0
    print(f"done -> {folder}", flush=True)
    return 0
