"""The pool model of benchmarks/rollout_order.py, whose step counts RESULTS.md reports."""


import numpy as np

from benchmark_loader import load_benchmark

rollout_order = load_benchmark("rollout_order")


def test_pool_model_by_hand():
    lengths = np.array([10, 3, 3, 20])
    # 2 slots, refill every 8: job 0 holds slot A to 16; jobs 1, 2 take slot B at 0 and 8; job 3 starts at 16 -> 40
    assert rollout_order.pool_steps(lengths, np.arange(4), 2) == 40
    # longest first: job 3 on A until 24, job 0 on B until 16, job 1 at 16 -> 24, job 2 at 24 -> 32
    assert rollout_order.pool_steps(lengths, np.array([3, 0, 1, 2]), 2) == 32


def test_pool_model_bounds():
    rng = np.random.default_rng(0)
    lengths = rng.integers(1, 400, 5000)
    for slots in (64, 512, 8192):
        steps = rollout_order.pool_steps(lengths, np.arange(lengths.size), slots)
        assert steps % 8 == 0
        assert steps >= max(-(-lengths.sum() // slots), -(-lengths.max() // 8) * 8)
    # one slot per job: the longest rollout, rounded up to the refill interval
    assert rollout_order.pool_steps(lengths, np.arange(lengths.size), 10**6) == -(-lengths.max() // 8) * 8
