"""The gradient command (``python -m experiments gradient``; the library: tests/qd/test_difficulty_gradient.py): the
stored-fitness command on a shipped archive (no walking: seconds)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from experiments import gradient as G
from experiments.common import UsageError
from jaxterrain import qd

RESULTS = Path(__file__).resolve().parents[2] / "docs" / "results"


def test_stored_gradient_command_reproduces_issue_13(tmp_path):
    """The shipped sound Perlin archive: % of cells at fitness >= 0.9 by bands of 10 cells of index distance are
    issue 13's 68, 27, 1, 0, 0, 0 %; fitness falls with distance."""
    archive = RESULTS / "exp1b_gpu_sound_perlin_archive.npz"
    assert G.main(G_args([str(archive), "--out", str(tmp_path / "run")])) == 0
    rows = list(csv.DictReader(open(tmp_path / "run" / "gradient.csv")))
    index = [r for r in rows if r["distance"] == "index" and r["series"] == "stored"]
    assert [round(100 * float(r["share_easy"])) for r in index[:6]] == [68, 27, 1, 0, 0, 0]
    assert len(index) == 7 and int(index[6]["filled"]) == 0  # bands up to the grid's corner, hypot(49, 49)
    assert sum(int(r["filled"]) for r in index) == 481
    summary = list(csv.DictReader(open(tmp_path / "run" / "gradient_summary.csv")))
    assert len(summary) == 1 and float(summary[0]["spearman"]) < -0.5
    for name in ("gradient.md", "gradient.png", "config.json"):
        assert (tmp_path / "run" / name).stat().st_size > 0
    with pytest.raises(UsageError, match="headings"):  # one line of python -m experiments, exit status 2
        G.resolve_protocol({"protocol": "headings", "headings": 3})


def G_args(argv):
    import argparse

    parser = argparse.ArgumentParser()
    G.add_arguments(parser)
    return parser.parse_args(argv)


def test_reseat_needs_a_protocol(tmp_path):
    with pytest.raises(UsageError, match="--reseat needs --protocol"):
        G.main(G_args([str(RESULTS / "exp1b_gpu_sound_perlin_archive.npz"), "--reseat", "--out",
                       str(tmp_path / "run")]))
    assert not (tmp_path / "run").exists()  # refused before the run folder


def test_the_commands_distances_are_the_librarys():
    """``--distance``'s choices (listed in the command so that --help imports no JAX) are the library's."""
    from jaxterrain.qd import gradient

    assert G.DISTANCES == gradient.DISTANCES
