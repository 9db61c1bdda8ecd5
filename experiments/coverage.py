"""``python -m experiments coverage``: Experiment 1b (paper Table 1, Figures 5 and 6).

Evolves one MAP-Elites archive per (descriptor pair, generator): the pairs TPI/TRI, roughness/TRI, roughness/TPI
x the generators (default: diamond_square, perlin, worley, gan, cppn), then the combined archive of each pair
(``jaxterrain.qd.combine``). A generator that cannot be built here (e.g. the GAN without trained weights) is
reported as skipped and left out of the combined archive.

Writes into the run folder:

* ``config.json``; ``archives/<generator>__<d0>-<d1>/`` with ``archive.npz``, ``metrics.csv`` and the checkpoint
  (a finished treatment is reused by ``--resume``); ``archives/combined__<d0>-<d1>.npz``;
* ``coverage.csv`` (generator, pair, coverage %, QD score, max / mean fitness, rejected by Algorithm 1) and
  ``coverage.md`` (Table 1: rows generators + Combined, columns the pairs; skipped generators listed);
* ``coverage.png`` (Figure 5: bars per generator and pair) and ``archives.png`` (Figure 6: one fitness heatmap per
  pair x generator, plus the combined archive).

Presets: ``paper`` and ``gpu`` (the paper's budget per treatment, see ``experiments/evolve.py``), ``gpu-short`` (a
tenth of it: all 15 treatments in about 15 x 3 GPU-minutes), ``paper-batched`` (the paper's 5 000 generations x 20
per treatment with every treatment at once: ``--batched``, below) and ``smoke`` (CPU, seconds).

``--batched`` evolves all treatments in one process at once (``jaxterrain.qd.evolve_many``): one jitted
generation mutates every treatment's 20 offspring and scores all 15 x 20 = 300 terrains with ONE walker call, so the
paper's deep lineages (5 000 mutations) cost 5 000 batched generations instead of 15 x 5 000 latency-bound ones. Its
checkpoint (all treatments) is ``batched/checkpoint.npz``; ``--resume`` continues it.

Several devices: ``--devices N`` (default: every visible device) splits each generation's offspring over N
devices in one process (``jaxterrain.qd.evolution``; with ``--batched``, the offspring of all treatments), so one
command uses every GPU of a host, or of several hosts (README, "Several devices"); the archives are the same for any
N. ``--shard I/N`` still runs only the treatments ``t % N == I`` of the fixed order of :func:`treatments` (every
treatment keeps the key it has in an unsharded run), to split Experiment 1b over independent jobs on the same run
folder; ``--resume`` without ``--shard`` then reuses the finished archives and writes the tables.
"""

from __future__ import annotations

import argparse
import csv
import io

from experiments import common
from experiments import evolve as evolve_cmd

PAIRS = (("tri", "tpi"), ("tri", "roughness"), ("tpi", "roughness"))  # paper: TPI/TRI, roughness/TRI, roughness/TPI
GENERATORS = ["diamond_square", "perlin", "worley", "gan", "cppn"]
PAPER_NAMES = {"cppn": "CPPN", "gan": "GAN", "perlin": "Perlin Noise", "worley": "Worley Noise",
               "diamond_square": "Diamond Square"}


def _preset(base: str, **kw) -> dict:
    cfg = {k: v for k, v in evolve_cmd.PRESETS[base].items()
           if k not in ("generator", "descriptors", "ranges", "mix", "fresh")}  # mix / fresh: evolve's mixed runs
    cfg.update(generators=list(GENERATORS), pairs=[list(p) for p in PAIRS], ranges=None)
    cfg.update(kw)
    return cfg


