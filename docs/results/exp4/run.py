"""Experiment 4 (issue 64 item 4): do evolved curricula teach climbing? Every stage resumable, each command <= 10 min.

    PYTHONPATH=. python docs/results/exp4/run.py --plan                                  # CPU: done / predicted minutes
    PYTHONPATH=. python docs/results/exp4/run.py archive mixed --time-limit 8 --pack $OUT/exp4.tar.gz     # one H200
    PYTHONPATH=. python docs/results/exp4/run.py train humanoid blind --time-limit 8 --pack $OUT/exp4.tar.gz
    PYTHONPATH=. python docs/results/exp4/run.py train humanoid perceptive --time-limit 8 --pack $OUT/exp4.tar.gz
    PYTHONPATH=. python docs/results/exp4/run.py archive steps --robot ant --time-limit 8 ...     # the ant's archives
    PYTHONPATH=. python docs/results/exp4/run.py train ant --ant perceptive/mixed-map blind/steps-map --time-limit 8 ...
    PYTHONPATH=. python docs/results/exp4/run.py train humanoid perceptive --scan-lr-scale 0.1 --treatments ...
    PYTHONPATH=. python docs/results/exp4/run.py evaluate --time-limit 8 --pack $OUT/exp4.tar.gz   # v2, then v1
    PYTHONPATH=. python docs/results/exp4/run.py write                                   # CPU: docs/results/exp4/

Call a stage again (the same command) until it prints ``done``: each resumes what ``--out`` holds (default
``runs/exp4``). On a fresh machine, unpack the last ``--pack`` tar in the repository root first (``tar xzf FILE``).

Stages (:data:`STAGES`):

- ``archive GEN [--robot R]`` (GEN: ``steps`` or ``mixed``): ``evolve --preset P --generator GEN`` into
  ``OUT/archive/<robot>-<gen>/`` (``--resume`` when there), with the flags of :data:`ARCHIVE_FLAGS` at ``gpu-short``
  (those docs/results/mixed_archive.md names for the mixed archive) and ``--robot ant`` for the ant. The
  humanoid's ``steps`` archive at ``gpu-short`` ships (``docs/results/steps_gpushort/archive.npz``): nothing runs.
- ``train humanoid OBS`` (OBS: ``blind`` / ``perceptive``): ONE ``curriculum`` run, ``OUT/train/humanoid-OBS/``,
  its five treatments (:data:`TREATMENTS`) in three populations (the two map treatments, DR and PLR, terrain levels:
  ``curriculum``'s grouping): the map curriculum on the steps archive and on
  the mixed archive, domain randomisation, PLR and terrain levels on the mixed archive (``--archives steps=.. mixed=..
  --baseline dr plr levels --baseline-archive mixed --no-combined --observation OBS``), ``--trials`` (10) trials each.
  ``--shard I/N`` runs process I's share of that run (``curriculum --shard``: whole populations, balanced), so that N
  processes, one per GPU, share it (on a 2 x H200: process 0 the two map treatments, then terrain levels; process 1
  DR and PLR, one population); the same train without ``--shard`` then writes the tables.
- ``train ant --ant OBS/TREATMENT OBS/TREATMENT``: the two treatments chosen after looking at the humanoid's
  results, each a ``learn --robot ant`` run on the ant's own archive (``archive GEN --robot ant`` first; an archive's
  fitness is one robot's), ``OUT/train/ant-OBS/TREATMENT/``. The choice is saved in ``OUT/ant.json``; later stages
  read it. ``--shard I/N`` trains only the I-th, (I+N)-th, ... of the ``--ant`` treatments (one per GPU).
- ``train humanoid perceptive --scan-lr-scale C --treatments T [T ...]`` (C finite, > 0, not 1): the perceptive
  humanoid's treatments retrained with the height scan's first-layer Adam steps scaled by C (``learn
  --scan-lr-scale``; docs/results/exp4/scan_diag/README.md), each a ``learn --robot humanoid --observation
  perceptive`` run on the humanoid's archive of T's generator with T's curriculum (the same config as the
  ``curriculum`` run's treatment but for the scale), ``OUT/train/humanoid-perceptive-scan<C>/T/``. The choice is
  saved in ``OUT/scan.json`` (one per ``--out``); later stages read it: ``evaluate`` walks its walkers (the
  perceptive base policy's walks are the ones already there), ``write`` writes its pages against the perceptive
  base policy and a comparison page per suite (each T retrained, at scale 1 and blind:
  ``humanoid-perceptive-scan<C>/<suite>-compare/``). ``--shard I/N`` as for the ant. Without
  ``--scan-lr-scale``, ``train humanoid perceptive`` is the original ``curriculum`` run above.
- ``evaluate [--part K/N]``: every walker of the train runs and each robot's shipped base policies, blind and perceptive, with
  ``--keys`` (10) evaluation keys, on suite v2 and then v1 (``suite.load(V, robot=...)``), through
  ``docs/results/suite_v2/reevaluate.py`` (:mod:`jaxterrain.suite.batch`: one result file per walk, written when it
  ends; a rerun skips what is there); ``OUT/eval/<suite>/`` are the stores. ``--eval-backend jax|warp`` (default
  warp, 2-3 times faster on v2). ``--part K/N`` walks every N-th walk from the K-th (N processes, one per GPU,
  into one store: ``benchmarks/device/exp4_eval.sh``). A stage that would run MuJoCo Warp with its stock heightfield collision
  (``provenance.warp_hfield()``) is refused in one line: apply the local-origin patch first.
- ``write`` (CPU): each store's groups as evaluation folders (``reevaluate.py --write``: ``heldout_<suite>/`` in
  each treatment, the base policies in ``OUT/base_<suite>/<robot>[_perceptive]/``), then ``generalise`` per robot,
  observation set and suite against that observation set's base policy (``--base``: its 10 keys), with levels passed
  and trial-level intervals (``levels.csv``, ``intervals.csv``, ``generalisation.md``), into
  ``--results/<run folder>/<suite>/`` (``<robot>-<obs>``, or ``humanoid-perceptive-scan<C>``; default
  ``docs/results/exp4/``), v1 beside v2 (``--beside``).
- ``--plan``: what is done and the predicted device minutes of the rest (:func:`predict`), from the measured rates of
  :data:`RATES` (or the walks a store recorded), each figure marked measured or assumed.

``--pack FILE.tar.gz``: after the stage, ONE gzipped tar of what the next command needs (:func:`pack_members`): the
archives without their ``checkpoint/`` folders once finished, every train run without the checkpoints of its
finished treatments (an unfinished one keeps ``checkpoint.npz``, needed to resume on another machine; the tar's
size is printed: the device returns at most 16 MiB a file, so resume a long ``train`` on the same warm machine), the
walkers actor-only (``rl.save_actor_only``: they walk and evaluate, ~24 KB each), the evaluation stores.
``--preset smoke`` with the tiny suite flags (``--size --seeds --families --generators --attempts --best --headings
--slots``, as reevaluate.py's) runs every stage on a CPU (``tests/integration/test_exp4_run.py``).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import os
import re
import subprocess
import sys
import time
from pathlib import Path

STARTED = time.perf_counter()

ROOT = Path(__file__).resolve().parents[3]
STAGES = ("archive", "train", "evaluate", "write")
GENERATORS = ("steps", "mixed")
ROBOTS = ("humanoid", "ant")
OBSERVATIONS = ("blind", "perceptive")
SUITES = ("v2", "v1")
TREATMENTS = ("steps-map", "mixed-map", "mixed-dr", "mixed-plr", "mixed-levels")
"""The humanoid's treatments, ``<archive>-<curriculum>`` (their folder names in a ``curriculum`` run)."""
BASELINES = ("dr", "plr", "levels")
"""The field's curricula, run on the mixed archive."""
SHIPPED_STEPS = "docs/results/steps_gpushort/archive.npz"
"""The humanoid's ``steps`` archive at ``gpu-short`` (evolve --preset gpu-short --generator steps, one H200,
2026-11-29)."""
ARCHIVE_FLAGS = {"mixed": ["--initial-population", "600", "--batch-size", "6000", "--fresh", "100",
                           "--rollout-slots", "16384"], "steps": []}
