"""Run: PYTHONPATH=. python docs/results/exp4/scan_diag/warp_surface.py jax|warp (CPU; warp needs warp-lang).
Does the physical surface (MJX-JAX vs MuJoCo Warp on the CPU, one tile) match the array the scan reads? Walk the
perceptive base policy on an x/y step terrain; for each step, each foot's clearance = foot bottom z - heights(foot xy)
(the scan's height function). Feet in contact sit at ~0 (minus penetration) if physics and array agree."""
import sys, numpy as np, jax, jax.numpy as jnp
from jaxterrain import rl
from jaxterrain.walker import WalkerEnv, WalkerConfig
backend = sys.argv[1]
t = np.zeros((256, 256), np.float32)
xs = np.arange(256)
for k in range(10):
    t[:, 30 + 10 * k:] += 0.04          # 4 cm risers every 0.4 m along +x
t[128:, :] += 0.06                          # +6 cm for y > 0: a transposed / flipped surface would show
t += 0.1
pol = rl.load_policy(rl.base_policy_dir('humanoid', 'perceptive'))
cfg = WalkerConfig(observation="perceptive")
if backend == "warp":
    cfg = cfg._replace(backend="warp", tiles=1, warp_worlds=4)
env = WalkerEnv(cfg)
terrain = env.make_bank(jnp.asarray(t)[None]).at(0) if backend == "warp" else jnp.asarray(t)
reset = jax.jit(jax.vmap(env.reset, in_axes=(0, None)))
step = jax.jit(jax.vmap(env.step, in_axes=(0, 0, None)))
s = reset(jax.random.split(jax.random.PRNGKey(0), 4), terrain)
feet = env._feet; r = env._foot_radius
clear, scanerr = [], []
ox, oy = env.tile_origin(0)
for i in range(120):
    s = step(s, jax.vmap(pol)(s.obs), terrain)
    g = np.asarray(s.data.geom_xpos)[:, feet]      # [E, feet, 3]
    h = np.asarray(jax.vmap(lambda x, y: env.terrain_height(terrain, x, y))(jnp.asarray(g[..., 0]) - ox, jnp.asarray(g[..., 1]) - oy))
    c = g[..., 2] - r - h
    alive = np.asarray(s.done) == 0
    clear.append(np.where(alive[:, None], c, np.nan))
clear = np.array(clear)  # [T, E, feet]
print(backend, 'x reached', np.round(np.asarray(s.data.qpos[:, 0] - ox), 2), 'y', np.round(np.asarray(s.data.qpos[:, 1] - oy), 2))
lo = np.nanpercentile(clear, [1, 5, 50], axis=0)  # per env, foot
print(backend, 'foot clearance percentiles 1/5/50 over steps (m), env x foot:\n', np.round(lo, 3))
print(backend, 'min over everything', np.nanmin(clear))
