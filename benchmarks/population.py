"""Treatments batched into one program (issue 63): a population's chunk against the walker's peak, and the six map
treatments of Experiment 2 in one program against one treatment alone.

    python benchmarks/population.py --parts peak,chunk --preset gpu-short --time-limit 9 --out runs/population
    python benchmarks/population.py --parts alone --preset gpu-short --time-limit 9 --out runs/population
    python benchmarks/population.py --parts six --preset gpu-short --time-limit 9 --out runs/population  # repeat
    python benchmarks/population.py --parts split --devices 0,1 --preset gpu-short --time-limit 9 --out runs/population
    python benchmarks/population.py --parts report --out runs/population

Each part writes ``<out>/<part>.json`` (``report``: ``<out>/population.json`` and a Markdown table) and is skipped
when that file says it is done, so a command that a time limit stopped is simply run again. Parts:

- ``peak``: the walker's peak physics rate, measured by ``benchmarks/rollouts.py`` (ours: the humanoid's walker +
  policy, ``--backend`` on ``--peak-layout`` at ``--peak-envs`` envs); its own JSON in ``<out>/rollouts.json``.
- ``chunk``: the six map treatments of ``curriculum --preset P`` (the five shipped archives and their combination,
  or ``--archives``; ``--trials`` each) set up as ONE population (``jaxterrain.curriculum.batch.population``: its
  program compiled, every trial at its first chunk), one untimed chunk, then up to ``--chunks`` chunks timed; and
  the same for ONE treatment alone (the first archive's, ``runner.setup``: the program ``learn`` and
  ``curriculum --no-batch-treatments`` run). Reports seconds per chunk, training env steps/s and physics steps/s
  (``trials x epochs_per_chunk x steps_per_epoch x n_frames`` per chunk; the evaluation walks not counted) against
  ``peak``'s, and the population's seconds per chunk over one treatment's.
- ``six`` / ``alone``: the whole runs, resumable across commands: the six map treatments as one population
  (``batch.run_treatments``) in ``<out>/six/``, and the first one alone (``runner.run_treatment``) in
  ``<out>/alone/``; each records its wall time (set-up and compiles included, summed over commands) once finished.
- ``split``: the six treatments over several GPUs, one process each (``--devices 0,1``: ``CUDA_VISIBLE_DEVICES=I``
  per process, as ``curriculum --shard I/N`` runs them): process I runs the treatments ``t % N == I`` as one
  population in ``<out>/split/`` and writes ``<out>/split<I>of<N>.json``; the part is done when every process is,
  its wall time the slowest process's. This command's own JAX does not preallocate GPU memory.
- ``report``: the figures of the parts done so far and the ratios (``six`` wall time over ``alone``'s; the target:
  at most 2; the 60-trial chunk's physics rate over the peak: at least 0.7; ``six`` over ``split``: the speed-up of
  the GPUs together, target at least 1.8 for two).

``--time-limit MIN`` bounds every command: ``chunk`` times fewer chunks, ``six`` / ``alone`` checkpoint and stop
(run them again). On a CPU, test it at tiny size: ``--preset smoke --archives a=A.npz b=B.npz --trials 1
--peak-envs 8 --peak-size 48 --backend jax --peak-layout classic``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import jax
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import rollouts  # noqa: E402
from common import environment, markdown_table, write_json  # noqa: E402

PARTS = ("peak", "chunk", "alone", "six", "split", "report")


def log(*a) -> None:
    print(f"[{time.strftime('%H:%M:%S')}]", *a, flush=True)


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, type=Path, help="result folder (one JSON per part; the runs of six/alone)")
    p.add_argument("--parts", default="peak,chunk", help=f"comma list of {', '.join(PARTS)}")
    p.add_argument("--preset", default="gpu-short", help="curriculum preset of the treatments (smoke, gpu-short, ...)")
    p.add_argument("--archives", nargs="+", default=None, metavar="NAME=PATH",
                   help="the map treatments' archives (default: curriculum's five shipped ones; with more than one, "
                        "their combination too)")
    p.add_argument("--trials", type=int, default=None, help="trials of each treatment (default: the preset's)")
    p.add_argument("--backend", default="auto", help="walker physics: auto, jax, warp (the preset's is auto)")
    p.add_argument("--chunks", type=int, default=4, help="chunk: chunks timed after the untimed first one")
    p.add_argument("--time-limit", type=float, default=None, metavar="MIN", help="minutes this command may take")
    p.add_argument("--peak-envs", default="65536", help="peak: envs per batch (rollouts.py --batch-sizes)")
    p.add_argument("--peak-layout", default="tiles", help="peak: rollouts.py --layout")
    p.add_argument("--peak-size", type=int, default=256, help="peak: terrain samples per side")
    p.add_argument("--sequential", type=Path, default=None, metavar="DIR",
                   help="report: a folder of the treatments run one after another (DIR/<treatment>/summary.json, "
                        "e.g. docs/results/exp3_gpushort) to compare six's hardest cells with, trial by trial")
    p.add_argument("--devices", default="0,1", help="split: the GPUs (CUDA_VISIBLE_DEVICES indices), one process each")
    p.add_argument("--shard", default=None, help=argparse.SUPPRESS)  # I/N: one process of split (internal)
    args = p.parse_args(argv)
    parts = [x for x in args.parts.split(",") if x]
    try:
        args.devices = [int(d) for d in args.devices.split(",")]
    except ValueError:
        args.devices = []
    if not args.devices or len(set(args.devices)) != len(args.devices) or min(args.devices) < 0:
        p.exit(2, f"{p.prog}: error: --devices must be distinct GPU indices >= 0, comma separated\n")
    if args.shard is not None:
        args.shard = tuple(int(v) for v in args.shard.split("/"))
        parts = ["shard"]
    bad = [x for x in parts if x not in PARTS and x != "shard"]
    if bad or not parts:
        p.exit(2, f"{p.prog}: error: --parts: {', '.join(bad) or 'none'}; choose from {', '.join(PARTS)}\n")
    for name in ("trials", "chunks"):
        value = getattr(args, name)
        if value is not None and value < 1:
            p.exit(2, f"{p.prog}: error: --{name} must be an integer >= 1, got {value}\n")
    if args.time_limit is not None and not args.time_limit > 0:
        p.exit(2, f"{p.prog}: error: --time-limit must be > 0 minutes, got {args.time_limit}\n")
    args.parts = parts
    return args


class Clock:
    """Seconds left of ``--time-limit`` (None: no limit)."""

    def __init__(self, minutes):
        self.t0, self.limit = time.perf_counter(), None if minutes is None else 60.0 * minutes

    def left(self):
        return None if self.limit is None else self.limit - (time.perf_counter() - self.t0)


def done(out: Path, part: str) -> dict | None:
    path = out / f"{part}.json"
    if path.exists():
        result = json.loads(path.read_text())
        if result.get("done"):
            return result
    return None


def treatments(args, folder: Path, **fields):
    """The map treatments ``[(name, LearnConfig)]`` of ``curriculum --preset P`` (its plan without baselines), with
    ``fields`` (flat config keys, e.g. ``overlap=True``) over the preset's."""
    from experiments import curriculum as exp

    cfg = {**exp.PRESETS[args.preset], "seed": 0, "command": "curriculum", "backend": args.backend, **fields}
    if args.archives:
        cfg["archives"] = exp.parse_archives(args.archives)
    if args.trials:
        cfg["trials"] = args.trials
    folder.mkdir(parents=True, exist_ok=True)
    return [(f"{name} map", exp.treatment_run(cfg, path, c)) for name, path, c in exp.treatments(cfg, folder)
            if c == "map"]


