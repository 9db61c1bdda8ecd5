"""An ``evolve`` run (one MAP-Elites archive) and a ``coverage`` run (Experiment 1b: every generator x descriptor
pair) as frozen, typed configs, nested where the concepts nest, with their presets and their serialised form.

    from jaxterrain.qd import run_config as R, runs
    run = R.PRESETS["smoke"]._replace(generator="worley")
    archive = runs.evolve_run(run, "runs/mine")                 # validates once, then evolves (None: time limit)
    flat = R.to_flat(run)                                       # config.json; R.from_flat(flat) == run

The shapes (each field consumed where ``docs/CONTRIBUTING.md`` says; ``schema.shape_lines`` prints them)::

    EvolveRun                           CoverageRun
      generator, size, fitness            generators, pairs, ranges (per descriptor), size, fitness, batched
      descriptors, ranges                 map_elites: MapElites
      mixture: Mixture (generators,       walks: Walks
        fresh; --generator mixed)         seed, preset
      map_elites: MapElites (generations, batch_size, initial_population, bins, window, stride,
        checkpoint_every, robot_height, out_of_range, store_heightmaps)
      walks: Walks (attempts, best, headings, robot, observation, backend, rollout_slots, spawn: the walker
        fitness)
      seed, preset

The serialised form is ``config.json``'s flat dict (:func:`to_flat` / :func:`from_flat`, through
:data:`EVOLVE_FIELDS` / :data:`COVERAGE_FIELDS`, ``{flat key: field path}``, whose keys are the flags' names);
:func:`from_flat` also reads the ``config.json`` of runs written before a key existed (:data:`LEGACY`). The checks of
single fields are :data:`EVOLVE_RULES` / :data:`COVERAGE_RULES`; :func:`jaxterrain.qd.runs.validate_evolve` and
:func:`jaxterrain.qd.table1.validate_coverage` run them with the checks against the registries. Standard library
only (``jaxterrain.runtime.schema``): ``--help`` reads the presets without importing JAX.
"""

from __future__ import annotations

from typing import NamedTuple, Optional

from jaxterrain.runtime.schema import at_least, at_most, from_flat as _from_flat, one_of, positive
from jaxterrain.runtime.schema import replace, to_flat as _to_flat, walks

__all__ = ["MapElites", "Walks", "Mixture", "EvolveRun", "CoverageRun", "EVOLVE_FIELDS", "COVERAGE_FIELDS",
           "LEGACY", "EVOLVE_RULES", "COVERAGE_RULES", "MIX_DEFAULT", "SPAWNS", "GENERATORS", "PAIRS", "PRESETS",
           "COVERAGE_PRESETS", "FLAT_PRESETS", "COVERAGE_FLAT_PRESETS", "EVOLVE_CONSUMERS", "COVERAGE_CONSUMERS",
           "from_flat", "to_flat", "coverage_from_flat", "coverage_to_flat", "EVOLVE_HELP", "COVERAGE_HELP"]


class MapElites(NamedTuple):
    """MAP-Elites' budget and grid (``qd.EvolveConfig``'s fields of the same names): ``generations`` after the
    ``initial_population`` random genomes, ``batch_size`` offspring each, ``bins`` cells per descriptor, the
    descriptors' ``window`` / ``stride``, Algorithm 1's ``robot_height`` (None: the features' default),
    ``out_of_range`` (clip / reject), and two run settings that do not change the archive: ``checkpoint_every``
    (generations per jitted chunk and checkpoint) and ``store_heightmaps`` (keep the elites' heightmaps)."""

    generations: int = 5000
    batch_size: int = 20
    initial_population: int = 100
    bins: int = 50
    window: int = 30
    stride: int = 2
    checkpoint_every: int = 250
    robot_height: Optional[float] = None
    out_of_range: str = "clip"
    store_heightmaps: bool = True


