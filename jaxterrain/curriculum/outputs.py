"""A treatment's output files: ``history.csv`` (one row per trial and chunk), ``sequences.csv`` (each trial's
terrains in order), ``milestones.csv`` / ``.md`` (Table 2's row), ``curve.png`` (hardest terrain traversed vs epoch,
mean +- 1 standard error) and ``summary.json`` (:func:`write_outputs`), and the trials' walkers,
``policies/trial_K/`` (:func:`export_policies`), all written atomically."""

from __future__ import annotations

import datetime as _dt
import json
from pathlib import Path

import jax
import numpy as np
from matplotlib.figure import Figure

from jaxterrain.curriculum.analysis import (
    MILESTONES,
    first_epochs,
    format_milestone,
    hardest_curve,
    milestone_summary,
    terrain_runs,
)
from jaxterrain.curriculum.selectors import get_selector
from jaxterrain.qd.grid import MAX_DISTANCE_50
from jaxterrain.rl.checkpoint import save_policy
from jaxterrain.runtime import provenance, statistics
from jaxterrain.runtime.io import atomic_write_csv, atomic_write_text, save_figure
from jaxterrain.walker import randomisation_json

__all__ = ["BOOTSTRAP_REPS", "PARTIAL", "POLICIES", "HISTORY_COLUMNS", "SEQUENCE_COLUMNS", "histories", "seen_epochs",
           "sequence_rows", "generator_counts", "milestone_rows", "summary_curve", "plot_curves", "write_outputs",
           "trial_policy", "export_policies"]

BOOTSTRAP_REPS = 2000
"""Resamples of the trials for ``summary.json``'s ``hardest_mean_ci`` and ``hardest_iqm`` (a bootstrap over whole
trials, :func:`jaxterrain.runtime.statistics.trial_estimates`, seed 0)."""
PARTIAL = "summary_partial.json"
"""The summary of an unfinished run's last checkpoint (``summary.json`` marks a finished one)."""
POLICIES = "policies"
"""The folder of a run's walkers: ``policies/trial_K/`` at the end, ``policies/chunk_CCCCC/trial_K/`` snapshots."""


def histories(states) -> dict:
    """Host numpy history arrays [T, C] of the trial states."""
    h = states.history
    return {"epoch": np.asarray(h.epoch), "terrain": np.asarray(h.terrain),
            "evaluation": np.asarray(h.evaluation, np.float64), "hardest": np.asarray(h.hardest, np.float64)}


HISTORY_COLUMNS = ("trial", "chunk", "epoch", "env_steps", "terrain", "cell", "bin0", "bin1", "distance", "evaluation",
                   "hardest", "seen_epoch")
"""The columns of ``history.csv``: one row per trial and chunk, ``terrain`` the terrain chunk ``chunk`` trained
on, ``evaluation`` the policy after that chunk (at ``epoch``) evaluated on it with the chunk's keys (``nan``: not
evaluated, ``CurriculumConfig.eval_lag``), ``seen_epoch`` the epochs of the policy the selector chose the next
terrain for when it saw that evaluation (:func:`seen_epochs`: ``epoch``, or one chunk later under ``eval_lag``
but at a finished trial's last evaluation; -1 where not evaluated)."""


def seen_epochs(hist: dict, config, done=None) -> np.ndarray:
    """``[T, C]`` int: per history row, the epochs the trial had trained (and kept) when the selector read the row's
    evaluation: the row's ``epoch`` (the plain and the overlapped order), ``epoch + epochs_per_chunk`` under
    ``config.eval_lag`` (the next chunk had trained meanwhile), except for the last row of a trial that is done
    (``done`` [T] bool, None: none is): the training that rode along its evaluation was dropped; -1 where the row
    holds no evaluation."""
    epoch = np.asarray(hist["epoch"])
    lag = np.full(epoch.shape, config.epochs_per_chunk if getattr(config, "eval_lag", False) else 0)
    if done is not None:
        last = np.sum(epoch >= 0, axis=1) - 1  # [T]
        ended = np.asarray(done, bool) & (last >= 0)
        lag[np.flatnonzero(ended), last[ended]] = 0
    return np.where((epoch >= 0) & ~np.isnan(np.asarray(hist["evaluation"], np.float64)), epoch + lag, -1)


SEQUENCE_COLUMNS = ("trial", "order", "terrain", "cell", "bin0", "bin1", "distance", "prior", "chunks",
                    "final_evaluation", "best_evaluation", "reached", "end_epoch", "generator")
