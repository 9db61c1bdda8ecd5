"""jaxterrain.rl: GAE and PPO loss against hand-computed numbers, learning on a toy env, checkpoints / resume,
seeds under vmap, no re-compilation when terrains change. CPU, tiny sizes."""

from __future__ import annotations

import functools
import json
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxterrain import rl
from jaxterrain.runtime import xla


# ---------------------------------------------------------------------------------------------------------------
# A 1-D "move to the target" env with the walker's interface (terrain is data: it shifts the target).
# ---------------------------------------------------------------------------------------------------------------
class PointState(NamedTuple):
    obs: jax.Array
    reward: jax.Array
    done: jax.Array
    truncation: jax.Array
    pos: jax.Array
    target: jax.Array
    t: jax.Array


class PointEnv:
    """pos, target in R; action a in [-1, 1] moves pos by 0.2 a; reward -|target - pos|; 16-step episodes.
    target = mean(terrain) + U(-1, 1). Counts how often ``step`` is traced."""

    observation_size = 2
    action_size = 1

    def __init__(self, horizon: int = 16):
        self.horizon = horizon
        self.traces = 0

    def reset(self, key, terrain):
        pos_key, target_key = jax.random.split(key)
        pos = jax.random.uniform(pos_key, (), minval=-1.0, maxval=1.0)
        target = jnp.mean(terrain) + jax.random.uniform(target_key, (), minval=-1.0, maxval=1.0)
        z = jnp.zeros((), jnp.float32)
        return PointState(jnp.stack([pos, target - pos]), z, z, z, pos, target, jnp.zeros((), jnp.int32))

    def step(self, state, action, terrain):
        self.traces += 1
        pos = state.pos + 0.2 * action[0]
        t = state.t + 1
        done = (t >= self.horizon).astype(jnp.float32)
        reward = -jnp.abs(state.target - pos)
        return PointState(jnp.stack([pos, state.target - pos]), reward, done, done, pos, state.target, t)


CFG = rl.PPOConfig(num_envs=16, unroll_length=8, num_unrolls=2, num_minibatches=4, update_epochs=4,
                   learning_rate=3e-3, gamma=0.9, reward_scaling=1.0, entropy_coef=0.0,
                   policy_hidden=(16, 16), value_hidden=(32, 32))
TERRAIN = jnp.zeros((4, 4), jnp.float32)
ENV = PointEnv()  # shared, so that tests reuse the compiled training chunks (cached per env, config, length)


# XLA's cheap CPU compile options (lowest backend optimisation, the classic emitter) for the programs a test checks
# against bounds or another computation within a tolerance only; the updates below would otherwise run eagerly, op by
# op, each scan and loop compiled at the default options on its own
FAST_COMPILE = xla.known_options(xla.FAST_CPU_COMPILE)


def compiled(fn, *args):
    """``fn(*args)``, compiled with :data:`FAST_COMPILE`."""
    return jax.jit(fn).lower(*args).compile(FAST_COMPILE)(*args)


def tree_equal(a, b) -> bool:
    la, lb = jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)
    return len(la) == len(lb) and all(np.array_equal(np.asarray(x), np.asarray(y)) for x, y in zip(la, lb))


def eval_return(env, state, config, n=64, key=jax.random.PRNGKey(123)):
    """Mean undiscounted return of the deterministic policy over n episodes."""

    @jax.jit
    def run(params, normaliser):
        s = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(key, n), TERRAIN)

        def body(s, _):
            a = rl.deterministic_action(config, env.action_size, params, normaliser, s.obs)
            s = jax.vmap(env.step, in_axes=(0, 0, None))(s, a, TERRAIN)
            return s, s.reward

        return jnp.mean(jnp.sum(jax.lax.scan(body, s, None, length=env.horizon)[1], axis=0))

    return float(run(state.params, state.normaliser))


