"""The archive's types and settings: :class:`EvolveConfig` (checked by :func:`resolve_config`), the host
:class:`Archive`, the descriptor ranges (:data:`DEFAULT_RANGES`) and the config's JSON form."""

from __future__ import annotations

import math
import numbers
from typing import Callable, NamedTuple

import jax
import numpy as np

from jaxterrain.runtime.validation import walks
from jaxterrain.terrain import TerrainScale, validate_scale
from jaxterrain.walker.config import SPAWNS
from jaxterrain.walker.robots import names as robot_names

__all__ = ["PRNGKey", "FitnessFn", "DEFAULT_RANGES", "EvolveConfig", "Archive", "resolve_config", "config_to_dict",
           "config_from_dict", "LEGACY_SPAWN"]

PRNGKey = jax.Array
FitnessFn = Callable[[jax.Array, PRNGKey, jax.Array], jax.Array]
"""``(heightmaps [B, H, W], key, needed [B] bool) -> [B]``; see :mod:`jaxterrain.qd.scoring`."""

# Grid ranges per descriptor name, shared by every generator (window 30, stride 2, 256 x 256 heightmaps in [0, 1]).
# How they were chosen (2026-11-21; `python -m experiments features --calibrate` does the same): 32 random genomes
# plus 32 twice-mutated ones of each generator were rendered at 256 x 256 and described with window 30 / stride 2.
# Each range is [0.5th, 99.5th] percentile of the pooled values, rounded outwards to 2 significant digits, with 0 as
# the lower end of these non-negative descriptors. Pooled percentiles [0.5, 99.5]: without the GAN (cppn,
# diamond_square, perlin, worley) tri [0.00046, 0.166], roughness [0.0024, 0.750]; with the GAN (all five)
# tri [0.00015, 0.152], tpi (mean |TPI|) [0.00001, 0.110], roughness [0.0007, 0.630].
# So nearly every terrain falls inside the grid and the 50 bins are not spent on values no generator reaches.
# The vertical-face descriptors (2026-11-29, CPU, the same 32 + 32 genomes of each of the six generators, ``steps``
# included, at window 30 / stride 2, pooled over the 287 of 384 that pass Algorithm 1, as ``features --calibrate``):
# faces [0, 0.806], max_step [0.00006, 0.261]. The top of faces is Perlin's small-scale noise (up to 0.92); steps
# alone spans faces [0, 0.16] and max_step [0.006, 0.26], so a steps archive fills max_step's range, a fifth of
# faces' (pass ``ranges`` to bin faces finer).
# Re-measure after changing a feature definition or the generators; other windows need ``config.ranges``.
DEFAULT_RANGES: dict[str, tuple[float, float]] = {
    "tri": (0.0, 0.17),
    "tpi": (0.0, 0.12),
    "roughness": (0.0, 0.76),
    "faces": (0.0, 0.81),
    "max_step": (0.0, 0.27),
}


