"""Calibrating held-out suite v2 for each robot (issue 61 item 3): a robot's base policy walks every v2 family at a
grid of values and seeds, and the level curves say which values map to mean fitness 0.8 (level 0) .. 0.3 (level 9).

    PYTHONPATH=. python docs/results/suite_v2/calibrate.py --out runs/suite_v2_cal            # GPU: both robots
    PYTHONPATH=. python docs/results/suite_v2/calibrate.py --grid v2 --out runs/suite_v2_check  # v2's own levels
    PYTHONPATH=. python docs/results/suite_v2/calibrate.py --select runs/suite_v2_cal           # CPU: pick levels

``--grid candidates`` (default; ``refined``: the ranges of :data:`REFINED`, narrowed from the first run): each family at ``--values`` (20) values of the robot's candidate range
(:data:`CANDIDATES`: linear where v1's curves located the range, geometric and wider for the re-parametrised
families), ``--seeds`` (5) terrains each: v2's terrains (``suite.v2_terrain``: a seed's layout does not depend on
the value, so a candidate value picked as a level IS that level's terrain, measured). ``--grid v2``: the levels of
``suite.V2_LEVELS`` (the suite as ``suite.load("v2", robot=...)`` builds it, without the generator samples).

The walks: ``suite.evaluate_policies`` with the robot's shipped base policy under the HEADINGS protocol (80 walks a
terrain, best 5 per heading, mean over 4 headings: what ``evaluate --preset gpu`` walks), MJX-JAX by default, one
call per robot (one compile each). Each robot's raw fitness is written when it ends (``fitness_<robot>.csv``) and a
robot already written is not walked again (a run cut short resumes with the same command).

Writes into ``--out``: ``fitness_<robot>.csv`` (robot, family, index, value, unit, seed, fitness),
``curves.csv`` (robot, family, index, value, unit, terrains, mean, sd, min, max), ``timing_<robot>.json``,
``curves.png`` (a panel per family, each robot's mean fitness against the value, 0.8 and 0.3 marked), and a page
per robot, ``calibration_<robot>.md``: for ``--grid v2`` the checks of every family's level curve (level 0 >= 0.8, level 9 <= 0.3, no
rise > 0.03; failures marked); for candidates, the 10 grid values per family that pass (``suite.calibration.
select_levels``), or, where none do, values interpolated on the curve's monotone fit (to measure with ``--grid v2``).
``--select FOLDER`` rewrites the page, figure, ``levels.json`` and ``V2_LEVELS.txt`` (the proposed levels, as the body
of ``heldout.V2_LEVELS`` to paste) from a folder's CSVs on the CPU. At the GPU's size: 10 families x 20 values x 5 seeds + flat = 1001 terrains a robot.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

import numpy as np

from jaxterrain.suite import calibration
from jaxterrain.suite.families import FAMILIES_V2, misfit
from jaxterrain.suite.heldout import ROBOTS, V2_LEVELS, v2_terrain
from jaxterrain.walker import WalkerConfig

CANDIDATES: dict[str, dict[str, tuple[str, float, float]]] = {
    # (spacing, lo, hi): around where v1's curves (docs/results/exp3_gpushort, ant_gpushort) fell from 0.8 to 0.3,
    # about 10 of the 20 values inside that fall (the ant's slope_up fell from 0.99 to 0.11 between grades 0.25 and
    # 0.30); geometric and wide for the families v2 re-parametrised (stairs, gaps, stepping stones, obstacles)
    "humanoid": {
        "slope_up": ("lin", 0.06, 0.22), "slope_down": ("geo", 0.06, 1.0),
        "stairs_up": ("geo", 0.005, 0.2), "stairs_down": ("geo", 0.005, 0.2),
        "boxes": ("lin", 0.02, 0.14), "obstacles": ("geo", 0.01, 0.5),
        "stepping_stones": ("geo", 0.003, 0.4), "gaps": ("geo", 0.003, 0.5),
        "waves": ("geo", 0.02, 0.5), "rough": ("lin", 0.008, 0.09),
    },
    "ant": {
        "slope_up": ("lin", 0.23, 0.32), "slope_down": ("lin", 0.2, 0.6),
        "stairs_up": ("geo", 0.01, 0.2), "stairs_down": ("geo", 0.01, 0.2),
        "boxes": ("geo", 0.08, 1.0), "obstacles": ("geo", 0.05, 0.5),
        "stepping_stones": ("geo", 0.002, 0.3), "gaps": ("geo", 0.002, 0.45),
        "waves": ("lin", 0.12, 0.5), "rough": ("geo", 0.05, 0.35),
    },
}
"""Each robot's candidate range per family: ``(spacing "lin" | "geo", lo, hi)``: the first run's grid."""

REFINED: dict[str, dict[str, tuple[str, float, float]]] = {
    # the first run's curves (one H200, 2026-11-29, MuJoCo Warp; docs/results/suite_v2/): from where each family's
    # monotone fit is about 0.95 to where it is about 0.2 (or flattens, 0.25 for the humanoid), so that the 20
    # values fall where the curve falls; geometric where that span is more than 3x
    "humanoid": {
        "slope_up": ("geo", 0.08, 0.22), "slope_down": ("geo", 0.065, 0.9),
        "stairs_up": ("lin", 0.02, 0.07), "stairs_down": ("geo", 0.019, 0.12),
        "boxes": ("lin", 0.025, 0.13), "obstacles": ("geo", 0.014, 0.3),
        "stepping_stones": ("geo", 0.017, 0.2), "gaps": ("lin", 0.032, 0.18),
        "waves": ("geo", 0.028, 0.4), "rough": ("geo", 0.008, 0.11),
    },
    "ant": {
        "slope_up": ("lin", 0.236, 0.29), "slope_down": ("lin", 0.21, 0.53),
        "stairs_up": ("lin", 0.046, 0.078), "stairs_down": ("lin", 0.085, 0.16),
        "boxes": ("lin", 0.15, 0.45), "obstacles": ("lin", 0.12, 0.32),
        "stepping_stones": ("lin", 0.06, 0.22), "gaps": ("lin", 0.1, 0.2),
        "waves": ("lin", 0.17, 0.4), "rough": ("geo", 0.05, 0.16),
    },
}
"""The second run's grid (``--grid refined``): each robot's range narrowed to where the first run's curve fell."""
GRIDS = {"candidates": CANDIDATES, "refined": REFINED}

