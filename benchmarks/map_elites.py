"""MAP-Elites throughput: our on-device loop (jaxterrain.qd.evolve) vs pyribs, and the paper-scale estimate.

    python benchmarks/map_elites.py                 # CPU-sized defaults
    python benchmarks/map_elites.py --preset gpu    # GPU machine: 256 x 256 terrains, large batches

(a) Cheap fitness (``1 - mean slope``, jaxterrain.difficulty.slope_fitness): the same MAP-Elites (Perlin genomes, the
    paper's mutation p = 0.35 / sigma = 10 % of range, uniform selection from filled cells, 50 x 50 grid over
    roughness / TPI at window 30 / stride 2, Algorithm 1, 100 initial genomes) run
      - by ``evolve`` on the default JAX device, at batch 20 (the paper's) and at a large batch;
      - by pyribs (``ribs.archives.GridArchive`` + ``sample_elites`` + the same mutation in NumPy) on the CPU, its
        evaluations (render + descriptors + Algorithm 1 + fitness) jitted by JAX on the CPU device.
    pyribs is skipped with a message when ``import ribs`` fails (``pip install ribs``).
(b) The real fitness (walker rollouts, ``attempts`` x ``best``) through ``difficulty.difficulty_fitness``: measured
    evaluations/s and the estimated time of a paper-scale treatment (100 100 evaluations x 20 attempts), for each
    ``--rollout-slots`` pool size in the same run (a pool also skips the terrains that Algorithm 1 rejects). When the
    base policy is not shipped yet, a fixed random linear policy stands in (its episodes end at other times than
    the base policy's, so the estimate is provisional and says so).

Compilation is excluded: every measured run is preceded by an identical warm-up run (the jitted functions are cached
per functions + config). Prints a Markdown table; ``--json FILE`` also writes the numbers.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path
from typing import NamedTuple

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

PRESETS = {
    # size, generations at batch 20, (big batch, its generations), pyribs generations, difficulty batch / gens
    "cpu": dict(size=64, gens_small=20, big_batch=200, gens_big=5, ribs_gens=20, diff_batch=4, diff_gens=1,
                attempts=20, best=5, window=30),
    "gpu": dict(size=256, gens_small=200, big_batch=1000, gens_big=20, ribs_gens=50, diff_batch=1000, diff_gens=2,
                attempts=20, best=5, window=30),
}
PAPER_EVALS = 100 + 5000 * 20


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--preset", choices=sorted(PRESETS), default="cpu")
    p.add_argument("--skip-ribs", action="store_true")
    p.add_argument("--skip-difficulty", action="store_true")
    p.add_argument("--rollout-slots", default="none,8192",
                   help="comma list of difficulty rollout pool sizes to time ('none': every rollout at once)")
    p.add_argument("--rollout-order", default="smooth", help="comma list of pool queue orders to time: smooth "
                   "(smoothest terrains' rollouts first, the default of difficulty_fitness) and / or job")
    p.add_argument("--diff-batch", type=int, default=None, help="offspring per generation with the difficulty "
                   "fitness (default: the preset's; the evolve gpu preset uses 4000)")
    p.add_argument("--json", type=Path, default=None)
    return p.parse_args(argv)


class Bench(NamedTuple):
    """What every part measures on: the Perlin generator at ``size``, the descriptor pair and window."""

    gen: object
    size: int
    window: int
    names: tuple = ("roughness", "tpi")

    def descriptors(self, hm):
        """[B, H, W] -> [B, 2]."""
        from jaxterrain import features

        return features.descriptors(hm, names=self.names, window=self.window, stride=2)

    def traversable(self, hm):
        """[B, H, W] -> [B] bool (Algorithm 1)."""
        from jaxterrain import features

        return features.is_traversable(hm)


def time_evolve(bench: Bench, batch: int, gens: int, fitness_fn, label: str) -> dict:
    """One ``qd.evolve`` run of ``gens`` generations at ``batch``, timed after an identical warm-up run."""
    import jax

    from jaxterrain import qd as A

    config = A.EvolveConfig(generations=gens, batch_size=batch, initial_population=100, bins=50,
                            descriptors=bench.names, window=bench.window, checkpoint_every=gens,
                            store_heightmaps=False)
    cache: dict = {}  # the warm-up's compiled programs, reused by the timed run
    run = lambda c: A.evolve(bench.gen, bench.descriptors, c, jax.random.key(0), fitness_fn=fitness_fn,  # noqa: E731
                             progress=False, traversable_fn=bench.traversable, compile_cache=cache)
    run(config)  # warm-up: compiles init + one chunk of `gens` generations
    t0 = time.perf_counter()
    arch = run(config)
    seconds = time.perf_counter() - t0
    evals = 100 + gens * batch
    row = dict(what=label, batch=batch, generations=gens, seconds=seconds, generations_per_s=gens / seconds,
               evaluations_per_s=evals / seconds, coverage=A.coverage(arch))
    print(f"  {label}: {row['generations_per_s']:.3g} gen/s, {row['evaluations_per_s']:.3g} evals/s "
          f"(coverage {row['coverage']:.1f}%)", flush=True)
    return row


def ribs_rows(bench: Bench, cfg: dict) -> list[dict]:
    """(a) the same MAP-Elites in pyribs on the CPU, at batch 20 and the preset's big batch; [] without pyribs."""
    try:
        import ribs
        from ribs.archives import GridArchive
    except ImportError as err:
        print(f"  pyribs: skipped, not installed ({err}); `pip install ribs` to compare", flush=True)
        return []
    import jax
    import jax.numpy as jnp
    import numpy as np

    from jaxterrain.difficulty import slope_fitness
    from jaxterrain import qd as A

    cpu = jax.devices("cpu")[0]
    ranges = [A.DEFAULT_RANGES[n] for n in bench.names]
    lo, hi = np.asarray(bench.gen.spec.lower), np.asarray(bench.gen.spec.upper)
    is_int = np.asarray(bench.gen.spec.integer)

    @jax.jit
    def evaluate(genomes):
        hm = jax.vmap(bench.gen.render_one)(genomes)
        return jnp.where(bench.traversable(hm), slope_fitness(hm), -jnp.inf), bench.descriptors(hm)

    def ribs_run(gens, batch, seed):
        rng = np.random.default_rng(seed)
        archive = GridArchive(solution_dim=len(lo), dims=(50, 50), ranges=ranges, seed=seed)
        init = np.where(is_int, np.floor(lo + rng.random((100, len(lo))) * (hi - lo + 1)),
                        lo + rng.random((100, len(lo))) * (hi - lo))
        init = np.minimum(init, hi)

        def ev(x):
            with jax.default_device(cpu):
                f, d = evaluate(jnp.asarray(x, jnp.float32))
            f, d = np.asarray(f), np.asarray(d)
            ok = np.isfinite(f)
            if ok.any():
                archive.add(x[ok], f[ok], np.clip(d[ok], [r[0] for r in ranges], [r[1] for r in ranges]))

        ev(init)
        for _ in range(gens):
            parents = archive.sample_elites(batch)["solution"]
            mask = rng.random(parents.shape) < 0.35
            child = np.clip(parents + mask * rng.normal(size=parents.shape) * 0.1 * (hi - lo), lo, hi)
            ev(np.where(is_int, np.round(child), child))
        return archive

    rows = []
    for batch, gens in ((20, cfg["ribs_gens"]), (cfg["big_batch"], max(2, cfg["gens_big"]))):
        ribs_run(1, batch, 0)  # warm-up (compiles the evaluation for both batch shapes)
        t0 = time.perf_counter()
        archive = ribs_run(gens, batch, 1)
        seconds = time.perf_counter() - t0
        rows.append(dict(what=f"pyribs {ribs.__version__} (CPU, eval jitted on CPU)", batch=batch,
                         generations=gens, seconds=seconds, generations_per_s=gens / seconds,
                         evaluations_per_s=(100 + gens * batch) / seconds, coverage=100.0 * len(archive) / 2500))
        print(f"  pyribs batch {batch}: {rows[-1]['generations_per_s']:.1f} gen/s, "
              f"{rows[-1]['evaluations_per_s']:.0f} evals/s", flush=True)
    return rows


