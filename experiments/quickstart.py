"""``python -m experiments quickstart``: a small end-to-end run on CPU.

Samples terrains from every available generator, renders them, computes the paper's descriptors (TRI, TPI,
roughness at window 30, stride 2) and Algorithm 1, walks the first ``--walk`` terrains of each generator with the
shipped base policy (``difficulty.evaluate``: ``--attempts`` walks each, fitness = mean of the best ``--best``), and
writes into a new run folder:

- ``terrains.png``     a grid of sample terrains, one row per generator
- ``descriptors.csv``  generator, genome index, tri, tpi, roughness, traversable, fitness (empty if not walked)
- ``descriptors.png``  the descriptor pairs of Experiment 1, one colour per generator
- ``difficulty.png``   difficulty (1 - fitness) against each descriptor, with Pearson r (Experiment 1a in small)
- ``summary.md``       per-generator means and timings
- ``config.json``      the options of this run
- ``report/``          ``report.html`` (one self-contained page of all of the above, with GIFs of the base policy
  walking the easiest, the median and the hardest walked terrain, rendered by MuJoCo through OSMesa on a CPU) and
  its Markdown twin ``report.md`` (``python -m experiments report``; without OpenGL the page says why the videos
  are missing)
"""

from __future__ import annotations

import argparse
from typing import Any, NamedTuple

from experiments import common
from experiments.common import UsageError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    common.add_terrains_argument(parser, "n", "their descriptors and figures; --walk of them are walked",
                                 default=32, aliases=("--n",))
    parser.add_argument("--size", type=int, default=256, help="heightmap side in pixels (32..1024)")
    parser.add_argument("--seed", type=int, default=0, help="PRNG seed of the terrains and walks")
    parser.add_argument("--generators", nargs="*", default=None,
                        help="generator names (default: every generator that loads)")
    parser.add_argument("--walk", type=int, default=4,
                        help="terrains per generator walked by the base policy (0: none)")
    parser.add_argument("--attempts", type=int, default=None,
                        help="walks per walked terrain (default 8; the paper: 20)")
    parser.add_argument("--best", type=int, default=None,
                        help="fitness = mean of the best this many walks (default 2; the paper: 5)")
    parser.add_argument("--out", default=None, help="run folder (default runs/quickstart-<time>)")
    parser.add_argument("--report", action=argparse.BooleanOptionalAction, default=True,
                        help="write report/, the HTML page (--no-report: leave it out)")
    parser.add_argument("--report-frames", type=int, default=None,
                        help="frames per walker video in the report (default 60; 0: a report without videos)")


DEFAULTS = {"attempts": 8, "best": 2, "report_frames": 60}
"""The values of the options whose default is None (not given), so that a flag the run would ignore is refused:
``--attempts`` / ``--best`` with ``--walk 0``, ``--report-frames`` with ``--no-report``."""


def check_flags(args: argparse.Namespace) -> None:
    """Flags this run would accept and ignore refused (:class:`~experiments.common.UsageError`), then the defaults
    of :data:`DEFAULTS` filled in (``config.json`` records them as before)."""
    if args.walk == 0:
        common.refuse_given({"--attempts": args.attempts, "--best": args.best},
                            "sets the walks, which --walk 0 leaves out: drop one of them")
    if not args.report:
        common.refuse_given({"--report-frames": args.report_frames},
                            "sets the report's videos, which --no-report leaves out: drop one of them")
    for key, value in DEFAULTS.items():
        if getattr(args, key) is None:
            setattr(args, key, value)


NAMES = ("tri", "tpi", "roughness")


class Sample(NamedTuple):
    """One generator's share of the quickstart: maps [n, S, S], descriptors [n, 3], traversable [n], render s,
    fitness [k] of the first k <= n terrains (None when not walked)."""

    maps: Any
    descriptors: Any
    traversable: Any
    render_s: float
    fitness: Any = None


def sample_generator(gen, key, n: int, size: int) -> Sample:
    """Render ``n`` random terrains of ``gen`` and describe them (window 30, or size / 4 on small maps)."""
    import time

    import jax
    import numpy as np

    from jaxterrain import features

    genomes = gen.sample(key, n)
    t0 = time.perf_counter()
    hm = jax.block_until_ready(gen.render(genomes))
    render_s = time.perf_counter() - t0
    window = min(30, size // 4)
    return Sample(np.asarray(hm), np.asarray(features.descriptors(hm, NAMES, window=window, stride=2)),
                  np.asarray(features.is_traversable(hm)), render_s)


def plot_terrains(samples: dict[str, Sample], path, cols: int = 6) -> None:
    """A grid of sample terrains, one row per generator."""
    import matplotlib.pyplot as plt

    from experiments.common import save_figure

    cols = min(cols, min(len(s.maps) for s in samples.values()))
    fig, axes = plt.subplots(len(samples), cols, figsize=(2 * cols, 2 * len(samples)), squeeze=False)
    for r, (name, s) in enumerate(samples.items()):
        for c in range(cols):
            ax = axes[r, c]
            ax.imshow(s.maps[c], cmap="terrain", vmin=0, vmax=1)
            ax.set_xticks([]), ax.set_yticks([])
            if c == 0:
                ax.set_ylabel(name)
    fig.tight_layout()
    save_figure(fig, path, dpi=80)


def plot_descriptor_pairs(samples: dict[str, Sample], path) -> None:
    """The three descriptor pairs of Experiment 1, one colour per generator."""
    import matplotlib.pyplot as plt

    from experiments.common import save_figure

    pairs = [("tri", "tpi"), ("tri", "roughness"), ("tpi", "roughness")]
    fig, axes = plt.subplots(1, 3, figsize=(12, 4))
    for ax, (a, b) in zip(axes, pairs):
        for name, s in samples.items():
            ax.scatter(s.descriptors[:, NAMES.index(a)], s.descriptors[:, NAMES.index(b)], s=8, label=name)
        ax.set_xlabel(a), ax.set_ylabel(b)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, path, dpi=80)


