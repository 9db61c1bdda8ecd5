"""``CurriculumConfig.eval_lag`` on the command line (``--overlap --eval-lag``), the walker's MJX on tiles at the
smoke preset: a two-treatment population stopped by its time limit after its first chunk and resumed ends bit for
bit where the uninterrupted one did (every file, summary and checkpoint leaf), and the lag shows in history.csv
(each terrain's extra chunk unevaluated, ``seen_epoch`` one chunk after ``epoch``). The solo runner: ``learn`` the
same way. Minutes of CPU (two programs compile)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from curriculum_archives import tiny_archive_file
from run_files import checkpoint, rows, summary

pytestmark = pytest.mark.slow

FILES = ("history.csv", "sequences.csv", "milestones.csv", "milestones.md", "metrics.csv")


def cli(*argv):
    from experiments.__main__ import main

    return main(list(argv))


def same_run(a: Path, b: Path) -> None:
    for file in FILES:
        assert (a / file).read_text() == (b / file).read_text(), (a, file)
    assert summary(a) == summary(b)
    one, two = checkpoint(a), checkpoint(b)
    assert one.keys() == two.keys() and all(np.array_equal(one[k], two[k], equal_nan=True) for k in one)


@pytest.fixture(scope="module")
def archives(tmp_path_factory):
    from jaxterrain import qd as A

    folder = tmp_path_factory.mktemp("arch")
    a = tiny_archive_file(folder, 4, "a.npz")
    arch = A.load(a)
    b = arch._replace(fitness=np.where(arch.source >= 0, 0.7 * arch.fitness + 0.1, arch.fitness).astype(np.float32))
    return a, str(A.save(folder / "b.npz", b))


LAG = ("--preset", "smoke", "--overlap", "--eval-lag", "--max-epochs", "6")


def test_a_lagged_population_resumes_to_the_uninterrupted_run_and_shows_its_lag(archives, tmp_path, capsys):
    a, b = archives
    whole, part = tmp_path / "whole", tmp_path / "part"
    args = ("curriculum", *LAG, "--archives", f"a={a}", f"b={b}", "--no-combined")
    assert cli(*args, "--out", str(whole)) == 0
    assert cli(*args, "--out", str(part), "--time-limit", "1e-6") == 3
    assert cli("curriculum", "--resume", str(part)) == 0
    for name in ("a-map", "b-map"):
        same_run(part / name, whole / name)
        assert json.loads((whole / name / "config.json").read_text())["eval_lag"] is True
        history = rows(whole / name / "history.csv")
        lagged = [r for r in history if r["evaluation"] != "nan"]
        unevaluated = [r for r in history if r["evaluation"] == "nan"]
        last = {r["trial"]: r for r in history}  # each trial's last row (every trial finished)
        assert lagged and all(int(r["seen_epoch"]) == int(r["epoch"]) + (r is not last[r["trial"]])
                              for r in lagged)  # one chunk (of 1 epoch) later, but at the end
        assert unevaluated and all(r["seen_epoch"] == "-1" for r in unevaluated)
        for r in unevaluated:  # the chunk after a terrain's last evaluation, on that terrain
            before = next(p for p in history if p["trial"] == r["trial"] and int(p["chunk"]) == int(r["chunk"]) - 1)
            assert before["terrain"] == r["terrain"] and before["evaluation"] != "nan"


def test_a_lagged_learn_run_resumes_to_the_uninterrupted_run(archives, tmp_path):
    a, _ = archives
    whole, part = tmp_path / "whole", tmp_path / "part"
    assert cli("learn", *LAG, "--archive", a, "--out", str(whole)) == 0
    assert cli("learn", *LAG, "--archive", a, "--out", str(part), "--time-limit", "1e-6") == 3
    assert cli("learn", "--resume", str(part)) == 0
    same_run(part, whole)
