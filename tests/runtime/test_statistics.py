"""jaxterrain.runtime.statistics: rliable's aggregates with seeded intervals, and its probability of improvement
computed for all tasks at once."""

import numpy as np
import pytest
from rliable import metrics as rm

from jaxterrain.runtime import statistics


def test_probability_of_improvement_equals_rliables():
    rng = np.random.default_rng(0)
    for shape_x, shape_y in [((10, 30), (10, 30)), ((10, 7), (1, 7)), ((3, 5), (4, 5))]:
        x = np.round(rng.random(shape_x), 1)  # rounded: ties, which count half
        y = np.round(rng.random(shape_y), 1)
        assert statistics.probability_of_improvement(x, y) == pytest.approx(rm.probability_of_improvement(x, y))
    same = rng.random((5, 4))
    assert statistics.probability_of_improvement(same, same) == pytest.approx(0.5)
    assert statistics.probability_of_improvement(same + 1.0, same) == 1.0


def test_intervals_bracket_the_point_and_repeat_with_the_seed():
    rng = np.random.default_rng(1)
    good, bad = 0.6 + 0.1 * rng.random((10, 40)), 0.4 + 0.1 * rng.random((10, 40))
    est = statistics.interval_estimates({"good": good, "bad": bad}, reps=300, seed=3)
    for name, x in (("good", good), ("bad", bad)):
        iqm, mean = est[name]["iqm"], est[name]["mean"]
        assert iqm.point == pytest.approx(statistics.iqm(x)) and mean.point == pytest.approx(x.mean())
        assert iqm.low <= iqm.point <= iqm.high and mean.low <= mean.point <= mean.high and iqm.high > iqm.low
    assert est["bad"]["iqm"].high < est["good"]["iqm"].low  # separated groups: disjoint intervals
    assert statistics.interval_estimates({"good": good}, reps=300, seed=3)["good"] == est["good"]
    pi = statistics.improvement({"good > bad": (good, bad), "bad > good": (bad, good)}, reps=200)
    assert pi["good > bad"].point == 1.0 and pi["bad > good"].point == 0.0


def test_a_constant_run_has_a_zero_width_interval_and_bad_scores_are_refused():
    flat = np.full((1, 6), 0.25)
    est = statistics.interval_estimates({"one run": flat}, reps=50)["one run"]["iqm"]
    assert est == (0.25, 0.25, 0.25)
    with pytest.raises(ValueError, match="finite"):
        statistics.iqm(np.array([[0.1, np.nan]]))
    with pytest.raises(ValueError, match=r"\[runs, tasks\]"):
        statistics.iqm(np.zeros(4))
    with pytest.raises(ValueError, match="confidence"):
        statistics.interval_estimates({"a": flat}, confidence=95)


def test_rank_correlation_of_a_monotone_pair_is_one():
    x = np.arange(8.0)
    r = statistics.rank_correlation(x, x ** 3)
    assert r["spearman"] == pytest.approx(1.0) and r["kendall"] == pytest.approx(1.0) and r["n"] == 8
    assert statistics.rank_correlation(x, -x)["spearman"] == pytest.approx(-1.0)
    assert np.isnan(statistics.rank_correlation(x, np.ones(8))["spearman"])


def test_the_bootstrap_leaves_numpys_global_generator_as_it_found_it():
    np.random.seed(123)
    expected = np.random.random()
    np.random.seed(123)
    statistics.interval_estimates({"a": np.random.default_rng(0).random((4, 5))}, reps=20, seed=9)
    assert np.random.random() == expected


# --- the trial as the unit (issue 61) -------------------------------------------------------------------------------

def _percentile_of_trial_means(means, reps, seed, confidence=0.95):
    """The bootstrap interval of the trial means, computed directly: rows drawn as ``trial_estimates`` draws them."""
    rows = np.random.default_rng(seed).integers(0, means.size, (reps, means.size))
    return tuple(np.percentile(means[rows].mean(axis=1), [50 * (1 - confidence), 50 * (1 + confidence)]))


