"""Every shipped walker on held-out suite v2 (issue 61 item 4), resumably, in commands that fit a GPU call.

    PYTHONPATH=. python docs/results/suite_v2/reevaluate.py --plan                        # CPU: what is left, how long
    PYTHONPATH=. python docs/results/suite_v2/reevaluate.py --time-limit 8 --pack $OUT/v2eval.tar.gz   # GPU

Walks, in this order, so that a run cut short still leaves whole experiments: each robot's shipped base policy with
``--keys`` (10) independent evaluation keys (the comparator of every page, as ``evaluate --keys 10`` walked it on
v1: ``docs/results/base_v1_keys_h200_2026-11-29/``), then every walker (``policies/trial_K``) of the experiment
folders given (default :data:`EXPERIMENTS`: Experiment 3, 3b, 3c, the wide recipe, the ant; 170 walkers), each
robot's walkers on ``suite.load("v2", robot=...)``. The protocol is the shipped held-out evaluations'
(``heldout/config.json``: ``evaluate --preset gpu --no-repeat --backend warp --slots 16384``; HEADINGS, 80 walks a
terrain, best 5 per heading, 4 headings, seed 0): every walker walks with the key ``evaluate`` gives every policy,
the base policy with keys 0..9, so each result is the row ``evaluate --suite v2 --robot R --keys 10 --policy ...``
would write. ``--observations blind perceptive`` walks each robot's perceptive base policy too (group
``base:<robot>:perceptive``; Experiment 4, ``docs/results/exp4/run.py``, which calls this script).

The logic is :mod:`jaxterrain.suite.batch`'s: each walk's fitness is written to ``--work`` (default
``runs/v2eval``) the moment it ends, atomically; a rerun skips what is there; under ``--time-limit MIN`` no walk
starts that is predicted to end past the limit (counted from this script's start). ``--pack FILE.tar.gz`` then puts
the work folder into ONE gzipped tar (about 1 MB when all 190 walks are done): unpack it in the repository root
(``tar xzf FILE``) and carry ``runs/v2eval`` into the next command (a fresh machine); the GPU machine writes nothing
else.

On the CPU, afterwards:

- ``--plan``: each group's walks done, and the predicted seconds of the rest (from the walks recorded in ``--work``);
- ``--write``: every group whose walks are all done, written in ``evaluate``'s files (``fitness.csv.gz``,
  ``levels.csv``, ``summary.md``, ``robustness.csv``, ``levels.png``, ``config.json``, ``timing.json``; from the
  store's records, no suite is built, so no ``suite.png``): a treatment's into ``<treatment>/<--heldout-name>/``
  (default ``heldout_v2``, beside v1's ``heldout/``; the base policy's key-0 walk as its ``base`` row, then its
  walkers, as on v1); a robot's base policy into ``<--base-out>/<robot>/`` (default
  ``docs/results/base_v2_keys_h200``; rows ``base``, ``base:key1`` .. ``base:key9``);
- ``python -m experiments generalise ... --heldout heldout_v2 --base docs/results/base_v2_keys_h200/humanoid
  --beside v1=<the page's v1 aggregate>``, per page: ``restate.py`` beside this file runs all four pages'.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import Counter
from pathlib import Path

STARTED = time.perf_counter()

ROOT = Path(__file__).resolve().parents[3]
EXPERIMENTS = ("docs/results/exp3_gpushort", "docs/results/exp3b_gpushort", "docs/results/exp3c_gpushort",
               "docs/results/wide_gpushort", "docs/results/ant_gpushort/learn")
"""The shipped experiments' folders, in the order they are walked (repository-relative)."""
BASE_OUT = "docs/results/base_v2_keys_h200"
ROBOT_ORDER = ("humanoid", "ant")


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    p.add_argument("folders", nargs="*", default=list(EXPERIMENTS), metavar="FOLDER",
                   help="experiment folders (a treatment with policies/trial_K, or a folder of them), walked in this "
                        "order after the base policies (default: the five shipped experiments)")
    p.add_argument("--work", type=Path, default=Path("runs/v2eval"),
                   help="the resumable results folder (default runs/v2eval): one file per walk")
    p.add_argument("--time-limit", type=float, default=None, metavar="MIN",
                   help="start no walk predicted to end later than MIN minutes after this script started")
    p.add_argument("--pack", type=Path, default=None, metavar="FILE",
                   help="afterwards, a gzipped tar of --work and every group folder written (relative to the "
                        "current folder), e.g. $OUT/v2eval.tar.gz")
    p.add_argument("--plan", action="store_true", help="print what is done and the predicted time of the rest; "
                                                      "walk nothing")
    p.add_argument("--write", action="store_true",
                   help="walk nothing: write every group whose walks are done as an evaluation folder (CPU, seconds)")
    p.add_argument("--part", default=None, metavar="K/N",
                   help="walk only every N-th job from the K-th (0 <= K < N), e.g. one process per GPU into one --work")
    p.add_argument("--gpus", type=int, default=None, metavar="N",
                   help="N processes, process k walking part k/N on GPU k (CUDA_VISIBLE_DEVICES=k), then --pack. "
                        "Under Warp on one 2 x H200 host (2026-11-29) two processes walked a humanoid walker in "
                        "24-42 s each (median 33 s), one process alone in 10-15 s (median 12 s): 0.06 against "
                        "0.08 walks/s; measure first")
    p.add_argument("--robots", nargs="*", default=None,
                   help="robots whose base policy walks with --keys keys first (default: the walkers' robots)")
    p.add_argument("--keys", type=int, default=10, help="evaluation keys of each base policy (default 10)")
    p.add_argument("--observations", nargs="+", choices=("blind", "perceptive"), default=["blind"],
                   help="the base policies walked per robot: its blind one (default) and / or its perceptive twin "
                        "(group base:<robot>:perceptive, written to BASE_OUT/<robot>_perceptive/)")
    p.add_argument("--heldout-name", default="heldout_v2",
                   help="a treatment's evaluation folder, inside it (default heldout_v2)")
    p.add_argument("--base-out", type=Path, default=Path(BASE_OUT),
                   help=f"the base policies' evaluations go to BASE_OUT/<robot>/ (default {BASE_OUT})")
    p.add_argument("--suite", default="v2", help="held-out suite version (default v2)")
    p.add_argument("--size", type=int, default=None, help="terrain side (a smaller build, for a CPU test)")
    p.add_argument("--seeds", type=int, default=None, help="terrains per level (a smaller build)")
    p.add_argument("--samples", type=int, default=None, help="generator samples (a smaller build)")
    p.add_argument("--families", nargs="+", default=None, help="families (a smaller build)")
    p.add_argument("--generators", nargs="*", default=None, help="generators (a smaller build)")
    p.add_argument("--attempts", type=int, default=80, help="walks per terrain (default 80)")
    p.add_argument("--best", type=int, default=5, help="best walks averaged per heading (default 5)")
    p.add_argument("--headings", type=int, choices=(1, 2, 4), default=4, help="headings (default 4)")
    p.add_argument("--backend", choices=("jax", "warp"), default="warp", help="MJX backend (default warp)")
    p.add_argument("--slots", type=int, default=16384, help="rollout pool (default 16384; 0: all walks at once)")
    p.add_argument("--chunk", type=int, default=None, help="terrains per call")
    p.add_argument("--seed", type=int, default=0, help="the evaluation key's seed (default 0, as shipped)")
    return p


