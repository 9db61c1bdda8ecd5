"""``python -m experiments report RUN_DIR [RUN_DIR ...]``: one HTML page (and a Markdown twin) of run folders.

The page (``report.html``) is self-contained (images base64-embedded, inline CSS and JS, no network): the
``config.json``, every table (CSV, Markdown) and figure (PNG) of each run, each archive (``.npz``) as a fitness
heatmap whose cells show their terrain's thumbnail on hover or click, and GIFs of the base policy (or ``--policy``)
walking the easiest, the median and the hardest terrain of each archive, rendered by MuJoCo's offscreen renderer
(``MUJOCO_GL``: osmesa on a CPU machine, from the Debian package ``libosmesa6``; egl on a GPU one). Without a
working OpenGL backend the page says that the renders were skipped and why. A run of ``evaluate --videos`` shows
its videos (each walker beside the base policy) in a Videos section, with the terrain and both fitness values. ``report.md`` holds the same with its
images in ``report_files/``.

Example::

    python -m experiments report runs/quickstart-20261122-101500
    python -m experiments report runs/evolve-a runs/evolve-b --out runs/report-ab --frames 90
"""

from __future__ import annotations

import argparse
from pathlib import Path

from experiments import common
from experiments.common import UsageError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("runs", nargs="+", type=Path, metavar="RUN_DIR", help="run folders to report on")
    parser.add_argument("--out", type=Path, default=None,
                        help="report folder (default: RUN_DIR/report for one run, runs/report-<time> for several)")
    parser.add_argument("--title", default="jaxterrain report", help="page title")
    parser.add_argument("--videos", action=argparse.BooleanOptionalAction, default=True,
                        help="walker videos (--no-videos: leave out the walks, no MJX rollout, no GL)")
    parser.add_argument("--video-steps", dest="video_steps", type=int, default=None,
                        help="env steps walked per video (15 ms each; default 1000)")
    common.add_deprecated_alias(parser, "--steps", "--video-steps", "video_steps", type=int)
    parser.add_argument("--frames", type=int, default=None,
                        help="frames per video (evenly spaced over the walk; default 60)")
    parser.add_argument("--video-width", dest="width", type=int, default=None,
                        help="video width in pixels (default 320)")
    parser.add_argument("--video-height", dest="height", type=int, default=None,
                        help="video height in pixels (default 240)")
    common.add_deprecated_alias(parser, "--width", "--video-width", "width", type=int)
    common.add_deprecated_alias(parser, "--height", "--video-height", "height", type=int)
    parser.add_argument("--thumb", type=int, default=64, help="thumbnail side in pixels")
    parser.add_argument("--policy", type=Path, default=None,
                        help="policy folder (jaxterrain.rl.save_policy) the videos walk; default: the shipped base "
                             "policy")
    parser.add_argument("--seed", type=int, default=None, help="PRNG seed of the videos' walks (default 0)")
    parser.add_argument("--gl", choices=("osmesa", "egl", "glfw"), default=None,
                        help="MuJoCo OpenGL backend (default: $MUJOCO_GL, else egl with an NVIDIA GPU, else osmesa)")


VIDEO_FLAGS = (("--video-steps", "video_steps", 1000), ("--frames", "frames", 60), ("--video-width", "width", 320),
               ("--video-height", "height", 240), ("--thumb", "thumb", 64))
"""``(flag, dest, default)`` of the sizes checked >= 1 (the videos' default None: not given, so that
``--no-videos`` refuses them)."""


def main(args: argparse.Namespace) -> int:
    from jaxterrain.report import render

    render.setup_gl(args.gl)  # before anything imports mujoco
    from experiments.common import run_folder
    from jaxterrain.report import write_report

    for run in args.runs:
        if not run.is_dir():
            raise UsageError(f"run folder not found: {run}")
    if not args.videos:  # --no-videos walks nothing: the videos' flags would be accepted and ignored
        common.refuse_given({"--video-steps": args.video_steps, "--frames": args.frames, "--video-width": args.width,
                             "--video-height": args.height, "--policy": args.policy, "--seed": args.seed,
                             "--gl": args.gl}, "shapes the walker videos, which --no-videos leaves out: drop one of "
                                               "them")
    for flag, name, default in VIDEO_FLAGS:
        value = default if getattr(args, name) is None else getattr(args, name)
        if value < 1:
            raise UsageError(f"{flag} must be >= 1, got {value}")
        setattr(args, name, value)
    out = args.out or (args.runs[0] / "report" if len(args.runs) == 1 else run_folder("report"))
    policy = None
    if args.policy is not None:
        from jaxterrain.rl import load_policy

        try:
            policy = load_policy(args.policy)
        except (OSError, ValueError) as err:
            raise UsageError(f"--policy {args.policy}: {str(err).splitlines()[0]}") from None
    path = write_report(args.runs, out, title=args.title, videos=args.videos, video_steps=args.video_steps,
                        video_frames=args.frames, video_size=(args.width, args.height), thumb=args.thumb,
                        seed=args.seed or 0, policy=policy, progress=lambda s: print(s, flush=True))
    print(f"wrote {path} and {path.with_suffix('.md')}")
    return 0
