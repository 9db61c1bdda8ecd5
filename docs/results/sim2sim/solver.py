"""Does a converged contact solve close the MJX / MuJoCo C gap? The base humanoid's walks under both engines with
the solver it trained with (``SOLVER_SOUND``: Newton 4 / 16) and with the XML's converged one (``SOLVER_XML``: 8 / 50,
Euler damping), on the terrains of ``measure.py``'s CPU run.

    PYTHONPATH=. python docs/results/sim2sim/solver.py --out docs/results/sim2sim/solver.json   # CPU, ~4 min

Per solver: the fitness of each terrain under each engine, the mean |difference|, and the per-walk mean |distance
difference| (walk ``a`` of a terrain starts from the same pose under both engines).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default=None, help="write the figures here (JSON)")
    p.add_argument("--perlin", type=int, default=4)
    p.add_argument("--levels", nargs="+", type=int, default=[3, 6])
    p.add_argument("--families", nargs="*", default=["flat", "slope_up", "stairs_up"])
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--solvers", nargs="+", choices=("sound", "xml"), default=["sound", "xml"],
                   help="solver options walked (walker.NAMED_SOLVERS; default both)")
    p.add_argument("--mjx", action=argparse.BooleanOptionalAction, default=True,
                   help="walk MJX-JAX too (--no-mjx: MuJoCo C alone; on this CPU MJX-JAX under SOLVER_XML did not "
                        "finish: its process slept after a minute, 2026-11-29)")
    args = p.parse_args(argv)

    import jax
    import numpy as np

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import measure  # noqa: E402 - this folder's script: the same terrains

    from jaxterrain import difficulty, rl
    from jaxterrain.difficulty import replay
    from jaxterrain.rl.checkpoint import policy_fn
    from jaxterrain.runtime.io import atomic_write_text
    from jaxterrain.walker import NAMED_SOLVERS, solver_label

    targs = argparse.Namespace(size=256, perlin=args.perlin, families=args.families, levels=args.levels, tiny=False)
    h, family, level = measure.terrains(targs)
    pol = rl.load_policy()
    protocol = difficulty.Protocol(20, 5)
    key = jax.random.key(0)
    out = {"terrains": [f"{f} {lv}" for f, lv in zip(family, level)], "solvers": {}}
    walks = {}
    for solver in (NAMED_SOLVERS[n] for n in args.solvers):
        cfg = difficulty.default_env_config((256, 256), policy=pol)._replace(solver=solver)
        t0 = time.perf_counter()
        d_mjx = None
        if args.mjx:
            d_mjx = np.asarray(difficulty.rollout_distances(h, key, policy=policy_fn(pol.config,
                                                                                     int(pol.action_size)),
                                                            policy_params=(pol.params, pol.normaliser),
                                                            env_config=cfg, protocol=protocol))
        t1 = time.perf_counter()
        w = replay.mujoco_distances(h, key, pol, protocol, env_config=cfg, workers=args.workers)
        t2 = time.perf_counter()
        f_c = np.asarray(difficulty.aggregate(w.distances, protocol))
        res = dict(fitness_mujoco=f_c.round(4).tolist(), mujoco_s=round(t2 - t1, 1))
        walks[solver_label(solver)] = (w.distances, f_c)
        if d_mjx is not None:
            f_mjx = np.asarray(difficulty.aggregate(d_mjx, protocol))
            res.update(fitness_mjx=f_mjx.round(4).tolist(), mean_abs_fitness_diff=float(np.abs(f_c - f_mjx).mean()),
                       mean_fitness_diff=float((f_c - f_mjx).mean()),
                       mean_abs_walk_diff=float(np.abs(w.distances - d_mjx).mean()),
                       walk_correlation=float(np.corrcoef(w.distances.ravel(), d_mjx.ravel())[0, 1]),
                       mjx_s=round(t1 - t0, 1))
        out["solvers"][solver_label(solver)] = res
        print(solver_label(solver), json.dumps({k: v for k, v in res.items() if not k.startswith("fitness")}),
              flush=True)
    if len(walks) == 2:  # MuJoCo C against itself: the trained solver against the converged one
        (da, fa), (db, fb) = walks.values()
        out["mujoco_sound_vs_xml"] = dict(mean_abs_fitness_diff=float(np.abs(fa - fb).mean()),
                                          mean_fitness_diff=float((fa - fb).mean()),
                                          mean_abs_walk_diff=float(np.abs(da - db).mean()),
                                          walk_correlation=float(np.corrcoef(da.ravel(), db.ravel())[0, 1]))
        print("mujoco C, sound - xml:", json.dumps(out["mujoco_sound_vs_xml"]), flush=True)
    if args.out:
        atomic_write_text(args.out, json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
