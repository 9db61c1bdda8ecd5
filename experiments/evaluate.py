"""``python -m experiments evaluate``: walkers on terrains they never saw.

    python -m experiments evaluate --policy runs/learn-cppn/policies/trial_0 runs/learn-cppn/policies/trial_1 \\
        --preset gpu --out runs/eval-cppn
    python -m experiments evaluate --policy DIR --archive docs/results/exp2_cppn_headings_archive.npz

Walks the shipped base policy (always, as ``base``) and every ``--policy`` folder (``rl.save_policy``'s format, as
``learn`` writes ``policies/trial_K/``) on the held-out suite (``--suite v1``, ``jaxterrain.suite``: the field's
sub-terrains at 10 graded levels and fresh samples of every generator) or on an archive's elites (``--archive``,
family ``archive``, levels = bands of 7.07 cells of distance from cell (0, 0)) or on your own terrains
(``--terrains DIR``: a folder of PNG / GeoTIFF / .npy / .npz heightmaps, one family per file, one level, value its
relief in metres, each resized to ``--size``, by default 256 cells as ``learn --terrains`` trains on; smoke: 128;
``jaxterrain.suite.folder``, images at ``--terrain-height M`` metres of full grey), under
``--protocol`` (default
``headings``: 20 walks in each of 4 headings, best 5 per heading). Every policy walks with the same key. A policy for
another robot or observation set is refused with one line naming its folder, before the run folder is made.

``--suite v2`` holds the levels calibrated for the robot of ``--robot`` (default the humanoid; every ``--policy``
must walk that robot), 5 terrains per level and 40 fresh samples of each generator, whose worst decile (CVaR at
10 %) ``robustness.csv`` reports. ``--keys K`` walks the base policy with K independent evaluation keys (rows
``base``, ``base:key1``, ...), which ``generalise`` reads as K runs of the comparator.

Presets: ``gpu`` (suite v1 at 256 x 256, 3 terrains per level, the HEADINGS protocol; the base policy walks twice
and the second, compiled call is timed) and ``smoke`` (CPU, a few minutes: three families and Perlin samples built
at 128 x 128, one terrain per level, 2 walks along +x, best 1; not ``v1``'s terrains). A family whose features do
not fit the map at ``--size`` (a 64-pixel map has 0.26 m of ground inside its 1 m start strips: no trench of ``gaps``,
one step of ``stairs_up``) is dropped, said on stderr and in ``summary.md`` (``jaxterrain.suite.misfit``).

``--engine mujoco`` walks the same walkers on the same terrains with MuJoCo's C engine on the CPU cores
(``--workers`` processes, default every core) instead of MJX: the same starts (MJX's reset, the same key), policy,
observation, termination and protocol, another simulator (sim2sim; ``jaxterrain.difficulty.replay``,
``docs/results/sim2sim.md``). It takes no ``--backend`` other than jax, no ``--rollout-slots`` / ``--chunk``, and
refuses a suite whose walks could take more than 24 hours on its workers (at 1 000 env steps per second per core).

Writes into the run folder: ``config.json``, ``fitness.csv`` (policy, family, level, seed, value, unit, fitness),
``levels.csv`` (policy, family, the highest level passed with every level below it passed too, a level passing at
mean fitness >= 0.9, -1 for none, and the mean fitness per level), ``summary.md`` (policies x families, policies
labelled by their folders relative to a common parent, and the families dropped at this size), ``levels.png`` (the
same, coloured by the share of each family's levels passed),
``suite.png`` (a terrain of every family at its easiest, middle and hardest level) and ``timing.json``.

``--randomise SPEC`` walks every policy under randomised physics (``jaxterrain.walker.parse_randomisation``; every
policy meets the same draws; MJX only, without ``--videos``); by default the nominal physics, whatever a policy was
trained under.

``--videos`` (off by default) adds ``videos/<walker>/<family>_L<level>.gif``: each walker beside the base policy on
the terrains of ``--video-terrains`` (default: per family the hardest level the walker passes and the first it
fails), and ``videos/videos.csv`` (``jaxterrain.report.compare.write_videos``). GIF only (no MP4 writer is a
dependency). Without an OpenGL backend for MuJoCo's renderer one line says why and the evaluation is still written.
"""

from __future__ import annotations

import argparse
import sys

from experiments import common