# ---------------------------------------------------------------------------------------------------------------
# Losses against hand-computed values
# ---------------------------------------------------------------------------------------------------------------
def test_gae_hand_computed_with_done_and_truncation():
    # gamma 0.9, lambda 0.8 (gamma * lambda = 0.72); column 0: episode ends (terminal) after t=1;
    # column 1: same, but the end at t=1 is a time limit (truncation): that step is left out.
    rewards = jnp.array([[1.0, 1.0], [2.0, 2.0], [3.0, 3.0], [4.0, 4.0]])
    values = jnp.array([[0.5, 0.5], [1.0, 1.0], [1.5, 1.5], [2.0, 2.0]])
    dones = jnp.array([[0.0, 0.0], [1.0, 1.0], [0.0, 0.0], [0.0, 0.0]])
    truncs = jnp.array([[0.0, 0.0], [0.0, 1.0], [0.0, 0.0], [0.0, 0.0]])
    last_value = jnp.array([3.0, 3.0])
    adv, targets = rl.gae(rewards, values, dones, last_value, 0.9, 0.8, truncs)
    # deltas: t0 1 + 0.9*1.0 - 0.5 = 1.4; t1 (terminal) 2 - 1.0 = 1.0; t2 3 + 0.9*2.0 - 1.5 = 3.3;
    #         t3 4 + 0.9*3.0 - 2.0 = 4.7
    # A3 = 4.7; A2 = 3.3 + 0.72*4.7 = 6.684; A1 = 1.0 (episode boundary); A0 = 1.4 + 0.72*1.0 = 2.12
    # column 1: delta1 masked -> A1 = 0, A0 = 1.4
    expected_adv = np.array([[2.12, 1.4], [1.0, 0.0], [6.684, 6.684], [4.7, 4.7]])
    np.testing.assert_allclose(np.asarray(adv), expected_adv, rtol=1e-6)
    np.testing.assert_allclose(np.asarray(targets), expected_adv + np.asarray(values), rtol=1e-6)
    # without truncations every done is terminal: column 1 equals column 0
    adv2, _ = rl.gae(rewards, values, dones, last_value, 0.9, 0.8)
    np.testing.assert_allclose(np.asarray(adv2[:, 1]), expected_adv[:, 0], rtol=1e-6)
    # lambda = 0 gives one-step TD errors
    adv0, _ = rl.gae(rewards, values, dones, last_value, 0.9, 0.0)
    np.testing.assert_allclose(np.asarray(adv0[:, 0]), [1.4, 1.0, 3.3, 4.7], rtol=1e-6)


def test_ppo_loss_hand_computed():
    logp_old = jnp.zeros(2)
    logp_new = jnp.log(jnp.array([1.5, 0.5]))  # ratios 1.5 and 0.5
    values, targets = jnp.array([1.0, 2.0]), jnp.array([2.0, 0.0])
    entropy = jnp.array([1.0, 3.0])
    kw = dict(clip_eps=0.2, vf_coef=0.5, entropy_coef=0.01)
    loss, aux = rl.ppo_loss(logp_new, logp_old, jnp.array([1.0, -1.0]), values, targets, entropy,
                            normalize_advantage=False, **kw)
    # policy: -mean(min(1.5*1, 1.2*1), min(0.5*-1, 0.8*-1)) = -mean(1.2, -0.8) = -0.2
    # value: 0.5 * 0.5 * mean(1, 4) = 0.625; entropy: -0.01 * 2 = -0.02
    assert float(aux["policy_loss"]) == pytest.approx(-0.2, abs=1e-6)
    assert float(aux["value_loss"]) == pytest.approx(0.625, abs=1e-6)
    assert float(aux["entropy_loss"]) == pytest.approx(-0.02, abs=1e-7)
    assert float(loss) == pytest.approx(0.405, abs=1e-6)
    kl = ((0.5 - math.log(1.5)) + (-0.5 - math.log(0.5))) / 2  # 0.143841
    assert float(aux["approx_kl"]) == pytest.approx(kl, abs=1e-6)
    assert float(aux["clip_fraction"]) == 1.0
    # normalised advantages: [1, 3] -> [-1, 1]: -mean(min(-1.5, -1.2), min(0.5, 0.8)) = -mean(-1.5, 0.5) = 0.5
    _, aux_n = rl.ppo_loss(logp_new, logp_old, jnp.array([1.0, 3.0]), values, targets, entropy,
                           normalize_advantage=True, **kw)
    assert float(aux_n["policy_loss"]) == pytest.approx(0.5, abs=1e-6)
    # gradient w.r.t. log_prob: -r A / n inside the clip range or where min() picks the unclipped term
    # (r = 0.5 < 1 - eps with A > 0), zero where the clipped term is chosen (r = 1.5 > 1 + eps with A > 0)
    lp3 = jnp.log(jnp.array([1.1, 0.5, 1.5]))
    g = jax.grad(lambda lp: rl.ppo_loss(lp, jnp.zeros(3), jnp.ones(3), jnp.zeros(3), jnp.zeros(3), jnp.zeros(3),
                                        normalize_advantage=False, **kw)[0])(lp3)
    np.testing.assert_allclose(np.asarray(g), [-1.1 / 3, -0.5 / 3, 0.0], atol=1e-6)


