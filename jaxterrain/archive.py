"""MAP-Elites terrain archives (paper section 3.3), batched on device through QDax.

    >>> from jaxterrain import archive
    >>> config = archive.EvolveConfig(generations=5000, batch_size=20, descriptors=("roughness", "tpi"))
    >>> arch = archive.evolve("perlin", None, config, key, checkpoint_dir="runs/x/ckpt")
    >>> archive.coverage(arch)                      # percent of the 50 x 50 cells filled
    >>> archive.save("perlin.npz", arch); arch = archive.load("perlin.npz")
    >>> both = archive.combine([arch_perlin, arch_cppn])   # cell by cell, highest fitness wins

The loop
--------
Generation 0 evaluates ``initial_population`` random genomes (``generator.sample``); every later generation draws
``batch_size`` parents uniformly (with replacement) from the filled cells, mutates them with ``generator.mutate``,
renders them, computes the two descriptors and the fitness, and inserts them into a QDax ``MapElitesRepertoire``
over a ``bins x bins`` grid of ``compute_euclidean_centroids``. Replacement is ordinary MAP-Elites (the paper keeps
the LOWEST-difficulty terrain, i.e. the HIGHEST fitness): the best offspring per cell enters only when strictly
better than the elite. Before insertion the fitness of an offspring is set to ``-inf`` (so it never enters) when

* it fails Algorithm 1 (``features.is_traversable``): counted in the ``rejected`` metric;
* its fitness is NaN (counted in ``nan``, among the offspring that passed the other checks);
* a descriptor is out of range and ``config.out_of_range == "reject"`` (counted in ``out_of_range`` either way).

Those offspring need no fitness: a fitness function that takes ``needed=`` is told which are left (the walker's
rollout pool then never starts their rollouts; 21 % of the offspring of a GPU-preset Perlin run were rejected).

No selection emitter from QDax is used (``MixingEmitter`` reuses one key for two splits; see NOTES.md): selection,
mutation and evaluation are written here, and the repertoire is QDax's. The whole loop runs on device:
``lax.scan`` over generations, one ``jit`` per chunk of ``checkpoint_every`` generations, with a checkpoint between
chunks.

Keys
----
Generation ``g`` (0 = initial population) uses ``fold_in(key, g)`` split into selection / mutation / evaluation
keys. Nothing else is random, so the archive after generation ``g`` depends only on ``(key, config, g)`` and not on
how the run was chunked or interrupted: a resumed run ends with exactly the archive of an uninterrupted one.

Descriptor ranges
-----------------
The grid range of a descriptor is fixed per descriptor NAME (the paper: "feature ranges were identical between
generator coverage maps"), looked up in :data:`DEFAULT_RANGES` unless ``config.ranges`` overrides it. Descriptors
outside the range are, by default, CLIPPED into the edge cells (``out_of_range="clip"``): the edge cell then means
"this value or more", which keeps hard-but-traversable terrains usable by a curriculum, and Algorithm 1 already bounds
how rough an archived terrain can be. ``out_of_range="reject"`` keeps them out instead. The stored descriptors are
always the raw (unclipped) values.

File format (``save`` / ``load``)
---------------------------------
One uncompressed ``.npz`` (written atomically) with these members:

* ``header``: uint8 bytes of a UTF-8 JSON object::

      {"format": "jaxterrain-archive", "version": 1,
       "generator_names": ["perlin", ...],          # index = source id
       "descriptor_names": ["roughness", "tpi"], "ranges": [[lo, hi], [lo, hi]], "bins": 50,
       "cells": 2500, "config": {...EvolveConfig fields...},
       "genomes": [<tree of generator 0>, ...],     # see below
       "heightmaps": {"shape": [n_filled, H, W], "dtype": "uint16", "scale": 65535} or null,
       "metrics": ["coverage", ...]}

  A genome tree is ``{"type": "leaf", "index": k}`` (array member ``genome_{i}_{k}``), ``{"type": "none"}``,
  ``{"type": "tuple"|"list", "children": [...]}``, ``{"type": "dict", "keys": [...], "children": [...]}`` or
  ``{"type": "namedtuple", "class": "module:QualName", "fields": [...], "children": [...]}``. A plain vector genome
  is a single leaf ``[cells, G]``.
* ``fitness`` [cells] float32 (``-inf`` = empty cell), ``descriptors`` [cells, 2] float32 (raw values),
  ``centroids`` [cells, 2] float32, ``source`` [cells] int32 (generator id; -1 = empty cell).
* ``genome_{i}_{k}`` [cells, ...]: leaf ``k`` of the genomes of generator ``i`` (zeros where another generator or
  nobody holds the cell).
* ``heightmaps`` [n_filled, H, W] uint16 (height * 65535, rounded) for the filled cells in increasing cell order
  (absent when the archive carries no heightmaps).
* ``metric_{name}`` [generations + 1] float32: the per-generation metrics.

``load`` checks the format name, the version, every member's presence, shape and dtype, and raises
``ValueError`` naming the file and the problem for a wrong, truncated or corrupt file.
"""

from __future__ import annotations

import functools
import importlib
import inspect
import json
import math
import os
import time
import zipfile
from pathlib import Path
from typing import Any, Callable, NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np

PRNGKey = jax.Array
FitnessFn = Callable[[jax.Array, PRNGKey], jax.Array]

FORMAT = "jaxterrain-archive"
VERSION = 1
CHECKPOINT_FORMAT = "jaxterrain-map-elites-checkpoint"
CHECKPOINT_VERSION = 1
CHECKPOINT_NAME = "checkpoint.npz"

METRIC_NAMES = ("coverage", "qd_score", "max_fitness", "mean_fitness", "rejected", "out_of_range", "nan", "inserted")

