"""A ``coverage`` run (Experiment 1b) as one call: a :class:`~jaxterrain.qd.run_config.CoverageRun` validated once,
an archive evolved for every generator x descriptor pair (one after another, or all at once with ``batched``),
Table 1 and Figures 5 and 6 written.

    from jaxterrain.qd import run_config as R, table1
    run = table1.validate_coverage(R.COVERAGE_PRESETS["smoke"])
    result = table1.coverage_run(run, "runs/table1")   # CoverageResult; None when the time limit stopped it
    result.coverage[("perlin", "tri-tpi")]                # percent of the cells filled

Writes into the folder: ``archives/<generator>__<pair>/`` (each treatment's :func:`jaxterrain.qd.runs.evolve_run`
folder: checkpoint, ``archive.npz``, ``metrics.csv``), ``batched/checkpoint.npz`` (``batched``),
``archives/combined__<pair>.npz`` (``qd.combine`` of a pair's archives), ``coverage.csv``, ``coverage.md`` (Table 1),
``coverage.png`` (Figure 5) and ``archives.png`` (Figure 6). Finished archives are reused, so a stopped run
continues with the same call; ``shard=(I, N)`` evolves only the treatments ``t % N == I`` (each with the key it has
in a whole run) and writes no tables (a later call without ``shard`` reuses every archive and writes them).
"""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Callable, NamedTuple, Optional

import jax
import numpy as np
from matplotlib.figure import Figure

from jaxterrain.features.alignment import generator_available
from jaxterrain.qd.archive import combine, coverage, qd_score
from jaxterrain.qd.archive_io import load, save
from jaxterrain.qd.config import Archive
from jaxterrain.qd.evolution import Treatment, evolve_many
from jaxterrain.qd.run_config import COVERAGE_RULES, CoverageRun, EvolveRun
from jaxterrain.qd.runs import (Deadline, TimeUp, announce_compile, check_descriptors, check_evolve_config,
                                check_generators, check_walker, evolve_config, evolve_run, fitness_of, plot_archive,
                                write_metrics_csv)
from jaxterrain.runtime import schema
from jaxterrain.runtime.io import atomic_write_text, save_figure

__all__ = ["PAPER_NAMES", "CoverageResult", "validate_coverage", "treatments", "treatment_run", "treatment_key",
           "pair_label", "paper_pair_label", "coverage_run", "markdown_table", "write_tables", "plot_figures"]

PAPER_NAMES = {"cppn": "CPPN", "gan": "GAN", "perlin": "Perlin Noise", "worley": "Worley Noise",
               "diamond_square": "Diamond Square"}
"""The generators' names in the paper's Table 1."""


class CoverageResult(NamedTuple):
    """What :func:`coverage_run` made: ``archives`` ``{(generator, pair label): Archive}`` (with ``combined``),
    ``coverage`` ``{(generator, pair label): percent}`` (None for a shard: no tables), ``skipped`` ``{generator:
    why}`` (not available here, e.g. the GAN without its weights) and the treatments evolved / in all."""

    archives: dict
    coverage: Optional[dict]
    skipped: dict
    done: int
    total: int


def validate_coverage(run: CoverageRun) -> CoverageRun:
    """Check ``run`` once, before anything compiles: its fields (``run_config.COVERAGE_RULES``), its generators
    (registered, rendering at ``size``), its pairs and ranges (every treatment's :class:`EvolveRun` validated as
    ``qd.runs.validate_evolve`` does) and the walker fitness's robot. ``ValueError`` naming ``CoverageRun.<path>``."""
    owner = "CoverageRun"
    schema.check(run, COVERAGE_RULES, owner)
    check_generators(run.generators, int(run.size), owner, "generators")
    check_walker(owner, run.fitness, int(run.size), run.walks.robot, run.walks.observation)
    ranges = dict(run.ranges or ())
    for pair in run.pairs:
        check_descriptors(pair, owner, "pairs")
        missing = [d for d in pair if ranges and d not in ranges]
        if missing:
            raise ValueError(f"{owner}.ranges: no range for descriptor(s) {missing} of pair {list(pair)}")
        check_evolve_config(treatment_run(run, pair, run.generators[0]), owner, {"descriptors": "pairs"})
    return run


def treatments(pairs, generators) -> list[tuple[int, tuple, str]]:
    """Every (descriptor pair, generator) of a run in its fixed order: ``[(index, pair, generator)]``. Shards take
    ``index % N == I``; the order (pairs outer) never depends on the sharding, nor does any treatment's key."""
    return [(k, pair, g) for k, (pair, g) in enumerate((p, g) for p in pairs for g in generators)]


