"""Table 2 and Figure 7 from per-trial curriculum histories (pure NumPy, host side).

    first = first_epochs(epoch [T, C], hardest [T, C])        # [T, 10] epochs to reach 5 %, ..., 50 % of 70.71
    mean, reached = milestone_summary(first)                  # [10] mean over the trials that reached it, [10] how many
    grid, mean, se = hardest_curve(epoch, hardest)            # Figure 7: hardest vs epoch, mean +- 1 standard error

History arrays are :class:`~jaxterrain.curriculum.core.History` fields stacked over trials: ``epoch`` [T, C] int
(-1 after a trial's last chunk), ``hardest`` [T, C] float (NaN after it).
"""

from __future__ import annotations

from typing import Optional, Sequence

import numpy as np

from jaxterrain.qd import MAX_DISTANCE_50

__all__ = ["MILESTONES", "PAPER_TABLE2", "first_epochs", "milestone_summary", "format_milestone", "hardest_curve",
           "terrain_runs"]

MILESTONES = tuple(round(0.05 * k, 2) for k in range(1, 11))
"""Table 2's columns: 5 %, 10 %, ..., 50 % of the maximum map distance."""

PAPER_TABLE2 = {  # epochs to first learn a terrain at each milestone (paper, Table 2; None = "-")
    "cppn": (40, 80, 120, 240, 960, 4720, 7000, 9880, 13280, None),
    "gan": (40, 80, 1000, None, None, None, None, None, None, None),
    "perlin": (40, 40, 160, 320, 960, 8680, None, None, None, None),
    "worley": (40, 80, 480, 2640, 4160, 14080, None, None, None, None),
    "diamond_square": (80, 160, 1280, None, None, None, None, None, None, None),
    "combined": (80, 120, 160, 320, 440, 3720, 7280, 10280, 15040, 29000),
}


def _valid(epoch: np.ndarray, hardest: np.ndarray) -> np.ndarray:
    return (np.asarray(epoch) >= 0) & np.isfinite(np.asarray(hardest, np.float64))


def first_epochs(epoch, hardest, fractions: Sequence[float] = MILESTONES,
                 max_distance: float = MAX_DISTANCE_50) -> np.ndarray:
    """``[T, F]`` float64: for each trial, the epoch of the first chunk whose hardest terrain reached
    ``fraction x max_distance`` (NaN where it never did). ``epoch``, ``hardest``: [T, C] (or [C] for one trial)."""
    epoch = np.atleast_2d(np.asarray(epoch))
    hardest = np.atleast_2d(np.asarray(hardest, np.float64))
    valid = _valid(epoch, hardest)
    out = np.full((epoch.shape[0], len(fractions)), np.nan)
    for j, f in enumerate(fractions):
        hit = valid & (np.nan_to_num(hardest, nan=-np.inf) >= f * max_distance - 1e-9)
        any_hit = hit.any(axis=1)
        first = np.argmax(hit, axis=1)
        out[any_hit, j] = epoch[any_hit, first[any_hit]]
    return out


def milestone_summary(first: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``first`` [T, F] -> ``(mean [F], reached [F] int)``: the mean epoch over the trials that reached each
    milestone (NaN where none did) and how many did."""
    first = np.atleast_2d(np.asarray(first, np.float64))
    reached = np.sum(np.isfinite(first), axis=0)
    total = np.nansum(first, axis=0)
    mean = np.where(reached > 0, total / np.maximum(reached, 1), np.nan)
    return mean, reached.astype(int)


def format_milestone(mean: float, reached: int, trials: int) -> str:
    """One Table 2 cell: ``"-"`` where no trial reached it, the rounded mean epoch, and ``" (k/T)"`` when only
    ``k`` of ``T`` trials did."""
    if reached == 0 or not np.isfinite(mean):
        return "-"
    cell = f"{mean:.0f}"
    return cell if reached == trials else f"{cell} ({reached}/{trials})"


def hardest_curve(epoch, hardest) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Figure 7: ``(epochs [G], mean [G], se [G])`` of the hardest terrain traversed over trials.

    The grid is the epochs of the longest trial, from 0 (hardest 0); a trial that ended earlier keeps its last value
    (the curve ends where the last trial ended). ``se`` = standard deviation (ddof 1) / sqrt(T), 0 for one trial.
    """
    epoch = np.atleast_2d(np.asarray(epoch))
    hardest = np.atleast_2d(np.asarray(hardest, np.float64))
    valid = _valid(epoch, hardest)
    lengths = valid.sum(axis=1)
    g = int(lengths.max()) if lengths.size else 0
    longest = int(np.argmax(lengths)) if lengths.size else 0
    grid = np.concatenate([[0], epoch[longest, :g]]).astype(np.int64)
    values = np.zeros((epoch.shape[0], g + 1))
    for t in range(epoch.shape[0]):
        n = int(lengths[t])
        if n:
            values[t, 1:n + 1] = hardest[t, :n]
            values[t, n + 1:] = hardest[t, n - 1]
    trials = values.shape[0]
    se = values.std(axis=0, ddof=1) / np.sqrt(trials) if trials > 1 else np.zeros(g + 1)
    return grid, values.mean(axis=0), se


def terrain_runs(terrain, evaluation, epoch: Optional[np.ndarray] = None) -> list[dict]:
    """One trial's terrain sequence from its history ``terrain`` [C], ``evaluation`` [C] (and ``epoch`` [C]):
    a list of ``{"terrain", "chunks", "final_evaluation", "best_evaluation", "end_epoch"}``, one per consecutive
    run of the same terrain (a terrain is never trained twice in a row unless it was not finished). A chunk trained
    but not evaluated (evaluation NaN: ``CurriculumConfig.eval_lag``'s chunk after a terrain's last evaluation)
    counts in ``chunks`` and ``end_epoch`` but not in the evaluations (NaN only for a run with none)."""
    terrain = np.asarray(terrain)
    evaluation = np.asarray(evaluation, np.float64)
    n = int(np.sum(terrain >= 0))
    runs: list[dict] = []
    for c in range(n):
        e = float(evaluation[c])
        if runs and runs[-1]["terrain"] == int(terrain[c]):
            r = runs[-1]
            r["chunks"] += 1
            r["best_evaluation"] = float(np.fmax(r["best_evaluation"], e))
        else:
            r = {"terrain": int(terrain[c]), "chunks": 1, "best_evaluation": e, "final_evaluation": e}
            runs.append(r)
        if not np.isnan(e):
            r["final_evaluation"] = e
        r["end_epoch"] = None if epoch is None else int(np.asarray(epoch)[c])
    return runs
