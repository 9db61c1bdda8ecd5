"""Many walkers on the held-out suite: ``suite.evaluate_policies`` with one program for every walker of one network
config (``rl.policy_fn`` cached per config), against its peer in the same run, a fresh policy function per walker
(what ``evaluate_policies`` did before: each walker compiled its own program).

    python benchmarks/evaluate_policies.py --backend jax --walkers 10 --peer 2 --out results.json

The walkers are the shipped Experiment 3 walkers (``docs/results/exp3_gpushort/*/policies/trial_*``, all of the base
policy's network config), walked one call each (``evaluate_policies([walker])``) so each call's seconds are known:
the first includes the compile, the others walk through the same program. The peer: ``--peer`` more walkers, each
through a policy function of its own (``rl.policy_fn.__wrapped__``), so each compiles. The target (issue 60): all
walkers within the first call plus (walkers - 1) walks of one. ``--size`` / ``--seeds`` / ``--samples`` /
``--families`` shrink the suite for a CPU check.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import jax  # noqa: E402
import numpy as np  # noqa: E402

from common import environment, timed  # noqa: E402
from jaxterrain import difficulty, rl, suite  # noqa: E402
from jaxterrain.suite import evaluation  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
WALKERS = ROOT / "docs" / "results" / "exp3_gpushort"


def shipped_walkers(n: int) -> list[Path]:
    """``n`` shipped Experiment 3 walker folders, trial by trial across the treatments (sorted, deterministic)."""
    folders = sorted(WALKERS.glob("*/policies/trial_*"), key=lambda p: (int(p.name.split("_")[1]), p.parent.parent.name))
    if len(folders) < n:
        raise SystemExit(f"--walkers {n}: only {len(folders)} shipped walkers under {WALKERS}")
    return folders[:n]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--backend", default="jax", choices=["jax", "warp"])
    p.add_argument("--walkers", type=int, default=10)
    p.add_argument("--peer", type=int, default=2, help="walkers walked with a policy function each (each compiles)")
    p.add_argument("--protocol", choices=sorted(difficulty.PROTOCOLS), default="headings")
    p.add_argument("--size", type=int, default=None)
    p.add_argument("--seeds", type=int, default=None)
    p.add_argument("--samples", type=int, default=None)
    p.add_argument("--families", nargs="*", default=None)
    p.add_argument("--out", type=Path, default=Path("evaluate_policies.json"))
    args = p.parse_args(argv)
    if args.walkers < 1 or args.peer < 0:
        raise SystemExit("--walkers must be >= 1 and --peer >= 0")
    s = suite.load("v1", size=args.size, seeds=args.seeds, samples=args.samples, families=args.families)
    protocol = difficulty.PROTOCOLS[args.protocol]
    folders = shipped_walkers(args.walkers + args.peer)
    walkers = [rl.load_policy(f) for f in folders]
    key = jax.random.key(0)
    result = {**environment(), "suite": s.name, "terrains": s.size, "protocol": protocol._asdict(),
              "backend": args.backend, "walkers": [str(f.relative_to(ROOT)) for f in folders]}
    print(f"{s.name}: {s.size} terrains, {args.walkers} walkers + {args.peer} peer walkers", flush=True)

    def one(policy):
        return evaluation.evaluate_policies([policy], s.heightmaps, key, protocol, args.backend, s.scale)

    shared = [timed(lambda w=w: one(w))[1] for w in walkers[:args.walkers]]
    for i, sec in enumerate(shared):
        print(f"shared program: walker {i}: {sec:.1f} s", flush=True)
    fresh = []
    cached = evaluation.policy_fn
    try:  # the peer: a new policy function per walker, as before the cache
        evaluation.policy_fn = rl.checkpoint.policy_fn.__wrapped__
        for w in walkers[args.walkers:]:
            fresh.append(timed(lambda w=w: one(w))[1])
            print(f"a program each: walker: {fresh[-1]:.1f} s", flush=True)
    finally:
        evaluation.policy_fn = cached
    total = float(np.sum(shared))
    walk = float(np.median(shared[1:])) if len(shared) > 1 else float("nan")
    result.update(shared_s=[round(x, 2) for x in shared], fresh_s=[round(x, 2) for x in fresh],
                  shared_total_s=round(total, 1), first_call_s=round(shared[0], 1), walk_s=round(walk, 2),
                  target_s=round(shared[0] + (args.walkers - 1) * walk, 1),
                  fresh_each_s=round(float(np.mean(fresh)), 1) if fresh else None,
                  projected_fresh_total_s=round(float(np.mean(fresh)) * args.walkers, 1) if fresh else None)
    if fresh:
        result["ratio_fresh_over_shared"] = round(result["projected_fresh_total_s"] / total, 2)
    print(json.dumps({k: v for k, v in result.items() if k != "walkers"}), flush=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