SEEDS, VALUES = 5, 20


def grid_values(spec: tuple[str, float, float], n: int) -> np.ndarray:
    """[n] increasing values of a candidate range ``(spacing, lo, hi)``: evenly spaced, or in ``log`` for "geo",
    each rounded to 4 significant digits (so that the CSVs, which write 6, hold the exact value a level is built
    from)."""
    kind, lo, hi = spec
    v = np.geomspace(lo, hi, n) if kind == "geo" else np.linspace(lo, hi, n)
    return np.array([float(f"{x:.4g}") for x in v])


def parse_range(text: str) -> tuple[str, tuple[str, float, float]]:
    """``"FAMILY=SPACING:LO:HI"`` (e.g. ``slope_up=geo:0.3:1.0``) as ``(family, (spacing, lo, hi))``; ValueError in
    one line naming what is wrong (an unknown or ungraded family, a spacing other than lin / geo, bounds outside the
    family's range of :data:`~jaxterrain.suite.families.FAMILIES_V2` or not increasing)."""
    fam, _, spec = text.partition("=")
    parts = spec.split(":")
    if fam not in FAMILIES_V2 or FAMILIES_V2[fam].levels == 1:
        graded = ", ".join(f for f, x in FAMILIES_V2.items() if x.levels > 1)
        raise ValueError(f"--range {text}: FAMILY must be one of {graded}")
    if len(parts) != 3 or parts[0] not in ("lin", "geo"):
        raise ValueError(f"--range {text}: give FAMILY=lin|geo:LO:HI")
    try:
        lo, hi = float(parts[1]), float(parts[2])
    except ValueError:
        raise ValueError(f"--range {text}: LO and HI must be numbers") from None
    f = FAMILIES_V2[fam]
    if not f.lo <= lo < hi <= f.hi:
        raise ValueError(f"--range {text}: need {f.lo:g} <= LO < HI <= {f.hi:g} ({fam}'s {f.unit} in v2)")
    return fam, (parts[0], lo, hi)


