"""One call from Python to a curriculum's results: :func:`run` runs (or continues) a treatment with
``runner.run_treatment`` and returns its walkers and its history as a :class:`TreatmentResult`; :func:`read_result`
reads a finished run folder (of this call or of ``python -m experiments learn``) into the same shape.

    from jaxterrain.curriculum import result, run_config
    out = result.run(run_config.PRESETS["smoke"], "runs/smoke")     # None when a time limit stopped it
    out.policies                  # (Path, ...): policies/trial_K, one walker per trial (rl.load_policy reads each)
    out.history["evaluation"]     # [rows] float64: one row of history.csv per trial and chunk
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import NamedTuple, Optional

import numpy as np

from jaxterrain.curriculum.outputs import POLICIES
from jaxterrain.curriculum.run_config import LearnConfig
from jaxterrain.curriculum.runner import run_treatment

__all__ = ["TreatmentResult", "run", "read_result"]


class TreatmentResult(NamedTuple):
    """A finished treatment. folder: its run folder. summary: ``summary.json`` (epochs, milestones, the selector's
    own counts). policies: ``policies/trial_K`` for K = 0 .. trials - 1, each a walker ``rl.load_policy`` reads.
    history: ``history.csv`` as columns (``trial``, ``chunk``, ``epoch``, ``env_steps``, ``terrain``, ``cell``,
    ``bin0``, ``bin1``, ``distance``, ``evaluation``, ``hardest``, ``seen_epoch``: ``outputs.HISTORY_COLUMNS``;
    runs written before 2026-11-29 lack ``seen_epoch``), each [rows] (int64 where every value is an integer, else
    float64), one row per trial and chunk it ran."""

    folder: Path
    summary: dict
    policies: tuple
    history: dict


def read_result(folder) -> TreatmentResult:
    """The :class:`TreatmentResult` of a finished run ``folder``; ``FileNotFoundError`` naming the file when it
    has not finished (no ``summary.json``)."""
    folder = Path(folder)
    summary = json.loads((folder / "summary.json").read_text())
    with open(folder / "history.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    history = {}
    for name in (rows[0] if rows else []):
        values = np.asarray([float(r[name]) for r in rows], np.float64)
        history[name] = values.astype(np.int64) if np.all(values == np.round(values)) and name not in (
            "distance", "evaluation", "hardest") else values
    policies = tuple(folder / POLICIES / f"trial_{k}" for k in range(int(summary["trials"])))
    return TreatmentResult(folder, summary, policies, history)


def run(config: LearnConfig, folder, *, time_limit_s: Optional[float] = None,
        progress: bool | str = True) -> Optional[TreatmentResult]:
    """Run (or continue) the treatment ``config`` (e.g. ``run_config.PRESETS["smoke"]``) in ``folder``
    (``runner.run_treatment``: validated once, checkpointed, resumable) and return its :class:`TreatmentResult`;
    None when ``time_limit_s`` stopped it first (call again to continue)."""
    if run_treatment(config, Path(folder), time_limit_s=time_limit_s, progress=progress) is None:
        return None
    return read_result(folder)
