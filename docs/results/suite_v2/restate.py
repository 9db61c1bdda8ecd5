"""The numbers the four results pages quote, on suite v2 beside v1 (issue 61 item 4), for rewriting the pages.

    PYTHONPATH=. python docs/results/suite_v2/restate.py                  # CPU, a few minutes: every page
    PYTHONPATH=. python docs/results/suite_v2/restate.py --pages wide --reps 200     # one page, quick look

Needs suite v2's evaluations (``reevaluate.py``: each treatment's ``heldout_v2/`` and the base policies' 10-key
folders under ``--base-out``). For each page of :data:`PAGES` it runs ``python -m experiments generalise`` with the
page's own v1 command (the same treatments and labels) on ``--heldout heldout_v2`` against the v2 base evaluation,
with the page's shipped v1 aggregate beside it (``--beside v1=...``), into the page's ``generalisation_v2/``; then
writes ``docs/results/suite_v2/restated/<page>.md`` and ``.json``: every figure of the page's kind on v1 and v2 side
by side, and the page's claims checked on each suite:

- each treatment's IQM, mean and P(beats base policy) with intervals over trials, rliable's stratified IQM
  interval, the gain in trial IQM over the base policy and how many walkers have a cell mean above the base
  policy's;
- the page's claims: every treatment above the base policy; the best treatment, its margin and its weakest walker
  against every other walker; the pairs each page compares (:data:`PAGES`), with P(X > Y), Welch p and its Holm
  adjustment; the paper's metric against held-out scores (mean within-treatment Spearman and its stratified
  permutation test, pooled Spearman); the width of the intervals over trials against the stratified ones;
- per family: the base policy's trial IQM, the best treatment, how many treatments lie above / below the base
  policy (trial-IQM intervals), and how many walkers of each treatment pass each family's level 0;
- on v2 only: each generator's worst decile (CVaR at 10 %) of its 40 fresh samples, per treatment (the mean over
  its walkers) and for the base policy (over its keys) (``robustness.csv``).

Nothing here is a number until the v2 evaluations exist: the script refuses to run without them.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[3]
BASE_OUT = "docs/results/base_v2_keys_h200"
HELDOUT = "heldout_v2"
R = "docs/results"

PAGES: dict[str, dict] = {
    "exp3": dict(page=f"{R}/exp3.md", robot="humanoid", runs=[f"{R}/exp3_gpushort"],
                 v1=f"{R}/exp3_gpushort/generalisation", out=f"{R}/exp3_gpushort/generalisation_v2",
                 pairs=[("worley map", "cppn map"), ("perlin map", "cppn map"), ("gan map", "cppn map"),
                        ("worley map", "perlin map"), ("worley map", "gan map"), ("perlin map", "gan map"),
                        ("cppn map", "combined map"), ("cppn map", "cppn random"), ("cppn map", "cppn roughness"),
                        ("cppn random", "cppn roughness")]),
    "exp3_curricula": dict(
        page=f"{R}/exp3_curricula.md", robot="humanoid",
        runs=[f"{R}/exp3_gpushort", f"{R}/exp3b_gpushort/cppn-dr", f"{R}/exp3b_gpushort/cppn-levels",
              f"{R}/exp3c_gpushort"],
        v1=f"{R}/exp3c_gpushort/generalisation", out=f"{R}/exp3c_gpushort/generalisation_v2",
        pairs=[("cppn plr", "cppn dr"), ("cppn plr", "cppn map"), ("cppn dr", "cppn map"), ("cppn levels", "cppn map"),
               ("cppn plr", "cppn levels"), ("cppn dr", "cppn levels"), ("cppn plr", "cppn accel"),
               ("cppn dr", "cppn accel"), ("cppn levels", "cppn accel"), ("cppn accel", "cppn map"),
               ("cppn map", "cppn roughness"), ("cppn random", "cppn map"),
               *[(m, c) for m in ("diamond_square map", "worley map", "perlin map", "gan map")
                 for c in ("cppn plr", "cppn dr")]]),
    "exp3b": dict(page=f"{R}/exp3_curricula.md", robot="humanoid", runs=[f"{R}/exp3b_gpushort", f"{R}/exp3_gpushort"],
                  v1=f"{R}/exp3b_gpushort/generalisation", out=f"{R}/exp3b_gpushort/generalisation_v2",
                  pairs=[("cppn plr", "cppn dr"), ("cppn plr", "cppn map"), ("cppn dr", "cppn map"),
                         ("cppn accel", "cppn map")]),
    "wide": dict(page=f"{R}/wide_recipe.md", robot="humanoid",
                 runs=[f"cppn-map-paper={R}/exp3_gpushort/cppn-map", f"perlin-map-paper={R}/exp3_gpushort/perlin-map",
                       f"cppn-map-wide={R}/wide_gpushort/cppn-map", f"perlin-map-wide={R}/wide_gpushort/perlin-map"],
                 v1=f"{R}/wide_gpushort/generalisation", out=f"{R}/wide_gpushort/generalisation_v2",
                 pairs=[("cppn-map-paper", "cppn-map-wide"), ("perlin-map-paper", "perlin-map-wide"),
                        ("perlin-map-wide", "cppn-map-wide"), ("perlin-map-paper", "cppn-map-paper")],
                 kept=[("cppn-map-wide", "cppn-map-paper"), ("perlin-map-wide", "perlin-map-paper")]),
    "ant": dict(page=f"{R}/ant_gpushort/README.md", robot="ant", runs=[f"ant-map={R}/ant_gpushort/learn"],
                v1=f"{R}/ant_gpushort/learn/generalisation", out=f"{R}/ant_gpushort/learn/generalisation_v2",
                pairs=[]),
}
"""Each page: its file, robot, the RUN arguments of its v1 ``generalise`` command (the same labels), its v1
aggregate, the v2 aggregate's folder, the pairs it compares (X, Y: P(X > Y)) and, for the wide recipe, the
(recipe, reference) pairs whose share of the reference's IQM gain over the base policy it quotes."""

