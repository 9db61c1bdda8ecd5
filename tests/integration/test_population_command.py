"""``python -m experiments curriculum`` running its treatments as one population (``jaxterrain.curriculum.batch``):
the smoke preset on two tiny archives (4 terrains each: the CPPN archive's first cells, the second with other priors)
plus their combination, three map treatments of 2 trials each in one compiled program.

What "equal to its run alone" means, on a CPU (docs/tutorials/curriculum.md):

1. bit for bit against the treatment run alone with as many trials as the population holds (6 here): its trials
   are that run's first ones (the trials' keys, ``split(key, T)``, do not depend on T), every leaf of its checkpoint
   and every row of its history.csv the same;
2. against the treatment run alone with its own 2 trials (``--no-batch-treatments``): the same terrain sequences,
   chunks and epochs, evaluations within 0.05: XLA's CPU matrix products block their sums by the batch's size, so
   a larger batch changes the last bits of the training, which the walker's physics amplifies.

A population stopped by its time limit (after the one-chunk probe of the rate) and resumed ends bit for bit where
the uninterrupted one did. Several minutes of CPU: three programs compile."""

from __future__ import annotations

import json

import numpy as np
import pytest

from curriculum_archives import tiny_archive_file
from run_files import checkpoint, rows, summary

FILES = ("history.csv", "sequences.csv", "milestones.csv", "milestones.md", "metrics.csv")


def cli(*argv):
    from experiments.__main__ import main

    return main(list(argv))


@pytest.fixture(scope="module")
def archives(tmp_path_factory):
    from jaxterrain import qd as A

    folder = tmp_path_factory.mktemp("arch")
    a = tiny_archive_file(folder, 4, "a.npz")
    arch = A.load(a)
    b = arch._replace(fitness=np.where(arch.source >= 0, 0.7 * arch.fitness + 0.1, arch.fitness).astype(np.float32))
    return a, str(A.save(folder / "b.npz", b))


@pytest.fixture(scope="module")
def population(tmp_path_factory, archives):
    """``(run folder, stdout)`` of one uninterrupted batched ``curriculum --preset smoke`` run."""
    import contextlib
    import io

    a, b = archives
    run = tmp_path_factory.mktemp("pop") / "whole"
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert cli("curriculum", "--preset", "smoke", "--archives", f"a={a}", f"b={b}", "--out", str(run)) == 0
    return run, out.getvalue()


TREATMENTS = ("a-map", "b-map", "combined-map")


@pytest.mark.slow
def test_a_population_equals_its_treatments_run_alone(population, archives, tmp_path):
    """One line says the three map treatments share a program; each treatment's files equal its runs alone as the
    module docstring defines equal (1: bit for bit at the population's 6 trials; 2: at its own 2 trials, the same
    terrains and evaluations within 0.05)."""
    run, printed = population
    assert "population 1 of 1: a map, b map, combined map (3 treatments, 6 trials, 24 envs per physics call) in " \
           "one program" in printed
    paths = dict(zip(TREATMENTS, archives + (str(run / "combined_archive.npz"),)))
    for name, archive in paths.items():
        alone = tmp_path / f"six-{name}"
        assert cli("learn", "--preset", "smoke", "--archive", archive, "--trials", "6", "--out", str(alone)) == 0
        mine = run / name
        assert [r for r in rows(alone / "history.csv") if int(r["trial"]) < 2] == rows(mine / "history.csv"), name
        six, two = checkpoint(alone), checkpoint(mine)
        assert six.keys() == two.keys()
        assert all(np.array_equal(six[k][:2] if six[k].ndim else six[k], two[k], equal_nan=True) for k in two), name
    seq = tmp_path / "sequential"
    assert cli("curriculum", "--preset", "smoke", "--archives", f"a={archives[0]}", f"b={archives[1]}",
               "--no-batch-treatments", "--out", str(seq)) == 0
    for name in TREATMENTS:
        a, b = rows(run / name / "history.csv"), rows(seq / name / "history.csv")
        assert [(r["trial"], r["chunk"], r["epoch"], r["terrain"]) for r in a] == \
            [(r["trial"], r["chunk"], r["epoch"], r["terrain"]) for r in b], name
        np.testing.assert_allclose([float(r["evaluation"]) for r in a], [float(r["evaluation"]) for r in b], atol=0.05)
        assert [r["terrain"] for r in rows(run / name / "sequences.csv")] == \
            [r["terrain"] for r in rows(seq / name / "sequences.csv")]
    assert (run / "table2.md").exists() and (run / "figure7a.png").exists()


