"""Table 2 and Figure 7 of docs/results/exp2_gpushort from the treatments' summary.json (three finished) and the
unfinished cppn-map's metrics.csv (mean hardest per chunk, 50 of 75 chunks)."""
import csv, json
from pathlib import Path
import numpy as np
import matplotlib; matplotlib.use("Agg")
import matplotlib.pyplot as plt
from experiments import curriculum as exp, common
from jaxterrain.curriculum import outputs

D = Path("docs/results/exp2_gpushort")
rows = [(f"{n} {c}", json.loads((D / f"{n}-{c}" / "summary.json").read_text()))
        for n, c in (("combined", "map"), ("perlin", "map"), ("cppn", "roughness"))]
exp.write_table(D, rows, trials=10)
m = list(csv.DictReader(open(D / "cppn-map" / "metrics.csv")))
epoch = np.array([0] + [40 * int(r["step"]) for r in m], float)
mean = np.array([np.sqrt(2)] + [float(r["hardest"]) for r in m])
curve = outputs.summary_curve
maps = {label.split(" ")[0]: curve(s) for label, s in rows if label.endswith(" map")}
maps["cppn (2 000 of 3 000 epochs; mean only)"] = (epoch, mean, np.zeros_like(mean))
fig, ax = plt.subplots(figsize=(7, 4))
outputs.plot_curves(ax, maps, "Figure 7a (gpu-short): map-based curriculum per archive (mean +- 1 s.e.)")
fig.tight_layout(); common.save_figure(fig, D / "figure7a.png")
pair = {"cppn map (2 000 epochs; mean only)": (epoch, mean, np.zeros_like(mean)),
        "cppn roughness": curve(rows[2][1])}
fig, ax = plt.subplots(figsize=(7, 4))
outputs.plot_curves(ax, pair, "Figure 7b (gpu-short): CPPN, map-based vs roughness-sorted curriculum")
fig.tight_layout(); common.save_figure(fig, D / "figure7b.png")
print(open(D / "table2.md").read())
