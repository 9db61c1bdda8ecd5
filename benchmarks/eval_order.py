"""Seconds per curriculum chunk under each evaluation order (issue 63 item 3), interleaved in one command.

    python benchmarks/eval_order.py --preset gpu-short --time-limit 9 --out runs/eval_order --work /tmp/eo  # one H200
    python benchmarks/eval_order.py --preset gpu-short --archives cppn=jaxterrain/assets/archives/cppn_headings.npz \\
        --time-limit 9 --out runs/eval_order_alone --work /tmp/eo_alone                               # one treatment

The orders (``--orders``, each a ``CurriculumConfig`` setting; ``sequential`` first, the peer):

- ``sequential``: train a chunk, then walk its evaluation (``overlap`` off; every preset's default);
- ``overlap``: the evaluation of chunk k rides along chunk k+1's training in the same physics calls (``overlap``),
  chunk k+1 trained again after a terrain switch (the plain loop's curriculum, one loop step more per switch);
- ``lag``: ``overlap`` and ``eval_lag``: the chunk trained meanwhile is kept after a switch (no step more; the
  selector sees each evaluation one chunk late).

Each order's population is set up as ``curriculum`` sets it up (``jaxterrain.curriculum.batch.population``: the map
treatments of ``curriculum --preset P``, by default the five shipped archives and their combination, or
``--archives``; ``--trials`` each; one program of all their trials, compiled, every trial at its first chunk) and
stepped one untimed chunk; then ``--rounds`` rounds, each timing ``--chunks`` chunks of every order in turn (the
order of the orders alternates from round to round), so drifts of the machine hit every order alike. Per round and
order: seconds per chunk (wall time of a block of n chunks / n: every running trial advances at least n chunks; loop
steps are not counted), and the terrain switches and unevaluated chunks (``lag``) in the block. The ratios are each
order's median seconds per chunk over ``sequential``'s, and per round (paired).

Writes ``<out>/eval_order.json`` after every round (``done`` once all rounds ran; a command that finds it done only
prints it) and a Markdown table. ``--time-limit MIN``: rounds stop when the next would not fit (estimated from the
round before, or from the untimed first chunks; the set-ups are not cut short). On a CPU, test it at
tiny size: ``--preset smoke --archives a=A.npz b=B.npz --trials 1 --chunks 1 --rounds 2 --backend jax``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import jax
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from common import environment, markdown_table, write_json  # noqa: E402
import population  # noqa: E402
from population import log  # noqa: E402

ORDERS = {"sequential": dict(overlap=False, eval_lag=False), "overlap": dict(overlap=True, eval_lag=False),
          "lag": dict(overlap=True, eval_lag=True)}
"""Each order's ``CurriculumConfig`` fields."""


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, type=Path, help="result folder (eval_order.json and .md)")
    p.add_argument("--work", type=Path, default=None,
                   help="the treatments' set-up folders (their combined archive; default OUT/setup)")
    p.add_argument("--orders", default="sequential,overlap,lag",
                   help=f"comma list of {', '.join(ORDERS)}; sequential first (the peer)")
    p.add_argument("--preset", default="gpu-short", help="curriculum preset of the treatments (smoke, gpu-short, ...)")
    p.add_argument("--archives", nargs="+", default=None, metavar="NAME=PATH",
                   help="the map treatments' archives (default: curriculum's five shipped ones and their "
                        "combination; one: that treatment alone)")
    p.add_argument("--trials", type=int, default=None, help="trials of each treatment (default: the preset's)")
    p.add_argument("--backend", default="auto", help="walker physics: auto, jax, warp (the preset's is auto)")
    p.add_argument("--chunks", type=int, default=3, help="chunks timed per order and round")
    p.add_argument("--rounds", type=int, default=3, help="rounds (each times every order once)")
    p.add_argument("--time-limit", type=float, default=None, metavar="MIN", help="minutes this command may take")
    args = p.parse_args(argv)
    orders = [x for x in args.orders.split(",") if x]
    bad = [x for x in orders if x not in ORDERS]
    if bad or not orders or orders[0] != "sequential" or len(set(orders)) != len(orders):
        p.exit(2, f"{p.prog}: error: --orders must list distinct orders of {', '.join(ORDERS)}, sequential first; "
                  f"got {args.orders!r}\n")
    for name in ("trials", "chunks", "rounds"):
        value = getattr(args, name)
        if value is not None and value < 1:
            p.exit(2, f"{p.prog}: error: --{name} must be an integer >= 1, got {value}\n")
    if args.time_limit is not None and not args.time_limit > 0:
        p.exit(2, f"{p.prog}: error: --time-limit must be > 0 minutes, got {args.time_limit}\n")
    args.orders = orders
    return args


