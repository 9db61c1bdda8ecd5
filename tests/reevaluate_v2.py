"""Shared by the tests of ``docs/results/suite_v2/reevaluate.py`` (the fast ones in ``tests/suite`` and the real
walks in ``tests/integration``): the script as a module, its tiny flags and two shipped walkers to walk."""

import shutil
from pathlib import Path

import pytest

import scripts

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "docs" / "results" / "suite_v2" / "reevaluate.py"
RESULTS = ROOT / "docs" / "results"
TINY = ["--size", "96", "--seeds", "1", "--families", "flat", "boxes", "--generators", "--attempts", "2", "--best",
        "1", "--headings", "1", "--backend", "jax", "--slots", "0", "--keys", "2"]
WALKERS = (("a", "exp3_gpushort/cppn-map/policies/trial_0"), ("b", "wide_gpushort/perlin-map/policies/trial_3"))


def load_script():
    """The module of ``reevaluate.py``."""
    module = scripts.load_script(SCRIPT, "suite_v2_reevaluate")
    return module


def make_experiment(root: Path) -> Path:
    """``root/exp``: treatments ``a`` (a paper-recipe walker) and ``b`` (a wide-recipe walker); returns ``root``."""
    for name, src in WALKERS:
        shutil.copytree(RESULTS / src, root / "exp" / name / "policies" / "trial_0")
    return root


def args(*extra):
    """The script's arguments for ``exp`` at the tiny size, plus ``extra``."""
    return ["exp", "--work", "work", "--base-out", "base", *TINY, *extra]


@pytest.fixture
def exp(tmp_path, monkeypatch):
    """``tmp_path/exp``: treatments ``a`` (a paper-recipe walker) and ``b`` (a wide-recipe walker); cwd tmp_path."""
    monkeypatch.chdir(tmp_path)
    return make_experiment(tmp_path)
