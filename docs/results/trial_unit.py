"""The worked example of ``docs/statistics.md`` (issue 61), recomputed from the raw held-out files:

    PYTHONPATH=. python docs/results/trial_unit.py      # writes docs/results/trial_unit.json (CPU, seconds)

Reads ``docs/results/exp3_gpushort/*/heldout/fitness.csv.gz`` and the ant's, and ``generalise``'s
``intervals.csv`` beside them (run ``python -m experiments generalise`` first: the pages name the commands). For each
Experiment 3 treatment: the standard deviation of its 10 trial means against the one independent cells would give
(``sqrt(sum_c var_c) / cells``, ``var_c`` the variance over trials of cell ``c``), and the width of its IQM interval
over trials against rliable's stratified one; the diamond-square map's weakest walker against every other walker;
the ant's gain over its base policy with pooled and with per-trial trimming.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from experiments.generalise import load_treatment
from jaxterrain import suite
from jaxterrain.runtime import statistics

RESULTS = Path(__file__).resolve().parent


def cell_matrix(t: dict, base: bool = False) -> np.ndarray:
    """[runs, cells] of a loaded treatment (its trials, or its base policy's evaluations)."""
    return suite.cell_scores(t["base"] if base else t["fitness"], t["family"], t["level"])[1]


def widths(path: Path, scope: str = "all") -> dict:
    """``{treatment: (trial-level IQM width, stratified IQM width)}`` from ``generalise``'s ``intervals.csv``."""
    return {r["treatment"]: (float(r["iqm_high"]) - float(r["iqm_low"]),
                             float(r["iqm_high_stratified"]) - float(r["iqm_low_stratified"]))
            for r in csv.DictReader(path.open()) if r["scope"] == scope}


def main() -> dict:
    exp3 = RESULTS / "exp3_gpushort"
    ts = [load_treatment(d) for d in sorted(exp3.iterdir()) if (d / "summary.json").is_file()]
    w = widths(exp3 / "generalisation" / "intervals.csv")
    out = {"exp3": {}}
    for t in ts:
        x = cell_matrix(t)                                          # [10 trials, 127 cells]
        sd = float(x.mean(axis=1).std(ddof=1))
        indep = float(np.sqrt(x.var(axis=0, ddof=1).sum()) / x.shape[1])
        wt, ws = w[t["label"]]
        out["exp3"][t["label"]] = {"trial_mean_sd": round(sd, 5), "sd_if_cells_independent": round(indep, 5),
                                   "sd_ratio": round(sd / indep, 2), "iqm_width_trials": round(wt, 4),
                                   "iqm_width_stratified": round(ws, 4), "width_ratio": round(wt / ws, 2)}
    means = {t["label"]: cell_matrix(t).mean(axis=1) for t in ts}
    ds = "diamond_square map"
    out["diamond_square_weakest_walker"] = {
        "weakest_cell_mean": round(float(means[ds].min()), 4),
        "best_other_walker": round(float(max(m.max() for k, m in means.items() if k != ds)), 4),
        "best_other_treatment": max((k for k in means if k != ds), key=lambda k: means[k].max())}
    ant = load_treatment(RESULTS / "ant_gpushort" / "learn")
    a, b = cell_matrix(ant), cell_matrix(ant, base=True)            # [10, 127], [1, 127]
    out["ant"] = {"base_evaluations": int(b.shape[0]),
                  "iqm_pooled": round(statistics.iqm(a), 4), "base_iqm": round(statistics.iqm(b), 4),
                  "gain_pooled": round(statistics.iqm(a) - statistics.iqm(b), 4),
                  "trial_iqm": round(statistics.trial_iqm(a), 4),
                  "gain_trial_iqm": round(statistics.trial_iqm(a) - statistics.trial_iqm(b), 4),
                  "walkers_above_base_mean": int(np.sum(a.mean(axis=1) > b.mean()))}
    (RESULTS / "trial_unit.json").write_text(json.dumps(out, indent=2) + "\n")
    return out


if __name__ == "__main__":
    print(json.dumps(main(), indent=2))