def treatments(args, folder: Path, order: str):
    """The map treatments ``[(name, LearnConfig)]`` of ``curriculum --preset P`` under ``order``."""
    return population.treatments(args, folder, **ORDERS[order])


def block_counts(before, after) -> dict:
    """Terrain switches and unevaluated chunks (``eval_lag``) recorded in a block: ``before``, the members'
    ``chunk`` [T_m] arrays at its start (host copies: the block donates its states); ``after``, their states."""
    switches = unevaluated = 0
    for lo, b in zip(before, after):
        t, e = np.asarray(b.history.terrain), np.asarray(b.history.evaluation)
        lo, hi = np.asarray(lo), np.asarray(b.chunk)
        for i in range(t.shape[0]):
            rows = slice(max(int(lo[i]) - 1, 0), int(hi[i]))
            switches += int(np.sum(np.diff(t[i, rows]) != 0))
            unevaluated += int(np.sum(np.isnan(e[i, int(lo[i]):int(hi[i])])))
    return {"switches": switches, "unevaluated": unevaluated}


def main(argv=None) -> int:
    args = parse_args(argv)
    t_start = time.perf_counter()
    left = lambda: None if args.time_limit is None else 60 * args.time_limit - (time.perf_counter() - t_start)  # noqa
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "eval_order.json"
    if path.exists() and json.loads(path.read_text()).get("done"):
        log(f"done before: {path}")
        print(path.read_text())
        return 0
    from jaxterrain.curriculum import batch, runner
    from jaxterrain.runtime.io import atomic_write_text

    log("environment", environment())
    pops, row = {}, {"preset": args.preset, "orders": args.orders, "chunks_per_block": args.chunks, "setup": {},
                     "rounds": []}
    for order in args.orders:
        folder = (args.work or args.out / "setup") / order
        plan = treatments(args, folder, order)
        t0 = time.perf_counter()
        members, block, _, trials = batch.population(
            [batch.Treatment(n, r, folder / n.replace(" ", "-")) for n, r in plan], say=log)
        m = len(members)
        states = tuple(x.states for x in members)
        setup_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        states = jax.block_until_ready(block(states, np.full(m, 1, np.int32), None))
        first = time.perf_counter() - t0
        pops[order] = [block, states, m]
        row["setup"][order] = {"treatments": [n for n, _ in plan], "trials": trials, "setup_compile_s": setup_s,
                               "first_chunk_s": first, "backend": runner.physics_of(plan[0][1])}
        log(order, row["setup"][order])
    for r in range(args.rounds):
        turn = args.orders if r % 2 == 0 else args.orders[:1] + args.orders[1:][::-1]
        last = row["rounds"][-1] if row["rounds"] else {o: {"s_per_chunk": row["setup"][o]["first_chunk_s"]}
                                                         for o in args.orders}
        guess = sum(last[o]["s_per_chunk"] * args.chunks for o in args.orders)
        if left() is not None and left() < 1.2 * guess:
            log(f"round {r}: no time left for another round ({left():.0f} s left, a round takes ~{guess:.0f} s)")
            break
        got = {}
        for order in turn:
            block, states, m = pops[order]
            before = [np.array(s.chunk) for s in states]
            t0 = time.perf_counter()
            new = jax.block_until_ready(block(states, np.full(m, args.chunks, np.int32), None))
            seconds = time.perf_counter() - t0
            got[order] = {"s_per_chunk": seconds / args.chunks, **block_counts(before, new)}
            pops[order][1] = new
        for order in args.orders:
            got[order]["vs_sequential"] = got[order]["s_per_chunk"] / got["sequential"]["s_per_chunk"]
        row["rounds"].append(got)
        log(f"round {r}", got)
        row["median_s_per_chunk"] = {o: float(np.median([x[o]["s_per_chunk"] for x in row["rounds"]]))
                                     for o in args.orders}
        row["median_vs_sequential"] = {o: row["median_s_per_chunk"][o] / row["median_s_per_chunk"]["sequential"]
                                       for o in args.orders}
        row["done"] = len(row["rounds"]) == args.rounds
        write_json(path, {"environment": environment(), **row})
    if not row["rounds"]:
        log("no round ran")
        return 3
    table = [{"order": o, "s per chunk (median)": row["median_s_per_chunk"][o],
              "vs sequential": row["median_vs_sequential"][o],
              "rounds": len(row["rounds"]), "switches": sum(x[o]["switches"] for x in row["rounds"]),
              "unevaluated": sum(x[o]["unevaluated"] for x in row["rounds"])} for o in args.orders]
    md = markdown_table(table, ["order", "s per chunk (median)", "vs sequential", "rounds", "switches", "unevaluated"])
    atomic_write_text(args.out / "eval_order.md", md + "\n")
    print(md)
    return 0 if row["done"] else 3


if __name__ == "__main__":
    sys.exit(main())