class Walks(NamedTuple):
    """The walker fitness (``fitness`` ``difficulty``): ``attempts`` walks per terrain in total, the ``best`` per
    heading averaged, over ``headings`` (1, 2, 4), by the shipped base policy of ``robot`` (its ``observation``
    set), on ``backend`` physics (``auto`` / ``jax`` / ``warp``) with a pool of ``rollout_slots`` env slots per
    device (None: every walk at once; speed only), each walker set down at a reset by the ``spawn`` rule
    (``jaxterrain.walker.SPAWNS``: ``feet``, or ``patch`` as every archive before 2026-11-29)."""

    attempts: int = 20
    best: int = 5
    headings: int = 1
    robot: str = "humanoid"
    observation: str = "blind"
    backend: str = "jax"
    rollout_slots: Optional[int] = None
    spawn: str = "feet"


class Mixture(NamedTuple):
    """``generator`` ``mixed``: the ``generators`` whose offspring compete for one archive's cells (None: the six
    built-in ones, :data:`MIX_DEFAULT`), ``fresh`` random genomes of each in every generation."""

    generators: Optional[tuple] = None
    fresh: int = 1


class EvolveRun(NamedTuple):
    """One archive of ``generator`` (a registered name, or ``mixed``: :class:`Mixture`) at ``size`` x ``size``
    pixels over the ``descriptors`` pair (grid ``ranges``: two (lo, hi) pairs, None for ``qd.DEFAULT_RANGES``),
    elites ranked by ``fitness`` (``difficulty``: the walker, :class:`Walks`; ``slope``: a cheap stand-in), from
    root key ``seed``; ``preset`` records the preset it was made from. Frozen; ``_replace`` or ``schema.replace``
    to change."""

    generator: str = "perlin"
    descriptors: tuple = ("roughness", "tpi")
    ranges: Optional[tuple] = None
    size: int = 256
    fitness: str = "difficulty"
    mixture: Mixture = Mixture()
    map_elites: MapElites = MapElites()
    walks: Walks = Walks()
    seed: int = 0
    preset: Optional[str] = None


GENERATORS = ("diamond_square", "perlin", "worley", "gan", "cppn")
"""Table 1's generators (``coverage``'s default)."""
PAIRS = (("tri", "tpi"), ("tri", "roughness"), ("tpi", "roughness"))
"""Table 1's descriptor pairs, the paper's columns TPI/TRI, roughness/TRI, roughness/TPI."""
MIX_DEFAULT = ("perlin", "worley", "diamond_square", "cppn", "gan", "steps")
"""``generator`` ``mixed``'s generators by default: the six built-in ones (``jaxterrain.generators.BUILTIN``)."""


class CoverageRun(NamedTuple):
    """Experiment 1b: an archive of every generator of ``generators`` for every descriptor pair of ``pairs`` (in
    that order, pairs outer: treatment ``k``'s key folds in its pair's and its generator's index), each an
    :class:`EvolveRun` of the same ``size``, ``fitness``, ``map_elites`` and ``walks``; ``ranges``: per
    descriptor ``((name, (lo, hi)), ...)`` sorted by name (None: ``qd.DEFAULT_RANGES``); ``batched``: every treatment
    at once (``qd.evolve_many``)."""

    generators: tuple = GENERATORS
    pairs: tuple = PAIRS
    ranges: Optional[tuple] = None
    size: int = 256
    fitness: str = "difficulty"
    batched: bool = False
    map_elites: MapElites = MapElites()
    walks: Walks = Walks()
    seed: int = 0
    preset: Optional[str] = None


_MAP_ELITES = {k: f"map_elites.{k}" for k in MapElites._fields}
_WALKS = {**{k: f"walks.{k}" for k in Walks._fields if k != "backend"}, "rollout_backend": "walks.backend"}
EVOLVE_FIELDS: dict[str, str] = {
    "generator": "generator", "descriptors": "descriptors", "ranges": "ranges", "size": "size", "fitness": "fitness",
    "mix": "mixture.generators", "fresh": "mixture.fresh", **_MAP_ELITES, **_WALKS, "seed": "seed",
    "preset": "preset"}
"""``{flat key: field path}`` of :class:`EvolveRun`: ``config.json``'s keys, which are the flags' names (``--`` and
dashes; ``rollout_backend`` is ``--backend``)."""
COVERAGE_FIELDS: dict[str, str] = {
    "generators": "generators", "pairs": "pairs", "ranges": "ranges", "size": "size", "fitness": "fitness",
    "batched": "batched", **_MAP_ELITES, **_WALKS, "seed": "seed", "preset": "preset"}