def check(p: argparse.ArgumentParser, args) -> None:
    """One line naming the flag (exit 2) for a value out of range, before anything is built."""
    from jaxterrain import suite

    if args.time_limit is not None and not args.time_limit > 0:
        p.error(f"--time-limit must be a number of minutes > 0; got {args.time_limit}")
    for name, lo in (("keys", 1), ("attempts", 1), ("best", 1), ("size", 32), ("seeds", 1), ("samples", 1)):
        v = getattr(args, name)
        if v is not None and v < lo:
            p.error(f"--{name} must be an integer >= {lo}; got {v}")
    if args.best > args.attempts // args.headings:
        p.error(f"--best must be <= attempts / headings = {args.attempts // args.headings}; got {args.best}")
    if args.slots < 0:
        p.error(f"--slots must be >= 0 (0: all walks at once); got {args.slots}")
    if args.suite not in suite.VERSIONS:
        p.error(f"--suite must be one of {', '.join(suite.VERSIONS)}; got {args.suite!r}")
    if not args.heldout_name or "/" in args.heldout_name or args.heldout_name in (".", "..", "heldout", "policies"):
        p.error(f"--heldout-name must be a new folder name inside each treatment (not heldout, v1's); got "
                f"{args.heldout_name!r}")
    if args.gpus is not None and (args.gpus < 1 or args.part is not None or args.plan or args.write):
        p.error(f"--gpus must be an integer >= 1, without --part, --plan or --write; got {args.gpus}")
    if args.part is not None:
        k, sep, n = args.part.partition("/")
        if not (sep and k.isdigit() and n.isdigit() and 0 <= int(k) < int(n)):
            p.error(f"--part must be K/N with integers 0 <= K < N; got {args.part!r}")
        args.part = (int(k), int(n))
    if args.pack is not None and not args.pack.name.endswith((".tar.gz", ".tgz")):
        p.error(f"--pack must name a .tar.gz or .tgz file; got {args.pack}")


