"""Perceptive walkers: the twin of a blind policy computes the blind policy's actions exactly (no physics here: the
networks alone), an env of another observation set is refused in one line naming both, and the shipped perceptive
base policies record their set and walk in the env that follows them."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxterrain import difficulty, rl
from jaxterrain.rl import networks as nets
from jaxterrain.walker import TerrainScale, WalkerConfig


def test_widened_networks_give_the_blind_actions_and_values_whatever_the_scan():
    base = rl.load_policy()
    extra = 153
    mean = np.linspace(-1.5, -1.0, extra).astype(np.float32)
    params, stats = rl.widen_inputs(base.params, base.normaliser, extra, mean, np.full(extra, 0.01, np.float32))
    obs = jax.random.normal(jax.random.PRNGKey(0), (64, base.observation_size)) * 2.0
    scan = jax.random.uniform(jax.random.PRNGKey(1), (64, extra), minval=-3.0, maxval=1.0)  # any terrain at all
    wide = jnp.concatenate([obs, scan], axis=1)
    a_blind = nets.deterministic_action(base.config, base.action_size, base.params, base.normaliser, obs)
    a_wide = nets.deterministic_action(base.config, base.action_size, params, stats, wide)
    # equal up to float rounding: the wider first layer sums its products in another order (3e-6 seen on 2 CPU cores)
    np.testing.assert_allclose(np.asarray(a_wide), np.asarray(a_blind), atol=1e-5)
    v_blind = nets.value_net(base.config).apply(base.params["value"], nets.normalize(base.normaliser, obs))
    v_wide = nets.value_net(base.config).apply(params["value"], nets.normalize(stats, wide))
    np.testing.assert_allclose(np.asarray(v_wide), np.asarray(v_blind), rtol=1e-5, atol=1e-4)
    assert float(stats.count) == float(base.normaliser.count)
    np.testing.assert_allclose(np.asarray(nets.stats_std(stats))[-extra:], 0.1, rtol=1e-4)
    np.testing.assert_allclose(np.asarray(stats.mean)[-extra:], mean)
    with pytest.raises(ValueError, match="^mean and var must have shape"):
        rl.widen_inputs(base.params, base.normaliser, extra, mean[:3], mean[:3])
    with pytest.raises(ValueError, match="var finite and > 0"):
        rl.widen_inputs(base.params, base.normaliser, 2, [0.0, 0.0], [1.0, 0.0])


@pytest.mark.parametrize("robot", ["humanoid", "ant"])
def test_the_shipped_perceptive_base_policy_is_its_blind_twin(robot):
    blind = difficulty.robot_base_policy(robot)
    seeing = difficulty.robot_base_policy(robot, "perceptive")
    fields = difficulty.policy_observation(seeing)
    assert fields["observation"] == "perceptive" and difficulty.policy_observation(blind) == {"observation": "blind"}
    cfg = difficulty.default_env_config((96, 96), TerrainScale(), seeing)
    assert cfg.observation == "perceptive" and cfg.robot == robot and cfg.solver == difficulty.policy_solver(blind)
    n = seeing.observation_size - blind.observation_size
    assert n == fields["scan_points"][0] * fields["scan_points"][1]
    obs = jax.random.normal(jax.random.PRNGKey(2), (32, seeing.observation_size))
    np.testing.assert_allclose(np.asarray(seeing(obs)), np.asarray(blind(obs[:, :blind.observation_size])),
                               atol=1e-5)
    surgery = seeing.meta["surgery"]
    assert surgery["samples"] > 1000 and min(surgery["scan_std"]) >= surgery["std_floor"] - 1e-6


def test_an_env_of_another_observation_set_is_refused_in_one_line():
    blind = rl.load_policy()
    seeing_cfg = difficulty.default_env_config((48, 48), TerrainScale(), blind)._replace(observation="perceptive")
    with pytest.raises(ValueError) as err:
        difficulty.evaluate(jnp.zeros((1, 48, 48)), jax.random.PRNGKey(0), attempts=1, best=1, policy=blind,
                            env_config=seeing_cfg)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith("observation mismatch: the policy")
    assert "observes blind, the env perceptive (17 x 9 heights, x -0.4..1.2 m, y -0.4..0.4 m)" in msg
    seeing = difficulty.robot_base_policy("humanoid", "perceptive")
    other_grid = seeing_cfg._replace(scan_points=(9, 5))
    with pytest.raises(ValueError, match=r"observes perceptive \(17 x 9 .*the env perceptive \(9 x 5"):
        difficulty.check_observation(seeing, other_grid)
    difficulty.check_observation(seeing, seeing_cfg._replace(scan_noise=0.05))  # noise is not the set
    difficulty.check_observation(lambda obs: obs, seeing_cfg)  # a bare callable records nothing: sizes decide
    with pytest.raises(ValueError, match="^observation must be one of blind, perceptive"):
        difficulty.fitness_fn(48, observation="sighted")
    assert isinstance(WalkerConfig().observation, str)


def test_every_command_that_walks_a_policy_takes_the_observation_set():
    """learn / curriculum (``runner.start_policy``), evaluate (``load_policies``), evolve (``EvolveConfig``) and
    train-base-policy (``resolve_settings``) pick the perceptive set; a ``--policy`` of another set than
    ``--observation`` is one line. Host only: nothing compiles. (evaluate's and train-base-policy's own choices:
    tests/integration/test_stage_commands.py.)"""
    from jaxterrain import qd
    from jaxterrain.curriculum import runner

    from jaxterrain.curriculum import run_config
    from jaxterrain.curriculum.presets import FLAT_PRESETS

    def run(**walker):  # the smoke preset's run with these walker settings
        return run_config.from_flat({**FLAT_PRESETS["smoke"], **walker})

    seeing_dir = rl.base_policy_dir("humanoid", "perceptive")
    assert runner.start_policy(run(observation="perceptive")).path == seeing_dir
    assert runner.start_policy(run(observation="perceptive", robot="ant")).path == rl.base_policy_dir("ant",
                                                                                                   "perceptive")
    assert runner.start_policy(run(policy=str(seeing_dir))).observation_size == 198  # a policy brings its own set
    with pytest.raises(runner.BadInput, match="^LearnConfig.walker.policy .*base_policy: it observes blind, not "
                                              "LearnConfig.walker.observation perceptive$"):
        runner.start_policy(run(observation="perceptive", policy=str(rl.base_policy_dir())))
    assert qd.config.config_from_dict(qd.config.config_to_dict(qd.EvolveConfig(observation="perceptive"))
                                      ).observation == "perceptive"
    with pytest.raises(ValueError, match="EvolveConfig.observation must be 'blind' or 'perceptive'"):
        qd.config.resolve_config(qd.EvolveConfig(observation="eyes"))


@pytest.mark.slow  # 10-70 s on 2 CPU cores; the default suite keeps under 15 min (2026-11-29)
def test_the_perceptive_twin_walks_flat_ground_with_the_blind_actions():
    """On the states of its own flat-ground walk (4 walks x 30 env steps, one jitted program) the twin's actions are
    the blind policy's on the blind part of the observation, to 1e-6."""
    from jaxterrain.walker import make_env

    blind, seeing = rl.load_policy(), difficulty.robot_base_policy("humanoid", "perceptive")
    env = make_env(difficulty.default_env_config((48, 48), TerrainScale(), seeing))
    terrain, nb = env.flat_terrain(), blind.observation_size

    def walk(key):
        s = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(key, 4), terrain)

        def body(s, _):
            a = seeing(s.obs)
            return jax.vmap(env.step, in_axes=(0, 0, None))(s, a, terrain), jnp.max(jnp.abs(a - blind(s.obs[:, :nb])))

        return jax.lax.scan(body, s, None, length=30)

    last, diff = jax.jit(walk)(jax.random.PRNGKey(3))
    assert float(jnp.max(diff)) <= 1e-6 and float(jnp.min(last.data.qpos[:, 0])) > env.x_start  # walked forward


