"""Scores of several runs, aggregated the way rliable says to (Agarwal et al., "Deep Reinforcement Learning at the
Edge of the Statistical Precipice", NeurIPS 2021): the interquartile mean (IQM) and the mean with stratified-bootstrap
confidence intervals, the probability of improvement between two methods, and rank correlations.

A method's scores are a matrix ``[runs, tasks]`` (e.g. 10 trials of a curriculum x the held-out suite's cells),
already normalised (fitness in [0, 1] needs nothing more). The bootstrap resamples runs within each task (rliable's
``StratifiedBootstrap``) with a ``RandomState(seed)`` of its own for each method: same seed, same intervals, whichever
methods are estimated together.

    from jaxterrain.runtime import statistics
    est = statistics.interval_estimates({"cppn map": a, "perlin map": b}, reps=2000)   # {name: {"iqm", "mean"}}
    est["cppn map"]["iqm"].low
    statistics.improvement({"perlin map > cppn map": (b, a)})                          # {name: Interval}

rliable is imported inside the functions that bootstrap: it imports ``arch`` (pandas, statsmodels), 2 s that
``import jaxterrain`` should not pay.
"""

from __future__ import annotations

import numbers
import warnings
from typing import Mapping, NamedTuple

import numpy as np
from scipy import stats

__all__ = ["Interval", "iqm", "probability_of_improvement", "interval_estimates", "improvement",
           "rank_correlation", "score_matrix"]


class Interval(NamedTuple):
    """A point estimate and its confidence interval ``[low, high]``."""

    point: float
    low: float
    high: float


