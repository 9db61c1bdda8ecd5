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

Writes into ``--out`` (default ``RUN/generalisation``): ``intervals.csv`` (each treatment's interquartile mean and
mean over all cells and per family, with 95 % stratified-bootstrap intervals: ``jaxterrain.runtime.statistics``,
rliable), ``improvement.csv`` (the probability that a treatment's walker beats the base policy, and each other
treatment's, on a cell), ``trials.csv`` (each trial's hardest cell traversed and held-out scores),
``correlation.json`` (rank correlation of the two over trials and over treatments), ``generalisation.md`` (the
tables) and the figures ``iqm.png``, ``families.png``, ``improvement.png`` and ``hardest_vs_heldout.png``.
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
    parser.add_argument("--reps", type=int, default=2000, help="bootstrap resamples per interval")
    parser.add_argument("--seed", type=int, default=0, help="seed of the bootstrap")


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


def treatment_folders(runs) -> list[tuple[Path, str | None]]:
    """``(folder, label)`` of every folder of ``runs`` (itself or a direct subfolder) holding a held-out evaluation
    and a summary, sorted; the label from ``LABEL=``: LABEL for the run folder itself, ``"LABEL <name>"`` for its
    subfolders, else None (the folder's name)."""
    out = []
    for run in runs:
        label = getattr(run, "label", None)
        for d in [run, *sorted(p for p in run.iterdir() if p.is_dir())]:
            if (d / "summary.json").is_file() and any((d / "heldout" / f).is_file()
                                                       for f in ("fitness.csv", "fitness.csv.gz")):
                own = None if label is None else label if d == run else f"{label} {d.name.replace('-', ' ')}"
                out.append((d, own))
    return out


def load_treatment(folder: Path, label: str | None = None) -> dict:
    """One treatment: its label, trials' hardest cell traversed, the held-out evaluation (trials in trial order, the
    base policy's rows apart). A :class:`~experiments.common.UsageError` naming the file (and the row or field) when
    either file is damaged."""
    import math

    from experiments.common import UsageError
    from jaxterrain import suite

    path = folder / "heldout" / "fitness.csv"
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
    walkers = sorted((trial(n), i) for i, n in enumerate(ev.policies) if n != "base" and trial(n) >= 0)
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
            "base": ev.fitness[[i for i, n in enumerate(ev.policies) if n == "base"]]}


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
    folders = treatment_folders(args.runs)
    if not folders:
        raise UsageError(f"no treatment with heldout/fitness.csv and summary.json in {', '.join(map(str, args.runs))}")
    ts = [load_treatment(f, label) for f, label in folders]
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
    scores = {t["label"]: suite.cell_scores(t["fitness"], t["family"], t["level"])[1] for t in ts}
    scores[BASE] = suite.cell_scores(np.concatenate([t["base"] for t in ts]), first["family"], first["level"])[1]
    names = [t["label"] for t in ts] + [BASE]
    families = list(dict.fromkeys(c[0] for c in cells))
    out = args.out or args.runs[0] / "generalisation"
    out.mkdir(parents=True, exist_ok=True)

    est = {"all": statistics.interval_estimates(scores, args.reps, args.seed)}
    for fam in families:
        cols = [i for i, c in enumerate(cells) if c[0] == fam]
        est[fam] = statistics.interval_estimates({n: s[:, cols] for n, s in scores.items()}, args.reps, args.seed)
    rows = [(n, scope, scores[n].shape[0], sum(1 for c in cells if scope == "all" or c[0] == scope),
             *(f"{v:.4f}" for v in (*e[n]["iqm"], *e[n]["mean"]))) for scope, e in est.items() for n in names]
    atomic_write_csv(out / "intervals.csv", ["treatment", "scope", "runs", "tasks", "iqm", "iqm_low", "iqm_high",
                                             "mean", "mean_low", "mean_high"], rows)
    pairs = {f"{a} > {BASE}": (scores[a], scores[BASE]) for a in names[:-1]}
    pairs.update({f"{a} > {b}": (scores[a], scores[b]) for a in names[:-1] for b in names[:-1] if a != b})
    pi = statistics.improvement(pairs, args.reps, args.seed)
    atomic_write_csv(out / "improvement.csv", ["x", "y", "probability", "low", "high"],
                     [(*k.split(" > "), *(f"{v:.4f}" for v in iv)) for k, iv in pi.items()])

    trial_rows, hard, held = [], [], []
    for t in ts:
        s = scores[t["label"]]
        for k, trial in enumerate(t["trials"]):
            trial_rows.append((t["label"], trial, f"{t['hardest'][k]:.3f}", f"{t['fitness'][k].mean():.4f}",
                               f"{s[k].mean():.4f}", f"{statistics.iqm(s[k:k + 1]):.4f}"))
            hard.append(t["hardest"][k])
            held.append(s[k].mean())
    atomic_write_csv(out / "trials.csv", ["treatment", "trial", "hardest_cell_distance", "terrain_mean",
                                          "cell_mean", "cell_iqm"], trial_rows)
    corr = {"trials": statistics.rank_correlation(hard, held)} if len(hard) >= 3 else {}
    if len(ts) >= 3:
        corr["treatments"] = statistics.rank_correlation([np.mean(t["hardest"]) for t in ts],
                                                         [scores[t["label"]].mean() for t in ts])
    corr["within"] = {t["label"]: statistics.rank_correlation(t["hardest"], scores[t["label"]].mean(axis=1))
                      for t in ts if len(t["trials"]) >= 3}
    atomic_write_text(out / "correlation.json", json.dumps(corr, indent=2, allow_nan=True) + "\n")
    helped = {fam: [n for n in names[:-1] if est[fam][n]["iqm"].low > est[fam][BASE]["iqm"].high] for fam in families}
    atomic_write_text(out / "generalisation.md", markdown(names, {n: s.shape[0] for n, s in scores.items()}, families, est, pi, corr, helped,
                                                                 len(cells), args))
    figures(out, names, families, est, pi, ts, scores)
    best = max(names[:-1], key=lambda n: est["all"][n]["iqm"].point)
    print(f"{len(ts)} treatments, {len(cells)} cells; highest IQM: {best} "
          f"{est['all'][best]['iqm'].point:.3f} (base {est['all'][BASE]['iqm'].point:.3f}) -> {out}", flush=True)
    return 0