def test_normaliser_matches_numpy():
    x = np.random.default_rng(0).normal(3.0, 2.0, size=(2, 50, 3)).astype(np.float32)
    stats = rl.update_stats(rl.update_stats(rl.init_stats(3), jnp.asarray(x[0])), jnp.asarray(x[1]))
    flat = x.reshape(-1, 3)
    np.testing.assert_allclose(np.asarray(stats.mean), flat.mean(0), rtol=1e-5)
    np.testing.assert_allclose(np.asarray(rl.normalize(stats, jnp.asarray(flat))),
                               (flat - flat.mean(0)) / flat.std(0), atol=1e-4)
    # before any data the normalisation is the identity
    np.testing.assert_allclose(np.asarray(rl.normalize(rl.init_stats(3), jnp.ones(3))), np.ones(3))


def test_update_normaliser_false_keeps_the_statistics():
    """``PPOConfig.update_normaliser=False`` (fine-tuning with the base policy's statistics frozen): an update
    leaves the normaliser as given and still trains; True merges the collected observations."""
    state = rl.init(jax.random.PRNGKey(0), ENV, CFG, TERRAIN)
    news = compiled(lambda s: [rl.update(s, jax.random.PRNGKey(1), TERRAIN, env=ENV,
                                         config=CFG._replace(update_normaliser=flag))[0] for flag in (True, False)],
                    state)
    for flag, new in zip((True, False), news):
        assert tree_equal(new.normaliser, state.normaliser) is not flag
        assert not tree_equal(new.params, state.params)


def test_truncation_bootstrap_values_the_final_observation():
    """``PPOConfig.truncation``: under ``mask`` (brax) a time-limit end is flagged and adds nothing; under
    ``bootstrap`` (SB3) it becomes a terminal step whose ``bootstrap`` is ``gamma * V(final obs)``, the obs before
    the auto-reset, valued with the collecting params. PointEnv ends every episode at step 16 by a time limit."""
    from jaxterrain.rl import networks as nets
    from jaxterrain.rl.collect import collect_steps

    cfg = CFG._replace(unroll_length=16, num_unrolls=1)
    state = rl.init(jax.random.PRNGKey(0), ENV, cfg, TERRAIN)
    data = dict(zip(("mask", "bootstrap"), compiled(lambda s: [
        collect_steps(s, jax.random.PRNGKey(1), TERRAIN, ENV, cfg._replace(truncation=t))[2]
        for t in ("mask", "bootstrap")], state)))
    last = data["mask"].done[0, -1]
    assert np.all(np.asarray(last) == 1.0) and np.all(np.asarray(data["mask"].truncation[0, -1]) == 1.0)
    assert np.all(np.asarray(data["mask"].bootstrap) == 0.0)
    boot = data["bootstrap"]
    assert np.all(np.asarray(boot.truncation) == 0.0) and np.array_equal(boot.done, data["mask"].done)
    # PointEnv's final obs: pos + 0.2 a, (target - pos) - 0.2 a, with a = tanh(raw)
    move = 0.2 * jnp.tanh(boot.raw_action[0, -1, :, 0])
    final = boot.obs[0, -1] + jnp.stack([move, -move], axis=-1)
    expected = cfg.gamma * nets.value_apply(cfg, state.params, state.normaliser, final)
    np.testing.assert_allclose(np.asarray(boot.bootstrap[0, -1]), np.asarray(expected), rtol=1e-5, atol=1e-6)
    assert np.all(np.asarray(boot.bootstrap[0, :-1]) == 0.0)
    for new, metrics in compiled(lambda s: [rl.update(s, jax.random.PRNGKey(2), TERRAIN, env=ENV,
                                                      config=cfg._replace(truncation=t))
                                            for t in ("mask", "bootstrap")], state):  # both train
        assert np.isfinite(float(metrics["value_loss"])) and not tree_equal(new.params, state.params)


