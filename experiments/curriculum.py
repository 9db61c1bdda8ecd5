"""``python -m experiments curriculum``: Experiment 2 whole - Figure 7a / 7b and Table 2 with the paper's numbers.

    python -m experiments curriculum --preset gpu-short --out runs/exp2 --time-limit 9     # all five generators
    python -m experiments curriculum --resume runs/exp2 --time-limit 9            # until it says "done"
    python -m experiments curriculum --preset gpu-short --archives cppn=A.npz perlin=B.npz ...   # other archives

Treatments (each one ``learn`` run, ``--trials`` trials together, in ``<run>/<name>-<curriculum>/``): the map
curriculum on every archive given (``NAME=PATH``; names as in the paper's Table 2: cppn, gan, perlin, worley,
diamond_square; by default :data:`DEFAULT_ARCHIVES`, the five shipped paper-budget roughness x TPI archives reseated
under ``difficulty.HEADINGS``, docs/results/exp2_paper.md), on their combination (``qd.combine``: the fitter
elite per cell; ``<run>/combined_archive.npz``; skipped with one archive or ``--no-combined``), and each
``--baseline`` on the ``--baseline-archive`` (one of ``--archives``' names, default ``cppn``; default baseline the
roughness-sorted standard CL of Figure 7b; ``--baseline roughness random`` adds the random order, Experiment 3's eight
treatments). Experiment 4 runs the field's curricula on the mixed archive:
``--archives steps=S.npz mixed=M.npz --baseline dr plr levels --baseline-archive mixed --no-combined`` (the map on
each archive, then ``mixed-dr``, ``mixed-plr``, ``mixed-levels``). Finished treatments are kept, so ``--resume``
continues where the time limit stopped. ``--shard I/N`` runs only process I's share, so that independent processes
(e.g. one per GPU: ``CUDA_VISIBLE_DEVICES=I ... --out RUN --shard I/N``) share one run folder: whole populations,
balanced (``batch.shard_groups``; Experiment 4's five over two: the two map treatments and terrain levels, then DR
and PLR), or ``t % N == I`` of that order with ``--no-batch-treatments``; ``--resume RUN`` without
``--shard`` then reuses the finished treatments and writes the tables. ``--resume RUN --report`` writes the tables
and figures from the treatments as they stand, the unfinished ones from their last checkpoint (``learn --report``;
marked ``[partial: E epochs]``), without training: e.g. before a GPU machine is given back.

Treatments run as populations (``jaxterrain.curriculum.batch``): those that share a walker and the harness's work
(the map curriculum on every archive; with it roughness and random, one terrain a chunk each) run their trials
together in ONE compiled program, each treatment with its own archive, selector and keys, and each treatment's
folder gets the files its run alone writes (on a CPU bit for bit; docs/tutorials/curriculum.md). One line per
population says which treatments share a program. ``--population-envs N`` caps the envs stepped together in one
program (default 131 072; a program that does not fit in the device's memory is split in two, said in one line);
``--block-seconds S`` the time between checkpoints; ``--no-batch-treatments`` runs them one after another, as
before (``--devices`` over several devices does too). A killed population resumes each treatment from its own
checkpoint.

Writes ``figure7a.png`` (hardest terrain traversed vs epoch, every map treatment, mean +- 1 standard error),
``figure7b.png`` (CPPN: map vs standard CL), ``table2.csv`` / ``table2.md`` (epochs to first traverse a terrain at
5 %, ..., 50 % of 70.71, ours beside the paper's), ``hardest.csv`` / ``hardest.md`` (each treatment's hardest
terrain traversed: mean +- s.e. beside intervals over trials of the mean and the IQM, and the probability that one
treatment's trial went further than another's), ``sequences.csv`` (every trial's terrains in order, all
treatments) and ``config.json``. Presets: those of ``learn`` (smoke, gpu-short, paper). ``--backend auto|jax|warp``: the
walker's physics of every treatment (``learn``'s flag; saved in ``config.json``, kept by ``--resume``).
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import shutil
import sys
import time
from pathlib import Path

from experiments import cli_gen, common
from experiments import learn

DEFAULT_ARCHIVES = {g: common.shipped(f"archives/{g}_headings.npz")
                    for g in ("cppn", "perlin", "worley", "diamond_square", "gan")}
"""The archives of Experiment 2 when ``--archives`` is not given: each generator's paper-budget roughness x TPI
archive (evolved after the fix of tied insertion), reseated under ``difficulty.HEADINGS``; package data
(``jaxterrain/assets/archives/G_headings.npz``, copies of ``docs/results/exp2_G_headings_archive.npz``)."""
BASELINES = tuple(name for name in common.SELECTOR_NAMES if name != "map")
"""The curricula of ``--baseline`` (``jaxterrain.curriculum.CurriculumConfig.selector``'s other than ``map``)."""
DEFAULT_ENVS = 131_072
"""``--population-envs``' default (``jaxterrain.curriculum.batch.DEFAULT_ENVS``, read here without importing JAX)."""
PRESETS = {name: {**{k: v for k, v in p.items() if k not in ("archive", "curriculum")},
                  "archives": dict(DEFAULT_ARCHIVES), "baseline": "roughness", "baseline_archive": "cppn",
                  "combined": True}
           for name, p in learn.PRESETS.items()}
RULES = learn.RULES
"""The declared checks of a treatment's flat keys (``learn``'s), from which the flags are made."""
RUN_KEYS = ("archives", "baseline", "baseline_archive", "combined")
"""The run's own keys (not a treatment's ``learn`` config): a run folder written before ``baseline_archive`` /
``combined`` existed lacks them and resumes with their defaults, ``cppn`` and True (:func:`baseline_archive`,
:func:`combined`)."""


HELP = {
    "trials": "trials of each treatment, run together",
    "max_epochs": "each trial's epoch budget (an epoch: 4 000 env steps; the paper: 30 000)",
    "chunks_per_call": "chunks per jitted call / checkpoint, in every treatment (learn's)",
    **learn.FINE_TUNING_HELP,
    "baseline": f"the baselines run on the --baseline-archive (default cppn), in this order: {', '.join(BASELINES)} "
                f"or module:object (Figure 7b; default roughness)",
    "baseline_archive": "the archive (one of --archives' names) the --baseline curricula run on (default cppn)",
    "combined": "with several archives, the map curriculum on their combination (qd.combine; default on); "
                "--no-combined skips that treatment",
    **learn.SELECTOR_HELP,
    "backend": "walker physics of every treatment: {backend}; warp holds one tile per trial",
}
"""Each flag's help (``experiments.cli_gen`` adds type, choices and range from ``learn.RULES``)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    common.add_run_arguments(parser, PRESETS, "smoke")
    common.add_devices_argument(parser)  # each treatment's trials split over the devices
    parser.add_argument("--archives", nargs="+", default=None, metavar="NAME=PATH",
                        help="archives of the map treatments (default: the five generators' archives shipped in "
                             "jaxterrain/assets/archives, G_headings.npz)")
    cli_gen.add_flags(parser, PRESETS, RULES, HELP, phrases={**learn.PHRASES, "scope": ", in every treatment"},
                      argparse_kwargs={
        **learn.ARGPARSE, "baseline": {"nargs": "+", "type": common.selector_name, "metavar": "NAME"},
        "baseline_archive": {"metavar": "NAME"}})
    common.add_deprecated_alias(parser, "--freeze-normaliser", "--no-update-normaliser", "update_normaliser",
                                const=False)
    common.add_protocol_argument(parser)  # default: each archive's own protocol (learn's)
    parser.add_argument("--report", action="store_true",
                        help="with --resume: Table 2 and the figures from the treatments as they stand (unfinished "
                             "ones from their last checkpoint, marked partial), without training")
    parser.add_argument("--shard", type=common.parse_shard, default=None, metavar="I/N",
                        help="run only process I's share of the treatments (independent processes, e.g. one per GPU, "
                             "on one run folder): whole populations balanced over the N processes "
                             "(batch.shard_groups), or t %% N == I of the fixed order with --no-batch-treatments; "
                             "then --resume without --shard writes the tables")
    parser.add_argument("--batch-treatments", action=argparse.BooleanOptionalAction, default=True,
                        help="run the treatments that share a walker and the harness's work (e.g. the map "
                             "curriculum on every archive) as one population in one compiled program, each "
                             "treatment's files as its run alone writes them; --no-batch-treatments: one after "
                             "another (the results are the same)")
    parser.add_argument("--population-envs", type=int, default=None, metavar="N",
                        help=f"envs stepped together in one population's program at most (default "
                             f"{DEFAULT_ENVS}, the walker's peak range on a GPU; a program that does not fit in the "
                             f"device's memory is split anyway)")
    parser.add_argument("--block-seconds", type=float, default=None, metavar="S",
                        help="a population's compiled block (chunks between checkpoints) is cut to about S seconds "
                             "at the rate measured (default 300; at most --chunks-per-call chunks)")
    common.add_progress_argument(parser)


def parse_archives(items) -> dict | None:
    if items is None:
        return None
    out = {}
    for item in items:
        name, sep, path = item.partition("=")
        if not sep or not name or not path:
            raise SystemExit(f"--archives: expected NAME=PATH, got {item!r}")
        out[name] = path
    return out


def check_config(args, cfg: dict) -> None:
    """Before a run folder: ``--baseline-archive`` names one of ``--archives`` (:func:`check_baseline_archive`), every
    ``--archives`` file reads as an archive a curriculum can use (``runner.load_archive``; read again per treatment),
    every curriculum flag given belongs to the map curriculum or a ``--baseline`` (``learn.check_selector_flags``)
    and ``--scan-lr-scale`` has a scan (``learn.check_scan_lr``); :class:`~experiments.common.UsageError`."""
    from jaxterrain.curriculum import runner

    check_baseline_archive(cfg, given=getattr(args, "baseline_archive", None) is not None,
                           baseline_given=getattr(args, "baseline", None) is not None)
    for name, path in sorted(cfg["archives"].items()):
        try:
            runner.load_archive(path, cfg["descriptors"])
        except runner.BadInput as err:
            text = str(err).removeprefix(f"LearnConfig.archive {path}: ")
            raise common.UsageError(f"--archives {name}={path}: {text}") from None
    learn.check_selector_flags(args, ["map", *baselines(cfg)], "--baseline")
    learn.check_scan_lr(_treatment_cfg(cfg, next(iter(cfg["archives"].values())), "map"))
    if getattr(args, "combined", None) and len(cfg["archives"]) < 2:
        raise common.UsageError(f"--combined: the map curriculum on the combination of several --archives; this run "
                                f"has one ({', '.join(cfg['archives'])})")


def baseline_archive(cfg: dict) -> str:
    """The archive name the baselines run on: ``cfg["baseline_archive"]``, ``cppn`` for a run folder written before
    the key existed."""
    return cfg.get("baseline_archive", "cppn")


def combined(cfg: dict) -> bool:
    """Whether the map curriculum runs on the archives' combination (with several archives): ``cfg["combined"]``,
    True for a run folder written before the key existed."""
    return bool(cfg.get("combined", True))


def check_baseline_archive(cfg: dict, given: bool = True, baseline_given: bool = True) -> None:
    """``--baseline-archive`` must name one of ``--archives``; :class:`~experiments.common.UsageError` listing them.
    Where neither it nor ``--baseline`` was given and the default (``cppn``) is not among the archives, the run has no
    baseline, as before the flag existed (e.g. ``--archives a=A b=B``: the map treatments alone)."""
    name, names = baseline_archive(cfg), sorted(cfg["archives"])
    if not isinstance(name, str) or not name:
        raise common.UsageError(f"--baseline-archive must be one of --archives' names ({', '.join(names)}); got "
                                f"{name!r}")
    if name not in names and given:
        raise common.UsageError(f"--baseline-archive must be one of --archives' names ({', '.join(names)}); got "
                                f"{name!r}")
    if name not in names and baseline_given:
        raise common.UsageError(f"--baseline runs on --baseline-archive {name} (the default), which is not among "
                                f"--archives' names ({', '.join(names)}); give --baseline-archive NAME")
    if not isinstance(cfg.get("combined", True), bool):
        raise common.UsageError(f"--combined must be true or false; got {cfg['combined']!r}")


def treatments(cfg: dict, folder: Path) -> list[tuple[str, str, str]]:
    """``[(name, archive path, curriculum)]`` in run order; writes the combined archive when needed.

    The map treatments go in the order of the archives' NAMES, whatever order ``--archives`` gave them in:
    ``config.json`` stores them with sorted keys, so a resumed run (and every ``--shard``) must see the order a fresh
    one does."""
    from jaxterrain.curriculum import runner

    from jaxterrain import qd as A

    archives = dict(sorted(cfg["archives"].items()))
    out = [(name, path, "map") for name, path in archives.items()]
    if len(archives) > 1 and combined(cfg):
        both = folder / "combined_archive.npz"
        if not both.exists():
            try:
                A.save(both, A.combine([runner.load_archive(p, cfg["descriptors"]) for p in archives.values()]))
            except ValueError as err:
                raise runner.BadInput(f"--archives: cannot combine them: {err}") from None
        out.append(("combined", str(both), "map"))
    name = baseline_archive(cfg)
    if name in archives:
        out += [(name, archives[name], b) for b in baselines(cfg)]
    return out


def baselines(cfg: dict) -> list[str]:
    """The run's baselines in order: ``config.json`` keeps one name (runs before Experiment 3) or a list."""
    b = cfg["baseline"]
    return [b] if isinstance(b, str) else list(b)


def _treatment_cfg(cfg: dict, path: str, curriculum: str) -> dict:
    """A treatment's flat config (its ``config.json``): the run's, on one archive with one curriculum."""
    keep = {k: v for k, v in cfg.items() if k not in (*RUN_KEYS, "command", "preset")}
    return {**keep, "archive": path, "curriculum": curriculum, "command": "learn"}


def treatment_run(cfg: dict, path: str, curriculum: str):
    """A treatment's typed run (``jaxterrain.curriculum.run_config.LearnConfig``)."""
    return learn.run_of(_treatment_cfg(cfg, path, curriculum))


def shown(label: str, summary: dict) -> str:
    """A treatment's name in tables and legends: ``label``, with ``[partial: E epochs]`` for a summary of an
    unfinished run (``runner.report_treatment``)."""

    return f"{label} [partial: {summary['epochs_max']} epochs]" if summary.get("partial") else label


def write_table(folder: Path, rows: list[tuple[str, dict]], trials: int) -> None:
    """table2.csv (ours: mean epochs and trials reaching each milestone; the paper's) and table2.md."""
    from jaxterrain.curriculum import MILESTONES, PAPER_TABLE2, format_milestone
    from jaxterrain.runtime.io import atomic_write_text

    pct = [f"{round(100 * m)}%" for m in MILESTONES]
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["treatment", "source"] + pct + [f"trials_{p}" for p in pct])
    md = ["| treatment | " + " | ".join(pct) + " |", "|---|" + "---|" * len(pct)]
    for label, s in rows:
        means, reached = s["milestone_epochs"], s["milestone_trials"]
        name = shown(label, s)
        w.writerow([name, "ours"] + ["" if m is None else f"{m:.1f}" for m in means] + reached)
        cells = [format_milestone(float("nan") if m is None else m, r, trials) for m, r in zip(means, reached)]
        md.append(f"| {name} (ours) | " + " | ".join(cells) + " |")
        paper = PAPER_TABLE2.get(label.split(" ")[0]) if label.endswith(" map") else None
        if paper is not None:
            w.writerow([label, "paper"] + ["" if v is None else v for v in paper] + [""] * len(pct))
            md.append(f"| {label} (paper) | " + " | ".join("-" if v is None else str(v) for v in paper) + " |")
    atomic_write_text(folder / "table2.csv", buf.getvalue())
    atomic_write_text(folder / "table2.md", "\n".join(md) + "\n")


