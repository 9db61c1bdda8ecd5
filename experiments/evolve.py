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
run writes ``shares.*`` too (above).

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
import csv
from pathlib import Path

from experiments import common

_PAPER = dict(generator="perlin", descriptors=["roughness", "tpi"], generations=5000, batch_size=20,
              initial_population=100, bins=50, size=256, window=30, stride=2, attempts=20, best=5, headings=1,
              checkpoint_every=250, fitness="difficulty", robot_height=None, out_of_range="clip", ranges=None,
              store_heightmaps=True, rollout_slots=None, rollout_backend="jax", robot="humanoid",
              observation="blind", mix=None, fresh=1)
MIX_DEFAULT = ("perlin", "worley", "diamond_square", "cppn", "gan", "steps")
"""``--generator mixed``'s generators by default: the six built-in ones (``jaxterrain.generators.BUILTIN``)."""
PRESETS: dict[str, dict] = {
    "paper": _PAPER,
    "gpu": {**_PAPER, "generations": 25, "batch_size": 4000, "checkpoint_every": 1, "rollout_slots": 16384,
            "fresh": 64},
    "gpu-short": {**_PAPER, "generations": 5, "batch_size": 2000, "checkpoint_every": 1, "store_heightmaps": False,
                  "rollout_slots": 8192, "fresh": 32},
    "smoke": {**_PAPER, "generations": 4, "batch_size": 8, "initial_population": 16, "bins": 10, "size": 32,
              "window": 8, "attempts": 2, "best": 1, "checkpoint_every": 2, "fitness": "slope",
              "ranges": [[0.0, 0.5], [-0.02, 0.02]]},
}


def preset_config(name: str):
    """The :class:`jaxterrain.qd.EvolveConfig` of a preset."""
    return evolve_config(PRESETS[name])


def _backend(name: str) -> str:
    """``--backend auto`` -> the physics ``jaxterrain.walker.resolve_backend`` picks on this machine."""
    if name != "auto":
        return str(name)
    from jaxterrain.walker import resolve_backend

    return resolve_backend("auto")


def evolve_config(cfg: dict):
    from jaxterrain.qd import EvolveConfig

    ranges = cfg.get("ranges")
    return EvolveConfig(
        generations=int(cfg["generations"]), batch_size=int(cfg["batch_size"]),
        initial_population=int(cfg["initial_population"]), bins=int(cfg["bins"]),
        descriptors=tuple(cfg["descriptors"]),
        ranges=None if ranges is None else tuple(tuple(map(float, r)) for r in ranges),
        window=int(cfg["window"]), stride=int(cfg["stride"]), attempts=int(cfg["attempts"]), best=int(cfg["best"]),
        headings=int(cfg.get("headings", 1)), checkpoint_every=int(cfg["checkpoint_every"]), robot_height=cfg.get("robot_height"),
        out_of_range=cfg.get("out_of_range", "clip"), store_heightmaps=bool(cfg.get("store_heightmaps", True)),
        rollout_slots=None if cfg.get("rollout_slots") is None else int(cfg["rollout_slots"]),
        rollout_backend=_backend(cfg.get("rollout_backend", "jax")), robot=str(cfg.get("robot") or "humanoid"),
        observation=str(cfg.get("observation") or "blind"),
    )


