"""Sim2sim: the fitness of the GPU-trained walkers under MuJoCo's C engine beside MJX-JAX (and MuJoCo Warp).

    PYTHONPATH=. python docs/results/sim2sim/measure.py --out runs/sim2sim --time-limit 8     # one H200 + 16 cores
    PYTHONPATH=. python docs/results/sim2sim/measure.py --out /tmp/s2s --tiny                 # CPU check, ~minutes

Walkers: both shipped base policies (humanoid, ant), the first ``--walkers`` trials of the Experiment 3 treatments
``diamond_square-map`` and ``cppn-map`` (``docs/results/exp3_gpushort/<treatment>/policies/trial_K``, humanoid) and of
the ant's curriculum (``docs/results/ant_gpushort/learn/policies/trial_K``). Terrains: ``--perlin`` Perlin maps
(genomes drawn uniformly, key 62, the default 1.0 m height scale: the paper's) and suite v1's ``flat``,
``slope_up``, ``slope_down``, ``stairs_up`` and ``stairs_down`` families at every level, one seed each. Protocol:
``--attempts`` walks along +x, best ``--best`` (default the paper's 20 / 5), the same key for every engine and
walker, so walk ``a`` of a terrain starts from the same pose under every engine.

Engines: ``mjx`` (MJX-JAX on the accelerator, ``difficulty.rollout_distances``), ``mujoco`` (MuJoCo's C engine on
``--workers`` processes, ``difficulty.replay``; queued before the MJX walks so both run at once) and, with
``--warp`` when warp-lang is importable, ``warp`` (MuJoCo Warp on tiles).

Writes into ``--out`` (resumable: a (policy, engine) whose rows are all in ``fitness.csv`` is not walked again):
``fitness.csv`` (group, policy, robot, family, level, terrain, engine, fitness, mean_steps), ``walks/`` (per
(policy, engine) ``npz``: distances and steps ``[terrains, attempts]``), ``summary.md`` / ``summary.json`` (mean
absolute fitness difference per walker group and terrain family for every engine pair, the largest gaps, the C
engine's env steps per second per core) and ``timing.json``.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
FAMILIES = ("flat", "slope_up", "slope_down", "stairs_up", "stairs_down")
TREATMENTS = (("humanoid diamond_square-map", "docs/results/exp3_gpushort/diamond_square-map/policies"),
              ("humanoid cppn-map", "docs/results/exp3_gpushort/cppn-map/policies"),
              ("ant curriculum", "docs/results/ant_gpushort/learn/policies"))
HEADER = ["group", "policy", "robot", "family", "level", "terrain", "engine", "fitness", "mean_steps"]


def parse(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="results folder (resumed when it holds a fitness.csv)")
    p.add_argument("--walkers", type=int, default=3, help="trials per treatment (default 3; 0: base policies only)")
    p.add_argument("--perlin", type=int, default=32, help="Perlin terrains (default 32)")
    p.add_argument("--size", type=int, default=256, help="terrain side in pixels (default 256, 4 cm a pixel)")
    p.add_argument("--attempts", type=int, default=20, help="walks per terrain (default 20)")
    p.add_argument("--best", type=int, default=5, help="best walks averaged (default 5)")
    p.add_argument("--episode-length", type=int, default=None, help="env steps per walk (default the walker's, 1000)")
    p.add_argument("--workers", type=int, default=None, help="MuJoCo C processes (default: every CPU core)")
    p.add_argument("--time-limit", type=float, default=None, metavar="MINUTES",
                   help="stop queueing and waiting after this many minutes; what ended is written (resume later)")
    p.add_argument("--warp", action="store_true", help="also walk MuJoCo Warp (needs warp-lang)")
    p.add_argument("--robots", nargs="+", choices=("humanoid", "ant"), default=["humanoid", "ant"],
                   help="whose walkers walk (default both)")
    p.add_argument("--families", nargs="*", choices=FAMILIES, default=list(FAMILIES),
                   help="suite v1 families walked (default flat slope_up slope_down stairs_up stairs_down)")
    p.add_argument("--levels", nargs="+", type=int, default=None, help="suite levels walked (default all ten)")
    p.add_argument("--tiny", action="store_true",
                   help="a CPU check: 96-pixel maps, 2 Perlin maps, levels 0 and 9 of each family, 1 walker per "
                        "treatment, 2 walks (best 1) of 60 steps, 2 workers")
    p.add_argument("--seed", type=int, default=0, help="the walks' key (default 0)")
    args = p.parse_args(argv)
    if args.tiny:
        args.size, args.perlin, args.walkers, args.attempts, args.best = 96, 2, 1, 2, 1
        args.episode_length = args.episode_length or 60
        args.workers = args.workers or 2
    for name, lo in (("walkers", 0), ("perlin", 0), ("size", 80), ("attempts", 1), ("best", 1)):
        if getattr(args, name) < lo:
            p.error(f"--{name} must be >= {lo} (the ant needs 77-pixel maps at 4 cm); got {getattr(args, name)}")
    if args.best > args.attempts:
        p.error(f"--best must be in [1, --attempts = {args.attempts}]; got {args.best}")
    if args.episode_length is not None and args.episode_length < 1:
        p.error(f"--episode-length must be >= 1; got {args.episode_length}")
    if args.workers is not None and args.workers < 1:
        p.error(f"--workers must be >= 1; got {args.workers}")
    if args.time_limit is not None and not args.time_limit > 0:
        p.error(f"--time-limit must be > 0 minutes; got {args.time_limit}")
    return args


def walkers(n: int, robots=("humanoid", "ant")) -> list[tuple[str, str, Path]]:
    """``(group, name, folder)``: the base policies, then trial 0 of every treatment, trial 1 of every one, ...
    (of ``robots`` only)."""
    from jaxterrain.rl.checkpoint import base_policy_dir

    out = [(f"{r} base", f"base_{r}", base_policy_dir(r)) for r in ("humanoid", "ant") if r in robots]
    for k in range(n):
        for group, folder in TREATMENTS:
            path = ROOT / folder / f"trial_{k}"
            if path.is_dir() and group.split()[0] in robots:
                out.append((group, f"{folder.split('/')[2]}/{folder.split('/')[3]}/trial_{k}", path))
    return out


def terrains(args):
    """``(heightmaps [N, S, S] in [0, 1], family [N], level [N])``."""
    import jax
    import numpy as np

    from jaxterrain import generators, suite

    maps, fam, lev = [], [], []
    if args.perlin:
        gen = generators.get("perlin", size=args.size)
        maps.append(np.asarray(gen.render(gen.sample(jax.random.key(62), args.perlin))))
        fam += ["perlin"] * args.perlin
        lev += list(range(args.perlin))
    if not args.families:
        return np.concatenate(maps).astype(np.float32), np.array(fam), np.array(lev)
    s = suite.load("v1", size=args.size, seeds=1, families=list(args.families), generator_names=[])
    levels = [0, 9] if args.tiny and args.levels is None else args.levels
    keep = np.ones(s.size, bool) if levels is None else np.isin(s.level, levels) | (s.family == "flat")
    maps.append(s.heightmaps[keep])
    fam += list(s.family[keep])
    lev += [int(v) for v in s.level[keep]]
    return np.concatenate(maps).astype(np.float32), np.array(fam), np.array(lev)


def read_rows(path: Path) -> list[dict]:
    if not path.is_file():
        return []
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def write_rows(path: Path, rows: list[dict]) -> None:
    from jaxterrain.runtime.io import atomic_write_csv

    atomic_write_csv(path, HEADER, [[r[h] for h in HEADER] for r in rows])


def summarise(rows: list[dict], timing: dict) -> tuple[dict, str]:
    """Mean absolute fitness differences per engine pair, walker group and terrain family; the largest gaps."""
    import numpy as np

    table: dict = {}
    for r in rows:
        # str(): rows read back from fitness.csv (a resumed run) hold strings, this run's rows ints
        table.setdefault((r["group"], r["policy"], r["family"], str(r["level"]), str(r["terrain"])), {})[r["engine"]] = \
            (float(r["fitness"]), float(r["mean_steps"]))
    engines = sorted({r["engine"] for r in rows})
    pairs = [(a, b) for a, b in (("mujoco", "mjx"), ("warp", "mjx"), ("mujoco", "warp")) if a in engines and b in
             engines]
    groups = list(dict.fromkeys(r["group"] for r in rows))
    fams = list(dict.fromkeys(r["family"] for r in rows))
    out: dict = {"pairs": {}, "largest": {}}
    lines = [f"# Sim2sim: MuJoCo C beside MJX ({timing.get('device', '?')}, {timing.get('date', '?')}, commit "
             f"{timing.get('commit', '?')})", ""]
    lines += [f"Protocol: {timing.get('attempts')} walks along +x, best {timing.get('best')}; "
              f"{timing.get('terrains')} terrains; episode {timing.get('episode_length') or 'the walker default'} "
              "steps. Mean |fitness(A) - fitness(B)| per walker group (rows) and terrain family (columns), "
              "then the mean signed difference A - B in brackets; n = (walker, terrain) pairs.", ""]
    for a, b in pairs:
        both = {k: v for k, v in table.items() if a in v and b in v}
        diff = {k: v[a][0] - v[b][0] for k, v in both.items()}
        cell = {}
        lines += [f"## {a} - {b}", "", "| group | " + " | ".join(fams) + " | all |",
                  "|---" * (len(fams) + 2) + "|"]
        for g in groups + ["all"]:
            row = []
            for f in fams + ["all"]:
                d = np.array([v for k, v in diff.items() if (g == "all" or k[0] == g) and (f == "all" or k[2] == f)])
                if d.size:
                    cell[f"{g}|{f}"] = {"mean_abs": float(np.abs(d).mean()), "mean": float(d.mean()),
                                        "n": int(d.size)}
                    row.append(f"{np.abs(d).mean():.3f} ({d.mean():+.3f}, n={d.size})")
                else:
                    row.append("-")
            lines.append(f"| {g} | " + " | ".join(row) + " |")
        top = sorted(diff, key=lambda k: -abs(diff[k]))[:12]
        out["pairs"][f"{a}-{b}"] = cell
        out["largest"][f"{a}-{b}"] = [dict(group=k[0], policy=k[1], family=k[2], level=int(k[3]), terrain=int(k[4]),
                                           **{f"fitness_{e}": table[k][e][0] for e in (a, b)},
                                           **{f"mean_steps_{e}": table[k][e][1] for e in (a, b)}) for k in top]
        lines += ["", f"Largest gaps ({a} - {b}):", "", f"| policy | family | level | {a} | {b} | mean steps "
                  f"{a} / {b} |", "|---|---|---|---|---|---|"]
        for k in top:
            lines.append(f"| {k[1]} | {k[2]} | {k[3]} | {table[k][a][0]:.3f} | {table[k][b][0]:.3f} | "
                         f"{table[k][a][1]:.0f} / {table[k][b][1]:.0f} |")
        lines.append("")
    if timing.get("mujoco_steps"):
        rate = timing.get("mujoco_steps_per_core_s")
        lines += [f"MuJoCo C: {timing['mujoco_steps']} env steps in {timing['mujoco_worker_s']:.0f} worker-seconds "
                  f"({timing['workers']} workers, {timing['mujoco_wall_s']} s wall); "
                  + (f"{rate:.0f} env steps/s per core in the jobs that ran compiled." if rate else
                     "every job compiled (no rate).")]
    out["timing"] = timing
    return out, "\n".join(lines) + "\n"


def main(argv=None) -> int:
    args = parse(argv)
    import subprocess

    import jax
    import numpy as np

    from jaxterrain import difficulty, rl
    from jaxterrain.difficulty import replay
    from jaxterrain.rl.checkpoint import policy_fn
    from jaxterrain.runtime import provenance
    from jaxterrain.runtime.io import atomic_save_npz, atomic_write_text

    t0 = time.perf_counter()
    deadline = None if args.time_limit is None else t0 + 60 * args.time_limit
    out = Path(args.out)
    (out / "walks").mkdir(parents=True, exist_ok=True)
    warp = False
    if args.warp:
        from jaxterrain.walker import warp_available

        warp = bool(warp_available())
        if not warp:
            print("sim2sim: --warp: warp-lang / mujoco-warp not importable here; walking MJX-JAX and MuJoCo C only",
                  file=sys.stderr)
    h, family, level = terrains(args)
    protocol = difficulty.Protocol(args.attempts, args.best)
    key = jax.random.key(args.seed)
    rows = read_rows(out / "fitness.csv")
    done = {(r["policy"], r["engine"]) for r in rows}
    pols = [(g, n, rl.load_policy(p)) for g, n, p in walkers(args.walkers, args.robots)]
    workers = args.workers or os.cpu_count() or 1
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                                text=True).stdout.strip()
    except OSError:
        commit = "?"
    timing = {"device": provenance.device(), "cpu_cores": os.cpu_count(), "workers": workers,
              "date": time.strftime("%Y-%m-%d"), "commit": commit, "terrains": int(h.shape[0]),
              "walkers": len(pols), "attempts": args.attempts, "best": args.best,
              "episode_length": args.episode_length, "mjx_s": {}, "warp_s": {}, "mujoco_steps": 0,
              "mujoco_worker_s": 0.0, "mujoco_compiled_steps": 0, "mujoco_compiled_s": 0.0, "mujoco_wall_s": None, "stopped_by_time_limit": False}
    print(f"sim2sim: {len(pols)} walkers x {h.shape[0]} terrains x {args.attempts} walks; engines mjx, mujoco"
          f"{', warp' if warp else ''}; {workers} C workers; {timing['device']}", flush=True)

    def config(p):
        cfg = difficulty.default_env_config((args.size, args.size), policy=p)
        return cfg if args.episode_length is None else cfg._replace(episode_length=args.episode_length)

    def record(group, name, p, engine, distances, steps):
        fit = np.asarray(difficulty.aggregate(distances, protocol))
        for i in range(h.shape[0]):
            rows.append(dict(group=group, policy=name, robot=difficulty.policy_robot(p), family=family[i],
                             level=int(level[i]), terrain=i, engine=engine, fitness=f"{fit[i]:.6f}",
                             mean_steps=f"{np.mean(steps[i]):.1f}"))
        atomic_save_npz(out / "walks" / f"{name.replace('/', '__')}__{engine}.npz", distances=np.asarray(distances),
                        steps=np.asarray(steps))
        write_rows(out / "fitness.csv", rows)
        done.add((name, engine))

    def out_of_time():
        return deadline is not None and time.perf_counter() > deadline

    pool = replay.make_pool(workers)
    pending = {}
    t_c = time.perf_counter()
    try:
        for g, n, p in pols:  # C walks queued first: the CPU cores walk while the accelerator does MJX
            if (n, "mujoco") not in done:
                pending[n] = (g, p, replay.submit_mujoco(pool, h, key, p, protocol, env_config=config(p)))

        def collect():
            for n in [n for n, v in pending.items() if v[2].ready()]:
                g, p, job = pending.pop(n)
                w = job.get()
                timing["mujoco_steps"] += int(w.steps.sum())
                timing["mujoco_worker_s"] += float(w.seconds)
                timing["mujoco_compiled_steps"] += int(w.compiled_steps)
                timing["mujoco_compiled_s"] += float(w.compiled_seconds)
                record(g, n, p, "mujoco", w.distances, w.steps)
                print(f"  mujoco {n}: mean fitness {np.asarray(difficulty.aggregate(w.distances, protocol)).mean():.3f}"
                      f" ({time.perf_counter() - t0:.0f} s)", flush=True)

        for g, n, p in pols:
            for engine in ("mjx", "warp") if warp else ("mjx",):
                collect()
                if (n, engine) in done:
                    continue
                if out_of_time():
                    timing["stopped_by_time_limit"] = True
                    break
                cfg = config(p)
                if engine == "warp":
                    cfg = cfg._replace(backend="warp", tiles=1)
                t1 = time.perf_counter()
                d, steps = difficulty.rollout_distances(h, key, policy=policy_fn(p.config, int(p.action_size)),
                                                        policy_params=(p.params, p.normaliser), env_config=cfg,
                                                        protocol=protocol, with_steps=True)
                d, steps = np.asarray(d), np.asarray(steps)
                timing[f"{engine}_s"][n] = round(time.perf_counter() - t1, 2)
                record(g, n, p, engine, d, steps)
                print(f"  {engine} {n}: mean fitness {np.asarray(difficulty.aggregate(d, protocol)).mean():.3f} "
                      f"({timing[f'{engine}_s'][n]:.1f} s)", flush=True)
        while pending and not out_of_time():
            collect()
            time.sleep(0.5)
        collect()
        if pending:
            timing["stopped_by_time_limit"] = True
            print(f"sim2sim: --time-limit reached; {len(pending)} walkers' MuJoCo C walks unfinished (run again to "
                  "resume)", flush=True)
    finally:
        pool.terminate()
    timing["mujoco_wall_s"] = round(time.perf_counter() - t_c, 1)
    if timing["mujoco_compiled_s"]:  # jobs that ran compiled: the engine's rate, without the compiles
        timing["mujoco_steps_per_core_s"] = timing["mujoco_compiled_steps"] / timing["mujoco_compiled_s"]
    timing["total_s"] = round(time.perf_counter() - t0, 1)
    if (out / "timing.json").is_file():  # a resumed run: the earlier runs' timings stay, this one's is added
        earlier = json.loads((out / "timing.json").read_text())
        timing["earlier_runs"] = earlier.pop("earlier_runs", []) + [earlier]
        for k in ("mujoco_steps", "mujoco_compiled_steps"):
            timing[f"{k}_all_runs"] = timing[k] + sum(r.get(k, 0) for r in timing["earlier_runs"])
    summary, text = summarise(rows, timing)
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=2) + "\n")
    atomic_write_text(out / "summary.md", text)
    atomic_write_text(out / "timing.json", json.dumps(timing, indent=2) + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
