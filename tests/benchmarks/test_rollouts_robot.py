"""benchmarks/rollouts.py --robot: an unknown robot fails in one line naming the flag, before any JAX work; a known
one gets its own walker config and shipped base policy (no compile here)."""

import jax
import pytest

from benchmark_loader import load_benchmark

rollouts = load_benchmark("rollouts")


def test_unknown_robot_is_one_line_naming_the_flag(capsys):
    with pytest.raises(SystemExit) as exc:
        rollouts.parse_args(["--robot", "dog"])
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 2
    names = ", ".join(rollouts.walker.robots.names())  # humanoid, ant (and any a test registered)
    assert len(err.splitlines()) == 1 and err.endswith(f": error: --robot: robot must be one of {names}, got 'dog'")


def test_default_is_the_humanoid():
    assert rollouts.parse_args([]).robot == "humanoid"
    assert rollouts.WalkerConfig(robot=rollouts.parse_args([]).robot) == rollouts.WalkerConfig()


def test_ant_walks_its_shipped_policy():
    args = rollouts.parse_args(["--robot", "ant", "--size", "96"])  # 3.84 m: the ant needs 1.0 + 1.3 m of margins
    env = rollouts.WalkerEnv(rollouts.WalkerConfig(terrain_shape=(args.size, args.size), robot=args.robot))
    policy, desc = rollouts.make_policy(env, jax.random.PRNGKey(0), args.robot)
    assert env.action_size == 8 and policy.action_size == 8
    assert desc.startswith("shipped base policy") and desc.rstrip(")").endswith("base_policy_ant")
