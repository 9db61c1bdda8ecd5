"""Does the evaluation order change what a curriculum teaches? (issue 63 item 3) Each command resumable, <= 10 min.

    PYTHONPATH=. python docs/results/eval_order/run.py train sequential --time-limit 9 --pack $OUT/eval_order.tar.gz
    PYTHONPATH=. python docs/results/eval_order/run.py train overlap --time-limit 9 --pack $OUT/eval_order.tar.gz
    PYTHONPATH=. python docs/results/eval_order/run.py train lag --time-limit 9 --pack $OUT/eval_order.tar.gz
    PYTHONPATH=. python docs/results/eval_order/run.py train overlap+lag --time-limit 9 ...   # or both, one program
    PYTHONPATH=. python docs/results/eval_order/run.py evaluate sequential --time-limit 9 --pack ...   # each order
    PYTHONPATH=. python docs/results/eval_order/run.py write                       # CPU: docs/results/eval_order/

Call a stage again (the same command) until it prints ``done``: each resumes what ``--out`` holds (default
``runs/eval_order``). On a fresh machine, unpack the last ``--pack`` tar in the repository root first
(``tar xzf FILE``).

The orders (:data:`ORDERS`), one ``learn`` treatment each (``--preset gpu-short``: the map curriculum on the CPPN
archive, ``--trials`` 10 trials, 3 000 epochs), the same seed:

- ``sequential``: train a chunk, then walk its evaluation (every preset's default; the peer);
- ``overlap`` (``--overlap``): chunk k's evaluation rides along chunk k+1's training, which is trained again after a
  terrain switch: the sequential curriculum (same keys, policies and choices on a CPU), in fewer physics calls;
- ``lag`` (``--overlap --eval-lag``): the chunk trained meanwhile is kept after a switch: no step more per switch,
  the selector sees each evaluation one chunk late, a chunk per switch trains on a finished terrain unevaluated.

Stages:

- ``train ORDER``: ``learn --preset P --archive A --trials N [flags] --out OUT/ORDER`` (``learn --resume`` when it
  is there), under what is left of ``--time-limit``.
- ``train overlap+lag``: the two overlapped orders as ONE population (``jaxterrain.curriculum.batch``: one compiled
  program; its members share the harness's work and may differ in ``eval_lag``), each with the config and into the
  folder its own ``train`` uses, so either command continues it (each member checkpoints as its solo run does). On
  a GPU, about the device time of one order instead of two.
- ``evaluate ORDER``: ``evaluate --preset E --no-repeat --policy OUT/ORDER/policies/trial_* --out
  OUT/ORDER/heldout`` (``--resume`` when there): the held-out suite v1 (``--eval-preset``, default ``gpu``).
- ``write`` (CPU): into ``--results`` (default ``docs/results/eval_order/``): ``hardest.csv`` (each trial's
  hardest archive cell traversed, per order), ``comparison.md`` (per order: the mean hardest cell with its 95 %
  interval over trials, ``jaxterrain.runtime.statistics.trial_estimates``; against ``sequential``: P(a trial of the
  order beats one of sequential) with its interval over trials, ``trial_improvement``, and Welch's test on the
  trials, ``welch_trials``; the wall time of each order's commands, ``summary.json``'s ``seconds``; the chunks
  trained unevaluated), then ``generalise sequential=.. overlap=.. lag=..`` on the held-out evaluations (the same
  intervals over trials for the suite's IQM, ``generalisation/``; ``--base FILE``: a shared base evaluation).

``--pack FILE.tar.gz``: after the stage, ONE gzipped tar of ``--out`` without the checkpoints of finished runs (an
unfinished run keeps ``checkpoint.npz``, needed to resume elsewhere). ``--preset smoke --eval-preset smoke`` runs
every stage on a CPU (``tests/integration/test_eval_order_run.py``).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import subprocess
import sys
import tarfile
import time
from pathlib import Path

STARTED = time.perf_counter()
ROOT = Path(__file__).resolve().parents[3]
ORDERS = {"sequential": [], "overlap": ["--overlap"], "lag": ["--overlap", "--eval-lag"]}
"""Each order's ``learn`` flags."""
PAIR = "overlap+lag"
"""``train``'s word for the two overlapped orders run as one population."""
STAGES = ("train", "evaluate", "write")
ARCHIVE = "jaxterrain/assets/archives/cppn_headings.npz"
TRIALS = 10


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    p.add_argument("stage", nargs="+", metavar="STAGE", help="train ORDER | evaluate ORDER | write")
    p.add_argument("--out", type=Path, default=Path("runs/eval_order"), help="the resumable runs (runs/eval_order)")
    p.add_argument("--results", type=Path, default=Path("docs/results/eval_order"),
                   help="write: where the tables go (default docs/results/eval_order)")
    p.add_argument("--time-limit", type=float, default=None, metavar="MIN",
                   help="stop (resumably) so that the command ends within about MIN minutes")
    p.add_argument("--pack", type=Path, default=None, metavar="FILE",
                   help="afterwards, one gzipped tar (.tar.gz) of --out without finished runs' checkpoints")
    p.add_argument("--preset", choices=("gpu-short", "smoke"), default="gpu-short",
                   help="learn preset (default gpu-short; smoke: a CPU check)")
    p.add_argument("--eval-preset", choices=("gpu", "smoke"), default="gpu",
                   help="evaluate preset (default gpu: suite v1; smoke: a CPU check)")
    p.add_argument("--archive", default=ARCHIVE, help=f"the map curriculum's archive (default {ARCHIVE})")
    p.add_argument("--trials", type=int, default=TRIALS, help=f"trials of each order (default {TRIALS})")
    p.add_argument("--backend", choices=("jax", "warp"), default=None,
                   help="the walker's physics in train and evaluate (default the presets')")
    p.add_argument("--base", type=Path, default=None, metavar="FILE",
                   help="write: the base policy's evaluation generalise compares with (its --base)")
    for flag, kind, what in SUITE_FLAGS:
        p.add_argument(flag, type=kind, default=None, help=f"evaluate: evaluate's {flag} ({what}; a CPU check)")
    p.add_argument("--families", nargs="+", default=None, help="evaluate: evaluate's --families (a CPU check)")
    p.add_argument("--generators", nargs="*", default=None, help="evaluate: evaluate's --generators (a CPU check)")
    return p


