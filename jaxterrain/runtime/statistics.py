"""Scores of several runs, aggregated the way rliable says to (Agarwal et al., "Deep Reinforcement Learning at the
Edge of the Statistical Precipice", NeurIPS 2021): the interquartile mean (IQM) and the mean with confidence
intervals, the probability of improvement between two methods, and rank correlations.

A method's scores are a matrix ``[runs, tasks]`` (e.g. 10 trials of a curriculum x the held-out suite's cells),
already normalised (fitness in [0, 1] needs nothing more). Two bootstraps, which assume different things
(``docs/statistics.md`` works through both on Experiment 3):

- **Over whole trials** (:func:`trial_estimates`, :func:`trial_improvement`; the primary interval): the rows of
  the ``[trials, cells]`` matrix are resampled with replacement, each row with all its cells. A trial is one walker
  evaluated on every cell, so its cells are correlated; resampling rows keeps that correlation, and the interval
  reflects how much the result would move with another set of trials. Optionally two-level: the terrains of each
  cell resampled too (the same draw for every trial of a replicate: every walker walks the same terrains). Pure
  numpy, ``np.random.default_rng(seed)``, vectorised over the replicates.
- **Stratified** (:func:`interval_estimates`, :func:`improvement`; rliable's ``StratifiedBootstrap``): the runs
  are resampled separately within each task, as if a run's tasks were independent. Kept for comparison with papers
  that report it; with strongly correlated cells its intervals are several times too narrow.

Pairwise tests on trial scores (:func:`welch_trials`: each trial's IQM or mean over the cells) are adjusted for multiplicity with :func:`holm`; the
association of a per-trial metric with held-out scores across treatments is tested by :func:`stratified_permutation`.

    from jaxterrain.runtime import statistics
    est = statistics.trial_estimates({"cppn map": a, "perlin map": b}, reps=2000)    # {name: {"iqm", "mean", ...}}
    est["cppn map"]["iqm"].low
    statistics.trial_improvement(b, a)                                                 # Interval of P(b > a)
    statistics.interval_estimates({"cppn map": a}, reps=2000)                          # rliable's, stratified

rliable is imported inside the functions that use it: it imports ``arch`` (pandas, statsmodels), 2 s that
``import jaxterrain`` should not pay.
"""

from __future__ import annotations

import numbers
import warnings
from typing import Mapping, NamedTuple

import numpy as np
from scipy import stats

__all__ = ["Interval", "iqm", "probability_of_improvement", "interval_estimates", "improvement",
           "rank_correlation", "score_matrix", "trial_iqm", "trial_estimates", "trial_improvement", "welch_trials",
           "holm", "stratified_permutation", "cvar"]


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


# --- the trial as the unit: a bootstrap over whole rows of [trials, cells] (issue 61) -------------------------------

_CHUNK = 4_000_000  # values gathered at once by a bootstrap (a replicate's [trials, terrains] or [nx, ny, cells])


def trial_iqm(scores) -> float:
    """The mean over runs of each run's IQM over its tasks (``[runs, tasks]`` -> each row trimmed by a quarter at
    each end, then averaged). Unlike :func:`iqm` (all ``runs x tasks`` scores pooled, then trimmed), every run is
    trimmed over the same ``tasks`` values whatever the number of runs, so a comparator with ONE evaluation (a base
    policy: 127 values) and a treatment of 10 trials (1 270 pooled values, spread by the trials too) are trimmed
    comparably. Equals :func:`iqm` for one run."""
    return float(np.mean(stats.trim_mean(score_matrix(scores), 0.25, axis=1)))


def _percentile(boot: np.ndarray, confidence: float) -> tuple[float, float]:
    """The percentile interval of ``boot`` [reps] (rliable's method)."""
    lo, hi = np.percentile(boot, [50.0 * (1.0 - confidence), 50.0 * (1.0 + confidence)])
    return float(lo), float(hi)


class _Layout(NamedTuple):
    """Terrains grouped into cells for the two-level bootstrap: ``order`` [N] the terrains sorted by cell,
    ``starts`` [C] each cell's first position in that order, ``start_of`` / ``size_of`` [N] the start and size of
    the cell of each sorted position."""

    order: np.ndarray
    starts: np.ndarray
    start_of: np.ndarray
    size_of: np.ndarray