PRESETS: dict[str, dict] = common.with_preset_names({
    "gpu": dict(suite="v1", archive=None, terrain_folder=None, terrain_height=None,
                policy=[], robot=None, observation=None, size=None, seeds=None, samples=None,
                families=None, generators=None, attempts=80, best=5, headings=4, backend="auto", slots=None, chunk=None,
                repeat=True, keys=1, videos=False, video_terrains=None, video_frames=75, video_width=320,
                video_height=240, video_starts=8, engine="mjx", workers=None, randomise=None),
    "smoke": dict(suite="v1", archive=None, terrain_folder=None, terrain_height=None,
                  policy=[], robot=None, observation=None, size=128, seeds=1, samples=4,
                  families=["flat", "stairs_up", "gaps"],
                  generators=["perlin"], attempts=2, best=1, headings=1, backend="jax", slots=None, chunk=None,
                  repeat=False, keys=1, videos=False, video_terrains=None, video_frames=75, video_width=320,
                  video_height=240, video_starts=8, engine="mjx", workers=None, randomise=None),
}, {"gpu-short": "gpu", "paper": ("gpu", {"attempts": 20, "best": 5, "headings": 1})})
BACKENDS = common.BACKEND_NAMES  # jaxterrain.walker.layout.BACKEND_CHOICES (literal: --help imports no JAX)
ENGINES = ("mjx", "mujoco")  # jaxterrain.difficulty.replay.ENGINES (literal: --help imports no JAX)
MUJOCO_STEPS_PER_CORE_S = 1000  # MuJoCo C humanoid env steps / s / core, measured (docs/results/sim2sim.md)
MUJOCO_MAX_HOURS = 24.0  # --engine mujoco refuses suites whose longest possible walk would take longer


def add_arguments(parser: argparse.ArgumentParser) -> None:
    common.add_run_arguments(parser, PRESETS, "smoke")
    parser.add_argument("--policy", nargs="+", default=None, metavar="DIR",
                        help="policy folders to evaluate beside the base policy (e.g. RUN/policies/trial_0)")
    parser.add_argument("--keys", type=int, default=None, metavar="K",
                        help="walk the base policy with K independent evaluation keys (rows base, base:key1, ..., "
                             "base:key{K-1}; key 0 is the one every --policy walks with): generalise reads them as "
                             "K runs of the comparator (give K = the treatments' trials)")
    parser.add_argument("--robot", default=None, metavar="NAME",
                        help="the base policy walked beside is this robot's shipped one (default humanoid); each "
                             "--policy walks the robot it was trained on")
    parser.add_argument("--observation", choices=("blind", "perceptive"), default=None,
                        help="the base policy walked beside: the robot's blind one (default, the paper's) or its "
                             "perceptive twin; each --policy walks with the observation set it records")
    parser.add_argument("--suite", default=None, help="held-out suite version (default v1; v2: levels calibrated "
                        "for the robot of --robot)")
    parser.add_argument("--archive", default=None, help="walk an archive's elites instead of the suite")
    parser.add_argument("--size", type=int, default=None, help="suite heightmap side in pixels (v1: 256)")
    parser.add_argument("--seeds", type=int, default=None, help="suite terrains per family level (v1: 3)")
    common.add_terrains_argument(parser, "samples", "the suite's generator terrains (v1: 96)", aliases=("--samples",),
                                 folder="walk your own terrains instead of the suite (.png, .tif/.tiff, .npy, .npz; "
                                        "jaxterrain.suite.folder), one family per file")
    parser.add_argument("--terrain-height", type=float, default=None, metavar="M",
                        help="--terrains DIR: metres of an image's full grey (default 1.0), and the relief every "
                             "metre file is rescaled to (default: its own metres), in (0, 1]")
    parser.add_argument("--families", nargs="+", default=None, help="suite families to build (default: all of the "
                        "version's; smoke: flat stairs_up gaps)")
    parser.add_argument("--generators", nargs="*", default=None, help="generators to sample (default: the version's "
                        "five; smoke: perlin)")
    parser.add_argument("--repeat", action=argparse.BooleanOptionalAction, default=None,
                        help="walk the base policy twice and time the second, compiled call (timing.json; default: "
                             "on in gpu, off in smoke)")
    parser.add_argument("--attempts", type=int, default=None, help="walks per terrain in total")
    parser.add_argument("--best", type=int, default=None, help="best walks averaged per heading")
    parser.add_argument("--headings", type=int, choices=(1, 2, 4), default=None, help="walking headings")
    common.add_protocol_argument(parser)
    common.add_backend_argument(parser)
    parser.add_argument("--engine", choices=ENGINES, default=None,
                        help="physics engine: mjx (default; MJX on the accelerator, --backend picks jax or warp) or "
                             "mujoco (MuJoCo's C engine on the CPU cores, the same starts and protocol: sim2sim)")
    parser.add_argument("--workers", type=int, default=None,
                        help="--engine mujoco: CPU processes walking (default: every core)")
    common.add_slots_argument(parser, "slots", "an int (default: all walks at once)", aliases=("--slots",))
    common.add_randomise_argument(parser, "every walk (a randomised protocol: every policy, the base policy "
                                          "included, meets the same draws; default: the nominal physics; MJX only)")
    parser.add_argument("--chunk", type=int, default=None, help="terrains per call (bounds device memory)")
    parser.add_argument("--videos", action=argparse.BooleanOptionalAction, default=None,
                        help="after the evaluation, GIFs of each --policy walker beside the base policy (the base "
                             "policy alone without --policy) on chosen terrains, one walk along +x each from the same "
                             "start (of --video-starts), into videos/<walker>/<family>_L<level>.gif with videos/videos.csv; GIF only "
                             "(Pillow: no MP4 writer is a dependency); needs an OpenGL backend for MuJoCo's renderer "
                             "(without one: a line saying why, the evaluation is still written)")
    parser.add_argument("--video-terrains", default=None, metavar="FAMILY:LEVEL,...",
                        help="terrains of the videos, e.g. slope_up:5,gen:perlin:3 (each level's seed-0 terrain); "
                             "default: per family the hardest level the walker passes and the first it fails")
    parser.add_argument("--video-frames", type=int, default=None,
                        help="most frames per video, evenly spaced over the longer walk, played at 15 a second "
                             "(a walk shorter than frames / 15 s gets fewer and plays in real time)")
    parser.add_argument("--video-starts", type=int, default=None,
                        help="reset poses each policy walks every video terrain from; the video shows the one the "
                             "walker went farthest from, the base policy from the same one")
    parser.add_argument("--video-width", type=int, default=None, help="pixels of each panel's width")
    parser.add_argument("--video-height", type=int, default=None, help="pixels of each panel's height")
    parser.add_argument("--gl", choices=("osmesa", "egl", "glfw"), default=None,
                        help="MuJoCo OpenGL backend of the videos (default: $MUJOCO_GL, else egl with an NVIDIA "
                             "GPU, else osmesa)")