def part_peak(args, out: Path) -> dict:
    """``benchmarks/rollouts.py``'s walker + policy at ``--peak-envs``: the best physics steps/s."""
    path = out / "rollouts.json"
    rollouts.main(["--skip", "raw,c,eval,solver,backend", "--backend", "warp" if args.backend == "auto" else
                   args.backend, "--layout", args.peak_layout, "--batch-sizes", args.peak_envs, "--size",
                   str(args.peak_size), "--bank", str(min(256, max(2, int(args.peak_envs.split(",")[0])))),
                   "--out", str(path)])
    r = json.loads(path.read_text())
    best = max(r["ours"], key=lambda row: row["steps_per_s"])
    return {"done": True, "peak_physics_steps_per_s": best["steps_per_s"], "envs": best["batch"],
            "backend": f"{best['backend']}/{best['layout']}", "robot": r["robot"], "rollouts": str(path)}


def timed_chunks(call, states, chunks: int, clock: Clock) -> tuple:
    """``(states, first_s, seconds per chunk, chunks timed)``: one untimed chunk, then as many as fit (at most
    ``chunks``) in one timed call; ``call(states, n) -> states``."""
    t0 = time.perf_counter()
    states = jax.block_until_ready(call(states, 1))
    first = time.perf_counter() - t0
    left = clock.left()
    n = chunks if left is None else max(1, min(chunks, int(0.8 * left / max(first, 1e-9))))
    t0 = time.perf_counter()
    states = jax.block_until_ready(call(states, n))
    return states, first, (time.perf_counter() - t0) / n, n