def difficulty_fitnesses(bench: Bench, cfg: dict, pools: list, orders: list[str]) -> tuple[dict, str]:
    """``{(slots, order): fitness_fn}`` of the walker difficulty for every pool size and queue order, and a note on
    the policy: the shipped base policy, or a fixed random linear stand-in when it is missing."""
    import jax
    import jax.numpy as jnp

    from jaxterrain import difficulty
    from jaxterrain.walker.rollout import batched_distances
    from jaxterrain.walker.layout import make_env
    from jaxterrain.qd.scoring import ignore_needed

    try:
        difficulty.default_policy()
        return ({(n, o): difficulty.difficulty_fitness(bench.size, cfg["attempts"], cfg["best"], slots=n,
                                              smooth_first=o == "smooth")
                 for n in pools for o in (orders if n is not None else ["job"])}, "shipped base policy")
    except RuntimeError as err:
        note = f"STAND-IN random linear policy (base policy missing: {str(err)[:60]}...)"
    from jaxterrain.terrain import TerrainScale
    from jaxterrain.walker import WalkerConfig

    env = make_env(WalkerConfig(terrain_shape=(bench.size, bench.size), scale=TerrainScale()))
    w = 0.1 * jax.random.normal(jax.random.key(42), (env.observation_size, env.action_size))

    def fitness(hm, key):
        d, _ = batched_distances(env, lambda obs: jnp.tanh(obs @ w), hm * TerrainScale().height, key,
                                            cfg["attempts"])
        return difficulty.best_of(d, cfg["best"])

    return {(None, "job"): ignore_needed(fitness)}, note


