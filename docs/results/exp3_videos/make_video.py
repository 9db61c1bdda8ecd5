"""Experiment 3 on video: the diamond-square map's walker (trial 0) beside the humanoid base policy on suite v1's
``slope_up`` at the level where their shipped held-out fitness differs most.

    PYTHONPATH=$PWD python docs/results/exp3_videos/make_video.py       # writes docs/results/exp3_videos/

Reads the shipped per-level fitness (``docs/results/exp3_gpushort/diamond_square-map/heldout/levels.csv``), picks
the ``slope_up`` level with the largest gap between the walker and ``base``, builds suite v1's ``slope_up`` terrains
exactly as v1 does (every family built, no generator samples: a family's terrains do not depend on those), and hands
them, with the shipped fitness of both policies on them (``fitness.csv.gz``), to
:func:`jaxterrain.report.compare.write_videos`: what ``evaluate --videos --video-terrains slope_up:LEVEL`` does
after an evaluation (both policies walk the level's seed-0 terrain from 8 reset poses on MJX; the video shows the
start the walker went farthest from, the base policy from the same start). Writes
``<walker>/slope_up_L<level>.gif``, ``videos.csv`` and ``video.json`` (the level, the shipped fitness, timings,
machine, commit).
"""

from __future__ import annotations

import csv
import json
import subprocess
import sys
import time
from pathlib import Path

from jaxterrain.report import render

render.setup_gl()  # before mujoco is imported

import jax  # noqa: E402
import numpy as np  # noqa: E402

from jaxterrain import difficulty, rl, suite  # noqa: E402
from jaxterrain.report import compare  # noqa: E402
from jaxterrain.runtime import provenance  # noqa: E402
from jaxterrain.runtime.io import atomic_write_text  # noqa: E402

ROOT = Path(__file__).resolve().parents[3]
RUN = ROOT / "docs/results/exp3_gpushort/diamond_square-map"
OUT = Path(__file__).resolve().parent
FAMILY, TRIAL, SEED = "slope_up", "trial_0", 0


def main() -> int:
    ok, why = render.gl_status()
    if not ok:
        print(why, file=sys.stderr)
        return 1
    per = {}
    with open(RUN / "heldout/levels.csv") as fh:
        for row in csv.DictReader(fh):
            if row["family"] == FAMILY and (row["policy"] == "base" or row["policy"].endswith(f"/{TRIAL}")):
                per["base" if row["policy"] == "base" else TRIAL] = np.array(row["per_level_fitness"].split(), float)
    gap = per[TRIAL] - per["base"]
    level = int(np.argmax(gap))
    shipped = suite.read_fitness(RUN / "heldout/fitness.csv.gz")
    keep = [shipped.policies.index("base"), next(i for i, p in enumerate(shipped.policies) if p.endswith(TRIAL))]
    s = suite.load("v1", families=suite.family_names(), generator_names=[])
    rows = np.flatnonzero(s.family == FAMILY)
    where = {(f, int(lv), int(sd)): i for i, (f, lv, sd) in enumerate(zip(shipped.family, shipped.level, shipped.seed))}
    cols = [where[(FAMILY, int(s.level[r]), int(s.seed[r]))] for r in rows]
    sub = s._replace(heightmaps=s.heightmaps[rows], family=s.family[rows], level=s.level[rows], seed=s.seed[rows],
                     value=s.value[rows], name=f"v1 {FAMILY}")
    fitness = shipped.fitness[keep][:, cols]
    policies = [difficulty.robot_base_policy("humanoid"), rl.load_policy(RUN / "policies" / TRIAL)]
    t0 = time.perf_counter()
    made = compare.write_videos(OUT, ["base", str((RUN / "policies" / TRIAL).relative_to(ROOT))], policies, sub, fitness,
                                jax.random.key(SEED), picks=[(FAMILY, level)],
                                labels=["base policy", f"diamond-square map walker ({TRIAL})"],
                                progress=lambda line: print(line, flush=True))
    elapsed = time.perf_counter() - t0
    (row,) = made
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                            text=True).stdout.strip()
    info = {
        "family": FAMILY, "level": level, "grade": float(row[5]), "suite_seed": int(row[4]),
        "shipped_level_fitness": {"walker": float(per[TRIAL][level]), "base": float(per["base"][level])},
        "shipped_gap_per_level": [round(float(g), 3) for g in gap],
        "video": dict(zip(compare.VIDEO_COLUMNS, map(str, row))),
        "gif_bytes": (OUT / row[7]).stat().st_size, "key": f"fold_in(key({SEED}), row * 8 + start)",
        "seconds": round(elapsed, 1), "gl": why, "device": provenance.device(), "commit": commit,
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
    }
    atomic_write_text(OUT / "video.json", json.dumps(info, indent=2) + "\n")
    print(json.dumps(info, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