def part_chunk(args, out: Path, clock: Clock) -> dict:
    """The six map treatments' population and one treatment alone, each timed from its first chunk."""
    from jaxterrain.curriculum import batch, runner

    plan = treatments(args, out / "chunk_runs")
    row = {"preset": args.preset, "treatments": [name for name, _ in plan]}
    t0 = time.perf_counter()
    members, block, _, trials = batch.population([batch.Treatment(n, r, out / "chunk_runs" / n.replace(" ", "-"))
                                                  for n, r in plan], say=log)
    setup_s = time.perf_counter() - t0
    m = len(members)
    _, first, per_chunk, n = timed_chunks(lambda s, k: block(s, np.full(m, k, np.int32), None),
                                          tuple(x.states for x in members), args.chunks, clock)
    run, config, arch, policy, env = runner.validate(plan[0][1])
    steps = config.epochs_per_chunk * config.steps_per_epoch
    frames = int(env.config.n_frames)
    row["population"] = {"trials": trials, "setup_compile_s": setup_s, "first_chunk_s": first, "chunks_timed": n,
                         "s_per_chunk": per_chunk, "env_steps_per_s": trials * steps / per_chunk,
                         "physics_steps_per_s": trials * steps * frames / per_chunk}
    log("population", row["population"])
    t0 = time.perf_counter()
    bank, solo_block, states = runner.setup(run, config, arch, policy, env)
    setup_s = time.perf_counter() - t0
    _, first, per_chunk, n = timed_chunks(lambda s, k: solo_block(s, bank, k), states, args.chunks, clock)
    alone = int(run.trials)
    row["alone"] = {"treatment": plan[0][0], "trials": alone, "setup_compile_s": setup_s, "first_chunk_s": first,
                    "chunks_timed": n, "s_per_chunk": per_chunk, "env_steps_per_s": alone * steps / per_chunk,
                    "physics_steps_per_s": alone * steps * frames / per_chunk}
    log("alone", row["alone"])
    row["population_vs_alone_s_per_chunk"] = row["population"]["s_per_chunk"] / per_chunk
    row["backend"] = runner.physics_of(run)
    row["done"] = True
    return row


def previous(out: Path, name: str) -> dict:
    """``<out>/<name>.json`` as an earlier command left it (``{}`` when none did)."""
    path = out / f"{name}.json"
    return json.loads(path.read_text()) if path.exists() else {}


def part_name(args, part: str) -> str:
    """The JSON name of ``part`` (``split<I>of<N>`` for one process of ``split``)."""
    return f"split{args.shard[0]}of{args.shard[1]}" if part == "shard" else part