"""``{flat key: field path}`` of :class:`CoverageRun`."""

LEGACY = {"headings": 1, "robot_height": None, "out_of_range": "clip", "store_heightmaps": True,
          "rollout_slots": None, "rollout_backend": "jax", "robot": "humanoid", "observation": "blind", "mix": None,
          "fresh": 1, "seed": 0, "batched": False, "ranges": None, "spawn": "patch"}
"""The value a ``config.json`` key had in the runs made before it was written (what :func:`from_flat` fills in)."""

_FITNESSES = ("difficulty", "slope")  # jaxterrain.difficulty.FITNESSES (a test keeps them equal)
SPAWNS = ("feet", "patch")
"""How the walker fitness sets each walker down at a reset (``jaxterrain.walker.SPAWNS``; a literal, a test keeps
them equal)."""
_COMMON_RULES = {
    "size": at_least(1), "fitness": one_of(_FITNESSES),
    **{f"map_elites.{k}": at_least(1) for k in ("generations", "batch_size", "initial_population", "bins",
                                                 "checkpoint_every", "stride")},
    "map_elites.window": (at_least(2), at_most("size")), "map_elites.robot_height": positive(),
    "map_elites.out_of_range": one_of(("clip", "reject")), "map_elites.store_heightmaps": one_of((True, False)),
    "walks.attempts": at_least(1), "walks.best": (at_least(1), at_most("walks.attempts")),
    "walks.headings": walks("walks.attempts", "walks.best"),
    "walks.observation": one_of(("blind", "perceptive")), "walks.backend": one_of(("auto", "jax", "warp")),
    "walks.rollout_slots": at_least(1), "walks.spawn": one_of(SPAWNS),
}
EVOLVE_RULES = {**_COMMON_RULES, "mixture.fresh": at_least(0)}
"""The checks of single fields of :class:`EvolveRun` (``schema.check``; those against registries and between
parts: ``qd.runs.validate_evolve``)."""
COVERAGE_RULES = dict(_COMMON_RULES)
"""The checks of single fields of :class:`CoverageRun` (the rest: ``qd.table1.validate_coverage``)."""


def _ranges_encode(ranges: tuple) -> dict:
    return {name: list(pair) for name, pair in ranges}


def _ranges_decode(ranges) -> tuple:
    if isinstance(ranges, dict):
        return tuple((name, tuple(ranges[name])) for name in sorted(ranges))
    return ranges


_COVERAGE_CODECS = {"ranges": (_ranges_encode, _ranges_decode)}


def from_flat(flat: dict) -> EvolveRun:
    """The :class:`EvolveRun` of a flat config (``config.json``, a preset's flat form, a command line's values);
    keys of older versions' files take :data:`LEGACY`'s values; ``ValueError`` naming unknown keys."""
    return _from_flat(EvolveRun, flat, EVOLVE_FIELDS, LEGACY)


def to_flat(run: EvolveRun, command: Optional[str] = None) -> dict:
    """The serialised form of ``run``: ``config.json``'s flat dict (``preset`` left out when None), with
    ``command`` added when given."""
    out = _to_flat(run, EVOLVE_FIELDS, omit_none=("preset",))
    return out if command is None else {**out, "command": command}


def coverage_from_flat(flat: dict) -> CoverageRun:
    """The :class:`CoverageRun` of a flat config (``ranges`` a ``{descriptor: [lo, hi]}`` object there)."""
    return _from_flat(CoverageRun, flat, COVERAGE_FIELDS, LEGACY, codecs=_COVERAGE_CODECS)


def coverage_to_flat(run: CoverageRun, command: Optional[str] = None) -> dict:
    """The serialised form of a :class:`CoverageRun` (:func:`coverage_from_flat` reads it back)."""
    out = _to_flat(run, COVERAGE_FIELDS, codecs=_COVERAGE_CODECS, omit_none=("preset",))
    return out if command is None else {**out, "command": command}