BASE = "base policy"


def read_csv(path: Path) -> list[dict]:
    with Path(path).open() as fh:
        return list(csv.DictReader(fh))


def aggregate(folder: Path) -> dict:
    """A generalise output folder's tables: ``intervals`` {(treatment, scope): row}, ``improvement`` {(x, y): row},
    ``trials`` [rows], ``correlation`` (dict), ``meta`` (dict; {} for folders written before meta.json)."""
    folder = Path(folder)
    meta = folder / "meta.json"
    return {"intervals": {(r["treatment"], r["scope"]): r for r in read_csv(folder / "intervals.csv")},
            "improvement": {(r["x"], r["y"]): r for r in read_csv(folder / "improvement.csv")},
            "trials": read_csv(folder / "trials.csv"),
            "correlation": json.loads((folder / "correlation.json").read_text()),
            "meta": json.loads(meta.read_text()) if meta.is_file() else {},
            "levels": read_csv(folder / "levels.csv") if (folder / "levels.csv").is_file() else []}


def f(row: dict, key: str) -> float:
    v = row.get(key, "")
    return float(v) if v not in ("", None) else float("nan")


def iv(row: dict, key: str, low: str | None = None, high: str | None = None) -> list[float]:
    """``[point, low, high]`` of column ``key`` (its ``_low`` / ``_high`` columns unless named)."""
    return [f(row, key), f(row, low or f"{key}_low"), f(row, high or f"{key}_high")]


def fmt(x: list[float] | None) -> str:
    if x is None or any(np.isnan(v) for v in x):
        return "-"
    return f"{x[0]:.3f} [{x[1]:.3f}, {x[2]:.3f}]"


def treatment_folders(spec: dict, root: Path, heldout: str) -> dict[str, Path]:
    """``{label: treatment folder}`` as ``generalise`` reads the page's RUN arguments with ``--heldout heldout``."""
    from experiments.generalise import labelled_path
    from experiments.generalise import treatment_folders as found

    runs = []
    for r in spec["runs"]:
        label, sep, rest = r.partition("=")
        runs.append(labelled_path(f"{label}={root / rest}" if sep else str(root / r)))
    return {(lab or d.name.replace("-", " ")): d for d, lab in found(runs, heldout)}