# Grid ranges per descriptor name, shared by every generator (window 30, stride 2, 256 x 256 heightmaps in [0, 1]).
# How they were chosen (2026-11-21; `python -m experiments features --calibrate` does the same): 32 random genomes
# plus 32 twice-mutated ones of each generator were rendered at 256 x 256 and described with window 30 / stride 2.
# Each range is [0.5th, 99.5th] percentile of the pooled values, rounded outwards to 2 significant digits, with 0 as
# the lower end of these non-negative descriptors. Pooled percentiles [0.5, 99.5]: without the GAN (cppn,
# diamond_square, perlin, worley) tri [0.00046, 0.166], roughness [0.0024, 0.750]; with the GAN (all five)
# tri [0.00015, 0.152], tpi (mean |TPI|) [0.00001, 0.110], roughness [0.0007, 0.630].
# So nearly every terrain falls inside the grid and the 50 bins are not spent on values no generator reaches.
# Re-measure after changing a feature definition or the generators; other windows need ``config.ranges``.
DEFAULT_RANGES: dict[str, tuple[float, float]] = {
    "tri": (0.0, 0.17),
    "tpi": (0.0, 0.12),
    "roughness": (0.0, 0.76),
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
      attempts, best: walker attempts per terrain and how many of the best are averaged (paper: 20 and 5).
      checkpoint_every: generations per jitted chunk (and between checkpoints when a checkpoint folder is given).
      robot_height: robot height in metres for Algorithm 1 (threshold robot_height / 3); None: the features
        module's default.
      traversable_window: Algorithm 1's window (approx. step length, paper: 26 pixels).
      out_of_range: "clip" (into the edge cells) or "reject" (never inserted); see the module docstring.
      store_heightmaps: render the elites at the end and keep their heightmaps (uint16) in the archive.
      rollout_slots: env slots of the difficulty fitness's rollout pool (``difficulty.batched_distances``), or
        None to run each generation's ``batch_size x attempts`` rollouts all at once. A speed knob only (same
        rollouts, statistically the same fitness), so a run may resume with another value.
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


# ----------------------------------------------------------------------------------------------------------------
# Config helpers
# ----------------------------------------------------------------------------------------------------------------


def resolve_config(config: EvolveConfig) -> EvolveConfig:
    """Check ``config`` on the host and fill in ``ranges`` from :data:`DEFAULT_RANGES`. Raises ``ValueError``."""
    def positive(name, value, minimum=1):
        if int(value) != value or value < minimum:
            raise ValueError(f"EvolveConfig.{name} must be an integer >= {minimum}; got {value!r}")

    positive("generations", config.generations, 0)
    for name in ("batch_size", "initial_population", "bins", "window", "stride", "attempts", "best",
                 "checkpoint_every", "traversable_window"):
        positive(name, getattr(config, name))
    if config.best > config.attempts:
        raise ValueError(f"EvolveConfig.best must be in [1, attempts={config.attempts}]; got {config.best}")
    names = tuple(config.descriptors)
    if len(names) != 2 or len(set(names)) != 2:
        raise ValueError(f"EvolveConfig.descriptors must be two different descriptor names; got {names!r}")
    if config.out_of_range not in ("clip", "reject"):
        raise ValueError(f"EvolveConfig.out_of_range must be 'clip' or 'reject'; got {config.out_of_range!r}")
    if config.rollout_slots is not None:
        positive("rollout_slots", config.rollout_slots)
    if config.robot_height is not None and not config.robot_height > 0:
        raise ValueError(f"EvolveConfig.robot_height must be > 0 metres or None; got {config.robot_height!r}")
    if config.ranges is None:
        missing = [n for n in names if n not in DEFAULT_RANGES]
        if missing:
            raise ValueError(
                f"EvolveConfig.ranges: no default range for descriptor(s) {missing}; known: "
                f"{sorted(DEFAULT_RANGES)}; pass ranges=((lo, hi), (lo, hi))"
            )
        ranges = tuple(DEFAULT_RANGES[n] for n in names)
    else:
        ranges = tuple(config.ranges)
    ranges = tuple((float(lo), float(hi)) for lo, hi in ranges)
    if len(ranges) != 2 or any(not (math.isfinite(lo) and math.isfinite(hi) and hi > lo) for lo, hi in ranges):
        raise ValueError(f"EvolveConfig.ranges must be two finite (lo, hi) pairs with hi > lo; got {config.ranges!r}")
    return config._replace(descriptors=names, ranges=ranges)


def config_to_dict(config: EvolveConfig) -> dict:
    """JSON-friendly dict of an :class:`EvolveConfig`."""
    d = config._asdict()
    d["descriptors"] = list(config.descriptors)
    d["ranges"] = None if config.ranges is None else [list(r) for r in config.ranges]
    return d


def config_from_dict(d: dict) -> EvolveConfig:
    """Inverse of :func:`config_to_dict`; unknown keys raise ``ValueError``."""
    unknown = set(d) - set(EvolveConfig._fields)
    if unknown:
        raise ValueError(f"unknown EvolveConfig field(s) {sorted(unknown)}; known: {list(EvolveConfig._fields)}")
    d = dict(d)
    if "descriptors" in d:
        d["descriptors"] = tuple(d["descriptors"])
    if d.get("ranges") is not None:
        d["ranges"] = tuple(tuple(float(v) for v in r) for r in d["ranges"])
    return EvolveConfig(**d)


def centroids_for(config: EvolveConfig) -> jax.Array:
    """[bins * bins, 2] float32 grid centroids over the config's ranges (QDax ``compute_euclidean_centroids``).

    Cell ``i * bins + j`` has descriptor 0 in bin ``j`` and descriptor 1 in bin ``i`` (QDax's meshgrid order).
    """
    from qdax.core.containers.mapelites_repertoire import compute_euclidean_centroids

    config = resolve_config(config)
    (lo0, hi0), (lo1, hi1) = config.ranges
    return compute_euclidean_centroids((config.bins, config.bins), minval=[lo0, lo1], maxval=[hi0, hi1])


