"""Actor-only copies of the walkers of finished runs (``rl.save_actor_only``: ~24 KB instead of
~1.1 MB, enough to walk and evaluate), so that a population's 60 walkers fit in what one device call returns.

    python3 benchmarks/device/ship.py runs/population/six runs/population/alone --to runs/ship

Every ``<run>/<treatment>/policies/trial_K/`` whose treatment has a ``summary.json`` becomes
``<to>/<run name>/<treatment>/policies/trial_K/``; copies already there are kept.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from jaxterrain import rl  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("runs", nargs="+", type=Path)
    p.add_argument("--to", required=True, type=Path)
    args = p.parse_args(argv)
    n = 0
    for run in args.runs:
        for trial in sorted(run.glob("*/policies/trial_*")):
            treatment = trial.parents[1]
            dest = args.to / run.name / treatment.name / "policies" / trial.name
            if not (treatment / "summary.json").exists() or (dest / "policy.msgpack").exists():
                continue
            rl.save_actor_only(trial, dest)
            n += 1
    print(f"ship: {n} walkers written actor-only under {args.to}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