def walk(samples: dict[str, Sample], k: int, attempts: int, best: int, key) -> tuple[dict[str, Sample], float]:
    """Fitness of the first ``k`` terrains of every sample in ONE batched ``difficulty.evaluate`` call (one compile).

    Returns the samples with ``fitness`` set and the seconds taken (compile included).
    """
    import time

    import numpy as np

    from jaxterrain import difficulty

    counts = {name: min(k, len(s.maps)) for name, s in samples.items()}
    maps = np.concatenate([s.maps[:counts[name]] for name, s in samples.items()])
    t0 = time.perf_counter()
    fitness = np.asarray(difficulty.evaluate(maps, key, attempts=attempts, best=best))
    seconds = time.perf_counter() - t0
    out, start = {}, 0
    for name, s in samples.items():
        out[name] = s._replace(fitness=fitness[start:start + counts[name]])
        start += counts[name]
    return out, seconds


def plot_difficulty(samples: dict[str, Sample], path) -> None:
    """Difficulty (1 - fitness) of the walked terrains against each descriptor, Pearson r over all of them."""
    import matplotlib.pyplot as plt
    import numpy as np

    from experiments.common import save_figure

    walked = {name: s for name, s in samples.items() if s.fitness is not None and len(s.fitness)}
    difficulty = np.concatenate([1.0 - s.fitness for s in walked.values()])
    fig, axes = plt.subplots(1, 3, figsize=(12, 4))
    for i, (ax, d) in enumerate(zip(axes, NAMES)):
        x = np.concatenate([s.descriptors[:len(s.fitness), i] for s in walked.values()])
        for name, s in walked.items():
            ax.scatter(s.descriptors[:len(s.fitness), i], 1.0 - s.fitness, s=14, label=name)
        r = np.corrcoef(x, difficulty)[0, 1] if len(x) > 2 and np.std(x) > 0 and np.std(difficulty) > 0 else np.nan
        ax.set_xlabel(d), ax.set_ylabel("difficulty (1 - fitness)"), ax.set_ylim(-0.05, 1.05)
        ax.set_title(f"Pearson r = {r:.2f} (n = {len(x)})", fontsize=9)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, path, dpi=80)


def descriptors_csv(samples: dict[str, Sample]) -> str:
    import csv
    import io

    out = io.StringIO()
    w = csv.writer(out)
    w.writerow(["generator", "index", *NAMES, "traversable", "fitness"])
    for name, s in samples.items():
        fitness = [] if s.fitness is None else s.fitness
        for i, row in enumerate(s.descriptors):
            w.writerow([name, i, *(f"{v:.6g}" for v in row), int(s.traversable[i]),
                        f"{fitness[i]:.4f}" if i < len(fitness) else ""])
    return out.getvalue()


def summary_markdown(samples: dict[str, Sample], skipped: dict[str, str], args: argparse.Namespace,
                     walk_note: str = "") -> str:
    lines = [f"# quickstart ({args.n} terrains per generator, {args.size} x {args.size}, seed {args.seed})", "",
             "| generator | mean TRI | mean TPI | mean roughness | traversable | mean fitness (walked) | "
             "render time (s, incl. compile) |",
             "|---|---|---|---|---|---|---|"]
    for name, s in samples.items():
        m = s.descriptors.mean(0)
        fit = "-" if s.fitness is None else f"{s.fitness.mean():.3f} ({len(s.fitness)})"
        lines.append(f"| {name} | {m[0]:.4g} | {m[1]:.4g} | {m[2]:.4g} | {s.traversable.mean():.0%} | {fit} | "
                     f"{s.render_s:.2f} |")
    lines += [f"| {name} | skipped: {why} | | | | | |" for name, why in skipped.items()]
    walked = any(s.fitness is not None for s in samples.values())
    files = "terrains.png, descriptors.png, descriptors.csv" + (", difficulty.png" if walked else "")
    lines += ["", walk_note, "", f"Files: {files}, config.json.", ""]
    return "\n".join(lines)