class EvolveConfig(NamedTuple):
    """MAP-Elites settings (defaults: the paper's protocol, 5 000 generations x 20 offspring).

    Attributes:
      generations: generations after the initial population (paper: 5 000).
      batch_size: offspring per generation (paper: 20).
      initial_population: random genomes evaluated in generation 0 (paper: 100).
      bins: cells per descriptor (paper: 50), so ``bins ** 2`` cells.
      descriptors: the two descriptor names (``features.descriptors`` names).
      ranges: ``((lo, hi), (lo, hi))`` grid ranges of the two descriptors, or None for :data:`DEFAULT_RANGES`.
      window, stride: descriptor kernel size and stride (paper: 30 and 2).
      attempts, best: walker attempts per terrain IN TOTAL and how many of the best are averaged PER HEADING
        (paper: 20 and 5).
      headings: 1 (the paper: every walk along +x), 2 or 4: the walker fitness is
        ``difficulty.Protocol(attempts, best, headings)`` (``attempts // headings`` walks per heading, the mean over
        headings of each heading's best ``best``); ``difficulty.HEADINGS`` is ``attempts=80, best=5, headings=4``.
        The archive records it, so a curriculum can evaluate under the protocol its fitness came from.
      checkpoint_every: RUN SETTING: generations per jitted chunk (and between checkpoints when a checkpoint folder
        is given); does not change the archive.
      robot_height: robot height in metres for Algorithm 1 (threshold robot_height / 3); None: the features
        module's default.
      traversable_window: Algorithm 1's window (approx. step length, paper: 26 pixels).
      out_of_range: "clip" (into the edge cells) or "reject" (never inserted); see the module docstring.
      store_heightmaps: RUN SETTING: render the elites at the end and keep their heightmaps (uint16) in the archive.
      rollout_slots: RUN SETTING: env slots of the difficulty fitness's rollout pool
        (``walker.rollout.batched_distances``), or None to run each generation's ``batch_size x attempts`` rollouts all
        at once. A speed knob only (same rollouts, statistically the same fitness), so a run may resume with
        another value.
      scale: the ONE :class:`~jaxterrain.terrain.TerrainScale` (metres per pixel and per heightmap unit) of both
        Algorithm 1 and the walker fitness (default ``TerrainScale()``: 0.04 m, 1.0 m).
      rollout_backend: RUN SETTING: the walker fitness's physics, ``"jax"`` (MJX-JAX) or ``"warp"`` (MuJoCo Warp on
        a bank of terrain tiles, ``difficulty.fitness_fn(backend=)``). The same walks up to the physics
        implementation's float arithmetic (fitness within 0.03, ``benchmarks/rollouts.py``'s backend check), so,
        like ``rollout_slots``, a run may resume with another value.

      robot: the walker whose shipped base policy the fitness walks (``jaxterrain.walker.robots``; its policy in
        ``rl.base_policy_dir(robot)``). The archive records it: an archive's fitness is one robot's difficulty.
      observation: which of the robot's shipped base policies walks: ``"blind"`` (the paper's) or
        ``"perceptive"`` (its twin with a height scan, ``rl.base_policy_dir(robot, "perceptive")``); recorded too.
      spawn: how the walker fitness sets each walker down at a reset (``walker.SPAWNS``, ``WalkerConfig.spawn``):
        ``"feet"`` (every foot clear of the terrain under it) or ``"patch"`` (the rule of every archive before
        2026-11-29: an archive header written before the field reads as ``"patch"``); recorded too.

    The run settings (and ``generations``) stay here so that config files and archive headers keep one shape; they
    are the host driver's, not the algorithm's.
    """

    generations: int = 5000
    batch_size: int = 20
    initial_population: int = 100
    bins: int = 50
    descriptors: tuple[str, str] = ("roughness", "tpi")
    ranges: tuple[tuple[float, float], tuple[float, float]] | None = None
    window: int = 30
    stride: int = 2
    attempts: int = 20
    best: int = 5
    checkpoint_every: int = 100
    robot_height: float | None = None
    traversable_window: int = 26
    out_of_range: str = "clip"
    store_heightmaps: bool = True
    rollout_slots: int | None = None
    scale: TerrainScale = TerrainScale()
    rollout_backend: str = "jax"
    headings: int = 1
    robot: str = "humanoid"
    observation: str = "blind"
    spawn: str = "feet"


class Archive(NamedTuple):
    """A MAP-Elites archive (host numpy arrays).

    Attributes:
      genomes: tuple with one genome pytree per generator name; leaves ``[cells, ...]`` (rows of cells held by
        another generator or empty are zeros).
      generator_names: tuple of generator names; ``source`` indexes it.
      source: [cells] int32, the generator id of each elite, -1 for an empty cell.
      fitness: [cells] float32, ``-inf`` for an empty cell.
      descriptors: [cells, 2] float32, raw (unclipped) descriptor values of the elites.
      centroids: [cells, 2] float32, grid centroids (cell i has centroid i).
      heightmaps: [cells, H, W] uint16 (height * 65535) of the elites (zeros for empty cells), or None.
      config: the :class:`EvolveConfig` (ranges resolved).
      metrics: dict name -> [generations + 1] float32 history (empty for a combined archive).
    """

    genomes: tuple
    generator_names: tuple[str, ...]
    source: np.ndarray
    fitness: np.ndarray
    descriptors: np.ndarray
    centroids: np.ndarray
    heightmaps: np.ndarray | None
    config: EvolveConfig
    metrics: dict

    @property
    def filled(self) -> np.ndarray:
        """[cells] bool, True where a cell holds an elite."""
        return self.source >= 0