def print_table(rows: list[dict]) -> None:
    print("\n| what | batch | generations | gen/s | evals/s | coverage % |\n| --- | --- | --- | --- | --- | --- |")
    for r in rows:
        print(f"| {r['what']} | {r['batch']} | {r['generations']} | {r['generations_per_s']:.2f} | "
              f"{r['evaluations_per_s']:.1f} | {r['coverage']:.1f} |")


def main(argv=None) -> int:
    args = parse_args(argv)
    cfg = dict(PRESETS[args.preset])
    if args.diff_batch is not None:
        cfg["diff_batch"] = args.diff_batch

    import jax

    from jaxterrain.difficulty import slope_fitness
    from jaxterrain import generators
    from jaxterrain.qd.scoring import ignore_needed

    bench = Bench(generators.get("perlin", size=cfg["size"]), cfg["size"], cfg["window"])
    device = jax.devices()[0]
    results = {"device": str(device), "platform": platform.platform(), "jax": jax.__version__, "preset": args.preset,
               "size": bench.size}
    print(f"device: {device}  (jax {jax.__version__}), terrains {bench.size} x {bench.size}", flush=True)

    print("(a) cheap fitness", flush=True)
    slope = ignore_needed(slope_fitness)
    rows = [time_evolve(bench, 20, cfg["gens_small"], slope, f"jaxterrain evolve on {device.platform}"),
            time_evolve(bench, cfg["big_batch"], cfg["gens_big"], slope, f"jaxterrain evolve on {device.platform}")]
    if args.skip_ribs:
        print("  pyribs: skipped (--skip-ribs)", flush=True)
    else:
        rows += ribs_rows(bench, cfg)

    if args.skip_difficulty:
        print("(b) difficulty: skipped (--skip-difficulty)", flush=True)
    else:
        print(f"(b) difficulty fitness ({cfg['attempts']} attempts, best {cfg['best']})", flush=True)
        pools = [None if v == "none" else int(v) for v in args.rollout_slots.split(",") if v]
        orders = [v for v in args.rollout_order.split(",") if v]
        fitnesses, note = difficulty_fitnesses(bench, cfg, pools, orders)
        print(f"  policy: {note}", flush=True)
        results["difficulty_policy"] = note
        results["paper_treatment_estimate_s"] = {}
        for (slots, order), fitness in fitnesses.items():
            # with a pool, the fitness skips the rollouts of terrains that Algorithm 1 rejects (needed=)
            label = f"slots {slots or 'all'}" + (f", {order} order" if slots is not None else "")
            row = time_evolve(bench, cfg["diff_batch"], cfg["diff_gens"], fitness,
                              f"jaxterrain evolve, difficulty fitness, rollout {label}")
            rows.append(row)
            estimate = PAPER_EVALS / row["evaluations_per_s"]
            results["paper_treatment_estimate_s"][label] = estimate
            print(f"  estimated paper-scale treatment ({PAPER_EVALS} evaluations x {cfg['attempts']} attempts): "
                  f"{estimate / 60:.1f} min ({estimate / 3600:.2f} h) at batch {cfg['diff_batch']}, {label}",
                  flush=True)

    print_table(rows)
    results["rows"] = rows
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(results, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
