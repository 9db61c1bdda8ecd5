"""``python -m experiments generalise RUN [RUN ...]``: Experiment 3 - do curricula make walkers that generalise?

    python -m experiments curriculum --preset gpu-short --baseline roughness random --out runs/exp3   # 8 treatments
    for T in runs/exp3/*/policies; do                                                      # each one's 10 walkers
        python -m experiments evaluate --preset gpu --policy $T/trial_* --out ${T%/policies}/heldout; done
    python -m experiments generalise runs/exp3                                             # this command (CPU)
    python -m experiments generalise runs/exp3 wide=runs/wide/cppn-map --out runs/compare     # LABEL=FOLDER

Reads every treatment of the RUN folders: a folder with ``heldout/fitness.csv`` (or ``fitness.csv.gz``: the held-out
evaluation of its walkers, as ``evaluate`` writes it, the base policy beside them) and ``summary.json`` (``learn``'s:
each trial's hardest archive cell traversed). A RUN is a ``curriculum`` run (its treatment subfolders) or one
``learn`` run. The tasks are the suite's cells (a family at a level, the mean fitness of its seeds); a treatment's
runs are its trials; the base policy's runs are its walks in each evaluation (the same policy: their spread is the
evaluation's noise, Warp's contact solver not being bit-deterministic).

Writes into ``--out`` (default ``RUN/generalisation``): ``intervals.csv`` (each treatment's interquartile mean, mean
and trial IQM over all cells and per family, with 95 % intervals: ``jaxterrain.runtime.statistics``),
``improvement.csv`` (the probability that a treatment's walker beats the base policy, and each other treatment's, on
a cell, with Welch's test on the trials and its Holm adjustment), ``trials.csv`` (each trial's hardest cell
traversed and held-out scores), ``correlation.json`` (rank correlation of the two over trials and over treatments,
the pooled one without each treatment in turn, and the permutation test stratified by treatment),
``generalisation.md`` (the tables) and the figures ``iqm.png``,
``families.png``, ``improvement.png`` and ``hardest_vs_heldout.png``.

The intervals (``docs/statistics.md``):

- **Primary: over trials.** A trial is one walker evaluated on every cell, so its cells are correlated; the
  bootstrap resamples whole trials (rows of ``[trials, cells]``, :func:`~jaxterrain.runtime.statistics.trial_estimates`,
  :func:`~jaxterrain.runtime.statistics.trial_improvement`). ``*_terrains`` columns: the two-level version, each
  cell's terrains resampled too.
- ``*_stratified`` columns: rliable's stratified bootstrap (runs resampled within each cell independently), for
  comparison with papers that report it; several times narrower than the data support here.
- **The base policy is one policy**: its runs are evaluations of the same weights (with ``--base FILE``: the K
  evaluations of ``evaluate --keys K``, one base evaluation shared by every page; without it, the base rows of each
  treatment folder's evaluation; one for a single run), so its interval holds no trial variance (``intervals.csv``'s ``note``); with
  one evaluation it has zero width. Its pooled IQM is trimmed over ``runs x cells`` values as the treatments' are,
  but those values do not spread with trials; ``trial_iqm`` (each run's IQM over the cells, averaged) trims every
  run over the same cells, and is what the per-family comparison with the base policy uses.
- Pairwise comparisons between treatments: Welch's t-test on the trials' IQMs (``welch_p``) and on their means
  (``welch_p_mean``), each Holm-adjusted over all pairs; a pair not below 0.05 after adjustment is exploratory.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path


BASE = "base policy"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("runs", nargs="+", type=labelled_path, metavar="RUN",
                        help="curriculum (or learn) run folders whose treatments have heldout/fitness.csv, or those "
                             "treatment folders; LABEL=FOLDER names a treatment LABEL (a run's: 'LABEL <treatment>')")
    parser.add_argument("--out", type=Path, default=None, help="output folder (default: RUN/generalisation)")
    parser.add_argument("--base", type=Path, default=None, metavar="FILE",
                        help="the base policy's evaluation to compare with (an evaluate run's fitness.csv[.gz], or its "
                             "folder; `evaluate --keys K` makes K runs of it), on the treatments' terrains: every "
                             "page then uses the same base evaluation (default: the base rows of each treatment's "
                             "heldout/fitness.csv, one run each)")
    parser.add_argument("--heldout", default="heldout", metavar="NAME",
                        help="the held-out evaluation folder inside each treatment (default heldout, suite v1's; "
                             "heldout_v2: suite v2's, docs/results/suite_v2/reevaluate.py)")
    parser.add_argument("--beside", type=labelled_path, default=None, metavar="[LABEL=]DIR",
                        help="another generalise output folder (e.g. the same treatments on suite v1) to set beside "
                             "this one: beside.csv and a section of generalisation.md (each treatment's IQM, mean and "
                             "P(beats base) on both, the ranks, which pairs each separates)")
    parser.add_argument("--reps", type=int, default=2000, help="bootstrap resamples per interval")
    parser.add_argument("--seed", type=int, default=0, help="seed of the bootstrap and of the permutation test")
    parser.add_argument("--permutations", type=int, default=10000,
                        help="permutations of the test of the paper's metric against held-out scores, stratified "
                             "by treatment")


class LabelledPath(type(Path())):
    """A RUN argument: the folder, and the ``LABEL`` of ``LABEL=FOLDER`` (None without one)."""

    label: str | None = None


def labelled_path(text: str) -> LabelledPath:
    """``"LABEL=FOLDER"`` or ``"FOLDER"`` (a LABEL has no ``/``; a folder whose name holds ``=`` is given with
    ``./``)."""
    label, sep, rest = text.partition("=")
    named = bool(sep and label and "/" not in label)
    path = LabelledPath(rest if named else text)
    path.label = label if named else None
    return path


def treatment_folders(runs, heldout: str = "heldout") -> list[tuple[Path, str | None]]:
    """``(folder, label)`` of every folder of ``runs`` (itself or a direct subfolder) holding a held-out evaluation
    (``<heldout>/fitness.csv[.gz]``) and a summary, sorted; the label from ``LABEL=``: LABEL for the run folder
    itself, ``"LABEL <name>"`` for its subfolders, else None (the folder's name)."""
    out = []
    for run in runs:
        label = getattr(run, "label", None)
        for d in [run, *sorted(p for p in run.iterdir() if p.is_dir())]:
            if (d / "summary.json").is_file() and any((d / heldout / f).is_file()
                                                       for f in ("fitness.csv", "fitness.csv.gz")):
                own = None if label is None else label if d == run else f"{label} {d.name.replace('-', ' ')}"
                out.append((d, own))
    return out


def load_treatment(folder: Path, label: str | None = None, heldout: str = "heldout") -> dict:
    """One treatment: its label, trials' hardest cell traversed, the held-out evaluation of ``folder/<heldout>/``
    (trials in trial order, the base policy's rows apart). A :class:`~experiments.common.UsageError` naming the file
    (and the row or field) when either file is damaged."""
    import math

    from experiments.common import UsageError
    from jaxterrain import suite

    path = folder / heldout / "fitness.csv"
    path = path if path.is_file() else path.with_suffix(".csv.gz")
    try:
        ev = suite.read_fitness(path)
    except (OSError, ValueError) as err:
        raise UsageError(str(err).splitlines()[0]) from None
    summary_path = folder / "summary.json"
    try:
        summary = json.loads(summary_path.read_text())
    except (OSError, ValueError) as err:
        raise UsageError(f"{summary_path}: not readable JSON ({type(err).__name__}: {err})") from None
    trial = lambda name: int(name.rsplit("trial_", 1)[1]) if name.rsplit("trial_", 1)[-1].isdigit() else -1  # noqa: E731
    walkers = sorted((trial(n), i) for i, n in enumerate(ev.policies) if not suite.runs.is_base(n) and trial(n) >= 0)
    if not walkers:
        raise UsageError(f"{path}: no policies/trial_K walker in it")
    hardest = summary.get("hardest") if isinstance(summary, dict) else None
    if not isinstance(hardest, list) or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                and math.isfinite(v) for v in hardest):
        raise UsageError(f"{summary_path}: field 'hardest' must be a list of finite numbers (each trial's hardest "
                         f"cell traversed); got {hardest!r}"[:300])
    if len(hardest) <= walkers[-1][0]:
        raise UsageError(f"{summary_path}: field 'hardest' has {len(hardest)} trials, but {path} holds the walker of "
                         f"trial {walkers[-1][0]}")
    return {"label": label or folder.name.replace("-", " "), "folder": folder, "family": ev.family, "level": ev.level,
            "trials": [t for t, _ in walkers], "fitness": ev.fitness[[i for _, i in walkers]],
            "hardest": [float(hardest[t]) for t, _ in walkers],
            "base": ev.fitness[[i for i, n in enumerate(ev.policies) if suite.runs.is_base(n)]]}