def resolve_config(config: EvolveConfig) -> EvolveConfig:
    """Check ``config`` on the host and fill in ``ranges`` from :data:`DEFAULT_RANGES`. Raises ``ValueError`` naming
    the field, what it allows and the value it got."""
    if not isinstance(config, EvolveConfig):
        raise ValueError(f"config must be a qd.EvolveConfig; got {type(config).__name__}")

    def positive(name, value, minimum=1):
        # ints only (numpy ints too): a float, a bool, None or a string is refused, as a float bins or window would
        # only fail later inside JAX
        if not isinstance(value, numbers.Integral) or isinstance(value, bool) or value < minimum:
            raise ValueError(f"EvolveConfig.{name} must be an integer >= {minimum}; got {value!r}")

    positive("generations", config.generations, 0)
    for name in ("batch_size", "initial_population", "bins", "stride", "attempts", "best", "headings",
                 "checkpoint_every"):
        positive(name, getattr(config, name))
    for name in ("window", "traversable_window"):  # features' windows are at least 2 x 2
        positive(name, getattr(config, name), 2)
    walks("EvolveConfig", config)
    if isinstance(config.descriptors, str) or not isinstance(config.descriptors, (tuple, list)):
        raise ValueError(f"EvolveConfig.descriptors must be two different descriptor names; got "
                         f"{config.descriptors!r}")
    names = tuple(config.descriptors)
    if len(names) != 2 or len(set(names)) != 2 or not all(isinstance(n, str) and n for n in names):
        raise ValueError(f"EvolveConfig.descriptors must be two different descriptor names; got {names!r}")
    if not isinstance(config.store_heightmaps, (bool, np.bool_)):
        raise ValueError(f"EvolveConfig.store_heightmaps must be True or False; got {config.store_heightmaps!r}")
    if config.out_of_range not in ("clip", "reject"):
        raise ValueError(f"EvolveConfig.out_of_range must be 'clip' or 'reject'; got {config.out_of_range!r}")
    if config.rollout_slots is not None:
        positive("rollout_slots", config.rollout_slots)
    if config.rollout_backend not in ("jax", "warp"):
        raise ValueError(f"EvolveConfig.rollout_backend must be 'jax' or 'warp'; got {config.rollout_backend!r}")
    if config.robot not in robot_names():
        raise ValueError(f"EvolveConfig.robot must be one of {', '.join(robot_names())}; got {config.robot!r}")
    if config.observation not in ("blind", "perceptive"):
        raise ValueError(f"EvolveConfig.observation must be 'blind' or 'perceptive'; got {config.observation!r}")
    if not isinstance(config.spawn, str) or config.spawn not in SPAWNS:
        raise ValueError(f"EvolveConfig.spawn must be one of {', '.join(SPAWNS)}; got {config.spawn!r}")
    if config.robot_height is not None and not (
            isinstance(config.robot_height, numbers.Real) and not isinstance(config.robot_height, bool)
            and math.isfinite(config.robot_height) and config.robot_height > 0):
        raise ValueError(f"EvolveConfig.robot_height must be > 0 metres or None; got {config.robot_height!r}")
    try:
        scale = config.scale
        if isinstance(scale, dict):
            scale = _scale_from_dict(scale)
        elif not isinstance(scale, TerrainScale) and isinstance(scale, (tuple, list)):
            if len(scale) != 2:
                raise ValueError(f"scale must be (cell_size, height); got {scale!r}")
            scale = TerrainScale(*scale)
        scale = validate_scale(scale)
    except ValueError as err:
        raise ValueError(f"EvolveConfig.scale: {err}") from err
    if config.ranges is None:
        missing = [n for n in names if n not in DEFAULT_RANGES]
        if missing:
            raise ValueError(
                f"EvolveConfig.ranges: no default range for descriptor(s) {missing}; known: "
                f"{sorted(DEFAULT_RANGES)}; pass ranges=((lo, hi), (lo, hi))"
            )
        ranges = tuple(DEFAULT_RANGES[n] for n in names)
    else:
        ranges = config.ranges
    try:
        if isinstance(ranges, (str, bytes)) or any(isinstance(r, (str, bytes)) or len(r) != 2 for r in ranges):
            raise TypeError
        ranges = tuple((_number(lo), _number(hi)) for lo, hi in ranges)
    except (TypeError, ValueError):
        raise ValueError(f"EvolveConfig.ranges must be two finite (lo, hi) pairs with hi > lo; got "
                         f"{config.ranges!r}") from None
    if len(ranges) != 2 or any(not (math.isfinite(lo) and math.isfinite(hi) and hi > lo) for lo, hi in ranges):
        raise ValueError(f"EvolveConfig.ranges must be two finite (lo, hi) pairs with hi > lo; got {config.ranges!r}")
    return config._replace(descriptors=names, ranges=ranges, scale=scale)


