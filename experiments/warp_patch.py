"""``python -m experiments warp-patch``: the local-origin fix of MuJoCo Warp's heightfield collision, applied to the
installed mujoco-mjx's vendored copy (:mod:`jaxterrain.walker.warp_patch`).

Examples::

    python -m experiments warp-patch            # patch (nothing to do when it is patched already)
    python -m experiments warp-patch --check    # print the status; exit 0 patched, 1 stock or absent
    python -m experiments warp-patch --revert   # the stock kernel again

Every Warp run (``--backend warp``, or ``auto`` on a GPU with MuJoCo Warp installed) needs it: run it once after
``pip install 'jaxterrain[warp]'`` (and after any reinstall of mujoco-mjx, which restores the stock file).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from experiments.common import UsageError

DESCRIPTION = """\
Patch MJX's vendored MuJoCo Warp heightfield collision (mujoco/mjx/third_party/mujoco_warp/_src/collision_convex.py
of mujoco-mjx 3.17.0, the engine of --backend warp). The stock kernel runs GJK / EPA in float32 at absolute
heightfield coordinates, so a foot buried far from the heightfield's centre gets contacts metres deep and the walker
is launched; the patch (6 changed lines, jaxterrain/assets/patches/mjx_vendored_hfield_local_origin.patch) computes
them relative to the heightfield subgrid's first sample. Measured: the ant's base policy on held-out suite v2 (701
terrains, 10 keys) walks 0.776-0.780 mean fitness patched against 0.685-0.689 stock (2 x H200 host, 2026-11-29, tree
2eb907c); the ant's spawn buries a foot on 19 of 73 sim2sim maps. This EDITS A FILE OF AN INSTALLED PACKAGE
(mujoco-mjx in this Python's site-packages; atomically, in pure Python): reinstalling mujoco-mjx undoes it, and
--revert restores the stock file. Applying to a patched file (or reverting a stock one) changes nothing. Exit
status: 0 done (with --check: the patch is in place), 1 with --check when the kernel is stock or absent, or when the
file cannot be patched (a mujoco-mjx other than 3.17.0, a folder not writable)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = DESCRIPTION
    which = parser.add_mutually_exclusive_group()
    which.add_argument("--check", action="store_true",
                       help="print the status (local-origin patch, stock or absent) and the file, change nothing; "
                            "exit 0 only when the patch is in place")
    which.add_argument("--revert", action="store_true", help="restore the stock kernel")
    parser.add_argument("--file", type=Path, default=None, metavar="PATH",
                        help="the collision_convex.py to act on (default: the installed mujoco-mjx's vendored copy, "
                             "which --check names)")


def main(args: argparse.Namespace) -> int:
    from jaxterrain.runtime import provenance
    from jaxterrain.walker import warp_patch

    if args.file is not None and not Path(args.file).is_file():
        raise UsageError(f"--file {str(args.file)!r}: no such file (give a copy of collision_convex.py)")
    target = args.file if args.file is not None else provenance.warp_hfield_source()
    if target is None:
        print("absent: this mujoco-mjx has no vendored MuJoCo Warp (mujoco/mjx/third_party/mujoco_warp/_src/"
              "collision_convex.py); nothing to patch", flush=True)
        return 1
    if args.check:
        now = warp_patch.status(target)
        print(f"{now}: {target}", flush=True)
        return 0 if now == warp_patch.PATCHED else 1
    before = warp_patch.status(target)
    try:
        after = warp_patch.apply(revert=args.revert, path=target)
    except ValueError as err:
        print(f"warp-patch: error: {str(err).splitlines()[0]}", file=sys.stderr, flush=True)
        return 1
    except OSError as err:
        print(f"warp-patch: error: cannot write {target} ({err.strerror or err}): run it as the user that installed "
              f"mujoco-mjx", file=sys.stderr, flush=True)
        return 1
    what = "unchanged" if after == before else f"was {before}"
    print(f"{after}: {target} ({what})", flush=True)
    return 0