@pytest.mark.slow
def test_a_stopped_population_resumes_to_the_uninterrupted_run(population, archives, tmp_path, capsys):
    """``--time-limit`` stops the population after its first chunk (the probe of the rate), every treatment
    checkpointed at chunk 1 (``--report`` reads them); ``--resume`` ends with the uninterrupted run's files, every
    checkpoint leaf and summary (wall time aside) bit for bit."""
    whole, _ = population
    a, b = archives
    part = tmp_path / "part"
    assert cli("curriculum", "--preset", "smoke", "--archives", f"a={a}", f"b={b}", "--out", str(part),
               "--time-limit", "1e-6") == 3
    assert "continue with: python -m experiments curriculum --resume" in capsys.readouterr().out
    from jaxterrain.runtime import driver

    for name in TREATMENTS:
        meta = driver.read_meta(part / name)
        assert meta["population"]["trials"] == 6 and not (part / name / "summary.json").exists()
    assert cli("curriculum", "--resume", str(part), "--report") == 0
    assert json.loads((part / "a-map" / "summary_partial.json").read_text())["chunks_done"] == 1
    assert cli("curriculum", "--resume", str(part)) == 0
    assert "resuming a map at chunk 1 of 4, b map at chunk 1 of 4, combined map at chunk 1 of 4" in \
        capsys.readouterr().out
    for name in TREATMENTS:
        for file in FILES:
            assert (part / name / file).read_text() == (whole / name / file).read_text(), (name, file)
        assert summary(part / name) == summary(whole / name)
        one, two = checkpoint(part / name), checkpoint(whole / name)
        assert one.keys() == two.keys() and all(np.array_equal(one[k], two[k], equal_nan=True) for k in one)


def test_populations_split_in_one_line_where_a_program_does_not_fit(archives, tmp_path, monkeypatch):
    """``batch.run_treatments`` groups the three smoke treatments into one population; where its program needs more
    memory than the device has it splits the group in two, saying so in one line, until each part fits; with
    ``--population-envs`` the plan itself keeps groups under that many envs. (The programs are faked: nothing
    compiles.)"""
    from jaxterrain.curriculum import batch
    from experiments import curriculum as exp

    a, b = archives
    cfg = {**exp.PRESETS["smoke"], "seed": 0, "archives": {"a": a, "b": b}, "command": "curriculum"}
    plan = exp.treatments(cfg, tmp_path)
    treatments = [batch.Treatment(f"{n} {c}", exp.treatment_run(cfg, p, c), tmp_path / f"{n}-{c}") for n, p, c in plan]
    ran = []

    def setup(valid, memory_bytes, say):
        if len(valid) > 1:
            raise batch._TooBig(int(3.5 * batch.GIB * len(valid)), int(4 * batch.GIB))
        ran.append(valid[0].treatment.desc)
        return [], None, valid[0].run.budget, 2

    monkeypatch.setattr(batch, "_setup", setup)
    monkeypatch.setattr(batch, "drive", lambda members, *args, **kwargs: True)
    lines = []
    batch.run_treatments(treatments, say=lines.append)
    assert lines == ["population a map, b map, combined map: its program needs 10.5 GiB, the device has 4.0 GiB: "
                     "split into 2 and 1 treatments",
                     "population a map, b map: its program needs 7.0 GiB, the device has 4.0 GiB: split into 1 and "
                     "1 treatments",
                     "population 1 of 3: a map (1 treatment, 2 trials, 8 envs per physics call) in one program",
                     "population 2 of 3: b map (1 treatment, 2 trials, 8 envs per physics call) in one program",
                     "population 3 of 3: combined map (1 treatment, 2 trials, 8 envs per physics call) in one program"]
    assert ran == ["a map", "b map", "combined map"]
    lines.clear()
    batch.run_treatments(treatments, max_envs=16, say=lines.append)
    assert lines[0].startswith("population a map, b map: its program needs") and len(lines) == 4
    lines.clear()  # a label names the process in every line and progress bar (several processes, one log)
    descs = []
    monkeypatch.setattr(batch, "drive", lambda members, *args, **kwargs: descs.append(kwargs["desc"]) or True)
    batch.run_treatments(treatments, max_envs=16, say=lines.append, label="shard 1/2 population")
    assert lines[0].startswith("shard 1/2 population a map, b map: its program needs") and len(lines) == 4
    assert lines[2] == "shard 1/2 population 2 of 3: b map (1 treatment, 2 trials, 8 envs per physics call) in one program"
    assert descs == ["shard 1/2 population 1", "shard 1/2 population 2", "shard 1/2 population 3"]


def test_population_flags_are_checked_before_a_run_folder(tmp_path, capsys):
    """``--population-envs`` / ``--block-seconds``: out of range, or given where no population runs
    (``--no-batch-treatments``, ``--report``): one line naming the flag, exit status 2, no run folder."""
    cases = [(["--population-envs", "0"], "--population-envs must be an integer >= 1"),
             (["--block-seconds", "nan"], "--block-seconds must be a finite number > 0"),
             (["--population-envs", "64", "--no-batch-treatments"], "--no-batch-treatments runs them one after"),
             (["--block-seconds", "60", "--report"], "--report trains nothing")]
    for i, (argv, needle) in enumerate(cases):
        out = tmp_path / f"run{i}"
        with pytest.raises(SystemExit) as stop:
            cli("curriculum", "--preset", "smoke", "--out", str(out), *argv)
        err = capsys.readouterr().err.strip().splitlines()
        assert stop.value.code == 2 and len(err) == 1 and needle in err[0], (argv, err)
        assert not out.exists()
