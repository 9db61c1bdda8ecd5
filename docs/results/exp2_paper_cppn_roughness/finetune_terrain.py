"""PPO fine-tuning of the base policy on one terrain of the CPPN HEADINGS archive, on a CPU, with the curriculum's
fine-tuning PPO (``CurriculumConfig().ppo_config``) but NUM_ENVS envs, spread over the given headings (env e walks
heading HEADINGS[e % len(HEADINGS)]). After every block of PER_BLOCK updates: the mean length of the envs' last
training episode per heading, 4 deterministic walks of at most 100 env steps per heading (steps walked / distance),
and the PPO losses' value loss, approx. KL, clip fraction and entropy, and the mean training episode return, at the
block's first and last update.

    python docs/results/exp2_paper_cppn_roughness/finetune_terrain.py \
        HEADINGS NUM_ENVS BLOCKS PER_BLOCK [CELL [LR [TRUNC]]]
    e.g. 0,1,2,3 64 8 20 152   (cell 152 = bank terrain 31, the baseline's second terrain; cell 0 = its first;
    LR: Adam's learning rate, default the curriculum's 3e-4; TRUNC: PPOConfig.truncation, mask (default) or bootstrap)
"""
import sys, time
import jax, jax.numpy as jnp, numpy as np
from jaxterrain import qd as A, difficulty as D, rl
from jaxterrain.qd import bank as B
from jaxterrain.curriculum import walker as W
from jaxterrain.curriculum.config import CurriculumConfig
from jaxterrain.terrain import TerrainScale

headings = [int(h) for h in sys.argv[1].split(",")]
num_envs, blocks, per_block = int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
arch = A.load("docs/results/exp2_cppn_headings_archive.npz")
cell = int(sys.argv[5]) if len(sys.argv) > 5 else 152
maps = np.asarray(B._render_filled(arch, np.array([cell]), 8))[0]
policy = rl.load_policy()
env = W.walker_env(policy, maps.shape, TerrainScale())
ppo = CurriculumConfig().ppo_config(policy.config)._replace(num_envs=num_envs)
if len(sys.argv) > 6:
    ppo = ppo._replace(learning_rate=float(sys.argv[6]))
if len(sys.argv) > 7:
    ppo = ppo._replace(truncation=sys.argv[7])
print(ppo)
state = W.start_state(env, ppo, policy, maps.shape)
turned = jnp.stack([jnp.rot90(jnp.asarray(maps), k) for k in range(4)])
env_heading = jnp.asarray([headings[e % len(headings)] for e in range(num_envs)])
terrains = turned[env_heading]
state = jax.jit(lambda s, k: rl.reset_envs(s, k, terrains, env=env, config=ppo))(state, jax.random.key(1))
run = jax.jit(lambda s: rl.run_updates(s, terrains, env=env, config=ppo, num_updates=per_block))
act = rl.policy_fn(ppo, env.action_size)

@jax.jit
def probe(params):
    def walk(terrain, key):
        def body(carry, _):
            s, alive = carry
            s2 = env.step(s, act(params, s.obs), terrain)
            return (s2, alive & (s2.done == 0)), (alive, s2.distance)
        alive, dist = jax.lax.scan(body, (env.reset(key, terrain), jnp.bool_(True)), None, length=100)[1]
        return alive.sum(), dist[jnp.maximum(alive.sum() - 1, 0)]
    return jax.vmap(lambda t: jax.vmap(lambda k: walk(t, k))(jax.random.split(jax.random.key(7), 4)))(turned)

def show(tag, state):
    L = np.asarray(state.episode.last_length); eh = np.asarray(env_heading)
    steps, dist = [np.asarray(x) for x in probe((state.params, state.normaliser))]
    per = " ".join(f"h{h}:{L[eh == h].mean():.0f}" for h in headings)
    walk = " ".join(f"h{h}:{steps[h].mean():.0f}/{dist[h].mean():.3f}" for h in range(4))
    print(f"{tag}: train ep len {per} | probe steps/dist {walk}", flush=True)

show("start", state)
t0 = time.time()
for b in range(blocks):
    state, metrics = run(state)
    jax.block_until_ready(state)
    show(f"update {(b + 1) * per_block} ({time.time() - t0:.0f} s, env steps {int(state.env_steps)})", state)
    m = {k: np.asarray(v) for k, v in metrics.items()}
    print("  sgd, first / last update of the block: " + " ".join(
        f"{k} {m[k][0]:.4g}/{m[k][-1]:.4g}" for k in ("value_loss", "approx_kl", "clip_fraction", "entropy",
                                                     "episode_return")), flush=True)