_PAPER = EvolveRun()
PRESETS: dict[str, EvolveRun] = {name: replace(_PAPER, {"preset": name, **changes}) for name, changes in {
    "paper": {},
    # the paper's evaluation budget in larger batches, for a GPU: 25 generations x 4 000, a checkpoint every one
    "gpu": {"map_elites.generations": 25, "map_elites.batch_size": 4000, "map_elites.checkpoint_every": 1,
            "walks.rollout_slots": 16384, "mixture.fresh": 64},
    # a tenth of it: one treatment in a few GPU minutes, so that coverage --preset gpu-short fits a session
    "gpu-short": {"map_elites.generations": 5, "map_elites.batch_size": 2000, "map_elites.checkpoint_every": 1,
                  "map_elites.store_heightmaps": False, "walks.rollout_slots": 8192, "mixture.fresh": 32},
    # a CPU in seconds: 32 x 32 terrains, 10 x 10 cells, the slope fitness (no walking)
    "smoke": {"map_elites.generations": 4, "map_elites.batch_size": 8, "map_elites.initial_population": 16,
              "map_elites.bins": 10, "size": 32, "map_elites.window": 8, "walks.attempts": 2, "walks.best": 1,
              "map_elites.checkpoint_every": 2, "fitness": "slope", "ranges": ((0.0, 0.5), (-0.02, 0.02))},
}.items()}
"""``evolve``'s presets, typed (``preset`` set to the name): ``paper`` (the paper's treatment: 100 + 5 000 x 20),
``gpu`` (the same budget in 25 generations of 4 000), ``gpu-short`` (a tenth), ``smoke`` (a CPU, seconds)."""


def _coverage(evolve: EvolveRun, name: str, **changes) -> CoverageRun:
    base = CoverageRun(size=evolve.size, fitness=evolve.fitness, map_elites=evolve.map_elites, walks=evolve.walks,
                       preset=name)
    return replace(base, changes)


COVERAGE_PRESETS: dict[str, CoverageRun] = {
    "paper": _coverage(PRESETS["paper"], "paper"),
    # the paper's 5 000 generations x 20 per treatment, every treatment at once: 15 x 20 = 300 terrains a generation
    # scored by one fitness call (qd.evolve_many), a checkpoint every 50 generations
    "paper-batched": _coverage(PRESETS["paper"], "paper-batched", batched=True,
                               **{"map_elites.checkpoint_every": 50}),
    "gpu": _coverage(PRESETS["gpu"], "gpu"),
    "gpu-short": _coverage(PRESETS["gpu-short"], "gpu-short"),
    # descriptors of 32 x 32 maps at window 8 are wider than the 256 x 256 defaults: the smoke preset's ranges
    "smoke": _coverage(PRESETS["smoke"], "smoke", ranges=(("roughness", (0.0, 1.0)), ("tpi", (-0.02, 0.02)),
                                                          ("tri", (0.0, 0.5))),
                       **{"map_elites.generations": 2, "map_elites.initial_population": 12,
                          "map_elites.batch_size": 8}),
}
"""``coverage``'s presets, typed: each of ``evolve``'s over Table 1's treatments, and ``paper-batched``."""


def _flat_preset(flat: dict) -> dict:
    return {k: v for k, v in flat.items() if k not in ("preset", "seed")}


FLAT_PRESETS: dict[str, dict] = {name: _flat_preset(to_flat(p)) for name, p in PRESETS.items()}
"""``evolve``'s presets in their flat form, without ``preset`` and ``seed`` (what a fresh run's ``config.json``
adds, with ``command``)."""
COVERAGE_FLAT_PRESETS: dict[str, dict] = {name: _flat_preset(coverage_to_flat(p))
                                          for name, p in COVERAGE_PRESETS.items()}
"""``coverage``'s presets in their flat form."""

_COMMON_CONSUMERS = {
    "": "qd.runs.evolve_run", "size": "qd.runs.generator_of (generators.get(name, size))",
    "fitness": "qd.runs.fitness_of (difficulty.FITNESSES)", "map_elites": "qd.runs.evolve_config (qd.evolve)",
    "walks": "qd.runs.evolve_config (qd.evolve's walker fitness)", "seed": "qd.runs.evolve_run (the root key)",
    "preset": "recorded",
}
EVOLVE_CONSUMERS = {**_COMMON_CONSUMERS, "generator": "qd.runs.generator_of",
                    "descriptors": "qd.runs.evolve_config", "ranges": "qd.runs.evolve_config",
                    "mixture": "qd.runs.generator_of (generators.mixture)"}
