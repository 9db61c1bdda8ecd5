"""Calibrating a suite's levels for a robot: a family's level curve (its base policy's mean fitness at each level,
easiest first) passes when level 0 is at least :data:`LEVEL0` (0.8), the last level at most :data:`LAST` (0.3),
and no level is above the one before by more than :data:`RISE` (0.03) (issue 61).

    check_curve([0.95, 0.9, ..., 0.2])                 # {"level0": 0.95, "last": 0.2, "max_rise": ..., "ok": True}
    select_levels(values, means)                       # 10 of a measured candidate grid's values that pass, or None
    propose_values(values, means)                      # 10 values by interpolating the grid's monotone fit

:func:`select_levels` picks levels among values whose terrains were measured (v2's terrain of a value and a seed
does not depend on the level it is given: ``heldout.v2_terrain``), so the curve it checks is a measured one;
:func:`propose_values` places levels between measured values where the grid is too coarse (they need measuring).
"""

from __future__ import annotations

import numpy as np

__all__ = ["LEVEL0", "LAST", "RISE", "check_curve", "select_levels", "propose_values", "decreasing_fit"]

LEVEL0 = 0.8
"""A family's level 0 must have at least this mean fitness for its robot's base policy."""
LAST = 0.3
"""A family's hardest level must have at most this mean fitness."""
RISE = 0.03
"""No level's mean fitness may exceed the level before it by more than this."""


def _curve(means) -> np.ndarray:
    m = np.asarray(means, np.float64)
    if m.ndim != 1 or m.size < 2 or not np.all(np.isfinite(m)):
        raise ValueError(f"means must be a 1-D array of >= 2 finite numbers (a level curve); got shape {m.shape}")
    return m


def check_curve(means, level0: float = LEVEL0, last: float = LAST, rise: float = RISE) -> dict:
    """The checks of a level curve ``means`` [levels] (mean fitness, easiest first): ``level0`` / ``last`` its
    first and last values, ``max_rise`` the largest ``means[k + 1] - means[k]`` (negative when it falls everywhere),
    ``rise_at`` the level ``k + 1`` where it is, and booleans ``ok_level0`` (>= ``level0``), ``ok_last`` (<=
    ``last``), ``ok_rises`` (every rise <= ``rise``), ``ok`` (all three). ValueError for fewer than 2 levels or a
    non-finite mean."""
    m = _curve(means)
    d = np.diff(m)
    k = int(np.argmax(d))
    out = {"level0": float(m[0]), "last": float(m[-1]), "max_rise": float(d[k]), "rise_at": k + 1,
           "ok_level0": bool(m[0] >= level0), "ok_last": bool(m[-1] <= last), "ok_rises": bool(d[k] <= rise + 1e-12)}
    out["ok"] = out["ok_level0"] and out["ok_last"] and out["ok_rises"]
    return out


def select_levels(values, means, levels: int = 10, level0: float = LEVEL0, last: float = LAST,
                  rise: float = RISE, margin: float = 0.05) -> np.ndarray | None:
    """Indices [levels] into a measured candidate grid (``values`` [G] increasing, ``means`` [G] the base policy's
    mean fitness at each) whose curve passes :func:`check_curve`, spread as evenly as the grid allows: of all
    passing choices, the one with the smallest sum of squared steps between neighbouring levels (equal steps
    minimise it, so levels bunched at 1.0 or at the floor are avoided; ties: the lowest indices). Ends with
    ``margin`` to spare (level 0 >= ``level0 + margin``, the last level <= ``last - margin``) are preferred where
    the grid has them, so that a new measurement of the same terrains still passes. None when no choice passes
    (too few grid values between ``level0`` and ``last``, or the curve rises there)."""
    v, m = np.asarray(values, np.float64), _curve(means)
    if v.shape != m.shape or np.any(np.diff(v) <= 0):
        raise ValueError(f"values must be increasing and as long as means ({m.size}); got {v.tolist()}")
    if not isinstance(levels, (int, np.integer)) or levels < 2:
        raise ValueError(f"levels must be an integer >= 2; got {levels!r}")
    for top, bottom in ((level0 + margin, last - margin), (level0, last)):
        idx = _even_levels(m, levels, top, bottom, rise)
        if idx is not None:
            return idx
    return None


def _even_levels(m: np.ndarray, levels: int, top: float, bottom: float, rise: float) -> np.ndarray | None:
    g = m.size
    cost = np.full((levels, g), np.inf)  # cost[k, i]: the smallest sum of squared steps of levels 0..k ending at i
    prev = np.full((levels, g), -1)
    cost[0, m >= top] = 0.0
    for k in range(1, levels):
        for i in range(k, g):
            for j in range(k - 1, i):
                if not np.isfinite(cost[k - 1, j]) or m[i] - m[j] > rise + 1e-12:
                    continue
                c = cost[k - 1, j] + (m[j] - m[i]) ** 2
                if c < cost[k, i] - 1e-15:
                    cost[k, i], prev[k, i] = c, j
    ends = [i for i in range(g) if m[i] <= bottom and np.isfinite(cost[levels - 1, i])]
    if not ends:
        return None
    i = min(ends, key=lambda e: (cost[levels - 1, e], e))
    out = [i]
    for k in range(levels - 1, 0, -1):
        i = int(prev[k, i])
        out.append(i)
    return np.array(out[::-1], np.int64)


def decreasing_fit(means, weights=None) -> np.ndarray:
    """The non-increasing sequence nearest to ``means`` [G] in (weighted) least squares (pool-adjacent-violators)."""
    m = _curve(means)
    w = np.ones_like(m) if weights is None else np.asarray(weights, np.float64)
    blocks: list[list[float]] = []  # [value, weight, count]
    for x, wx in zip(m, w):
        blocks.append([x, wx, 1])
        while len(blocks) > 1 and blocks[-2][0] < blocks[-1][0]:
            b = blocks.pop()
            a = blocks[-1]
            a[0] = (a[0] * a[1] + b[0] * b[1]) / (a[1] + b[1])
            a[1] += b[1]
            a[2] += b[2]
    return np.concatenate([np.full(c, x) for x, _, c in blocks])


def propose_values(values, means, levels: int = 10, top: float = 0.88, bottom: float = 0.22,
                   geometric: bool = False) -> np.ndarray | None:
    """``levels`` increasing values where the grid's non-increasing fit (:func:`decreasing_fit`) crosses mean
    fitness ``linspace(top, bottom, levels)`` (linear interpolation between grid values; in ``log(value)`` when
    ``geometric``), for a grid too coarse for :func:`select_levels`: they are not measured. None when the fit does
    not span ``top`` to ``bottom`` (the grid's range is too narrow: widen it)."""
    v, m = np.asarray(values, np.float64), decreasing_fit(means)
    if v.shape != m.shape or np.any(np.diff(v) <= 0) or (geometric and v[0] <= 0):
        raise ValueError(f"values must be increasing (and > 0 when geometric) and as long as means; got {v.tolist()}")
    if m[0] < top or m[-1] > bottom:
        return None
    x = np.log(v) if geometric else v
    out = []
    for t in np.linspace(top, bottom, levels):
        i = int(np.flatnonzero(m <= t)[0])  # the first grid value at or below the target
        if i == 0 or m[i] == m[i - 1]:
            out.append(x[i])
        else:
            out.append(x[i - 1] + (m[i - 1] - t) / (m[i - 1] - m[i]) * (x[i] - x[i - 1]))
    out = np.maximum.accumulate(np.asarray(out))
    return np.exp(out) if geometric else out
