"""Data-parallel PPO over 4 forced CPU devices (a subprocess: XLA_FLAGS must precede jax's start): one update with
the envs split over the devices and the minibatch gradients summed across them equals the one-device update up to
float rounding, with 6 envs (uneven over 4 devices) and minibatches of 6 segments (padded to 8, weight 0)."""

from __future__ import annotations

import textwrap
from pathlib import Path

from test_sharding import run_on_devices

TESTS = str(Path(__file__).parent)

_SCRIPT = textwrap.dedent("""
    import sys
    sys.path.insert(0, TESTS)
    import jax, numpy as np
    from jaxterrain import rl, sharding as SH
    from test_rl import PointEnv, CFG, TERRAIN

    assert len(jax.devices()) == 4
    env, config = PointEnv(), CFG._replace(num_envs=6, num_minibatches=2, update_epochs=2)
    assert config.minibatch_segments == 6
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
    print("ok")
""").replace("TESTS", repr(TESTS))


def test_data_parallel_ppo_update_equals_one_device():
    assert run_on_devices(_SCRIPT).strip().endswith("ok")