def plan(robot: str, grid: str, values: int, families, ranges: dict | None = None) -> dict[str, np.ndarray]:
    """``{family: [values] the values walked}`` for ``robot`` (``flat``: its one value); ``ranges`` ``{family:
    (spacing, lo, hi)}`` replaces the grid's range of those families (``--range``; not for ``--grid v2``)."""
    out = {}
    for f in families:
        if FAMILIES_V2[f].levels == 1:
            out[f] = np.zeros(1)
        elif grid == "v2":
            out[f] = np.asarray(V2_LEVELS[robot][f], np.float64)
        else:
            out[f] = grid_values((ranges or {}).get(f) or GRIDS[grid][robot][f], values)
    return out


def build(robot: str, grid: str, values: int, seeds: int, size: int, families, ranges: dict | None = None):
    """``(heightmaps [N, size, size], rows [(family, index, value, unit, seed)])``: v2's terrains of the plan."""
    maps, rows = [], []
    for f, vals in plan(robot, grid, values, families, ranges).items():
        for i, v in enumerate(vals):
            for s in range(seeds if FAMILIES_V2[f].levels > 1 else 1):
                maps.append(v2_terrain(f, float(v), s, size))
                rows.append((f, i, float(v), FAMILIES_V2[f].unit, s))
    return np.stack(maps).astype(np.float32), rows


def walk(robot: str, args, out: Path) -> None:
    """Walk ``robot``'s base policy on its plan and write ``fitness_<robot>.csv`` and ``timing_<robot>.json``."""
    import jax

    from jaxterrain import difficulty, suite
    from jaxterrain.runtime import provenance
    from jaxterrain.runtime.io import atomic_write_csv, atomic_write_text

    t0 = time.perf_counter()
    policy = difficulty.robot_base_policy(robot)
    maps, rows = build(robot, args.grid, args.values, args.seeds, args.size, args.families, args.ranges)
    build_s = time.perf_counter() - t0
    protocol = difficulty.Protocol(args.attempts, args.best, args.headings)
    print(f"{robot}: {len(rows)} terrains at {args.size} px built in {build_s:.1f} s; walking {protocol.attempts} "
          f"walks each on {args.backend}", flush=True)
    t1 = time.perf_counter()
    key = jax.random.fold_in(jax.random.key(args.seed), ROBOTS.index(robot) if robot in ROBOTS else 99)
    fit = suite.evaluate_policies([policy], maps, key, protocol, args.backend, None, args.slots, args.chunk)[0]
    walk_s = time.perf_counter() - t1
    atomic_write_csv(out / f"fitness_{robot}.csv", ["robot", "family", "index", "value", "unit", "seed", "fitness"],
                     [(robot, f, i, f"{v:.6g}", u, s, f"{x:.4f}") for (f, i, v, u, s), x in zip(rows, fit)])
    timing = {"robot": robot, "grid": args.grid, "terrains": len(rows), "size": args.size,
              "protocol": protocol._asdict(), "backend": args.backend, "slots": args.slots, "build_s": round(build_s, 2),
              "ranges": {f: list(r) for f, r in args.ranges.items()},
              **({"warp_hfield": provenance.warp_hfield()} if args.backend == "warp" else {}),
              "spawn": WalkerConfig().spawn,  # the rule the walks spawn by (the library default)
              "walk_s_with_compile": round(walk_s, 2), "device": provenance.device(),
              "commit": provenance.git_commit(short=True)}
    atomic_write_text(out / f"timing_{robot}.json", json.dumps(timing, indent=2) + "\n")
    print(f"{robot}: walked in {walk_s:.1f} s (compile included); mean fitness {fit.mean():.3f}", flush=True)


def read_fitness(out: Path) -> dict[str, dict[str, list]]:
    """``{robot: {family: [(index, value, unit, [fitness per seed])]}}`` from ``fitness_<robot>.csv``."""
    data: dict = {}
    for path in sorted(out.glob("fitness_*.csv")):
        with path.open() as fh:
            for r in csv.DictReader(fh):
                fam = data.setdefault(r["robot"], {}).setdefault(r["family"], {})
                entry = fam.setdefault(int(r["index"]), [float(r["value"]), r["unit"], []])
                entry[2].append(float(r["fitness"]))
    return {rb: {f: [(i, *e) for i, e in sorted(d.items())] for f, d in fams.items()} for rb, fams in data.items()}