def groups(jobs) -> dict[str, list]:
    """``{group: [jobs]}`` in order of first appearance."""
    out: dict[str, list] = {}
    for j in jobs:
        out.setdefault(j.group, []).append(j)
    return out


def group_folder(group: str, args) -> Path:
    """Where a group's evaluation goes: ``BASE_OUT/<robot>`` for ``base:<robot>`` (``BASE_OUT/<robot>_perceptive``
    for ``base:<robot>:perceptive``), else ``<treatment>/<name>``."""
    if group.startswith("base:"):
        return args.base_out / "_".join(group.split(":")[1:])
    return Path(group) / args.heldout_name


def written(folder: Path, names) -> bool:
    """Whether ``folder`` holds the evaluation of exactly the jobs ``names``."""
    cfg = folder / "config.json"
    return (folder / "fitness.csv.gz").is_file() and cfg.is_file() and json.loads(cfg.read_text()).get("jobs") == list(names)


def predict(store, jobs) -> dict[str, float]:
    """Predicted seconds of each robot's pending walks in one process: its suite's build, its first walk (compile
    included) and the others, from the walks recorded in ``store`` (``batch``'s defaults where none are)."""
    from jaxterrain.suite import batch

    metas = store.metas() if store is not None else []
    out = {}
    for r in dict.fromkeys(j.robot for j in jobs):
        n = sum(1 for j in jobs if j.robot == r and (store is None or not store.has(j.name)))
        first = [m["seconds"] for m in metas if m.get("robot") == r and not m.get("compiled_before")]
        again = [m["seconds"] for m in metas if m.get("robot") == r and m.get("compiled_before")]
        build = store.build_seconds(r) if store is not None else []
        f = max(first or [batch.FIRST_WALK_S])
        a = float(sum(again) / len(again)) if again else f
        out[r] = 0.0 if n == 0 else max(build or [batch.BUILD_S]) + f + (n - 1) * a
    return out


def spawn(argv: list[str], args) -> int:
    """``--gpus N``: this script N times at once, process k with ``--part k/N`` on GPU k (``CUDA_VISIBLE_DEVICES``),
    its lines prefixed ``[gpu k]``, under what is left of ``--time-limit``; then ``--pack``. Returns the first
    nonzero exit status of a process, else 0."""
    import os
    import subprocess
    import threading

    from jaxterrain.suite import batch

    drop = {"--gpus": 1, "--pack": 1}
    rest, i = [], 0
    while i < len(argv):
        flag = argv[i].split("=", 1)[0]
        if flag in drop:
            i += 1 + (drop[flag] if "=" not in argv[i] else 0)
            continue
        rest.append(argv[i])
        i += 1
    if args.time_limit is not None:
        left = args.time_limit - (time.perf_counter() - STARTED) / 60.0
        rest = _replace_flag(rest, "--time-limit", f"{max(left, 0.01):.3f}")
    procs = []
    for k in range(args.gpus):
        env = {**os.environ, "CUDA_VISIBLE_DEVICES": str(k), "PYTHONUNBUFFERED": "1"}
        procs.append(subprocess.Popen([sys.executable, str(Path(__file__).resolve()), *rest, "--part",
                                       f"{k}/{args.gpus}"], env=env, stdout=subprocess.PIPE,
                                      stderr=subprocess.STDOUT, text=True))

    def relay(k, proc):
        for line in proc.stdout:
            print(f"[gpu {k}] {line}", end="", flush=True)

    threads = [threading.Thread(target=relay, args=(k, pr)) for k, pr in enumerate(procs)]
    for t in threads:
        t.start()
    codes = [pr.wait() for pr in procs]
    for t in threads:
        t.join()
    if args.pack is not None:
        batch.pack([args.work], args.pack, Path.cwd())
        print(f"packed {args.work} into {args.pack} ({args.pack.stat().st_size / 1e6:.2f} MB)", flush=True)
    return next((c for c in codes if c), 0)