PRESETS: dict[str, dict] = {
    "paper": _preset("paper", batched=False),
    # the paper's protocol (5 000 generations x 20 per treatment), every treatment at once: 15 x 20 = 300 terrains
    # per generation, scored by one fitness call (jaxterrain.qd.evolve_many); a checkpoint every 50 generations
    "paper-batched": _preset("paper", batched=True, checkpoint_every=50),
    "gpu": _preset("gpu", batched=False),
    "gpu-short": _preset("gpu-short", batched=False),
    # ranges of the smoke preset: descriptors of 32 x 32 maps at window 8 (wider than the 256 x 256 defaults)
    "smoke": _preset("smoke", generations=2, initial_population=12, batch_size=8, batched=False,
                     ranges={"tri": [0.0, 0.5], "tpi": [-0.02, 0.02], "roughness": [0.0, 1.0]}),
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    common.add_run_arguments(parser, PRESETS, "smoke", {"paper-batched": "the paper's 5 000 generations of 20 per "
                                                                         "treatment, every treatment at once "
                                                                         "(--batched)"})
    common.add_devices_argument(parser)
    parser.add_argument("--generators", nargs="+", default=None,
                        help=f"generator names (default: {' '.join(GENERATORS)})")
    parser.add_argument("--generations", type=int, default=None,
                        help="MAP-Elites generations of each treatment after its initial population")
    parser.add_argument("--batch-size", type=int, default=None, help="offspring per generation")
    parser.add_argument("--size", type=int, default=None, help="heightmap side in pixels")
    parser.add_argument("--bins", type=int, default=None, help="cells per descriptor")
    parser.add_argument("--fitness", choices=common.FITNESS_NAMES, default=None,
                        help="what an elite's fitness measures: difficulty (the base policy walks it) or slope (a "
                             "cheap stand-in, no walking)")
    common.add_protocol_argument(parser)
    parser.add_argument("--batched", action=argparse.BooleanOptionalAction, default=None,
                        help="evolve every treatment at once (one jitted generation, one fitness call on all "
                             "treatments' offspring; jaxterrain.qd.evolve_many); not with --shard")
    parser.add_argument("--shard", type=common.parse_shard, default=None, metavar="I/N",
                        help="run only the treatments t with t %% N == I (independent jobs sharing one --out; see "
                             "the module docstring); then --resume without --shard writes the tables")


def treatments(pairs, generators) -> list[tuple[int, tuple, str]]:
    """Every (descriptor pair, generator) of a run in its fixed order: ``[(index, pair, generator)]``. Shards take
    ``index % N == I``; the order (pairs outer) never depends on the sharding, nor does any treatment's key."""
    return [(k, pair, g) for k, (pair, g) in enumerate((p, g) for p in pairs for g in generators)]


def overrides(args) -> dict:
    return dict(generators=args.generators, generations=args.generations, batch_size=args.batch_size,
                size=args.size, bins=args.bins, fitness=args.fitness, batched=args.batched,
                **common.protocol_overrides(args))


def pair_label(pair) -> str:
    return f"{pair[0]}-{pair[1]}"


def paper_pair_label(pair) -> str:
    """The paper's column names: 'Roughness/TPI' = roughness on one axis, TPI on the other."""
    nice = {"tri": "TRI", "tpi": "TPI", "roughness": "Roughness"}
    return f"{nice.get(pair[1], pair[1])}/{nice.get(pair[0], pair[0])}"


def markdown_table(cov: dict, generators: list[str], pairs, skipped: dict) -> str:
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


def run_batched(cfg: dict, todo, pairs, gens, folder, clock, key, mesh=None) -> dict:
    """Every treatment of ``todo`` at once (``archive.evolve_many``), checkpointed in ``folder/batched``; each
    treatment keeps the key it has in an unbatched run. Returns ``{(generator, pair label): Archive}``; finished
    archives are written where :func:`experiments.evolve.run_treatment` writes them (and reused)."""
    import jax

    from jaxterrain import qd as A

    def place(pair, g):
        return folder / "archives" / f"{g}__{pair_label(pair)}"

    if all((place(pair, g) / "archive.npz").exists() for _, pair, g in todo):
        print("batched: every treatment already done", flush=True)
        return {(g, pair_label(pair)): A.load(place(pair, g) / "archive.npz") for _, pair, g in todo}
    treatments = [A.Treatment(g, tuple(pair), jax.random.fold_in(jax.random.fold_in(key, pairs.index(pair)),
                                                                 gens.index(g))) for _, pair, g in todo]
    config = evolve_cmd.evolve_config({**cfg, "descriptors": list(todo[0][1]), "ranges": None})
    evolve_cmd.announce_compile(cfg, config)

    def progress(info):
        cov = info["coverage"]
        print(f"[{len(cov)} treatments] gen {info['generation']}/{info['generations']}  coverage min "
              f"{min(cov):.2f}% mean {sum(cov) / len(cov):.2f}% max {max(cov):.2f}%  "
              f"{info['evaluations_per_s']:.1f} evals/s", flush=True)
        if info["generation"] < info["generations"]:
            clock.check()

    out = A.evolve_many(treatments, config, jax.random.fold_in(key, 2**31 - 1),
                        fitness_fn=evolve_cmd.fitness_fn(cfg["fitness"]), checkpoint_dir=folder / "batched",
                        progress=progress, generator_options={"size": int(cfg["size"])}, ranges=cfg.get("ranges"),
                        mesh=mesh)
    result = {}
    for (_, pair, g), arch in zip(todo, out):
        place(pair, g).mkdir(parents=True, exist_ok=True)
        A.save(place(pair, g) / "archive.npz", arch)
        evolve_cmd.write_metrics_csv(place(pair, g) / "metrics.csv", arch.metrics)
        result[(g, pair_label(pair))] = arch
    return result


def main(args) -> int:
    import jax

    mesh = common.device_mesh(args.devices)
    folder, cfg = common.setup_run("coverage", args, PRESETS, "smoke", overrides(args))
    clock = common.Clock(args.time_limit)
    key = jax.random.key(int(cfg["seed"]))
    pairs = [tuple(p) for p in cfg["pairs"]]
    gens = list(cfg["generators"])
    skipped = {}
    for g in gens:
        ok, why = common.generator_available(g, int(cfg["size"]))
        if not ok:
            skipped[g] = why
            print(f"[{g}] skipped: {why}", flush=True)
    available = [g for g in gens if g not in skipped]
    todo = treatments(pairs, available)
    shard_i, shard_n = args.shard or (0, 1)
    mine = [t for t in todo if t[0] % shard_n == shard_i]
    resume_hint = f"python -m experiments coverage --resume {folder}"
    if cfg.get("batched") and args.shard is not None:
        raise SystemExit("--batched runs every treatment in one process; it cannot be combined with --shard")
    try:
        if cfg.get("batched"):
            archives = run_batched(cfg, todo, pairs, gens, folder, clock, key, mesh)
        else:
            shard = "" if args.shard is None else f" of shard {shard_i}/{shard_n}"
            archives = run_each(cfg, mine, pairs, gens, folder, clock, key, mesh, shard)
    except common.TimeUp:
        shard = "" if args.shard is None else f" --shard {shard_i}/{shard_n}"
        print(f"time limit reached; continue with: {resume_hint}{shard}", flush=True)
        return 3
    if args.shard is not None:
        print(f"shard {shard_i}/{shard_n} done ({len(mine)} of {len(todo)} treatments); once every shard is done, "
              f"write the tables with: {resume_hint}", flush=True)
        return 0
    cov = write_tables(folder, archives, pairs, gens, available, skipped)
    plot_figures(folder, archives, cov, pairs, available)
    print(f"done -> {folder}", flush=True)
    return 0


def run_each(cfg, mine, pairs, gens, folder, clock, key, mesh, shard: str) -> dict:
    """Evolve the treatments ``mine`` ((k, pair, generator) of :func:`treatments`) one after another, each resumed
    or reused from its folder; ``{(generator, pair label): Archive}``. ``common.TimeUp`` at the time limit."""
    import jax

    archives = {}
    ranges = cfg.get("ranges")
    for n, (_, pair, g) in enumerate(mine, 1):
        tcfg = dict(cfg, ranges=None if ranges is None else [ranges[pair[0]], ranges[pair[1]]])
        tkey = jax.random.fold_in(jax.random.fold_in(key, pairs.index(pair)), gens.index(g))
        archives[(g, pair_label(pair))] = evolve_cmd.run_treatment(
            tcfg, g, pair, folder / "archives" / f"{g}__{pair_label(pair)}", clock, tkey,
            label=f"({n}/{len(mine)}{shard}) ", mesh=mesh)
    return archives


def write_tables(folder, archives: dict, pairs, gens, available, skipped: dict) -> dict:
    """Add the combined archive of each pair to ``archives`` (and save it), write ``coverage.csv`` and Table 1
    (``coverage.md``); ``{(generator, pair label): coverage %}``."""
    from jaxterrain import qd as A
    from jaxterrain.runtime.io import atomic_write_text

    rows, cov = [], {}
    for pair in pairs:
        members = [archives[(g, pair_label(pair))] for g in available]
        if members:
            comb = A.combine(members)
            A.save(folder / "archives" / f"combined__{pair_label(pair)}.npz", comb)
            archives[("combined", pair_label(pair))] = comb
        for g in available + (["combined"] if members else []):
            a = archives[(g, pair_label(pair))]
            c = A.coverage(a)
            cov[(g, pair_label(pair))] = c
            f = a.fitness[a.filled]
            rej = int(a.metrics["rejected"].sum()) if "rejected" in a.metrics else ""
            rows.append([g, pair_label(pair), f"{c:.4f}", f"{A.qd_score(a):.4f}",
                         f"{f.max():.4f}" if f.size else "", f"{f.mean():.4f}" if f.size else "", rej])
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["generator", "pair", "coverage_percent", "qd_score", "max_fitness", "mean_fitness", "rejected"])
    w.writerows(rows)
    w.writerows([[g, "", "skipped", why, "", "", ""] for g, why in skipped.items()])
    atomic_write_text(folder / "coverage.csv", buf.getvalue())
    table = markdown_table(cov, gens, pairs, skipped)
    atomic_write_text(folder / "coverage.md", table)
    print(table, flush=True)
    return cov