# ----------------------------------------------------------------------------------------------------------------
# One MAP-Elites generation (pure functions; the caller jits / scans)
# ----------------------------------------------------------------------------------------------------------------


RENDER_CHUNK = 1024
"""Terrains rendered at once inside a generation (``lax.map`` over chunks of ``vmap``): bounds the generators'
temporaries (the GAN at batch 4 096 asks XLA for ~139 GiB) at larger GPU batches; below it, it is one ``vmap``."""


class _Fns(NamedTuple):
    sample: Callable
    mutate: Callable
    render_one: Callable  # genome -> [H, W] (vmapped here)
    descriptors: Callable  # heightmaps[B, H, W] -> [B, 2]
    traversable: Callable  # heightmaps[B, H, W] -> [B] bool
    fitness: FitnessFn  # (heightmaps[B, H, W], key) -> [B]


def _evaluate(fns: _Fns, config: EvolveConfig, genomes, key):
    """Render and score a batch. Returns (fitness for insertion [B], raw descriptors [B, 2], cell descriptors
    [B, 2], counts dict)."""
    heightmaps = jax.lax.map(fns.render_one, genomes, batch_size=RENDER_CHUNK)
    raw = jnp.asarray(fns.descriptors(heightmaps), jnp.float32)
    traversable = jnp.asarray(fns.traversable(heightmaps), bool)
    lo = jnp.asarray([r[0] for r in config.ranges], jnp.float32)
    hi = jnp.asarray([r[1] for r in config.ranges], jnp.float32)
    finite_desc = jnp.all(jnp.isfinite(raw), axis=-1)
    outside = jnp.any((raw < lo) | (raw > hi), axis=-1) | ~finite_desc
    eligible = traversable & finite_desc  # could enter the archive, so their fitness is needed
    if config.out_of_range == "reject":
        eligible = eligible & ~outside
    if _takes_needed(fns.fitness):
        fitness = fns.fitness(heightmaps, key, needed=eligible)
    else:
        fitness = fns.fitness(heightmaps, key)
    fitness = jnp.asarray(fitness, jnp.float32).reshape(-1)
    nan = jnp.isnan(fitness) & eligible  # the others' fitness was not needed
    keep = eligible & ~nan
    insert_fitness = jnp.where(keep, fitness, -jnp.inf)
    cell_desc = jnp.clip(jnp.where(jnp.isfinite(raw), raw, lo), lo, hi)
    counts = {
        "rejected": jnp.sum(~traversable).astype(jnp.float32),
        "out_of_range": jnp.sum(outside).astype(jnp.float32),
        "nan": jnp.sum(nan).astype(jnp.float32),
    }
    return insert_fitness, raw, cell_desc, counts


def _takes_needed(fitness_fn) -> bool:
    """Whether a fitness function accepts ``needed=`` ([B] bool: the terrains whose fitness can matter), the hint
    that lets :func:`difficulty_fitness` skip the rollouts of terrains that Algorithm 1 rejected."""
    try:
        return "needed" in inspect.signature(fitness_fn).parameters
    except (TypeError, ValueError):
        return False


def _insert(repertoire, genomes, raw, cell_desc, fitness):
    """QDax insertion of a scored batch; raw descriptors are kept in ``extra_scores['raw']``."""
    before = repertoire.fitnesses
    repertoire = repertoire.add(genomes, cell_desc, fitness, {"raw": raw})
    inserted = jnp.sum(repertoire.fitnesses != before).astype(jnp.float32)
    return repertoire, inserted


def _metrics(repertoire, counts, inserted):
    fit = repertoire.fitnesses.reshape(-1)
    filled = fit > -jnp.inf
    n = jnp.sum(filled)
    safe = jnp.where(filled, fit, 0.0)
    return {
        "coverage": 100.0 * jnp.mean(filled.astype(jnp.float32)),
        "qd_score": jnp.sum(safe),
        "max_fitness": jnp.where(n > 0, jnp.max(fit), jnp.nan),
        "mean_fitness": jnp.where(n > 0, jnp.sum(safe) / jnp.maximum(n, 1), jnp.nan),
        "inserted": inserted,
        **counts,
    }


def _generation_keys(key: PRNGKey, generation):
    gen_key = jax.random.fold_in(key, generation)
    return jax.random.split(gen_key, 3)  # selection, mutation, evaluation


def init_repertoire(fns: _Fns, config: EvolveConfig, centroids: jax.Array, key: PRNGKey):
    """Generation 0: ``initial_population`` random genomes into an empty repertoire. Returns (repertoire, metrics)."""
    from qdax.core.containers.mapelites_repertoire import MapElitesRepertoire

    sample_key, _, eval_key = _generation_keys(key, 0)
    genomes = fns.sample(sample_key, config.initial_population)
    fitness, raw, cell_desc, counts = _evaluate(fns, config, genomes, eval_key)
    empty = MapElitesRepertoire.init_default(
        genotype=jax.tree.map(lambda x: x[0], genomes),
        centroids=centroids,
        one_extra_score={"raw": raw[0]},
        keys_extra_scores=("raw",),
    )
    repertoire, inserted = _insert(empty, genomes, raw, cell_desc, fitness)
    return repertoire, _metrics(repertoire, counts, inserted)