"""``evolve``'s flags beyond ``--preset gpu-short --generator GEN`` (docs/results/mixed_archive.md's command); only
at ``gpu-short``."""
TRIALS = 10
KEYS = 10

RATES = {
    "archive_steps_s": (217.0, "measured: evolve --preset gpu-short --generator steps, one H200, MJX-JAX, 2026-11-29 "
                               "(docs/results/steps_gpushort)"),
    "archive_mixed_s": (396.0, "measured: the humanoid's mixed archive, evolve --preset gpu-short --generator mixed "
                               "(30 600 terrains), 396 s in one command, MJX-JAX, one H200 of a 2 x H200 host, "
                               "2026-11-30 (docs/results/mixed_archive.md)"),
    "archive_ant_factor": (1.76, "measured: the ant's steps archive, 381.2 s for the command with its compile (one "
                                 "H200 of a 2 x H200 host, MJX-JAX, 2026-11-30, docs/results/exp4/archives/"
                                 "ant-steps.tar.gz), against the humanoid's 217 s (another lease, 2026-11-29)"),
    "treatment_s_warp": ((388.0, 476.0), "measured: a gpu-short treatment alone, 388-476 s, MuJoCo Warp, one H200, "
                                         "Experiment 2 (exp2_all.md), 2026-11-29"),
    "treatment_s_jax": (780.0, "measured: learn --preset gpu-short --backend jax, 10.4 s a chunk x 75 chunks, one "
                               "H200, 2026-11-29 (/work/shared/NOTES.md)"),
    "population_factor": (0.74, "measured: Experiment 4's blind humanoid training itself, its five treatments as "
                                "three populations: 5.04 and 5.31 s a chunk for the two 20-trial populations "
                                "against 3.80 s for terrain levels alone (Warp, 2 x H200, same lease, 2026-11-30, "
                                "docs/results/exp4/chunk_times.py): (5.04 + 5.31 + 3.80) / (5 x 3.80). The six map "
                                "treatments' run predicted 0.73 (2.73 s + 0.136 s a trial, batch.FIXED_TRIALS)"),
    "v2_first_s": (67.0, "measured: the humanoid's first walk of suite v2 (compile included), MJX-JAX, one H200, "
                         "2026-11-29"),
    "v2_walker_s_jax": ((25.0, 35.0), "measured: the humanoid's walk of suite v2 (701 terrains, 80 walks each), "
                                      "25-35 s a walker, MJX-JAX, one H200, 2026-11-29"),
    "v1_first_s": (67.0, "assumed: as v2's first walk; not measured"),
    "v2_walker_s_warp": ((10.9, 14.1), "measured: 106 humanoid walks of suite v2 under MuJoCo Warp (stock kernel), "
                                       "one process, compiled: median 10.9 s, 90th percentile 14.1 s (8.9-18.0 s), "
                                       "one H200 and one 2 x H200 host, 2026-11-29 (suite_v2/warp_progress)"),
    "v1_walker_s_warp": ((7.0, 7.0), "measured: suite v1, ~7 s a walker, MuJoCo Warp, one H200, 2026-11-29"),
    "v1_walker_s_jax": ((25.0 * 372 / 701, 35.0 * 372 / 701), "assumed: v2's MJX-JAX rate x 372 / 701 terrains; not "
                                                             "measured"),
    "compile_s": ((35.0, 85.0), "measured: what each train command spends outside its chunks (set-up, compile): "
                                "35-42 s for one treatment, 67-85 s for the six-treatment population, per command "
                                "(commands_s less the chunks' time; Warp, 2 x H200, 2026-11-30, "
                                "docs/results/population)"),
    "build_s": (31.0, "measured: suite v2's build, the humanoid's 25.2-31.0 s, the ant's 2.8-29.1 s, on the GPU "
                      "machines, 2026-11-29 (suite_v2/warp_progress, builds.jsonl)"),
    "ant_eval_factor": (1.76, "measured: the ant's walkers on suite v2 under Warp with the local-origin patch, one "
                              "process, median 20.6 s (20.4-21.2, 9 walks) against the humanoid's 11.7 s in the "
                              "same lease, one H200, 2026-11-29 (benchmarks/RESULTS.md)"),
}
"""The figures ``--plan`` predicts from: ``name: (value or (low, high), where it comes from)``."""


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    p.add_argument("stage", nargs="*", metavar="STAGE",
                   help="archive GEN | train ROBOT [OBS] | evaluate | write (none with --plan)")
    p.add_argument("--out", type=Path, default=Path("runs/exp4"), help="the resumable results (default runs/exp4)")
    p.add_argument("--results", type=Path, default=Path("docs/results/exp4"),
                   help="write: where the generalise folders go (default docs/results/exp4)")
    p.add_argument("--time-limit", type=float, default=None, metavar="MIN",
                   help="stop (resumably) so that the command ends within about MIN minutes")
    p.add_argument("--pack", type=Path, default=None, metavar="FILE",
                   help="afterwards, one gzipped tar (.tar.gz) of what the next command needs (with --plan: the "
                        "pack alone, nothing runs)")
    p.add_argument("--plan", action="store_true", help="print what is done and the predicted device minutes")
    p.add_argument("--robot", choices=ROBOTS, default="humanoid", help="archive: whose archive (default humanoid)")
    p.add_argument("--ant", nargs="+", default=None, metavar="OBS/TREATMENT",
                   help=f"train ant: the two best treatments (one for a check; OBS: blind, perceptive; TREATMENT: "
                        f"{', '.join(TREATMENTS)})")
    p.add_argument("--treatments", nargs="+", choices=TREATMENTS, default=None, metavar="TREATMENT",
                   help=f"train humanoid: a subset of the treatments (default all: {', '.join(TREATMENTS)}; a "
                        f"mixed-* baseline needs mixed-map, which its curriculum run makes too); saved in "
                        f"OUT/humanoid.json at the first train")
    p.add_argument("--scan-lr-scale", type=float, default=None, metavar="C",
                   help="train humanoid perceptive: retrain --treatments with learn --scan-lr-scale C (finite, > 0, "
                        "not 1) into OUT/train/humanoid-perceptive-scan<C>/ (saved in OUT/scan.json; later stages "
                        "read it); without it, the original curriculum run")
    p.add_argument("--shard", default=None, metavar="I/N",
                   help="train humanoid: only process I's share of its curriculum run (curriculum --shard: whole "
                        "populations, balanced), so that N processes (one per GPU: CUDA_VISIBLE_DEVICES=I) share one "
                        "run; then the same train without --shard writes the tables (nothing compiles). train ant "
                        "(and train humanoid perceptive --scan-lr-scale): only the I-th, (I+N)-th, ... of its "
                        "treatments")
    p.add_argument("--part", default=None, metavar="K/N",
                   help="evaluate: walk only part K of N of the walks (reevaluate.py's --part: every N-th walk from "
                        "the K-th, into the one store), so that N processes, one per GPU, share them")
    p.add_argument("--preset", choices=("gpu-short", "smoke"), default="gpu-short",
                   help="evolve / curriculum / learn preset (default gpu-short; smoke: a CPU check)")
    p.add_argument("--trials", type=int, default=TRIALS, help=f"trials of each treatment (default {TRIALS})")
    p.add_argument("--backend", choices=("jax", "warp"), default=None,
                   help="MJX backend of train (default the preset's: MuJoCo Warp where it is installed)")
    p.add_argument("--eval-backend", choices=("jax", "warp"), default="warp",
                   help="MJX backend of evaluate (default warp: a humanoid walk of suite v2 in 10.9 s median "
                        "against 25-35 s under jax, one H200, 2026-11-29)")
    p.add_argument("--archive-size", type=int, default=None,
                   help="archive: evolve's --size (a CPU check; default the preset's)")
    p.add_argument("--keys", type=int, default=KEYS, help=f"evaluation keys of each base policy (default {KEYS})")
    p.add_argument("--suites", nargs="+", choices=SUITES, default=list(SUITES),
                   help="evaluate / write: the suites (default v2 v1, in that order)")
    for flag, kind, what in (("--size", int, "terrain side"), ("--seeds", int, "terrains per level"),
                             ("--samples", int, "generator samples"), ("--attempts", int, "walks per terrain"),
                             ("--best", int, "best walks averaged per heading"), ("--headings", int, "headings"),
                             ("--slots", int, "rollout pool")):
        p.add_argument(flag, type=kind, default=None, help=f"evaluate: reevaluate.py's {flag} ({what})")
    p.add_argument("--families", nargs="+", default=None, help="evaluate: reevaluate.py's --families")
    p.add_argument("--generators", nargs="*", default=None, help="evaluate: reevaluate.py's --generators")
    return p