def load_base(path: Path, family, level) -> "np.ndarray":
    """The base policy's runs ``[K, terrains]`` from an evaluation's ``fitness.csv`` (``path`` the file or its
    folder; rows ``base``, ``base:key1``, ...: ``evaluate --keys K``), on the terrains ``family`` / ``level`` [N] of
    the treatments. UsageError naming the file when it does not read, holds no base rows or other terrains."""
    import numpy as np

    from experiments.common import UsageError
    from jaxterrain import suite

    path = Path(path)
    if path.is_dir():
        path = next((path / f for f in ("fitness.csv", "fitness.csv.gz") if (path / f).is_file()), path / "fitness.csv")
    try:
        ev = suite.read_fitness(path)
    except (OSError, ValueError) as err:
        raise UsageError(f"--base: {str(err).splitlines()[0]}") from None
    rows = [i for i, n in enumerate(ev.policies) if suite.runs.is_base(n)]
    if not rows:
        raise UsageError(f"--base {path}: no base policy rows (base, base:key1, ...) in it")
    if not (np.array_equal(ev.family, family) and np.array_equal(ev.level, level)):
        raise UsageError(f"--base {path}: evaluated on other terrains than the treatments")
    return ev.fitness[rows]


def main(args: argparse.Namespace) -> int:
    import numpy as np

    from experiments.common import UsageError
    from jaxterrain import suite
    from jaxterrain.runtime import statistics
    from jaxterrain.runtime.io import atomic_write_csv, atomic_write_text

    for run in args.runs:
        if not run.is_dir():
            raise UsageError(f"RUN {run}: no such folder")
    if args.reps < 1:
        raise UsageError(f"--reps must be an integer >= 1; got {args.reps}")
    if args.permutations < 1:
        raise UsageError(f"--permutations must be an integer >= 1; got {args.permutations}")
    heldout = getattr(args, "heldout", "heldout")
    if not heldout or "/" in heldout or heldout in (".", ".."):
        raise UsageError(f"--heldout must be a folder name inside each treatment (heldout, heldout_v2); got {heldout!r}")
    beside = getattr(args, "beside", None)
    if beside is not None and not (beside / "intervals.csv").is_file():
        raise UsageError(f"--beside {beside}: no intervals.csv in it (give a generalise output folder)")
    folders = treatment_folders(args.runs, heldout)
    if not folders:
        raise UsageError(f"no treatment with {heldout}/fitness.csv and summary.json in "
                         f"{', '.join(map(str, args.runs))}")
    ts = [load_treatment(f, label, heldout) for f, label in folders]
    seen: dict[str, Path] = {}
    for t in ts:
        if t["label"] in seen:
            raise UsageError(f"two treatments named {t['label']!r} ({seen[t['label']]}, {t['folder']}): pass the "
                             f"treatment folders you want, or name them: LABEL=FOLDER")
        seen[t["label"]] = t["folder"]
    first = ts[0]
    for t in ts[1:]:
        if not (np.array_equal(t["family"], first["family"]) and np.array_equal(t["level"], first["level"])):
            raise UsageError(f"{t['folder']}: evaluated on other terrains than {first['folder']}")
    cells, _ = suite.cell_scores(first["fitness"], first["family"], first["level"])
    terrain = {t["label"]: t["fitness"] for t in ts}                       # [trials, terrains]
    terrain[BASE] = (np.concatenate([t["base"] for t in ts]) if args.base is None   # [evaluations, terrains]
                     else load_base(args.base, first["family"], first["level"]))
    scores = {n: suite.cell_scores(f, first["family"], first["level"])[1] for n, f in terrain.items()}  # [runs, cells]
    cell_of = np.array([f"{f}|{lv}" for f, lv in zip(first["family"], first["level"])])  # [terrains]
    names = [t["label"] for t in ts] + [BASE]
    families = list(dict.fromkeys(c[0] for c in cells))
    out = args.out or args.runs[0] / "generalisation"
    out.mkdir(parents=True, exist_ok=True)

    est, two, strat = {}, {}, {}   # {scope: {name: {"iqm", "mean", ...: Interval}}}: trials, trials + terrains, rliable
    for scope in ["all", *families]:
        cols = [i for i, c in enumerate(cells) if scope == "all" or c[0] == scope]
        tcols = np.flatnonzero((first["family"] == scope) | (scope == "all"))
        est[scope] = statistics.trial_estimates({n: s[:, cols] for n, s in scores.items()}, args.reps, args.seed)
        two[scope] = statistics.trial_estimates({n: f[:, tcols] for n, f in terrain.items()}, args.reps, args.seed,
                                                cells=cell_of[tcols])
        strat[scope] = statistics.interval_estimates({n: s[:, cols] for n, s in scores.items()}, args.reps,
                                                     args.seed)
    rows = [(n, scope, scores[n].shape[0], sum(1 for c in cells if scope == "all" or c[0] == scope),
             *(f"{v:.4f}" for v in (*e[n]["iqm"], *e[n]["mean"], *e[n]["trial_iqm"], *two[scope][n]["iqm"][1:],
                                    *strat[scope][n]["iqm"][1:], *strat[scope][n]["mean"][1:])),
             NO_TRIAL_VARIANCE if n == BASE else "")
            for scope, e in est.items() for n in names]
    atomic_write_csv(out / "intervals.csv", ["treatment", "scope", "runs", "tasks", "iqm", "iqm_low", "iqm_high",
                                             "mean", "mean_low", "mean_high", "trial_iqm", "trial_iqm_low",
                                             "trial_iqm_high", "iqm_low_terrains", "iqm_high_terrains",
                                             "iqm_low_stratified", "iqm_high_stratified", "mean_low_stratified",
                                             "mean_high_stratified", "note"], rows)

    keys = [(a, BASE) for a in names[:-1]] + [(a, b) for a in names[:-1] for b in names[:-1] if a != b]
    pi = {f"{a} > {b}": statistics.trial_improvement(scores[a], scores[b], args.reps, args.seed) for a, b in keys}
    pi_strat = statistics.improvement({f"{a} > {b}": (scores[a], scores[b]) for a, b in keys}, args.reps, args.seed)
    pairs = [(a, b) for i, a in enumerate(names[:-1]) for b in names[i + 1:-1]]   # unordered treatment pairs
    test = {}
    for stat in ("iqm", "mean"):  # Welch on each trial's IQM (the pages' aggregate) and on its mean
        welch = [statistics.welch_trials(scores[a], scores[b], stat)["p"] for a, b in pairs]
        for (a, b), p, h in zip(pairs, welch, statistics.holm(welch)):
            test.setdefault(f"{a} > {b}", []).extend((p, h))
            test.setdefault(f"{b} > {a}", []).extend((p, h))
    atomic_write_csv(out / "improvement.csv", ["x", "y", "probability", "low", "high", "low_stratified",
                                               "high_stratified", "welch_p", "holm_p", "welch_p_mean",
                                               "holm_p_mean"],
                     [(*k.split(" > "), *(f"{v:.4f}" for v in (*iv, *pi_strat[k][1:])),
                       *(f"{v:.4g}" if k in test else "" for v in test.get(k, (0.0,) * 4)))
                      for k, iv in pi.items()])

    base_mean = scores[BASE].mean()
    above = {n: int(np.sum(scores[n].mean(axis=1) > base_mean)) for n in names[:-1]}
    trial_rows, hard, held, group = [], [], [], []
    for t in ts:
        s = scores[t["label"]]
        for k, trial in enumerate(t["trials"]):
            trial_rows.append((t["label"], trial, f"{t['hardest'][k]:.3f}", f"{t['fitness'][k].mean():.4f}",
                               f"{s[k].mean():.4f}", f"{statistics.iqm(s[k:k + 1]):.4f}"))
            hard.append(t["hardest"][k])
            held.append(s[k].mean())
            group.append(t["label"])
    atomic_write_csv(out / "trials.csv", ["treatment", "trial", "hardest_cell_distance", "terrain_mean",
                                          "cell_mean", "cell_iqm"], trial_rows)
    corr = {"trials": statistics.rank_correlation(hard, held)} if len(hard) >= 3 else {}
    if len(ts) >= 3:
        corr["treatments"] = statistics.rank_correlation([np.mean(t["hardest"]) for t in ts],
                                                         [scores[t["label"]].mean() for t in ts])
    corr["within"] = {t["label"]: statistics.rank_correlation(t["hardest"], scores[t["label"]].mean(axis=1))
                      for t in ts if len(t["trials"]) >= 3}
    if len(ts) >= 3:  # how much the pooled figure hangs on one treatment: it again without each in turn
        g = np.array(group)
        corr["trials_without"] = {t["label"]: statistics.rank_correlation(np.array(hard)[g != t["label"]],
                                                                          np.array(held)[g != t["label"]])
                                  for t in ts}
    corr["within_stratified"] = statistics.stratified_permutation(hard, held, group, args.permutations, args.seed)
    atomic_write_text(out / "correlation.json", json.dumps(corr, indent=2, allow_nan=True) + "\n")
    base_hi, base_lo = ({f: est[f][BASE]["trial_iqm"].high for f in families},
                        {f: est[f][BASE]["trial_iqm"].low for f in families})
    helped = {f: [n for n in names[:-1] if est[f][n]["trial_iqm"].low > base_hi[f]] for f in families}
    hurt = {f: [n for n in names[:-1] if est[f][n]["trial_iqm"].high < base_lo[f]] for f in families}
    runs = {n: s.shape[0] for n, s in scores.items()}
    text = markdown(names, runs, families, est, two, strat, pi, pi_strat, test, above, corr, helped, hurt, len(cells),
                    args)
    suite_name = evaluated_suite(first["folder"] / heldout) or heldout
    atomic_write_text(out / "meta.json", json.dumps({"suite": suite_name, "heldout": heldout, "base": None if args.base
                                                     is None else str(args.base), "cells": len(cells),
                                                     "treatments": names[:-1]}, indent=2) + "\n")
    text += levels_section(out, {t["label"]: suite.levels_passed_gain(terrain[t["label"]], terrain[BASE],
                                                                     first["family"], first["level"], args.reps,
                                                                     args.seed) for t in ts})
    if beside is not None:
        text += beside_section(out, beside, suite_name, names, est, pi, test, trial_rows)
    atomic_write_text(out / "generalisation.md", text)
    figures(out, names, families, est, strat, pi, ts, scores)
    best = max(names[:-1], key=lambda n: est["all"][n]["iqm"].point)
    iv = est["all"][best]["iqm"]
    print(f"{len(ts)} treatments, {len(cells)} cells; highest IQM: {best} {iv.point:.3f} [{iv.low:.3f}, "
          f"{iv.high:.3f}] (95 % interval over trials; base {est['all'][BASE]['iqm'].point:.3f}, "
          f"{runs[BASE]} evaluation{'s' if runs[BASE] > 1 else ''} of one policy) -> {out}", flush=True)
    return 0