def test_scan_lr_scale_shrinks_adams_steps_on_the_first_layers_scan_rows_only():
    """``PPOConfig(scan_inputs=S, scan_lr_scale=c)``: one Adam step moves the first-layer kernel rows that read the
    last S observation entries (policy and value networks) c times as far as with c = 1, and every other weight
    exactly as far; bad values are refused in one line."""
    base = rl.load_policy()
    extra = 153
    params, _ = rl.widen_inputs(base.params, base.normaliser, extra, np.zeros(extra, np.float32),
                                np.ones(extra, np.float32))
    grads = jax.tree_util.tree_map(lambda p: jnp.ones_like(p) * 0.5, params)  # same gradient on every weight

    def step(config):
        opt = rl.make_optimizer(config)
        updates, _ = opt.update(grads, opt.init(params), params)
        return updates

    plain = step(base.config._replace(scan_inputs=extra))  # scale 1: as every weight
    scaled = step(base.config._replace(scan_inputs=extra, scan_lr_scale=0.1))
    for net in ("policy", "value"):
        k_plain = np.asarray(plain[net]["params"]["mlp"]["hidden_0"]["kernel"])
        k_scaled = np.asarray(scaled[net]["params"]["mlp"]["hidden_0"]["kernel"])
        blind = k_plain.shape[0] - extra
        assert k_plain.shape[0] == base.observation_size + extra
        np.testing.assert_allclose(k_scaled[blind:], 0.1 * k_plain[blind:], rtol=1e-6)
        np.testing.assert_array_equal(k_scaled[:blind], k_plain[:blind])
        assert np.abs(k_plain[blind:]).min() > 0
        np.testing.assert_array_equal(np.asarray(scaled[net]["params"]["mlp"]["hidden_1"]["kernel"]),
                                      np.asarray(plain[net]["params"]["mlp"]["hidden_1"]["kernel"]))
    recorded = base.config._replace(scan_inputs=extra, scan_lr_scale=0.1)
    assert rl.PPOConfig.from_json_dict(recorded.to_json_dict()) == recorded  # a policy file records both
    with pytest.raises(ValueError, match="^PPOConfig.scan_lr_scale must be a finite number > 0.0"):
        rl.validate_config(base.config._replace(scan_lr_scale=0.0))
    with pytest.raises(ValueError, match="scan_inputs"):
        rl.validate_config(base.config._replace(scan_inputs=-1))