def treatment_run(run: CoverageRun, pair, generator: str) -> EvolveRun:
    """The :class:`EvolveRun` of one treatment: ``generator`` over ``pair`` with the run's settings and the pair's
    ranges (None: the defaults)."""
    ranges = None if run.ranges is None else tuple(dict(run.ranges)[d] for d in pair)
    return EvolveRun(generator=generator, descriptors=tuple(pair), ranges=ranges, size=run.size, fitness=run.fitness,
                     map_elites=run.map_elites, walks=run.walks, seed=run.seed, preset=run.preset)


def treatment_key(key, run: CoverageRun, pair, generator: str):
    """The root key of one treatment: ``key`` folded with the pair's and the generator's index in ``run``."""
    pairs = [tuple(p) for p in run.pairs]
    return jax.random.fold_in(jax.random.fold_in(key, pairs.index(tuple(pair))), list(run.generators).index(generator))


def pair_label(pair) -> str:
    """``tri-tpi``: a pair's name in file names and tables."""
    return f"{pair[0]}-{pair[1]}"


def paper_pair_label(pair) -> str:
    """The paper's column names: 'Roughness/TPI' = roughness on one axis, TPI on the other."""
    nice = {"tri": "TRI", "tpi": "TPI", "roughness": "Roughness"}
    return f"{nice.get(pair[1], pair[1])}/{nice.get(pair[0], pair[0])}"


def _place(folder: Path, pair, generator: str) -> Path:
    return folder / "archives" / f"{generator}__{pair_label(pair)}"


def coverage_run(run: CoverageRun, folder, time_limit_s: Optional[float] = None, mesh=None,
                 shard: Optional[tuple[int, int]] = None,
                 say: Callable[[str], None] = print) -> Optional[CoverageResult]:
    """Evolve ``run``'s treatments into ``folder`` and write Table 1 and Figures 5 and 6 (module docstring); None
    when ``time_limit_s`` (seconds from now) stopped it after a checkpoint. ``mesh``: the devices each generation's
    offspring are split over; ``shard``: ``(I, N)``, only the treatments ``t % N == I``, no tables (not with
    ``batched``)."""
    folder = Path(folder)
    if run.batched and shard is not None:
        raise ValueError("CoverageRun.batched runs every treatment in one process; it cannot be combined with a shard")
    key = jax.random.key(int(run.seed))
    skipped = {}
    for g in run.generators:
        ok, why = generator_available(g, int(run.size))
        if not ok:
            skipped[g] = why
            say(f"[{g}] skipped: {why}")
    available = [g for g in run.generators if g not in skipped]
    todo = treatments([tuple(p) for p in run.pairs], available)
    shard_i, shard_n = shard or (0, 1)
    mine = [t for t in todo if t[0] % shard_n == shard_i]
    deadline = Deadline(time_limit_s)
    try:
        if run.batched:
            archives = _run_batched(run, todo, folder, deadline, key, mesh, say)
        else:
            of = "" if shard is None else f" of shard {shard_i}/{shard_n}"
            archives = {}
            for n, (_, pair, g) in enumerate(mine, 1):
                archives[(g, pair_label(pair))] = evolve_run(
                    treatment_run(run, pair, g), _place(folder, pair, g), mesh=mesh,
                    key=treatment_key(key, run, pair, g), label=f"({n}/{len(mine)}{of}) ", figures=False,
                    deadline=deadline, say=say)
    except TimeUp:
        return None
    if shard is not None:
        return CoverageResult(archives, None, skipped, len(mine), len(todo))
    pairs = [tuple(p) for p in run.pairs]
    cov = write_tables(folder, archives, pairs, list(run.generators), available, skipped, say)
    plot_figures(folder, archives, cov, pairs, available)
    return CoverageResult(archives, cov, skipped, len(mine), len(todo))


def _run_batched(run: CoverageRun, todo, folder: Path, deadline: Deadline, key, mesh, say) -> dict:
    """Every treatment of ``todo`` at once (``qd.evolve_many``), checkpointed in ``folder/batched``; each treatment
    keeps the key it has in an unbatched run; finished archives are written where the unbatched run writes them
    (and reused)."""
    if all((_place(folder, pair, g) / "archive.npz").exists() for _, pair, g in todo):
        say("batched: every treatment already done")
        return {(g, pair_label(pair)): load(_place(folder, pair, g) / "archive.npz") for _, pair, g in todo}
    chosen = [Treatment(g, tuple(pair), treatment_key(key, run, pair, g)) for _, pair, g in todo]
    config = evolve_config(treatment_run(run, todo[0][1], todo[0][2])._replace(ranges=None))
    announce_compile(treatment_run(run, todo[0][1], todo[0][2]), config)

    def progress(info):
        cov = info["coverage"]
        say(f"[{len(cov)} treatments] gen {info['generation']}/{info['generations']}  coverage min "
            f"{min(cov):.2f}% mean {sum(cov) / len(cov):.2f}% max {max(cov):.2f}%  "
            f"{info['evaluations_per_s']:.1f} evals/s")
        if info["generation"] < info["generations"]:
            deadline.check()

    ranges = None if run.ranges is None else {name: list(pair) for name, pair in run.ranges}
    out = evolve_many(chosen, config, jax.random.fold_in(key, 2**31 - 1), fitness_fn=fitness_of(run.fitness),
                      checkpoint_dir=folder / "batched", progress=progress, generator_options={"size": int(run.size)},
                      ranges=ranges, mesh=mesh)
    result = {}
    for (_, pair, g), arch in zip(todo, out):
        _place(folder, pair, g).mkdir(parents=True, exist_ok=True)
        save(_place(folder, pair, g) / "archive.npz", arch)
        write_metrics_csv(_place(folder, pair, g) / "metrics.csv", arch.metrics)
        result[(g, pair_label(pair))] = arch
    return result