def add_arguments(parser: argparse.ArgumentParser) -> None:
    common.add_run_arguments(parser, PRESETS, "smoke")
    common.add_devices_argument(parser)
    parser.add_argument("--generator", default=None,
                        help="registered generator name (default perlin), or mixed: one archive whose offspring of "
                             "every --mix generator compete for the cells, each elite recording its generator")
    parser.add_argument("--mix", nargs="+", default=None, metavar="NAME",
                        help=f"with --generator mixed: the generators of the mixture (default: all six, "
                             f"{' '.join(MIX_DEFAULT)})")
    parser.add_argument("--fresh", type=int, default=None,
                        help="with --generator mixed: fresh random genomes of EACH generator among every "
                             "generation's offspring, so that a generator holding no cell keeps competing (presets: "
                             "1, gpu-short 32, gpu 64)")
    parser.add_argument("--descriptors", nargs=2, default=None, metavar=("D0", "D1"),
                        help="descriptor pair, e.g. roughness tpi")
    parser.add_argument("--generations", type=int, default=None,
                        help="MAP-Elites generations after the initial population")
    parser.add_argument("--batch-size", type=int, default=None, help="offspring per generation")
    parser.add_argument("--initial-population", type=int, default=None, help="random genomes evaluated first")
    parser.add_argument("--bins", type=int, default=None, help="cells per descriptor")
    parser.add_argument("--size", type=int, default=None, help="heightmap side in pixels")
    parser.add_argument("--checkpoint-every", type=int, default=None, help="generations between checkpoints")
    parser.add_argument("--fitness", choices=common.FITNESS_NAMES, default=None,
                        help="what an elite's fitness measures: difficulty (the base policy walks it) or slope (a "
                             "cheap stand-in, no walking)")
    parser.add_argument("--attempts", type=int, default=None, help="walks per terrain in total")
    parser.add_argument("--best", type=int, default=None, help="best walks averaged per heading")
    parser.add_argument("--headings", type=int, choices=(1, 2, 4), default=None,
                        help="headings of the walks (1: the paper's +x; 4: +x, +y, -x, -y; mean over headings)")
    common.add_protocol_argument(parser)
    common.add_slots_argument(parser, "rollout_slots", "per device (default: all walks of a generation at once)")
    common.add_backend_argument(parser, "walker physics of the difficulty rollouts", dest="rollout_backend")
    common.add_deprecated_alias(parser, "--rollout-backend", "--backend", "rollout_backend",
                                choices=common.BACKEND_NAMES)
    parser.add_argument("--robot", default=None, metavar="NAME",
                        help="whose shipped base policy the walker fitness walks (default humanoid; "
                             "jaxterrain.walker.robots, or a --plugin's); the archive records it")
    parser.add_argument("--observation", choices=("blind", "perceptive"), default=None,
                        help="which of the robot's shipped base policies the walker fitness walks: blind (default, "
                             "the paper's) or perceptive (with a height scan); the archive records it")
    parser.add_argument("--store-heightmaps", action=argparse.BooleanOptionalAction, default=None,
                        help="store the elites' heightmaps in archive.npz (--no-store-heightmaps: leave them out, "
                             "they can be re-rendered from the genomes)")
    common.add_deprecated_alias(parser, "--no-heightmaps", "--no-store-heightmaps", "store_heightmaps", const=False)


def overrides(args) -> dict:
    return dict(generator=args.generator, descriptors=args.descriptors, generations=args.generations,
                batch_size=args.batch_size, initial_population=args.initial_population, bins=args.bins,
                size=args.size, checkpoint_every=args.checkpoint_every, fitness=args.fitness,
                **common.protocol_overrides(args), store_heightmaps=args.store_heightmaps,
                rollout_slots=args.rollout_slots, rollout_backend=args.rollout_backend, robot=args.robot,
                observation=args.observation, mix=args.mix, fresh=args.fresh)


def announce_compile(cfg: dict, config) -> None:
    """Say what the first generations compile and about how long that takes here (``jaxterrain.runtime.estimates``);
    generation 0 (the initial population) and 1 (the first offspring batch) each compile."""
    from jaxterrain.runtime.estimates import announce

    walks = cfg.get("fitness") == "difficulty"
    announce("map-elites" if walks else "map-elites-slope",
             f"{config.batch_size} offspring" + (f", {config.rollout_backend} physics" if walks else ""))


