"""Does starting the smoothest terrains' rollouts first shorten a pooled difficulty evaluation?

A rollout pool (``walker.rollout.batched_distances(slots=S)``) runs until its last-started rollout has ended, so the
order of its queue sets the length of the tail in which most slots sit idle. Starting the long rollouts first
(longest-first scheduling) shortens it. The walker walks smooth terrains longest, so ``smooth_first`` (the default
of ``difficulty.evaluate`` and ``difficulty.difficulty_fitness``) orders the queue by ``walker.rollout.smoothness_priority``.

In one run, on the default device:

1. ``--terrains`` random terrains of ``--generator`` (256 x 256, default scale, shipped base policy), every rollout
   at once, to record each rollout's length (env steps) and the smoothness priority of its terrain;
2. the real pooled evaluation with ``--slots`` slots in job order and smoothest first: seconds (after an identical
   warm-up call) and fitness (the same in both orders);
3. a model of the pool at GPU scale: ``--model-terrains`` terrains drawn (with replacement) from the measured ones,
   ``--model-slots`` slots, the pool's own rules (a slot refills every 8 env steps, jobs start in queue order):
   pool steps of each order. A pool step costs about the same whatever the order, so the ratio of steps is the
   ratio of times.

    python benchmarks/rollout_order.py                       # CPU-sized
    python benchmarks/rollout_order.py --terrains 1000 --slots 4096 --model-terrains 4000 --model-slots 16384
"""

from __future__ import annotations

import argparse
import heapq
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from common import block, environment, markdown_table, write_json  # noqa: E402


def pool_steps(lengths: np.ndarray, order: np.ndarray, slots: int, refill_every: int = 8) -> int:
    """Env steps a pool of ``slots`` takes for jobs of ``lengths`` [J] (env steps) started in ``order`` [J].

    The rules of ``difficulty._pooled_distances``: every slot starts at step 0 (or stays empty); a slot whose job
    ended takes the next job at the next multiple of ``refill_every``; the loop ends at the first multiple of
    ``refill_every`` at which no slot is busy.
    """
    r = refill_every
    free = [0] * min(slots, len(order))  # times at which the slots are free (a heap)
    heapq.heapify(free)
    end = 0
    for j in order:
        t = heapq.heappop(free)
        finish = t + -(-max(int(lengths[j]), 1) // r) * r
        end = max(end, finish)
        heapq.heappush(free, finish)
    return end


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--generator", default="perlin")
    p.add_argument("--terrains", type=int, default=24)
    p.add_argument("--attempts", type=int, default=10)
    p.add_argument("--slots", type=int, default=48, help="slots of the real pooled run")
    p.add_argument("--model-terrains", type=int, default=4000)
    p.add_argument("--model-attempts", type=int, default=20)
    p.add_argument("--model-slots", default="4096,8192,16384", help="comma list of modelled pool sizes")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", type=Path, default=None)
    args = p.parse_args(argv)

    import jax

    from jaxterrain import difficulty, generators

    from jaxterrain.difficulty import evaluation

    from jaxterrain.terrain import TerrainScale

    from jaxterrain.walker.rollout import smoothness_priority

    gen = generators.get(args.generator)
    key = jax.random.key(args.seed)
    hm = block(gen.render(gen.sample(key, args.terrains)))
    a = args.attempts
    policy = difficulty.default_policy()
    env_config = difficulty.default_env_config(tuple(hm.shape[1:]), TerrainScale(), policy)
    rollout_key = jax.random.PRNGKey(args.seed + 1)
    print(f"{environment()['device']}: {args.terrains} {args.generator} terrains x {a} attempts", flush=True)

    t0 = time.perf_counter()
    terrains_m = hm * env_config.scale.height
    dist, lengths = block(evaluation._compiled(env_config, a, policy, False, None)(terrains_m, rollout_key, None))
    lengths = np.asarray(lengths)
    print(f"all at once: {time.perf_counter() - t0:.1f} s incl. compile; rollout length mean {lengths.mean():.0f}, "
          f"max {lengths.max()} env steps", flush=True)
    priority = np.asarray(smoothness_priority(terrains_m))
    rho = np.corrcoef(np.argsort(np.argsort(priority)), np.argsort(np.argsort(lengths.mean(1))))[0, 1]
    print(f"Spearman correlation of smoothness priority and mean rollout length: {rho:.2f}", flush=True)

    rows, results = [], {"environment": environment(), "args": vars(args) | {"json": str(args.json)},
                         "rollout_length_mean": float(lengths.mean()), "rollout_length_max": int(lengths.max()),
                         "spearman_priority_length": float(rho)}
    fitness = {}
    for smooth in (False, True):
        fn = evaluation._compiled(env_config, a, policy, False, args.slots, smooth)
        block(fn(terrains_m, rollout_key, None))  # compile + warm-up
        t0 = time.perf_counter()
        d, n = block(fn(terrains_m, rollout_key, None))
        seconds = time.perf_counter() - t0
        fitness[smooth] = np.asarray(difficulty.best_of(d, min(5, a)))
        order = "smoothest first" if smooth else "job order"
        rows.append({"what": f"real pool, {order}", "terrains": args.terrains, "slots": args.slots,
                     "seconds": seconds})
        print(rows[-1], flush=True)
    results["real_seconds_ratio_job_over_smooth"] = rows[-2]["seconds"] / rows[-1]["seconds"]
    results["fitness_max_abs_diff"] = float(np.max(np.abs(fitness[True] - fitness[False])))

    rng = np.random.default_rng(args.seed)
    pick = rng.integers(0, args.terrains, args.model_terrains)
    attempt = rng.integers(0, a, (args.model_terrains, args.model_attempts))
    m_len = lengths[pick[:, None], attempt].reshape(-1)  # [terrains * attempts], terrain-major like the pool's jobs
    m_pri = np.repeat(priority[pick], args.model_attempts)
    job_order = np.arange(m_len.size)
    smooth_order = np.lexsort((job_order, -m_pri))
    for s in (int(v) for v in args.model_slots.split(",") if v):
        steps = {name: pool_steps(m_len, o, s) for name, o in (("job", job_order), ("smooth", smooth_order))}
        ideal = int(np.ceil(m_len.sum() / s))
        rows.append({"what": f"model: {args.model_terrains} x {args.model_attempts} on {s} slots",
                     "steps job order": steps["job"], "steps smoothest first": steps["smooth"],
                     "ratio": steps["job"] / steps["smooth"], "ideal": ideal})
        print(rows[-1], flush=True)
        results[f"model_{s}"] = rows[-1]
    results["rows"] = rows
    if args.json:
        write_json(args.json, results)
    print()
    print(markdown_table(rows[:2], ["what", "terrains", "slots", "seconds"]))
    print()
    print(markdown_table(rows[2:], ["what", "steps job order", "steps smoothest first", "ratio", "ideal"]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
