"""Data-parallel PPO over 4 forced CPU devices (a subprocess: XLA_FLAGS must precede jax's start): one update with
the envs split over the devices and the minibatch gradients summed across them equals the one-device update up to
float rounding, with 6 envs (uneven over 4 devices: XLA partitions the env steps; minibatches of 6 segments padded to 8, weight 0)
and with 8 envs (2 per device: each device collects its own under shard_map)."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest
from devices import run_on_devices

from jaxterrain.walker import warp_available

TESTS = str(Path(__file__).resolve().parents[1] / "rl")  # the unit tests whose fixtures the script reuses

SCRIPT = textwrap.dedent("""
    import sys
    sys.path.insert(0, TESTS)
    import jax, numpy as np
    from jaxterrain import rl
    from jaxterrain.runtime import sharding as SH
    from test_rl import PointEnv, CFG, TERRAIN

    def check(num_envs):
        env, config = PointEnv(), CFG._replace(num_envs=num_envs, num_minibatches=2, update_epochs=2)
        assert config.minibatch_segments == num_envs
        start = jax.jit(lambda k: rl.init(k, env, config, TERRAIN))(jax.random.PRNGKey(0))  # one init for both
        one, m1 = rl.train(None, env, config, 1, TERRAIN, state=start)
        four, m4 = rl.train(None, env, config, 1, TERRAIN, state=start, mesh=SH.make_mesh())
        for a, b, s in zip(jax.tree.leaves(one.params), jax.tree.leaves(four.params), jax.tree.leaves(start.params)):
            assert np.max(np.abs(np.asarray(a) - np.asarray(s))) > 1e-3  # the update moved the parameters ...
            np.testing.assert_allclose(np.asarray(b), np.asarray(a), rtol=1e-5, atol=1e-6)  # ... the same way
        for a, b in zip(jax.tree.leaves((one.normaliser, one.env_state, one.episode)),
                        jax.tree.leaves((four.normaliser, four.env_state, four.episode))):
            np.testing.assert_allclose(np.asarray(b), np.asarray(a), rtol=1e-6, atol=1e-6)  # same envs, same draws
        for name in ("loss", "policy_loss", "value_loss", "entropy", "approx_kl", "grad_norm", "mean_std",
                     "episode_return"):
            np.testing.assert_allclose(m4[name], m1[name], rtol=1e-5, atol=1e-6, err_msg=name)
        assert four.params["policy"] is not None and all(
            x.sharding.is_fully_replicated for x in jax.tree.leaves(four.params))  # the policy replicated

    assert len(jax.devices()) == 4
    for num_envs in (6, 8):  # 6: uneven over 4 devices (XLA splits the env steps); 8: 2 per device (shard_map)
        check(num_envs)
    print("ok")
""").replace("TESTS", repr(TESTS))


@pytest.mark.slow  # 10-70 s on 2 CPU cores; the default suite keeps under 15 min (2026-11-29)
def test_data_parallel_ppo_update_equals_one_device():
    assert run_on_devices(SCRIPT).strip().endswith("ok")


_WARP_SCRIPT = textwrap.dedent("""
    import jax, jax.numpy as jnp, numpy as np
    from jaxterrain import rl, difficulty, generators, walker
    from jaxterrain.runtime import sharding as SH
    gen = generators.get("perlin", size=96)
    bank = jnp.clip(gen.render(gen.sample(jax.random.key(1), 4)).astype(jnp.float32), 0, 1)
    n = 8
    config = rl.PPOConfig(num_envs=n, unroll_length=5, num_unrolls=2, num_minibatches=2, update_epochs=1)
    cfg = difficulty.default_env_config((96, 96), backend="warp")._replace(tiles=4, warp_worlds=n)
    env = walker.make_env(cfg)
    terrains = env.make_bank(bank * cfg.scale.height).at(jnp.arange(n) % 4)  # a tile per env
    start = jax.jit(lambda k, t: rl.init(k, env, config, t))(jax.random.key(3), terrains)
    one, m1 = rl.train(None, env, config, 1, terrains, state=start)
    two, m2 = rl.train(None, env, config, 1, terrains, state=start, mesh=SH.make_mesh())
    np.testing.assert_array_equal(np.asarray(two.env_state.obs), np.asarray(one.env_state.obs))  # same walks
    for a, b, s in zip(jax.tree.leaves(one.params), jax.tree.leaves(two.params), jax.tree.leaves(start.params)):
        assert np.max(np.abs(np.asarray(a) - np.asarray(s))) > 1e-4
        np.testing.assert_allclose(np.asarray(b), np.asarray(a), rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(m2["loss"], m1["loss"], rtol=1e-5, atol=1e-6)
    print("ok")
""")


@pytest.mark.slow
@pytest.mark.skipif(not warp_available()[0], reason=warp_available()[1])
def test_data_parallel_ppo_on_warp_equals_one_device():
    """MuJoCo Warp's physics is an opaque call that XLA cannot partition: each of 2 devices collects its own 4 envs
    under shard_map (the Warp Data's shared contact buffers replicated), and the update equals one device's."""
    assert run_on_devices(_WARP_SCRIPT, devices=2).strip().endswith("ok")
