"""The engines of ``measure.py``'s results paired walk for walk: per walker group, mean |C - Warp|, |C - MJX-JAX|,
|Warp - MJX-JAX| and the paired difference |C - Warp| - |C - MJX-JAX| with a 95 % bootstrap interval over maps (all
of a group's walkers on one map resampled together: the map is the unit, the walkers are fixed).

    python docs/results/sim2sim/engines.py docs/results/sim2sim/h200/fitness.csv --out docs/results/sim2sim/engines.json
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

import numpy as np


def table(path: Path) -> dict:
    """``{(group, policy, terrain): {engine: fitness}}`` of a ``measure.py`` ``fitness.csv``."""
    out: dict = {}
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            out.setdefault((r["group"], r["policy"], int(r["terrain"])), {})[r["engine"]] = float(r["fitness"])
    return out


def compare(t: dict, group: str | None, samples: int = 2000, seed: int = 0) -> dict:
    """The means and the paired difference's interval for ``group`` (None: every walker)."""
    keys = [k for k, v in t.items() if (group is None or k[0] == group) and {"mujoco", "warp", "mjx"} <= set(v)]
    maps = sorted({k[2] for k in keys})
    by_map = {m: [k for k in keys if k[2] == m] for m in maps}

    def means(chosen):
        ks = [k for m in chosen for k in by_map[m]]
        f = {e: np.array([t[k][e] for k in ks]) for e in ("mujoco", "warp", "mjx")}
        cw, cm = np.abs(f["mujoco"] - f["warp"]), np.abs(f["mujoco"] - f["mjx"])
        return {"c_warp": cw.mean(), "c_mjx": cm.mean(), "warp_mjx": np.abs(f["warp"] - f["mjx"]).mean(),
                "diff": (cw - cm).mean()}

    rng = np.random.default_rng(seed)
    boot = [means(rng.choice(maps, len(maps)))["diff"] for _ in range(samples)]
    res = {k: round(float(v), 4) for k, v in means(maps).items()}
    res["diff_ci95"] = [round(float(v), 4) for v in np.percentile(boot, [2.5, 97.5])]
    res["pairs"], res["maps"] = len(keys), len(maps)
    return res


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("csv", type=Path, help="measure.py's fitness.csv with mujoco, mjx and warp rows")
    p.add_argument("--out", type=Path, default=None, help="JSON to write (default: print only)")
    args = p.parse_args(argv)
    t = table(args.csv)
    groups = list(dict.fromkeys(k[0] for k in t))
    res = {g: compare(t, g) for g in groups}
    res["all"] = compare(t, None)
    for g, r in res.items():
        print(f"{g}: |C-Warp| {r['c_warp']:.3f}  |C-MJX| {r['c_mjx']:.3f}  |Warp-MJX| {r['warp_mjx']:.3f}  "
              f"diff {r['diff']:+.3f} [{r['diff_ci95'][0]:+.3f}, {r['diff_ci95'][1]:+.3f}]")
    if args.out:
        args.out.write_text(json.dumps(res, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
