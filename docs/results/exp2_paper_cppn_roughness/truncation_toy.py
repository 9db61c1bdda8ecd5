"""PPOConfig.truncation on a toy env (CPU, seconds): a fixed 20-step track whose episodes all end at the goal by
truncation; the observation is a noisy height over the ground (1 +- 0.05) that jumps by DROP on the last step before
the goal (the roughness baseline's terrain 31 in miniature), plus the last action. Reward 1 - 0.1 a^2 per step, gamma
0.97 (a continuing walk is worth about 33). UPDATES (default 40) per mode; prints the value loss at updates 1, U/4,
U/2, 3U/4, U and the mean value target at updates 1, U/2, U.

    python docs/results/exp2_paper_cppn_roughness/truncation_toy.py DROP SEED [UPDATES]     e.g. 1.0 0
"""
import jax, jax.numpy as jnp, numpy as np
from typing import NamedTuple
from jaxterrain import rl

class S(NamedTuple):
    obs: jax.Array; reward: jax.Array; done: jax.Array; truncation: jax.Array; t: jax.Array; key: jax.Array

class GoalEnv:
    """Walks a fixed track; obs = [height over ground + noise, action echo]; the ground drops at the goal line:
    the last H0 steps before the goal see the height jump. Ends by truncation at the goal (step `horizon`)."""
    observation_size = 2; action_size = 1
    def __init__(self, horizon=20, drop=1.0): self.horizon, self.drop = horizon, drop
    def _obs(self, t, key, a):
        h = 1.0 + 0.05 * jax.random.normal(key) + jnp.where(t >= self.horizon - 1, self.drop, 0.0)
        return jnp.stack([h, a])
    def reset(self, key, terrain):
        z = jnp.zeros((), jnp.float32)
        return S(self._obs(0, key, z), z, z, z, jnp.zeros((), jnp.int32), key)
    def step(self, s, action, terrain):
        key, sub = jax.random.split(s.key)
        t = s.t + 1
        done = (t >= self.horizon).astype(jnp.float32)
        reward = 1.0 - 0.1 * jnp.square(action[0])
        return S(self._obs(t, sub, action[0]), reward, done, done, t, key)

import sys
drop = float(sys.argv[1]) if len(sys.argv) > 1 else 1.0
env = GoalEnv(drop=drop)
T = jnp.zeros((4, 4))
seed = int(sys.argv[2]) if len(sys.argv) > 2 else 0
n = int(sys.argv[3]) if len(sys.argv) > 3 else 40
for trunc in ("mask", "bootstrap"):
    cfg = rl.PPOConfig(num_envs=32, unroll_length=10, num_unrolls=2, num_minibatches=4, update_epochs=8,
                       learning_rate=3e-4, gamma=0.97, reward_scaling=1.0, policy_hidden=(16, 16),
                       value_hidden=(64, 64, 64), truncation=trunc)
    st = rl.init(jax.random.PRNGKey(seed), env, cfg, T)
    st, m = rl.train(jax.random.PRNGKey(seed), env, cfg, n, T, state=st, updates_per_chunk=20)
    vl = np.asarray(m["value_loss"]); vt = np.asarray(m["value_target"])
    at = [0, n // 4 - 1, n // 2 - 1, 3 * n // 4 - 1, n - 1]
    print(f"drop {drop} seed {seed} {trunc:9s} value loss", " ".join(f"{x:.4g}" for x in vl[at]),
          "| value target", " ".join(f"{x:.4g}" for x in vt[[0, n // 2 - 1, n - 1]]) + ("" if n == 40 else f" ({n} updates)"))