def overrides(args) -> dict:
    return dict(policy=args.policy, robot=args.robot, observation=args.observation, keys=args.keys, suite=args.suite,
                archive=args.archive, size=args.size, seeds=args.seeds,
                samples=None if isinstance(args.samples, str) else args.samples,
                terrain_folder=args.samples if isinstance(args.samples, str) else None,
                terrain_height=args.terrain_height, families=args.families, generators=args.generators, repeat=args.repeat,
                backend=args.backend, slots=args.slots, chunk=args.chunk, videos=args.videos,
                video_terrains=args.video_terrains, video_frames=args.video_frames, video_width=args.video_width,
                video_height=args.video_height, video_starts=args.video_starts, engine=args.engine, workers=args.workers,
                randomise=args.randomise,
                **common.protocol_overrides(args))


def base_names(keys: int) -> list[str]:
    """The ``fitness.csv`` names of the base policy's ``keys`` evaluations: ``base`` (the key every policy walks
    with), then ``base:key1`` .. ``base:key{keys-1}`` (``jax.random.fold_in`` of that key by 1 .. keys-1)."""
    return ["base"] + [f"base:key{k}" for k in range(1, keys)]


def is_base(name: str) -> bool:
    """Whether a ``fitness.csv`` policy name is one of the base policy's evaluations (:func:`base_names`)."""
    return name == "base" or (name.startswith("base:key") and name[8:].isdigit())