def _layout(cells, n_terrains: int) -> _Layout:
    """``cells`` [N]: each terrain's cell (any labels; a cell = the terrains with one label). ``ValueError`` when its
    length is not the scores' ``N``."""
    c = np.asarray(cells)
    if c.shape != (n_terrains,):
        raise ValueError(f"cells must have shape [terrains] = ({n_terrains},) like the scores' last axis; got shape "
                         f"{c.shape}")
    _, codes = np.unique(c, return_inverse=True)
    order = np.argsort(codes, kind="stable")
    sorted_codes = codes[order]
    starts = np.flatnonzero(np.r_[True, sorted_codes[1:] != sorted_codes[:-1]])
    sizes = np.diff(np.r_[starts, n_terrains])
    return _Layout(order, starts, np.repeat(starts, sizes), np.repeat(sizes, sizes))


def _cell_means(values: np.ndarray, lay: _Layout) -> np.ndarray:
    """``values`` [..., N] (terrains) -> [..., C] the mean of each cell's terrains, cells in ``lay``'s order."""
    v = values[..., lay.order]
    return np.add.reduceat(v, lay.starts, axis=-1) / np.diff(np.r_[lay.starts, v.shape[-1]])


def _terrain_draws(lay: _Layout, reps: int, rng: np.random.Generator) -> np.ndarray:
    """[reps, N] terrain indices (into the unsorted terrains), each cell's terrains drawn with replacement from its
    own terrains, laid out in ``lay``'s sorted order (so :func:`_cell_means` of the gathered values needs no
    second sort: pass ``_Layout`` with the identity order)."""
    pos = lay.start_of + np.floor(rng.random((reps, lay.order.size)) * lay.size_of).astype(np.int64)
    return lay.order[pos]


def _check_terrain_scores(x: np.ndarray, cells) -> tuple[np.ndarray, _Layout | None]:
    """The ``[trials, cells]`` matrix of ``x`` and the two-level layout (None without ``cells``)."""
    if cells is None:
        return x, None
    lay = _layout(cells, x.shape[1])
    return _cell_means(x, lay), lay


def _resampled(x: np.ndarray, lay: _Layout, draws: np.ndarray) -> np.ndarray:
    """[reps, trials, C]: the cell means of ``x`` [trials, N] over the terrains ``draws`` [reps, N]."""
    gathered = np.moveaxis(x[:, draws], 0, 1)  # [reps, trials, N], sorted by cell
    ident = lay._replace(order=np.arange(lay.order.size))
    return _cell_means(gathered, ident)