def level0_passes(folder: Path) -> dict[str, int]:
    """``{family: walkers passing level 0}`` of an evaluation's ``levels.csv`` (base rows left out)."""
    from jaxterrain.suite.runs import is_base

    out: dict[str, int] = {}
    for r in read_csv(folder / "levels.csv"):
        if not is_base(r["policy"]):
            out[r["family"]] = out.get(r["family"], 0) + int(int(r["highest_level_passed"]) >= 0)
    return out


def robustness(folder: Path, base: bool = False) -> dict[str, float]:
    """``{generator: mean CVaR at 10 % over the walkers (or, with ``base``, over the base policy's rows)}`` of an
    evaluation's ``robustness.csv``; {} without one (v1's evaluations)."""
    from jaxterrain.suite.runs import is_base

    path = folder / "robustness.csv"
    if not path.is_file():
        return {}
    per: dict[str, list] = {}
    for r in read_csv(path):
        if is_base(r["policy"]) == base:
            per.setdefault(r["generator"], []).append(float(r["cvar10"]))
            SAMPLES[r["generator"]] = int(r["samples"])
    return {g: float(np.mean(v)) for g, v in per.items()}


SAMPLES: dict[str, int] = {}
"""Each generator's samples in the last ``robustness.csv`` read (the worst decile's sample size)."""


