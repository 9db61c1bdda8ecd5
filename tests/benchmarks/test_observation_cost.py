"""benchmarks/observation_cost.py: bad flags are one line before any JAX work, and each robot's blind and perceptive
walkers get its shipped base policy and perceptive twin (no compile here: the timed loops compile MJX, minutes on a
CPU, and their figures are the GPU machine's)."""

import pytest

from benchmark_loader import load_benchmark

bench = load_benchmark("observation_cost")


@pytest.mark.parametrize("argv", [["--variants", "blind,eyes"], ["--layouts", "shared"], ["--batch-sizes", "0"],
                                  ["--robot", "dog"]])
def test_bad_flags_are_one_line(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        bench.parse_args(argv)
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 2 and len(err.splitlines()) == 1 and ": error: " in err


@pytest.mark.parametrize("robot, scan", [("humanoid", 153), ("ant", 187)])
def test_each_robot_walks_its_blind_policy_and_its_perceptive_twin(robot, scan):
    size = 96
    blind_env = bench.WalkerEnv(bench.WalkerConfig(terrain_shape=(size, size), robot=robot))
    seeing_env = bench.WalkerEnv(bench.WalkerConfig(terrain_shape=(size, size), robot=robot, observation="perceptive"))
    assert seeing_env.observation_size - blind_env.observation_size == scan
    policies, desc = bench.policies(robot, blind_env, seeing_env)
    assert policies["perceptive"].observation_size == seeing_env.observation_size
    assert desc["perceptive"].endswith("_perceptive") and not desc["blind"].endswith("_perceptive")