def check(p: argparse.ArgumentParser, args) -> None:
    """Every flag and the stage's words, in one line naming the flag (exit 2), before anything runs; sets
    ``args.what`` (the stage's words as a tuple) and ``args.ant_pairs`` (``[(obs, treatment)]``)."""
    words = tuple(args.stage)
    if args.plan and words:
        p.error(f"--plan runs no stage; got {' '.join(words)}")
    if not args.plan and not words:
        p.error(f"give a stage ({', '.join(STAGES)}) or --plan")
    if words and words[0] not in STAGES:
        p.error(f"STAGE must be one of {', '.join(STAGES)}; got {words[0]!r}")
    if words and words[0] == "archive" and (len(words) != 2 or words[1] not in GENERATORS):
        p.error(f"archive takes one generator: {' or '.join(GENERATORS)}; got {' '.join(words[1:]) or 'none'}")
    if words and words[0] == "train":
        if len(words) < 2 or words[1] not in ROBOTS:
            p.error(f"train takes a robot: {' or '.join(ROBOTS)}; got {' '.join(words[1:]) or 'none'}")
        if words[1] == "humanoid" and (len(words) != 3 or words[2] not in OBSERVATIONS):
            p.error(f"train humanoid takes an observation set: {' or '.join(OBSERVATIONS)}; got "
                    f"{' '.join(words[2:]) or 'none'}")
        if words[1] == "ant" and len(words) != 2:
            p.error(f"train ant takes its treatments from --ant OBS/TREATMENT ...; got {' '.join(words[2:])}")
        if words[1] == "ant" and args.ant is None:
            p.error("train ant needs --ant OBS/TREATMENT OBS/TREATMENT (the two chosen after the humanoid's results)")
    if words and words[0] in ("evaluate", "write") and len(words) != 1:
        p.error(f"{words[0]} takes no further word; got {' '.join(words[1:])}")
    if args.robot != "humanoid" and not (words and words[0] == "archive"):
        p.error("--robot chooses whose archive the archive stage evolves; train takes the robot as a word")
    if args.ant is not None and not (words and words[:2] == ("train", "ant")):
        p.error("--ant chooses the ant's treatments of 'train ant' (later stages read OUT/ant.json)")
    args.ant_pairs = None if args.ant is None else parse_ant(p, args.ant)
    if args.scan_lr_scale is not None:
        if words != ("train", "humanoid", "perceptive"):
            p.error("--scan-lr-scale retrains perceptive humanoid treatments: 'train humanoid perceptive "
                    "--scan-lr-scale C --treatments T ...' (later stages read OUT/scan.json)")
        if args.treatments is None:
            p.error("--scan-lr-scale needs --treatments T [T ...]: the perceptive humanoid's treatments to retrain")
        c = args.scan_lr_scale
        if not (math.isfinite(c) and c > 0) or c == 1:
            p.error(f"--scan-lr-scale must be a finite number > 0 other than 1 (1: the original run, without the "
                    f"flag); got {c}")
    if args.treatments is not None:
        if not (words and words[:2] == ("train", "humanoid")):
            p.error("--treatments chooses the humanoid's treatments of 'train humanoid' (later stages read "
                    "OUT/humanoid.json)")
        if args.scan_lr_scale is None:
            check_treatments(p, args.treatments)
        elif len(set(args.treatments)) != len(args.treatments):  # learn runs: no baseline needs mixed-map
            p.error(f"--treatments: each treatment once; got {' '.join(args.treatments)}")
    if args.shard is not None:
        if not (words and words[0] == "train"):
            p.error("--shard splits a 'train' stage over processes (train humanoid OBS: its curriculum run's "
                    "populations; train ant, train humanoid perceptive --scan-lr-scale: its treatments)")
        from experiments.common import parse_shard  # curriculum's own parser of I/N

        try:
            args.shard = parse_shard(args.shard)
        except argparse.ArgumentTypeError:
            p.error(f"--shard must be I/N with N >= 1 and 0 <= I < N; got {args.shard!r}")
    if args.part is not None:
        if words[:1] != ("evaluate",):
            p.error("--part splits the walks of 'evaluate' over processes")
        from experiments.common import parse_shard  # the same I/N as --shard

        try:
            args.part = parse_shard(args.part)
        except argparse.ArgumentTypeError:
            p.error(f"--part must be K/N with integers 0 <= K < N; got {args.part!r}")
    if args.time_limit is not None and not (math.isfinite(args.time_limit) and args.time_limit > 0):
        p.error(f"--time-limit must be a finite number of minutes > 0; got {args.time_limit}")
    if args.pack is not None and not args.pack.name.endswith((".tar.gz", ".tgz")):
        p.error(f"--pack must name a .tar.gz or .tgz file; got {args.pack}")
    if args.pack is not None and not args.out.resolve().is_relative_to(Path.cwd().resolve()):
        p.error(f"--pack stores --out relative to the current folder (unpack it there); --out {args.out} is outside it")
    for name, lo in (("trials", 1), ("keys", 1), ("archive_size", 32), ("size", 32), ("seeds", 1), ("samples", 1),
                     ("attempts", 1), ("best", 1), ("slots", 0)):
        v = getattr(args, name)
        if v is not None and v < lo:
            p.error(f"--{name.replace('_', '-')} must be an integer >= {lo}; got {v}")
    if args.headings is not None and args.headings not in (1, 2, 4):
        p.error(f"--headings must be one of 1, 2, 4; got {args.headings}")
    if args.out.exists() and not args.out.is_dir():
        p.error(f"--out {args.out} is a file")
    warp = (words[:1] == ("evaluate",) and args.eval_backend == "warp") or (
        words[:1] == ("train",) and (args.backend == "warp" or (args.backend is None and auto_picks_warp())))
    if warp and _warp_hfield() == "stock":
        p.error("MuJoCo Warp here runs its stock heightfield collision (contacts metres deep for a foot buried far "
                "from the heightfield's centre: the ant's suite-v2 mean 0.686 against 0.777 patched); run "
                "'python -m experiments warp-patch' (mjx_vendored_hfield_local_origin.patch) first, or pass "
                + ("--eval-backend jax" if words[:1] == ("evaluate",) else "--backend jax"))
    args.what = words


