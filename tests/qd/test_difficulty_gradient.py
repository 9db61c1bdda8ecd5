"""jaxterrain.qd.gradient: the band table, correlations and sampling on hand-made archives (NumPy only), the
driver on a shipped archive's stored fitness (no walking: seconds), and reseating. The command around it:
tests/integration/test_gradient.py."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from jaxterrain import qd
from jaxterrain.qd import gradient as G

RESULTS = Path(__file__).resolve().parents[2] / "docs" / "results"


def _hand_made(bins=10):
    """A 10 x 10 archive: cells on the diagonal band filled, fitness 1 near (0, 0) falling to 0 at the far corner."""
    cells = np.array([i * bins + j for i in range(bins) for j in range(bins) if abs(i - j) <= 1])
    b = qd.cell_bins(cells, bins)
    fitness = 1.0 - np.hypot(b[:, 0], b[:, 1]) / np.hypot(bins - 1, bins - 1)
    return cells, b, fitness.astype(np.float32)


def test_cell_bins_and_distances():
    """Cell i * bins + j has descriptor-0 bin j, descriptor-1 bin i; corner distance = hypot(b0 + 1, b1 + 1)."""
    b = qd.cell_bins(np.array([0, 1, 50, 2499, 7 * 50 + 3]), 50)
    assert b.tolist() == [[0, 0], [1, 0], [0, 1], [49, 49], [3, 7]]
    np.testing.assert_allclose(G.distance_from_origin(b, "corner"), [np.sqrt(2), np.sqrt(5), np.sqrt(5),
                                                                     np.hypot(50, 50), np.hypot(4, 8)], rtol=1e-6)
    np.testing.assert_allclose(G.distance_from_origin(b, "index"), [0, 1, 1, np.hypot(49, 49), np.hypot(3, 7)],
                               rtol=1e-6)
    with pytest.raises(ValueError, match="distance"):
        G.distance_from_origin(b, "manhattan")


def test_band_table_hand_made():
    d = np.array([0.0, 3.0, 9.99, 10.0, 15.0, 19.0, 35.0, 36.0])
    f = np.array([1.0, 0.9, 0.5, 0.95, 0.2, np.nan, 0.91, 0.89])
    t = G.band_table(d, f, width=10.0, threshold=0.9)
    assert t["lo"].tolist() == [0, 10, 20, 30] and t["hi"].tolist() == [10, 20, 30, 40]
    assert t["filled"].tolist() == [3, 3, 0, 2]
    np.testing.assert_allclose(t["share"], [2 / 3, 1 / 3, np.nan, 1 / 2])  # NaN fitness counts as not easy
    np.testing.assert_allclose(t["mean"], [2.4 / 3, 1.15 / 3, np.nan, 0.9])
    t = G.band_table(d, f, width=20.0, threshold=0.5, bands=3)  # a fixed number of bands, the last one empty
    assert t["filled"].tolist() == [6, 2, 0] and np.isnan(t["share"][2])
    np.testing.assert_allclose(t["share"][:2], [4 / 6, 1.0])
    for kwargs, match in ((dict(width=0.0), "width"), (dict(threshold=0.0), "threshold"),
                          (dict(threshold=1.5), "threshold"), (dict(bands=0), "bands")):
        with pytest.raises(ValueError, match=match):
            G.band_table(d, f, **kwargs)
    with pytest.raises(ValueError, match="same length"):
        G.band_table(d[:3], f)


def test_gradient_of_a_hand_made_archive():
    cells, b, fitness = _hand_made()
    d = G.distance_from_origin(b, "index")
    t = G.band_table(d, fitness, width=5.0, threshold=0.6)
    # fitness >= 0.6 <=> d <= 0.4 * 12.73 = 5.09: all 10 cells below 5, 2 of the 12 in [5, 10) (d = 5.0), none beyond
    assert t["filled"].tolist() == [10, 12, 6] and cells.size == 28
    np.testing.assert_allclose(t["share"], [1.0, 2 / 12, 0.0])
    pearson, spearman = G.correlations(d, fitness)
    assert pearson == pytest.approx(-1.0) and spearman == pytest.approx(-1.0)
    assert all(np.isnan(G.correlations(d, np.ones_like(d))))


def test_correlations_with_ties_and_spread_sample():
    # ties share their average rank: ranks of d are 3.5 1 3.5 2, of f 1 2 3 4 -> Spearman = Pearson of those ranks
    pearson, spearman = G.correlations(np.array([3.0, 1.0, 3.0, 2.0]), np.array([1.0, 2.0, 3.0, 4.0]))
    assert spearman == pytest.approx(np.corrcoef([3.5, 1.0, 3.5, 2.0], [1, 2, 3, 4])[0, 1])
    assert pearson == pytest.approx(np.corrcoef([3.0, 1.0, 3.0, 2.0], [1, 2, 3, 4])[0, 1])
    d = np.array([5.0, 1.0, 9.0, 3.0, 7.0, 2.0])
    rows = G.spread_sample(d, 3)  # sorted positions 0, 2 (round(2.5)), 5: the nearest, one between, the farthest
    assert rows.tolist() == [1, 2, 3] and d[rows].tolist() == [1.0, 9.0, 3.0]
    assert G.spread_sample(d, None).tolist() == list(range(6)) and G.spread_sample(d, 10).size == 6


@pytest.mark.slow  # 40 s on 2 CPU cores (renders the 1 096 genomes twice); the rule itself: test_map_elites' reseat
def test_reseat_of_the_shipped_cppn_archive_matches_insertion_bug_counts(tmp_path):
    """``write_reseated`` (``--reseat``) on the pre-fix CPPN archive, fed its stored fitness instead of a walk: the
    289 genomes ``validate`` refuses (docs/results/insertion_bug.md) are dropped, every kept elite re-derives to its
    cell, and the file loads as an archive. The walk itself is the command's GPU part (not run here)."""
    from jaxterrain import qd as A

    elites = G.load_elites(str(RESULTS / "exp1b_gpu_sound_cppn_archive.npz"))
    walked = {"rows": np.arange(elites["cells"].size), "fitness": elites["fitness"]}
    from jaxterrain import difficulty

    counts = G.write_reseated(tmp_path / "cppn_reseated.npz", elites, walked, difficulty.HEADINGS)
    assert counts["elites"] == 1096 and counts["refused"] == 289
    assert counts["kept"] == 1096 - 289 - counts["displaced"] and counts["moved"] >= counts["displaced"] > 0
    out = A.load(tmp_path / "cppn_reseated.npz")
    assert int(out.filled.sum()) == counts["kept"] and A.check_cells(out).all()
    assert (out.config.attempts, out.config.best, out.config.headings) == (80, 5, 4)  # the protocol it was given


