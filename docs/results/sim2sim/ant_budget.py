"""Is the ant's MuJoCo Warp contact budget large enough? Its walks under Warp with the robot's budget
(``warp_contacts`` 16, ``warp_njmax`` 96 per env) and with larger ones, on the sim2sim maps (``measure.py``'s 32
Perlin maps and suite v1's five families, 73 maps) and on suite v2 for the ant: per budget, the share of walks that
end within ``--short`` env steps (an invalid step: dropped contacts or constraint rows, or non-finite physics), the
maps where that share is at least half, and the mean fitness; MJX-JAX (no budget) as the peer in the same process.

    PYTHONPATH=. python docs/results/sim2sim/ant_budget.py --out $OUT/ant_budget.json     # one H200 with Warp, ~3 min
    PYTHONPATH=. python docs/results/sim2sim/ant_budget.py --out /tmp/b.json --tiny --budgets 16:96   # CPU, MJX only

On a machine without warp-lang only the MJX-JAX row is walked (``--tiny`` shrinks everything for a CPU check).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT))


def parse(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, required=True, help="JSON written (atomically)")
    p.add_argument("--budgets", nargs="+", default=["16:96", "32:192", "64:384"], metavar="CONTACTS:ROWS",
                   help="Warp budgets per env walked (default 16:96 32:192 64:384; the first is the robot's)")
    p.add_argument("--short", type=int, default=5, help="a walk of at most this many env steps is 'ended at once'")
    p.add_argument("--suites", nargs="+", choices=("sim2sim", "v2"), default=["sim2sim", "v2"])
    p.add_argument("--attempts", type=int, default=20, help="walks per map (default 20, best 5 averaged)")
    p.add_argument("--tiny", action="store_true", help="CPU check: 4 Perlin maps of 128 x 128, v2 at 128 x 128")
    args = p.parse_args(argv)
    budgets = []
    for b in args.budgets:
        try:
            c, r = (int(v) for v in b.split(":"))
        except ValueError:
            p.error(f"--budgets: each must be CONTACTS:ROWS with two integers >= 1, got {b!r}")
        if c < 1 or r < 1:
            p.error(f"--budgets: each must be CONTACTS:ROWS with two integers >= 1, got {b!r}")
        budgets.append((c, r))
    args.budgets = budgets
    if args.short < 1 or args.attempts < 5:
        p.error("--short must be >= 1 and --attempts >= 5")
    return args


def maps(name: str, tiny: bool):
    """``(heightmaps [N, S, S] in [0, 1], labels [N])`` of ``name``."""
    import jax
    import numpy as np

    from jaxterrain import generators, suite

    size = 128 if tiny else 256  # the ant needs 2.3 m of margins
    if name == "sim2sim":
        gen = generators.get("perlin", size=size)
        h = [np.asarray(gen.render(gen.sample(jax.random.key(62), 4 if tiny else 32)))]
        labels = [f"perlin {i}" for i in range(h[0].shape[0])]
        s = suite.load("v1", size=size, seeds=1, families=["flat", "slope_up", "slope_down", "stairs_up",
                                                          "stairs_down"], generator_names=[])
    else:
        h, labels = [], []
        s = suite.load("v2", robot="ant", **({"size": 128, "seeds": 1, "samples": 2} if tiny else {}))
    h.append(np.asarray(s.heightmaps))
    labels += [f"{f} {int(lv)}" for f, lv in zip(s.family, s.level)]
    return np.concatenate(h).astype(np.float32), labels


def walk(h, cfg, policy, attempts: int):
    """``(fitness [N], steps [N, attempts])`` of ``policy`` under ``cfg`` (the paper's protocol, best 5)."""
    import jax
    import numpy as np

    from jaxterrain import difficulty
    from jaxterrain.rl.checkpoint import policy_fn

    protocol = difficulty.Protocol(attempts, 5)
    d, steps = difficulty.rollout_distances(h, jax.random.key(0), policy=policy_fn(policy.config,
                                            int(policy.action_size)), policy_params=(policy.params,
                                            policy.normaliser), env_config=cfg, protocol=protocol, with_steps=True)
    return np.asarray(difficulty.aggregate(d, protocol)), np.asarray(steps)


def main(argv=None) -> int:
    args = parse(argv)
    import numpy as np

    from jaxterrain import difficulty, rl
    from jaxterrain.rl.checkpoint import BASE_POLICY_DIR
    from jaxterrain.runtime import provenance
    from jaxterrain.runtime.io import atomic_write_text
    from jaxterrain.walker import warp_available

    policy = rl.load_policy(BASE_POLICY_DIR.parent / "base_policy_ant")
    warp = bool(warp_available()[0])
    out = {"device": provenance.device(), "date": time.strftime("%Y-%m-%d"), "short": args.short,
           "attempts": args.attempts, "warp": warp, "suites": {}}
    for name in args.suites:
        h, labels = maps(name, args.tiny)
        base = difficulty.default_env_config(tuple(h.shape[1:]), policy=policy)
        rows = []
        variants = [("mjx-jax", base)] + ([(f"warp {c}:{r}", base._replace(backend="warp", tiles=1, warp_contacts=c,
                                                                           warp_njmax=r)) for c, r in args.budgets]
                                          if warp else [])
        for label, cfg in variants:
            t0 = time.perf_counter()
            fit, steps = walk(h, cfg, policy, args.attempts)
            short = (steps <= args.short).mean(axis=1)
            row = {"engine": label, "seconds": round(time.perf_counter() - t0, 1), "mean_fitness":
                   round(float(fit.mean()), 4), "walks_ended_at_once": round(float(short.mean()), 4),
                   "maps_half_ended_at_once": [labels[i] for i in np.flatnonzero(short >= 0.5)],
                   "fitness": [round(float(v), 4) for v in fit]}
            rows.append(row)
            print(f"{name} {label}: mean fitness {row['mean_fitness']:.3f}, walks ended within {args.short} steps "
                  f"{100 * row['walks_ended_at_once']:.1f} %, maps >= half: {len(row['maps_half_ended_at_once'])} "
                  f"({row['seconds']} s)", flush=True)
        out["suites"][name] = {"maps": labels, "rows": rows}
        atomic_write_text(args.out, json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