def plot_figures(folder, archives: dict, cov: dict, pairs, available) -> None:
    """Figure 5 (coverage bars, ``coverage.png``) and Figure 6 (the archives' heatmaps, rows = pairs, columns =
    generators and the combined archive, ``archives.png``)."""
    import matplotlib
    import numpy as np

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jaxterrain import qd as A

    shown = available + (["combined"] if available else [])
    fig, ax = plt.subplots(figsize=(7, 3.5))
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
    common.save_figure(fig, folder / "coverage.png", dpi=150)

    fig, axes = plt.subplots(len(pairs), len(shown), figsize=(2.9 * len(shown) + 1, 2.6 * len(pairs)), squeeze=False,
                             layout="constrained")
    img = None
    for i, pair in enumerate(pairs):
        for j, g in enumerate(shown):
            a = archives[(g, pair_label(pair))]
            img = evolve_cmd.plot_archive(axes[i, j], a, f"{PAPER_NAMES.get(g, g)}: {A.coverage(a):.2f}%")
    if img is not None:
        fig.colorbar(img, ax=axes.ravel().tolist(), shrink=0.6, label="fitness (darker = fitter)")
    for a in axes.ravel():
        a.tick_params(labelsize=6)
    common.save_figure(fig, folder / "archives.png", dpi=130)