def test_perfectly_correlated_cells_give_the_interval_of_the_trial_means():
    """Every cell of a trial equal: resampling trials is resampling the trial means; rliable's stratified bootstrap
    resamples each cell on its own and is about sqrt(cells) times too narrow."""
    rng = np.random.default_rng(2)
    means = rng.normal(0.5, 0.05, 10)
    x = np.repeat(means[:, None], 40, axis=1)                        # [10 trials, 40 cells]
    est = statistics.trial_estimates({"x": x}, reps=3000, seed=7)["x"]
    assert est["mean"].point == pytest.approx(means.mean())
    assert est["mean"][1:] == pytest.approx(_percentile_of_trial_means(means, 3000, 7))
    # the IQM of perfectly correlated cells: 400 values, 100 cut at each end: half of the 3rd and 8th trial means
    s = np.sort(means)
    assert est["iqm"].point == pytest.approx((20 * s[2] + 40 * s[3:7].sum() + 20 * s[7]) / 200)
    assert est["trial_iqm"][1:] == pytest.approx(est["mean"][1:])     # each trial's IQM is its mean here
    strat = statistics.interval_estimates({"x": x}, reps=3000, seed=7)["x"]["mean"]
    ratio = (est["mean"].high - est["mean"].low) / (strat.high - strat.low)
    assert 4.0 < ratio < 9.0, ratio                                   # sqrt(40) = 6.3


def test_independent_cells_give_about_the_stratified_interval():
    x = np.random.default_rng(3).normal(0.5, 0.1, (10, 60))          # no trial effect: cells independent
    est = statistics.trial_estimates({"x": x}, reps=3000, seed=1)["x"]
    strat = statistics.interval_estimates({"x": x}, reps=3000, seed=1)["x"]
    for k in ("mean", "iqm"):
        ratio = (est[k].high - est[k].low) / (strat[k].high - strat[k].low)
        assert 0.8 < ratio < 1.25, (k, ratio)
    # and the width is the textbook one: 2 * 1.96 * sd / sqrt(600) for the mean
    assert est["mean"].high - est["mean"].low == pytest.approx(2 * 1.96 * x.std() / np.sqrt(x.size), rel=0.15)


def test_one_row_has_zero_width_and_trial_iqm_trims_comparably():
    b = np.random.default_rng(4).random((1, 30))
    one = statistics.trial_estimates({"base": b}, reps=200)["base"]
    assert all(iv.low == iv.high == iv.point for iv in one.values())
    assert one["trial_iqm"].point == pytest.approx(statistics.iqm(b))
    # ten trials that are the base shifted by +-0.1 (no gain on average): every trial trimmed over the same 30 cells
    # gives the base's IQM; pooling the 300 values trims the shifted copies and does not
    t = b + np.array([-0.1, 0.1] * 5)[:, None]
    assert statistics.trial_iqm(t) == pytest.approx(statistics.iqm(b))
    assert abs(statistics.iqm(t) - statistics.iqm(b)) > 1e-3


def test_the_two_level_bootstrap_adds_the_terrains_variance():
    """One trial (no trial variance), 100 cells of two terrains scoring 0 and 1: the two-level interval of the mean is
    the terrain resampling's, 2 * 1.96 * sqrt(0.125 / 100); the rows-only bootstrap has none."""
    x = np.tile([0.0, 1.0], 100)[None, :]                             # [1 trial, 200 terrains]
    cells = np.repeat(np.arange(100), 2)
    two = statistics.trial_estimates({"x": x}, reps=4000, seed=0, cells=cells)["x"]
    assert two["mean"].point == pytest.approx(0.5)
    assert two["mean"].high - two["mean"].low == pytest.approx(2 * 1.96 * np.sqrt(0.125 / 100), rel=0.15)
    one = statistics.trial_estimates({"x": x.reshape(1, 100, 2).mean(axis=2)}, reps=100)["x"]["mean"]
    assert one.high == one.low == 0.5
    # the same point estimates as the cell matrix, whatever the cells' labels and order
    y = np.random.default_rng(5).random((6, 12))
    labels = np.array(list("cbacbacbacba"))
    cm = np.stack([y[:, labels == c].mean(axis=1) for c in "abc"], axis=1)
    two = statistics.trial_estimates({"y": y}, reps=50, cells=labels)["y"]
    assert two["iqm"].point == pytest.approx(statistics.iqm(cm)) and two["mean"].point == pytest.approx(cm.mean())
    with pytest.raises(ValueError, match="cells must have shape"):
        statistics.trial_estimates({"y": y}, cells=labels[:5])