SUITE_FLAGS = (("--size", int, "terrain side"), ("--seeds", int, "terrains per level"),
               ("--attempts", int, "walks per terrain"), ("--best", int, "best walks averaged per heading"),
               ("--headings", int, "headings"))
"""``evaluate``'s suite flags passed through (default: the preset's)."""


def suite_argv(args) -> list[str]:
    """The given suite flags as ``evaluate`` arguments."""
    argv = []
    for flag, _, _ in SUITE_FLAGS:
        value = getattr(args, flag[2:].replace("-", "_"))
        argv += [] if value is None else [flag, str(value)]
    argv += [] if args.families is None else ["--families", *args.families]
    return argv + ([] if args.generators is None else ["--generators", *args.generators])


def check(p: argparse.ArgumentParser, args) -> None:
    """Every flag and the stage's words, one line naming the flag (exit 2), before anything runs."""
    words = tuple(args.stage)
    if words[0] not in STAGES:
        p.error(f"STAGE must be one of {', '.join(STAGES)}; got {words[0]!r}")
    choices = (*ORDERS, PAIR) if words[0] == "train" else tuple(ORDERS)
    if words[0] in ("train", "evaluate") and (len(words) != 2 or words[1] not in choices):
        p.error(f"{words[0]} takes one order: {', '.join(choices)}; got {' '.join(words[1:]) or 'none'}")
    if words[0] == "write" and len(words) != 1:
        p.error(f"write takes no further word; got {' '.join(words[1:])}")
    if args.time_limit is not None and not (math.isfinite(args.time_limit) and args.time_limit > 0):
        p.error(f"--time-limit must be a finite number of minutes > 0; got {args.time_limit}")
    if args.pack is not None and not args.pack.name.endswith((".tar.gz", ".tgz")):
        p.error(f"--pack must name a .tar.gz or .tgz file; got {args.pack}")
    if args.trials < 2:
        p.error(f"--trials must be an integer >= 2 (intervals over trials); got {args.trials}")
    if words[0] == "train" and not Path(args.archive).is_file():
        p.error(f"--archive {args.archive}: no such file")


def left_minutes(args) -> float | None:
    return None if args.time_limit is None else args.time_limit - (time.perf_counter() - STARTED) / 60.0


def cli(argv: list[str], args) -> int:
    """``python -m experiments ARGV`` (a child process from the repository root's package) under what is left of
    ``--time-limit``; its output goes through. Its exit status (3: the time limit stopped it)."""
    left = left_minutes(args)
    if left is not None:
        if left <= 0.05:
            print(f"time limit: no time left for {argv[0]}", flush=True)
            return 3
        argv = [*argv, "--time-limit", f"{left:.3f}"]
    print("+ python -m experiments " + " ".join(argv), flush=True)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]).rstrip(
        os.pathsep), "PYTHONUNBUFFERED": "1"}
    return subprocess.call([sys.executable, "-m", "experiments", *argv], env=env)


