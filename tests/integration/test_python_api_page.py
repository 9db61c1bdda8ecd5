"""docs/tutorials/python-api.md runs as written: each Python block in a fresh folder (the repository's docs/
reachable), its printed line what the page's drivers return. The curriculum block trains (minutes: slow)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "tutorials" / "python-api.md"
BLOCKS = re.findall(r"```python\n(.*?)```", PAGE.read_text(), flags=re.S)
EXPECTED = {  # block -> the line it prints
    0: "2 2 True",                                  # learn smoke: 2 trials, one walker each
    1: "3 3 ['batch_stats', 'params']",             # train-gan: 3 steps
    2: "[68, 27, 1] -0.85",                         # gradient: issue 13's shares of the sound Perlin archive
    3: "(4,) 16",                                   # features: 2 genomes + 2 mutants; 4 x 4 correlations
    4: "('worley',) (100,) [('combined', 'tri-tpi'), ('perlin', 'tri-tpi'), ('worley', 'tri-tpi')]",  # 10 x 10 cells
    5: "False 4 ['base'] (1, 24)",                  # 4 smoke updates; the base policy on 24 smoke terrains
}


def test_the_page_has_one_block_per_driver():
    assert len(BLOCKS) == len(EXPECTED)
    assert "result.run(" in BLOCKS[0] and "train_gan(" in BLOCKS[1] and "gradient.gradient(" in BLOCKS[2]
    assert "feature_alignment(" in BLOCKS[3] and "evolve_run(" in BLOCKS[4] and "coverage_run(" in BLOCKS[4]
    assert "train_base_policy(" in BLOCKS[5] and "evaluate_run(" in BLOCKS[5]


@pytest.mark.parametrize("block", [pytest.param(0, marks=pytest.mark.slow), 1, 2, 3, pytest.param(4, marks=pytest.mark.slow),
                                   pytest.param(5, marks=pytest.mark.slow)])  # 0: 377 s on 2 CPU cores (2026-11-29)
def test_a_block_runs_as_written(block, tmp_path, monkeypatch, capsys):
    (tmp_path / "docs").symlink_to(ROOT / "docs")
    monkeypatch.chdir(tmp_path)
    exec(compile(BLOCKS[block], f"python-api.md block {block}", "exec"), {})
    assert capsys.readouterr().out.strip().splitlines()[-1] == EXPECTED[block]