def markdown_table(cov: dict, generators: list[str], pairs, skipped: dict) -> str:
    """Table 1: coverage (%) per generator (rows, then the combined archive) and pair (the paper's columns)."""
    cols = [paper_pair_label(p) for p in pairs]
    lines = ["| Terrain generator | " + " | ".join(cols) + " |", "| --- |" + " --- |" * len(cols)]
    for g in generators + ["combined"]:
        if g in skipped:
            continue
        name = "Combined" if g == "combined" else PAPER_NAMES.get(g, g)
        cells = [f"{cov[(g, pair_label(p))]:.2f}%" if (g, pair_label(p)) in cov else "-" for p in pairs]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    text = "\n".join(lines) + "\n"
    if skipped:
        text += "\nSkipped (not available here): " + "; ".join(f"{g} ({why})" for g, why in skipped.items()) + "\n"
    return text


def write_tables(folder: Path, archives: dict, pairs, gens, available, skipped: dict, say=print) -> dict:
    """Add the combined archive of each pair to ``archives`` (and save it), write ``coverage.csv`` and Table 1
    (``coverage.md``, also given to ``say``); ``{(generator, pair label): coverage %}``."""
    rows, cov = [], {}
    for pair in pairs:
        members = [archives[(g, pair_label(pair))] for g in available]
        if members:
            comb = combine(members)
            save(folder / "archives" / f"combined__{pair_label(pair)}.npz", comb)
            archives[("combined", pair_label(pair))] = comb
        for g in available + (["combined"] if members else []):
            a = archives[(g, pair_label(pair))]
            c = coverage(a)
            cov[(g, pair_label(pair))] = c
            f = a.fitness[a.filled]
            rej = int(a.metrics["rejected"].sum()) if "rejected" in a.metrics else ""
            rows.append([g, pair_label(pair), f"{c:.4f}", f"{qd_score(a):.4f}",
                         f"{f.max():.4f}" if f.size else "", f"{f.mean():.4f}" if f.size else "", rej])
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["generator", "pair", "coverage_percent", "qd_score", "max_fitness", "mean_fitness", "rejected"])
    w.writerows(rows)
    w.writerows([[g, "", "skipped", why, "", "", ""] for g, why in skipped.items()])
    atomic_write_text(folder / "coverage.csv", buf.getvalue())
    table = markdown_table(cov, gens, pairs, skipped)
    atomic_write_text(folder / "coverage.md", table)
    say(table)
    return cov


def plot_figures(folder: Path, archives: dict, cov: dict, pairs, available) -> None:
    """Figure 5 (coverage bars, ``coverage.png``) and Figure 6 (the archives' heatmaps, rows = pairs, columns =
    generators and the combined archive, ``archives.png``)."""
    shown = available + (["combined"] if available else [])
    fig = Figure(figsize=(7, 3.5))
    ax = fig.subplots()
    width = 0.8 / max(len(pairs), 1)
    x = np.arange(len(shown))
    for k, pair in enumerate(pairs):
        ax.bar(x + k * width, [cov.get((g, pair_label(pair)), 0.0) for g in shown], width,
               label=paper_pair_label(pair))
    ax.set_xticks(x + width * (len(pairs) - 1) / 2, [PAPER_NAMES.get(g, g.capitalize()) for g in shown],
                  rotation=20, fontsize=8)
    ax.set_ylabel("coverage (%)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, folder / "coverage.png", dpi=150)

    fig = Figure(figsize=(2.9 * len(shown) + 1, 2.6 * len(pairs)), layout="constrained")
    axes = fig.subplots(len(pairs), len(shown), squeeze=False)
    img = None
    for i, pair in enumerate(pairs):
        for j, g in enumerate(shown):
            a: Archive = archives[(g, pair_label(pair))]
            img = plot_archive(axes[i, j], a, f"{PAPER_NAMES.get(g, g)}: {coverage(a):.2f}%")
    if img is not None:
        fig.colorbar(img, ax=axes.ravel().tolist(), shrink=0.6, label="fitness (darker = fitter)")
    for a in axes.ravel():
        a.tick_params(labelsize=6)
    save_figure(fig, folder / "archives.png", dpi=130)