def _iv(iv) -> str:
    return f"{iv.point:.3f} [{iv.low:.3f}, {iv.high:.3f}]"


def markdown(names, runs, families, est, pi, corr, helped, cells: int, args) -> str:
    lines = [f"# Experiment 3: held-out scores ({cells} suite cells; 95 % stratified-bootstrap intervals, "
             f"{args.reps} resamples, seed {args.seed})", "",
             "| treatment | runs | IQM | mean | P(beats base policy) |", "|---|---|---|---|---|"]
    for n in names:
        p = "-" if n == BASE else _iv(pi[f"{n} > {BASE}"])
        lines.append(f"| {n} | {runs[n]} | {_iv(est['all'][n]['iqm'])} | {_iv(est['all'][n]['mean'])} | {p} |")
    lines += ["", "IQM per family (cells of the family as tasks):", "",
              "| treatment | " + " | ".join(families) + " |", "|---|" + "---|" * len(families)]
    for n in names:
        lines.append(f"| {n} | " + " | ".join(f"{est[f][n]['iqm'].point:.2f}" for f in families) + " |")
    nobody = [f for f, who in helped.items() if not who]
    lines += ["", "Families where some treatment's IQM interval lies above the base policy's: "
              + ("; ".join(f"{f} ({', '.join(who)})" for f, who in helped.items() if who) or "none") + ".",
              "Families no treatment improves on (intervals overlap the base policy's): "
              + (", ".join(nobody) or "none") + ".", "",
              "Probability of improvement between treatments (row beats column on a cell):", "",
              "| X \\ Y | " + " | ".join(names[:-1]) + " |", "|---|" + "---|" * (len(names) - 1)]
    for a in names[:-1]:
        lines.append(f"| {a} | " + " | ".join("-" if a == b else f"{pi[f'{a} > {b}'].point:.2f}"
                                             for b in names[:-1]) + " |")
    lines += ["", "Rank correlation of the hardest archive cell traversed (the paper's metric, each on its own "
              "archive) with the held-out cell mean:", ""]
    for scope, c in corr.items():
        if scope == "within":
            continue
        lines.append(f"- over {scope} (n = {c['n']}): Spearman {c['spearman']:.2f} (p = {c['spearman_p']:.3g}), "
                     f"Kendall {c['kendall']:.2f} (p = {c['kendall_p']:.3g})")
    for label, c in corr.get("within", {}).items():
        lines.append(f"- within {label} (n = {c['n']}): Spearman {c['spearman']:.2f}")
    return "\n".join(lines) + "\n"


def figures(out: Path, names, families, est, pi, ts, scores) -> None:
    import numpy as np
    from matplotlib.figure import Figure

    from jaxterrain.runtime.io import save_figure

    fig = Figure(figsize=(6.5, 0.45 * len(names) + 1.2))
    ax = fig.subplots()
    for i, n in enumerate(names):
        iv = est["all"][n]["iqm"]
        ax.errorbar(iv.point, i, xerr=[[iv.point - iv.low], [iv.high - iv.point]], fmt="o",
                    color="grey" if n == names[-1] else "C0", capsize=3)
    ax.axvline(est["all"][names[-1]]["iqm"].point, color="grey", lw=0.8, ls="--")
    ax.set_yticks(range(len(names)), names, fontsize=8)
    ax.set_xlabel("IQM of held-out cell fitness (95 % CI)")
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
        ax.errorbar(iv.point, i, xerr=[[iv.point - iv.low], [iv.high - iv.point]], fmt="o", capsize=3)
    ax.axvline(0.5, color="grey", lw=0.8, ls="--")
    ax.set_yticks(range(len(names) - 1), names[:-1], fontsize=8)
    ax.set_xlabel("P(a trial's walker beats the base policy on a cell) (95 % CI)")
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
