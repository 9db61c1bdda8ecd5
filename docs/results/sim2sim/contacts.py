"""Where MuJoCo C and MJX-JAX disagree before any dynamics: the contacts and the contact forces of ONE state.

    PYTHONPATH=. python docs/results/sim2sim/contacts.py --out docs/results/sim2sim/contacts.json   # CPU, ~2 min

The humanoid in its start pose is put down at ``--points`` places along the track of a flat map and of suite v1's
``stairs_up`` map with ``--step`` m steps (256 x 256, 4 cm), its lower foot ``--sink`` m into the ground under it,
at rest. Both engines run one ``forward`` on that same state (the same MjModel: C ``mj_forward``, MJX ``mjx.forward``
of ``mjx.put_model`` of it) and we compare what the terrain does to the body: the number of foot contacts with
penetration (``dist < 0``), the deepest penetration, and the constraint force on the free root (``qfrc_constraint
[:3]``, N: the terrain's push on the body after the contact solve). On flat ground the two see the same contacts;
across a stair's edge C MuJoCo's sphere-heightfield collision (the sphere against the heightfield's triangular
prisms) and MJX-JAX's own heightfield routine can differ (MuJoCo issue #1730).
"""

from __future__ import annotations

import argparse
import json
import sys
import time


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default=None, help="write the per-place figures and the summary here (JSON)")
    p.add_argument("--points", type=int, default=64, help="places along the track (default 64)")
    p.add_argument("--step", type=float, default=0.15, help="stair height, m (default 0.15: level 6 of stairs_up)")
    p.add_argument("--sink", type=float, default=0.01, help="how deep the lower foot sits in the ground, m")
    p.add_argument("--size", type=int, default=256, help="map side in pixels (default 256)")
    args = p.parse_args(argv)

    import jax
    import jax.numpy as jnp
    import mujoco
    import numpy as np
    from mujoco import mjx

    from jaxterrain import difficulty, rl, suite
    from jaxterrain.runtime.io import atomic_write_text
    from jaxterrain.walker import WalkerEnv
    from jaxterrain.walker.mujoco_c import CEngine

    pol = rl.load_policy()
    env = WalkerEnv(difficulty.default_env_config((args.size, args.size), policy=pol))
    engine = CEngine(env)
    mm = env.mj_model
    feet = [mujoco.mj_name2id(mm, mujoco.mjtObj.mjOBJ_GEOM, n) for n in env.robot.foot_geoms]
    floor = mujoco.mj_name2id(mm, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    maps = {"flat": np.zeros((args.size, args.size), np.float32),
            f"stairs_up {args.step:g} m": suite.build_terrain("stairs_up", args.step, args.size) * env.elevation_z}
    xs = np.linspace(env.x_start, env.x_goal, args.points)
    out = {"points": args.points, "sink_m": args.sink, "maps": {}}
    t0 = time.perf_counter()
    for name, terrain in maps.items():
        model_c = engine.model(terrain)
        mx = env.model(jnp.asarray(terrain))
        d0 = mujoco.MjData(model_c)
        qpos = np.tile(np.asarray(model_c.qpos0, np.float64), (args.points, 1))
        qpos[:, 0] = xs
        rows = []
        for i in range(args.points):  # the lower foot `sink` into the terrain under it (C geometry, bilinear heights)
            d0.qpos[:] = qpos[i]
            mujoco.mj_kinematics(model_c, d0)
            ground = [float(env.terrain_height(jnp.asarray(terrain), d0.geom_xpos[g, 0], d0.geom_xpos[g, 1]))
                      for g in feet]
            gap = min(d0.geom_xpos[g, 2] - model_c.geom_size[g, 0] - ground[k] for k, g in enumerate(feet))
            qpos[i, 2] -= gap + args.sink
        # C
        c = []
        for i in range(args.points):
            d = mujoco.MjData(model_c)
            d.qpos[:] = qpos[i]
            mujoco.mj_forward(model_c, d)
            con = [d.contact[j] for j in range(d.ncon) if floor in (d.contact[j].geom1, d.contact[j].geom2)]
            c.append(dict(n=sum(1 for k in con if k.dist < 0), depth=-min([k.dist for k in con] + [0.0]),
                          force=d.qfrc_constraint[:3].tolist()))
        # MJX-JAX
        fwd = jax.jit(jax.vmap(lambda q: mjx.forward(mx, mjx.make_data(mx).replace(qpos=q))))
        dx = fwd(jnp.asarray(qpos, jnp.float32))
        dist = np.asarray(dx._impl.contact.dist if hasattr(dx, "_impl") and hasattr(dx._impl, "contact")
                          else dx.contact.dist)
        geom = np.asarray(dx._impl.contact.geom if hasattr(dx, "_impl") and hasattr(dx._impl, "contact")
                          else dx.contact.geom)
        qfrc = np.asarray(dx.qfrc_constraint)[:, :3]
        for i in range(args.points):
            on_floor = (geom[i] == floor).any(axis=-1)
            real = on_floor & (dist[i] < 0)
            m = dict(n=int(real.sum()), depth=float(-min(dist[i][on_floor].min(initial=0.0), 0.0)),
                     force=qfrc[i].tolist())
            rows.append(dict(x=float(xs[i]), c=c[i], mjx=m))
        fz_c = np.array([r["c"]["force"][2] for r in rows])
        fz_m = np.array([r["mjx"]["force"][2] for r in rows])
        fx_c = np.array([r["c"]["force"][0] for r in rows])
        fx_m = np.array([r["mjx"]["force"][0] for r in rows])
        n_c = np.array([r["c"]["n"] for r in rows])
        n_m = np.array([r["mjx"]["n"] for r in rows])
        summary = dict(contacts_differ=int((n_c != n_m).sum()), mean_contacts_c=float(n_c.mean()),
                       mean_contacts_mjx=float(n_m.mean()),
                       mean_abs_fz_diff_N=float(np.abs(fz_c - fz_m).mean()),
                       max_abs_fz_diff_N=float(np.abs(fz_c - fz_m).max()),
                       mean_abs_fx_diff_N=float(np.abs(fx_c - fx_m).mean()),
                       max_abs_fx_diff_N=float(np.abs(fx_c - fx_m).max()),
                       mean_fz_c_N=float(fz_c.mean()), mean_fz_mjx_N=float(fz_m.mean()))
        out["maps"][name] = dict(summary=summary, rows=rows)
        print(f"{name}: {json.dumps(summary)}", flush=True)
    out["seconds"] = round(time.perf_counter() - t0, 1)
    if args.out:
        atomic_write_text(args.out, json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