def generation_step(fns: _Fns, config: EvolveConfig, key: PRNGKey, repertoire, generation):
    """One generation ``generation >= 1``: uniform parents from filled cells, mutate, evaluate, insert.

    When the archive is empty (every initial terrain rejected) the offspring are fresh random genomes instead.
    Returns (repertoire, metrics dict of scalars).
    """
    select_key, mutate_key, eval_key = _generation_keys(key, generation)
    fit = repertoire.fitnesses.reshape(-1)
    filled = fit > -jnp.inf
    any_filled = jnp.any(filled)
    p = jnp.where(any_filled, filled.astype(jnp.float32), 1.0)
    p = p / jnp.sum(p)
    idx = jax.random.choice(select_key, fit.shape[0], (config.batch_size,), replace=True, p=p)
    parents = jax.tree.map(lambda x: x[idx], repertoire.genotypes)
    offspring = jax.lax.cond(
        any_filled,
        lambda: fns.mutate(mutate_key, parents),
        lambda: jax.tree.map(lambda f, p: f.astype(p.dtype), fns.sample(select_key, config.batch_size), parents),
    )
    fitness, raw, cell_desc, counts = _evaluate(fns, config, offspring, eval_key)
    repertoire, inserted = _insert(repertoire, offspring, raw, cell_desc, fitness)
    return repertoire, _metrics(repertoire, counts, inserted)


# ----------------------------------------------------------------------------------------------------------------
# evolve
# ----------------------------------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=32)
def _descriptor_fn(names: tuple[str, ...], window: int, stride: int):
    from jaxterrain import features

    def descriptor_fn(heightmaps):
        return features.descriptors(heightmaps, names=names, window=window, stride=stride)

    return descriptor_fn


@functools.lru_cache(maxsize=32)
def _traversable_fn(robot_height: float | None, window: int):
    from jaxterrain import features

    kwargs = {"window": window}
    if robot_height is not None:
        kwargs["robot_height"] = robot_height

    def traversable_fn(heightmaps):
        return features.is_traversable(heightmaps, **kwargs)

    return traversable_fn


def _default_fns(generator, descriptors, config, fitness_fn, traversable_fn):
    # The default functions are cached per settings so that repeated runs in one process reuse compiled chunks.
    if callable(descriptors):
        descriptor_fn = descriptors
    else:
        descriptor_fn = _descriptor_fn(tuple(config.descriptors), config.window, config.stride)
    if traversable_fn is None:
        traversable_fn = _traversable_fn(config.robot_height, config.traversable_window)
    if fitness_fn is None:
        fitness_fn = difficulty_fitness(generator.size, config.attempts, config.best, slots=config.rollout_slots)
    return _Fns(generator.sample, generator.mutate, generator.render_one, descriptor_fn, traversable_fn, fitness_fn)


@functools.lru_cache(maxsize=8)
def difficulty_fitness(size: int, attempts: int = 20, best: int = 5, scale=None,
                       slots: int | None = None, smooth_first: bool = True) -> FitnessFn:
    """The paper's fitness as a pure function for use inside jit / scan: ``(heightmaps[B, size, size], key) -> [B]``.

    Same computation as ``difficulty.evaluate`` (shipped base policy, ``attempts`` rollouts per terrain, mean of the
    ``best`` distances) through its pure ``batched_distances`` / ``best_of``; the env and policy are built here, on
    the host, once (cached per arguments; ``scale`` must then be hashable, e.g. a ``TerrainScale``). ``slots``: env
    slots fed from a queue of the ``B x attempts`` rollouts (see ``difficulty.batched_distances``; None = all at once);
    ``smooth_first``: the queue starts the smoothest terrains' rollouts, the longest, first (speed only).
    """
    from jaxterrain import difficulty
    from jaxterrain.terrain import TerrainScale

    scale = TerrainScale() if scale is None else scale
    policy = difficulty.default_policy()
    env = difficulty.make_env(difficulty.default_env_config((int(size), int(size)), scale, policy))

    def fitness(heightmaps, key, needed=None):
        terrains = jnp.asarray(heightmaps, jnp.float32) * jnp.float32(scale.height)
        priority = difficulty.smoothness_priority(terrains) if slots is not None and smooth_first else None
        distances, _ = difficulty.batched_distances(env, policy, terrains, key, attempts, slots=slots, needed=needed,
                                                    priority=priority)
        return difficulty.best_of(distances, best)

    return fitness


def _key_data(key) -> np.ndarray:
    if jnp.issubdtype(key.dtype, jax.dtypes.prng_key):
        return np.asarray(jax.random.key_data(key))
    return np.asarray(key)


