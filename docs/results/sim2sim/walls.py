"""Why the ant stalls on Perlin maps under MuJoCo C: the side walls of the heightfield's prisms.

    PYTHONPATH=. python docs/results/sim2sim/walls.py --out docs/results/sim2sim/walls.json   # CPU, ~1 min

MJX-JAX's sphere-heightfield collision (``mujoco/mjx/_src/collision_convex.py``, ``_hfield_collision``) replaces
every contact normal whose vertical component is below 1e-6 (a prism's vertical side wall) by the normal of the
prism's top face ("resolves issues with cracks of doom"), and keeps at most 4 contacts per foot. C MuJoCo keeps the
side walls' horizontal normals. This walks ``--policy`` (default the ant's base policy) on the ``measure.py`` Perlin
maps ``--maps`` (default 7, the ant's largest gap: C 0.045, MJX 0.941) under MuJoCo C from the protocol's first
``--walks`` starts and counts, every env step, the foot contacts whose normal is within 45 degrees of horizontal
(``|n_z| < 0.707``) and within 5 degrees of it (``|n_z| < 0.087``: a wall), and how far the walk got.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default=None)
    p.add_argument("--policy", default=None, help="policy folder (default: the ant's base policy)")
    p.add_argument("--maps", type=int, nargs="+", default=[7],
                   help="indices of the Perlin maps of measure.py (default 7)")
    p.add_argument("--walks", type=int, default=4)
    p.add_argument("--steps", type=int, default=400)
    args = p.parse_args(argv)

    import jax
    import jax.numpy as jnp
    import mujoco
    import numpy as np

    from jaxterrain import difficulty, generators, rl
    from jaxterrain.rl.checkpoint import base_policy_dir
    from jaxterrain.runtime.io import atomic_write_text
    from jaxterrain.walker import CEngine, WalkerEnv

    pol = rl.load_policy(args.policy or base_policy_dir("ant"))
    gen = generators.get("perlin", size=256)
    maps = np.asarray(gen.render(gen.sample(jax.random.key(62), 32)))  # measure.py's Perlin maps
    cfg = difficulty.default_env_config((256, 256), policy=pol)
    env = WalkerEnv(cfg)
    engine = CEngine(env)
    keys = jax.random.split(jax.random.key(0), (1, 20))[0, :args.walks]  # measure.py's keys: walk a of the map
    act = jax.jit(pol)
    observe, controls = jax.jit(env.observe), jax.jit(env.controls)
    out = {"policy": str(pol.path), "steps": args.steps, "maps": {}}
    for i in args.maps:
        terrain = maps[i] * np.float32(cfg.scale.height)
        start = engine.starts(keys, np.broadcast_to(terrain, (args.walks,) + terrain.shape))
        m = engine.model(terrain)
        floor = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "floor")
        walks = []
        for w in range(args.walks):
            d = mujoco.MjData(m)
            d.qpos[:], d.qvel[:] = start.qpos[w], start.qvel[w]
            mujoco.mj_forward(m, d)
            slanted = walls = total = 0
            for _ in range(args.steps):
                obs = observe(jnp.asarray(d.qpos, jnp.float32), jnp.asarray(d.qvel, jnp.float32),
                              jnp.asarray(terrain))
                d.ctrl[:] = np.asarray(controls(act(obs))[0])
                mujoco.mj_step(m, d, nstep=cfg.n_frames)
                for k in range(d.ncon):
                    c = d.contact[k]
                    if floor in (c.geom1, c.geom2) and c.dist < 0:
                        nz = abs(c.frame[2])
                        total += 1
                        slanted += nz < 0.707
                        walls += nz < 0.087
            x = float((d.qpos[0] - start.x_start[w]) / env.track_length)
            walks.append(dict(distance_after_steps=round(x, 3), contacts=total,
                              within_45deg_of_horizontal=int(slanted), walls_within_5deg=int(walls)))
        wall_share = sum(w["walls_within_5deg"] for w in walks) / max(sum(w["contacts"] for w in walks), 1)
        out["maps"][i] = dict(walks=walks, wall_share=round(wall_share, 4),
                              mean_distance=round(float(np.mean([w["distance_after_steps"] for w in walks])), 3))
        print(i, json.dumps({k: v for k, v in out["maps"][i].items() if k != "walks"}), flush=True)
    if args.out:
        atomic_write_text(Path(args.out), json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