def load_policies(paths, robot: str | None = None, observation: str | None = None) -> list:
    """The base policy of ``robot`` (default the humanoid's; ``observation``: its blind, default, or perceptive one)
    and every folder of ``paths``, loaded; UsageError naming a folder that does not load, an unknown robot or one
    without a shipped base policy."""
    from experiments.common import UsageError
    from jaxterrain import difficulty, rl

    try:
        out = [difficulty.robot_base_policy("humanoid" if robot is None else robot, observation or "blind")]
    except ValueError as err:
        raise UsageError(f"--{'observation' if observation else 'robot'}: {err}") from None
    for p in paths or []:
        try:
            out.append(rl.load_policy(p))
        except (OSError, ValueError) as err:
            raise UsageError(f"--policy {p}: {str(err).splitlines()[0]}") from None
    return out


def check_terrain_flags(cfg: dict) -> None:
    """UsageError naming the flag for an unknown suite or family, a size below 32 pixels or an archive that is
    missing or does not read (it is read again when walked)."""
    from pathlib import Path

    from experiments.common import UsageError
    from jaxterrain import suite

    if cfg["suite"] not in suite.VERSIONS:
        raise UsageError(f"--suite must be one of {', '.join(suite.VERSIONS)}; got {cfg['suite']!r}")
    unknown = [f for f in cfg["families"] or [] if f not in suite.FAMILIES]
    if unknown:
        raise UsageError(f"--families: unknown {', '.join(map(repr, unknown))}; choose from "
                         f"{', '.join(suite.FAMILIES)}")
    keys = cfg.get("keys", 1)
    if not isinstance(keys, int) or isinstance(keys, bool) or keys < 1:
        raise UsageError(f"--keys must be an integer >= 1; got {keys!r}")
    if cfg["size"] is not None and cfg["size"] < 32:
        raise UsageError(f"--size must be an integer >= 32 pixels; got {cfg['size']}")
    if cfg["archive"] and not Path(cfg["archive"]).is_file():
        raise UsageError(f"--archive {cfg['archive']}: no such file")
    if cfg["archive"]:
        from jaxterrain import qd

        try:
            qd.load(cfg["archive"])
        except (OSError, ValueError) as err:
            raise UsageError(f"--archive {cfg['archive']}: {str(err).splitlines()[0]}") from None
    if cfg.get("terrain_folder") and cfg["archive"]:
        raise UsageError("--terrains DIR walks a folder of heightmaps instead of --archive: give one")
    if cfg.get("terrain_height") is not None and not cfg.get("terrain_folder"):
        raise UsageError("--terrain-height applies to --terrains DIR (a folder of heightmaps), which is not given")
    if cfg.get("terrain_folder"):
        folder_suite(cfg)


def check_video_flags(cfg: dict) -> list | None:
    """The ``(family, level)`` pairs of ``--video-terrains`` (None: the default picks); UsageError naming the flag
    for a malformed list, a family this evaluation does not walk, a level the family lacks, ``--video-terrains``
    without ``--videos`` or a frame count / panel size out of range."""
    from experiments.common import UsageError
    from jaxterrain import suite
    from jaxterrain.report import compare

    for key, low in (("video_frames", 1), ("video_width", 16), ("video_height", 16), ("video_starts", 1)):
        v = cfg[key]
        if not isinstance(v, int) or isinstance(v, bool) or v < low or v > 4096:
            raise UsageError(f"--{key.replace('_', '-')} must be an integer in [{low}, 4096]; got {v!r}")
    if cfg["video_terrains"] is None:
        return None
    if not cfg["videos"]:
        raise UsageError("--video-terrains chooses the terrains of --videos, which is off: give --videos too")
    try:
        picks = compare.parse_picks(cfg["video_terrains"])
    except ValueError as err:
        raise UsageError(f"--video-{err}") from None
    if cfg["archive"]:
        levels = {"archive": suite.LEVELS}
    elif cfg.get("terrain_folder"):
        levels = {name: 1 for name in folder_suite(cfg).family}
    else:
        fams = cfg["families"] or suite.VERSIONS[cfg["suite"]]["families"]
        gens = suite.VERSIONS[cfg["suite"]]["generators"] if cfg["generators"] is None else cfg["generators"]
        levels = {**{f: suite.FAMILIES[f].levels for f in fams}, **{f"gen:{g}": suite.LEVELS for g in gens}}
    for fam, lv in picks:
        if fam not in levels:
            raise UsageError(f"--video-terrains: family {fam!r} is not walked here; choose from "
                             f"{', '.join(levels)}")
        if lv >= levels[fam]:
            raise UsageError(f"--video-terrains: {fam} has levels 0 to {levels[fam] - 1}; got {lv}")
    return picks


