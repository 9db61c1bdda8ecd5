"""Where fine-tuning's value net diverges: PPO fine-tuning of the base policy on one terrain of the CPPN HEADINGS
archive (CPU; the curriculum's fine-tuning PPO with 64 envs spread over HEADINGS), one update at a time. After each
update one more batch is collected with the current params (not trained on) and its steps are split by kind: the
first step of an episode, terminal ends (falls), truncated ends (the goal or the time limit). For each kind: the
value predictions V, the GAE targets, the rewards, and the torso-height observation (component 0) raw and
normalised by the running statistics.

    python docs/results/exp2_paper_cppn_roughness/value_divergence.py CELL HEADINGS UPDATES [TRUNCATION]
    e.g. 152 0,1,3 8 mask   (cell 152 = bank terrain 31, the baseline's second terrain; TRUNCATION: PPOConfig's,
    mask (the default, brax's) or bootstrap)


Pinned: it reads private functions of the package as they were at commit ac5ee06; run it at that commit
(``git worktree add /tmp/at-ac5ee06 ac5ee06``). Kept as the record of how its figures were made."""
import sys
import jax, jax.numpy as jnp, numpy as np
from jaxterrain import qd as A, rl
from jaxterrain.qd import bank as B
from jaxterrain.rl import networks as nets
from jaxterrain.rl.losses import gae
from jaxterrain.rl.ppo import _collect
from jaxterrain.curriculum import walker as W
from jaxterrain.curriculum.config import CurriculumConfig
from jaxterrain.terrain import TerrainScale

cell, headings, updates = int(sys.argv[1]), [int(h) for h in sys.argv[2].split(",")], int(sys.argv[3])
arch = A.load("docs/results/exp2_cppn_headings_archive.npz")
maps = np.asarray(B._render_filled(arch, np.array([cell]), 8))[0]
policy = rl.load_policy()
env = W.walker_env(policy, maps.shape, TerrainScale())
ppo = CurriculumConfig().ppo_config(policy.config)._replace(num_envs=64)
if len(sys.argv) > 4:
    ppo = ppo._replace(truncation=sys.argv[4])
print(ppo)
state = W.start_state(env, ppo, policy, maps.shape)
turned = jnp.stack([jnp.rot90(jnp.asarray(maps), k) for k in range(4)])
terrains = turned[jnp.asarray([headings[e % len(headings)] for e in range(64)])]
state = jax.jit(lambda s, k: rl.reset_envs(s, k, terrains, env=env, config=ppo))(state, jax.random.key(1))
run = jax.jit(lambda s: rl.run_updates(s, terrains, env=env, config=ppo, num_updates=1))
mask_ppo = ppo._replace(truncation="mask")  # collect with ends flagged, to split the steps by kind


@jax.jit
def look(s):
    data, boot = _collect(s, jax.random.key(5), terrains, env, mask_ppo)[2:4]  # [K, T, N, ...], [K, N, O]
    v = nets.value_apply(ppo, s.params, s.normaliser, data.obs)
    last = nets.value_apply(ppo, s.params, s.normaliser, boot)
    _, targets = jax.vmap(lambda r, vv, d, lv, tr: gae(r * ppo.reward_scaling, vv, d, lv, ppo.gamma, ppo.gae_lambda,
                                                        tr))(data.reward, v, data.done, last, data.truncation)
    return data, v, targets, nets.normalize(s.normaliser, data.obs)


for u in range(updates):
    state, metrics = run(state)
    data, v, targets, z = [jax.device_get(x) for x in look(state)]
    d, tr, r, raw = (np.asarray(data.done), np.asarray(data.truncation), np.asarray(data.reward),
                     np.asarray(data.obs))
    v, targets, z = np.asarray(v), np.asarray(targets), np.asarray(z)
    first = np.concatenate([np.zeros_like(d[:, :1]), d[:, :-1]], axis=1) > 0  # the step after an end
    kinds = {"all steps": np.ones_like(d, bool), "first of episode": first, "terminal end": (d > 0) & (tr == 0),
             "truncated end": tr > 0}
    print(f"update {u + 1}: value loss {float(metrics['value_loss'][0]):.4g}", flush=True)
    for k, m in kinds.items():
        if m.any():
            print(f"   {k:16s} n {m.sum():5d}  V mean/max {v[m].mean():10.1f} / {v[m].max():10.1f}  target mean "
                  f"{targets[m].mean():10.1f}  reward {r[m].mean():5.2f}  torso height {raw[..., 0][m].mean():.3f} m "
                  f"(normalised {z[..., 0][m].mean():5.1f}, max {np.abs(z[..., 0][m]).max():5.1f})", flush=True)
