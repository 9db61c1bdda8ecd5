"""Writes tests/data/walker_reference.npz: a humanoid walk of 30 random actions on a random terrain (CPU), made with
the walker before the robot spec (commit 7b3c39c); tests/walker/test_robots.py checks the spec'd walker reproduces
it within the float32 tolerances stated there (not bit for bit: physics differs in the last bits across
CPUs and jax versions). Run from the repository root: python tests/data/make_walker_reference.py"""

import os
from pathlib import Path

if __name__ == "__main__" and "xla_cpu_use_fusion_emitters" not in os.environ.get("XLA_FLAGS", ""):
    # the test processes' XLA setting (tests/conftest.py): the same compiled program as the test's
    from jaxterrain.runtime import xla

    if xla.flag_known("--xla_cpu_use_fusion_emitters=false"):
        os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " --xla_cpu_use_fusion_emitters=false").strip()

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain.terrain import TerrainScale
from jaxterrain.walker import WalkerConfig, WalkerEnv


def walk(config):
    """The walk as one compiled program, reset included. The stored file was written with the reset run eagerly, op
    by op; as one program the walk is the same within the test's tolerances (measured 2026-11-30: qpos 1.9e-5, obs
    7.3e-4, reward 4.0e-5 from the stored walk) for about half the CPU time (an eager MJX reset dispatches and
    compiles every operation on its own: ~18 s on 2 CPU cores)."""
    env = WalkerEnv(config)
    terrain = jnp.asarray(np.random.default_rng(0).uniform(0, 0.3, (32, 64)), jnp.float32)
    actions = jax.random.uniform(jax.random.key(2), (30, env.action_size), minval=-1, maxval=1)

    def step(s, a):
        s = env.step(s, a, terrain)
        return s, (s.data.qpos, s.obs, s.reward, s.done)

    run = jax.jit(lambda key, acts: jax.lax.scan(step, env.reset(key, terrain), acts)[1])
    qpos, obs, reward, done = run(jax.random.key(1), actions)
    return {"qpos": np.asarray(qpos), "obs": np.asarray(obs), "reward": np.asarray(reward), "done": np.asarray(done)}


CONFIG = WalkerConfig(terrain_shape=(32, 64), scale=TerrainScale(cell_size=0.2, height=0.5))

if __name__ == "__main__":
    np.savez_compressed(Path(__file__).with_name("walker_reference.npz"), **walk(CONFIG))