def finished(folder: Path) -> bool:
    return (folder / "summary.json").is_file() and (folder / "policies").is_dir()


def stage_train(args, order: str) -> int:
    folder = args.out / order
    if finished(folder):
        print(f"train {order}: done ({folder})", flush=True)
        return 0
    if (folder / "config.json").is_file():
        argv = ["learn", "--resume", str(folder)]
    else:
        argv = ["learn", "--preset", args.preset, "--archive", str(args.archive), "--trials", str(args.trials),
                *ORDERS[order], "--out", str(folder)] + (["--backend", args.backend] if args.backend else [])
    code = cli(argv, args)
    if code == 0:
        print(f"train {order}: done ({folder})", flush=True)
    return code


def order_flat(args, order: str) -> dict:
    """The ``config.json`` that ``train ORDER`` writes (``learn``'s: the preset's flat config with the flags)."""
    from experiments import learn

    flat = {**learn.PRESETS[args.preset], "preset": args.preset, "seed": 0, "archive": str(args.archive),
            "trials": int(args.trials),
            "overlap": "--overlap" in ORDERS[order], "eval_lag": "--eval-lag" in ORDERS[order], "command": "learn"}
    return flat if args.backend is None else {**flat, "backend": args.backend}


def stage_train_pair(args) -> int:
    """``train overlap+lag`` (module docstring): both orders in one ``batch.run_treatments`` call."""
    from experiments import common
    from jaxterrain.curriculum import batch, run_config

    orders = PAIR.split("+")
    if all(finished(args.out / o) for o in orders):
        print(f"train {PAIR}: done ({args.out})", flush=True)
        return 0
    treatments = []
    for order in orders:
        folder = args.out / order
        if not (folder / "config.json").is_file():
            folder.mkdir(parents=True, exist_ok=True)
            common.write_config(folder, order_flat(args, order))
        flat = common.load_config(folder)
        common.record_provenance(folder, "learn", {"order": order, "stage": f"train {PAIR}"},
                                 resumed=(folder / "checkpoint.npz").is_file(), backend=common.physics(flat),
                                 spawn=common.spawn_rule("learn", flat))
        treatments.append(batch.Treatment(order, run_config.from_flat(flat), folder))
    left = left_minutes(args)
    summaries = batch.run_treatments(treatments, None if left is None else max(left * 60.0, 1e-3),
                                     progress="plain", say=lambda line: print(line, flush=True))
    if all(s is not None for s in summaries):
        print(f"train {PAIR}: done ({args.out})", flush=True)
        return 0
    print(f"train {PAIR}: stopped by the time limit (checkpointed); run the same command again", flush=True)
    return 3


def stage_evaluate(args, order: str) -> int:
    folder, heldout = args.out / order, args.out / order / "heldout"
    if not finished(folder):
        print(f"evaluate {order}: run 'train {order}' first (no {folder / 'summary.json'})", file=sys.stderr)
        return 2
    if (heldout / "fitness.csv").is_file() or (heldout / "fitness.csv.gz").is_file():
        print(f"evaluate {order}: done ({heldout})", flush=True)
        return 0
    if (heldout / "config.json").is_file():
        argv = ["evaluate", "--resume", str(heldout)]
    else:
        policies = sorted((folder / "policies").glob("trial_*"), key=lambda d: int(d.name.split("_")[1]))
        argv = ["evaluate", "--preset", args.eval_preset, "--no-repeat", "--policy", *map(str, policies), "--out",
                str(heldout), *suite_argv(args)] + (["--backend", args.backend] if args.backend else [])
    code = cli(argv, args)
    if code == 0:
        print(f"evaluate {order}: done ({heldout})", flush=True)
    return code


def hardest_rows(out: Path) -> dict:
    """``{order: {"hardest": [trials], "seconds", "unevaluated", "chunks"}}`` of the finished orders."""
    got = {}
    for order in ORDERS:
        folder = out / order
        if not finished(folder):
            continue
        summary = json.loads((folder / "summary.json").read_text())
        with open(folder / "history.csv", newline="") as f:
            rows = list(csv.DictReader(f))
        got[order] = {"hardest": [float(x) for x in summary["hardest"]], "seconds": summary.get("seconds"),
                      "chunks": len(rows), "unevaluated": sum(r["evaluation"] == "nan" for r in rows)}
    return got