def evolve(
    generator,
    descriptors,
    config: EvolveConfig,
    key: PRNGKey,
    fitness_fn: FitnessFn | None = None,
    checkpoint_dir: str | os.PathLike | None = None,
    progress: bool | Callable[[dict], None] = True,
    traversable_fn: Callable[[jax.Array], jax.Array] | None = None,
    generator_options: dict | None = None,
) -> Archive:
    """Run MAP-Elites for one generator and one descriptor pair; returns the final :class:`Archive`.

    Args:
      generator: a ``Generator`` (see generators/base.py) or a registered generator name.
      descriptors: None (use ``config.descriptors``), a pair of descriptor names (replaces ``config.descriptors``),
        or a callable ``heightmaps[B, H, W] -> [B, 2]`` (e.g. a learned descriptor; ``config.descriptors`` then only
        names it and ``config.ranges`` must be given unless the names have defaults).
      config: :class:`EvolveConfig`.
      key: PRNG key; generation ``g`` uses ``fold_in(key, g)``.
      fitness_fn: ``(heightmaps[B, H, W] float32, key) -> fitness[B]``, traceable (it runs inside the scan; higher
        = easier; NaN never enters); default :func:`difficulty_fitness` (``difficulty.evaluate``'s computation with
        ``config.attempts`` / ``config.best``). A fitness function with a ``needed`` keyword gets ``needed=[B] bool``,
        the offspring that can enter the archive (Algorithm 1 passed, descriptors usable), and may skip the rest:
        :func:`difficulty_fitness` does not walk them when ``config.rollout_slots`` is set.
      checkpoint_dir: folder for ``checkpoint.npz``, written atomically after every chunk of
        ``config.checkpoint_every`` generations. When it already holds a checkpoint of the same run (same generator,
        key and config except ``generations``) the run continues from it.
      progress: True prints one line per chunk; a callable receives a dict per chunk instead; False is silent.
      traversable_fn: ``heightmaps[B, H, W] -> [B] bool`` replacing Algorithm 1 (default ``features.is_traversable``
        with ``config.robot_height`` and ``config.traversable_window``).
      generator_options: options for ``generators.get`` when ``generator`` is a name (e.g. ``{"size": 64}``).
    """
    if isinstance(generator, str):
        from jaxterrain import generators as _generators

        generator = _generators.get(generator, **(generator_options or {}))
    if descriptors is not None and not callable(descriptors):
        config = config._replace(descriptors=tuple(descriptors))
    config = resolve_config(config)
    fns = _default_fns(generator, descriptors, config, fitness_fn, traversable_fn)
    centroids = centroids_for(config)
    report = _reporter(progress, generator.name)

    ckpt_path = None if checkpoint_dir is None else Path(checkpoint_dir) / CHECKPOINT_NAME
    state = None
    if ckpt_path is not None and ckpt_path.exists():
        state = _load_checkpoint(ckpt_path, generator.name, config, key)
        report({"event": "resume", "generation": state[1]})
    t0 = time.perf_counter()
    if state is None:
        repertoire, metrics0 = _compiled_init(fns, _step_config(config))(key, centroids)
        history = {k: [float(v)] for k, v in jax.device_get(metrics0).items()}
        done = 0
        if ckpt_path is not None:
            _save_checkpoint(ckpt_path, generator.name, config, key, repertoire, done, history)
        report(_line(0, config.generations, history, time.perf_counter() - t0, config.initial_population))
    else:
        repertoire, done, history = state

    chunk = _chunk_runner(fns, _step_config(config))
    while done < config.generations:
        stop = min(done + config.checkpoint_every, config.generations)
        t1 = time.perf_counter()
        repertoire, metrics = chunk(key, repertoire, jnp.arange(done, stop))
        metrics = jax.device_get(metrics)
        for name, values in metrics.items():
            history.setdefault(name, []).extend(float(v) for v in np.asarray(values))
        done = stop
        if ckpt_path is not None:
            _save_checkpoint(ckpt_path, generator.name, config, key, repertoire, done, history)
        report(_line(done, config.generations, history, time.perf_counter() - t1,
                     len(np.asarray(metrics["coverage"])) * config.batch_size))
    return _to_archive(generator, repertoire, config, history)


def _step_config(config: EvolveConfig) -> EvolveConfig:
    """The config with the fields that do not change one generation's computation normalised (cache key)."""
    return config._replace(generations=0, checkpoint_every=1, store_heightmaps=False)


@functools.lru_cache(maxsize=8)
def _compiled_init(fns: _Fns, config: EvolveConfig):
    return jax.jit(lambda key, centroids: init_repertoire(fns, config, centroids, key))


@functools.lru_cache(maxsize=8)
def _chunk_runner(fns: _Fns, config: EvolveConfig):
    """jit of a scan over an explicit array of generation numbers (compiles once per chunk length).

    Cached per (functions, config): repeated runs with the same functions (tests, benchmarks) compile once.
    """

    def run(key, repertoire, generations):
        def body(rep, generation):
            return generation_step(fns, config, key, rep, generation)

        return jax.lax.scan(body, repertoire, generations)

    return jax.jit(run)


def _line(done, total, history, seconds, evaluations):
    return {
        "event": "chunk",
        "generation": done,
        "generations": total,
        "seconds": seconds,
        "evaluations_per_s": evaluations / max(seconds, 1e-9),
        **{k: v[-1] for k, v in history.items()},
        "rejected_total": float(np.sum(history.get("rejected", [0.0]))),
    }


def progress_printer(name: str):
    """The default progress callback of :func:`evolve`: one line per chunk, prefixed by ``[name]``."""

    def report(info):
        if info["event"] == "resume":
            print(f"[{name}] resuming from checkpoint at generation {info['generation']}", flush=True)
            return
        print(
            f"[{name}] gen {info['generation']}/{info['generations']}  coverage {info['coverage']:.2f}%  "
            f"qd {info['qd_score']:.2f}  max {info['max_fitness']:.3f}  mean {info['mean_fitness']:.3f}  "
            f"rejected {int(info['rejected_total'])}  {info['evaluations_per_s']:.1f} evals/s",
            flush=True,
        )

    return report


def _reporter(progress, name):
    if callable(progress):
        return progress
    return progress_printer(name) if progress else (lambda info: None)


def _to_archive(generator, repertoire, config, history) -> Archive:
    fitness = np.asarray(repertoire.fitnesses, np.float32).reshape(-1)
    filled = fitness > -np.inf
    genomes = jax.tree.map(np.asarray, repertoire.genotypes)
    heightmaps = None
    if config.store_heightmaps:
        heightmaps = render_elites(generator, genomes, filled)
    return Archive(
        genomes=(genomes,),
        generator_names=(generator.name,),
        source=np.where(filled, 0, -1).astype(np.int32),
        fitness=fitness,
        descriptors=np.asarray(repertoire.extra_scores["raw"], np.float32),
        centroids=np.asarray(repertoire.centroids, np.float32),
        heightmaps=heightmaps,
        config=config,
        metrics={k: np.asarray(v, np.float32) for k, v in history.items()},
    )