def part_run(args, out: Path, clock: Clock, which: str) -> dict:
    """The whole runs: ``six`` (the map treatments as one population), ``alone`` (the first one, today's runner)
    or ``shard`` (one process of ``split``: its share of the six as one population); resumable; the wall time (each
    treatment's summary ``seconds``, summed over commands) once done."""
    from jaxterrain.curriculum import batch, runner

    folder = out / ("split" if which == "shard" else which)
    plan = treatments(args, folder)
    if which == "shard":
        i, n = args.shard
        plan = [t for k, t in enumerate(plan) if k % n == i]
    name = part_name(args, which)
    commands = list(previous(out, name).get("commands_s", []))
    t0 = time.perf_counter()
    left = clock.left()
    if which in ("six", "shard"):
        summaries = batch.run_treatments([batch.Treatment(n, r, folder / n.replace(" ", "-")) for n, r in plan],
                                         left, say=log, progress="plain",
                                         label=f"shard {args.shard[0]}/{args.shard[1]} population"
                                         if which == "shard" else "population")
    else:
        summaries = [runner.run_treatment(plan[0][1], folder / plan[0][0].replace(" ", "-"), left, desc=plan[0][0],
                                          progress="plain")]
        plan = plan[:1]
    commands.append(time.perf_counter() - t0)
    finished = all(s is not None for s in summaries)
    row = {"preset": args.preset, "treatments": [n for n, _ in plan], "commands_s": commands, "done": finished}
    if finished:
        row["wall_s"] = max(float(s["seconds"]) for s in summaries)  # one program: every member's is the group's
        row["hardest_mean"] = {n: s["hardest_mean"] for (n, _), s in zip(plan, summaries)}
        row["hardest_iqm"] = {n: s["hardest_iqm"] for (n, _), s in zip(plan, summaries)}
    log(name, row)
    return row


def part_split(args, out: Path, clock: Clock) -> dict:
    """``split``: one process per ``--devices`` GPU, each ``--shard I/N`` of this script (the same flags, the time
    left), run together; done when every process's JSON says so."""
    n = len(args.devices)
    forward = ["--out", str(out), "--preset", args.preset, "--backend", args.backend]
    forward += (["--archives", *args.archives] if args.archives else []) + (["--trials", str(args.trials)]
                                                                           if args.trials else [])
    left = clock.left()
    if left is not None:
        forward += ["--time-limit", f"{max(left, 1.0) / 60.0:.4f}"]
    t0 = time.perf_counter()
    procs = []
    for i, gpu in enumerate(args.devices):
        env = {**os.environ, "CUDA_VISIBLE_DEVICES": str(gpu)}
        if args.preallocate is None:  # set by main for this process alone
            env.pop("XLA_PYTHON_CLIENT_PREALLOCATE", None)
        procs.append(subprocess.Popen([sys.executable, str(Path(__file__).resolve()), *forward, "--shard", f"{i}/{n}"],
                                      env=env))
    rcs = [p.wait() for p in procs]
    shards = [previous(out, f"split{i}of{n}") for i in range(n)]
    row = {"preset": args.preset, "devices": args.devices, "returncodes": rcs,
           "commands_s": list(previous(out, "split").get("commands_s", [])) + [time.perf_counter() - t0],
           "treatments": [t for s in shards for t in s.get("treatments", [])],
           "done": all(s.get("done") for s in shards)}
    if row["done"]:
        row["wall_s"] = max(float(s["wall_s"]) for s in shards)  # the processes ran together: the slowest's
        row["shard_wall_s"] = [float(s["wall_s"]) for s in shards]
        row["hardest_mean"] = {k: v for s in shards for k, v in s["hardest_mean"].items()}
        row["hardest_iqm"] = {k: v for s in shards for k, v in s["hardest_iqm"].items()}
    log("split", row)
    return row


def slug(treatment: str) -> str:
    return treatment.replace(" ", "-")


def hardest_rows(out: Path, peers: dict[str, Path]) -> list[dict]:
    """Six's treatments against their runs elsewhere (``peers``: ``{name: folder of treatment folders}``), trial by
    trial: each side's mean hardest cell with its interval over trials (``statistics.trial_estimates``) and P(a
    trial of six beats a trial of the peer) with its interval (``statistics.trial_improvement``: 0.5 inside it =
    no difference the trials support)."""
    from jaxterrain.runtime import statistics

    rows = []
    for summary in sorted((out / "six").glob("*/summary.json")):
        six = np.asarray(json.loads(summary.read_text())["hardest"], np.float64)[:, None]
        for peer, folder in peers.items():
            other = folder / summary.parent.name / "summary.json"
            if not other.exists():
                continue
            them = np.asarray(json.loads(other.read_text())["hardest"], np.float64)[:, None]
            a, b = (statistics.trial_estimates({"x": v})["x"]["mean"] for v in (six, them))
            p = statistics.trial_improvement(six, them)
            rows.append({"treatment": summary.parent.name, "peer": peer, "six": list(a), "peer_mean": list(b),
                         "p_six_better": list(p), "differ": not p.low <= 0.5 <= p.high})
    return rows