def _number(v) -> float:
    """``float(v)`` for a real number (not a bool or a string); TypeError otherwise."""
    if isinstance(v, (bool, str, bytes)) or not isinstance(v, (numbers.Real, np.ndarray)):
        raise TypeError
    return float(v)


def _scale_from_dict(d: dict) -> TerrainScale:
    """A :class:`TerrainScale` from its JSON form; ``ValueError`` naming unknown fields."""
    unknown = set(d) - set(TerrainScale._fields)
    if unknown:
        raise ValueError(f"unknown TerrainScale field(s) {sorted(unknown)}; known: {list(TerrainScale._fields)}")
    return TerrainScale(**d)


def config_to_dict(config: EvolveConfig) -> dict:
    """JSON-friendly dict of an :class:`EvolveConfig`."""
    d = config._asdict()
    d["descriptors"] = list(config.descriptors)
    d["ranges"] = None if config.ranges is None else [list(r) for r in config.ranges]
    d["scale"] = {"cell_size": float(config.scale.cell_size), "height": float(config.scale.height)}
    return d


LEGACY_SPAWN = "patch"
"""The spawn rule of a config dict written before :class:`EvolveConfig` had ``spawn`` (what
:func:`config_from_dict` fills in): the rule of every archive evolved before 2026-11-29."""


def config_from_dict(d: dict) -> EvolveConfig:
    """Inverse of :func:`config_to_dict`; unknown keys raise ``ValueError``; a dict without ``spawn`` (an archive
    written before the field) reads as :data:`LEGACY_SPAWN`."""
    unknown = set(d) - set(EvolveConfig._fields)
    if unknown:
        raise ValueError(f"unknown EvolveConfig field(s) {sorted(unknown)}; known: {list(EvolveConfig._fields)}")
    d = {"spawn": LEGACY_SPAWN, **d}
    if "descriptors" in d:
        d["descriptors"] = tuple(d["descriptors"])
    if d.get("ranges") is not None:
        try:
            d["ranges"] = tuple(tuple(_number(v) for v in r) for r in d["ranges"])
        except (TypeError, ValueError):
            raise ValueError(f"EvolveConfig.ranges must be two finite (lo, hi) pairs with hi > lo; got "
                             f"{d['ranges']!r}") from None
    if isinstance(d.get("scale"), dict):  # absent in files written before the field existed: the default scale
        try:
            d["scale"] = _scale_from_dict(d["scale"])
        except ValueError as err:
            raise ValueError(f"EvolveConfig.scale: {err}") from None
    return EvolveConfig(**d)
