"""Levels passed, with the trial as the unit: how many more levels of each family a treatment's walkers pass than
a comparator (the base policy), with a bootstrap interval over whole trials.

A walker passes a level when the mean fitness of the level's terrains is >= :data:`~jaxterrain.suite.THRESHOLD`,
and its score on a family is the highest level it passes with every level below it passed
(:func:`~jaxterrain.suite.highest_level_passed`: -1 when level 0 fails). Experiment 4's target is stated in these
units ("three more levels than the base policy on ``stairs_up``, ``gaps`` and ``boxes``").

    gain = passing.levels_passed_gain(walkers, base, suite.family, suite.level)   # {family: {"walkers", "base", "gain"}}
    gain["stairs_up"]["gain"]            # Interval(point, low, high) of mean(walkers) - mean(base), in levels

The bootstrap resamples whole trials (the rows of ``walkers``: one walker on every terrain) and the comparator's
rows (its independent evaluation keys) with replacement, and optionally the terrains of each (family, level) cell
(one draw per replicate, shared by every row: all walk the same terrains). A level passed by a fluke of its few
terrains then moves the interval, as it should. Pure numpy, ``np.random.default_rng(seed)``.
"""

from __future__ import annotations

import numbers

import numpy as np

from jaxterrain.runtime.statistics import Interval
from jaxterrain.suite.evaluation import THRESHOLD

__all__ = ["highest_passed", "levels_passed", "levels_passed_gain"]

_CHUNK = 2_000_000  # gathered values per bootstrap chunk (bounds memory: ~16 MB of float64)


def highest_passed(per_level, threshold: float = THRESHOLD) -> np.ndarray:
    """Vectorised :func:`~jaxterrain.suite.highest_level_passed`: ``per_level`` [..., levels] mean fitness (easiest
    first; NaN = a level the suite lacks, stepped over) -> [...] int, the highest level ``k`` with every present
    level ``0..k`` passed, -1 when the first present level fails (or none is present)."""
    m = np.asarray(per_level, np.float64)
    nan = np.isnan(m)
    ok = np.cumprod(nan | (m >= threshold), axis=-1).astype(bool) & ~nan
    idx = np.arange(m.shape[-1])
    return np.where(ok, idx, -1).max(axis=-1)


def _check(fitness, name: str, n: int | None) -> np.ndarray:
    try:
        f = np.atleast_2d(np.asarray(fitness, np.float64))
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a [rows, terrains] array of numbers; got {type(fitness).__name__}") from None
    if f.ndim != 2 or f.shape[0] < 1 or f.shape[1] < 1:
        raise ValueError(f"{name} must have shape [rows, terrains] with rows, terrains >= 1; got shape {f.shape}")
    if n is not None and f.shape[1] != n:
        raise ValueError(f"{name} must have {n} terrains (the family / level length); got shape {f.shape}")
    if not np.all(np.isfinite(f)):
        raise ValueError(f"{name} must be finite (a NaN or inf would poison its level's mean)")
    return f


def _cells(family, level) -> tuple[list[str], np.ndarray, list[np.ndarray]]:
    """``(families, cell_of [F, Lmax] int cell index or -1, members [C] terrain-index arrays)``."""
    fam, lv = np.asarray(family), np.asarray(level)
    if fam.ndim != 1 or lv.shape != fam.shape:
        raise ValueError(f"family and level must both have shape [terrains]; got {fam.shape} and {lv.shape}")
    if fam.size == 0:
        raise ValueError("family must name at least one terrain")
    if not np.issubdtype(lv.dtype, np.integer) or np.any(lv < 0):
        raise ValueError("level must hold integers >= 0 (each terrain's level in its family)")
    families = list(dict.fromkeys(fam.tolist()))
    lmax = int(lv.max()) + 1
    cell_of = np.full((len(families), lmax), -1, np.int64)
    members = []
    for i, f in enumerate(families):
        for k in range(lmax):
            idx = np.flatnonzero((fam == f) & (lv == k))
            if idx.size:
                cell_of[i, k] = len(members)
                members.append(idx)
    return families, cell_of, members


