"""``docs/results/suite_v2/reevaluate.py`` walking for real at a tiny size on the CPU (MJX-JAX, 11 terrains of 96
pixels, 2 walks each): its rows are ``evaluate``'s for the same flags, and a robot's base policy and its walkers of
two recipes (the paper's and the wide one, trained with other envs and minibatches) go through ONE compiled program:
after the first walk nothing is traced or compiled again (issue 60 item 4, issue 61 item 4)."""

from __future__ import annotations


import numpy as np
import pytest

from jaxterrain import suite
from reevaluate_v2 import args, exp, load_script, ROOT, SCRIPT  # exp: a fixture


@pytest.fixture
def script():
    return load_script()


@pytest.mark.slow
def test_the_walks_are_evaluates_rows_and_a_robots_policies_share_one_program(script, exp, capsys):
    """Real walks (MJX-JAX on the CPU, 11 terrains of 96 pixels, 2 walks each): the base policy with 2 keys and two
    walkers of two recipes; the first walk compiles (about a minute) and no later walk compiles or retraces its
    program. Then ``evaluate`` with the same flags writes the same rows."""
    from jax import monitoring

    events = []
    monitoring.register_event_duration_secs_listener(
        lambda name, secs, **kw: events.append((name, secs)) if name.startswith("/jax/core/compile") else None)
    per_call = []
    for _ in range(4):  # started long ago: each call walks one job (the first of a call always runs)
        n = len(events)
        assert script.main(args("--time-limit", "0.001")) == 0
        per_call.append([(name, secs) for name, secs in events[n:]])
    out = capsys.readouterr().out
    assert out.count("mean fitness") == 4 and out.count("compile included") == 4  # a new process each call...
    slow = [[e for e in call if e[1] > 1.0] for call in per_call]
    assert slow[0], "the first walk compiles its program"
    assert slow[1:] == [[], [], []], slow  # ...but in this one, the program compiled once: nothing retraced
    assert script.main(args("--write")) == 0
    from experiments.__main__ import main as cli

    assert cli(["evaluate", "--preset", "smoke", "--suite", "v2", "--robot", "humanoid", "--size", "96", "--seeds",
               "1", "--families", "flat", "boxes", "--generators", "--attempts", "2", "--best", "1", "--headings", "1",
               "--backend", "jax", "--keys", "2", "--policy", "exp/a/policies/trial_0", "exp/b/policies/trial_0",
               "--out", "ev"]) == 0
    ev = suite.read_fitness(exp / "ev" / "fitness.csv")
    base = suite.read_fitness(exp / "base" / "humanoid" / "fitness.csv.gz")
    a = suite.read_fitness(exp / "exp" / "a" / "heldout_v2" / "fitness.csv.gz")
    b = suite.read_fitness(exp / "exp" / "b" / "heldout_v2" / "fitness.csv.gz")
    assert ev.policies == ["base", "base:key1", "exp/a/policies/trial_0", "exp/b/policies/trial_0"]
    np.testing.assert_array_equal(ev.fitness, np.stack([base.fitness[0], base.fitness[1], a.fitness[1], b.fitness[1]]))
    assert ev.fitness[0, 0] == pytest.approx(1.0)  # flat ground: crossed


@pytest.mark.slow
def test_gpus_n_runs_n_processes_on_parts_of_the_jobs_into_one_work_folder_and_packs_it(script, exp, capsys):
    """``--gpus 2`` on the CPU (CUDA_VISIBLE_DEVICES set but unused): two processes, each with its part of the 4
    walks and its own compile, then one tar of the work folder."""
    import subprocess
    import sys
    import tarfile

    run = subprocess.run([sys.executable, str(SCRIPT), *args("--gpus", "2", "--pack", "out/v2eval.tar.gz")],
                         capture_output=True, text=True, cwd=exp, env={**__import__("os").environ,
                                                                       "PYTHONPATH": str(ROOT)}, timeout=900)
    assert run.returncode == 0, run.stdout + run.stderr
    lines = run.stdout.splitlines()
    assert sum(line.startswith("[gpu 0] ") and "mean fitness" in line for line in lines) == 2
    assert sum(line.startswith("[gpu 1] ") and "mean fitness" in line for line in lines) == 2
    with tarfile.open(exp / "out" / "v2eval.tar.gz") as tar:
        assert sum(m.startswith("work/results/") for m in tar.getnames()) == 4
