"""Warp contacts of the ant's reset pose on one map placed at each of several tiles of a T-tile bank."""
import sys, os
sys.path.insert(0, "docs/results/sim2sim")
import numpy as np, jax, jax.numpy as jnp, mujoco
import ant_budget as ab
from mujoco.mjx.third_party import mujoco_warp as mjw
from jaxterrain import difficulty, rl
from jaxterrain.rl.checkpoint import BASE_POLICY_DIR
from jaxterrain.walker import WalkerEnv
from jaxterrain.terrain import TerrainScale
h, labels = ab.maps("sim2sim", False)
policy = rl.load_policy(BASE_POLICY_DIR.parent / "base_policy_ant")
base = difficulty.default_env_config(tuple(h.shape[1:]), policy=policy)
T = int(sys.argv[1]); MAP = int(sys.argv[2]); KEY = int(os.environ.get("KEY", "1"))
tiles = [int(v) for v in sys.argv[3].split(",")] if len(sys.argv) > 3 else list(range(T))
env = WalkerEnv(base._replace(tiles=T))
mjm = env.mj_model
m = None
for t in tiles:
    hm = np.zeros((T,) + h.shape[1:], np.float32); hm[t] = h[MAP] * TerrainScale().height  # other tiles flat
    bank = env.make_bank(jnp.asarray(hm))
    s = env.reset(jax.random.split(jax.random.key(0), 3)[KEY], bank.at(t))
    mjm.hfield_data[:] = np.asarray(bank.data).reshape(-1)
    mjd = mujoco.MjData(mjm); mjd.qpos[:] = np.asarray(s.data.qpos); mjd.qvel[:] = np.asarray(s.data.qvel)
    mujoco.mj_forward(mjm, mjd)
    feet = [g for g in range(mjm.ngeom) if mjm.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE and (mjm.geom_conaffinity[g] | mjm.geom_contype[g])]
    clear = [mjd.geom_xpos[g][2] - mjm.geom_size[g, 0] - float(env.terrain_height(bank.at(t), mjd.geom_xpos[g][0], mjd.geom_xpos[g][1])) for g in feet]
    print("  feet bottom above terrain under centre (m):", np.round(clear, 3), " sphere fully buried:", [c < -2 * mjm.geom_size[g, 0] for c, g in zip(clear, feet)])
    m = mjw.put_model(mjm)
    d = mjw.put_data(mjm, mjd, nworld=1, naconmax=512, njmax=2048)
    mjw.forward(m, d)
    n = int(d.nacon.numpy()[0]); dist = d.contact.dist.numpy()[:n]
    ox, oy = (float(v) for v in env.tile_origin(t))
    print(f"T={T} map {labels[MAP]} tile {t} origin ({ox:+.2f},{oy:+.2f}) torso world ({mjd.qpos[0]:+.2f},{mjd.qpos[1]:+.2f}): "
          f"Warp min dist {dist.min():+.4f} qacc max {np.abs(d.qacc.numpy()[0]).max():.0f} | C min dist {mjd.contact.dist[:mjd.ncon].min():+.4f} qacc max {np.abs(mjd.qacc).max():.0f}", flush=True)
