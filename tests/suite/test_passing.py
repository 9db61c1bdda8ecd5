"""Levels passed with the trial as the unit (`suite.passing`): the statistic of Experiment 4's target."""

import numpy as np
import pytest

from jaxterrain import suite
from jaxterrain.suite import passing

# Two families, three levels each, two terrains per level: N = 12.
FAMILY = np.array(["stairs"] * 6 + ["gaps"] * 6)
LEVEL = np.array([0, 0, 1, 1, 2, 2] * 2)


def _rows(per_level_stairs, per_level_gaps, n=1):
    """[n, 12] fitness with every terrain of a level at the given value."""
    row = np.concatenate([np.repeat(per_level_stairs, 2), np.repeat(per_level_gaps, 2)])
    return np.tile(row, (n, 1)).astype(np.float64)


def test_highest_passed_matches_the_scalar_rule_including_gaps_in_the_levels():
    cases = [[0.95, 0.93, 0.5, 0.91], [float("nan"), 0.95, 0.92], [0.5, 0.95], [float("nan")], [0.9, 0.9, 0.9]]
    for c in cases:
        assert passing.highest_passed(c) == suite.highest_level_passed(c)


def test_levels_passed_agrees_with_passed_levels_for_each_policy():
    rng = np.random.default_rng(0)
    f = np.clip(rng.normal(0.85, 0.15, (3, 12)), 0, 1)
    fams, got = passing.levels_passed(f, FAMILY, LEVEL)
    for p in range(3):
        want = {}
        for fam in fams:
            rows = FAMILY == fam
            per = [f[p, rows & (LEVEL == k)].mean() for k in range(3)]
            want[fam] = suite.highest_level_passed(per)
        assert dict(zip(fams, got[p].tolist())) == want


def test_a_known_gain_has_a_zero_width_interval_when_rows_are_identical():
    walkers = _rows([1.0, 1.0, 1.0], [1.0, 0.95, 0.2], n=4)   # stairs: level 2; gaps: level 1
    base = _rows([0.5, 0.5, 0.5], [0.95, 0.1, 0.1], n=3)       # stairs: -1;      gaps: level 0
    g = passing.levels_passed_gain(walkers, base, FAMILY, LEVEL, reps=200)
    assert g["stairs"]["gain"] == (3.0, 3.0, 3.0)
    assert g["gaps"]["gain"] == (1.0, 1.0, 1.0)
    assert g["stairs"]["base"] == (-1.0, -1.0, -1.0)


def test_the_interval_resamples_whole_trials():
    # Half the trials pass stairs to level 2, half fail level 0: the gain's interval spans the trials' spread.
    walkers = np.concatenate([_rows([1, 1, 1], [1, 1, 1], n=5), _rows([0, 0, 0], [1, 1, 1], n=5)])
    base = _rows([0, 0, 0], [1, 1, 1], n=10)
    g = passing.levels_passed_gain(walkers, base, FAMILY, LEVEL, reps=2000, terrains=False)
    st = g["stairs"]["gain"]
    assert st.point == pytest.approx(1.5)  # (5 x 2 + 5 x -1) / 10 - (-1)
    assert 0.5 < st.low < st.point < st.high < 2.6
    assert g["gaps"]["gain"] == (0.0, 0.0, 0.0)


def test_terrain_resampling_widens_a_level_passed_by_one_lucky_terrain():
    # Level 1 of stairs: terrains 0.99 and 0.85, mean 0.92 (passed); resampled, the pair is 0.85/0.85 a quarter of
    # the time (failed): the walkers' interval must reach below their point.
    w = _rows([1.0, 1.0, 0.0], [1.0, 1.0, 1.0], n=3)
    w[:, 2], w[:, 3] = 0.99, 0.85
    base = _rows([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], n=3)
    fixed = passing.levels_passed_gain(w, base, FAMILY, LEVEL, reps=500, terrains=False)["stairs"]["walkers"]
    resampled = passing.levels_passed_gain(w, base, FAMILY, LEVEL, reps=500, terrains=True)["stairs"]["walkers"]
    assert fixed == (1.0, 1.0, 1.0)
    assert resampled.point == 1.0 and resampled.low == 0.0


def test_same_seed_same_interval():
    rng = np.random.default_rng(3)
    w, b = rng.random((4, 12)), rng.random((2, 12))
    a = passing.levels_passed_gain(w, b, FAMILY, LEVEL, reps=300, seed=7, threshold=0.5)
    assert a == passing.levels_passed_gain(w, b, FAMILY, LEVEL, reps=300, seed=7, threshold=0.5)


@pytest.mark.parametrize("kw, match", [
    (dict(walkers=np.zeros((2, 11))), "walkers must have 12 terrains"),
    (dict(base=np.full((2, 12), np.nan)), "base must be finite"),
    (dict(reps=0), "reps must be an int >= 1"),
    (dict(confidence=1.0), r"confidence must be in \(0, 1\)"),
    (dict(level=LEVEL - 1), "level must hold integers >= 0"),
])
def test_bad_input_is_refused_in_one_line(kw, match):
    args = dict(walkers=np.ones((2, 12)), base=np.ones((1, 12)), family=FAMILY, level=LEVEL)
    args.update(kw)
    with pytest.raises(ValueError, match=match):
        passing.levels_passed_gain(**args)