def trial_estimates(scores: Mapping[str, np.ndarray], reps: int = 2000, seed: int = 0, confidence: float = 0.95,
                    cells=None) -> dict[str, dict[str, Interval]]:
    """``{name: {"iqm", "mean", "trial_iqm": Interval}}`` for each method's scores, with intervals from a bootstrap
    over whole trials: ``reps`` resamples of the rows (trials) with replacement, every row with all its cells;
    percentile intervals at ``confidence``. Each method has its own ``np.random.default_rng(seed)``: its interval
    does not depend on which others are estimated beside it.

    ``scores``: ``{name: [trials, cells]}``; or, with ``cells`` ([terrains], each terrain's cell, any labels), ``{name:
    [trials, terrains]}`` and a two-level bootstrap: each replicate also resamples the terrains within each cell
    (one draw shared by all the replicate's trials: every walker walks the same terrains), the cells being the means
    of their terrains. A cell of one terrain contributes no terrain variance.

    ``iqm``: :func:`iqm` of all ``trials x cells`` scores pooled (rliable's aggregate; the pages' point estimate).
    ``mean``: the mean. ``trial_iqm``: :func:`trial_iqm`, each trial's IQM over its cells, averaged: trimmed over
    the same number of values for any number of trials; compare a comparator with one evaluation on this one.

    A method with ONE row (one evaluation of one policy) gets an interval of zero width: it holds no trial
    variance, and says nothing about how another evaluation or another policy would score. The same holds for rows
    that are repeated evaluations of one policy (only the evaluation's noise)."""
    _check_bootstrap(reps, seed, confidence)
    if not isinstance(scores, Mapping):
        raise ValueError(f"scores must be a mapping {{name: [trials, cells] scores}}; got {type(scores).__name__}")
    out = {}
    for name, raw in scores.items():
        x = score_matrix(raw)
        cm, lay = _check_terrain_scores(x, cells)
        n = cm.shape[0]
        rng = np.random.default_rng(int(seed))
        boot = np.empty((3, reps))
        step = max(1, _CHUNK // (n * x.shape[1]))
        per_trial = stats.trim_mean(cm, 0.25, axis=1)  # [trials]
        for a in range(0, reps, step):
            r = min(step, reps - a)
            if lay is not None:
                draws = _terrain_draws(lay, r, rng)
            rows = rng.integers(0, n, (r, n))
            if lay is None:
                sample = cm[rows]                                      # [r, trials, cells]
                boot[2, a:a + r] = per_trial[rows].mean(axis=1)
            else:
                sample = _resampled(x, lay, draws)[np.arange(r)[:, None], rows]
                boot[2, a:a + r] = stats.trim_mean(sample, 0.25, axis=2).mean(axis=1)
            flat = sample.reshape(r, -1)
            boot[0, a:a + r] = stats.trim_mean(flat, 0.25, axis=1)
            boot[1, a:a + r] = flat.mean(axis=1)
        points = (iqm(cm), float(cm.mean()), trial_iqm(cm))
        out[name] = {k: Interval(p, *_percentile(boot[i], confidence))
                     for i, (k, p) in enumerate(zip(("iqm", "mean", "trial_iqm"), points))}
    return out


def trial_improvement(x, y, reps: int = 2000, seed: int = 0, confidence: float = 0.95, cells=None) -> Interval:
    """:func:`probability_of_improvement` P(X > Y) (a run of X above a run of Y on a cell, ties half, averaged over
    cells) with a bootstrap over whole trials: each replicate resamples the rows of ``x`` and of ``y``
    independently (two independent sets of trials), every row with all its cells. ``x`` [trials_x, cells], ``y``
    [trials_y, cells]; with ``cells`` ([terrains]), ``x`` / ``y`` are per terrain and the terrains of each cell are
    resampled too, one draw for both methods (they walk the same terrains). A ``y`` of one row (a base policy
    evaluated once) is a fixed comparator: the interval holds X's trial variance only."""
    _check_bootstrap(reps, seed, confidence)
    xs, ys = score_matrix(x), score_matrix(y)
    if xs.shape[1] != ys.shape[1]:
        raise ValueError(f"trial_improvement: x has {xs.shape[1]} tasks, y {ys.shape[1]}")
    xc, lay = _check_terrain_scores(xs, cells)
    yc, _ = _check_terrain_scores(ys, cells)
    nx, ny = xc.shape[0], yc.shape[0]
    rng = np.random.default_rng(int(seed))
    boot = np.empty(reps)
    if lay is None:
        a, b = xc[:, None, :], yc[None, :, :]
        w = (a > b).mean(axis=2) + 0.5 * (a == b).mean(axis=2)     # [nx, ny]: P(trial i of X beats trial j of Y)
        ix, iy = rng.integers(0, nx, (reps, nx)), rng.integers(0, ny, (reps, ny))
        boot[:] = w[ix[:, :, None], iy[:, None, :]].mean(axis=(1, 2))
    else:
        step = max(1, _CHUNK // (nx * ny * xc.shape[1] + (nx + ny) * xs.shape[1]))
        for s in range(0, reps, step):
            r = min(step, reps - s)
            draws = _terrain_draws(lay, r, rng)
            ix, iy = rng.integers(0, nx, (r, nx)), rng.integers(0, ny, (r, ny))
            xa = _resampled(xs, lay, draws)[np.arange(r)[:, None], ix][:, :, None, :]
            yb = _resampled(ys, lay, draws)[np.arange(r)[:, None], iy][:, None, :, :]
            boot[s:s + r] = ((xa > yb).mean(axis=(1, 2, 3)) + 0.5 * (xa == yb).mean(axis=(1, 2, 3)))
    return Interval(probability_of_improvement(xc, yc), *_percentile(boot, confidence))


def welch_trials(x, y, statistic: str = "iqm") -> dict[str, float]:
    """Welch's t-test of two methods' trial scores: each trial's :func:`iqm` over its cells (``statistic="iqm"``,
    the pages' aggregate) or its mean (``"mean"``). ``x`` [trials_x, cells], ``y`` [trials_y, cells]. Returns
    ``{"t", "p", "n_x", "n_y"}``, two-sided; NaN ``t`` / ``p`` when either has fewer than two trials or both are
    constant (a comparator with one evaluation has no trial variance to test against)."""
    if statistic not in ("iqm", "mean"):
        raise ValueError(f"statistic must be 'iqm' or 'mean'; got {statistic!r}")
    score = (lambda m: stats.trim_mean(m, 0.25, axis=1)) if statistic == "iqm" else (lambda m: m.mean(axis=1))
    a, b = score(score_matrix(x)), score(score_matrix(y))
    if a.size < 2 or b.size < 2 or (np.ptp(a) == 0 and np.ptp(b) == 0):
        return {"t": float("nan"), "p": float("nan"), "n_x": int(a.size), "n_y": int(b.size)}
    t, p = stats.ttest_ind(a, b, equal_var=False)
    return {"t": float(t), "p": float(p), "n_x": int(a.size), "n_y": int(b.size)}


def holm(pvalues) -> np.ndarray:
    """Holm's step-down adjustment of ``pvalues`` [m] for ``m`` comparisons (family-wise error): the k-th smallest
    p (k = 0, 1, ...) times ``m - k``, made non-decreasing in that order, capped at 1. NaNs are left out of ``m``
    and stay NaN. Reject at level alpha where the adjusted p <= alpha."""
    p = np.asarray(pvalues, np.float64).ravel()
    out = np.full(p.shape, np.nan)
    ok = np.flatnonzero(~np.isnan(p))
    if ok.size:
        order = ok[np.argsort(p[ok], kind="stable")]
        adj = np.minimum(1.0, np.maximum.accumulate(p[order] * (ok.size - np.arange(ok.size))))
        out[order] = adj
    return out


def stratified_permutation(x, y, groups, reps: int = 10000, seed: int = 0) -> dict:
    """Is a per-trial metric ``x`` associated with held-out scores ``y`` within treatments? The statistic is the
    mean over ``groups`` (treatments) of the within-group Spearman rho; its null distribution comes from ``reps``
    permutations of ``y`` within each group (``np.random.default_rng(seed)``), which keep each treatment's level of
    both (a pooled correlation mixes the treatments' differences in with the association). ``x``, ``y``,
    ``groups``: [n]. Groups with fewer than 3 members or a constant ``x`` or ``y`` are left out (listed under
    ``"skipped"``).

    Returns ``{"statistic", "p", "groups", "n", "reps", "per_group": {group: rho}, "skipped": [...]}``: ``p``
    two-sided, ``(1 + #{|T*| >= |T|}) / (1 + reps)``; NaN statistic and p when no group is left."""
    _check_bootstrap(reps, seed, 0.5)
    a, b, g = np.asarray(x, np.float64).ravel(), np.asarray(y, np.float64).ravel(), np.asarray(groups).ravel()
    if not (a.shape == b.shape == g.shape):
        raise ValueError(f"stratified_permutation: x, y and groups must have one length; got {a.size}, {b.size}, "
                         f"{g.size}")
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        raise ValueError("stratified_permutation: x and y must be finite")
    rng = np.random.default_rng(int(seed))
    per, skipped, null = {}, [], np.zeros(reps)
    for key in dict.fromkeys(g.tolist()):
        m = g == key
        if m.sum() < 3 or np.ptp(a[m]) == 0 or np.ptp(b[m]) == 0:
            skipped.append(key)
            continue
        rx, ry = stats.rankdata(a[m]), stats.rankdata(b[m])
        rx, ry = rx - rx.mean(), ry - ry.mean()
        rx, ry = rx / np.linalg.norm(rx), ry / np.linalg.norm(ry)   # rho = rx . ry (Pearson of the ranks)
        per[key] = float(rx @ ry)
        null += rng.permuted(np.broadcast_to(ry, (reps, ry.size)), axis=1) @ rx
    if not per:
        return {"statistic": float("nan"), "p": float("nan"), "groups": 0, "n": int(a.size), "reps": int(reps),
                "per_group": {}, "skipped": skipped}
    t = float(np.mean(list(per.values())))
    null /= len(per)
    p = (1 + int(np.sum(np.abs(null) >= abs(t) - 1e-12))) / (1 + reps)
    return {"statistic": t, "p": float(p), "groups": len(per), "n": int(sum(np.sum(g == k) for k in per)),
            "reps": int(reps), "per_group": per, "skipped": skipped}


def cvar(values, alpha: float = 0.1) -> float:
    """The conditional value at risk of ``values`` [n] at level ``alpha`` in (0, 1]: the mean of the worst (lowest)
    ``alpha`` fraction, ``alpha * n`` values with the boundary value counted by its fraction (Acerbi and Tasche's
    discrete CVaR: ``n = 20, alpha = 0.1`` is the mean of the two lowest; ``n = 15`` the lowest plus half of the
    second, over 1.5). The worst-decile robustness figure of the held-out suite's generator samples (``alpha =
    0.1``; SFL / Kinetix practice). ValueError for no value, a non-finite one or ``alpha`` outside (0, 1]."""
    x = np.sort(np.asarray(values, np.float64).ravel())
    if x.size == 0 or not np.all(np.isfinite(x)):
        raise ValueError(f"values must be one or more finite numbers; got {x.size} values")
    if isinstance(alpha, bool) or not isinstance(alpha, numbers.Real) or not 0.0 < float(alpha) <= 1.0:
        raise ValueError(f"alpha must be a number in (0, 1]; got {alpha!r}")
    k = float(alpha) * x.size
    whole = int(np.floor(k + 1e-9))
    part = k - whole if k - whole > 1e-9 else 0.0
    total = x[:whole].sum() + (part * x[whole] if part else 0.0)
    return float(total / k)
