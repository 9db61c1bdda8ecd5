"""The worked example of ``docs/statistics.md`` (issue 61), recomputed from the raw held-out files:

    PYTHONPATH=. python docs/results/trial_unit.py      # writes docs/results/trial_unit.json (CPU, seconds)

Reads ``docs/results/exp3_gpushort/*/heldout/fitness.csv.gz`` and the ant's, and ``generalise``'s
``intervals.csv`` beside them (run ``python -m experiments generalise`` first: the pages name the commands). For each
Experiment 3 treatment: the standard deviation of its 10 trial means against the one independent cells would give
(``sqrt(sum_c var_c) / cells``, ``var_c`` the variance over trials of cell ``c``), and the width of its IQM interval
over trials against rliable's stratified one; the diamond-square map's weakest walker against every other walker;
the ant's gain over its base policy with pooled and with per-trial trimming, against the base policy's one
evaluation beside the walkers and against its 10-key evaluation (``base_v1_keys_h200_2026-11-29/ant``, issue 61
item 2: the comparator of every page).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from experiments.generalise import load_base, load_treatment
from jaxterrain import suite
from jaxterrain.runtime import statistics

RESULTS = Path(__file__).resolve().parent
BASE_KEYS = RESULTS / "base_v1_keys_h200_2026-11-29"   # the base policies with 10 evaluation keys


def cell_matrix(t: dict, base: bool = False) -> np.ndarray:
    """[runs, cells] of a loaded treatment (its trials, or its base policy's evaluations)."""
    return suite.cell_scores(t["base"] if base else t["fitness"], t["family"], t["level"])[1]


def widths(path: Path, scope: str = "all") -> dict:
    """``{treatment: (trial-level IQM width, stratified IQM width)}`` from ``generalise``'s ``intervals.csv``."""
    return {r["treatment"]: (float(r["iqm_high"]) - float(r["iqm_low"]),
                             float(r["iqm_high_stratified"]) - float(r["iqm_low_stratified"]))
            for r in csv.DictReader(path.open()) if r["scope"] == scope}


def ant_gain(a: np.ndarray, b: np.ndarray) -> dict:
    """The walkers ``a`` [trials, cells] against the base policy's runs ``b`` [runs, cells]: pooled and per-run
    trimmed IQMs and the gains, and how many walkers have a cell mean above the base policy's."""
    return {"base_evaluations": int(b.shape[0]),
            "iqm_pooled": round(statistics.iqm(a), 4), "base_iqm": round(statistics.iqm(b), 4),
            "gain_pooled": round(statistics.iqm(a) - statistics.iqm(b), 4),
            "trial_iqm": round(statistics.trial_iqm(a), 4), "base_trial_iqm": round(statistics.trial_iqm(b), 4),
            "gain_trial_iqm": round(statistics.trial_iqm(a) - statistics.trial_iqm(b), 4),
            "walkers_above_base_mean": int(np.sum(a.mean(axis=1) > b.mean()))}


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
    a = cell_matrix(ant)                                            # [10, 127]
    keys = suite.cell_scores(load_base(BASE_KEYS / "ant", ant["family"], ant["level"]), ant["family"],
                             ant["level"])[1]                       # [10 keys, 127]
    out["ant"] = ant_gain(a, cell_matrix(ant, base=True))          # [1, 127]: the evaluation beside the walkers
    out["ant_base_10_keys"] = ant_gain(a, keys)
    (RESULTS / "trial_unit.json").write_text(json.dumps(out, indent=2) + "\n")
    return out


if __name__ == "__main__":
    print(json.dumps(main(), indent=2))
