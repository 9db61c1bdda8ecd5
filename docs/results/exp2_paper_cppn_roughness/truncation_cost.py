"""CPU cost of PPOConfig.truncation="bootstrap" (one more value-net call per env step): the curriculum's fine-tuning PPO
with 64 envs on terrain 31, 4-update calls, 12 updates timed after a warm-up call, mask then bootstrap, twice.

    python docs/results/exp2_paper_cppn_roughness/truncation_cost.py
"""
import time, sys
import jax, jax.numpy as jnp, numpy as np
from jaxterrain import qd as A, rl
from jaxterrain.qd import bank as B
from jaxterrain.curriculum import walker as W
from jaxterrain.curriculum.config import CurriculumConfig
from jaxterrain.terrain import TerrainScale
arch = A.load("docs/results/exp2_cppn_headings_archive.npz")
maps = np.asarray(B._render_filled(arch, np.array([152]), 8))[0]
policy = rl.load_policy()
env = W.walker_env(policy, maps.shape, TerrainScale())
terrains = jnp.stack([jnp.asarray(maps)] * 64)
for rep in range(2):
  for t in ("mask", "bootstrap"):
    ppo = CurriculumConfig().ppo_config(policy.config)._replace(num_envs=64, truncation=t)
    state = W.start_state(env, ppo, policy, maps.shape)
    state = jax.jit(lambda s, k: rl.reset_envs(s, k, terrains, env=env, config=ppo))(state, jax.random.key(1))
    run = jax.jit(lambda s: rl.run_updates(s, terrains, env=env, config=ppo, num_updates=4))
    jax.block_until_ready(run(state))
    t0 = time.perf_counter(); s = state
    for _ in range(3):
        s, _m = run(s)
    jax.block_until_ready(s)
    dt = (time.perf_counter() - t0) / 12
    print(f"rep {rep} {t}: {dt:.3f} s per update ({ppo.steps_per_update / dt:.0f} env steps/s)", flush=True)