"""Where each field of :class:`EvolveRun` is consumed (``docs/CONTRIBUTING.md``; a test checks the functions)."""
COVERAGE_CONSUMERS = {**_COMMON_CONSUMERS, "": "qd.table1.coverage_run",
                      "generators": "qd.table1.treatments", "pairs": "qd.table1.treatments",
                      "ranges": "qd.table1.treatment_run", "batched": "qd.table1.coverage_run"}
"""Where each field of :class:`CoverageRun` is consumed."""

EVOLVE_HELP: dict[str, str] = {
    "generator": "registered generator name, or mixed: one archive whose offspring of every --mix "
                 "generator compete for the cells, each elite recording its generator",
    "mix": f"with --generator mixed: the generators of the mixture (default: all six, {' '.join(MIX_DEFAULT)})",
    "fresh": "with --generator mixed: fresh random genomes of EACH generator among every generation's offspring, so "
             "that a generator holding no cell keeps competing",
    "descriptors": "descriptor pair, e.g. roughness tpi",
    "generations": "MAP-Elites generations after the initial population",
    "batch_size": "offspring per generation",
    "initial_population": "random genomes evaluated first",
    "bins": "cells per descriptor",
    "size": "heightmap side in pixels",
    "checkpoint_every": "generations between checkpoints",
    "fitness": "what an elite's fitness measures: difficulty (the base policy walks it) or slope (a cheap stand-in, "
               "no walking)",
    "attempts": "walks per terrain in total",
    "best": "best walks averaged per heading",
    "headings": "headings of the walks (1: the paper's +x; 4: +x, +y, -x, -y; mean over headings)",
    "rollout_slots": "{slots}: per device (default: all walks of a generation at once)",
    "rollout_backend": "walker physics of the difficulty rollouts: {backend}",
    "robot": "whose shipped base policy the walker fitness walks (default humanoid; jaxterrain.walker.robots, or a "
             "--plugin's); the archive records it",
    "observation": "which of the robot's shipped base policies the walker fitness walks: blind (default, the "
                   "paper's) or perceptive (with a height scan); the archive records it",
    "spawn": "how the walker fitness sets each walker down at a reset: feet (default: the body lifted until every "
             "foot clears the terrain under it) or patch (only the lowest foot clear of a 0.5 m patch under the "
             "torso: every archive before 2026-11-29, which cut the ant's feet into rising ground; a run saved before "
             "reads as patch, or resumed, as the rule its provenance.jsonl says it started with); the archive "
             "records it",
    "store_heightmaps": "store the elites' heightmaps in archive.npz (--no-store-heightmaps: leave them out, they can "
                        "be re-rendered from the genomes)",
}
"""``evolve``'s flags: each flat key's help, the field's documentation as the command line's ``--help`` shows it
(``experiments.cli_gen`` adds the type, the choices, the allowed range of the field's rule where the text says
``{range}`` or at its end, and every preset's value; ``{backend}``, ``{randomise}`` and ``{slots}`` are
phrases every command shares, ``experiments.common.PHRASES``). The keys are the flags the command exposes, in
``--help``'s order."""

COVERAGE_HELP: dict[str, str] = {
    "generators": f"generator names (default: {' '.join(GENERATORS)})",
    "generations": "MAP-Elites generations of each treatment after its initial population",
    "batch_size": "offspring per generation",
    "size": "heightmap side in pixels",
    "bins": "cells per descriptor",
    "fitness": "what an elite's fitness measures: difficulty (the base policy walks it) or slope (a cheap stand-in, "
               "no walking)",
    "batched": "evolve every treatment at once (one jitted generation, one fitness call on all treatments' offspring; "
               "jaxterrain.qd.evolve_many); not with --shard",
}
"""``coverage``'s flags: each flat key's help, the field's documentation as the command line's ``--help`` shows it
(``experiments.cli_gen`` adds the type, the choices, the allowed range of the field's rule where the text says
``{range}`` or at its end, and every preset's value; ``{backend}``, ``{randomise}`` and ``{slots}`` are
phrases every command shares, ``experiments.common.PHRASES``). The keys are the flags the command exposes, in
``--help``'s order."""