def score_matrix(scores) -> np.ndarray:
    """``scores`` as a float64 ``[runs, tasks]`` matrix; ValueError (one line) for another shape or a non-finite
    value."""
    try:
        x = np.asarray(scores, np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"scores must be a [runs, tasks] matrix of numbers; got {type(scores).__name__}") from None
    if x.ndim != 2 or x.shape[0] < 1 or x.shape[1] < 1:
        raise ValueError(f"scores must be a [runs, tasks] matrix with at least one of each; got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("scores must be finite (a NaN or inf would poison every aggregate)")
    return x


def iqm(scores) -> float:
    """The interquartile mean of all ``[runs, tasks]`` scores pooled: the mean of the middle 50 % (rliable's
    ``aggregate_iqm``, scipy's ``trim_mean(..., 0.25)``)."""
    return float(stats.trim_mean(score_matrix(scores).ravel(), proportiontocut=0.25))


def probability_of_improvement(x, y) -> float:
    """P(X > Y): for each task, the probability that a run of X scores above a run of Y (ties count half; the
    Mann-Whitney U over ``runs_x * runs_y``), averaged over tasks. rliable's ``probability_of_improvement``, computed
    for all tasks at once (rliable calls ``scipy.stats.mannwhitneyu`` once per task). ``x`` [runs_x, tasks],
    ``y`` [runs_y, tasks]."""
    x, y = score_matrix(x), score_matrix(y)
    if x.shape[1] != y.shape[1]:
        raise ValueError(f"probability_of_improvement: x has {x.shape[1]} tasks, y {y.shape[1]}")
    a, b = x[:, None, :], y[None, :, :]
    return float(np.mean((a > b).mean(axis=(0, 1)) + 0.5 * (a == b).mean(axis=(0, 1))))


def _check_bootstrap(reps, seed, confidence) -> None:
    """The bootstrap's settings: ``reps`` an integer >= 1, ``seed`` an integer in [0, 2**32 - 1], ``confidence`` a
    number in (0, 1); ``ValueError`` naming the one that is not."""
    def is_int(v):
        return isinstance(v, numbers.Integral) and not isinstance(v, bool)

    if not is_int(reps) or reps < 1:
        raise ValueError(f"reps must be an integer >= 1; got {reps!r}")
    if not is_int(seed) or not 0 <= seed < 2 ** 32:
        raise ValueError(f"seed must be an integer in [0, 2**32 - 1]; got {seed!r}")
    if (not isinstance(confidence, numbers.Real) or isinstance(confidence, bool)
            or not 0.0 < float(confidence) < 1.0):
        raise ValueError(f"confidence must be in (0, 1); got {confidence!r}")


def _bootstrap(score_dict: dict, func, reps: int, seed: int, confidence: float):
    """rliable's ``get_interval_estimates`` once per method, each with its own ``RandomState(seed)``: a method's
    interval does not depend on which others are estimated beside it."""
    from rliable import library as rly  # 2 s of imports (arch, pandas): only where a bootstrap runs

    point, ci = {}, {}
    outer = np.random.get_state()  # rliable's StratifiedBootstrap draws from numpy's global generator (1.2.0
    try:                           # ignores its random_state there): seed it per method, and restore it after
        for name, scores in score_dict.items():
            np.random.seed(int(seed))
            with warnings.catch_warnings():  # arch deprecates the RandomState that rliable passes it
                warnings.simplefilter("ignore", FutureWarning)
                p, c = rly.get_interval_estimates({name: scores}, func, reps=int(reps),
                                                  confidence_interval_size=float(confidence),
                                                  random_state=np.random.RandomState(int(seed)))
            point[name], ci[name] = p[name], c[name]
    finally:
        np.random.set_state(outer)
    return point, ci


def interval_estimates(scores: Mapping[str, np.ndarray], reps: int = 2000, seed: int = 0,
                       confidence: float = 0.95) -> dict[str, dict[str, Interval]]:
    """``{name: {"iqm": Interval, "mean": Interval}}`` for each method's ``[runs, tasks]`` scores: the point
    estimates over all scores, the ``confidence`` interval from ``reps`` stratified-bootstrap resamples of the runs
    (percentile method, rliable's defaults otherwise)."""
    _check_bootstrap(reps, seed, confidence)
    if not isinstance(scores, Mapping):
        raise ValueError(f"scores must be a mapping {{name: [runs, tasks] scores}}; got {type(scores).__name__}")
    mats = {k: score_matrix(v) for k, v in scores.items()}
    both = lambda s: np.array([stats.trim_mean(s.ravel(), 0.25), s.mean()])  # noqa: E731
    point, ci = _bootstrap(mats, both, reps, seed, confidence)
    return {k: {"iqm": Interval(float(point[k][0]), float(ci[k][0, 0]), float(ci[k][1, 0])),
                "mean": Interval(float(point[k][1]), float(ci[k][0, 1]), float(ci[k][1, 1]))} for k in mats}


def improvement(pairs: Mapping[str, tuple], reps: int = 2000, seed: int = 0,
                confidence: float = 0.95) -> dict[str, Interval]:
    """``{name: Interval}`` of :func:`probability_of_improvement` for each ``name: (x, y)`` pair, with its
    stratified-bootstrap interval (each method's runs resampled within each task)."""
    _check_bootstrap(reps, seed, confidence)
    if not isinstance(pairs, Mapping) or not all(isinstance(v, (tuple, list)) and len(v) == 2 for v in pairs.values()):
        raise ValueError("pairs must be a mapping {name: (x, y)} of two [runs, tasks] score matrices each")
    mats = {k: [score_matrix(x), score_matrix(y)] for k, (x, y) in pairs.items()}
    for k, (x, y) in mats.items():
        if x.shape[1] != y.shape[1]:
            raise ValueError(f"pairs[{k!r}]: x has {x.shape[1]} tasks, y {y.shape[1]}")
    point, ci = _bootstrap(mats, probability_of_improvement, reps, seed, confidence)
    return {k: Interval(float(point[k]), float(np.ravel(ci[k])[0]), float(np.ravel(ci[k])[1])) for k in mats}


def rank_correlation(x, y) -> dict[str, float]:
    """Spearman's rho and Kendall's tau (tau-b: ties allowed) of two equally long 1-D samples, with their two-sided
    p-values and ``n``. NaN where one sample is constant. ``ValueError`` for a NaN or inf in either sample."""
    try:
        a, b = np.asarray(x, np.float64).ravel(), np.asarray(y, np.float64).ravel()
    except (TypeError, ValueError):
        raise ValueError("rank_correlation: x and y must be 1-D samples of numbers; got "
                         f"{type(x).__name__} and {type(y).__name__}") from None
    if a.shape != b.shape or a.size < 3:
        raise ValueError(f"rank_correlation needs two samples of equal length >= 3; got {a.size} and {b.size}")
    for name, v in (("x", a), ("y", b)):
        if not np.all(np.isfinite(v)):
            raise ValueError(f"rank_correlation: {name} must be finite (a NaN or inf has no rank); got "
                             f"{int(np.sum(~np.isfinite(v)))} non-finite of {v.size}")
    if np.ptp(a) == 0 or np.ptp(b) == 0:
        return {"spearman": float("nan"), "spearman_p": float("nan"), "kendall": float("nan"),
                "kendall_p": float("nan"), "n": int(a.size)}
    rho, rp = stats.spearmanr(a, b)
    tau, tp = stats.kendalltau(a, b)
    return {"spearman": float(rho), "spearman_p": float(rp), "kendall": float(tau), "kendall_p": float(tp),
            "n": int(a.size)}
