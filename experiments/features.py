"""``python -m experiments features``: Experiment 1a (paper Figure 4), feature alignment with difficulty.

For each generator (default CPPN and Perlin) it renders random genomes and chains of mutated ones (so that the
terrains span easy to hard), computes TRI, TPI and roughness at several windows (default 5, 10, 20, 30, 40; stride
2), any extra registered descriptor (e.g. a learned traversability model, when registered in ``jaxterrain.features``)
and the ground-truth difficulty (1 - fitness of the walker's base policy; ``--fitness slope`` for a cheap stand-in),
then the Pearson correlation matrix of all of them. The presets add the learned ``traversability`` descriptor
(:mod:`jaxterrain.features.learned`, the paper's fourth feature).

Writes into the run folder: ``config.json``, ``values_<generator>.csv`` (one row per terrain), ``correlations.csv``
(generator, feature_a, feature_b, r), ``correlation_<generator>.png`` (heatmaps like Figure 4) and
``correlations.png`` (both side by side), ``figure4.png`` / ``figure4.csv`` (Figure 4: TRI, TPI and roughness at
``figure_window``, the extra descriptors and difficulty, one heatmap per generator), plus with ``--calibrate``
``ranges.json``: the [0.5, 99.5] percentile of each descriptor over all generators at the archive window (the
recipe of ``jaxterrain.qd.DEFAULT_RANGES``).

The work is :func:`jaxterrain.features.alignment.feature_alignment`'s; this command is its flags and files. Long
runs go through ``jaxterrain.runtime.driver.run_chunks``, one step per batch of ``batch`` terrains (generator after
generator): after every batch ``checkpoint.npz`` (the columns measured so far; the one before kept as
``checkpoint.prev.npz``), ``metrics.csv`` and TensorBoard events (``tb/``: the batch's mean difficulty and
traversable fraction) and a progress bar; ``--time-limit MIN`` stops after a batch (exit code 3) and ``--resume RUN``
continues from there with the same values.
"""

from __future__ import annotations

import argparse

from experiments import common

PRESETS: dict[str, dict] = common.with_preset_names({
    "paper": dict(generators=["cppn", "perlin"], samples=250, mutation_steps=4, size=256, windows=[5, 10, 20, 30, 40],
                  stride=2, fitness="difficulty", attempts=20, best=5, batch=50, extra_descriptors=["traversability"],
                  calibrate=False, calibrate_window=30, figure_window=30),
    "gpu": dict(generators=["cppn", "perlin"], samples=250, mutation_steps=4, size=256, windows=[5, 10, 20, 30, 40],
                stride=2, fitness="difficulty", attempts=20, best=5, batch=250, extra_descriptors=["traversability"],
                calibrate=False, calibrate_window=30, figure_window=30),
    "smoke": dict(generators=["cppn", "perlin"], samples=6, mutation_steps=1, size=48, windows=[5, 10],
                  stride=2, fitness="slope", attempts=2, best=1, batch=12, extra_descriptors=["traversability"],
                  calibrate=False, calibrate_window=10, figure_window=10),
}, {"gpu-short": ("gpu", {"samples": 25})})


def add_arguments(parser: argparse.ArgumentParser) -> None:
    common.add_run_arguments(parser, PRESETS, "smoke")
    parser.add_argument("--generators", nargs="+", default=None, help="generator names (default cppn perlin)")
    common.add_terrains_argument(parser, "samples", "random genomes, each also mutated --mutation-steps times "
                                            "(1 + mutation-steps terrains each)", aliases=("--samples",))
    parser.add_argument("--mutation-steps", type=int, default=None,
                        help="mutated descendants of each random genome, >= 0")
    parser.add_argument("--size", type=int, default=None, help="heightmap side in pixels")
    parser.add_argument("--windows", nargs="+", type=int, default=None,
                        help="window sides (pixels, >= 2) at which TRI / TPI / roughness are computed")
    parser.add_argument("--fitness", choices=common.FITNESS_NAMES, default=None,
                        help="what the features are correlated with: difficulty (the base policy walks each "
                             "terrain) or slope (a cheap stand-in, no walking)")
    parser.add_argument("--extra-descriptors", nargs="+", default=None, metavar="NAME",
                        help="registered descriptors measured besides TRI / TPI / roughness, at the first of --windows "
                             "(e.g. faces max_step traversability)")
    parser.add_argument("--calibrate", action=argparse.BooleanOptionalAction, default=None,
                        help="also measure descriptor ranges (see jaxterrain.qd.DEFAULT_RANGES)")
    common.add_progress_argument(parser)


def overrides(args) -> dict:
    return dict(generators=args.generators, samples=args.samples, mutation_steps=args.mutation_steps,
                size=args.size, windows=args.windows, fitness=args.fitness, extra_descriptors=args.extra_descriptors,
                calibrate=args.calibrate)


def settings_of(cfg: dict):
    """The library's ``AlignmentSettings`` of the run's settings ``cfg``."""
    from jaxterrain.features.alignment import AlignmentSettings

    return AlignmentSettings(
        generators=tuple(cfg["generators"]), samples=int(cfg["samples"]), mutation_steps=int(cfg["mutation_steps"]),
        size=int(cfg["size"]), windows=tuple(int(w) for w in cfg["windows"]), stride=int(cfg["stride"]),
        batch=int(cfg["batch"]), extra_descriptors=tuple(cfg.get("extra_descriptors") or ()),
        calibrate=bool(cfg.get("calibrate")), calibrate_window=int(cfg["calibrate_window"]),
        figure_window=int(cfg.get("figure_window") or 0),
        fitness_walks=int(cfg["attempts"]) if cfg["fitness"] == "difficulty" else 0)


def main(args) -> int:
    import jax

    from jaxterrain.difficulty import named_fitness
    from jaxterrain.features.alignment import feature_alignment

    folder, cfg = common.setup_resumable_run("features", args, PRESETS, "smoke", overrides(args))
    fitness_fn = jax.jit(named_fitness(cfg["fitness"], int(cfg["attempts"]), int(cfg["best"]), int(cfg["size"])))
    try:
        result = feature_alignment(settings_of(cfg), fitness_fn, int(cfg["seed"]), folder,
                                   resume=args.resume is not None,
                                   time_limit_s=None if args.time_limit is None else 60.0 * args.time_limit,
                                   progress=common.progress_mode(args), say=common.say)
    except ValueError as err:
        print(err, flush=True)
        return 1
    if result is None:
        print(f"time limit reached; continue with: python -m experiments features --resume {folder}", flush=True)
        return 3
    print(f"done -> {folder}", flush=True)
    return 0