def test_trial_estimates_repeat_with_the_seed_whatever_else_is_estimated():
    rng = np.random.default_rng(6)
    a, b = rng.random((10, 20)), rng.random((8, 20))
    both = statistics.trial_estimates({"a": a, "b": b}, reps=500, seed=3)
    assert statistics.trial_estimates({"a": a}, reps=500, seed=3)["a"] == both["a"]
    assert statistics.trial_estimates({"a": a}, reps=500, seed=4)["a"] != both["a"]


def test_probability_of_improvement_over_trials_on_known_cases():
    cells = 5
    x = np.repeat(np.array([[1.0], [2.0], [3.0]]), cells, axis=1)    # trial scores 1, 2, 3 on every cell
    y = np.repeat(np.array([[1.5], [2.5], [3.5]]), cells, axis=1)    # 1.5, 2.5, 3.5: x beats y in 3 of 9 pairs
    iv = statistics.trial_improvement(x, y, reps=20000, seed=0, confidence=0.9)
    assert iv.point == pytest.approx(1 / 3)
    # the exact bootstrap distribution: all 27 x 27 resamples of the two sets of trials, equally likely
    import itertools
    draws = list(itertools.product(range(3), repeat=3))
    exact = np.sort([np.mean(x[list(i), :1] > y[list(j), :1].T) for i in draws for j in draws])
    cdf = np.arange(1, exact.size + 1) / exact.size
    assert iv.low == pytest.approx(exact[np.searchsorted(cdf, 0.05)])    # 0: P(0) = 0.14
    assert iv.high == pytest.approx(exact[np.searchsorted(cdf, 0.95)])   # 7/9 (P(<= 6/9) = 0.942, P(<= 7/9) = 0.967)
    assert iv.high == pytest.approx(7 / 9)
    # against one fixed comparator row: X's trials 1 and 3 around it; resampling gives 0, 1/2 or 1
    iv = statistics.trial_improvement(x[[0, 2]], np.full((1, cells), 2.0), reps=4000, seed=0)
    assert iv == pytest.approx((0.5, 0.0, 1.0))
    # ties count half; the point is rliable's
    rng = np.random.default_rng(7)
    a, b = np.round(rng.random((6, 9)), 1), np.round(rng.random((4, 9)), 1)
    assert statistics.trial_improvement(a, b, reps=50).point == pytest.approx(rm.probability_of_improvement(a, b))
    assert statistics.trial_improvement(a + 2, b, reps=50) == (1.0, 1.0, 1.0)
    # two-level: the point on the cell means, the same for any labels
    t = np.repeat(np.arange(9), 2)
    two = statistics.trial_improvement(np.repeat(a, 2, axis=1), np.repeat(b, 2, axis=1), reps=50, cells=t)
    assert two.point == pytest.approx(rm.probability_of_improvement(a, b)) and two.low <= two.point <= two.high
    with pytest.raises(ValueError, match="tasks"):
        statistics.trial_improvement(a, b[:, :4])