def test_config_validation_names_the_field():
    with pytest.raises(ValueError, match="num_minibatches"):
        rl.validate_config(CFG._replace(num_minibatches=5))
    with pytest.raises(ValueError, match="gamma"):
        rl.validate_config(CFG._replace(gamma=1.5))
    with pytest.raises(ValueError, match="action_distribution"):
        rl.validate_config(CFG._replace(action_distribution="beta"))
    with pytest.raises(ValueError, match="truncation"):
        rl.validate_config(CFG._replace(truncation="drop"))
    assert rl.PPOConfig().steps_per_update == 3072 * 10 * 4
    assert rl.PPOConfig.from_json_dict(json.loads(json.dumps(CFG.to_json_dict()))) == CFG


# ---------------------------------------------------------------------------------------------------------------
# Training
# ---------------------------------------------------------------------------------------------------------------
def test_ppo_improves_point_env():
    env = ENV
    state = rl.init(jax.random.PRNGKey(0), env, CFG, TERRAIN)
    before = eval_return(env, state, CFG)
    state, metrics = rl.train(jax.random.PRNGKey(0), env, CFG, 24, TERRAIN, state=state, updates_per_chunk=2)
    after = eval_return(env, state, CFG)
    # optimal ~ -2.4 (|gap| <= 2 closes at 0.2 per step); an untrained policy is around -7 or worse
    assert after > before + 3.0, (before, after)
    assert after > -4.0, after
    assert metrics["episode_return"][-1] > metrics["episode_return"][1] + 2.0
    assert int(state.env_steps) == 24 * CFG.steps_per_update and int(state.update_step) == 24
    assert np.all(np.isfinite(metrics["loss"]))


def test_checkpoint_round_trip_and_resume_equals_uninterrupted(tmp_path):
    env = ENV
    key = jax.random.PRNGKey(7)
    s0 = rl.init(key, env, CFG, TERRAIN)
    full, _ = rl.train(key, env, CFG, 4, TERRAIN, state=s0, updates_per_chunk=2)

    half, _ = rl.train(key, env, CFG, 2, TERRAIN, state=s0, updates_per_chunk=2)
    path = tmp_path / "ckpt.npz"
    rl.save_checkpoint(path, half)
    loaded = rl.load_checkpoint(path, like=s0)
    assert tree_equal(loaded, half)  # bit-equal params, Adam state, normaliser, env state, counters, key
    assert tree_equal(loaded.opt_state, half.opt_state) and int(loaded.update_step) == 2
    resumed, _ = rl.train(jax.random.PRNGKey(999), env, CFG, 2, TERRAIN, state=loaded, updates_per_chunk=2)
    assert tree_equal(resumed, full)
    assert not tree_equal(half.params, full.params)

    # without the env state: params etc. restored, env state taken from `like`
    rl.save_checkpoint(tmp_path / "small.npz", half, include_env_state=False)
    small = rl.load_checkpoint(tmp_path / "small.npz", like=s0)
    assert tree_equal(small.params, half.params) and tree_equal(small.env_state, s0.env_state)
    # a checkpoint of another config is refused with the leaf named
    other = rl.init(key, env, CFG._replace(policy_hidden=(8,)), TERRAIN)
    with pytest.raises(ValueError, match="policy"):
        rl.load_checkpoint(path, like=other)


def test_seeds_under_vmap_equal_separate_runs():
    env = ENV
    keys = jax.random.split(jax.random.PRNGKey(3), 2)
    both, m_both = rl.train(keys, env, CFG, 2, TERRAIN, updates_per_chunk=2)
    assert both.update_step.shape == (2,) and m_both["loss"].shape == (2, 2)
    for i in range(2):
        single, m_single = rl.train(keys[i], env, CFG, 2, TERRAIN, updates_per_chunk=2)
        for a, b in zip(jax.tree_util.tree_leaves(single.params), jax.tree_util.tree_leaves(both.params)):
            np.testing.assert_allclose(np.asarray(b[i]), np.asarray(a), rtol=1e-4, atol=1e-5)
        np.testing.assert_allclose(m_both["episode_return"][i], m_single["episode_return"], rtol=1e-4, atol=1e-4)
    k0 = jax.tree_util.tree_leaves(both.params)[0]
    assert not np.allclose(np.asarray(k0[0]), np.asarray(k0[1]))


