"""``docs/results/suite_v2/restate.py`` on a made-up page: two treatments evaluated on a small "v1" and "v2" (the
files ``evaluate`` and ``reevaluate.py`` write, fitness made up), the v1 aggregate shipped beside them. It runs
``generalise`` on v2 with v1 beside it and writes the page's digest, whose figures are the ones the files imply;
without the v2 evaluations it refuses, naming what is missing."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from jaxterrain import suite
from scripts import load_script

SCRIPT = Path(__file__).resolve().parents[2] / "docs" / "results" / "suite_v2" / "restate.py"


@pytest.fixture(scope="module")
def restate():
    module = load_script(SCRIPT, "suite_v2_restate")
    return module


@pytest.fixture(scope="module")
def small():
    """A suite's table (no heightmaps: nothing here walks or draws a terrain): flat, boxes at 10 levels x 2 seeds
    and 10 Perlin samples in 3 bands (``Suite`` as ``batch.Store.suite`` gives it)."""
    from jaxterrain.terrain import TerrainScale

    rows = [("flat", 0, 0, 0.0)] + [("boxes", lv, s, 0.03 + 0.01 * lv) for lv in range(10) for s in range(2)] + \
        [("gen:perlin", k % 3, k // 3, 1.0 + k) for k in range(10)]
    rows = rows[:21] + sorted(rows[21:], key=lambda r: (r[1], r[2]))
    return suite.Suite("v2:humanoid-custom(test)", np.zeros((len(rows), 0, 0), np.float32),
                       np.array([r[0] for r in rows]), np.array([r[1] for r in rows]),
                       np.array([r[2] for r in rows]), np.array([r[3] for r in rows]),
                       {"flat": "-", "boxes": "m height", "gen:perlin": "cells"}, TerrainScale(), {}, {}, "humanoid")


def evaluation(folder: Path, s, base: np.ndarray, walkers: np.ndarray, prefix: str):
    names = ["base"] + [f"{prefix}/policies/trial_{k}" for k in range(len(walkers))]
    suite.write_evaluation(folder, names, s, np.vstack([base[None], walkers]), suite_figure=False)
    (folder / "config.json").write_text(json.dumps({"suite": s.name.split(":")[0], "robot": "humanoid"}))


def page(root: Path, s):
    """``root/docs/results/expA/{good,fair}`` with v1 (``heldout``) and v2 (``heldout_v2``) evaluations, their
    summaries, the base policy's v2 evaluation with 3 keys and the v1 aggregate."""
    from experiments.__main__ import main as cli

    rng = np.random.default_rng(0)
    n = s.size
    base = np.clip(0.3 + 0.1 * rng.random(n), 0, 1)
    exp = root / "docs" / "results" / "expA"
    for name, lift, heldout in (("good", (0.4, 0.3), "heldout"), ("fair", (0.2, 0.35), "heldout"),
                                ("good", (0.4, 0.3), "heldout_v2"), ("fair", (0.2, 0.35), "heldout_v2")):
        up = lift[0] if heldout == "heldout" else lift[1]   # v2 reverses the order of the two
        walkers = np.clip(base[None] + up + 0.02 * rng.standard_normal((5, n)), 0, 1)
        evaluation(exp / name / heldout, s, base, walkers, f"expA/{name}")
        (exp / name / "summary.json").write_text(json.dumps({"hardest": [10.0, 11, 12, 13, 14]}))
    keys = np.clip(base[None] + 0.01 * rng.standard_normal((3, n)), 0, 1)
    suite.write_evaluation(root / "base_v2" / "humanoid", ["base", "base:key1", "base:key2"], s, keys,
                           suite_figure=False)
    assert cli(["generalise", str(exp), "--reps", "50", "--permutations", "20", "--out",
                str(exp / "generalisation")]) == 0
    return {"page": "docs/results/expA.md", "robot": "humanoid", "runs": ["docs/results/expA"],
            "v1": "docs/results/expA/generalisation", "out": "docs/results/expA/generalisation_v2",
            "pairs": [("good", "fair")]}


def test_the_digest_sets_v2_beside_v1_with_the_figures_the_files_imply(restate, small, tmp_path):
    spec = page(tmp_path, small)
    nums = restate.restate("expA", spec, tmp_path, tmp_path / "base_v2", reps=50, permutations=20)
    v1, v2 = nums["v1"], nums["v2"]
    assert v1["order"] == ["good", "fair"] and v2["order"] == ["fair", "good"]
    assert v2["rows"]["base policy"]["runs"] == 3 and v1["rows"]["base policy"]["runs"] == 2   # 2 v1 evaluations beside
    assert v2["claims"]["beats_base"]["walkers_above_base_mean"] == 10
    assert v2["claims"]["best"]["treatment"] == "fair"
    (pair,) = v2["claims"]["pairs"]
    assert pair["x"] == "good" and pair["y"] == "fair" and pair["p"][0] < 0.1
    assert v1["claims"]["pairs"][0]["p"][0] > 0.9
    # level 0 of boxes: a walker passes where its two terrains' mean is >= 0.9
    s2 = suite.read_fitness(tmp_path / "docs/results/expA/fair/heldout_v2/fitness.csv")
    rows = (s2.family == "boxes") & (s2.level == 0)
    assert v2["level0"]["fair"]["boxes"] == int(np.sum(s2.fitness[1:, rows].mean(axis=1) >= 0.9))
    cv = v2["robustness"]["fair"]["perlin"]
    per = [suite.generator_robustness(f, s2.family)["perlin"]["cvar"] for f in s2.fitness[1:]]
    assert cv == pytest.approx(np.mean(per), abs=1e-3) and "base policy" in v2["robustness"]
    lv = {(r["treatment"], r["family"]): r for r in restate.read_csv(tmp_path / spec["out"] / "levels.csv")}
    assert v2["levels_gained"]["fair"]["boxes"] == [float(lv[("fair", "boxes")][k]) for k in
                                                    ("gain", "gain_low", "gain_high")]
    assert v2["levels_gained"]["base policy"]["boxes"][0] == float(lv[("fair", "boxes")]["base"])
    md = (tmp_path / "docs/results/suite_v2/restated/expA.md").read_text()
    assert "Levels passed on v2" in md
    assert md.startswith("# expA: the numbers of `docs/results/expA.md` on suite v2 beside v1")
    assert "| P(good > fair) |" in md and "## Worst decile" in md and "--heldout heldout_v2" in md
    assert (tmp_path / "docs/results/expA/generalisation_v2/beside.csv").is_file()
    data = json.loads((tmp_path / "docs/results/suite_v2/restated/expA.json").read_text())
    assert data["v2"]["order"] == ["fair", "good"]
    # without the v2 evaluations it refuses, naming what is missing
    with pytest.raises(ValueError, match="no v2 base evaluation"):
        restate.restate("expA", spec, tmp_path, tmp_path / "nowhere")
    (tmp_path / "docs/results/expA/fair/heldout_v2/fitness.csv").unlink()
    with pytest.raises(ValueError, match="no heldout_v2/ yet for fair"):
        restate.restate("expA", spec, tmp_path, tmp_path / "base_v2")