def run_treatment(cfg: dict, generator: str, descriptors, folder: Path, clock: common.Clock, key, label: str = "",
                  mesh=None):
    """Evolve one archive into ``folder`` (checkpointed there); returns the Archive, or the saved one if done.
    ``mesh``: the devices each generation's offspring are split over (``qd.evolve``)."""
    from jaxterrain import qd as A

    folder = Path(folder)
    done_path = folder / "archive.npz"
    if done_path.exists():
        print(f"{label}{generator} {descriptors}: already done ({done_path})", flush=True)
        return A.load(done_path)
    config = evolve_config({**cfg, "descriptors": list(descriptors)})
    fitness = fitness_fn(cfg["fitness"])
    announce_compile(cfg, config)
    printer = A.progress_printer(label + generator)
    if generator == "mixed":
        generator = mixture_of(cfg)

    def progress(info):
        printer(info)
        if info.get("generation", 0) < info.get("generations", 0):  # the last chunk goes on to save the archive
            clock.check()

    arch = A.evolve(generator, None, config, key, fitness_fn=fitness, checkpoint_dir=folder / "checkpoint",
                    progress=progress, generator_options={"size": int(cfg["size"])}, mesh=mesh)
    A.save(done_path, arch)
    write_metrics_csv(folder / "metrics.csv", arch.metrics)
    return arch


def mixture_of(cfg: dict):
    """The ``jaxterrain.generators.mixture`` of a ``--generator mixed`` config (its ``mix``, ``fresh`` and ``size``)."""
    from jaxterrain import generators

    return generators.mixture(tuple(cfg.get("mix") or MIX_DEFAULT), fresh=int(cfg.get("fresh", 1)),
                              size=int(cfg["size"]))


def check_mixed(args, cfg: dict) -> None:
    """``--mix`` / ``--fresh`` only with ``--generator mixed``; a mixture of two or more distinct generators whose
    fresh samples leave room for mutated offspring (``batch_size > fresh x generators``);
    :class:`~experiments.common.UsageError`."""
    if cfg.get("generator") != "mixed":
        for flag, value in (("--mix", args.mix), ("--fresh", args.fresh)):
            if value is not None:
                raise common.UsageError(f"{flag}: only with --generator mixed (this run's generator is "
                                        f"{cfg.get('generator')!r})")
        return
    names = list(cfg.get("mix") or MIX_DEFAULT)
    if len(names) < 2 or len(set(names)) != len(names):
        raise common.UsageError(f"--mix: two or more distinct generator names; got {' '.join(names)}")
    from jaxterrain import generators

    for name in names:  # the default six are not checked by common.check_values: e.g. diamond-square's sizes
        try:
            generators.get(name, size=int(cfg["size"]))
        except (ValueError, OSError) as err:
            raise common.UsageError(f"--size {cfg['size']} does not suit generator {name!r} of --generator mixed: "
                                    f"{str(err).splitlines()[0]}") from None
    need = int(cfg.get("fresh", 1)) * len(names)
    if int(cfg["batch_size"]) <= need:
        raise common.UsageError(f"--batch-size must be > {need} with --generator mixed (--fresh {cfg.get('fresh', 1)} "
                                f"of each of {len(names)} generators); got {cfg['batch_size']}")


def check_robot_walks(args, cfg: dict) -> None:
    """``--robot`` only with a fitness that walks a robot (``difficulty``, the walker's): with ``slope`` it would
    be recorded in the archive yet walk nothing; :class:`~experiments.common.UsageError`."""
    if args.robot is not None and cfg.get("fitness") != "difficulty":
        raise common.UsageError(f"--robot {args.robot}: only the walker fitness walks a robot (--fitness difficulty); "
                                f"this run's fitness is {cfg.get('fitness')!r}, which walks none")
    if args.observation is not None and cfg.get("fitness") != "difficulty":
        raise common.UsageError(f"--observation {args.observation}: only the walker fitness walks a policy "
                                f"(--fitness difficulty); this run's fitness is {cfg.get('fitness')!r}")


def fitness_fn(name: str):
    """The ``fitness_fn`` of ``qd.evolve`` for ``--fitness NAME``: ``jaxterrain.difficulty.FITNESSES[name]``, where None (the
    walker, ``"difficulty"``) lets ``qd.evolve`` build it from the config (attempts, best, rollout slots and
    the ONE scale that Algorithm 1 uses too)."""
    return common.fitness_of(name)


