"""Step the ant on chosen tiles of a T-tile bank (the 73 sim2sim maps), print per env why walks end."""
import sys, time
sys.path.insert(0, "docs/results/sim2sim")
import numpy as np, jax, jax.numpy as jnp
import ant_budget as ab
from jaxterrain import difficulty, rl
from jaxterrain.rl.checkpoint import BASE_POLICY_DIR, policy_fn
from jaxterrain.walker import WalkerEnv, TILE_AXES
from jaxterrain.terrain import TerrainScale
backend = sys.argv[1]; ntiles = int(sys.argv[2]); pick = [int(v) for v in sys.argv[3].split(",")]
nsteps = int(sys.argv[4]) if len(sys.argv) > 4 else 6
order = sys.argv[5] if len(sys.argv) > 5 else "first"   # which maps fill the bank
h, labels = ab.maps("sim2sim", False)
policy = rl.load_policy(BASE_POLICY_DIR.parent / "base_policy_ant")
base = difficulty.default_env_config(tuple(h.shape[1:]), policy=policy)
att = 3
n = len(pick) * att
cfg = base._replace(backend=backend, tiles=ntiles, **({"warp_worlds": n, "warp_contacts": 16, "warp_njmax": 96} if backend == "warp" else {}))
env = WalkerEnv(cfg)
print("grid", env.grid, "hfield", env.mj_model.hfield_nrow, env.mj_model.hfield_ncol, "size", env.mj_model.hfield_size, flush=True)
# bank: tile k holds map pick[k] for k < len(pick) when order == "pick", else tile i holds map i (first ntiles maps; picks must be < ntiles)
hm = h * TerrainScale().height
if order == "pick":
    maps = list(pick) + [m for m in range(len(h)) if m not in pick][: ntiles - len(pick)]
    tiles_of = list(range(len(pick)))
elif order.startswith("at:"):
    tiles_of = [int(v) for v in order[3:].split(",")]
    rest = [m for m in range(len(h)) if m not in pick]
    maps = [None] * ntiles
    for m_, t_ in zip(pick, tiles_of): maps[t_] = m_
    for t_ in range(ntiles):
        if maps[t_] is None: maps[t_] = rest.pop(0)
else:
    maps = list(range(ntiles)); tiles_of = pick
bank = env.make_bank(jnp.asarray(hm[maps]))
idx = jnp.repeat(jnp.asarray(tiles_of, jnp.int32), att)
keys = jax.random.split(jax.random.key(0), n)
act = policy_fn(policy.config, int(policy.action_size)); params = (policy.params, policy.normaliser)
reset = jax.jit(jax.vmap(env.reset, in_axes=(0, TILE_AXES)))
def stepf(s, b, i):
    a = jax.vmap(lambda o: act(params, o))(s.obs)
    s2 = jax.vmap(env.step, in_axes=(0, 0, TILE_AXES))(s, a, b.at(i))
    # raw physics without the invalid rollback, to see what Warp did
    m = env.model(b)
    d = s.data.replace(ctrl=jax.vmap(lambda x: env.controls(x)[0])(a))
    if backend == "warp":
        d = d.replace(_impl=d._impl.replace(overflow=jnp.zeros_like(d._impl.overflow)))
    d = jax.vmap(lambda dd: jax.lax.fori_loop(0, cfg.n_frames, lambda _, q: __import__("mujoco").mjx.step(m, q), dd))(d) if False else d
    ov = s2.data._impl.overflow if backend == "warp" else jnp.zeros(n, jnp.int32)
    return s2, ov
stepj = jax.jit(stepf)
s = reset(keys, bank.at(idx))
ox, oy = jax.vmap(env.tile_origin)(idx)
def show(t, s, ov=None):
    q = np.asarray(s.data.qpos); v = np.asarray(s.data.qvel)
    for e in range(n):
        x, y = q[e, 0] - float(ox[e]), q[e, 1] - float(oy[e])
        ground = float(env.terrain_height(bank.at(idx[e]), q[e, 0], q[e, 1]))
        print(f"t={t} env {e} map {maps[int(idx[e])]:2d} ({labels[maps[int(idx[e])]]}) tile {int(idx[e])} x={x:+.3f} y={y:+.3f} z={q[e,2]:.3f} ground={ground:.3f} "
              f"|qv|max={np.abs(v[e]).max():.1f} done={float(s.done[e]):.0f} failed={float(s.failed[e]):.0f} "
              f"steps={int(s.steps[e])} ov={'' if ov is None else np.asarray(ov).reshape(n, -1)[e].tolist()} ncon={'' if backend!='warp' else ''}", flush=True)
show(0, s)
for t in range(1, nsteps + 1):
    s, ov = stepj(s, bank, idx)
    show(t, s, ov)