def summarise(out: Path, grid: str) -> None:
    """``curves.csv``, ``curves.png``, ``levels.json`` and a ``calibration_<robot>.md`` per robot from the folder's fitness files."""
    from jaxterrain.runtime.io import atomic_write_csv, atomic_write_text

    data = read_fitness(out)
    if not data:
        raise SystemExit(f"{out}: no fitness_<robot>.csv to summarise")
    rows = []
    for rb, fams in data.items():
        for f, pts in fams.items():
            for i, v, u, fit in pts:
                a = np.asarray(fit)
                rows.append((rb, f, i, f"{v:.6g}", u, a.size, f"{a.mean():.4f}", f"{a.std(ddof=1) if a.size > 1 else 0:.4f}",
                             f"{a.min():.4f}", f"{a.max():.4f}"))
    atomic_write_csv(out / "curves.csv", ["robot", "family", "index", "value", "unit", "terrains", "mean", "sd", "min",
                                          "max"], rows)
    timing = {p.stem.split("_", 1)[1]: json.loads(p.read_text()) for p in sorted(out.glob("timing_*.json"))}
    chosen, pages = {}, {}
    for rb, fams in data.items():
        t = timing.get(rb, {})
        lines = pages[rb] = []
        ranges = "".join(f"; {f} over {r[1]:g} .. {r[2]:g} ({r[0]})" for f, r in t.get("ranges", {}).items())
        lines += [f"{t.get('terrains', '?')} terrains ({t.get('grid', grid)} grid{ranges}), walked on "
                  f"{t.get('device', '?')} at commit {t.get('commit', '?')}, {t.get('backend', '?')}, "
                  f"{t.get('walk_s_with_compile', '?')} s with the compile; build {t.get('build_s', '?')} s.", ""]
        lines += ["| family | unit | values walked | level 0 | last level | largest rise (at level) | checks | "
                  "levels (value: mean fitness) |", "|---|---|---|---|---|---|---|---|"]
        chosen[rb] = {}
        for f, pts in fams.items():
            vals = np.array([p[1] for p in pts])
            means = np.array([np.mean(p[3]) for p in pts])
            unit = pts[0][2]
            if vals.size == 1:
                lines.append(f"| {f} | {unit} | 1 | {means[0]:.3f} | - | - | - | - |")
                continue
            if grid == "v2":
                idx, note = np.arange(vals.size), "v2's levels"
            else:
                idx = calibration.select_levels(vals, means)
                note = "measured grid values"
            if idx is not None:
                c = calibration.check_curve(means[idx])
                chosen[rb][f] = {"values": [float(x) for x in vals[idx]], "measured": True}
                marks = "pass" if c["ok"] else "**FAIL**: " + ", ".join(
                    k for k, ok in (("level 0 < 0.8", c["ok_level0"]), ("last > 0.3", c["ok_last"]),
                                    ("rise > 0.03", c["ok_rises"])) if not ok)
                levels = "; ".join(f"{x:.4g}: {m:.2f}" for x, m in zip(vals[idx], means[idx]))
                lines.append(f"| {f} | {unit} | {vals.size} | {c['level0']:.3f} | {c['last']:.3f} | "
                             f"{c['max_rise']:+.3f} ({c['rise_at']}) | {marks} ({note}) | {levels} |")
            else:
                spec = t.get("ranges", {}).get(f) or GRIDS.get(grid, CANDIDATES).get(rb, {}).get(f, ("lin",))
                geo = spec[0] == "geo" and vals[0] > 0
                prop = calibration.propose_values(vals, means, geometric=geo)
                if prop is None:
                    why = "**FAIL**: the grid does not span 0.88 .. 0.22 (range " + \
                          f"{means.max():.2f} .. {means.min():.2f}): widen it"
                    chosen[rb][f] = {"values": None, "measured": False}
                else:
                    why = "**not measured**: no 10 grid values pass; values interpolated on the monotone fit"
                    chosen[rb][f] = {"values": [round(float(x), 4) for x in prop], "measured": False}
                curve = "; ".join(f"{x:.4g}: {m:.2f}" for x, m in zip(vals, means))
                lines.append(f"| {f} | {unit} | {vals.size} | {means[0]:.3f} | {means[-1]:.3f} | - | {why} | "
                             f"grid: {curve} |")
        lines.append("")
    for rb, lines in pages.items():
        head = [f"# Held-out suite v2: calibration for the {rb}", "",
                f"The {rb}'s shipped base policy on v2's terrains; a family's level curve passes when level 0 has mean "
                "fitness >= 0.8, the last level <= 0.3, and no level is above the one before by more than 0.03 "
                "(issue 61). Mean over each value's terrains (seeds). Written by "
                f"`docs/results/suite_v2/calibrate.py` ({grid} grid); the figure shows every robot of the run.", "",
                "![level curves](curves.png)", ""]
        atomic_write_text(out / f"calibration_{rb}.md", "\n".join(head + lines))
    atomic_write_text(out / "levels.json", json.dumps(chosen, indent=2) + "\n")
    atomic_write_text(out / "V2_LEVELS.txt", levels_literal(chosen))
    figure(out, data, chosen)
    print(f"-> {', '.join(str(out / f'calibration_{rb}.md') for rb in pages)}", flush=True)