"""The columns of ``sequences.csv`` (:func:`sequence_rows`)."""


def sequence_rows(hist: dict, bank, config, names: tuple = ()) -> list:
    """``sequences.csv`` rows: trial, order, terrain, cell, bin0, bin1, distance, prior, chunks, final and best
    evaluation, reached (the threshold), end epoch, generator (``names[bank.source[terrain]]``; the id where
    ``names`` lacks it)."""
    cell, bins, source = np.asarray(bank.cell), np.asarray(bank.bins), np.asarray(bank.source)
    dist, prior = np.asarray(bank.distance), np.asarray(bank.fitness)
    name = lambda k: names[source[k]] if 0 <= source[k] < len(names) else str(int(source[k]))  # noqa: E731
    rows = []
    for t in range(hist["terrain"].shape[0]):
        for i, r in enumerate(terrain_runs(hist["terrain"][t], hist["evaluation"][t], hist["epoch"][t])):
            k = r["terrain"]
            rows.append([t, i, k, int(cell[k]), int(bins[k, 0]), int(bins[k, 1]), f"{dist[k]:.3f}", f"{prior[k]:.4f}",
                         r["chunks"], f"{r['final_evaluation']:.4f}", f"{r['best_evaluation']:.4f}",
                         int(r["best_evaluation"] >= config.threshold * config.max_fitness), r["end_epoch"], name(k)])
    return rows


def generator_counts(rows: list) -> dict:
    """Per generator, over every trial's terrain sequence (``sequence_rows``): the terrains trained, the chunks
    spent on them and the terrains finished (threshold reached) - which generators a combined archive's curriculum
    actually uses."""
    col = SEQUENCE_COLUMNS.index
    out: dict = {}
    for r in rows:
        c = out.setdefault(r[col("generator")], {"terrains": 0, "chunks": 0, "finished": 0})
        c["terrains"] += 1
        c["chunks"] += int(r[col("chunks")])
        c["finished"] += int(r[col("reached")])
    return dict(sorted(out.items()))


def milestone_rows(label: str, hist: dict) -> tuple[list, list]:
    """Table 2 row of one treatment: (CSV row with mean epochs and counts, Markdown cells)."""
    trials = hist["epoch"].shape[0]
    mean, reached = milestone_summary(first_epochs(hist["epoch"], hist["hardest"]))
    cells = [format_milestone(m, r, trials) for m, r in zip(mean, reached)]
    csv_row = [label] + [("" if r == 0 else f"{m:.1f}") for m, r in zip(mean, reached)] + [int(r) for r in reached]
    assert len(cells) == len(MILESTONES)
    return csv_row, cells


def summary_curve(summary: dict) -> tuple:
    """(epoch, mean, se), each [K] float: a treatment's hardest-terrain curve from its ``summary.json`` dict, in the
    form :func:`plot_curves` takes."""
    return tuple(np.asarray(summary["curve"][k], float) for k in ("epoch", "mean", "se"))


def plot_curves(ax, curves: dict, title: str = "") -> None:
    """Figure 7 style: hardest terrain traversed (cells) vs epoch, mean +- 1 standard error, one line per label."""
    for label, (grid, mean, se) in curves.items():
        ax.step(grid, mean, where="post", label=label)
        ax.fill_between(grid, mean - se, mean + se, step="post", alpha=0.25)
    ax.set_xlabel("epoch")
    ax.set_ylabel("hardest terrain traversed (cells from (0, 0))")
    ax.set_ylim(0, MAX_DISTANCE_50)
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7)