def test_the_driver_returns_the_tables_it_writes(tmp_path):
    """``gradient(archives, folder)`` on the shipped sound Perlin archive's stored fitness: issue 13's band shares
    (68, 27, 1, 0, 0, 0 % by index distance), returned as rows and written as the CSV files; without a folder it
    writes nothing and returns the same rows."""
    archive = RESULTS / "exp1b_gpu_sound_perlin_archive.npz"
    lines = []
    result = G.gradient([archive], tmp_path / "run", say=lines.append)
    index = [r for r in result.bands if r["distance"] == "index" and r["series"] == "stored"]
    assert [round(100 * r["share_easy"]) for r in index[:6]] == [68, 27, 1, 0, 0, 0]
    assert len(result.summary) == 1 and result.summary[0]["spearman"] < -0.5 and result.walks == {}
    rows = list(csv.DictReader(open(tmp_path / "run" / "gradient.csv")))
    assert len(rows) == len(result.bands) and [float(r["band_lo"]) for r in rows] == [r["band_lo"] for r in result.bands]
    assert lines and lines[-1].startswith("  stored: n 481")
    again = G.gradient([archive], say=lambda line: None)
    assert again.summary == result.summary and not (tmp_path / "none").exists()
    with pytest.raises(ValueError, match="distance must be one of corner, index"):
        G.gradient([archive], settings=G.GradientSettings(distance="manhattan"))
    with pytest.raises(ValueError, match="reseat needs a protocol"):
        G.gradient([archive], reseat_walked=True)
    with pytest.raises(ValueError, match="missing.npz: cannot read it"):
        G.load_elites(tmp_path / "missing.npz")
