"""``python -m experiments gradient ARCHIVE.npz [...]``: the difficulty gradient of MAP-Elites archives
(:func:`jaxterrain.qd.gradient.gradient`, which documents the measures; this command is its flags and files).

The stored fitness is the paper's protocol (20 walks along +x, best 5), as the archive was evolved. With
``--protocol headings`` (or ``paper``) every elite is re-rendered and walked again under that
:class:`jaxterrain.difficulty.Protocol` (fields overridable: ``--attempts --best --headings --start-spread
--rule``), in ONE batched call over all elites on a rollout pool (``--rollout-slots``; ``auto`` = 16 384 on a GPU, all
at once on a CPU), and the tables show the protocols side by side: ``stored``, the protocol, and ``heading 0`` (the
same rollouts' +x walks alone). ``--sample N`` walks only N elites per archive, evenly spread over distance.

Writes into the run folder (``runs/gradient-<time>/`` or ``--out``): ``config.json``, ``gradient.csv`` (one row per
archive, protocol, distance measure and band), ``gradient_summary.csv`` (one row per archive and protocol:
correlations, shares, cost), ``gradient.md``, ``gradient.png`` and, when walked, ``<archive>_walks.npz`` (cells,
distances, stored fitness and every rollout's distance and length, heading-major). ``--reseat`` (with
``--protocol``, every elite) also writes ``<archive>_reseated.npz`` (``jaxterrain.qd.reseat`` with the fitness walked
here; ``docs/results/insertion_bug.md``).

Example (GPU)::

    python -m experiments gradient docs/results/exp1b_gpu_sound_cppn_archive.npz --protocol headings --out DIR
"""

from __future__ import annotations

import argparse
from pathlib import Path

from experiments import common

PRESETS: dict[str, dict] = common.with_preset_names({
    "default": dict(archives=[], protocol=None, attempts=None, best=None, headings=None, start_spread=None,
                    rule=None, slots="auto", chunk=None, sample=None, band_width=10.0, threshold=0.9,
                    distance="corner", reseat=False),
}, {"smoke": "default", "gpu-short": "default", "gpu": "default", "paper": "default"})
PROTOCOLS = ("paper", "headings")
WALK_KEYS = ("attempts", "best", "headings", "start_spread", "rule", "chunk", "sample")
"""The keys that only shape the walks of ``--protocol`` (with ``slots`` and ``seed``: refused without it)."""
DISTANCES = ("corner", "index")


# ----------------------------------------------------------------------------------------------------------------
# The command
# ----------------------------------------------------------------------------------------------------------------
def add_arguments(parser: argparse.ArgumentParser) -> None:
    common.add_run_arguments(parser, PRESETS, "default", time_limit=False)
    parser.add_argument("archives", nargs="*", type=str, help="archive.npz files (jaxterrain.qd.save format)")
    parser.add_argument("--protocol", choices=PROTOCOLS, default=None,
                        help="also walk every elite again under this protocol (difficulty.PAPER or HEADINGS)")
    parser.add_argument("--attempts", type=int, default=None, help="override the protocol's attempts (in total)")
    parser.add_argument("--best", type=int, default=None, help="override the protocol's best (per heading)")
    parser.add_argument("--headings", type=int, choices=(1, 2, 4), default=None, help="override the headings")
    parser.add_argument("--start-spread", type=float, default=None, help="override the start spread (m)")
    parser.add_argument("--rule", choices=("mean", "min"), default=None, help="override the rule over headings")
    common.add_slots_argument(parser, "slots", "an int, 'all' or 'auto' (16384 on a GPU, all at once on a CPU)",
                              type=str, aliases=("--slots",))
    parser.add_argument("--chunk", type=int, default=None, help="elites per compiled call (bounds device memory)")
    parser.add_argument("--sample", type=int, default=None, help="walk only N elites per archive, spread over "
                        "distance")
    parser.add_argument("--band-width", type=float, default=None, help="band width in cells (default 10)")
    parser.add_argument("--threshold", type=float, default=None, help="'easy' fitness threshold (default 0.9)")
    parser.add_argument("--distance", choices=DISTANCES, default=None,
                        help="distance measure of the figure and summary (default corner; the CSV has both)")
    parser.add_argument("--reseat", action=argparse.BooleanOptionalAction, default=None,
                        help="with --protocol (no --sample): also write <archive>_reseated.npz, every valid genome "
                             "in its own terrain's cell with the fitness walked here (jaxterrain.qd.reseat)")


