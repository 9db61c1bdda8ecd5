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