def suite_numbers(agg: dict, folders: dict[str, Path], heldout: str, pairs, kept, base_folder: Path | None) -> dict:
    """Every figure of one page on one suite, from its aggregate and the treatments' evaluations."""
    ivs, imp = agg["intervals"], agg["improvement"]
    names = [t for (t, s) in ivs if s == "all" and t != BASE]
    families = list(dict.fromkeys(s for (_, s) in ivs if s != "all"))
    trials: dict[str, list[float]] = {}
    for r in agg["trials"]:
        trials.setdefault(r["treatment"], []).append(float(r["cell_mean"]))
    base_all = ivs[(BASE, "all")]
    base_mean = f(base_all, "mean")
    rows = {}
    for n in names:
        a = ivs[(n, "all")]
        p = imp.get((n, BASE), {})
        w = trials.get(n, [])
        rows[n] = {"runs": int(a["runs"]), "iqm": iv(a, "iqm"), "iqm_stratified": iv(a, "iqm", "iqm_low_stratified",
                                                                                      "iqm_high_stratified"),
                   "mean": iv(a, "mean"), "trial_iqm": iv(a, "trial_iqm"),
                   "p_beats_base": iv(p, "probability", "low", "high") if p else None,
                   "gain_trial_iqm": f(a, "trial_iqm") - f(base_all, "trial_iqm"),
                   "gain_iqm": f(a, "iqm") - f(base_all, "iqm"),
                   "walkers_above_base_mean": int(sum(x > base_mean for x in w)), "walkers": len(w),
                   "width_ratio": (f(a, "iqm_high") - f(a, "iqm_low"))
                   / max(f(a, "iqm_high_stratified") - f(a, "iqm_low_stratified"), 1e-12)}
    rows[BASE] = {"runs": int(base_all["runs"]), "iqm": iv(base_all, "iqm"),
                  "iqm_stratified": iv(base_all, "iqm", "iqm_low_stratified", "iqm_high_stratified"),
                  "mean": iv(base_all, "mean"), "trial_iqm": iv(base_all, "trial_iqm")}
    order = sorted(names, key=lambda n: -rows[n]["iqm"][0])
    claims: dict = {}
    above = [n for n in names if rows[n]["p_beats_base"] and rows[n]["p_beats_base"][1] > 0.5]
    iqm_above = [n for n in names if rows[n]["iqm"][1] > rows[BASE]["iqm"][2]]
    lowest = min(names, key=lambda n: rows[n]["p_beats_base"][1] if rows[n]["p_beats_base"] else 9.0)
    claims["beats_base"] = {"p_interval_above_half": len(above), "iqm_interval_above_base": len(iqm_above),
                            "treatments": len(names), "lowest_p": [lowest, rows[lowest]["p_beats_base"]],
                            "walkers_above_base_mean": sum(rows[n]["walkers_above_base_mean"] for n in names),
                            "walkers": sum(rows[n]["walkers"] for n in names)}
    if len(order) >= 2:
        best = order[0]
        ps = {o: imp.get((best, o), {}) for o in order[1:]}
        others = [x for o in order[1:] for x in trials.get(o, [])]
        claims["best"] = {"treatment": best, "iqm": rows[best]["iqm"], "next": order[1],
                          "next_iqm": rows[order[1]]["iqm"],
                          "p_over_each_min": min(f(p, "probability") for p in ps.values()),
                          "p_low_over_each_min": min(f(p, "low") for p in ps.values()),
                          "holm_max": max(f(p, "holm_p") for p in ps.values()),
                          "weakest_walker": min(trials.get(best, [np.nan])),
                          "best_other_walker": max(others) if others else float("nan")}
    claims["pairs"] = []
    for x, y in pairs:
        p = imp.get((x, y))
        if p is None:
            continue
        claims["pairs"].append({"x": x, "y": y, "p": iv(p, "probability", "low", "high"), "welch_p": f(p, "welch_p"),
                                "holm_p": f(p, "holm_p"), "separated": f(p, "holm_p") < 0.05})
    claims["kept"] = [{"recipe": a, "reference": b, "share_of_iqm_gain": rows[a]["gain_iqm"] / rows[b]["gain_iqm"]}
                      for a, b in (kept or []) if a in rows and b in rows and rows[b]["gain_iqm"] != 0]
    c = agg["correlation"]
    w = c.get("within_stratified") or {}
    claims["metric"] = {"within_mean_spearman": w.get("statistic"), "within_p": w.get("p"),
                        "within_groups": w.get("groups"), "pooled_trials": c.get("trials"),
                        "pooled_treatments": c.get("treatments"),
                        "without": {k: v.get("spearman") for k, v in (c.get("trials_without") or {}).items()}}
    ratios = [rows[n]["width_ratio"] for n in names]
    claims["width_ratio"] = [min(ratios), max(ratios)] if ratios else None
    fam = {}
    for g in families:
        b = ivs[(BASE, g)]
        best = max(names, key=lambda n: f(ivs[(n, g)], "iqm"))
        fam[g] = {"base_trial_iqm": iv(b, "trial_iqm"), "best": best, "best_iqm": f(ivs[(best, g)], "iqm"),
                  "above_base": sorted(n for n in names if f(ivs[(n, g)], "trial_iqm_low") > f(b, "trial_iqm_high")),
                  "below_base": sorted(n for n in names if f(ivs[(n, g)], "trial_iqm_high") < f(b, "trial_iqm_low")),
                  "iqm": {n: f(ivs[(n, g)], "iqm") for n in [*names, BASE]}}
    level0 = {n: level0_passes(folders[n] / heldout) for n in names if n in folders}
    robust = {n: robustness(folders[n] / heldout) for n in names if n in folders}
    if base_folder is not None:
        robust[BASE] = robustness(base_folder, base=True)
    gained: dict = {}  # levels passed, each treatment's gain over the base policy with its interval
    for r in agg.get("levels", []):
        gained.setdefault(r["treatment"], {})[r["family"]] = [f(r, "gain"), f(r, "gain_low"), f(r, "gain_high")]
        gained.setdefault(BASE, {})[r["family"]] = [f(r, "base"), f(r, "base_low"), f(r, "base_high")]
    return {"suite": agg["meta"].get("suite"), "order": order, "rows": rows, "claims": claims, "families": fam,
            "level0": level0, "levels_gained": gained, "robustness": {k: v for k, v in robust.items() if v}}