def test_welch_and_holm_on_hand_values():
    p = statistics.holm([0.01, 0.04, 0.03, 0.005])
    # sorted 0.005, 0.01, 0.03, 0.04 times 4, 3, 2, 1 = 0.02, 0.03, 0.06, 0.04 -> made non-decreasing: 0.06
    assert p == pytest.approx([0.03, 0.06, 0.06, 0.02])
    assert statistics.holm([0.5, 0.6]) == pytest.approx([1.0, 1.0])
    q = statistics.holm([0.02, np.nan, 0.04])                          # a NaN is no comparison: m = 2
    assert q[0] == pytest.approx(0.04) and np.isnan(q[1]) and q[2] == pytest.approx(0.04)
    x = np.repeat(np.array([1.0, 2.0, 3.0])[:, None], 4, axis=1)
    y = np.repeat(np.array([2.0, 3.0, 4.0, 5.0])[:, None], 4, axis=1)
    w = statistics.welch_trials(x, y)
    from scipy import stats
    assert w["p"] == pytest.approx(stats.ttest_ind([1, 2, 3], [2, 3, 4, 5], equal_var=False).pvalue)
    assert w["t"] < 0 and w["n_x"] == 3 and w["n_y"] == 4
    assert np.isnan(statistics.welch_trials(x, y[:1])["p"])           # one evaluation: nothing to test against
    # each trial's IQM (default) or mean: a trial with one outlying cell moves its mean, not its IQM
    z = np.array([[0.1, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.9]] * 2) + np.array([[0.0], [0.02]])
    v = z + np.array([[0.0, 0, 0, 0, 0, 0, 0, 0.8], [0.0, 0, 0, 0, 0, 0, 0, 0.8]]) + np.array([[0.01], [0.03]])
    assert statistics.welch_trials(v, z)["p"] == pytest.approx(
        stats.ttest_ind([0.51, 0.55], [0.5, 0.52], equal_var=False).pvalue)
    assert statistics.welch_trials(v, z, "mean")["p"] == pytest.approx(
        stats.ttest_ind(v.mean(axis=1), z.mean(axis=1), equal_var=False).pvalue)


def test_stratified_permutation_with_and_without_association():
    groups = np.repeat(["a", "b", "c"], 4)
    x = np.tile([1.0, 2.0, 3.0, 4.0], 3)
    # within every group the held-out ranks 2, 4, 1, 3: Spearman exactly 0; the groups' levels rise with x's
    y = np.tile([2.0, 4.0, 1.0, 3.0], 3) + np.repeat([0.0, 10.0, 20.0], 4)
    x_lv = x + np.repeat([0.0, 10.0, 20.0], 4)
    none = statistics.stratified_permutation(x_lv, y, groups, reps=2000, seed=0)
    assert none["statistic"] == pytest.approx(0.0) and none["p"] == 1.0 and none["groups"] == 3
    assert statistics.rank_correlation(x_lv, y)["spearman"] > 0.8     # pooled: the groups' levels, not an association
    # y rising with x in every group (6 each): Spearman 1 in each; a permutation reaches |mean| 1 with chance 3e-8
    g6, x6 = np.repeat(["a", "b", "c"], 6), np.tile(np.arange(6.0), 3)
    yes = statistics.stratified_permutation(x6, x6 ** 2 - np.repeat([0.0, 5.0, 9.0], 6), g6, reps=2000, seed=0)
    assert yes["statistic"] == pytest.approx(1.0) and yes["p"] == pytest.approx(1 / 2001)
    # the statistic is the mean of scipy's within-group Spearman, ties included
    rng = np.random.default_rng(8)
    xs, ys = np.round(rng.random(18), 1), rng.random(18)
    from scipy import stats
    r = statistics.stratified_permutation(xs, ys, g6, reps=500, seed=1)
    assert r["statistic"] == pytest.approx(np.mean([stats.spearmanr(xs[g6 == k], ys[g6 == k])[0] for k in "abc"]))
    assert 0.0 < r["p"] <= 1.0
    skipped = statistics.stratified_permutation(np.concatenate([xs, [1, 1, 1]]), np.concatenate([ys, [1, 2, 3]]),
                                                np.concatenate([g6, ["d", "d", "d"]]), reps=50)
    assert skipped["skipped"] == ["d"] and skipped["groups"] == 3     # constant x in group d: no rank correlation