def render_elites(generator, genomes, filled: np.ndarray, batch: int = 64) -> np.ndarray:
    """Heightmaps ``[cells, H, W]`` uint16 (height * 65535) of the filled cells (zeros elsewhere)."""
    cells = filled.shape[0]
    size = generator.size
    out = np.zeros((cells, size, size), np.uint16)
    idx = np.flatnonzero(filled)
    render = jax.jit(jax.vmap(generator.render_one))
    for s in range(0, len(idx), batch):
        part = idx[s : s + batch]
        pad = np.concatenate([part, np.repeat(part[-1:], batch - len(part))])  # one compiled shape
        maps = np.asarray(render(jax.tree.map(lambda x: jnp.asarray(x[pad]), genomes)))[: len(part)]
        out[part] = np.round(np.clip(maps, 0.0, 1.0) * 65535.0).astype(np.uint16)
    return out


def heightmaps(archive: Archive) -> np.ndarray:
    """The elites' heightmaps as float32 [cells, H, W] in [0, 1] (zeros for empty cells)."""
    if archive.heightmaps is None:
        raise ValueError("this archive carries no heightmaps (EvolveConfig.store_heightmaps was False); render "
                         "generator i's elites with render_elites(generators.get(archive.generator_names[i]), "
                         "archive.genomes[i], archive.source == i)")
    return archive.heightmaps.astype(np.float32) / 65535.0


def coverage(archive: Archive) -> float:
    """Percent of the cells that hold an elite (0-100)."""
    return 100.0 * float(np.mean(archive.source >= 0))


def qd_score(archive: Archive) -> float:
    """Sum of the elites' fitness."""
    return float(np.sum(archive.fitness[archive.source >= 0]))


def elite(archive: Archive, cell: int) -> tuple[str, Any]:
    """``(generator_name, genome)`` of the elite in ``cell``; ``ValueError`` for an empty cell."""
    cells = archive.fitness.shape[0]
    if not 0 <= cell < cells:
        raise ValueError(f"cell must be in [0, {cells - 1}]; got {cell}")
    s = int(archive.source[cell])
    if s < 0:
        raise ValueError(f"cell {cell} is empty")
    return archive.generator_names[s], jax.tree.map(lambda x: x[cell], archive.genomes[s])


def grid(archive: Archive, values: np.ndarray | None = None) -> np.ndarray:
    """``[bins, bins]`` image of ``values`` (default: fitness, NaN for empty cells); row = descriptor 1 bin,
    column = descriptor 0 bin (plot with ``origin='lower'``)."""
    bins = archive.config.bins
    v = archive.fitness if values is None else np.asarray(values)
    v = np.where(archive.source >= 0, v, np.nan).astype(np.float32)
    return v.reshape(bins, bins)


# ----------------------------------------------------------------------------------------------------------------
# combine
# ----------------------------------------------------------------------------------------------------------------


def _grid_signature(config: EvolveConfig):
    return (tuple(config.descriptors), tuple(map(tuple, config.ranges)), config.bins, config.window, config.stride)


def combine(archives: Sequence[Archive]) -> Archive:
    """Merge archives cell by cell, keeping the highest-fitness elite and remembering its generator.

    All archives must share descriptor names, ranges, bins, window/stride and centroids (``ValueError`` otherwise).
    Ties go to the earlier archive. Heightmaps are kept when every input has them. Metrics are dropped.
    """
    archives = list(archives)
    if not archives:
        raise ValueError("combine: archives must be a non-empty sequence")
    ref = archives[0]
    for i, a in enumerate(archives[1:], 1):
        if _grid_signature(a.config) != _grid_signature(ref.config):
            raise ValueError(
                "combine: archives must share descriptors, ranges, bins, window and stride; archive 0 has "
                f"{_grid_signature(ref.config)}, archive {i} has {_grid_signature(a.config)}"
            )
        if a.centroids.shape != ref.centroids.shape or not np.allclose(a.centroids, ref.centroids):
            raise ValueError(f"combine: archive {i} has different centroids from archive 0")
    names: list[str] = []
    genomes: list = []
    for a in archives:
        for j, n in enumerate(a.generator_names):
            if n not in names:
                names.append(n)
                genomes.append(jax.tree.map(np.zeros_like, a.genomes[j]))
    cells = ref.fitness.shape[0]
    best = np.full(cells, -np.inf, np.float32)
    source = np.full(cells, -1, np.int32)
    descriptors = np.zeros_like(ref.descriptors)
    keep_maps = all(a.heightmaps is not None for a in archives)
    maps = np.zeros_like(ref.heightmaps) if keep_maps else None
    for a in archives:
        fit = np.where(a.source >= 0, a.fitness, -np.inf)
        win = fit > best
        if not win.any():
            continue
        best = np.where(win, fit, best)
        new_source = np.array([names.index(n) for n in a.generator_names], np.int32)[np.maximum(a.source, 0)]
        source = np.where(win, new_source, source)
        descriptors[win] = a.descriptors[win]
        if keep_maps:
            maps[win] = a.heightmaps[win]
        for j, n in enumerate(a.generator_names):
            rows = win & (a.source == j)
            k = names.index(n)
            genomes[k] = jax.tree.map(lambda dst, src: np.where(_bcast(rows, dst), src, dst), genomes[k], a.genomes[j])
    # a cell taken over later by another generator keeps stale genome rows in the loser's slot: zero them
    for k in range(len(names)):
        genomes[k] = jax.tree.map(lambda x: np.where(_bcast(source == k, x), x, np.zeros_like(x)), genomes[k])
    return Archive(tuple(genomes), tuple(names), source, best, descriptors, ref.centroids.copy(), maps,
                   ref.config, {})


def _bcast(mask, x):
    return mask.reshape(mask.shape + (1,) * (np.ndim(x) - 1))


# ----------------------------------------------------------------------------------------------------------------
# Pytree <-> JSON + flat arrays
# ----------------------------------------------------------------------------------------------------------------