def write_metrics_csv(path: Path, metrics: dict) -> None:
    import io

    from jaxterrain.runtime.io import atomic_write_text

    names = sorted(metrics)
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["generation", *names])
    for g in range(len(metrics[names[0]]) if names else 0):
        w.writerow([g, *(f"{float(metrics[n][g]):.6g}" for n in names)])
    atomic_write_text(path, buf.getvalue())


def plot_archive(ax, arch, title: str = ""):
    """Draw an archive's fitness grid on a matplotlib axis (darker = fitter, like the paper's Figure 6)."""
    from jaxterrain import qd as A

    (lo0, hi0), (lo1, hi1) = arch.config.ranges
    img = ax.imshow(A.fitness_grid(arch), origin="lower", extent=(lo0, hi0, lo1, hi1), aspect="auto",
                    cmap="viridis_r", vmin=0.0, vmax=1.0, interpolation="nearest")
    ax.set_xlabel(arch.config.descriptors[0])
    ax.set_ylabel(arch.config.descriptors[1])
    ax.set_title(title or f"{'+'.join(arch.generator_names)}: {A.coverage(arch):.2f}%", fontsize=8)
    return img


def main(args) -> int:
    import jax
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jaxterrain import qd as A

    mesh = common.device_mesh(args.devices)
    fitness = args.fitness or PRESETS.get(args.preset or "smoke", {}).get("fitness")
    if args.robot is not None or args.observation is not None:  # before the run folder: one line (its base policy
        from jaxterrain import difficulty  # only where the fitness walks)
        from jaxterrain.walker import robots

        try:
            robots.get(args.robot or "humanoid")
        except ValueError as err:
            raise common.UsageError(f"--robot: {err}") from None
        try:
            if fitness == "difficulty":
                difficulty.robot_base_policy(args.robot or "humanoid", args.observation or "blind")
        except ValueError as err:
            raise common.UsageError(f"--{'observation' if args.observation else 'robot'}: {err}") from None
    if fitness == "difficulty":  # the walker fitness needs terrains the robot has a track on (its margins)
        from jaxterrain.walker import WalkerConfig, min_terrain_side

        cfg0 = common.preset_with_flags(PRESETS, args, overrides(args))
        robot = cfg0.get("robot") or "humanoid"
        need = min_terrain_side(WalkerConfig(robot=robot))
        if cfg0.get("size") is not None and int(cfg0["size"]) < need:
            raise common.UsageError(f"--size must be >= {need} pixels for the walker fitness of robot {robot} (its "
                                    f"episode margins at 4 cm a pixel); got {cfg0['size']}")
    def check(c):
        check_robot_walks(args, c)
        check_mixed(args, c)

    folder, cfg = common.setup_run("evolve", args, PRESETS, "smoke", overrides(args), check=check)
    clock = common.Clock(args.time_limit)
    try:
        arch = run_treatment(cfg, cfg["generator"], cfg["descriptors"], folder, clock, jax.random.key(cfg["seed"]),
                             mesh=mesh)
    except common.TimeUp:
        print(f"time limit reached; continue with: python -m experiments evolve --resume {folder}", flush=True)
        return 3
    fig, ax = plt.subplots(figsize=(4, 3.5))
    fig.colorbar(plot_archive(ax, arch), ax=ax, label="fitness")
    fig.tight_layout()
    common.save_figure(fig, folder / "archive.png", dpi=120)
    if cfg["generator"] == "mixed":
        from experiments import shares

        mix = mixture_of(cfg).spec
        shares.write_all(folder, {"mixed": arch}, 10.0, f"{len(mix.names)} generators, fresh {mix.fresh}, preset "
                                                        f"{cfg.get('preset')}")
    print(f"done: coverage {A.coverage(arch):.2f}%  qd {A.qd_score(arch):.2f}  "
          f"rejected by Algorithm 1: {int(arch.metrics['rejected'].sum())}  -> {folder}", flush=True)
    return 0
