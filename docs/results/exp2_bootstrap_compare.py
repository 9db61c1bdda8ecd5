"""Experiment 2 under two settings, treatment by treatment: the hardest terrain traversed (cells from the origin) at
given epochs, mean +- standard error over the trials, and Welch's p of the difference.

    python docs/results/exp2_bootstrap_compare.py RUN_A RUN_B [--epochs 400 1000 2000 3000]

RUN_A and RUN_B are ``curriculum`` run folders (one sub-folder per treatment, each with ``history.csv``). A trial's
hardest terrain at epoch E is its ``hardest`` in the last ``history.csv`` row at or before E (a trial that stopped
earlier keeps its last value). Prints a markdown table.
"""
import argparse
import csv
import pathlib
import warnings

import numpy as np
from scipy import stats


def hardest_at(history: pathlib.Path, epochs: list[int]) -> np.ndarray:
    """[T, len(epochs)]: each trial's hardest terrain at each epoch (0 before its first chunk)."""
    rows = list(csv.DictReader(history.open()))
    trials = sorted({int(r["trial"]) for r in rows})
    out = np.zeros((len(trials), len(epochs)))
    for r in rows:
        t, e, h = trials.index(int(r["trial"])), int(r["epoch"]), float(r["hardest"])
        for j, ej in enumerate(epochs):
            if e <= ej:
                out[t, j] = max(out[t, j], h)
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("run_a", type=pathlib.Path)
    p.add_argument("run_b", type=pathlib.Path)
    p.add_argument("--epochs", type=int, nargs="+", default=[400, 1000, 2000, 3000])
    a = p.parse_args()
    names = sorted(d.name for d in a.run_a.iterdir()
                   if (d / "history.csv").is_file() and (a.run_b / d.name / "history.csv").is_file())
    print("| treatment | run | " + " | ".join(f"{e} epochs" for e in a.epochs) + " |")
    print("|---|---|" + "---|" * len(a.epochs))
    for n in names:
        ha, hb = (hardest_at(r / n / "history.csv", a.epochs) for r in (a.run_a, a.run_b))
        for run, h in ((a.run_a, ha), (a.run_b, hb)):
            cells = []
            for j in range(len(a.epochs)):
                s = f"{h[:, j].mean():.2f} +- {h[:, j].std(ddof=1) / np.sqrt(len(h)):.2f}"
                if h is hb:
                    with warnings.catch_warnings():  # identical samples (e.g. every trial on one terrain): p is nan
                        warnings.simplefilter("ignore", RuntimeWarning)
                        pv = stats.ttest_ind(ha[:, j], hb[:, j], equal_var=False).pvalue
                    s += f" (p {pv:.2f})" if np.isfinite(pv) else " (p -)"
                cells.append(s)
            print(f"| {n} | {run.name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
