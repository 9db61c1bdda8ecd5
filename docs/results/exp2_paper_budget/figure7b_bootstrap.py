"""Figure 7b at the paper's budget with the roughness-sorted baseline under both truncation modes: the CPPN map
(``mask``), standard CL under ``mask`` and under ``bootstrap``; each curve from its run folder's ``summary.json``.

    python docs/results/exp2_paper_budget/figure7b_bootstrap.py      # -> docs/results/exp2_paper_budget/
"""
import json
import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from experiments import common  # noqa: E402
from jaxterrain.curriculum import outputs  # noqa: E402

HERE = pathlib.Path(__file__).resolve().parent
RUNS = {"cppn map (mask)": HERE.parent / "exp2_paper_cppn_map",
        "cppn roughness (mask)": HERE.parent / "exp2_paper_cppn_roughness",
        "cppn roughness (bootstrap)": HERE.parent / "exp2_paper_cppn_roughness" / "truncation" / "paper_bootstrap"}


def curve(run: pathlib.Path) -> tuple:
    """(epoch, mean, se) of the run's hardest terrain traversed, each [K]."""
    return outputs.summary_curve(json.loads((run / "summary.json").read_text()))


if __name__ == "__main__":
    fig, ax = plt.subplots(figsize=(7, 4))
    outputs.plot_curves(ax, {label: curve(run) for label, run in RUNS.items()},
                      "Figure 7b at 30 000 epochs: CPPN map vs roughness-sorted CL, both truncation modes")
    fig.tight_layout()
    common.save_figure(fig, HERE / "figure7b_bootstrap.png")
    print(f"-> {HERE / 'figure7b_bootstrap.png'}")