def report_terrains(samples: dict[str, Sample]) -> list[tuple[str, str, Any]]:
    """``(label, caption, heightmap)`` of the easiest, median and hardest walked terrain (fewer when fewer were
    walked), for the report's videos."""
    import numpy as np

    walked = [(float(f), name, i) for name, s in samples.items() if s.fitness is not None
              for i, f in enumerate(s.fitness)]
    if not walked:
        return []
    walked.sort(key=lambda t: -t[0])
    picks = {"easy": walked[0]}
    if len(walked) >= 3:
        picks["medium"] = walked[len(walked) // 2]
    if len(walked) >= 2:
        picks["hard"] = walked[-1]
    return [(label, f"{name} terrain {i}, fitness {f:.3f}", np.asarray(samples[name].maps[i]))
            for label, (f, name, i) in picks.items()]


def write_report(run, samples: dict[str, Sample], frames: int) -> None:
    """``run/report/``: the page of this run, with videos of the walked terrains unless ``frames`` is 0."""
    import time

    from jaxterrain.report import write_report as write

    t0 = time.perf_counter()
    path = write([run], run / "report", title=f"jaxterrain quickstart: {run.name}", videos=frames > 0,
                 video_frames=max(frames, 1), video_size=(240, 180), thumb=64,
                 extra_terrains={run: report_terrains(samples)}, progress=lambda s: print(s, flush=True))
    print(f"report {path} ({time.perf_counter() - t0:.0f} s)", flush=True)


def main(args: argparse.Namespace) -> int:
    from jaxterrain.report import render

    render.setup_gl()  # MuJoCo's OpenGL backend (osmesa / egl) must be chosen before mujoco is imported
    import jax

    from experiments.common import record_provenance, run_folder, write_config
    from jaxterrain import generators
    from jaxterrain.runtime.io import atomic_write_text

    check_flags(args)
    if args.n < 1:
        raise UsageError("--terrains must be >= 1")
    if not 32 <= args.size <= 1024:
        raise UsageError("--size must be in [32, 1024]")
    if args.walk < 0:
        raise UsageError(f"--walk must be >= 0, got {args.walk}")
    if args.attempts < 1 or not 1 <= args.best <= args.attempts:
        raise UsageError(f"--attempts must be >= 1 and --best in [1, attempts], got {args.attempts} / {args.best}")
    if args.report_frames < 0:
        raise UsageError(f"--report-frames must be >= 0, got {args.report_frames}")
    run = run_folder("quickstart", args.out)
    run.mkdir(parents=True, exist_ok=True)
    write_config(run, vars(args))
    record_provenance(run, "quickstart", vars(args))

    key = jax.random.key(args.seed)
    samples, skipped = {}, {}
    for name in args.generators or generators.names():
        try:
            gen = generators.get(name, size=args.size)
        except Exception as err:  # e.g. GAN weights not shipped
            skipped[name] = str(err).splitlines()[0]
            print(f"skip {name}: {skipped[name]}")
            continue
        key, sample_key = jax.random.split(key)
        samples[name] = s = sample_generator(gen, sample_key, args.n, args.size)
        print(f"{name:15s} {args.n} terrains rendered in {s.render_s:.2f} s (incl. compile); "
              f"traversable {s.traversable.mean():.0%}", flush=True)
    if not samples:
        raise UsageError("no generator could be loaded")

    walk_note = "Not walked (--walk 0)."
    if args.walk > 0:
        from jaxterrain.runtime import estimates

        estimates.announce("walks", f"{args.walk} terrains of each generator, {args.attempts} walks each")
        try:
            samples, seconds = walk(samples, args.walk, args.attempts, args.best, jax.random.fold_in(key, 1))
        except RuntimeError as err:  # the base policy is not shipped
            walk_note = f"Not walked: {str(err).splitlines()[0]}"
            print(walk_note, flush=True)
        else:
            from jaxterrain import difficulty, walker
            from jaxterrain.terrain import TerrainScale

            env_config = difficulty.default_env_config((args.size, args.size), TerrainScale(),
                                                       difficulty.default_policy())  # what evaluate walked under
            solver = walker.solver_label(env_config.solver)
            walk_note = (f"Fitness: the shipped base policy ({solver}) walked the first {args.walk} terrains of "
                         f"each generator {args.attempts} times; fitness = mean normalised distance of the best "
                         f"{args.best}, difficulty = 1 - fitness ({seconds:.1f} s incl. compile).")
            print(f"walked {sum(len(s.fitness) for s in samples.values())} terrains x {args.attempts} attempts in "
                  f"{seconds:.1f} s (incl. compile)", flush=True)
            plot_difficulty(samples, run / "difficulty.png")
    plot_terrains(samples, run / "terrains.png")
    plot_descriptor_pairs(samples, run / "descriptors.png")
    atomic_write_text(run / "descriptors.csv", descriptors_csv(samples))
    atomic_write_text(run / "summary.md", summary_markdown(samples, skipped, args, walk_note))
    print(f"wrote {run}", flush=True)
    if args.report:
        write_report(run, samples, args.report_frames)
    return 0
