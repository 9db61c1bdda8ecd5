"""Does a robot's terrain fitness depend on the physics backend and layout? One robot, its shipped base policy, the
same keys and terrains under MJX-JAX (classic: one heightfield per env; tiles: one heightfield of tiles) and MuJoCo
Warp (tiles, at the robot's contact budget and at a larger one).

    python benchmarks/ant_backends.py [--robot ant] [--terrains 32] [--size 256] [--backends jax,warp]
        [--contacts 48 --njmax 240] [--out r.json]

Terrains: 4 flat, then ``--terrains`` Perlin terrains (``generators.get("perlin")``, key 3), 20 walks each (key 1),
fitness the best 5 of 20 (``difficulty.rollout_distances``). Prints one JSON line per variant: flat mean of all
walks, Perlin fitness mean, and the mean and largest per-terrain difference against MJX-JAX classic. On a GPU two
runs of one variant already differ per terrain (``benchmarks/determinism.py``: up to 0.11 for the humanoid); a mean
difference across many terrains that a second run of the same variant does not show is the backend's.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--robot", default="ant", help="a registered robot with a shipped base policy")
    p.add_argument("--terrains", type=int, default=32, help="Perlin terrains (after 4 flat ones)")
    p.add_argument("--size", type=int, default=256, help="terrain samples per side")
    p.add_argument("--backends", default="jax,warp", help="jax (classic and tiles) and / or warp (tiles)")
    p.add_argument("--contacts", type=int, default=None, help="warp's larger budget: contacts per env (default 3x the "
                   "robot's)")
    p.add_argument("--njmax", type=int, default=None, help="warp's larger budget: constraint rows per env (default 3x)")
    p.add_argument("--out", default=None, help="JSON result path (per-terrain fitness of every variant)")
    args = p.parse_args(argv)
    if args.terrains < 1 or args.size < 4:
        p.error("--terrains must be >= 1 and --size >= 4")
    if not set(args.backends.split(",")) <= {"jax", "warp"}:
        p.error(f"--backends must be a comma list of jax, warp; got {args.backends!r}")
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    import jax
    import jax.numpy as jnp
    import numpy as np

    from common import environment, write_json
    from jaxterrain import difficulty, generators

    gen = generators.get("perlin", size=args.size)
    maps = jnp.clip(jnp.asarray(gen.render(gen.sample(jax.random.PRNGKey(3), args.terrains)), jnp.float32), 0, 1)
    maps = jnp.concatenate([jnp.zeros((4, args.size, args.size)), maps])
    policy = difficulty.robot_base_policy(args.robot)
    base = difficulty.default_env_config((args.size, args.size), policy=policy)
    variants = {}
    if "jax" in args.backends.split(","):
        variants.update({"jax/classic": base, "jax/tiles": base._replace(tiles=1)})
    if "warp" in args.backends.split(","):
        w = base._replace(backend="warp", tiles=1)
        from jaxterrain.walker import robots

        spec = robots.get(args.robot)
        contacts = args.contacts or 3 * spec.default("warp_contacts")
        njmax = args.njmax or 3 * spec.default("warp_njmax")
        variants[f"warp/tiles c{spec.default('warp_contacts')}"] = w  # the robot's budget (its defaults)
        variants[f"warp/tiles c{contacts}"] = w._replace(warp_contacts=contacts, warp_njmax=njmax)
    result, ref = {"environment": environment(), "robot": args.robot, "variants": {}}, None
    for name, cfg in variants.items():
        t = time.time()
        d = np.asarray(difficulty.rollout_distances(maps, jax.random.PRNGKey(1), 20, policy=policy, env_config=cfg))
        fit = np.sort(d, 1)[:, -5:].mean(1)
        ref = fit if ref is None else ref
        row = {"variant": name, "flat_all": float(d[:4].mean()), "perlin_fitness_mean": float(fit[4:].mean()),
               "perlin_all_mean": float(d[4:].mean()), "vs_first_mean_diff": float((fit - ref)[4:].mean()),
               "vs_first_max_abs": float(np.abs(fit - ref)[4:].max()), "seconds": round(time.time() - t, 1)}
        print(json.dumps(row), flush=True)
        result["variants"][name] = {**row, "fitness": fit.tolist(), "all": d.mean(1).tolist()}
    write_json(args.out, result)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