def _warp_hfield() -> str:
    from jaxterrain.runtime import provenance  # imports JAX: only where a stage will run MuJoCo Warp

    return provenance.warp_hfield()


def auto_picks_warp() -> bool:
    """Whether the presets' ``auto`` backend runs MuJoCo Warp here: warp-lang importable and JAX on a GPU (the rule
    of ``jaxterrain.walker.resolve_backend``; a CPU with warp-lang installed runs MJX-JAX)."""
    if importlib.util.find_spec("warp") is None:
        return False
    import jax  # only where warp-lang is installed

    return jax.default_backend() == "gpu"


def parse_ant(p: argparse.ArgumentParser, items: list[str]) -> list[tuple[str, str]]:
    """``--ant``'s ``OBS/TREATMENT`` items as ``[(obs, treatment)]``: exactly two, distinct, each known."""
    pairs = []
    for item in items:
        obs, sep, name = item.partition("/")
        if not sep or obs not in OBSERVATIONS or name not in TREATMENTS:
            p.error(f"--ant must be OBS/TREATMENT with OBS one of {', '.join(OBSERVATIONS)} and TREATMENT one of "
                    f"{', '.join(TREATMENTS)}; got {item!r}")
        pairs.append((obs, name))
    if len(pairs) > 2 or len(set(pairs)) != len(pairs):
        p.error(f"--ant takes the two best treatments (one for a check), each OBS/TREATMENT once; got "
                f"{' '.join(items)}")
    return pairs


def check_treatments(p: argparse.ArgumentParser, names: list[str]) -> None:
    """``--treatments``: each once; a baseline on the mixed archive only with ``mixed-map`` (``curriculum`` runs the
    map curriculum on every archive it is given)."""
    if len(set(names)) != len(names):
        p.error(f"--treatments: each treatment once; got {' '.join(names)}")
    if any(n in ("mixed-dr", "mixed-plr", "mixed-levels") for n in names) and "mixed-map" not in names:
        p.error("--treatments: a mixed-* baseline needs mixed-map (curriculum runs the map curriculum on every archive "
                "it is given)")


def humanoid_generators(out: Path) -> list[str]:
    """The humanoid archives its runs need: each map treatment's of the curriculum run, each treatment's of the
    retrain (``OUT/scan.json``)."""
    retrain = (scan_choice(out) or (0.0, []))[1]
    return [g for g in GENERATORS if f"{g}-map" in humanoid_choice(out) or any(t.split("-", 1)[0] == g
                                                                                for t in retrain)]


def humanoid_choice(out: Path) -> list[str]:
    """The humanoid's treatments: ``OUT/humanoid.json``'s (a subset given by ``--treatments``) or all of them."""
    path = out / "humanoid.json"
    return list(TREATMENTS) if not path.is_file() else list(json.loads(path.read_text())["treatments"])


# ---------------------------------------------------------------------------------------------------------------
# where things are
# ---------------------------------------------------------------------------------------------------------------
def archive_folder(out: Path, robot: str, gen: str) -> Path:
    return out / "archive" / f"{robot}-{gen}"


def archive_path(out: Path, robot: str, gen: str, preset: str) -> Path:
    """The archive a robot's curricula read: the shipped steps archive for the humanoid at gpu-short, else the
    ``archive`` stage's."""
    if robot == "humanoid" and gen == "steps" and preset == "gpu-short":
        return ROOT / SHIPPED_STEPS
    return archive_folder(out, robot, gen) / "archive.npz"


def archive_done(out: Path, robot: str, gen: str, preset: str) -> bool:
    path = archive_path(out, robot, gen, preset)
    if path == ROOT / SHIPPED_STEPS:
        return path.is_file()
    return path.is_file() and (archive_folder(out, robot, gen) / "done.json").is_file()


def archive_share_left(out: Path, robot: str, gen: str, preset: str) -> float:
    """The share of an archive's ``evolve`` run still to do: 0 when done, 1 when not started, else the generations
    left over all (its checkpoint's ``metrics.csv`` holds one row for the initial population and one per
    generation since; the initial population, a tenth of a generation's offspring, is not counted)."""
    if archive_done(out, robot, gen, preset):
        return 0.0
    folder = archive_folder(out, robot, gen)
    metrics = folder / "checkpoint" / "metrics.csv"
    try:
        total = int(json.loads((folder / "config.json").read_text())["generations"])
        done = len(metrics.read_text().strip().splitlines()) - 2  # header and the initial population
    except (OSError, KeyError, ValueError, TypeError):
        return 1.0
    return min(1.0, max(0.0, (total - done) / total)) if total > 0 and done >= 0 else 1.0


def train_folder(out: Path, robot: str, obs: str) -> Path:
    return out / "train" / f"{robot}-{obs}"


def treatment_done(folder: Path) -> bool:
    """A treatment (a learn run, or a curriculum run's subfolder) has finished: its ``summary.json`` and walkers."""
    return (folder / "summary.json").is_file() and (folder / "policies").is_dir()


def ant_choice(out: Path) -> list[tuple[str, str]] | None:
    path = out / "ant.json"
    return None if not path.is_file() else [tuple(x) for x in json.loads(path.read_text())["treatments"]]


def scan_choice(out: Path) -> tuple[float, list[str]] | None:
    """The perceptive humanoid's retrain (``OUT/scan.json``): ``(scale, [treatments])``, or None before it."""
    path = out / "scan.json"
    if not path.is_file():
        return None
    saved = json.loads(path.read_text())
    return float(saved["scale"]), list(saved["treatments"])


def scan_folder(out: Path, scale: float) -> Path:
    """The retrain's run folder, ``OUT/train/humanoid-perceptive-scan<C>`` (C as ``{:g}`` writes it: 0.1)."""
    return out / "train" / f"humanoid-perceptive-scan{scale:g}"


def runs(out: Path) -> list[tuple[str, str, Path, list[str]]]:
    """Every train run planned: ``(robot, obs, folder, [treatments])``; the ant's once chosen (``OUT/ant.json``),
    then the perceptive humanoid's retrain once chosen (``OUT/scan.json``)."""
    plan = [("humanoid", obs, train_folder(out, "humanoid", obs), humanoid_choice(out)) for obs in OBSERVATIONS]
    for obs in OBSERVATIONS:
        names = [t for o, t in ant_choice(out) or [] if o == obs]
        if names:
            plan.append(("ant", obs, train_folder(out, "ant", obs), names))
    scan = scan_choice(out)
    if scan is not None:
        plan.append(("humanoid", "perceptive", scan_folder(out, scan[0]), scan[1]))
    return plan


def run_label(robot: str, folder: Path) -> str:
    """A train run's name after its robot in ``--plan``: its folder's (``blind``, ``perceptive``,
    ``perceptive-scan0.1``); the part before the first ``-`` is its observation set."""
    return folder.name.removeprefix(robot + "-")


def curriculum_argv(args, obs: str, names: list[str] = TREATMENTS) -> list[str]:
    """The humanoid's ``curriculum`` command of observation set ``obs`` (a fresh run) for the treatments ``names``
    (default all: ``--archives steps=.. mixed=.. --baseline dr plr levels --baseline-archive mixed --no-combined``)."""
    out = args.out
    gens = [g for g in GENERATORS if f"{g}-map" in names]
    argv = ["curriculum", "--preset", args.preset, "--archives",
            *[f"{g}={archive_path(out, 'humanoid', g, args.preset)}" for g in gens]]
    baselines = [b for b in BASELINES if f"mixed-{b}" in names]
    argv += ["--baseline", *baselines, "--baseline-archive", "mixed"] if baselines else []
    argv += ["--no-combined"] if len(gens) > 1 else []
    argv += ["--observation", obs, "--trials", str(args.trials), "--out", str(train_folder(out, "humanoid", obs))]
    return argv + (["--backend", args.backend] if args.backend else [])