def fit_size(args, cfg0: dict, policies) -> int:
    """A terrain side every policy's robot can walk (``walker.min_terrain_side``): a ``--size`` below it is refused
    naming it; a preset's (smoke: 128 pixels) is raised to the next multiple of 32 that fits, said on stderr, and
    recorded in the run's config as if given (``args.size``). Returns a side the policies can be checked on: the
    size, or the robots' minimum where the suite's own size (None) or an archive's terrains are walked."""
    from experiments.common import UsageError
    from jaxterrain import difficulty
    from jaxterrain.walker import WalkerConfig, min_terrain_side

    size = cfg0["size"]
    robots = sorted({difficulty.policy_robot(p) for p in policies})
    need = max(min_terrain_side(WalkerConfig(robot=r)) for r in robots)
    if size is None or cfg0["archive"]:
        return need
    if size >= need:
        return size
    if args.size is not None:
        raise UsageError(f"--size must be >= {need} pixels for robot {', '.join(robots)} (its episode margins at "
                         f"4 cm a pixel); got {size}")
    args.size = cfg0["size"] = -(-need // 32) * 32
    print(f"evaluate: --size {args.size} (the {args.preset or 'smoke'} preset's {size} pixels are too small for robot "
          f"{', '.join(robots)})", file=sys.stderr)
    return args.size


def mujoco_workers(cfg: dict) -> int:
    """The CPU processes of ``--engine mujoco``: ``--workers``, else every core."""
    import os

    return int(cfg.get("workers") or os.cpu_count() or 1)


def check_engine(args, cfg: dict) -> None:
    """UsageError for flags that do not apply to the engine: ``--engine mujoco`` with an MJX ``--backend`` other than
    jax, ``--rollout-slots`` or ``--chunk`` (MJX's batching), a ``--workers`` below 1 or ``--randomise``; ``--workers``
    with MJX."""
    from experiments.common import UsageError

    if cfg.get("engine") == "mujoco":
        if args.backend not in (None, "jax"):
            raise UsageError(f"--backend {args.backend} is an MJX backend; --engine mujoco steps MuJoCo's C engine on "
                             "the CPU (drop --backend)")
        for flag, key in (("--rollout-slots", "slots"), ("--chunk", "chunk")):
            if cfg.get(key) is not None:
                raise UsageError(f"{flag} batches MJX's walks; --engine mujoco walks on CPU processes (--workers)")
        if cfg.get("workers") is not None and cfg["workers"] < 1:
            raise UsageError(f"--workers must be an integer >= 1; got {cfg['workers']}")
        if cfg.get("randomise") is not None:
            raise UsageError("--randomise randomises MJX's walks; --engine mujoco walks the nominal physics")
    elif args.workers is not None:
        raise UsageError("--workers sets the CPU processes of --engine mujoco; MJX walks on the accelerator")


def check_mujoco_cost(cfg: dict, terrains_n: int, policies_n: int) -> None:
    """UsageError when ``--engine mujoco``'s walks could take longer than :data:`MUJOCO_MAX_HOURS` on its workers,
    at :data:`MUJOCO_STEPS_PER_CORE_S` env steps per second per core with every walk lasting the episode."""
    from experiments.common import UsageError
    from jaxterrain.walker import WalkerConfig

    steps = policies_n * terrains_n * int(cfg["attempts"]) * WalkerConfig().episode_length
    hours = steps / (MUJOCO_STEPS_PER_CORE_S * mujoco_workers(cfg)) / 3600
    if hours > MUJOCO_MAX_HOURS:
        raise UsageError(f"--engine mujoco: {policies_n} policies x {terrains_n} terrains x {cfg['attempts']} walks "
                         f"could take up to {hours:.0f} h on {mujoco_workers(cfg)} CPU processes (more than "
                         f"{MUJOCO_MAX_HOURS:.0f} h): walk fewer terrains (--seeds, --samples, --families) or walks "
                         "(--attempts)")


def folder_suite(cfg: dict):
    """``--terrains DIR``'s folder as a suite, one family per file (``suite.folder_suite``); UsageError naming the
    flag and the file."""
    from experiments.common import UsageError
    from jaxterrain import suite

    try:
        side = cfg.get("size") or suite.TERRAIN_SIDE  # --size, else the curriculum's 256 cells
        return suite.folder_suite(suite.load_folder(cfg["terrain_folder"], cfg.get("terrain_height"), side))
    except ValueError as err:
        msg = str(err).replace("give a terrain height M", "give --terrain-height M")
        if msg.startswith("terrain height"):
            raise UsageError(f"--terrain-height{msg[len('terrain height'):]}") from None
        raise UsageError(f"--{msg}" if msg.startswith("terrains ") else f"--terrains: {msg}") from None


def terrains(cfg: dict):
    """The suite of the config, the archive's elites as a one-family suite, or a folder's terrains."""
    from experiments.common import UsageError
    from jaxterrain import qd, suite

    if cfg.get("terrain_folder"):
        return folder_suite(cfg)
    if cfg["archive"]:
        try:
            return suite.archive_suite(qd.load(cfg["archive"]))
        except (OSError, ValueError) as err:
            raise UsageError(f"--archive {cfg['archive']}: {str(err).splitlines()[0]}") from None
    try:
        robot = None if suite.VERSIONS[cfg["suite"]]["robot"] is None else (cfg.get("robot") or "humanoid")
        return suite.load(cfg["suite"], robot=robot, size=cfg["size"], seeds=cfg["seeds"], samples=cfg["samples"],
                          families=cfg["families"], generator_names=cfg["generators"])
    except ValueError as err:
        raise UsageError(f"--{str(err)}") from None


def main(args) -> int:
    import json
    import time

    import jax
    import numpy as np

    from jaxterrain import difficulty, suite
    from jaxterrain.runtime import provenance
    from jaxterrain.runtime.io import atomic_write_text
    from jaxterrain.terrain import TerrainScale
    from jaxterrain.walker import parse_randomisation, randomisation_label, resolve_backend

    cfg0 = common.preset_with_flags(PRESETS, args, overrides(args))
    check_engine(args, cfg0)
    policies = load_policies(cfg0["policy"], cfg0.get("robot"), cfg0.get("observation"))  # before the run folder: a bad folder is one line, nothing left behind
    check_terrain_flags(cfg0)
    own = cfg0["archive"] or cfg0.get("terrain_folder")  # an archive's or a folder's terrains, not the suite's
    if suite.VERSIONS[cfg0["suite"]]["robot"] is not None and not own:  # v2: levels per robot
        robot = cfg0.get("robot") or "humanoid"
        other = [str(getattr(p, "path", p)) for p in policies[1:] if difficulty.policy_robot(p) != robot]
        if other:
            raise common.UsageError(f"--suite {cfg0['suite']} holds the levels of robot {robot} (--robot); these "
                                    f"policies walk another robot: {', '.join(other)}")
    check_video_flags(cfg0)
    if cfg0["videos"] and cfg0.get("randomise") is not None:
        raise common.UsageError("--videos draws the walks under the nominal physics; evaluate --randomise without "
                                "--videos (and the videos in a run without it)")
    if cfg0["videos"]:  # before anything imports mujoco
        from jaxterrain.report import render

        render.setup_gl(args.gl)
    side = fit_size(args, cfg0, policies)
    try:  # another robot or observation set: refused before anything is built
        suite.check_policies(policies, (side, side), TerrainScale())
    except ValueError as err:
        raise common.UsageError(str(err)) from None
    t0 = time.perf_counter()
    s = None
    if cfg0["engine"] == "mujoco":  # the CPU engine's cost is checked on the terrains, before the run folder
        s = terrains(cfg0)
        check_mujoco_cost(cfg0, s.size, len(policies))
    folder, cfg = common.setup_run("evaluate", args, PRESETS, "smoke", overrides(args))
    n_keys = int(cfg.get("keys", 1))
    names = base_names(n_keys) + [str(p) for p in cfg["policy"]]
    terrain_keys = ("suite", "archive", "terrain_folder", "terrain_height", "size", "seeds", "samples", "families",
                    "generators")
    if s is None or any(cfg[k] != cfg0[k] for k in terrain_keys):
        s = terrains(cfg)
    build_s = time.perf_counter() - t0
    protocol = difficulty.Protocol(int(cfg["attempts"]), int(cfg["best"]), int(cfg["headings"]))
    engine = cfg.get("engine") or "mjx"
    backend = resolve_backend(cfg["backend"]) if engine == "mjx" else "jax"
    walk = dict(engine=engine, workers=mujoco_workers(cfg))
    randomised = parse_randomisation(cfg.get("randomise"))
    if cfg.get("randomise") is not None:
        walk["randomisation"] = randomised
    for fam, why in s.dropped.items():
        print(f"evaluate: family {fam} dropped at --size {cfg['size']}: {why}", file=sys.stderr)
    on = backend if engine == "mjx" else f"MuJoCo C ({walk['workers']} CPU processes)"
    print(f"{s.name}: {s.size} terrains, {len(s.families())} families; {len(policies)} policies on {on}, "
          f"{protocol.attempts} walks each (best {protocol.best} per heading, {protocol.headings} headings)"
          + (f", randomised physics: {randomisation_label(randomised)}" if "randomisation" in walk else ""), flush=True)
    key = jax.random.fold_in(jax.random.key(int(cfg["seed"])), 3)
    t1 = time.perf_counter()
    from jaxterrain.runtime.estimates import compiling

    with compiling("suite-walk", f"{s.size} terrains x {protocol.attempts} walks, {backend} physics"):
        first = suite.evaluate_policies(policies[:1], s.heightmaps, key, protocol, backend, s.scale, cfg["slots"],
                                        cfg["chunk"], **walk)
    first_s = time.perf_counter() - t1  # compile + walk of the base policy
    again, walk_s = None, None
    if cfg["repeat"]:  # the same walks again, compiled: one policy on the whole suite
        t2 = time.perf_counter()
        again = suite.evaluate_policies(policies[:1], s.heightmaps, key, protocol, backend, s.scale, cfg["slots"],
                                        cfg["chunk"], **walk)
        walk_s = time.perf_counter() - t2
    fitness = first
    for k in range(1, n_keys):  # the base policy again, with independent keys: runs of the comparator
        fitness = np.concatenate([fitness, suite.evaluate_policies(policies[:1], s.heightmaps, jax.random.fold_in(key, k),
                                                                   protocol, backend, s.scale, cfg["slots"],
                                                                   cfg["chunk"], **walk)])
    if len(policies) > 1:  # the other policies: the same compiled program, their weights as data
        fitness = np.concatenate([fitness, suite.evaluate_policies(policies[1:], s.heightmaps, key, protocol, backend,
                                                                 s.scale, cfg["slots"], cfg["chunk"], **walk)])
    suite.write_evaluation(folder, names, s, fitness)
    videos_s = None
    if cfg["videos"]:
        from jaxterrain.report import compare

        t3 = time.perf_counter()
        own = [0] + list(range(n_keys, len(names)))  # one row per policy: the base policy's first key, then the walkers
        made = compare.write_videos(folder / "videos", [names[i] for i in own], policies, s, fitness[own],
                                    jax.random.fold_in(jax.random.key(int(cfg["seed"])), 5),
                                    picks=check_video_flags(cfg), frames=int(cfg["video_frames"]),
                                    width=int(cfg["video_width"]), height=int(cfg["video_height"]),
                                    starts=int(cfg["video_starts"]), backend=backend,
                                    progress=lambda line: print(f"evaluate: {line}", file=sys.stderr, flush=True))
        videos_s = round(time.perf_counter() - t3, 3)
        if isinstance(made, str):
            print(f"evaluate: videos skipped: {made}", file=sys.stderr, flush=True)
        else:
            print(f"{len(made)} videos in {videos_s:.0f} s -> {folder / 'videos'}", flush=True)
    timing = {"suite": s.name, "terrains": s.size, "policies": len(policies), "base_keys": n_keys, "backend": backend,
              "engine": engine, "workers": walk["workers"] if engine == "mujoco" else None,
              "walks_per_terrain": protocol.attempts, "build_s": round(build_s, 3),
              "first_call_s": round(first_s, 3), "walk_s_one_policy": None if walk_s is None else round(walk_s, 3),
              "all_policies_s": round(time.perf_counter() - t1, 3),
              "repeat_equal": None if again is None else bool((first == again).all()),
              "videos_s": videos_s, "device": provenance.device()}
    atomic_write_text(folder / "timing.json", json.dumps(timing, indent=2) + "\n")
    said = "" if walk_s is None else f", {walk_s:.1f} s compiled"
    print(f"one policy on {s.size} terrains: {first_s:.1f} s the first call{said} -> {folder}", flush=True)
    return 0