def levels_literal(chosen: dict) -> str:
    """``chosen`` (``levels.json``) as the body of ``heldout.V2_LEVELS`` to paste (families with no values left out,
    unmeasured ones marked), wrapped at 120 columns."""
    import textwrap

    lines = []
    for rb, fams in chosen.items():
        lines.append(f'    "{rb}": {{')
        for f, e in fams.items():
            if not e["values"]:
                lines.append(f"        # {f}: no values (widen its range)")
                continue
            text = f'"{f}": (' + ", ".join(repr(v) for v in e["values"]) + "),"
            text += "" if e["measured"] else "  # NOT MEASURED: interpolated"
            lines += textwrap.wrap(text, 118, initial_indent=" " * 8, subsequent_indent=" " * 12)
        lines.append("    },")
    return "\n".join(lines) + "\n"


def figure(out: Path, data, chosen) -> None:
    from matplotlib.figure import Figure
    from matplotlib.ticker import NullFormatter

    from jaxterrain.runtime.io import save_figure

    fams = [f for f in FAMILIES_V2 if any(f in d and len(d[f]) > 1 for d in data.values())]
    if not fams:
        return
    cols = min(5, len(fams))
    rowsn = -(-len(fams) // cols)
    fig = Figure(figsize=(3.0 * cols, 2.6 * rowsn), layout="constrained")
    axes = np.atleast_1d(fig.subplots(rowsn, cols, squeeze=False)).ravel()
    for ax, f in zip(axes, fams):
        for c, (rb, d) in enumerate(data.items()):
            if f not in d:
                continue
            v = np.array([p[1] for p in d[f]])
            fit = [np.asarray(p[3]) for p in d[f]]
            m = np.array([a.mean() for a in fit])
            ax.fill_between(v, [a.min() for a in fit], [a.max() for a in fit], color=f"C{c}", alpha=0.15, lw=0)
            ax.plot(v, m, "o-", color=f"C{c}", ms=3, lw=1, label=rb)
            pick = (chosen.get(rb, {}).get(f) or {}).get("values")
            if pick:
                ax.plot(pick, np.interp(pick, v, m), "x", color=f"C{c}", ms=6)
        ax.axhline(calibration.LEVEL0, color="grey", lw=0.6, ls="--")
        ax.axhline(calibration.LAST, color="grey", lw=0.6, ls="--")
        ax.set_ylim(-0.02, 1.02)
        if any(v[0] > 0 and v[-1] / v[0] > 3 for v in ([p[1] for p in d[f]] for d in data.values() if f in d)):
            ax.set_xscale("log")
            ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_title(f"{f} ({FAMILIES_V2[f].unit})", fontsize=8)
        ax.tick_params(labelsize=6)
    for ax in axes[len(fams):]:
        ax.set_visible(False)
    axes[0].legend(fontsize=6)
    fig.suptitle("v2 level curves: base policy mean fitness (band: min-max over seeds; x: levels picked)", fontsize=9)
    save_figure(fig, out / "curves.png")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=Path("runs/suite_v2_calibration"))
    p.add_argument("--robots", nargs="+", default=list(ROBOTS), help="robots to calibrate (default: both)")
    p.add_argument("--grid", choices=("candidates", "refined", "v2"), default="candidates",
                   help="candidates: the first run's wide ranges; refined: the ranges narrowed from its curves; v2: "
                        "v2's levels")
    p.add_argument("--values", type=int, default=VALUES, help="candidate values per family (default 20)")
    p.add_argument("--seeds", type=int, default=SEEDS, help="terrains per value (default 5)")
    p.add_argument("--size", type=int, default=256, help="terrain side in pixels (v2: 256)")
    p.add_argument("--families", nargs="+", default=list(FAMILIES_V2), help="families (default: all of v2's)")
    p.add_argument("--attempts", type=int, default=80)
    p.add_argument("--best", type=int, default=5)
    p.add_argument("--headings", type=int, choices=(1, 2, 4), default=4)
    p.add_argument("--backend", choices=("jax", "warp"), default="jax")
    p.add_argument("--slots", type=int, default=16384, help="rollout pool (default 16384; 0: all walks at once)")
    p.add_argument("--chunk", type=int, default=None)
    p.add_argument("--seed", type=int, default=0, help="the evaluation key's seed")
    p.add_argument("--range", action="append", default=[], metavar="FAMILY=SPACING:LO:HI", dest="range_",
                   help="replace the grid's range of one family (repeatable), e.g. slope_up=geo:0.3:1.0; recorded "
                        "in timing_<robot>.json (not with --grid v2)")
    p.add_argument("--select", type=Path, default=None, metavar="FOLDER",
                   help="only rewrite FOLDER's page, figure and levels.json from its fitness CSVs (CPU)")
    args = p.parse_args(argv)
    if args.select is not None:
        if not args.select.is_dir():
            p.error(f"--select {args.select}: no such folder")
        grids = {json.loads(t.read_text()).get("grid") for t in args.select.glob("timing_*.json")}
        summarise(args.select, grids.pop() if len(grids) == 1 else args.grid)
        return 0
    try:
        args.ranges = dict(parse_range(r) for r in args.range_)
    except ValueError as err:
        p.error(str(err))
    if args.ranges and args.grid == "v2":
        p.error("--range: not with --grid v2 (v2's levels are walked as they are)")
    bad = [r for r in args.robots if r not in V2_LEVELS]
    if bad:
        p.error(f"--robots: unknown {', '.join(bad)}; choose from {', '.join(V2_LEVELS)}")
    bad = [f for f in args.families if f not in FAMILIES_V2]
    if bad:
        p.error(f"--families: unknown {', '.join(bad)}; choose from {', '.join(FAMILIES_V2)}")
    for name, lo in (("values", 2), ("seeds", 1), ("size", 32), ("attempts", 1), ("best", 1)):
        if getattr(args, name) < lo:
            p.error(f"--{name} must be an integer >= {lo}; got {getattr(args, name)}")
    if args.best > args.attempts // args.headings:
        p.error(f"--best must be <= attempts / headings = {args.attempts // args.headings}; got {args.best}")
    if args.slots < 0:
        p.error(f"--slots must be >= 0 (0: all walks at once); got {args.slots}")
    args.slots = args.slots or None
    for f in args.families:
        why = misfit(f, args.size, version="v2")
        if why:
            print(f"calibrate: {f} does not fit {args.size} pixels ({why}); built cut down", file=sys.stderr)
    args.out.mkdir(parents=True, exist_ok=True)
    for robot in args.robots:
        done = args.out / f"timing_{robot}.json"
        if done.is_file() and json.loads(done.read_text()).get("grid") != args.grid:
            p.error(f"--out {args.out}: {robot} was walked on another grid there; give another --out")
        if (args.out / f"fitness_{robot}.csv").is_file():
            print(f"{robot}: {args.out / f'fitness_{robot}.csv'} exists; not walked again", flush=True)
            continue
        walk(robot, args, args.out)
    summarise(args.out, args.grid)
    return 0


if __name__ == "__main__":
    sys.exit(main())