def markdown(key: str, spec: dict, v1: dict, v2: dict, commands: list[str]) -> str:
    """The page's digest: v1 and v2 side by side."""
    names = [n for n in v2["order"] if n in v1["rows"]] + [n for n in v2["order"] if n not in v1["rows"]]
    L = [f"# {key}: the numbers of `{spec['page']}` on suite v2 beside v1", "",
         "Written by `docs/results/suite_v2/restate.py` from the aggregates below (intervals over trials, 95 %); "
         "every v2 figure comes from `reevaluate.py`'s evaluations. Rewrite the page from these; say where v1 and v2 "
         "disagree.", "", "Commands:", "", "```", *commands, "```", "",
         f"Suites: v1 = `{spec['v1']}` ({v1['suite'] or 'v1'}), v2 = `{spec['out']}` ({v2['suite']}).", "",
         "## Treatments", "",
         "| treatment | IQM v1 | IQM v2 | [stratified v2] | mean v1 | mean v2 | P(beats base) v1 | P(beats base) v2 "
         "| trial-IQM gain v1 / v2 | walkers above base mean v1 / v2 |", "|---|---|---|---|---|---|---|---|---|---|"]
    for n in [*names, BASE]:
        a, b = v1["rows"].get(n), v2["rows"][n]
        gain = (f"{a['gain_trial_iqm']:+.3f} / {b['gain_trial_iqm']:+.3f}" if n != BASE and a else
                f"- / {b['gain_trial_iqm']:+.3f}" if n != BASE else "-")
        above = (f"{a['walkers_above_base_mean']} of {a['walkers']} / {b['walkers_above_base_mean']} of "
                 f"{b['walkers']}" if n != BASE and a else "-")
        L.append(f"| {n}{' (one policy, ' + str(b['runs']) + ' keys)' if n == BASE else ''} | "
                 f"{fmt(a['iqm']) if a else '-'} | {fmt(b['iqm'])} | [{b['iqm_stratified'][1]:.3f}, "
                 f"{b['iqm_stratified'][2]:.3f}] | {fmt(a['mean']) if a else '-'} | {fmt(b['mean'])} | "
                 f"{fmt(a.get('p_beats_base')) if a else '-'} | {fmt(b.get('p_beats_base'))} | {gain} | {above} |")
    L += ["", "## The page's claims on each suite", "", "| claim | v1 | v2 |", "|---|---|---|"]

    def both(fn):
        return [fn(v1), fn(v2)]

    def bb(s):
        c = s["claims"]["beats_base"]
        return (f"P interval > 0.5: {c['p_interval_above_half']} of {c['treatments']}; IQM interval above the "
                f"base's: {c['iqm_interval_above_base']} of {c['treatments']}; lowest P: {c['lowest_p'][0]} "
                f"{fmt(c['lowest_p'][1])}; walkers above the base's mean: {c['walkers_above_base_mean']} of "
                f"{c['walkers']}")
    L.append("| every treatment above the base policy | " + " | ".join(both(bb)) + " |")

    def best(s):
        c = s["claims"].get("best")
        if not c:
            return "-"
        return (f"{c['treatment']} {fmt(c['iqm'])}, next {c['next']} {fmt(c['next_iqm'])}; P(best > each) >= "
                f"{c['p_over_each_min']:.2f} (lows >= {c['p_low_over_each_min']:.2f}), Holm p <= {c['holm_max']:.2g}; "
                f"its weakest walker {c['weakest_walker']:.4f} vs the best other walker {c['best_other_walker']:.4f}")
    L.append("| the best treatment | " + " | ".join(both(best)) + " |")
    pairs = {(p["x"], p["y"]): p for p in v2["claims"]["pairs"]}
    pairs1 = {(p["x"], p["y"]): p for p in v1["claims"]["pairs"]}
    for k in dict.fromkeys([*pairs1, *pairs]):
        cell = lambda p: "-" if p is None else (f"P {fmt(p['p'])}, Welch p {p['welch_p']:.2g}, Holm "  # noqa: E731
                                                f"{p['holm_p']:.2g}{' **separated**' if p['separated'] else ''}")
        L.append(f"| P({k[0]} > {k[1]}) | {cell(pairs1.get(k))} | {cell(pairs.get(k))} |")
    for k in v2["claims"]["kept"]:
        old = next((x for x in v1["claims"]["kept"] if x["recipe"] == k["recipe"]), None)
        L.append(f"| {k['recipe']}'s share of {k['reference']}'s IQM gain over the base policy | "
                 f"{'-' if old is None else format(old['share_of_iqm_gain'], '.0%')} | {k['share_of_iqm_gain']:.0%} |")

    def metric(s):
        m = s["claims"]["metric"]
        t = m["pooled_trials"] or {}
        out = (f"within-treatment mean Spearman {m['within_mean_spearman']:.2f} (stratified permutation p = "
               f"{m['within_p']:.2g}, {m['within_groups']} treatments)" if m["within_mean_spearman"] is not None else "-")
        if t:
            out += f"; pooled over {t['n']} trials {t['spearman']:.2f} (p = {t['spearman_p']:.2g})"
        if m["without"]:
            lo, hi = min(m["without"].values()), max(m["without"].values())
            out += f"; without one treatment {lo:.2f} to {hi:.2f}"
        return out
    L.append("| the paper's metric against held-out scores | " + " | ".join(both(metric)) + " |")
    L.append("| IQM interval over trials / stratified, width | " + " | ".join(
        both(lambda s: "-" if not s["claims"]["width_ratio"] else
             f"{s['claims']['width_ratio'][0]:.1f} to {s['claims']['width_ratio'][1]:.1f} times")) + " |")
    fams = list(dict.fromkeys([*v1["families"], *v2["families"]]))
    L += ["", "## Per family", "",
          "Trial-IQM intervals over trials against the base policy's; the best treatment by pooled IQM. v2's "
          "families are v1's at other (per-robot) levels and v2's generator samples are fresh draws (every draw kept), so "
          "a family's figures on the two suites measure different terrains.", "",
          "| family | base trial IQM v1 | v2 | best v1 | best v2 | above base v1 / v2 | below base v1 / v2 |",
          "|---|---|---|---|---|---|---|"]
    for g in fams:
        a, b = v1["families"].get(g), v2["families"].get(g)
        cell = lambda x, k: "-" if x is None else (fmt(x[k]) if k == "base_trial_iqm" else  # noqa: E731
                                                   f"{x['best']} {x['best_iqm']:.2f}" if k == "best" else
                                                   str(len(x[k])))
        L.append(f"| {g} | {cell(a, 'base_trial_iqm')} | {cell(b, 'base_trial_iqm')} | {cell(a, 'best')} | "
                 f"{cell(b, 'best')} | {cell(a, 'above_base')} / {cell(b, 'above_base')} | {cell(a, 'below_base')} / "
                 f"{cell(b, 'below_base')} |")
    below = {g: x["below_base"] for g, x in v2["families"].items() if x["below_base"]}
    if below:
        L += ["", "Below the base policy on v2: " + "; ".join(f"{g} ({', '.join(n)})" for g, n in below.items()) + "."]
    graded = [g for g in fams if not g.startswith("gen:") and g != "flat"]
    L += ["", "Walkers passing level 0 (mean fitness >= 0.9 there), v1 / v2:", "",
          "| treatment | " + " | ".join(graded) + " |", "|---|" + "---|" * len(graded)]
    for n in names:
        a, b = v1["level0"].get(n, {}), v2["level0"].get(n, {})
        L.append(f"| {n} | " + " | ".join(f"{a.get(g, '-')} / {b.get(g, '-')}" for g in graded) + " |")
    gained = v2.get("levels_gained") or {}
    if gained:
        L += ["", "Levels passed on v2 (the highest level passed, every level below passed too): each treatment's gain "
              "over the base policy, the mean over its trials minus the base's over its keys, with its interval over "
              "trials, base keys and the terrains of each level (`levels.csv`); the base policy's own figure last "
              "(-1: it fails level 0).", "",
              "| treatment | " + " | ".join(graded) + " |", "|---|" + "---|" * len(graded)]
        for n in [*names, BASE]:
            r = gained.get(n, {})
            L.append(f"| {n} | " + " | ".join(
                (f"{r[g][0]:+.1f} [{r[g][1]:+.1f}, {r[g][2]:+.1f}]" if n != BASE else f"{r[g][0]:.1f}") if g in r
                else "-" for g in graded) + " |")
    if v2["robustness"]:
        gens = list(dict.fromkeys(g for r in v2["robustness"].values() for g in r))
        L += ["", "## Worst decile of the generators' fresh samples (v2 only)", "",
              "CVaR at 10 % of each generator's fresh samples (the mean fitness of its worst tenth; samples: "
              + ", ".join(f"{g} {SAMPLES.get(g, '?')}" for g in gens) + "), per treatment the mean over its "
              "walkers, for the base policy over its keys.", "",
              "| treatment | " + " | ".join(gens) + " |", "|---|" + "---|" * len(gens)]
        for n in [*names, BASE]:
            r = v2["robustness"].get(n, {})
            L.append(f"| {n} | " + " | ".join(f"{r[g]:.3f}" if g in r else "-" for g in gens) + " |")
    return "\n".join(L) + "\n"