def test_no_recompile_when_terrains_change():
    env = PointEnv()
    n = CFG.num_envs
    per_env = jnp.zeros((n, 4, 4))
    state = rl.init(jax.random.PRNGKey(0), env, CFG, per_env)
    step = jax.jit(functools.partial(rl.update, env=env, config=CFG))
    state, m1 = step(state, jax.random.PRNGKey(1), per_env)
    traces = env.traces
    assert traces > 0
    shifted = per_env + jnp.arange(n, dtype=jnp.float32)[:, None, None]  # other values, same shape
    state, m2 = step(state, jax.random.PRNGKey(2), shifted)
    state, m3 = step(state, jax.random.PRNGKey(3), per_env * 2.0 + 5.0)
    assert env.traces == traces
    # the terrain really is data: targets move with it (the fresh reset pool uses the new terrains)
    fresh = rl.reset_envs(state, jax.random.PRNGKey(4), shifted, env=env, config=CFG)
    np.testing.assert_allclose(np.asarray(fresh.env_state.target) - np.arange(n), 0.0, atol=1.0 + 1e-6)
    assert float(jnp.max(fresh.env_state.target)) > 10.0

    # train(): chunks are cached, a second call with new terrain values does not trace again
    state = rl.init(jax.random.PRNGKey(0), ENV, CFG, TERRAIN)
    state, _ = rl.train(None, ENV, CFG, 2, TERRAIN, state=state, updates_per_chunk=2)
    traces = ENV.traces
    state, _ = rl.train(None, ENV, CFG, 4, TERRAIN + 1.0, state=state, updates_per_chunk=2)
    assert ENV.traces == traces

    with pytest.raises(ValueError, match="num_envs"):
        step(state, jax.random.PRNGKey(5), jnp.zeros((n + 1, 4, 4)))


def test_riders_step_with_ppo_and_leave_its_update_unchanged():
    """``rl.ride_updates``: 3 riders (their own terrains, a fixed policy) stepped in PPO's batched steps for 2
    updates: PPO's state and metrics equal ``run_updates``' exactly; the riders took every one of the 2 x 2 x 8 steps
    (never reset), as stepping them alone does; ``record`` saw each step with the riders' rows."""
    env = PointEnv()
    state = rl.init(jax.random.PRNGKey(0), env, CFG, TERRAIN)
    ride_terrains = jnp.arange(3, dtype=jnp.float32)[:, None, None] + jnp.zeros((3, 4, 4))
    riders = jax.vmap(env.reset)(jax.random.split(jax.random.PRNGKey(9), 3), ride_terrains)
    act = lambda obs: jnp.clip(obs[:, 1:2], -1.0, 1.0)  # noqa: E731 - move toward the target
    record = lambda c, s, start: c + s.pos[start:]  # noqa: E731 - the sum of the riders' positions
    ride = rl.Ride(act=act, terrains=ride_terrains, record=record)
    run = jax.jit(lambda s, r, c: rl.ride_updates(s, TERRAIN, r, ride, c, env=env, config=CFG, num_updates=2))
    out, riders_out, total, metrics = run(state, riders, jnp.zeros(3))
    plain, plain_metrics = jax.jit(lambda s: rl.run_updates(s, TERRAIN, env=env, config=CFG, num_updates=2))(state)
    assert tree_equal(out, plain) and tree_equal(metrics, plain_metrics)
    steps = 2 * CFG.num_unrolls * CFG.unroll_length
    alone, pos_sum = riders, jnp.zeros(3)
    for _ in range(steps):
        alone = jax.vmap(env.step)(alone, act(alone.obs), ride_terrains)
        pos_sum = pos_sum + alone.pos
    assert np.all(np.asarray(riders_out.t) == steps)  # past the 16-step horizon: never reset
    np.testing.assert_allclose(np.asarray(riders_out.pos), np.asarray(alone.pos), atol=1e-6)
    np.testing.assert_allclose(np.asarray(total), np.asarray(pos_sum), atol=1e-5)