def write_outputs(folder: Path, run, config, bank, states, seconds: float | None,
                  chunks_done: int | None = None, names: tuple = ()) -> dict:
    """history.csv, sequences.csv, milestones.csv/.md, curve.png and summary.json; returns the summary. With
    ``chunks_done`` (an unfinished run's last checkpoint, :func:`report_treatment`) the summary goes to
    ``summary_partial.json`` with ``"partial": true`` and ``"chunks_done"``, and the curve's title says so; without
    it, ``summary.json``, and a ``summary_partial.json`` left by an earlier report is removed. The summary holds each
    trial's hardest terrain traversed, their mean +- s.e., and (the trials resampled :data:`BOOTSTRAP_REPS`
    times: :func:`~jaxterrain.runtime.statistics.trial_estimates`, pure numpy) the mean's 95 % interval ``hardest_mean_ci`` and the interquartile mean with its
    interval ``hardest_iqm`` ([point, low, high]). ``seconds``: the wall
    time of every command that ran the treatment, summed over resumes (each from its set-up and compilation on; the
    interpreter's start-up and imports are not in it), None where unknown. ``names``: the archive's generator names
    (``sequences.csv``'s ``generator`` column, the summary's ``generators``: :func:`generator_counts`). ``run``: the
    treatment's :class:`~jaxterrain.curriculum.run_config.LearnConfig` (its archive and selector name it)."""
    hist = histories(states)
    cell, bins, dist = np.asarray(bank.cell), np.asarray(bank.bins), np.asarray(bank.distance)
    seen = seen_epochs(hist, config, np.asarray(states.done))
    rows = []
    for t in range(hist["epoch"].shape[0]):
        for c in np.flatnonzero(hist["epoch"][t] >= 0):
            k = int(hist["terrain"][t, c])
            rows.append([t, c, int(hist["epoch"][t, c]), int(hist["epoch"][t, c]) * config.steps_per_epoch, k,
                         int(cell[k]), int(bins[k, 0]), int(bins[k, 1]), f"{dist[k]:.3f}",
                         f"{hist['evaluation'][t, c]:.4f}", f"{hist['hardest'][t, c]:.3f}",
                         int(seen[t, c])])
    atomic_write_csv(folder / "history.csv", list(HISTORY_COLUMNS), rows)
    sequences = sequence_rows(hist, bank, config, names)
    atomic_write_csv(folder / "sequences.csv", list(SEQUENCE_COLUMNS), sequences)
    label = f"{Path(getattr(run, 'terrains', None) or run.archive).stem} {run.curriculum.selector}"
    pct = [f"{round(100 * m)}%" for m in MILESTONES]
    csv_row, cells = milestone_rows(label, hist)
    atomic_write_csv(folder / "milestones.csv", ["treatment"] + [f"epochs_{p}" for p in pct] + [f"trials_{p}" for p in pct],
         [csv_row])

    atomic_write_text(folder / "milestones.md", "| treatment | " + " | ".join(pct) + " |\n|---|" + "---|" * len(pct)
                      + f"\n| {label} | " + " | ".join(cells) + " |\n")
    grid, mean, se = hardest_curve(hist["epoch"], hist["hardest"])
    fig = Figure(figsize=(6, 3.5))
    ax = fig.subplots()
    upto = "" if chunks_done is None else f", partial: {chunks_done} of {config.max_chunks} chunks"
    plot_curves(ax, {label: (grid, mean, se)}, f"{label}: {hist['epoch'].shape[0]} trials{upto}, mean +- 1 s.e.")
    fig.tight_layout()
    save_figure(fig, folder / "curve.png")
    final = np.asarray(states.hardest, np.float64)
    est = statistics.trial_estimates({label: final[:, None]}, reps=BOOTSTRAP_REPS)[label]  # trials resampled
    summary = {
        "label": label, "trials": int(final.size), "hardest": final.tolist(), "hardest_mean": float(final.mean()),
        "hardest_se": float(final.std(ddof=1) / np.sqrt(final.size)) if final.size > 1 else 0.0,
        "hardest_mean_ci": [est["mean"].low, est["mean"].high], "hardest_iqm": list(est["iqm"]),
        "epochs": np.asarray(states.epoch).tolist(), "epochs_max": int(np.max(np.asarray(states.epoch))),
        **{name: np.asarray(value).tolist() for name, value in
           jax.vmap(get_selector(config).summary)(states.selector).items()},
        "ended_without_terrains": [bool(d and e < config.max_epochs)
                                   for d, e in zip(np.asarray(states.done), np.asarray(states.epoch))],
        "milestones": dict(zip(pct, cells)), "seconds": seconds, "bank_terrains": int(bank.size),
        "generators": generator_counts(sequences),
        "milestone_epochs": [None if v == "" else float(v) for v in csv_row[1:1 + len(pct)]],
        "milestone_trials": csv_row[1 + len(pct):],
        "curve": {"epoch": grid.tolist(), "mean": mean.tolist(), "se": se.tolist()},
    }
    if chunks_done is not None:
        summary.update(partial=True, chunks_done=int(chunks_done))
    atomic_write_text(folder / ("summary.json" if chunks_done is None else PARTIAL), json.dumps(summary, indent=2)
                      + "\n")
    if chunks_done is None:  # finished: an earlier --report's partial summary is out of date
        (folder / PARTIAL).unlink(missing_ok=True)
    return summary