def overrides(args) -> dict:
    return dict(archives=list(args.archives) or None, protocol=args.protocol, attempts=args.attempts, best=args.best,
                headings=args.headings, start_spread=args.start_spread, rule=args.rule, slots=args.slots,
                chunk=args.chunk, sample=args.sample, band_width=args.band_width, threshold=args.threshold,
                distance=args.distance, reseat=args.reseat)


def resolve_protocol(cfg: dict):
    """The :class:`~jaxterrain.difficulty.Protocol` of the config (None when nothing is walked again)."""
    from jaxterrain import difficulty

    if cfg.get("protocol") is None:
        return None
    if cfg["protocol"] not in PROTOCOLS:
        raise common.UsageError(f"--protocol must be one of {', '.join(PROTOCOLS)}; got {cfg['protocol']!r}")
    base = difficulty.PAPER if cfg["protocol"] == "paper" else difficulty.HEADINGS
    fields = {k: cfg.get(k) for k in ("attempts", "best", "headings", "start_spread", "rule")}
    try:
        return base._replace(**{k: v for k, v in fields.items() if v is not None}).validate()
    except ValueError as err:
        raise common.UsageError(f"--protocol / --attempts / --best / --headings / --start-spread / --rule: "
                                f"{str(err).splitlines()[0]}") from None


def parse_slots(value) -> int | str | None:
    """``--rollout-slots``: None, ``"all"``, ``"auto"`` or an integer >= 1 (also as text); :class:`~experiments.common.UsageError`
    otherwise."""
    if value in (None, "all", "auto"):
        return value
    try:
        slots = int(value)
    except (TypeError, ValueError):
        slots = 0
    if isinstance(value, bool) or slots < 1 or (isinstance(value, float) and value != slots):
        raise common.UsageError(f"--rollout-slots must be an integer >= 1, 'all' or 'auto'; got {value!r}")
    return slots


def resolve_slots(value) -> int | None:
    """``"auto"`` -> 16 384 on a GPU / TPU, None (all at once) on a CPU; ``"all"`` / None -> None; else an int."""
    import jax

    value = parse_slots(value)
    if value in (None, "all"):
        return None
    if value == "auto":
        return None if jax.default_backend() == "cpu" else 16384
    return value


def check_config(cfg: dict) -> None:
    """Before a run folder: at least one archive, each an existing file that reads as an archive with elites
    (``qd.gradient.load_elites``; read again when walked, not kept); ``--slots``, ``--distance``, the protocol's fields
    and ``--reseat``'s needs."""
    if not cfg.get("archives"):
        raise common.UsageError("give at least one archive.npz (ARCHIVE ...)")
    for path in cfg["archives"]:
        if not Path(path).is_file():
            raise common.UsageError(f"archive {path}: no such file")
    parse_slots(cfg.get("slots"))
    if cfg.get("distance") not in DISTANCES:
        raise common.UsageError(f"--distance must be one of {', '.join(DISTANCES)}; got {cfg.get('distance')!r}")
    protocol = resolve_protocol(cfg)
    if protocol is None:  # nothing is walked: the flags of the walks would be accepted and ignored
        common.refuse_given({common.flag(k): cfg.get(k) for k in WALK_KEYS}
                            | {"--rollout-slots": None if cfg.get("slots") in (None, "auto") else cfg["slots"],
                               "--seed": cfg.get("seed") or None},
                            "sets the walks of --protocol, which is not given (the stored fitness is read, nothing "
                            "is walked): give --protocol paper or headings, or drop it")
    if cfg.get("reseat") and (protocol is None or cfg.get("sample") is not None):
        raise common.UsageError("--reseat needs --protocol (every elite walked again) and no --sample")
    if cfg.get("reseat") and (protocol.start_spread != 0.0 or protocol.rule != "mean"):
        raise common.UsageError("--reseat: an archive records the protocol's attempts, best and headings only; not "
                                "with --start-spread or --rule min")
    from jaxterrain.qd.gradient import load_elites

    for path in cfg["archives"]:
        try:
            load_elites(path)
        except ValueError as err:
            raise common.UsageError(str(err)) from None


def main(args) -> int:
    from jaxterrain.qd.gradient import GradientSettings, gradient

    folder, cfg = common.setup_run("gradient", args, PRESETS, "default", overrides(args), check=check_config)
    settings = GradientSettings(float(cfg["band_width"]), float(cfg["threshold"]), cfg["distance"])
    gradient(cfg["archives"], folder, protocol=resolve_protocol(cfg), settings=settings, seed=int(cfg["seed"]),
             slots=resolve_slots(cfg.get("slots")), chunk=cfg.get("chunk"), sample=cfg.get("sample"),
             reseat_walked=bool(cfg.get("reseat")), say=lambda line: print(line, flush=True))
    print(f"done -> {folder}", flush=True)
    return 0