def test_policy_export_and_load(tmp_path, monkeypatch):
    env = PointEnv()
    state = rl.init(jax.random.PRNGKey(0), env, CFG, TERRAIN)
    state = state._replace(normaliser=rl.update_stats(state.normaliser, jnp.array([[1.0, 2.0], [3.0, -2.0]])))
    rl.save_policy(tmp_path / "pol", state.params, state.normaliser, CFG, env.observation_size, env.action_size)
    policy = rl.load_policy(tmp_path / "pol")
    obs = jax.random.normal(jax.random.PRNGKey(1), (5, 2)) * 10.0
    expected = rl.deterministic_action(CFG, 1, state.params, state.normaliser, obs)
    np.testing.assert_array_equal(np.asarray(jax.jit(policy)(obs)), np.asarray(expected))
    assert policy.config == CFG and policy.action_size == 1 and policy(obs[0]).shape == (1,)
    assert float(jnp.max(jnp.abs(policy(obs * 100.0)))) <= 1.0
    # actor-only (how released walkers ship): the same actions, no value network, smaller on disk
    rl.save_policy(tmp_path / "actor", policy.params, policy.normaliser, CFG, env.observation_size, env.action_size,
                   actor_only=True)
    actor = rl.load_policy(tmp_path / "actor")
    assert set(actor.params) == {"policy"} and actor.meta["actor_only"] and not policy.meta["actor_only"]
    np.testing.assert_array_equal(np.asarray(jax.jit(actor)(obs)), np.asarray(expected))
    assert (tmp_path / "actor" / "policy.msgpack").stat().st_size < (tmp_path / "pol" / "policy.msgpack").stat().st_size
    monkeypatch.setattr(rl.checkpoint, "BASE_POLICY_DIR", tmp_path / "missing")
    with pytest.raises(FileNotFoundError, match="train-base-policy"):
        rl.load_policy()


def test_driver_resume_equals_uninterrupted(tmp_path):
    """rl.chunk_fn under jaxterrain.runtime.driver.run_chunks: a run stopped after one chunk and restored from its
    checkpoint.npz ends bit-identical (state and metric history) to an uninterrupted one; rl.train(run_dir=...)
    writes the same files."""
    from jaxterrain.runtime import driver

    key = jax.random.PRNGKey(11)
    s0 = rl.init(key, ENV, CFG, TERRAIN)
    chunk = rl.chunk_fn(ENV, CFG, TERRAIN)
    full, done, h_full = driver.run_chunks(chunk, s0, total=4, every=2, run_dir=tmp_path / "a", progress=False)
    assert done == 4 and int(full.update_step) == 4 and len(h_full["loss"]) == 4
    _, done, _ = driver.run_chunks(chunk, s0, total=4, every=2, run_dir=tmp_path / "b", progress=False,
                                   time_limit_s=1e-6)
    assert done == 2  # stopped after the first chunk, checkpoint written
    state, start, history, _ = driver.restore(tmp_path / "b", like=s0)
    assert start == 2 and int(state.update_step) == 2 and len(history["loss"]) == 2
    resumed, done, h_res = driver.run_chunks(chunk, state, total=4, every=2, start=start, history=history,
                                             run_dir=tmp_path / "b", progress=False)
    assert done == 4 and tree_equal(resumed, full) and h_res == h_full
    rows = (tmp_path / "b" / "metrics.csv").read_text().splitlines()
    assert [r.split(",")[0] for r in rows[1:]] == ["1", "2", "3", "4"]
    # the library entry point: same state as the driver loop, the checkpoint loads with rl.load_checkpoint
    trained, metrics = rl.train(key, ENV, CFG, 4, TERRAIN, state=s0, updates_per_chunk=2, run_dir=tmp_path / "c")
    assert tree_equal(trained, full) and metrics["loss"].shape == (4,)
    np.testing.assert_array_equal(metrics["loss"], np.asarray(h_full["loss"], np.float32))
    assert tree_equal(rl.load_checkpoint(tmp_path / "c" / driver.CHECKPOINT_NAME, like=s0), full)
