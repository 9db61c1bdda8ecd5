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

``--time-limit MIN`` starts no further policy's walk of the suite after MIN minutes (exit code 3; each row walked
is kept in ``walked.npz``) and ``--resume FOLDER`` walks only the rows left.

``--randomise SPEC`` walks every policy under randomised physics (``jaxterrain.walker.parse_randomisation``; every
policy meets the same draws; MJX only, without ``--videos``); by default the nominal physics, whatever a policy was
trained under.

``--videos`` (off by default) adds ``videos/<walker>/<family>_L<level>.gif``: each walker beside the base policy on
the terrains of ``--video-terrains`` (default: per family the hardest level the walker passes and the first it
fails), and ``videos/videos.csv`` (``jaxterrain.report.compare.write_videos``). ``--video-format mp4`` writes
``.mp4`` (H.264) instead of ``.gif``, ``both`` both; MP4 needs the optional extra ``pip install 'jaxterrain[video]'``
(imageio-ffmpeg, its own ffmpeg binary), without which the flag is refused in one line before anything runs. Without
an OpenGL backend for MuJoCo's renderer one line says why and the evaluation is still written.

This module is the command line only: the run is a ``jaxterrain.suite.run_config.EvaluateRun`` (its presets there,
``config.json`` its flat form, ``--print-config`` its printout), validated and walked by
``jaxterrain.suite.runs.evaluate_run``; the videos are ``jaxterrain.report.compare.evaluation_videos``.
"""

from __future__ import annotations

import argparse
import sys

from experiments import cli_gen, common

_CONFIG = common.library_file("suite.run_config")  # jaxterrain.suite.run_config, read without JAX
PRESETS: dict[str, dict] = _CONFIG.FLAT_PRESETS
"""The presets in their flat (``config.json``) form, defined in the library: ``jaxterrain.suite.run_config.PRESETS``."""
TYPED = common.Typed("EvaluateRun", _CONFIG.FIELDS, _CONFIG.from_flat, _CONFIG.to_flat, _CONFIG.RULES)



def add_arguments(parser: argparse.ArgumentParser) -> None:
    common.add_run_arguments(parser, PRESETS, "smoke")
    cli_gen.add_typed_flags(parser, TYPED, PRESETS, _CONFIG.HELP, {
        "policy": {"metavar": "DIR"}, "keys": {"metavar": "K"}, "robot": {"metavar": "NAME"},
        "samples": {"type": common.count_or_folder, "metavar": "N|DIR"}, "terrain_height": {"metavar": "M"},
        "generators": {"nargs": "*"}, "slots": {"metavar": "SLOTS"}, "randomise": {"metavar": "SPEC"},
        "video_terrains": {"metavar": "FAMILY:LEVEL,..."}})
    common.add_protocol_argument(parser)
    common.add_deprecated_alias(parser, "--slots", "--rollout-slots", "slots", type=int, metavar="SLOTS")
    common.add_deprecated_alias(parser, "--samples", "--terrains", "samples", type=int, metavar="N")
    parser.add_argument("--gl", choices=("osmesa", "egl", "glfw"), default=None,
                        help="MuJoCo OpenGL backend of the videos (default: $MUJOCO_GL, else egl with an NVIDIA "
                             "GPU, else osmesa)")


def overrides(args) -> dict:
    """The config values given on the command line (None: not given); ``--terrains`` is a count of generator
    samples or a folder of heightmaps."""
    out = common.flag_values(args, TYPED)
    folder = isinstance(args.samples, str)
    out.update(samples=None if folder else args.samples, terrain_folder=args.samples if folder else None)
    return out


def check_flags(args, run) -> None:
    """A new run's flags that it would accept and ignore: the suite's (``--suite``, ``--size``, ``--seeds``,
    ``--terrains N``, ``--families``, ``--generators``) when ``--archive`` or ``--terrains DIR`` is walked instead
    (``--size`` sizes a folder's terrains too), the videos' (``--video-frames``, ``--video-starts``,
    ``--video-width``, ``--video-height``, ``--video-format``, ``--gl``) without ``--videos``;
    :class:`~experiments.common.UsageError`."""
    t = run.terrains
    if t.archive or t.folder:
        instead = f"--archive {t.archive}" if t.archive else f"--terrains {t.folder}"
        common.refuse_given({"--suite": args.suite, "--size": args.size if t.archive else None, "--seeds": args.seeds,
                             "--terrains": args.samples if isinstance(args.samples, int) else None,
                             "--families": args.families, "--generators": args.generators},
                            f"builds the held-out suite; this run walks {instead} instead: drop it")
    if not run.videos.on:
        common.refuse_given({common.flag(k): getattr(args, k) for k in ("video_frames", "video_starts", "video_width",
                                                                         "video_height", "video_format", "gl")},
                            "shapes the videos of --videos, which is off: give --videos too")


def main(args) -> int:
    from jaxterrain.report import compare
    from jaxterrain.suite import runs

    say_err = lambda line: print(common.flags_in(line, TYPED), file=sys.stderr, flush=True)  # noqa: E731
    ready = []

    def validate(run):
        if run.videos.on:  # the OpenGL backend, before the renderer is made
            from jaxterrain.report import render

            render.setup_gl(args.gl)
        ready.append(runs.validate_evaluate(run, raise_size=args.size is None, note=say_err))
        return ready[-1].run

    folder, run = common.setup_typed("evaluate", args, PRESETS, "smoke", TYPED, overrides(args), validate,
                                     check=lambda r: check_flags(args, r))
    try:
        result = runs.evaluate_run(ready[-1], folder, videos=compare.evaluation_videos, note=say_err,
                                   time_limit_s=common.minutes_to_seconds(args.time_limit))
    except runs.TerrainError as err:  # built when walked (after the run folder): e.g. a size that holds no family
        raise common.UsageError(common.flags_in(str(err), TYPED)) from None
    if result is None:
        print(f"time limit reached; continue with: python -m experiments evaluate --resume {folder}", flush=True)
        return 3
    return 0