def _flatten(tree, leaves: list):
    if tree is None:
        return {"type": "none"}
    if isinstance(tree, tuple) and hasattr(tree, "_fields"):
        cls = type(tree)
        return {
            "type": "namedtuple",
            "class": f"{cls.__module__}:{cls.__qualname__}",
            "fields": list(tree._fields),
            "children": [_flatten(c, leaves) for c in tree],
        }
    if isinstance(tree, (tuple, list)):
        return {"type": type(tree).__name__, "children": [_flatten(c, leaves) for c in tree]}
    if isinstance(tree, dict):
        keys = list(tree)
        if not all(isinstance(k, str) for k in keys):
            raise ValueError(f"archive genomes: dict keys must be strings to be saved; got {keys!r}")
        return {"type": "dict", "keys": keys, "children": [_flatten(tree[k], leaves) for k in keys]}
    if isinstance(tree, (np.ndarray, jax.Array, np.generic, float, int, bool)):
        leaves.append(np.asarray(tree))
        return {"type": "leaf", "index": len(leaves) - 1}
    raise ValueError(
        f"archive genomes: cannot save a pytree node of type {type(tree).__name__}; use arrays in "
        "tuples, lists, dicts or NamedTuples"
    )


def _unflatten(node, leaves: list):
    kind = node["type"]
    if kind == "none":
        return None
    if kind == "leaf":
        return leaves[node["index"]]
    children = [_unflatten(c, leaves) for c in node.get("children", [])]
    if kind == "tuple":
        return tuple(children)
    if kind == "list":
        return children
    if kind == "dict":
        return dict(zip(node["keys"], children))
    if kind == "namedtuple":
        module, _, qualname = node["class"].partition(":")
        try:
            obj = importlib.import_module(module)
            for part in qualname.split("."):
                obj = getattr(obj, part)
        except (ImportError, AttributeError) as err:
            raise ValueError(f"genome class {node['class']} cannot be imported: {err}") from err
        return obj(*children)
    raise ValueError(f"unknown genome tree node type {kind!r}")


def _count_leaves(node) -> int:
    if node["type"] == "leaf":
        return 1
    return sum(_count_leaves(c) for c in node.get("children", []))


# ----------------------------------------------------------------------------------------------------------------
# save / load
# ----------------------------------------------------------------------------------------------------------------


def save(path: str | os.PathLike, archive: Archive) -> Path:
    """Write ``archive`` to ``path`` (.npz, format in the module docstring), atomically."""
    from jaxterrain.io import atomic_save_npz

    cells = archive.fitness.shape[0]
    arrays: dict[str, np.ndarray] = {}
    trees = []
    for i, g in enumerate(archive.genomes):
        leaves: list = []
        trees.append(_flatten(g, leaves))
        for k, leaf in enumerate(leaves):
            if leaf.ndim < 1 or leaf.shape[0] != cells:
                raise ValueError(f"save: genome leaf {k} of generator {i} has shape {leaf.shape}; needs [{cells}, ...]")
            arrays[f"genome_{i}_{k}"] = leaf
    filled = archive.source >= 0
    hm_header = None
    if archive.heightmaps is not None:
        hm = np.asarray(archive.heightmaps)[filled]
        hm_header = {"shape": list(hm.shape), "dtype": "uint16", "scale": 65535}
        arrays["heightmaps"] = hm.astype(np.uint16)
    header = {
        "format": FORMAT,
        "version": VERSION,
        "generator_names": list(archive.generator_names),
        "descriptor_names": list(archive.config.descriptors),
        "ranges": [list(r) for r in archive.config.ranges],
        "bins": archive.config.bins,
        "cells": cells,
        "config": config_to_dict(archive.config),
        "genomes": trees,
        "heightmaps": hm_header,
        "metrics": sorted(archive.metrics),
    }
    arrays["header"] = np.frombuffer(json.dumps(header).encode("utf-8"), np.uint8)
    arrays["fitness"] = np.asarray(archive.fitness, np.float32)
    arrays["descriptors"] = np.asarray(archive.descriptors, np.float32)
    arrays["centroids"] = np.asarray(archive.centroids, np.float32)
    arrays["source"] = np.asarray(archive.source, np.int32)
    for name, values in archive.metrics.items():
        arrays[f"metric_{name}"] = np.asarray(values, np.float32)
    return atomic_save_npz(path, **arrays)


def _open_npz(path: Path, what: str):
    if not path.exists():
        raise FileNotFoundError(f"{what} file {str(path)!r} does not exist")
    try:
        data = np.load(path, allow_pickle=False)
        members = {name: data[name] for name in data.files}  # reads (and CRC-checks) every member
        header = json.loads(bytes(members.pop("header")).decode("utf-8"))
    except (zipfile.BadZipFile, EOFError, OSError, KeyError, ValueError, UnicodeDecodeError) as err:
        raise ValueError(f"{str(path)!r} is not a readable {what} file (truncated or corrupt?): {err}") from err
    if not isinstance(header, dict):
        raise ValueError(f"{str(path)!r}: the header is not a JSON object")
    return header, members


def _need(path, members, name, shape, dtype):
    if name not in members:
        raise ValueError(f"{str(path)!r}: member {name!r} is missing")
    a = members[name]
    if tuple(a.shape) != tuple(shape) or (dtype is not None and a.dtype != np.dtype(dtype)):
        raise ValueError(
            f"{str(path)!r}: member {name!r} has shape {a.shape} dtype {a.dtype}; expected {tuple(shape)} {dtype}"
        )
    return a


