"""``docs/results/eval_order/run.py`` end to end at the tiniest size on the CPU (slow: two ``learn`` programs and
two suite walks compile): the sequential and the lagged order trained (the lagged one stopped by its time limit and
resumed), both walked on a tiny suite, ``--pack`` and ``write`` (the hardest cell per trial with intervals over
trials, generalise on the held-out walks). Each stage run again says ``done`` without running anything. The stages
that run on the GPU machine run as there, without the packages its image lacks (``tests/gpu_image.py``)."""

from __future__ import annotations

import csv
import json
import tarfile
from pathlib import Path

import numpy as np
import pytest
from gpu_image import image
from scripts import load_script

from curriculum_archives import tiny_archive_file

SCRIPT = Path(__file__).resolve().parents[2] / "docs" / "results" / "eval_order" / "run.py"
TINY = ["--size", "96", "--seeds", "1", "--families", "flat", "boxes", "--generators", "--attempts", "2", "--best",
        "1", "--headings", "1"]


@pytest.mark.slow
def test_eval_order_stages_at_the_tiniest_size(tmp_path, monkeypatch, capsys, request):
    archive = tiny_archive_file(tmp_path, 4, "a.npz")  # from the repository root (the stored archive's path)
    monkeypatch.chdir(tmp_path)
    gpu = pytest.MonkeyPatch()  # the GPU image, until write
    request.addfinalizer(gpu.undo)
    image(gpu)
    run = load_script(SCRIPT, "eval_order_run")
    out = tmp_path / "runs"
    base = ["--out", str(out), "--preset", "smoke", "--eval-preset", "smoke", "--trials", "2", "--archive", archive]

    def stage(*argv):
        code = run.main([*argv, *base])
        return code, capsys.readouterr().out

    assert stage("write")[0] == 2  # nothing trained yet: one line
    assert stage("train", "sequential")[0] == 0
    assert stage("train", "lag", "--time-limit", "0.1")[0] == 3  # stopped after its probe chunk, resumable
    code, text = stage("train", "lag", "--pack", str(tmp_path / "eo.tar.gz"))
    assert code == 0 and "learn --resume" in text
    assert json.loads((out / "lag" / "config.json").read_text())["eval_lag"] is True
    code, text = stage("train", "sequential")
    assert code == 0 and "train sequential: done" in text and "+ python" not in text
    with tarfile.open(tmp_path / "eo.tar.gz") as tar:
        names = tar.getnames()
    assert any(n.endswith("lag/policies/trial_1/policy.msgpack") for n in names)
    assert not any(n.endswith("checkpoint.npz") for n in names)  # both finished
    for order in ("sequential", "lag"):
        assert stage("evaluate", order, *TINY)[0] == 0
    gpu.undo()
    results = tmp_path / "results"
    code, text = stage("write", "--results", str(results))
    assert code == 0, text
    with open(results / "hardest.csv") as f:
        rows = list(csv.DictReader(f))
    assert [(r["order"], r["trial"]) for r in rows] == [("sequential", "0"), ("sequential", "1"), ("lag", "0"),
                                                        ("lag", "1")]
    table = json.loads((results / "hardest.json").read_text())
    for order in ("sequential", "lag"):
        h = json.loads((out / order / "summary.json").read_text())["hardest"]
        assert table[order]["mean"][0] == pytest.approx(np.mean(h))
        assert table[order]["mean"][1] <= table[order]["mean"][0] <= table[order]["mean"][2]
    assert 0 <= table["lag"]["p_beats_sequential"][0] <= 1 and table["sequential"]["unevaluated"] == 0
    assert "| lag |" in (results / "comparison.md").read_text()
    assert (results / "generalisation" / "generalisation.md").is_file()


@pytest.mark.slow
def test_the_two_overlapped_orders_as_one_population_equal_their_solo_runs(tmp_path, monkeypatch, capsys):
    """``train overlap+lag`` runs both overlapped orders in one program (stopped by its time limit and resumed):
    each folder holds the ``config.json`` its own ``train`` writes and that run's results (its chunks' terrains as the
    order's solo run chose them, the hardest cell of every trial, and the evaluations within 0.05, as
    ``test_population_command``: the population's batch differs, so XLA's CPU sums differ in the last bits and the
    walks drift by up to 8e-4 over 4 chunks here),
    and ``train lag`` afterwards says done."""
    archive = tiny_archive_file(tmp_path, 4, "a.npz")
    monkeypatch.chdir(tmp_path)
    run = load_script(SCRIPT, "eval_order_run")

    def stage(out, *argv):
        code = run.main([*argv, "--out", str(out), "--preset", "smoke", "--trials", "2", "--archive", archive])
        return code, capsys.readouterr().out

    pair, solo = tmp_path / "pair", tmp_path / "solo"
    assert stage(pair, "train", "overlap+lag", "--time-limit", "0.05")[0] == 3
    code, text = stage(pair, "train", "overlap+lag")
    assert code == 0 and "train overlap+lag: done" in text, text
    for order in ("overlap", "lag"):
        assert stage(solo, "train", order)[0] == 0
        mine, theirs = (json.loads((f / order / "config.json").read_text()) for f in (pair, solo))
        assert {k: v for k, v in mine.items() if k != "archive"} == {k: v for k, v in theirs.items() if k != "archive"}
        a, b = (json.loads((f / order / "summary.json").read_text())["hardest"] for f in (pair, solo))
        np.testing.assert_allclose(a, b, atol=1e-4)
        rows = [list(csv.DictReader(open(f / order / "history.csv"))) for f in (pair, solo)]
        assert [(r["trial"], r["epoch"], r["terrain"]) for r in rows[0]] == [(r["trial"], r["epoch"], r["terrain"])
                                                                            for r in rows[1]]
        scores = np.array([[float(r["evaluation"]) for r in rr] for rr in rows])
        assert np.any(scores[1] > 0)  # the chunks' evaluations walked somewhere: a comparison that can fail
        np.testing.assert_allclose(scores[0], scores[1], atol=0.05)  # test_population_command's tolerance
        assert (pair / order / "policies" / "trial_1" / "policy.msgpack").is_file()
    code, text = stage(pair, "train", "lag")
    assert code == 0 and "train lag: done" in text and "+ python" not in text
