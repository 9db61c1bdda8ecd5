"""MAP-Elites terrain archives (paper section 3.3): the host :class:`Archive`, its file format, and the drivers.

    >>> from jaxterrain import archive
    >>> config = archive.EvolveConfig(generations=5000, batch_size=20, descriptors=("roughness", "tpi"))
    >>> arch = archive.evolve("perlin", None, config, key, checkpoint_dir="runs/x/ckpt")
    >>> archive.coverage(arch)                      # percent of the 50 x 50 cells filled
    >>> archive.save("perlin.npz", arch); arch = archive.load("perlin.npz")
    >>> both = archive.combine([arch_perlin, arch_cppn])   # cell by cell, highest fitness wins
    >>> bank = archive.to_device(arch, scale)       # jaxterrain.bank.TerrainBank, the elites on device
    >>> ok = archive.check_cells(arch)              # [cells] bool: each elite's genome re-derives its own cell

The pipeline: :mod:`jaxterrain.scoring` (render, descriptors, Algorithm 1, fitness; QDax's scoring contract),
:mod:`jaxterrain.map_elites` (the pure state, ``init`` / ``step``, the one-winner-per-cell insertion, several
treatments at once), :mod:`jaxterrain.evolution` (the host drivers ``evolve`` / ``evolve_many``, re-exported here),
and this module (the host archive).

The loop (see :mod:`jaxterrain.map_elites`): generation 0 evaluates ``initial_population`` random genomes; every
later generation mutates ``batch_size`` parents drawn uniformly from the filled cells. Replacement is ordinary
MAP-Elites (the paper keeps the LOWEST-difficulty terrain, i.e. the HIGHEST fitness): one offspring per cell (the
fittest, the lowest batch index among ties) enters when strictly better than the elite. An offspring never enters
when it fails Algorithm 1 (``rejected`` metric), its fitness is NaN (``nan``), or a descriptor is out of range with
``out_of_range="reject"`` (``out_of_range`` counts them either way).

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

import importlib
import json
import math
import os
import zipfile
from pathlib import Path
from typing import Any, Callable, NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain.map_elites import METRIC_NAMES
from jaxterrain.terrain import TerrainScale, validate_scale

PRNGKey = jax.Array
FitnessFn = Callable[[jax.Array, PRNGKey, jax.Array], jax.Array]
"""``(heightmaps [B, H, W], key, needed [B] bool) -> [B]``; see :mod:`jaxterrain.scoring`."""

FORMAT = "jaxterrain-archive"
VERSION = 1

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
      checkpoint_every: RUN SETTING: generations per jitted chunk (and between checkpoints when a checkpoint folder
        is given); does not change the archive.
      robot_height: robot height in metres for Algorithm 1 (threshold robot_height / 3); None: the features
        module's default.
      traversable_window: Algorithm 1's window (approx. step length, paper: 26 pixels).
      out_of_range: "clip" (into the edge cells) or "reject" (never inserted); see the module docstring.
      store_heightmaps: RUN SETTING: render the elites at the end and keep their heightmaps (uint16) in the archive.
      rollout_slots: RUN SETTING: env slots of the difficulty fitness's rollout pool
        (``difficulty.batched_distances``), or None to run each generation's ``batch_size x attempts`` rollouts all
        at once. A speed knob only (same rollouts, statistically the same fitness), so a run may resume with
        another value.
      scale: the ONE :class:`~jaxterrain.terrain.TerrainScale` (metres per pixel and per heightmap unit) of both
        Algorithm 1 and the walker fitness (default ``TerrainScale()``: 0.04 m, 1.0 m).

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
    scale = config.scale
    if isinstance(scale, dict):
        scale = TerrainScale(**scale)
    elif not isinstance(scale, TerrainScale) and isinstance(scale, (tuple, list)):
        scale = TerrainScale(*scale)
    try:
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
        ranges = tuple(config.ranges)
    ranges = tuple((float(lo), float(hi)) for lo, hi in ranges)
    if len(ranges) != 2 or any(not (math.isfinite(lo) and math.isfinite(hi) and hi > lo) for lo, hi in ranges):
        raise ValueError(f"EvolveConfig.ranges must be two finite (lo, hi) pairs with hi > lo; got {config.ranges!r}")
    return config._replace(descriptors=names, ranges=ranges, scale=scale)


def config_to_dict(config: EvolveConfig) -> dict:
    """JSON-friendly dict of an :class:`EvolveConfig`."""
    d = config._asdict()
    d["descriptors"] = list(config.descriptors)
    d["ranges"] = None if config.ranges is None else [list(r) for r in config.ranges]
    d["scale"] = {"cell_size": float(config.scale.cell_size), "height": float(config.scale.height)}
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
    if isinstance(d.get("scale"), dict):  # absent in files written before the field existed: the default scale
        d["scale"] = TerrainScale(**d["scale"])
    return EvolveConfig(**d)


def centroids_for(config: EvolveConfig) -> jax.Array:
    """[bins * bins, 2] float32 grid centroids over the config's ranges (QDax ``compute_euclidean_centroids``).

    Cell ``i * bins + j`` has descriptor 0 in bin ``j`` and descriptor 1 in bin ``i`` (QDax's meshgrid order).
    """
    from qdax.core.containers.mapelites_repertoire import compute_euclidean_centroids

    config = resolve_config(config)
    (lo0, hi0), (lo1, hi1) = config.ranges
    return compute_euclidean_centroids((config.bins, config.bins), minval=[lo0, lo1], maxval=[hi0, hi1])


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


def rederive_cells(archive: Archive, generator_options: dict | None = None, batch: int = 64, gens: dict | None = None,
                   descriptor_fn=None):
    """Re-render every elite from its STORED genome and re-derive its cell, as insertion would.

    Each filled cell's genome is rendered by its own generator (``gens[name]`` if given, else
    ``generators.get(name, **generator_options)``), described with the archive's config (``descriptor_fn``
    ``[B, H, W] -> [B, 2]`` if given, else ``features.descriptors`` with ``config.descriptors``, ``window``,
    ``stride``), clipped into the ranges as for insertion, and assigned to the nearest centroid (QDax's
    ``get_cells_indices``).

    Returns:
      ``(cells [cells] int32, raw [cells, 2] float32)``: the re-derived cell of each elite (-1 for an empty cell)
      and its recomputed raw descriptors (NaN for an empty cell).
    """
    from qdax.core.containers.mapelites_repertoire import get_cells_indices

    from jaxterrain import features, generators

    if int(batch) != batch or batch < 1:
        raise ValueError(f"batch must be an integer >= 1; got {batch!r}")
    config = archive.config
    if descriptor_fn is None:
        names, window, stride = tuple(config.descriptors), config.window, config.stride

        def descriptor_fn(maps):
            return features.descriptors(maps, names=names, window=window, stride=stride)

    n_cells = archive.fitness.shape[0]
    cells = np.full(n_cells, -1, np.int32)
    raw = np.full((n_cells, 2), np.nan, np.float32)
    lo = jnp.asarray([r[0] for r in config.ranges], jnp.float32)
    hi = jnp.asarray([r[1] for r in config.ranges], jnp.float32)
    centroids = jnp.asarray(archive.centroids)

    def derive_fn(render_one):
        def derive(genomes):
            d = jnp.asarray(descriptor_fn(jax.vmap(render_one)(genomes)), jnp.float32)
            return get_cells_indices(jnp.clip(jnp.where(jnp.isfinite(d), d, lo), lo, hi), centroids), d

        return jax.jit(derive)

    for g, name in enumerate(archive.generator_names):
        idx = np.flatnonzero(archive.source == g)
        if idx.size == 0:
            continue
        gen = gens[name] if gens is not None and name in gens else generators.get(name, **(generator_options or {}))
        fn = derive_fn(gen.render_one)
        for s in range(0, idx.size, batch):
            part = idx[s:s + batch]
            pad = np.concatenate([part, np.repeat(part[-1:], batch - part.size)])  # one compiled shape
            c, d = fn(jax.tree.map(lambda x: jnp.asarray(x[pad]), archive.genomes[g]))
            cells[part] = np.asarray(c)[:part.size]
            raw[part] = np.asarray(d)[:part.size]
    return cells, raw


def check_cells(archive: Archive, generator_options: dict | None = None, batch: int = 64, gens: dict | None = None,
                descriptor_fn=None) -> np.ndarray:
    """``[cells]`` bool: True where the stored elite re-derives to its own cell (:func:`rederive_cells`, same
    arguments); empty cells are True. A False marks an elite whose genome renders to a terrain of another cell (e.g.
    a genome mixed from several offspring by the tie bug of QDax 0.5.0's ``MapElitesRepertoire.add``; see
    ``docs/results/insertion_bug.md``)."""
    cells, _ = rederive_cells(archive, generator_options, batch, gens, descriptor_fn)
    return (archive.source < 0) | (cells == np.arange(cells.shape[0]))


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


def to_device(archive: Archive, scale: TerrainScale | None = None):
    """The archive's filled cells on device: :func:`jaxterrain.bank.from_archive` (a ``TerrainBank``, heightmaps in
    metres). ``scale`` defaults to the archive's own ``config.scale``, the scale its fitness was measured at."""
    from jaxterrain.bank import from_archive

    return from_archive(archive, archive.config.scale if scale is None else scale)


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


# The host drivers live in jaxterrain.evolution (imported last: it uses this module's names).
from jaxterrain.evolution import (  # noqa: E402
    Treatment,
    difficulty_fitness,
    evolve,
    evolve_many,
    progress_printer,
)