def write_figures(folder: Path, rows: list[tuple[str, dict]], baseline: str | list[str], on: str = "cppn") -> None:
    """Figure 7a (every map treatment) and Figure 7b (the map curriculum against the baselines ``baseline`` on the
    archive ``on``, the run's ``--baseline-archive``), each only where it has curves to draw."""
    from jaxterrain.curriculum import outputs

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    maps = {shown(label.split(" ")[0], s): outputs.summary_curve(s) for label, s in rows if label.endswith(" map")}
    if maps:
        fig, ax = plt.subplots(figsize=(7, 4))
        outputs.plot_curves(ax, maps, "Figure 7a: map-based curriculum per archive (mean +- 1 s.e.)")
        fig.tight_layout()
        common.save_figure(fig, folder / "figure7a.png")
    names = [baseline] if isinstance(baseline, str) else list(baseline)
    pair = {shown(label, s): outputs.summary_curve(s) for label, s in rows
            if label == f"{on} map" or label in {f"{on} {b}" for b in names}}
    if len(pair) >= 2 and any(label == f"{on} map" for label, _ in rows):
        fig, ax = plt.subplots(figsize=(7, 4))
        title = "CPPN" if on == "cppn" else on
        outputs.plot_curves(ax, pair, f"Figure 7b: {title}, map-based vs {' / '.join(names)} curriculum")
        fig.tight_layout()
        common.save_figure(fig, folder / "figure7b.png")


