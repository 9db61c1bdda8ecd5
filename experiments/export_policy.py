"""``python -m experiments export-policy --policy DIR --onnx OUT.onnx``: a walker as one ONNX file.

The policy network and its observation normaliser in one graph (``obs [batch, O]`` raw float32 -> ``action [batch,
A]`` in [-1, 1]), with the robot, the observation layout, the action -> actuator ctrl mapping, the control time step
and the policy's provenance in the file's metadata (:mod:`jaxterrain.rl.onnx`). Before the file is written the graph
is run with onnxruntime against the JAX policy (largest action difference <= 1e-5, else nothing is written). Needs
the optional extra: ``pip install 'jaxterrain[onnx]'``.

Examples::

    python -m experiments export-policy --policy runs/learn-x/policies/trial_0 --onnx walker.onnx
    python -m experiments export-policy --robot ant --onnx ant_base.onnx          # a shipped base policy
"""

from __future__ import annotations

import argparse
from pathlib import Path

from experiments.common import UsageError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    which = parser.add_mutually_exclusive_group(required=True)
    which.add_argument("--policy", type=Path, default=None, metavar="DIR",
                       help="policy folder to export (policy.msgpack + config.json, e.g. RUN/policies/trial_0)")
    which.add_argument("--robot", default=None, metavar="NAME",
                       help="export this robot's shipped base policy instead (humanoid, ant)")
    parser.add_argument("--onnx", type=Path, required=True, metavar="OUT.onnx",
                        help="the ONNX file to write (atomically; its folder is made)")
    parser.add_argument("--batch", type=int, default=None,
                        help="a fixed batch size for the graph's input (default: a dynamic batch axis)")
    parser.add_argument("--no-verify", action="store_true",
                        help="skip the onnxruntime check against the JAX policy before writing")


def check(args: argparse.Namespace) -> Path:
    """Check the flags before anything loads; the policy folder to export. UsageError naming the flag."""
    out = Path(args.onnx)
    if out.suffix.lower() != ".onnx":
        raise UsageError(f"--onnx {str(out)!r}: the file name must end in .onnx")
    if out.is_dir():
        raise UsageError(f"--onnx {str(out)!r} is a folder; give a file name ending in .onnx")
    for parent in out.parents:
        if parent.exists() and not parent.is_dir():
            raise UsageError(f"--onnx {str(out)!r} lies under {parent}, which is a file")
    if args.robot is not None:
        from jaxterrain.rl import base_policy_dir

        folder = base_policy_dir(args.robot)
        if not (folder / "policy.msgpack").is_file():
            raise UsageError(f"--robot {args.robot}: no base policy is shipped for it ({folder})")
        return folder
    folder = Path(args.policy)
    if not folder.exists():
        raise UsageError(f"--policy {str(folder)!r}: no such folder")
    if folder.is_file():
        folder = folder.parent
    missing = [n for n in ("policy.msgpack", "config.json") if not (folder / n).is_file()]
    if missing:
        raise UsageError(f"--policy {str(args.policy)!r}: not a policy folder (no {' or '.join(missing)})")
    return folder


def main(args: argparse.Namespace) -> int:
    folder = check(args)
    from jaxterrain.rl import load_policy
    from jaxterrain.rl import onnx as rl_onnx

    try:
        rl_onnx.onnx_modules(runtime=not args.no_verify)
    except ImportError as err:
        raise UsageError(str(err)) from None
    flag = f"--robot {args.robot}" if args.robot is not None else f"--policy {str(args.policy)!r}"
    try:
        policy = load_policy(folder)
        rl_onnx.onnx_metadata(policy)  # the walker's layout matches the policy (ValueError otherwise), before writing
    except (OSError, ValueError) as err:
        raise UsageError(f"{flag}: {str(err).splitlines()[0]}") from None
    path = rl_onnx.export_onnx(policy, args.onnx, batch=args.batch, verify=not args.no_verify)
    meta = rl_onnx.read_onnx_metadata(path)
    check_text = ("not checked (--no-verify)" if meta["verification"] is None else
                  f"onnxruntime {meta['verification']['onnxruntime']} matches the JAX policy to "
                  f"{meta['verification']['max_abs_diff']:.2g} over {meta['verification']['observations']} observations")
    print(f"wrote {path} ({path.stat().st_size / 1024:.1f} KB): {meta['robot']}, obs [{args.batch or 'batch'}, "
          f"{meta['observation']['size']}] -> action [{args.batch or 'batch'}, {meta['action']['size']}], "
          f"dt {meta['control']['dt']:g} s; {check_text}")
    return 0