def _replace_flag(argv: list[str], flag: str, value: str) -> list[str]:
    out, i = [], 0
    while i < len(argv):
        if argv[i] == flag:
            i += 2
            continue
        if argv[i].startswith(flag + "="):
            i += 1
            continue
        out.append(argv[i])
        i += 1
    return [*out, flag, value]


def main(argv=None) -> int:
    p = parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    args = p.parse_args(argv)
    check(p, args)
    if args.gpus is not None:
        return spawn(argv, args)
    from jaxterrain import difficulty, suite
    from jaxterrain.suite import batch

    try:
        walkers = batch.walker_jobs(args.folders)
    except ValueError as err:
        p.error(f"FOLDER: {err}" + ("; the default folders are repository-relative: run from the repository root"
                                    if Path.cwd().resolve() != ROOT else ""))
    robots = args.robots if args.robots is not None else sorted(
        {j.robot for j in walkers}, key=lambda r: (ROBOT_ORDER.index(r) if r in ROBOT_ORDER else 99, r))
    try:
        bases = [j for r in robots for o in dict.fromkeys(args.observations) for j in batch.base_jobs(r, args.keys, o)]
    except ValueError as err:
        p.error(f"--robots: {err}")
    jobs = bases + walkers
    protocol = difficulty.Protocol(args.attempts, args.best, args.headings)
    build = {k: getattr(args, k) for k in ("size", "seeds", "samples", "families", "generators")
             if getattr(args, k) is not None}
    settings = batch.settings(args.suite, protocol, args.backend, args.slots or None, args.chunk, args.seed,
                              **({"build": build} if build else {}))
    by_group = groups(jobs)
    fresh = not (args.work / "settings.json").is_file()
    if args.write and fresh:
        p.error(f"--work {args.work}: no walks here yet (unpack the GPU's tar in the repository root first)")
    try:
        store = None if args.plan and fresh else batch.Store(args.work, settings)
    except batch.StoreMismatch as err:
        p.error(f"--work: {err}")
    if args.plan:
        return plan(store, jobs, by_group, args)
    if args.write:
        return write_groups(store, by_group, args, build)
    built: dict = {}

    def suites(robot: str):
        if robot not in built:
            robot_arg = robot if suite.VERSIONS[args.suite]["robot"] is not None else None
            built[robot] = suite.load(args.suite, robot=robot_arg, size=args.size, seeds=args.seeds,
                                      samples=args.samples, families=args.families, generator_names=args.generators)
        return built[robot]

    limit = None if args.time_limit is None else args.time_limit * 60.0
    mine = jobs if args.part is None else batch.part(jobs, *args.part)
    report = batch.run(mine, store, suites, time_limit_s=limit, started=STARTED,
                       log=lambda line: print(line, flush=True))
    if report["stopped"]:
        print(f"stopped: {report['stopped']}", flush=True)
    print(f"{len(report['walked'])} walked, {len(report['skipped'])} done before, {len(report['left'])} left; "
          f"{report['seconds']:.0f} s", flush=True)
    if args.pack is not None:
        batch.pack([args.work], args.pack, Path.cwd())
        print(f"packed {args.work} into {args.pack} ({args.pack.stat().st_size / 1e6:.2f} MB)", flush=True)
    return 0


def plan(store, jobs, by_group: dict, args) -> int:
    """``--plan``: each group's walks done (and whether its evaluation is written), the predicted seconds of the
    rest."""
    from jaxterrain.suite import batch

    has = (lambda name: False) if store is None else store.has  # noqa: E731
    for g, js in by_group.items():
        k = sum(has(j.name) for j in js)
        mark = "written" if written(group_folder(g, args), [j.name for j in js] if g.startswith("base:") else
                                    [f"base:{js[0].robot}"] + [j.name for j in js]) else ""
        kinds = {} if store is None else kernels(store, [j.name for j in js if has(j.name)])
        kind = f"[{', '.join(f'{n} {w}' for w, n in sorted(kinds.items()))}]" if kinds else ""
        print(f"{g}: {k}/{len(js)} walked {mark} {kind}".replace("  ", " ").rstrip())
    left = predict(store, jobs)
    measured = store is not None and bool(store.metas())
    print(f"{sum(has(j.name) for j in jobs)} of {len(jobs)} walks done; the rest predicted at "
          + ", ".join(f"{r} {s:.0f} s" for r, s in left.items()) + f" ({sum(left.values()) / 60:.1f} min, one "
          "process; each further process adds a build and a compile per robot"
          + ("" if measured else f"; no walk recorded in {args.work}: {batch.FIRST_WALK_S:.0f} s a walk, "
             "batch.FIRST_WALK_S") + ")")
    return 0