def restate(key: str, spec: dict, root: Path, base_out: Path, reps: int = 2000, permutations: int = 10000,
            run: bool = True) -> dict:
    """One page: ``generalise`` on v2 (unless ``run`` is False: the v2 aggregate exists), then the digest into
    ``root/docs/results/suite_v2/restated/<key>.md`` / ``.json``. Returns the numbers (``{"v1": ..., "v2": ...}``).
    ValueError naming what is missing (a treatment without ``heldout_v2/``, the base folder, the v1 aggregate)."""
    from experiments.__main__ import main as cli

    base = base_out / spec["robot"]
    if not any((base / n).is_file() for n in ("fitness.csv.gz", "fitness.csv")):
        raise ValueError(f"{base}: no v2 base evaluation (run reevaluate.py first)")
    v1_folders = treatment_folders(spec, root, "heldout")
    v2_folders = treatment_folders(spec, root, HELDOUT)
    missing = sorted(set(v1_folders) - set(v2_folders))
    if missing:
        raise ValueError(f"{key}: no {HELDOUT}/ yet for {', '.join(missing)} (run reevaluate.py first)")
    runs = [r.split("=", 1)[0] + "=" + str(root / r.split("=", 1)[1]) if "=" in r else str(root / r)
            for r in spec["runs"]]
    argv = ["generalise", *runs, "--heldout", HELDOUT, "--base", str(base), "--beside", f"v1={root / spec['v1']}",
            "--out", str(root / spec["out"]), "--reps", str(reps), "--permutations", str(permutations)]
    if run and cli(argv) != 0:
        raise ValueError(f"{key}: generalise failed")
    if run:  # the aggregate's text files name folders repository-relative, as the shown command does
        for f in (root / spec["out"]).glob("*"):
            if f.suffix in (".md", ".json") and str(root) + "/" in (text := f.read_text()):
                f.write_text(text.replace(str(root) + "/", ""))
    shown = ["python -m experiments " + " ".join(a.replace(str(root) + "/", "") for a in argv)]
    v1 = suite_numbers(aggregate(root / spec["v1"]), v1_folders, "heldout", spec["pairs"], spec.get("kept"), None)
    v2 = suite_numbers(aggregate(root / spec["out"]), v2_folders, HELDOUT, spec["pairs"], spec.get("kept"), base)
    out = root / "docs" / "results" / "suite_v2" / "restated"
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{key}.md").write_text(markdown(key, spec, v1, v2, shown))
    (out / f"{key}.json").write_text(json.dumps({"v1": v1, "v2": v2}, indent=1, default=float) + "\n")
    return {"v1": v1, "v2": v2}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--pages", nargs="+", default=list(PAGES), help=f"pages (default all: {', '.join(PAGES)})")
    p.add_argument("--base-out", type=Path, default=Path(BASE_OUT),
                   help=f"the v2 base evaluations' folder, as reevaluate.py --base-out (default {BASE_OUT})")
    p.add_argument("--reps", type=int, default=2000, help="bootstrap resamples (default 2000, as the pages)")
    p.add_argument("--permutations", type=int, default=10000, help="permutations (default 10000, as the pages)")
    p.add_argument("--digest-only", action="store_true", help="the v2 aggregates exist: only rewrite the digests")
    args = p.parse_args(argv)
    bad = [k for k in args.pages if k not in PAGES]
    if bad:
        p.error(f"--pages: unknown {', '.join(bad)}; choose from {', '.join(PAGES)}")
    if args.reps < 1 or args.permutations < 1:
        p.error("--reps and --permutations must be integers >= 1")
    base_out = args.base_out if args.base_out.is_absolute() else ROOT / args.base_out
    for k in args.pages:
        try:
            restate(k, PAGES[k], ROOT, base_out, args.reps, args.permutations, run=not args.digest_only)
        except ValueError as err:
            p.error(str(err))
        print(f"{k}: docs/results/suite_v2/restated/{k}.md", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