def learn_argv(args, robot: str, obs: str, treatment: str, folder: Path, scale: float | None = None) -> list[str]:
    """The ``learn`` command of one treatment ``<gen>-<curriculum>`` (a fresh run) into ``folder/treatment``: on
    ``robot``'s archive of ``gen``, with ``--scan-lr-scale scale`` when given (the perceptive humanoid's retrain;
    the ant's treatments take none)."""
    gen, curriculum = treatment.split("-", 1)
    argv = ["learn", "--robot", robot, "--preset", args.preset, "--archive",
            str(archive_path(args.out, robot, gen, args.preset)), "--curriculum", curriculum, "--observation", obs,
            "--trials", str(args.trials), "--out", str(folder / treatment)]
    argv += [] if scale is None else ["--scan-lr-scale", repr(float(scale))]
    return argv + (["--backend", args.backend] if args.backend else [])


def archive_argv(args, gen: str, robot: str) -> list[str]:
    argv = ["evolve", "--preset", args.preset, "--generator", gen, "--out", str(archive_folder(args.out, robot, gen))]
    argv += ARCHIVE_FLAGS[gen] if args.preset == "gpu-short" else []
    if robot != "humanoid":
        argv += ["--robot", robot] + (["--fitness", "difficulty"] if args.preset != "gpu-short" else [])
    return argv + (["--size", str(args.archive_size)] if args.archive_size else [])


# ---------------------------------------------------------------------------------------------------------------
# the stages
# ---------------------------------------------------------------------------------------------------------------
def left_minutes(args) -> float | None:
    return None if args.time_limit is None else args.time_limit - (time.perf_counter() - STARTED) / 60.0


def cli(argv: list[str], args) -> int:
    """``python -m experiments ARGV`` (a child process, from the repository root) under what is left of
    ``--time-limit``; its output goes through. Returns its exit status (3: the time limit stopped it)."""
    left = left_minutes(args)
    if left is not None:
        if left <= 0.05:
            print(f"time limit: no time left for {' '.join(argv[:1])}", flush=True)
            return 3
        argv = [*argv, "--time-limit", f"{left:.3f}"]
    print("+ python -m experiments " + " ".join(argv), flush=True)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]).rstrip(
        os.pathsep), "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "experiments", *argv], cwd=Path.cwd(), env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    for line in proc.stdout:
        sys.stdout.write(line)
    return proc.wait()


def stage_archive(args, gen: str, robot: str) -> int:
    folder = archive_folder(args.out, robot, gen)
    if archive_done(args.out, robot, gen, args.preset):
        print(f"archive {robot} {gen}: done ({archive_path(args.out, robot, gen, args.preset)})", flush=True)
        return 0
    resume = (folder / "config.json").is_file()
    code = cli(["evolve", "--resume", str(folder)] if resume else archive_argv(args, gen, robot), args)
    if code == 0:
        from jaxterrain.runtime.io import atomic_write_text

        atomic_write_text(folder / "done.json", json.dumps({"seconds_this_command": round(
            time.perf_counter() - STARTED, 1)}) + "\n")
        print(f"archive {robot} {gen}: done ({folder / 'archive.npz'})", flush=True)
    return code


def stage_train_scan(args) -> int:
    """``train humanoid perceptive --scan-lr-scale C --treatments T ...``: one ``learn`` run per treatment (of
    ``--shard``'s share), resumed where its ``config.json`` is; the choice saved in ``OUT/scan.json``."""
    scale, names = args.scan_lr_scale, list(args.treatments)
    saved = scan_choice(args.out)
    if saved is not None and (saved[0] != scale or sorted(saved[1]) != sorted(names)):
        print(f"train humanoid perceptive: {args.out}/scan.json chose --scan-lr-scale {saved[0]:g} --treatments "
              f"{' '.join(saved[1])}; give the same or another --out", file=sys.stderr)
        return 2
    missing = [g for g in GENERATORS if any(t.split("-", 1)[0] == g for t in names)
               and not archive_done(args.out, "humanoid", g, args.preset)]
    if missing:
        print(f"train humanoid perceptive: run 'archive {missing[0]}' first (no "
              f"{archive_path(args.out, 'humanoid', missing[0], args.preset)})", file=sys.stderr)
        return 2
    if saved is None:
        from jaxterrain.runtime.io import atomic_write_text

        args.out.mkdir(parents=True, exist_ok=True)
        atomic_write_text(args.out / "scan.json", json.dumps({"scale": scale, "treatments": names}) + "\n")
    else:
        names = saved[1]  # the saved order: every --shard splits the same list
    run = scan_folder(args.out, scale)
    label = run_label("humanoid", run)
    return learn_runs(args, [(f"humanoid {label}/{t}", run / t,
                              learn_argv(args, "humanoid", "perceptive", t, run, scale)) for t in names])


def learn_runs(args, jobs: list[tuple[str, Path, list[str]]]) -> int:
    """One ``learn`` run per job ``(label, folder, its fresh argv)``, of ``--shard I/N``'s share (the I-th, (I+N)-th,
    ... job): skipped when done, resumed where its ``config.json`` is. The ant's treatments and the perceptive
    humanoid's retrain. Returns the first failing exit status, else 0."""
    if args.shard is not None:
        index, count = args.shard
        jobs = jobs[index::count]
    for label, folder, argv in jobs:
        if treatment_done(folder):
            print(f"train {label}: done ({folder})", flush=True)
            continue
        code = cli(["learn", "--resume", str(folder)] if (folder / "config.json").is_file() else argv, args)
        if code != 0:
            return code
        print(f"train {label}: done ({folder})", flush=True)
    return 0


def stage_train(args, robot: str, obs: str | None) -> int:
    if args.scan_lr_scale is not None:
        return stage_train_scan(args)
    if robot == "humanoid":
        saved = (args.out / "humanoid.json").is_file()
        names = humanoid_choice(args.out) if saved or args.treatments is None else list(args.treatments)
        if saved and args.treatments is not None and sorted(args.treatments) != sorted(names):
            print(f"train humanoid: {args.out}/humanoid.json chose {' '.join(names)}; give the same --treatments or "
                  f"another --out", file=sys.stderr)
            return 2
        missing = [g for g in GENERATORS if f"{g}-map" in names and not archive_done(args.out, "humanoid", g,
                                                                                      args.preset)]
        if missing:
            print(f"train humanoid: run 'archive {missing[0]}' first (no "
                  f"{archive_path(args.out, 'humanoid', missing[0], args.preset)})", file=sys.stderr)
            return 2
        if not saved:
            from jaxterrain.runtime.io import atomic_write_text

            args.out.mkdir(parents=True, exist_ok=True)
            atomic_write_text(args.out / "humanoid.json", json.dumps({"treatments": names}) + "\n")
        folder = train_folder(args.out, "humanoid", obs)
        if all(treatment_done(folder / t) for t in names) and (folder / "hardest.csv").is_file():
            print(f"train humanoid {obs}: done ({folder})", flush=True)
            return 0
        shard = [] if args.shard is None else ["--shard", "{}/{}".format(*args.shard)]
        code = cli((["curriculum", "--resume", str(folder)] if (folder / "config.json").is_file()
                    else curriculum_argv(args, obs, names)) + shard, args)
        if code == 0 and shard:
            print(f"train humanoid {obs} shard {shard[1]}: done ({folder}); once every shard is, the same train "
                  f"without --shard writes the tables", flush=True)
        elif code == 0:
            print(f"train humanoid {obs}: done ({folder})", flush=True)
        return code
    pairs = args.ant_pairs
    saved = ant_choice(args.out)
    if saved is not None and sorted(saved) != sorted(pairs):
        print(f"train ant: {args.out}/ant.json chose {' '.join('/'.join(x) for x in saved)}; give the same --ant or "
              f"another --out", file=sys.stderr)
        return 2
    missing = sorted({t.split("-", 1)[0] for _, t in pairs if not archive_done(args.out, "ant", t.split("-", 1)[0],
                                                                               args.preset)})
    if missing:
        print(f"train ant: run 'archive {missing[0]} --robot ant' first", file=sys.stderr)
        return 2
    if saved is None:
        from jaxterrain.runtime.io import atomic_write_text

        args.out.mkdir(parents=True, exist_ok=True)
        atomic_write_text(args.out / "ant.json", json.dumps({"treatments": [list(x) for x in pairs]}) + "\n")
    return learn_runs(args, [(f"ant {obs}/{t}", train_folder(args.out, "ant", obs) / t,
                              learn_argv(args, "ant", obs, t, train_folder(args.out, "ant", obs))) for obs, t in pairs])