NOT_RECORDED = "stock (not recorded)"
"""The heightfield kernel of a Warp walk recorded before ``warp_hfield`` was (2eb907c): every one was stock."""


def recorded(metas, field: str, unrecorded: str) -> dict[str, int]:
    """How many of the walks' ``metas`` recorded each value of ``field`` (``unrecorded`` for a walk made before the
    field was recorded)."""
    return dict(Counter(m.get(field, unrecorded) for m in metas))


def kernels(store, names) -> dict[str, int]:
    """How many of the walks ``names`` (all in ``store``) ran on each MuJoCo Warp heightfield kernel
    (``provenance.warp_hfield``, recorded with each walk; :data:`NOT_RECORDED` before it was); ``{}`` for a store of
    MJX-JAX walks."""
    if store.settings["backend"] != "warp":
        return {}
    return recorded([store.read(n)[1] for n in names], "warp_hfield", NOT_RECORDED)


SPAWN_NOT_RECORDED = "patch (not recorded)"
"""The spawn rule (``WalkerConfig.spawn``) of a walk recorded before ``spawn`` was: every one spawned by the patch
rule."""


def write_groups(store, by_group: dict, args, build: dict) -> int:
    """``--write``: every group whose walks are all in ``store`` written as an evaluation (``batch.write_group``,
    from the store's records: no suite is built); the others named. A group whose walks ran on different MuJoCo
    Warp heightfield kernels (stock and patched: :func:`kernels`; "stock (not recorded)" counts as stock) or by
    different spawn rules (:data:`SPAWN_NOT_RECORDED` counts as patch) is not written: it is named in
    one line and the exit status is 1."""
    from jaxterrain.suite import batch

    config = {"command": "docs/results/suite_v2/reevaluate.py", "suite": args.suite, "attempts": args.attempts,
              "best": args.best, "headings": args.headings, "backend": args.backend, "slots": args.slots or None,
              "chunk": args.chunk, "seed": args.seed, **build}
    done, wrote, waiting, mixed = lambda n: store.has(n), 0, [], []  # noqa: E731
    for group, js in by_group.items():
        names = [j.name for j in js]
        robot = js[0].robot
        if group.startswith("base:"):
            rows, labels = names, ["base"] + [f"base:key{j.key}" for j in js[1:]]
        else:  # the base policy's key-0 walk as the treatment's base row, as on v1
            rows, labels = [f"base:{robot}"] + names, ["base"] + names
        folder = group_folder(group, args)
        if not all(map(done, rows)):
            waiting.append(f"{group} ({sum(map(done, rows))}/{len(rows)})")
            continue
        metas = [store.read(n)[1] for n in rows]
        kinds = recorded(metas, "warp_hfield", NOT_RECORDED) if store.settings["backend"] == "warp" else {}
        rules = recorded(metas, "spawn", SPAWN_NOT_RECORDED)
        if len({k.split(" ")[0] for k in kinds}) > 1 or len({k.split(" ")[0] for k in rules}) > 1:
            both = {**{f"kernel {k}": n for k, n in kinds.items()}, **{f"spawn {k}": n for k, n in rules.items()}}
            mixed.append(f"{group} ({', '.join(f'{n} {k}' for k, n in sorted(both.items()))})")
            continue
        if written(folder, rows):
            continue
        batch.write_group(store, rows, folder, store.suite(robot), labels,
                          {**config, "robot": robot, "keys": len(js) if group.startswith("base:") else 1,
                           "policy": [] if group.startswith("base:") else names,
                           **({"warp_hfield": next(iter(kinds))} if kinds else {}),
                           "spawn": next(iter(rules)).split(" ")[0]})
        wrote += 1
        print(f"{group}: {folder}", flush=True)
    print(f"{wrote} evaluations written" + (f"; not yet walked: {', '.join(waiting)}" if waiting else ""), flush=True)
    if mixed:
        print(f"not written, walks on different MuJoCo Warp heightfield kernels or spawn rules: {'; '.join(mixed)}; "
              "walk them again on one (runs/v2eval/results/<walk>.npz: remove the odd ones)", file=sys.stderr,
              flush=True)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