def test_scan_lr_scale_refuses_networks_whose_first_layer_is_not_wider_than_the_scan():
    """``scale_scan_rows`` (``make_optimizer`` with ``scan_lr_scale`` != 1) scales the last ``scan_inputs`` rows of
    every first-layer kernel; networks with no first layer, or one of ``scan_inputs`` rows or fewer (a blind
    policy's, or a scan size that is not the walker's), are refused in one line at ``init`` and at ``update``."""
    config = rl.PPOConfig(policy_hidden=(4,), value_hidden=(4,), scan_inputs=6, scan_lr_scale=0.1)
    wide = nets.init_params(jax.random.PRNGKey(0), config, 9, 2)  # 3 blind entries, then 6 scanned
    opt = rl.make_optimizer(config)
    updates, _ = opt.update(jax.tree.map(jnp.ones_like, wide), opt.init(wide), wide)
    kernel = np.asarray(updates["policy"]["params"]["mlp"]["hidden_0"]["kernel"])
    np.testing.assert_allclose(kernel[3:], 0.1 * kernel[:3].mean() * np.ones_like(kernel[3:]), rtol=1e-5)
    for narrow in (nets.init_params(jax.random.PRNGKey(0), config, 6, 2),  # the scan alone: no blind rows
                   nets.init_params(jax.random.PRNGKey(0), config, 4, 2),
                   {"policy": {"params": {"dense": {"kernel": jnp.ones((9, 4))}}}}):  # no hidden_0 at all
        with pytest.raises(ValueError, match=r"^rl.scale_scan_rows: scan_inputs=6 needs first-layer kernels"):
            opt.init(narrow)
        scale = rl.scale_scan_rows(6, 0.1)
        with pytest.raises(ValueError, match=r"^rl.scale_scan_rows: scan_inputs=6 needs"):
            scale.update(narrow, scale.init(wide))
    assert rl.make_optimizer(config._replace(scan_lr_scale=1.0)).init(narrow) is not None  # scale 1: nothing scaled
