"""benchmarks/ppo.py: the brax config mapping, the jax >= 0.10 patch, the walker as a brax Env, and (slow) the
whole --quick run."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxterrain import rl
from jaxterrain.walker import TerrainScale, WalkerConfig, WalkerEnv
from jaxterrain.runtime import xla

from benchmark_loader import load_benchmark

bench = load_benchmark("ppo")

FAST_COMPILE = xla.known_options({"xla_backend_optimization_level": 0, "xla_llvm_disable_expensive_passes": True,
                "xla_cpu_use_fusion_emitters": False})
SMALL_ENV = WalkerConfig(terrain_shape=(16, 32), scale=TerrainScale(cell_size=0.2, height=0.5), episode_length=30)


def test_brax_kwargs_same_ppo_shape():
    cfg = rl.PPOConfig(num_envs=2048, unroll_length=10, num_unrolls=16, num_minibatches=32, update_epochs=8,
                       policy_hidden=(32, 32), value_hidden=(64,) * 3, max_grad_norm=1.0)
    kw = bench.brax_kwargs(cfg, episode_length=1000, updates=4, epochs=3, seed=5)
    assert kw["num_envs"] == 2048 and kw["unroll_length"] == 10 and kw["num_minibatches"] == 32
    assert kw["batch_size"] == 1024  # 2048 envs x 16 unrolls / 32 minibatches: the MJX tutorial's recipe
    # one brax training step collects what one rl.update collects and takes the same Adam steps
    assert kw["batch_size"] * kw["unroll_length"] * kw["num_minibatches"] == cfg.steps_per_update == 327_680
    assert kw["num_updates_per_batch"] == 8
    # 3 epochs of 4 training steps: num_evals - 1 epochs, each num_timesteps / (epochs * steps per update) steps
    assert kw["num_evals"] == 4 and kw["num_timesteps"] == 3 * 4 * 327_680 and kw["run_evals"] is False
    assert (kw["discounting"], kw["gae_lambda"], kw["clipping_epsilon"]) == (0.97, 0.95, 0.3)
    assert (kw["entropy_cost"], kw["learning_rate"], kw["reward_scaling"]) == (1e-3, 3e-4, 0.1)
    assert kw["max_grad_norm"] == 1.0 and kw["episode_length"] == 1000 and kw["seed"] == 5
    nets = kw["network_factory"](45, 17)
    p = nets.policy_network.init(jax.random.PRNGKey(0))
    v = nets.value_network.init(jax.random.PRNGKey(0))
    shapes = lambda t: [x.shape for x in jax.tree_util.tree_leaves(t) if x.ndim == 2]  # noqa: E731
    assert shapes(p) == [(45, 32), (32, 32), (32, 34)]  # tanh-normal: loc and scale, 2 x 17
    assert shapes(v) == [(45, 64), (64, 64), (64, 64), (64, 1)]
    with pytest.raises(ValueError, match="updates and epochs"):
        bench.brax_kwargs(cfg, 1000, updates=0, epochs=1)
    with pytest.raises(ValueError, match="num_minibatches"):
        bench.brax_kwargs(cfg._replace(num_minibatches=3), 1000, 1, 1)


def test_device_put_replicated_patch_is_local():
    had = hasattr(jax, "device_put_replicated")
    tree = {"a": jnp.arange(3.0), "b": (jnp.int32(4),)}
    with bench.patched_device_put_replicated():
        rep = jax.device_put_replicated(tree, jax.local_devices()[:1])
        assert rep["a"].shape == (1, 3) and rep["b"][0].shape == (1,)
        # brax's _unpmap reads the first addressable shard
        np.testing.assert_array_equal(np.asarray(rep["a"].addressable_shards[0].data.squeeze(0)), [0.0, 1.0, 2.0])
        assert int(rep["b"][0][0]) == 4
    assert hasattr(jax, "device_put_replicated") == had  # nothing left behind


@pytest.mark.slow  # 10-70 s on 2 CPU cores; the default suite keeps under 15 min (2026-11-29)
def test_brax_walker_wraps_the_same_env():
    from brax.envs.base import Env, State

    env = WalkerEnv(SMALL_ENV)
    terrain = jnp.linspace(0.0, 0.2, 32)[None, :] * jnp.ones((16, 1))
    benv = bench.brax_walker(env, terrain)
    assert isinstance(benv, Env) and benv.backend == "mjx"
    assert benv.observation_size == env.observation_size == 45 and benv.action_size == env.action_size == 17
    key = jax.random.PRNGKey(3)
    # both resets in ONE program (one MJX compile; at XLA's cheap CPU options, compared only with each other)
    ours, theirs = jax.jit(lambda k: (env.reset(k, terrain), benv.reset(k))).lower(key).compile(FAST_COMPILE)(key)
    assert isinstance(theirs, State)
    np.testing.assert_array_equal(np.asarray(theirs.obs), np.asarray(ours.obs))
    np.testing.assert_array_equal(np.asarray(theirs.pipeline_state.data.qpos), np.asarray(ours.data.qpos))
    assert float(theirs.reward) == 0.0 and float(theirs.done) == 0.0 and set(theirs.metrics) == set(ours.metrics)
    stepped = jax.eval_shape(benv.step, theirs, jnp.zeros(17))  # shapes only: no physics compile
    assert stepped.obs.shape == (45,) and stepped.reward.shape == () and stepped.done.shape == ()
    with pytest.raises(ValueError, match="terrain must have shape"):
        bench.brax_walker(env, jnp.zeros((8, 8)))


@pytest.mark.slow
def test_quick_run_writes_all_measurements(tmp_path):
    # MJX + two PPO compiles on a CPU: about 3-5 minutes on 2 shared cores
    out = tmp_path / "ppo.json"
    result = bench.main(["--quick", "--num-envs", "4", "--unrolls", "1", "--updates", "1", "--out", str(out)])
    saved = json.loads(out.read_text())
    assert [r["what"] for r in saved["runs"]] == ["ours, shared terrain", "ours, per-env terrains",
                                                   "brax ppo.train, shared terrain"]
    steps = 4 * 5 * 1  # num_envs x unroll x unrolls
    for row in saved["runs"]:
        assert row["finite"] and row["steps_per_s"] > 0 and len(row["seconds"]) == 1
        assert row["device"] and row["jax"] == jax.__version__ and row["config"]["steps_per_update"] == steps
    # ours: the compiling call and one timed one; brax: two warm-up epochs (both compile) and one timed one
    assert [r["env_steps"] for r in saved["runs"]] == [2 * steps, 2 * steps, 3 * steps]
    assert len(saved["runs"][2]["epoch_seconds"]) == 3
    assert set(saved["ratio_vs_brax"]) == {"ours, shared terrain", "ours, per-env terrains"}
    assert result["ratio_vs_brax"] == pytest.approx(saved["ratio_vs_brax"])