def trial_policy(states, trial: int) -> tuple:
    """``(params, normaliser)`` of trial ``trial`` of the stacked trial states (host numpy leaves): the walker that
    trial has trained, policy AND value net, as ``rl.save_policy`` takes them."""
    pick = lambda tree: jax.tree.map(lambda x: np.asarray(jax.device_get(x))[trial], tree)  # noqa: E731
    return pick(states.policy.params), pick(states.policy.normaliser)


def export_policies(folder: Path, run, config, ppo, env, start_policy, bank, states,
                    subdir: str | None = None, names: tuple = ()) -> list[Path]:
    """Write every trial's walker as ``folder/policies[/subdir]/trial_K/`` (``rl.save_policy``: ``policy.msgpack``
    + ``config.json``, which :func:`jaxterrain.rl.load_policy` reads and ``python -m experiments evaluate`` walks).

    ``config.json`` keeps the starting policy's ``walker_config`` (its contact solver: a walker walks as trained only
    under it; with ``randomisation`` set to the walker's when fine-tuning randomised the physics) and adds ``curriculum``: the archive (its path relative to the run folder ``folder``, or
    ``<jaxterrain>/...`` for a shipped one: ``runtime.provenance.portable_path``, no machine's absolute path; and
    its file's sha256; None, and ``terrain_folder`` the folder, for a run on a folder of heightmaps), the starting
    policy (the same way), the selector, the trial, its seed, the epochs and env steps it trained, its terrain
    sequence (bank indices, cells, distances and generators in the order trained), the hardest
    terrain it traversed, the chunk of the run; and ``provenance`` (commit, device, date, the walker's ``spawn`` rule;
    for a walker trained on MuJoCo Warp, ``warp_hfield``: its heightfield collision, ``runtime.provenance.warp_hfield``).
    ``run`` is the treatment's
    ``LearnConfig``, ``ppo`` the fine-tuning PPOConfig (the networks' shapes); ``env`` the walker env (observation and action sizes). Returns the
    folders, in trial order."""
    hist = histories(states)
    epochs = np.asarray(states.epoch)
    terrains = getattr(run, "terrains", None)  # a folder of heightmaps instead of the archive (runner.OwnTerrains)
    archive_sha = provenance.file_sha256(run.archive) if run.archive and not terrains else None
    out = []
    base_meta = dict(getattr(start_policy, "meta", None) or {})
    walker_config = base_meta.get("walker_config")
    randomised = randomisation_json(env.config.randomisation)  # the physics randomisation fine-tuning trained under
    if randomised is not None:
        walker_config = {**(walker_config or {}), "randomisation": randomised}
    cell, dist, source = np.asarray(bank.cell), np.asarray(bank.distance), np.asarray(bank.source)
    for t in range(hist["epoch"].shape[0]):
        runs = terrain_runs(hist["terrain"][t], hist["evaluation"][t], hist["epoch"][t])
        order = [int(r["terrain"]) for r in runs]
        params, normaliser = trial_policy(states, t)
        extra = {
            "walker_config": walker_config,
            "curriculum": {
                "archive": None if terrains else provenance.portable_path(str(run.archive), folder),
                **({"terrain_folder": provenance.portable_path(str(terrains), folder)} if terrains else {}),
                "archive_file_sha256": archive_sha, "selector": run.curriculum.selector, "trial": t,
                "seed": int(run.seed), "epochs": int(epochs[t]),
                "env_steps": int(epochs[t]) * int(config.steps_per_epoch),
                "chunks": int(np.sum(hist["epoch"][t] >= 0)), "hardest": float(np.asarray(states.hardest)[t]),
                "terrains": order, "cells": [int(cell[k]) for k in order],
                "distances": [round(float(dist[k]), 3) for k in order],
                "generators": [names[source[k]] if 0 <= source[k] < len(names) else str(int(source[k]))
                               for k in order],
                "start_policy": provenance.portable_path(str(getattr(start_policy, "path", "") or ""), folder),
            },
            "provenance": {"commit": provenance.git_commit(), "device": provenance.device(),
                           "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
                           **({"warp_hfield": provenance.warp_hfield()} if env.backend == "warp" else {}),
                           "spawn": env.config.spawn},
        }
        path = Path(folder) / POLICIES / (subdir or "") / f"trial_{t}"
        out.append(save_policy(path, params, normaliser, ppo, env.observation_size, env.action_size, extra=extra))
    return out