def load(path: str | os.PathLike) -> Archive:
    """Read an archive written by :func:`save`; ``ValueError`` for a wrong, truncated or corrupt file."""
    path = Path(path)
    header, m = _open_npz(path, "archive")
    if header.get("format") != FORMAT:
        raise ValueError(f"{str(path)!r} is not a jaxterrain archive (format {header.get('format')!r})")
    if header.get("version") != VERSION:
        raise ValueError(
            f"{str(path)!r}: archive format version {header.get('version')!r}; this reader knows {VERSION}"
        )
    try:
        config = resolve_config(config_from_dict(header["config"]))
        cells = int(header["cells"])
        names = tuple(header["generator_names"])
        trees = header["genomes"]
        metric_names = header["metrics"]
        hm_header = header["heightmaps"]
    except (KeyError, TypeError) as err:
        raise ValueError(f"{str(path)!r}: incomplete header ({err})") from err
    if cells != config.bins**2 or len(trees) != len(names):
        raise ValueError(f"{str(path)!r}: header is inconsistent (cells {cells}, bins {config.bins})")
    fitness = _need(path, m, "fitness", (cells,), np.float32)
    descriptors = _need(path, m, "descriptors", (cells, 2), np.float32)
    centroids = _need(path, m, "centroids", (cells, 2), np.float32)
    source = _need(path, m, "source", (cells,), np.int32)
    if np.any(source >= len(names)) or np.any(source < -1):
        raise ValueError(f"{str(path)!r}: source ids outside [-1, {len(names) - 1}]")
    genomes = []
    for i, tree in enumerate(trees):
        leaves = []
        for k in range(_count_leaves(tree)):
            name = f"genome_{i}_{k}"
            if name not in m:
                raise ValueError(f"{str(path)!r}: member {name!r} is missing")
            if m[name].ndim < 1 or m[name].shape[0] != cells:
                raise ValueError(f"{str(path)!r}: member {name!r} has shape {m[name].shape}; expected [{cells}, ...]")
            leaves.append(m[name])
        genomes.append(_unflatten(tree, leaves))
    maps = None
    if hm_header is not None:
        n_filled = int(np.sum(source >= 0))
        shape = tuple(hm_header["shape"])
        hm = _need(path, m, "heightmaps", (n_filled,) + shape[1:], np.uint16)
        maps = np.zeros((cells,) + shape[1:], np.uint16)
        maps[source >= 0] = hm
    metrics = {name: _need(path, m, f"metric_{name}", m.get(f"metric_{name}", np.zeros(0)).shape, np.float32)
               for name in metric_names}
    return Archive(tuple(genomes), names, source, fitness, descriptors, centroids, maps, config, metrics)


# ----------------------------------------------------------------------------------------------------------------
# Checkpoints (one run's repertoire + progress; same npz conventions)
# ----------------------------------------------------------------------------------------------------------------


def _resume_signature(config: EvolveConfig) -> dict:
    d = config_to_dict(config)
    for speed_only in ("generations", "checkpoint_every", "rollout_slots"):
        d.pop(speed_only)
    return d


def _save_checkpoint(path: Path, name: str, config, key, repertoire, generation: int, history: dict) -> None:
    from jaxterrain.io import atomic_save_npz

    leaves: list = []
    tree = _flatten(jax.tree.map(np.asarray, repertoire.genotypes), leaves)
    header = {
        "format": CHECKPOINT_FORMAT,
        "version": CHECKPOINT_VERSION,
        "generator": name,
        "generation": int(generation),
        "config": config_to_dict(config),
        "genomes": tree,
        "metrics": sorted(history),
    }
    arrays = {f"genome_{k}": leaf for k, leaf in enumerate(leaves)}
    arrays.update(
        header=np.frombuffer(json.dumps(header).encode("utf-8"), np.uint8),
        key=_key_data(key),
        fitnesses=np.asarray(repertoire.fitnesses),
        descriptors=np.asarray(repertoire.descriptors),
        centroids=np.asarray(repertoire.centroids),
        raw=np.asarray(repertoire.extra_scores["raw"]),
        **{f"metric_{k}": np.asarray(v, np.float64) for k, v in history.items()},
    )
    atomic_save_npz(path, **arrays)


def _load_checkpoint(path: Path, name: str, config: EvolveConfig, key):
    from qdax.core.containers.mapelites_repertoire import MapElitesRepertoire

    header, m = _open_npz(path, "checkpoint")
    if header.get("format") != CHECKPOINT_FORMAT or header.get("version") != CHECKPOINT_VERSION:
        raise ValueError(f"{str(path)!r} is not a jaxterrain MAP-Elites checkpoint of version {CHECKPOINT_VERSION}")
    if header["generator"] != name:
        raise ValueError(f"checkpoint {str(path)!r} is of generator {header['generator']!r}, not {name!r}")
    saved = resolve_config(config_from_dict(header["config"]))
    if _resume_signature(saved) != _resume_signature(config):
        raise ValueError(
            f"checkpoint {str(path)!r} was made with another config: {_resume_signature(saved)} != "
            f"{_resume_signature(config)}; use another checkpoint folder"
        )
    if not np.array_equal(m["key"], _key_data(key)):
        raise ValueError(f"checkpoint {str(path)!r} was made with another PRNG key; use the same key to resume")
    generation = int(header["generation"])
    if generation > config.generations:
        raise ValueError(
            f"checkpoint {str(path)!r} is at generation {generation}, beyond config.generations={config.generations}"
        )
    leaves = [m[f"genome_{k}"] for k in range(_count_leaves(header["genomes"]))]
    genotypes = jax.tree.map(jnp.asarray, _unflatten(header["genomes"], leaves))
    repertoire = MapElitesRepertoire(
        genotypes=genotypes,
        fitnesses=jnp.asarray(m["fitnesses"]),
        descriptors=jnp.asarray(m["descriptors"]),
        centroids=jnp.asarray(m["centroids"]),
        extra_scores={"raw": jnp.asarray(m["raw"])},
        keys_extra_scores=("raw",),
    )
    history = {k: [float(v) for v in m[f"metric_{k}"]] for k in header["metrics"]}
    return repertoire, generation, history