def _per_level(x: np.ndarray, cell_of: np.ndarray, cell_means: np.ndarray) -> np.ndarray:
    """[..., F, Lmax] level means (NaN where a family lacks the level) from ``cell_means`` [..., C]."""
    padded = np.concatenate([cell_means, np.full(cell_means.shape[:-1] + (1,), np.nan)], axis=-1)
    return padded[..., cell_of]  # cell -1 -> the NaN column


def levels_passed(fitness, family, level, threshold: float = THRESHOLD) -> tuple[list[str], np.ndarray]:
    """``(families, passed [P, F] int)``: each row's highest level passed in each family (-1: level 0 failed).
    ``fitness``: [P, N] (or [N]), ``family`` / ``level``: [N] (``Suite.family`` / ``Suite.level``)."""
    families, cell_of, members = _cells(family, level)
    f = _check(fitness, "fitness", len(np.asarray(family)))
    means = np.stack([f[:, m].mean(axis=1) for m in members], axis=-1)  # [P, C]
    return families, highest_passed(_per_level(f, cell_of, means), threshold)


def levels_passed_gain(walkers, base, family, level, reps: int = 2000, seed: int = 0, confidence: float = 0.95,
                       terrains: bool = True, threshold: float = THRESHOLD) -> dict[str, dict[str, Interval]]:
    """``{family: {"walkers", "base", "gain": Interval}}``: the mean over ``walkers``' rows (trials) of the highest
    level passed, the same over ``base``'s rows (the comparator's evaluation keys), and their difference, each with a
    percentile interval at ``confidence`` from ``reps`` bootstrap replicates that resample the rows of each with
    replacement and, with ``terrains``, the terrains of every (family, level) cell (shared by all rows).

    ``walkers``: [T, N] fitness of T trials; ``base``: [K, N] (K >= 1; one row gives the comparator no spread of its
    own); ``family`` / ``level``: [N]. Identical rows and ``terrains=False`` give intervals of zero width."""
    for name, v in (("reps", reps), ("seed", seed)):
        if isinstance(v, bool) or not isinstance(v, numbers.Integral) or v < (1 if name == "reps" else 0):
            raise ValueError(f"{name} must be an int >= {1 if name == 'reps' else 0}; got {v!r}")
    if not 0.0 < float(confidence) < 1.0:
        raise ValueError(f"confidence must be in (0, 1); got {confidence}")
    families, cell_of, members = _cells(family, level)
    n = len(np.asarray(family))
    w, b = _check(walkers, "walkers", n), _check(base, "base", n)
    rows = np.concatenate([w, b])  # [T + K, N]
    t = w.shape[0]

    def passed(cell_means):  # [..., T + K, C] -> [..., T + K, F]
        return highest_passed(_per_level(rows, cell_of, cell_means), threshold)

    point = passed(np.stack([rows[:, m].mean(axis=1) for m in members], axis=-1))
    rng = np.random.default_rng(int(seed))
    boot = np.empty((3, int(reps), len(families)))
    step = max(1, _CHUNK // rows.size)
    for a in range(0, int(reps), step):
        r = min(step, int(reps) - a)
        if terrains:
            cm = np.stack([rows[:, m[rng.integers(0, m.size, (r, m.size))]].mean(axis=-1).T
                           for m in members], axis=-1)  # [r, T + K, C]
            p = passed(cm)
        else:
            p = np.broadcast_to(point, (r,) + point.shape)
        wi = rng.integers(0, t, (r, t))
        bi = t + rng.integers(0, b.shape[0], (r, b.shape[0]))
        ar = np.arange(r)[:, None]
        boot[0, a:a + r] = p[ar, wi].mean(axis=1)
        boot[1, a:a + r] = p[ar, bi].mean(axis=1)
    boot[2] = boot[0] - boot[1]
    lo_q, hi_q = 50.0 * (1.0 - confidence), 50.0 * (1.0 + confidence)
    pw, pb = point[:t].mean(axis=0), point[t:].mean(axis=0)
    out = {}
    for i, fam in enumerate(families):
        est = (pw[i], pb[i], pw[i] - pb[i])
        out[fam] = {k: Interval(float(est[j]), *(float(q) for q in np.percentile(boot[j, :, i], [lo_q, hi_q])))
                    for j, k in enumerate(("walkers", "base", "gain"))}
    return out
