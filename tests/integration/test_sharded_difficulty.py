"""Difficulty evaluation over 4 forced CPU devices (a subprocess: XLA_FLAGS must precede jax's start): 5 terrains
(padded to 8) split over the devices, each walked from its own key on a pool of 3 env slots per device, give the
distances of the one-device call of the same keys (all walks at once) up to float rounding. Two walker compiles at
XLA's lowest CPU optimisation: slow."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

SCRIPT = textwrap.dedent("""
    import jax, jax.numpy as jnp, numpy as np
    from jaxterrain import difficulty as D
    from jaxterrain.runtime import sharding as SH
    from jaxterrain.terrain import TerrainScale
    from jaxterrain.walker import WalkerConfig, make_env

    assert len(jax.devices()) == 4
    config = WalkerConfig(terrain_shape=(32, 32), scale=TerrainScale(cell_size=0.2, height=0.5), episode_length=40)
    policy = lambda params, obs: params["gain"] * obs[5:22] + params["bias"]
    params = {"gain": jnp.float32(0.8), "bias": jnp.full(17, 0.05, jnp.float32)}
    rng = np.random.default_rng(0)
    maps = jnp.asarray(np.concatenate([np.zeros((1, 32, 32)), rng.random((4, 32, 32)) * 0.6]), jnp.float32)
    key = jax.random.key(3)
    got = D.rollout_distances(maps, key, 4, policy=policy, env_config=config, policy_params=params, slots=3,
                              smooth_first=True, mesh=SH.make_mesh(), split=SPLIT)
    env, protocol = make_env(config), D.Protocol(4, 1)
    want, steps = jax.jit(lambda t, k, p: D.keyed_distances(env, policy, t, k, protocol, p))(
        maps * 0.5, SH.row_keys(key, 5), params)
    got, want, steps = np.asarray(got), np.asarray(want), np.asarray(steps)
    assert got.shape == (5, 4) and len(set(steps.ravel().tolist())) > 1 and want.max() > 0
    np.testing.assert_allclose(got, want, atol=1e-5)
    print("ok")
""")


@pytest.mark.slow
@pytest.mark.parametrize("split", ["shard_map", "dispatch"])
def test_sharded_difficulty_equals_one_device(split):
    """Both ways of splitting rows (``sharding.map_rows``): one program over the mesh, and one program per device
    dispatched together (the default on GPUs)."""
    flags = ("--xla_force_host_platform_device_count=4 --xla_backend_optimization_level=0 "
             "--xla_llvm_disable_expensive_passes=true")
    env = dict(os.environ, XLA_FLAGS=flags, JAX_PLATFORMS="cpu")
    script = SCRIPT.replace("SPLIT", repr(split))  # the library takes the split as an argument
    out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=1200)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.strip().endswith("ok")