def _bars(point: float, low: float, high: float) -> list[list[float]]:
    """An error bar's ``[[below], [above]]`` for matplotlib, never negative: an interval of one trial (or of equal
    values) has ``low == point == high`` up to float rounding, which matplotlib refuses."""
    return [[max(point - low, 0.0)], [max(high - point, 0.0)]]


def levels_section(out: Path, gains: dict) -> str:
    """``levels.csv`` (per treatment and family: the trials' mean highest level passed, the base policy's, and the
    gain, each with its interval over trials, base keys and terrains: ``suite.levels_passed_gain``) and the section of
    ``generalisation.md`` that shows the gains (a family's levels passed: level 0 up to the highest with every level
    below passed, mean fitness >= 0.9)."""
    from jaxterrain.runtime.io import atomic_write_csv

    names = list(gains)
    families = list(next(iter(gains.values())))
    atomic_write_csv(out / "levels.csv", ["treatment", "family", "walkers", "walkers_low", "walkers_high", "base",
                                          "base_low", "base_high", "gain", "gain_low", "gain_high"],
                     [(n, f, *(f"{v:.3f}" for k in ("walkers", "base", "gain") for v in gains[n][f][k]))
                      for n in names for f in families])
    lines = ["", "## Levels passed", "",
             "Highest level passed per family (every level below passed; a level passes at mean fitness >= 0.9; -1: "
             "level 0 fails): each treatment's gain over the base policy in levels, the mean over its trials minus "
             "the base's over its evaluations, with a 95 % interval over trials, base evaluations and the terrains "
             "of each level (`levels.csv` has both means). **Bold**: the interval clears 0.", "",
             "| family | base | " + " | ".join(names) + " |", "|---|---|" + "---|" * len(names)]
    for f in families:
        b = gains[names[0]][f]["base"]
        cells = []
        for n in names:
            g = gains[n][f]["gain"]
            txt = f"{g.point:+.1f} [{g.low:+.1f}, {g.high:+.1f}]"
            cells.append(f"**{txt}**" if g.low > 0 or g.high < 0 else txt)
        lines.append(f"| {f} | {b.point:.1f} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def evaluated_suite(folder: Path) -> str | None:
    """The suite an ``evaluate`` folder walked, from its ``config.json`` (``v1``; ``v2:<robot>`` for a per-robot
    version), or None where it does not say."""
    try:
        cfg = json.loads((folder / "config.json").read_text())
    except (OSError, ValueError):
        return None
    name = cfg.get("suite") if isinstance(cfg, dict) else None
    if not isinstance(name, str) or cfg.get("archive") or cfg.get("terrain_folder"):
        return None
    return f"{name}:{cfg.get('robot') or 'humanoid'}" if name != "v1" else name


SEPARATED = 0.05
"""A pair of treatments is separated when Welch's test on the trials' IQMs, Holm-adjusted over all pairs, is below
this."""


def beside_section(out: Path, beside: Path, here: str, names, est, pi, test, trial_rows) -> str:
    """``beside.csv`` (each treatment on this run's suite and on ``beside``'s: IQM, mean, trial IQM and
    P(beats base policy) with their intervals over trials, rank by IQM), ``beside.png`` and the section of
    ``generalisation.md`` that compares the two: how the treatments' ranks agree (Spearman, Kendall over
    treatments), how each trial's cell mean agrees (Spearman over trials), which pairs each separates (Holm-adjusted
    Welch p < :data:`SEPARATED`) and whether the other agrees. ``beside``: a generalise output folder (its
    ``intervals.csv``, ``improvement.csv``, ``trials.csv``; ``meta.json`` names its suite)."""
    import csv

    import numpy as np
    from matplotlib.figure import Figure

    from experiments.common import UsageError
    from jaxterrain.runtime import statistics
    from jaxterrain.runtime.io import atomic_write_csv, save_figure

    try:
        meta = json.loads((beside / "meta.json").read_text()) if (beside / "meta.json").is_file() else {}
        there = getattr(beside, "label", None) or meta.get("suite") or "beside"
        iv = {r["treatment"]: r for r in csv.DictReader((beside / "intervals.csv").open()) if r["scope"] == "all"}
        imp = ({(r["x"], r["y"]): r for r in csv.DictReader((beside / "improvement.csv").open())}
               if (beside / "improvement.csv").is_file() else {})
        tr = ({(r["treatment"], r["trial"]): float(r["cell_mean"]) for r in csv.DictReader((beside / "trials.csv").open())}
              if (beside / "trials.csv").is_file() else {})
        num = lambda r, k: float(r[k]) if r.get(k) not in (None, "") else float("nan")  # noqa: E731
    except (OSError, KeyError, ValueError) as err:
        raise UsageError(f"--beside {beside}: not a generalise output ({type(err).__name__}: {err})") from None
    if here == there:
        here, there = f"{here} (here)", f"{there} (beside)"
    common = [n for n in names if n in iv]
    if not common:
        raise UsageError(f"--beside {beside}: none of these treatments is in it ({', '.join(names[:-1])})")
    walkers = [n for n in common if n != BASE]
    rank_here = {n: k + 1 for k, n in enumerate(sorted(walkers, key=lambda n: -est["all"][n]["iqm"].point))}
    rank_there = {n: k + 1 for k, n in enumerate(sorted(walkers, key=lambda n: -num(iv[n], "iqm")))}
    rows = []
    for n in common:
        e, r = est["all"][n], iv[n]
        p_here = pi.get(f"{n} > {BASE}")
        p_there = imp.get((n, BASE))
        rows.append((n, *(f"{v:.4f}" for v in (*e["iqm"], num(r, "iqm"), num(r, "iqm_low"), num(r, "iqm_high"),
                                                e["mean"].point, num(r, "mean"), e["trial_iqm"].point,
                                                num(r, "trial_iqm"))),
                     *(f"{v:.4f}" for v in ((*p_here,) if p_here else (np.nan,) * 3)),
                     *((f"{num(p_there, k):.4f}" for k in ("probability", "low", "high")) if p_there else ("",) * 3),
                     rank_here.get(n, ""), rank_there.get(n, "")))
    atomic_write_csv(out / "beside.csv", ["treatment", "iqm", "iqm_low", "iqm_high", "iqm_beside", "iqm_low_beside",
                                          "iqm_high_beside", "mean", "mean_beside", "trial_iqm", "trial_iqm_beside",
                                          "p_beats_base", "p_beats_base_low", "p_beats_base_high",
                                          "p_beats_base_beside", "p_beats_base_low_beside",
                                          "p_beats_base_high_beside", "rank", "rank_beside"], rows)
    lines = ["", f"## Beside {there} (`{beside}`)", "",
             f"The same treatments on {here} (this page) and on {there}; intervals over trials (95 %). Ranks by IQM "
             "among the treatments in both.", "",
             f"| treatment | IQM {here} | IQM {there} | mean {here} | mean {there} | P(beats base) {here} | "
             f"P(beats base) {there} | rank {here} | rank {there} |", "|---|---|---|---|---|---|---|---|---|"]
    for n in common:
        r = iv[n]
        p_here, p_there = pi.get(f"{n} > {BASE}"), imp.get((n, BASE))
        lines.append(f"| {n} | {_iv(est['all'][n]['iqm'])} | {num(r, 'iqm'):.3f} [{num(r, 'iqm_low'):.3f}, "
                     f"{num(r, 'iqm_high'):.3f}] | {est['all'][n]['mean'].point:.3f} | {num(r, 'mean'):.3f} | "
                     + (_iv(p_here) if p_here else "-") + " | "
                     + (f"{num(p_there, 'probability'):.3f} [{num(p_there, 'low'):.3f}, {num(p_there, 'high'):.3f}]"
                        if p_there else "-") + f" | {rank_here.get(n, '-')} | {rank_there.get(n, '-')} |")
    missing = [n for n in names if n not in iv]
    if missing:
        lines += ["", f"Not in {there}: {', '.join(missing)}."]
    lines.append("")
    if len(walkers) >= 3:
        c = statistics.rank_correlation([est["all"][n]["iqm"].point for n in walkers], [num(iv[n], "iqm") for n in walkers])
        lines.append(f"- Treatments' IQMs, {here} against {there} (n = {c['n']}): Spearman {c['spearman']:.2f} "
                     f"(p = {c['spearman_p']:.3g}), Kendall {c['kendall']:.2f} (p = {c['kendall_p']:.3g}).")
    pairs = [(str(t), str(k), float(m)) for t, k, _, _, m, *_ in trial_rows if (str(t), str(k)) in tr]
    if len(pairs) >= 3:
        c = statistics.rank_correlation([m for *_, m in pairs], [tr[(t, k)] for t, k, _ in pairs])
        lines.append(f"- Each trial's cell mean, {here} against {there} (n = {c['n']} walkers): Spearman "
                     f"{c['spearman']:.2f} (p = {c['spearman_p']:.3g}).")
    beats = lambda lo: lo > 0.5  # noqa: E731
    b_here = [n for n in walkers if pi.get(f"{n} > {BASE}") and beats(pi[f"{n} > {BASE}"].low)]
    b_there = [n for n in walkers if imp.get((n, BASE)) and beats(num(imp[(n, BASE)], "low"))]
    lines.append(f"- Treatments whose P(beats base policy) interval lies above 0.5: {len(b_here)} of {len(walkers)} "
                 f"on {here}, {len(b_there)} of {len(walkers)} on {there}"
                 + (f"; on one only: {', '.join(sorted(set(b_here) ^ set(b_there)))}" if set(b_here) ^ set(b_there)
                    else "") + ".")
    verdict = {}
    for i, a in enumerate(walkers):
        for b in walkers[i + 1:]:
            h = test.get(f"{a} > {b}")
            t = imp.get((a, b))
            if h is None or t is None or t.get("holm_p") in (None, ""):
                continue
            sep_h = pi[f"{a} > {b}"].point - 0.5 if h[1] < SEPARATED else 0.0
            sep_t = num(t, "probability") - 0.5 if num(t, "holm_p") < SEPARATED else 0.0
            key = ("both" if sep_h * sep_t > 0 else "reversed" if sep_h * sep_t < 0 else
                   "here" if sep_h else "there" if sep_t else "neither")
            winner = (a, b) if (sep_h or sep_t) >= 0 else (b, a)
            verdict.setdefault(key, []).append(f"{winner[0]} > {winner[1]}" if key != "neither" else f"{a} / {b}")
    if verdict:
        n_pairs = sum(map(len, verdict.values()))
        lines.append(f"- Pairs of treatments (Welch on the trials' IQMs, Holm-adjusted p < {SEPARATED:g} on each page's "
                     f"own pairs), {n_pairs} in both: separated on both, the same way: {len(verdict.get('both', []))}; "
                     f"on {here} only: {len(verdict.get('here', []))}; on {there} only: "
                     f"{len(verdict.get('there', []))}; reversed: {len(verdict.get('reversed', []))}; on neither: "
                     f"{len(verdict.get('neither', []))}.")
        for key, said in (("here", f"on {here} only"), ("there", f"on {there} only"),
                          ("reversed", f"reversed (as {here} has them)")):
            if verdict.get(key):
                lines.append(f"  - {said}: " + "; ".join(verdict[key]))
    fig = Figure(figsize=(5.0, 4.5))
    ax = fig.subplots()
    for n in common:
        e, r = est["all"][n]["iqm"], iv[n]
        x, y = num(r, "iqm"), e.point
        ax.errorbar(x, y, xerr=_bars(x, num(r, "iqm_low"), num(r, "iqm_high")),
                    yerr=_bars(y, e.low, e.high), fmt="o", capsize=2, color="grey" if n == BASE else None)
        ax.annotate(n, (x, y), fontsize=6, xytext=(3, 3), textcoords="offset points")
    ax.set_xlabel(f"IQM on {there} (95 % CI over trials)")
    ax.set_ylabel(f"IQM on {here} (95 % CI over trials)")
    ax.set_title("Held-out IQM per treatment on both suites", fontsize=9)
    fig.tight_layout()
    save_figure(fig, out / "beside.png")
    lines += ["", "![IQM on both suites](beside.png)", ""]
    return "\n".join(lines)


NO_TRIAL_VARIANCE = "one policy: its runs are evaluations of the same weights, so its interval holds no trial variance"


def _iv(iv) -> str:
    return f"{iv.point:.3f} [{iv.low:.3f}, {iv.high:.3f}]"


def _ci(iv) -> str:
    return f"[{iv.low:.3f}, {iv.high:.3f}]"


def markdown(names, runs, families, est, two, strat, pi, pi_strat, test, above, corr, helped, hurt, cells: int,
             args) -> str:
    base = names[-1]
    nb = runs[base]
    lines = [f"# Held-out scores ({cells} suite cells; 95 % intervals, {args.reps} resamples, seed {args.seed})", "",
             "Primary intervals resample whole trials (each walker with all its cells: "
             "`statistics.trial_estimates`); *terrains* also resamples each cell's terrains (two-level); "
             "*stratified* is rliable's stratified bootstrap (runs resampled within each cell as if cells were "
             "independent: too narrow when a trial's cells are correlated; for comparison with papers that use "
             "it). *Trial IQM*: each trial's IQM over the cells, averaged (every run trimmed over the same "
             f"{cells} values); compare with the base policy on it.", "",
             f"**The {base} is one policy**: its {nb} run{'s are evaluations' if nb > 1 else ' is one evaluation'} "
             + (f"(`{args.base}`, independent keys) " if getattr(args, "base", None) else "")
             + "of the same weights, so its interval holds no trial variance (only the evaluation's noise"
             + ("" if nb > 1 else ": none with one evaluation, an interval of zero width") + ").", "",
             "| treatment | runs | IQM [over trials] | IQM [terrains too] | IQM [stratified] | mean [over trials] | "
             "trial IQM [over trials] | P(beats base policy) [over trials] | trials above base mean |",
             "|---|---|---|---|---|---|---|---|---|"]
    for n in names:
        e = est["all"][n]
        p = "-" if n == base else _iv(pi[f"{n} > {base}"])
        k = "-" if n == base else f"{above[n]} of {runs[n]}"
        lines.append(f"| {n}{' (one policy)' if n == base else ''} | {runs[n]} | {_iv(e['iqm'])} | "
                     f"{_ci(two['all'][n]['iqm'])} | {_ci(strat['all'][n]['iqm'])} | {_iv(e['mean'])} | "
                     f"{_iv(e['trial_iqm'])} | {p} | {k} |")
    lines += ["", "IQM per family (cells of the family as tasks; pooled IQM):", "",
              "| treatment | " + " | ".join(families) + " |", "|---|" + "---|" * len(families)]
    for n in names:
        lines.append(f"| {n} | " + " | ".join(f"{est[f][n]['iqm'].point:.2f}" for f in families) + " |")
    nobody = [f for f, who in helped.items() if not who]
    lines += ["", "Families where a treatment's trial-IQM interval (over trials) lies above the base policy's: "
              + ("; ".join(f"{f} ({', '.join(who)})" for f, who in helped.items() if who) or "none") + ".",
              "Families no treatment improves on (intervals overlap the base policy's, or lie below it): "
              + (", ".join(nobody) or "none") + ".",
              "Families where a treatment's trial-IQM interval lies below the base policy's: "
              + ("; ".join(f"{f} ({', '.join(who)})" for f, who in hurt.items() if who) or "none") + ".", ""]
    if len(names) > 2:
        lines += ["Probability of improvement between treatments (row beats column on a cell; point estimates):", "",
                  "| X \\ Y | " + " | ".join(names[:-1]) + " |", "|---|" + "---|" * (len(names) - 1)]
        for a in names[:-1]:
            lines.append(f"| {a} | " + " | ".join("-" if a == b else f"{pi[f'{a} > {b}'].point:.2f}"
                                                 for b in names[:-1]) + " |")
        m = len(names[:-1]) * (len(names) - 2) // 2
        lines += ["", f"Pairwise comparisons ({m} pairs): P(X > Y) with its interval over trials and the "
                  "stratified one; Welch's t-test on the trials' IQMs (each trial's IQM over the cells) and on their "
                  f"means, each Holm-adjusted over the {m} pairs. A pair whose Holm-adjusted p is above 0.05 is "
                  "exploratory: the trials do not separate the two.", "",
                  "| X | Y | P(X > Y) [over trials] | [stratified] | Welch p (IQM) | Holm | Welch p (mean) | Holm |",
                  "|---|---|---|---|---|---|---|---|"]
        for i, a in enumerate(names[:-1]):
            for b in names[i + 1:-1]:
                a_, b_ = (a, b) if pi[f"{a} > {b}"].point >= 0.5 else (b, a)
                k = f"{a_} > {b_}"
                lines.append(f"| {a_} | {b_} | {_iv(pi[k])} | {_ci(pi_strat[k])} | "
                             + " | ".join(f"{v:.3g}" for v in test[k]) + " |")
    lines += ["", "Rank correlation of the hardest archive cell traversed (the paper's metric, each on its own "
              "archive) with the held-out cell mean:", ""]
    for scope, c in corr.items():
        if scope in ("within", "within_stratified", "trials_without"):
            continue
        lines.append(f"- over {scope} (n = {c['n']}, pooled): Spearman {c['spearman']:.2f} "
                     f"(p = {c['spearman_p']:.3g}), Kendall {c['kendall']:.2f} (p = {c['kendall_p']:.3g})")
    for label, c in corr.get("within", {}).items():
        lines.append(f"- within {label} (n = {c['n']}): Spearman {c['spearman']:.2f}")
    if corr.get("trials_without"):
        lines.append("- over trials without one treatment (pooled; how much the figure hangs on one): "
                     + "; ".join(f"without {k} {c['spearman']:.2f} (p = {c['spearman_p']:.2g})"
                                 for k, c in corr["trials_without"].items()))
    w = corr.get("within_stratified")
    if w and w["groups"]:
        lines.append(f"- mean within-treatment Spearman over {w['groups']} treatment{'s' * (w['groups'] != 1)}: "
                     f"{w['statistic']:.2f}, "
                     f"p = {w['p']:.3g} (permutation test stratified by treatment, {w['reps']} permutations: the "
                     "held-out scores shuffled within each treatment)")
    return "\n".join(lines) + "\n"


def figures(out: Path, names, families, est, strat, pi, ts, scores) -> None:
    import numpy as np
    from matplotlib.figure import Figure

    from jaxterrain.runtime.io import save_figure

    fig = Figure(figsize=(6.5, 0.45 * len(names) + 1.2))
    ax = fig.subplots()
    for i, n in enumerate(names):
        for iv, dy, style in ((est["all"][n]["iqm"], 0.0, dict(fmt="o", capsize=3)),
                              (strat["all"][n]["iqm"], 0.25, dict(fmt="none", capsize=2, lw=0.8))):
            ax.errorbar(iv.point, i + dy, xerr=_bars(iv.point, iv.low, iv.high),
                        color="grey" if n == names[-1] else ("C0" if dy == 0 else "C1"), **style)
    ax.axvline(est["all"][names[-1]]["iqm"].point, color="grey", lw=0.8, ls="--")
    ax.set_yticks(range(len(names)), names, fontsize=8)
    ax.set_xlabel("IQM of held-out cell fitness (95 % CI: over trials; thin, above: stratified)")
    ax.set_title("Held-out suite: interquartile mean per treatment", fontsize=9)
    fig.tight_layout()
    save_figure(fig, out / "iqm.png")

    grid = np.array([[est[f][n]["iqm"].point for f in families] for n in names])
    fig = Figure(figsize=(max(6.0, 2.5 + 0.5 * len(families)), 0.4 * len(names) + 2.0))
    ax = fig.subplots()
    im = ax.imshow(grid - grid[-1:], cmap="RdBu", vmin=-0.2, vmax=0.2, aspect="auto")
    for (i, j), v in np.ndenumerate(grid):
        ax.text(j, i, f"{v:.2f}", ha="center", va="center", fontsize=6)
    ax.set_xticks(range(len(families)), families, rotation=60, ha="right", fontsize=7)
    ax.set_yticks(range(len(names)), names, fontsize=7)
    ax.set_title("IQM per family (text); colour: difference from the base policy", fontsize=9)
    fig.colorbar(im, ax=ax)
    fig.tight_layout()
    save_figure(fig, out / "families.png")

    fig = Figure(figsize=(6.5, 0.45 * len(names) + 1.0))
    ax = fig.subplots()
    for i, n in enumerate(names[:-1]):
        iv = pi[f"{n} > {names[-1]}"]
        ax.errorbar(iv.point, i, xerr=_bars(iv.point, iv.low, iv.high), fmt="o", capsize=3)
    ax.axvline(0.5, color="grey", lw=0.8, ls="--")
    ax.set_yticks(range(len(names) - 1), names[:-1], fontsize=8)
    ax.set_xlabel("P(a trial's walker beats the base policy on a cell) (95 % CI over trials)")
    fig.tight_layout()
    save_figure(fig, out / "improvement.png")

    fig = Figure(figsize=(6.0, 4.0))
    ax = fig.subplots()
    for t in ts:
        ax.scatter(t["hardest"], scores[t["label"]].mean(axis=1), s=14, label=t["label"])
    ax.axhline(scores[names[-1]].mean(), color="grey", lw=0.8, ls="--", label=names[-1])
    ax.set_xlabel("hardest archive cell traversed (distance from cell (0, 0), own archive)")
    ax.set_ylabel("held-out cell mean fitness")
    ax.legend(fontsize=6)
    fig.tight_layout()
    save_figure(fig, out / "hardest_vs_heldout.png")