def load_reevaluate():
    """``docs/results/suite_v2/reevaluate.py`` as a module: the resumable many-walker evaluation this stage reuses."""
    path = ROOT / "docs" / "results" / "suite_v2" / "reevaluate.py"
    spec = importlib.util.spec_from_file_location("suite_v2_reevaluate", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.STARTED = STARTED  # its --time-limit counts from this command's start
    return module


def suite_flags(args) -> list[str]:
    """reevaluate.py's protocol and suite-build flags given here."""
    out = []
    for name in ("size", "seeds", "samples", "attempts", "best", "headings", "slots"):
        v = getattr(args, name)
        out += [] if v is None else [f"--{name}", str(v)]
    if args.families is not None:
        out += ["--families", *args.families]
    if args.generators is not None:
        out += ["--generators", *args.generators]
    return out


def reevaluate_argv(args, suite: str, folders: list[Path], robots: list[str]) -> list[str]:
    return [*map(str, folders), "--work", str(args.out / "eval" / suite), "--suite", suite,
            "--heldout-name", f"heldout_{suite}", "--base-out", str(args.out / f"base_{suite}"),
            "--robots", *robots, "--observations", *OBSERVATIONS, "--keys", str(args.keys),
            "--backend", args.eval_backend, *suite_flags(args)]


def trained(out: Path) -> tuple[list[Path], list[str]]:
    """The finished train runs' folders to walk (every treatment done) and the unfinished ones' names."""
    folders, waiting = [], []
    for _, _, folder, names in runs(out):
        (folders if all(treatment_done(folder / t) for t in names) else waiting).append(folder)
    return folders, [f.name for f in waiting]


def stage_evaluate(args) -> int:
    folders, waiting = trained(args.out)
    if waiting:
        print(f"evaluate: not trained yet (walked later): {', '.join(waiting)}", flush=True)
    if not folders:
        print("evaluate: no train run has finished yet", file=sys.stderr)
        return 2
    robots = [r for r in ROBOTS if any(f.name.startswith(r + "-") for f in folders)]
    module = load_reevaluate()
    for suite in args.suites:
        argv = reevaluate_argv(args, suite, folders, robots) + (
            [] if args.time_limit is None else ["--time-limit", str(args.time_limit)]) + (
            [] if args.part is None else ["--part", "{}/{}".format(*args.part)])
        print(f"+ reevaluate.py {' '.join(argv)}", flush=True)
        code = module.main(argv)
        if code:
            return code
        if plan_walks(args, folders, robots, [suite]):  # the time limit stopped it: the next suite waits
            break
    left = plan_walks(args, folders, robots)
    part = "" if args.part is None else " part {}/{}".format(*args.part)
    print(f"evaluate{part}: done" if not left and not waiting else f"evaluate{part}: {left} walks left; run it again",
          flush=True)
    return 0


def plan_walks(args, folders: list[Path], robots: list[str], suites: list[str] | None = None) -> int:
    """Walks not yet in the stores of ``suites`` (default ``--suites``): of ``--part``'s share only, when given
    (the jobs in reevaluate.py's order: each robot's base policies, blind then perceptive, then the walkers)."""
    from jaxterrain.suite import batch

    jobs = [j for r in robots for o in OBSERVATIONS for j in batch.base_jobs(r, args.keys, o)]
    jobs += batch.walker_jobs(folders)
    jobs = jobs if args.part is None else batch.part(jobs, *args.part)
    n = 0
    for suite in args.suites if suites is None else suites:
        results = args.out / "eval" / suite / "results"
        n += sum(not (results / f"{_file(j.name)}.npz").is_file() for j in jobs)
    return n


def stage_write(args) -> int:
    module = load_reevaluate()
    folders, waiting = trained(args.out)
    robots = [r for r in ROBOTS if any(f.name.startswith(r + "-") for f in folders)]
    if waiting or not folders:
        print(f"write: train runs not finished: {', '.join(waiting) or 'all'}", file=sys.stderr)
        return 2
    for suite in args.suites:
        if not (args.out / "eval" / suite / "settings.json").is_file():
            print(f"write: suite {suite} not walked yet ({args.out / 'eval' / suite})", file=sys.stderr)
            return 2
        walked = json.loads((args.out / "eval" / suite / "settings.json").read_text())["backend"]
        code = module.main(reevaluate_argv(argparse.Namespace(**{**vars(args), "eval_backend": walked}), suite,
                                           folders, robots) + ["--write"])  # the backend the walks ran on
        if code:
            return code
    for robot, obs, folder, names in runs(args.out):
        base = "_".join([robot] + ([obs] if obs != "blind" else []))
        previous = None
        for suite in reversed(args.suites):  # v1 first, so that v2's page shows it beside
            heldout = f"heldout_{suite}"
            if not all((folder / t / heldout / "fitness.csv.gz").is_file() for t in names):
                print(f"write: {folder.name} on {suite} not all walked yet", file=sys.stderr)
                return 2
            dest = args.results / folder.name / suite
            argv = ["generalise", *[f"{t}={folder / t}" for t in names], "--heldout", heldout,
                    "--base", str(args.out / f"base_{suite}" / base), "--out", str(dest)]
            argv += [] if previous is None else ["--beside", f"{previous[0]}={previous[1]}"]
            code = cli(argv, argparse.Namespace(time_limit=None))
            if code:
                return code
            previous = (suite, dest)
    code = write_compare(args)
    if code:
        return code
    print(f"write: done -> {args.results}", flush=True)
    return 0


def compare_treatments(out: Path) -> list[tuple[str, Path]]:
    """The retrain's comparison (``LABEL``, treatment folder): each retrained treatment T, then T of the original
    perceptive run and of the blind one where they ran it (``perceptive-T-scan<C>``, ``perceptive-T``,
    ``blind-T``); empty before ``OUT/scan.json``."""
    scan = scan_choice(out)
    if scan is None:
        return []
    scale, names = scan
    ran = humanoid_choice(out)
    pairs = []
    for t in names:
        pairs.append((f"perceptive-{t}-scan{scale:g}", scan_folder(out, scale) / t))
        pairs += [(f"{obs}-{t}", train_folder(out, "humanoid", obs) / t) for obs in ("perceptive", "blind")
                  if t in ran]
    return pairs


def write_compare(args) -> int:
    """One ``generalise`` page per suite of :func:`compare_treatments` against the perceptive base policy, into
    ``--results/humanoid-perceptive-scan<C>/<suite>-compare/`` (v1 beside v2); nothing before ``OUT/scan.json``."""
    pairs = compare_treatments(args.out)
    if not pairs:
        return 0
    scale = scan_choice(args.out)[0]
    previous = None
    for suite in reversed(args.suites):
        heldout = f"heldout_{suite}"
        dest = args.results / scan_folder(args.out, scale).name / f"{suite}-compare"
        argv = ["generalise", *[f"{label}={folder}" for label, folder in pairs], "--heldout", heldout,
                "--base", str(args.out / f"base_{suite}" / "humanoid_perceptive"), "--out", str(dest)]
        argv += [] if previous is None else ["--beside", f"{previous[0]}={previous[1]}"]
        code = cli(argv, argparse.Namespace(time_limit=None))
        if code:
            return code
        previous = (suite, dest)
    return 0


# ---------------------------------------------------------------------------------------------------------------
# --plan
# ---------------------------------------------------------------------------------------------------------------
def _mid(v) -> tuple[float, float]:
    return (float(v[0]), float(v[1])) if isinstance(v, tuple) else (float(v), float(v))


def predict(state: dict, rates: dict = RATES) -> dict:
    """Predicted device seconds ``(low, high)`` of what is left, per item, from ``state`` (:func:`read_state`) and
    ``rates`` (:data:`RATES`). Pure arithmetic, no files:

    - an archive left: its seconds (the ant's times ``archive_ant_factor``);
    - a train run: its treatments not done x ``treatment_s_<train_backend>`` (the humanoid's ``curriculum`` runs,
      ``humanoid OBS``, times ``population_factor``; the retrain's ``learn`` runs, ``humanoid perceptive-scan<C>``,
      not), plus ``compile_s`` for each command of 480 s less the compile that it needs;
    - a suite: for each robot with walks left, a build, one first walk per program (observation set: a run label's
      part before ``-``) with walks left, and the other walks at ``<suite>_walker_s_<eval_backend>`` (the ant's
      times ``ant_eval_factor``); the walks a store recorded replace the rates (``state["measured"][suite]``:
      ``(first_s, (low, high))``);
    - before the ant's treatments are chosen (``state["ant_pending"]``): two ant treatments, both ant archives and
      the ant's walks (two programs: ``2 x trials`` walkers and ``2 x keys`` base walks per suite)."""
    out = {}
    share = state.get("archive_share", {})  # {(robot, gen): share left}; 1 where absent
    for robot, gen in state["archives_left"]:
        s = rates[f"archive_{gen}_s"][0] * (rates["archive_ant_factor"][0] if robot == "ant" else 1.0)
        s *= share.get((robot, gen), 1.0)
        out[f"archive {gen} --robot {robot}"] = (s, s)
    lo_t, hi_t = _mid(rates[f"treatment_s_{state['train_backend']}"][0])
    lo_c, hi_c = _mid(rates["compile_s"][0])

    def train(seconds: tuple[float, float]) -> tuple[float, float]:  # plus a compile per command
        n = commands((seconds[0], seconds[1]), 480.0 - hi_c)
        return seconds[0] + n * lo_c, seconds[1] + n * hi_c

    for name, left in state["train_left"].items():
        robot, label = name.split(" ", 1)
        k = rates["population_factor"][0] if robot == "humanoid" and label in OBSERVATIONS else 1.0
        if left:
            out[f"train {name}"] = train((left * lo_t * k, left * hi_t * k))
    walks_left = {suite: dict(w) for suite, w in state["walks_left"].items()}
    if state["ant_pending"]:
        out["train ant (2 treatments, not chosen yet)"] = train((2 * lo_t, 2 * hi_t))
        for gen in GENERATORS:
            s = rates[f"archive_{gen}_s"][0] * rates["archive_ant_factor"][0] * share.get(("ant", gen), 1.0)
            if s > 0:
                out[f"archive {gen} --robot ant (not chosen yet)"] = (s, s)
        for w in walks_left.values():
            for obs in OBSERVATIONS:
                w[("ant", obs)] = state["trials"] + state["keys"]
    for suite, walks in walks_left.items():  # {suite: {(robot, obs): n}}
        first, per = state["measured"].get(suite) or (rates[f"{suite}_first_s"][0],
                                                      rates[f"{suite}_walker_s_{state['eval_backend']}"][0])
        lo_w, hi_w = _mid(per)
        lo = hi = 0.0
        for robot in dict.fromkeys(r for r, _ in walks):
            f = rates["ant_eval_factor"][0] if robot == "ant" else 1.0
            programs = {}  # {observation set: walks left}: the retrain's walkers walk on the perceptive program
            for (r, label), n in walks.items():
                if r == robot and n > 0:
                    programs[label.split("-", 1)[0]] = programs.get(label.split("-", 1)[0], 0) + n
            if programs:
                n, m = sum(programs.values()), len(programs)
                lo += f * (rates["build_s"][0] + m * first + (n - m) * lo_w)
                hi += f * (rates["build_s"][0] + m * first + (n - m) * hi_w)
        if lo or hi:
            out[f"evaluate {suite}"] = (lo, hi)
    return out


def commands(seconds: tuple[float, float], limit_s: float = 480.0) -> int:
    """Commands of ``limit_s`` (``--time-limit 8``) needed for ``seconds`` (the high end)."""
    return max(1, math.ceil(seconds[1] / limit_s))


def read_state(args) -> dict:
    """What ``--out`` holds, for :func:`predict`: archives left, treatments left per train run (``"robot label"``,
    :func:`run_label`), walks left per suite and ``(robot, label)`` (walkers of the planned runs, and ``--keys`` base
    walks of both observation sets of each robot that trains, under the observation set's own label), the walk
    rates recorded in each store, the backends counted (train: ``--backend``, else ``warp``, what ``auto`` picks
    where MuJoCo Warp is installed; evaluate: ``--backend``, else ``jax``)."""
    out = args.out
    choice = ant_choice(out)
    needed = [("humanoid", g) for g in humanoid_generators(out)]
    needed += [("ant", g) for g in dict.fromkeys(t.split("-", 1)[0] for _, t in choice or [])]
    state = {"archives_left": [(r, g) for r, g in needed if not archive_done(out, r, g, args.preset)],
             "train_left": {}, "walks_left": {}, "measured": {}, "ant_pending": choice is None,
             "train_backend": args.backend or "warp", "eval_backend": args.eval_backend, "trials": args.trials,
             "keys": args.keys}
    state["archive_share"] = {(r, g): archive_share_left(out, r, g, args.preset)
                              for r, g in [("humanoid", g) for g in GENERATORS] + [("ant", g) for g in GENERATORS]}
    plan = runs(out)
    for robot, _, folder, names in plan:  # keys "robot label": the retrain apart from the original run
        state["train_left"][f"{robot} {run_label(robot, folder)}"] = sum(not treatment_done(folder / t)
                                                                         for t in names)
    for suite in args.suites:
        results = out / "eval" / suite / "results"
        have = {p.stem for p in results.glob("*.npz")} if results.is_dir() else set()
        walks = {}
        for robot, _, folder, names in plan:
            walks[(robot, run_label(robot, folder))] = sum(
                _file(str(folder / t / "policies" / f"trial_{k}")) not in have for t in names
                for k in range(args.trials))
        for robot in dict.fromkeys(r for r, _, _, _ in plan):
            for obs in OBSERVATIONS:
                base = f"base:{robot}" + ("" if obs == "blind" else f":{obs}")
                walks[(robot, obs)] = walks.get((robot, obs), 0) + sum(
                    _file(base + (f":key{k}" if k else "")) not in have for k in range(args.keys))
        state["walks_left"][suite] = walks
        meta = _recorded(out / "eval" / suite)
        if meta is not None:
            state["measured"][suite] = meta
    return state


def _file(name: str) -> str:
    """A job's result file name without ``.npz`` (``jaxterrain.suite.batch``'s rule)."""
    return re.sub(r"[^A-Za-z0-9._-]+", "+", name).strip("+")


def _recorded(folder: Path) -> tuple[float, tuple[float, float]] | None:
    """``(slowest first walk, (fastest, slowest) later walk)`` recorded in a store, or None when it has none."""
    results = folder / "results"
    if not results.is_dir():
        return None
    import numpy as np

    first, again = [], []
    for p in sorted(results.glob("*.npz")):
        with np.load(p, allow_pickle=False) as z:
            m = json.loads(str(z["meta"]))
        (again if m.get("compiled_before") else first).append(float(m["seconds"]))
    if not first and not again:
        return None
    f = max(first) if first else max(again)
    return f, ((min(again), max(again)) if again else (f, f))


def print_plan(args) -> int:
    state = read_state(args)
    print(f"Experiment 4 in {args.out} (preset {args.preset}, {args.trials} trials, {args.keys} keys):")
    for robot, gen in [("humanoid", g) for g in GENERATORS] + [("ant", g) for g in GENERATORS]:
        if robot == "ant" and state["ant_pending"]:
            left = state["archive_share"][("ant", gen)]
            if left < 1.0:  # evolved ahead of the ant's choice
                mark = "done" if left == 0.0 else f"partial ({left:.0%} left)"
                print(f"  archive {gen} --robot ant: {mark} ({archive_folder(args.out, 'ant', gen)})")
            continue
        needed = gen in humanoid_generators(args.out) if robot == "humanoid" else any(
            t.startswith(gen) for _, t in ant_choice(args.out) or [])
        if needed:
            left = state["archive_share"][(robot, gen)]
            mark = "done" if left == 0.0 else "left" if left == 1.0 else f"partial ({left:.0%} left)"
            print(f"  archive {gen} --robot {robot}: {mark} ({archive_path(args.out, robot, gen, args.preset)})")
    for robot, _, folder, names in runs(args.out):
        name = f"{robot} {run_label(robot, folder)}"
        print(f"  train {name}: {len(names) - state['train_left'][name]}/{len(names)} treatments done")
    if state["ant_pending"]:
        print("  train ant: not chosen yet (train ant --ant OBS/TREATMENT OBS/TREATMENT after the humanoid's "
              "results): predicted at 2 treatments, with their archives")
    for suite, walks in state["walks_left"].items():
        print(f"  evaluate {suite}: " + ", ".join(f"{r} {o} {n} walks left" for (r, o), n in walks.items())
              + (f" (rates recorded in {args.out}/eval/{suite})" if suite in state["measured"] else ""))
    pred = predict(state)
    print(f"predicted device time of the rest (one H200; train on {state['train_backend']}, evaluate on "
          f"{state['eval_backend']}; commands of --time-limit 8):")
    for name, (lo, hi) in pred.items():
        print(f"  {name}: {lo / 60:.1f}-{hi / 60:.1f} min, {commands((lo, hi))} command(s)")
    lo, hi = sum(v[0] for v in pred.values()), sum(v[1] for v in pred.values())
    print(f"  total: {lo / 60:.1f}-{hi / 60:.1f} min, {sum(commands(v) for v in pred.values())} commands")
    print("from (measured / assumed):")
    for name, (value, source) in RATES.items():
        print(f"  {name} = {value}: {source}")
    return 0


# ---------------------------------------------------------------------------------------------------------------
# --pack
# ---------------------------------------------------------------------------------------------------------------
def pack_members(out: Path) -> list[Path]:
    """What the next command needs from ``out``, file by file: every file except the ``checkpoint/`` folder of a
    finished archive and the checkpoints (``checkpoint*.npz``) of a finished treatment."""
    members = []
    if not out.is_dir():
        return members
    for path in sorted(out.rglob("*")):
        if not path.is_file() or path.name.endswith(".tmp"):
            continue
        rel = path.relative_to(out).parts
        if rel[0] == "archive" and "checkpoint" in rel[2:-1] and (out / rel[0] / rel[1] / "done.json").is_file():
            continue
        if path.name.startswith("checkpoint") and path.suffix == ".npz" and treatment_done(path.parent):
            continue
        members.append(path)
    return members


def walker_file(path: Path) -> bool:
    """Whether ``path`` is a walker's ``policy.msgpack`` or ``config.json`` (a folder under ``policies/`` holding
    both)."""
    return (path.name in ("policy.msgpack", "config.json") and "policies" in path.parts[:-1]
            and (path.parent / "policy.msgpack").is_file() and (path.parent / "config.json").is_file())


PACK_TRAIN_CHECKPOINTS = 12 * 2**20
"""Unfinished train checkpoints beyond this many bytes in all stay out of a pack (said in one line), so that the
pack stays under the 16 MiB a file the device returns may have; archives and finished work always go in."""


def pack(args) -> None:
    import io
    import tarfile
    import tempfile

    from jaxterrain import rl
    from jaxterrain.runtime.io import atomic_write_bytes

    root = Path.cwd().resolve()
    members = pack_members(args.out)
    unfinished = [p for p in members if p.name.startswith("checkpoint") and p.suffix == ".npz"
                  and p.relative_to(args.out).parts[0] == "train"]
    held = sum(p.stat().st_size for p in unfinished)
    if held > PACK_TRAIN_CHECKPOINTS:  # the pack would not come back: keep what will
        members = [p for p in members if p not in unfinished]
        print(f"pack: left out {len(unfinished)} unfinished train checkpoint(s), {held / 2**20:.1f} MiB, over what a "
              f"pack may carry ({PACK_TRAIN_CHECKPOINTS / 2**20:.0f} MiB): they resume on this machine only",
              flush=True)
    buf = io.BytesIO()
    with tempfile.TemporaryDirectory() as tmp, tarfile.open(fileobj=buf, mode="w:gz") as tar:
        for path in members:
            arcname = os.path.relpath(path.resolve(), root)
            if walker_file(path):  # a walker travels actor-only: 50 full ones (~55 MB) would not come back
                copy = Path(tmp) / os.path.dirname(arcname)
                if not (copy / "policy.msgpack").is_file():
                    rl.save_actor_only(path.parent, copy)
                path = copy / path.name
            tar.add(path, arcname=arcname)
    atomic_write_bytes(args.pack, buf.getvalue())
    size = args.pack.stat().st_size
    checkpoints = sum(p.stat().st_size for p in members if p.name.startswith("checkpoint"))
    over = ("; OVER the 16 MiB a file the device returns: resume on the same warm machine" if size > 16 * 2**20
            else "")
    print(f"packed {args.out} into {args.pack} ({size / 2**20:.2f} MiB; checkpoints {checkpoints / 2**20:.1f} MiB "
          f"before compression){over}", flush=True)


def main(argv=None) -> int:
    p = parser()
    args = p.parse_args(argv)
    check(p, args)
    if args.plan:  # with --pack: the plan, then the pack (nothing runs)
        code = print_plan(args)
        if args.pack is not None and args.out.is_dir():
            pack(args)
        return code
    stage = args.what[0]
    if stage == "archive":
        code = stage_archive(args, args.what[1], args.robot)
    elif stage == "train":
        code = stage_train(args, args.what[1], args.what[2] if len(args.what) > 2 else None)
    elif stage == "evaluate":
        code = stage_evaluate(args)
    else:
        code = stage_write(args)
    if args.pack is not None and args.out.is_dir():
        pack(args)
    if code == 3:
        print("time limit reached; run the same command again to continue", flush=True)
    return code


if __name__ == "__main__":
    sys.exit(main())