def stage_write(args) -> int:
    import numpy as np

    from jaxterrain.runtime import statistics
    from jaxterrain.runtime.io import atomic_write_csv, atomic_write_text

    got = hardest_rows(args.out)
    if "sequential" not in got or len(got) < 2:
        print(f"write: needs the sequential order and another finished in {args.out} (have: "
              f"{', '.join(got) or 'none'})", file=sys.stderr)
        return 2
    args.results.mkdir(parents=True, exist_ok=True)
    atomic_write_csv(args.results / "hardest.csv", ["order", "trial", "hardest"],
                     [[o, t, f"{h:.3f}"] for o, r in got.items() for t, h in enumerate(r["hardest"])])
    scores = {o: np.asarray(r["hardest"], np.float64)[:, None] for o, r in got.items()}  # [trials, 1 cell]
    est = statistics.trial_estimates(scores)
    seq = scores["sequential"]
    lines = ["| order | hardest cell, mean [95 % CI over trials] | P(beats sequential) [95 % CI] | Welch t, p | "
             "chunks (unevaluated) | wall s |", "|---|---|---|---|---|---|"]
    table = {}
    for order, r in got.items():
        mean = est[order]["mean"]
        row = {"mean": list(mean), "trials": len(r["hardest"]), "seconds": r["seconds"], "chunks": r["chunks"],
               "unevaluated": r["unevaluated"]}
        vs = "peer"
        if order != "sequential":
            p = statistics.trial_improvement(scores[order], seq)
            w = statistics.welch_trials(scores[order], seq, statistic="mean")
            row.update(p_beats_sequential=list(p), welch=w)
            vs = f"{p.point:.2f} [{p.low:.2f}, {p.high:.2f}] | {w['t']:.2f}, {w['p']:.3f}"
        else:
            vs = "peer | "
        seconds = "" if r["seconds"] is None else f"{float(r['seconds']):.0f}"
        lines.append(f"| {order} | {mean.point:.2f} [{mean.low:.2f}, {mean.high:.2f}] | {vs} | {r['chunks']} "
                     f"({r['unevaluated']}) | {seconds} |")
        table[order] = row
    atomic_write_text(args.results / "hardest.json", json.dumps(table, indent=2) + "\n")
    md = ["# Evaluation order: the paper's metric", "",
          f"Hardest archive cell traversed per trial ({args.out}; `learn --preset {args.preset}`), intervals over "
          "trials (`jaxterrain.runtime.statistics`: trial_estimates, trial_improvement, welch_trials).", "", *lines]
    code = 0
    evaluated = [o for o in got if (args.out / o / "heldout" / "fitness.csv").is_file()
                 or (args.out / o / "heldout" / "fitness.csv.gz").is_file()]
    if len(evaluated) >= 2:
        from experiments.__main__ import main as experiments

        argv = ["generalise", *[f"{o}={args.out / o}" for o in evaluated], "--out",
                str(args.results / "generalisation")] + (["--base", str(args.base)] if args.base else [])
        print("+ python -m experiments " + " ".join(argv), flush=True)
        code = experiments(argv)
        md += ["", "Held-out suite: [generalisation/generalisation.md](generalisation/generalisation.md) (IQM with "
               "intervals over trials, Welch's test on the trials' IQMs, Holm-adjusted)."]
    else:
        md += ["", f"Held-out suite: not yet evaluated for every order (evaluated: {', '.join(evaluated) or 'none'})."]
    atomic_write_text(args.results / "comparison.md", "\n".join(md) + "\n")
    print("\n".join(md), flush=True)
    return code


def pack(args) -> None:
    """``--pack``: ``--out`` as one tar.gz, without the checkpoints of finished runs."""
    args.pack.parent.mkdir(parents=True, exist_ok=True)
    tmp = args.pack.with_name(args.pack.name + ".tmp")
    with tarfile.open(tmp, "w:gz") as tar:
        for path in sorted(args.out.rglob("*")):
            if not path.is_file():
                continue
            run = next((p for p in path.parents if (p / "config.json").is_file()), None)
            if path.name.startswith("checkpoint") and run is not None and (run / "summary.json").is_file():
                continue
            tar.add(path, arcname=str(path))
    os.replace(tmp, args.pack)
    print(f"packed {args.out} into {args.pack} ({args.pack.stat().st_size / 2 ** 20:.1f} MiB)", flush=True)


def main(argv=None) -> int:
    global STARTED
    STARTED = time.perf_counter()  # --time-limit counts from here (also when main is called again in one process)
    p = parser()
    args = p.parse_args(argv)
    check(p, args)
    stage = args.stage[0]
    if stage == "train":
        code = stage_train_pair(args) if args.stage[1] == PAIR else stage_train(args, args.stage[1])
    elif stage == "evaluate":
        code = stage_evaluate(args, args.stage[1])
    else:
        code = stage_write(args)
    if args.pack is not None and stage != "write" and args.out.is_dir():
        pack(args)
    return code


if __name__ == "__main__":
    sys.exit(main())
