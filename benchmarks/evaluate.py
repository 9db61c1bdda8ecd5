"""One walker on the whole held-out suite: ``suite.evaluate_policies`` (every terrain in one program) against its
peer, the same terrains walked by ``difficulty.evaluate`` one family at a time, in the same run.

    python benchmarks/evaluate.py --backend jax,warp --peer warp --out results.json

For each backend: the suite (``v1`` unless ``--size`` / ``--seeds`` / ``--families`` shrink it, for a CPU check) is
built once; the base policy walks it under ``--protocol`` (default ``headings``: 80 walks per terrain) twice with the
same key, and the second, compiled call is the figure (the target: at most 60 s on one H100). The peer walks each
family's terrains in its own call (each family's batch size compiles once; its second call is timed) and sums them.
Also written: the base policy's fitness per terrain (``fitness_<backend>.npz``, with the suite's family / level /
seed) and, with ``--outputs DIR``, the evaluation's files (``suite.write_evaluation``: CSV, Markdown, figures).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import jax  # noqa: E402
import numpy as np  # noqa: E402

from common import environment, timed  # noqa: E402
from jaxterrain import difficulty, rl, suite  # noqa: E402
from jaxterrain.rl.checkpoint import policy_fn  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--backend", default="jax", help="comma-separated: jax, warp")
    p.add_argument("--peer", default="", help="comma-separated backends to time the per-family peer on")
    p.add_argument("--protocol", choices=sorted(difficulty.PROTOCOLS), default="headings")
    p.add_argument("--size", type=int, default=None)
    p.add_argument("--seeds", type=int, default=None)
    p.add_argument("--samples", type=int, default=None)
    p.add_argument("--families", nargs="*", default=None)
    p.add_argument("--slots", type=int, default=None, help="rollout pool (MJX-JAX: bounds device memory)")
    p.add_argument("--chunk", type=int, default=None)
    p.add_argument("--out", type=Path, default=Path("evaluate_results.json"))
    p.add_argument("--outputs", type=Path, default=None, help="also write the evaluation's files here")
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    s = suite.load("v1", size=args.size, seeds=args.seeds, samples=args.samples, families=args.families)
    build_s = time.perf_counter() - t0
    protocol = difficulty.PROTOCOLS[args.protocol]
    base = rl.load_policy()
    key = jax.random.key(0)
    result = {**environment(), "suite": s.name, "terrains": s.size, "families": list(s.families()),
              "missing": s.missing, "protocol": protocol._asdict(), "build_s": round(build_s, 2), "runs": {}}
    print(f"{s.name}: {s.size} terrains built in {build_s:.1f} s", flush=True)
    for backend in [b for b in args.backend.split(",") if b]:
        run = lambda: suite.evaluate_policies([base], s.heightmaps, key, protocol, backend, s.scale,  # noqa: E731
                                              args.slots, args.chunk)
        first, first_s = timed(run)
        second, second_s = timed(run)
        row = {"first_call_s": round(first_s, 2), "walk_s": round(second_s, 2),
               "walks": int(s.size * protocol.attempts), "repeat_equal": bool(np.array_equal(first, second)),
               "fitness_mean": float(np.mean(second))}
        if backend in args.peer.split(","):
            apply, params = policy_fn(base.config, base.action_size), (base.params, base.normaliser)
            cfg = difficulty.default_env_config(tuple(s.heightmaps.shape[1:]), s.scale, base, backend)
            per, peer_first, peer_second = {}, 0.0, 0.0
            for fam in s.families():
                maps = s.heightmaps[s.family == fam]
                call = lambda: difficulty.evaluate(maps, key, policy=apply, policy_params=params,  # noqa: E731
                                                   env_config=cfg, protocol=protocol, slots=args.slots,
                                                   chunk=args.chunk)
                _, a = timed(call)
                f, b = timed(call)
                per[fam] = round(b, 3)
                peer_first, peer_second = peer_first + a, peer_second + b
            row["peer"] = {"first_calls_s": round(peer_first, 2), "walk_s": round(peer_second, 2), "per_family_s": per,
                           "ratio_peer_over_suite": round(peer_second / second_s, 3)}
        result["runs"][backend] = row
        print(backend, json.dumps(row), flush=True)
        np.savez_compressed(args.out.parent / f"fitness_{backend}.npz", fitness=np.asarray(second)[0],
                            family=s.family.astype(str), level=s.level, seed=s.seed, value=s.value)
        if args.outputs is not None:
            out = args.outputs / backend
            out.mkdir(parents=True, exist_ok=True)
            suite.write_evaluation(out, ["base"], s, np.asarray(second))
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