def write_sequences(folder: Path, done: list[tuple[str, Path]]) -> None:
    """``sequences.csv`` of every treatment in one file, a ``treatment`` column first. The columns are the union of
    the treatments' (in order of appearance), so a treatment written by an older version, with fewer columns, leaves
    its missing cells empty."""
    from jaxterrain.runtime.io import atomic_write_text

    tables = [(label, list(csv.DictReader(io.StringIO((sub / "sequences.csv").read_text())))) for label, sub in done]
    columns = ["treatment"]
    for _, rows in tables:
        columns += [c for c in (rows[0] if rows else {}) if c not in columns]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=columns, restval="", lineterminator="\n")
    w.writeheader()
    for label, rows in tables:
        w.writerows({"treatment": label, **r} for r in rows)
    atomic_write_text(folder / "sequences.csv", buf.getvalue())


def write_hardest(folder: Path, rows: list[tuple[str, dict]]) -> None:
    """hardest.csv / hardest.md: each treatment's hardest terrain traversed over its trials, mean +- s.e. beside the
    mean's and the interquartile mean's 95 % intervals (a bootstrap over whole trials, ``statistics.trial_estimates``,
    seed 0: numpy alone, so a GPU image without rliable writes them), and the probability that a trial of one
    treatment went further than a trial of another."""
    import numpy as np

    from jaxterrain.curriculum.outputs import BOOTSTRAP_REPS
    from jaxterrain.runtime import statistics
    from jaxterrain.runtime.io import atomic_write_csv, atomic_write_text

    scores = {shown(label, s): np.asarray(s["hardest"], np.float64)[:, None] for label, s in rows}
    est = statistics.trial_estimates(scores, reps=BOOTSTRAP_REPS)
    table = []
    md = ["| treatment | trials | mean +- s.e. | mean [95 % CI] | IQM [95 % CI] |", "|---|---|---|---|---|"]
    for name, x in scores.items():
        se = x.std(ddof=1) / np.sqrt(x.size) if x.size > 1 else 0.0
        m, q = est[name]["mean"], est[name]["iqm"]
        table.append((name, x.size, f"{x.mean():.3f}", f"{se:.3f}", f"{m.low:.3f}", f"{m.high:.3f}", f"{q.point:.3f}",
                      f"{q.low:.3f}", f"{q.high:.3f}"))
        md.append(f"| {name} | {x.size} | {x.mean():.2f} +- {se:.2f} | {m.point:.2f} [{m.low:.2f}, {m.high:.2f}] | "
                  f"{q.point:.2f} [{q.low:.2f}, {q.high:.2f}] |")
    names = list(scores)
    if len(names) > 1:
        md += ["", "P(a trial of the row went further than a trial of the column):", "",
               "| | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
        md += [f"| {a} | " + " | ".join("-" if a == b else f"{statistics.probability_of_improvement(scores[a], scores[b]):.2f}"
                                        for b in names) + " |" for a in names]
    atomic_write_csv(folder / "hardest.csv", ["treatment", "trials", "mean", "se", "mean_low", "mean_high", "iqm",
                                              "iqm_low", "iqm_high"], table)
    atomic_write_text(folder / "hardest.md", "\n".join(md) + "\n")


def write_outputs(folder: Path, cfg: dict, rows: list[tuple[str, dict]], done: list[tuple[str, Path]]) -> None:
    """Table 2, Figure 7a / 7b, hardest.csv / .md and sequences.csv of the treatments' ``rows`` (label, summary) in
    ``done`` folders."""
    write_table(folder, rows, int(cfg["trials"]))
    write_hardest(folder, rows)
    write_figures(folder, rows, cfg["baseline"], baseline_archive(cfg))
    write_sequences(folder, done)


def report(folder: Path, cfg: dict, plan) -> int:
    """``--report``: every treatment as it stands (``runner.report_treatment``; none compiles), then the tables."""
    from jaxterrain.curriculum import runner

    rows, done = [], []
    for name, path, curriculum in plan:
        sub = folder / f"{name}-{curriculum}"
        summary = runner.report_treatment(treatment_run(cfg, path, curriculum), sub) if sub.is_dir() else None
        if summary is None:
            print(f"{name} {curriculum}: no checkpoint yet", flush=True)
            continue
        rows.append((f"{name} {curriculum}", summary))
        done.append((f"{name} {curriculum}", sub))
        print(f"{shown(f'{name} {curriculum}', summary)}: hardest {summary['hardest_mean']:.2f}", flush=True)
    if not rows:
        print(f"curriculum: no treatment of {folder} has a checkpoint yet", file=sys.stderr)
        return 2
    write_outputs(folder, cfg, rows, done)
    print(f"report: {len(rows)} of {len(plan)} treatments -> {folder}/table2.md and the figures", flush=True)
    return 0


def check_population_flags(args) -> None:
    """``--population-envs`` (an integer >= 1) and ``--block-seconds`` (> 0) size a population: refused with
    ``--no-batch-treatments`` or ``--report`` (nothing would read them); :class:`~experiments.common.UsageError`."""
    import math

    given = [f for f, v in (("--population-envs", args.population_envs), ("--block-seconds", args.block_seconds))
             if v is not None]
    if given and not args.batch_treatments:
        raise common.UsageError(f"{' and '.join(given)}: size a population of treatments; --no-batch-treatments "
                                f"runs them one after another")
    if given and args.report:
        raise common.UsageError(f"{' and '.join(given)}: size a population of treatments; --report trains nothing")
    if args.population_envs is not None and args.population_envs < 1:
        raise common.UsageError(f"--population-envs must be an integer >= 1; got {args.population_envs}")
    if args.block_seconds is not None and not (math.isfinite(args.block_seconds) and args.block_seconds > 0):
        raise common.UsageError(f"--block-seconds must be a finite number > 0; got {args.block_seconds}")


def shard_of(args, checked: list, count: int, devices: int) -> list[int]:
    """The ``--shard`` process of each treatment of the plan (``checked``: their ``runner.validate`` results, in
    the plan's order): with populations (``--batch-treatments``, one device) ``batch.shard_groups`` keeps each
    population on one process and balances them; else ``t % count``."""
    from jaxterrain.curriculum import batch

    if count == 1 or not args.batch_treatments or devices > 1:
        return [t % count for t in range(len(checked))]
    keys = [batch.group_key(run, config, policy, env) for run, config, _, policy, env in checked]
    return batch.shard_groups(keys, [batch.envs_of(c[0]) for c in checked], [int(c[0].trials) for c in checked],
                              count, int(args.population_envs or batch.DEFAULT_ENVS))


def run_populations(args, cfg: dict, folder: Path, mine: list, left: float | None) -> list | None:
    """The treatments ``mine`` (``(name, archive, curriculum)``) in populations (``jaxterrain.curriculum.batch``):
    one line per population saying which treatments share a program; their summaries (None where the time limit
    stopped one), or None after a one-line error (a treatment's input, checked before anything compiles)."""
    from jaxterrain.curriculum import batch, runner

    treatments = [batch.Treatment(f"{name} {curriculum}", treatment_run(cfg, path, curriculum),
                                  folder / f"{name}-{curriculum}") for name, path, curriculum in mine]
    try:
        return batch.run_treatments(treatments, None if left is None else max(left, 1e-3),
                                    max_envs=args.population_envs,
                                    block_seconds=args.block_seconds or batch.BLOCK_SECONDS,
                                    progress=common.progress_mode(args), say=lambda line: print(line, flush=True),
                                    label=f"shard {args.shard[0]}/{args.shard[1]} population" if args.shard
                                    else "population")
    except runner.BadInput as err:
        print(f"curriculum: {learn.flags_in(str(err), mine[0][2])}", file=sys.stderr)
        return None


def main(args) -> int:
    from jaxterrain.curriculum import runner

    check_population_flags(args)
    if args.report and args.resume is None:
        raise common.UsageError("--report needs --resume RUN (the run to report on)")
    if args.report:
        common.refuse_given({"--shard": args.shard, "--time-limit": args.time_limit, "--devices": args.devices},
                            "--report writes the tables of every treatment and trains nothing: drop one of them")
    if args.baseline is not None and len(set(args.baseline)) < len(args.baseline):
        raise common.UsageError(f"--baseline: each of {', '.join(BASELINES)} at most once; got {' '.join(args.baseline)}")
    over = {"archives": parse_archives(args.archives), **cli_gen.given(args, HELP),
            **learn.fine_tuning_overrides(args), **common.protocol_overrides(args)}
    mesh = common.device_mesh(args.devices)
    folder, cfg = common.setup_run("curriculum", args, PRESETS, "smoke", over, check=lambda c: check_config(args, c),
                                   rules=RULES)
    start = time.perf_counter()
    limit = None if args.time_limit is None else 60.0 * args.time_limit
    curriculum = "map"  # the curriculum whose flags an error names (its own, once the plan is read)
    checked = []  # each treatment's validated run, for --shard's populations
    try:
        plan = treatments(cfg, folder)
        for name, path, curriculum in plan:  # every treatment's input, before anything is compiled
            run = treatment_run(cfg, path, curriculum)
            checked.append(runner.validate(runner.report_run(run) if args.report else run))
            runner.check_resumable(folder / f"{name}-{curriculum}", run, checked[-1][2], physics=not args.report)
    except runner.BadInput as err:
        print(f"curriculum: {learn.flags_in(str(err), curriculum)}", file=sys.stderr)
        if args.resume is None and {p.name for p in folder.iterdir()} <= {common.CONFIG_NAME, common.PROVENANCE_NAME,
                                                                          "combined_archive.npz"}:
            shutil.rmtree(folder)  # nothing of a run in it yet (as learn)
        return 2
    if args.report:
        return report(folder, cfg, plan)
    rows, done = [], []
    shard_i, shard_n = args.shard or (0, 1)
    shard = "" if args.shard is None else f" --shard {shard_i}/{shard_n}"
    mine = [p for p, k in zip(plan, shard_of(args, checked, shard_n, mesh.size)) if k == shard_i]
    for name, path, curriculum in mine:
        sub = folder / f"{name}-{curriculum}"
        sub.mkdir(parents=True, exist_ok=True)
        common.write_config(sub, _treatment_cfg(cfg, path, curriculum))
    batched = args.batch_treatments and len(mine) > 1 and mesh.size == 1
    if args.batch_treatments and len(mine) > 1 and mesh.size > 1:
        print(f"curriculum: each treatment's trials split over the {mesh.size} devices, one treatment after another "
              f"(a population runs on one device: --devices 1 batches them)", flush=True)
    if batched:
        summaries = run_populations(args, cfg, folder, mine, None if limit is None else limit - (time.perf_counter()
                                                                                                   - start))
        if summaries is None:
            return 2
    else:
        summaries = []
        for name, path, curriculum in mine:
            left = None if limit is None else max(limit - (time.perf_counter() - start), 1e-3)
            summaries.append(runner.run_treatment(treatment_run(cfg, path, curriculum), folder / f"{name}-{curriculum}",
                                                  left, desc=f"{name} {curriculum}", mesh=mesh,
                                                  progress=common.progress_mode(args)))
            if summaries[-1] is None:
                break
    for (name, _, curriculum), summary in zip(mine, summaries):
        if summary is None:
            print(f"time limit reached; continue with: python -m experiments curriculum --resume {folder}{shard}",
                  flush=True)
            return 3
        rows.append((f"{name} {curriculum}", summary))
        done.append((f"{name} {curriculum}", folder / f"{name}-{curriculum}"))
    if args.shard is not None:
        print(f"shard {shard_i}/{shard_n} done ({len(rows)} of {len(plan)} treatments); when every shard is, write the "
              f"tables with: python -m experiments curriculum --resume {folder}", flush=True)
        return 0
    write_outputs(folder, cfg, rows, done)
    print(f"done: {len(rows)} treatments -> {folder}/table2.md, figure7a.png, figure7b.png", flush=True)
    print(json.dumps({label: s["hardest_mean"] for label, s in rows}), flush=True)
    return 0