def part_report(out: Path, sequential: Path | None = None) -> dict:
    """The ratios of the parts done so far, as ``population.json`` and a printed table; six's hardest cells against
    ``alone`` (same commit), ``split`` (when done) and ``sequential`` (:func:`hardest_rows`)."""
    got = {p: done(out, p) for p in PARTS[:-1]}
    report = {"environment": environment(), **{p: r for p, r in got.items() if r}}
    rows = []
    if got["chunk"]:
        for what in ("population", "alone"):
            r = got["chunk"][what]
            rows.append({"what": f"{what} ({r['trials']} trials)", "s per chunk": r["s_per_chunk"],
                         "physics M steps/s": r["physics_steps_per_s"] / 1e6,
                         "of the peak": (r["physics_steps_per_s"] / got["peak"]["peak_physics_steps_per_s"]
                                         if got["peak"] else float("nan"))})
        report["chunk_vs_alone"] = got["chunk"]["population_vs_alone_s_per_chunk"]
        if got["peak"]:
            report["population_of_peak"] = (got["chunk"]["population"]["physics_steps_per_s"]
                                            / got["peak"]["peak_physics_steps_per_s"])
    if got["six"] and got["alone"]:
        report["six_vs_alone_wall"] = got["six"]["wall_s"] / got["alone"]["wall_s"]
        rows += [{"what": f"{p} (whole run)", "wall s": got[p]["wall_s"]} for p in ("six", "alone")]
    if got["six"] and got["split"]:
        report["six_vs_split_wall"] = got["six"]["wall_s"] / got["split"]["wall_s"]
        rows.append({"what": f"split over {len(got['split']['devices'])} GPUs (whole run)",
                     "wall s": got["split"]["wall_s"]})
    peers = {"alone": out / "alone", **({"split": out / "split"} if got["split"] else {}),
             **({"sequential": sequential} if sequential else {})}
    report["hardest"] = hardest_rows(out, peers) if got["six"] else []
    write_json(out / "population.json", report)
    print(markdown_table(rows, ["what", "s per chunk", "physics M steps/s", "of the peak", "wall s"]))
    for r in report["hardest"]:
        print(f"{r['treatment']} vs {r['peer']}: six {r['six'][0]:.2f} [{r['six'][1]:.2f}, {r['six'][2]:.2f}], "
              f"peer {r['peer_mean'][0]:.2f} [{r['peer_mean'][1]:.2f}, {r['peer_mean'][2]:.2f}], P(six > peer) "
              f"{r['p_six_better'][0]:.2f} [{r['p_six_better'][1]:.2f}, {r['p_six_better'][2]:.2f}]"
              + (" DIFFER" if r["differ"] else ""))
    print(json.dumps({k: v for k, v in report.items() if k in ("chunk_vs_alone", "population_of_peak",
                                                                "six_vs_alone_wall", "six_vs_split_wall")}))
    return report


def main(argv=None) -> int:
    args = parse_args(argv)
    clock = Clock(args.time_limit)
    args.out.mkdir(parents=True, exist_ok=True)
    args.preallocate = os.environ.get("XLA_PYTHON_CLIENT_PREALLOCATE")
    if "split" in args.parts and args.preallocate is None:  # this process's JAX must leave the GPUs to split's
        os.environ["XLA_PYTHON_CLIENT_PREALLOCATE"] = "false"
    log("environment", environment())
    for part in args.parts:
        if part == "report":
            part_report(args.out, args.sequential)
            continue
        name = part_name(args, part)
        if done(args.out, name):
            log(f"{part}: done before ({args.out / (name + '.json')})")
            continue
        if clock.left() is not None and clock.left() <= 0:
            log(f"{part}: no time left; run the command again")
            return 3
        if part == "peak":
            row = part_peak(args, args.out)
        elif part == "chunk":
            row = part_chunk(args, args.out, clock)
        elif part == "split":
            row = part_split(args, args.out, clock)
        else:
            row = part_run(args, args.out, clock, part)
        write_json(args.out / f"{name}.json", {"environment": environment(), **row})
        if not row.get("done"):
            log(f"{part}: stopped by the time limit; run the command again")
            return 3
    return 0


if __name__ == "__main__":
    sys.exit(main())
