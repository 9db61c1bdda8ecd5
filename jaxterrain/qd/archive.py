"""Host queries of MAP-Elites terrain archives (paper section 3.3): render, re-derive and reseat elites, coverage,
QD score, grids, and :func:`combine`.

    >>> from jaxterrain import qd
    >>> config = qd.EvolveConfig(generations=5000, batch_size=20, descriptors=("roughness", "tpi"))
    >>> arch = qd.evolve("perlin", None, config, key, checkpoint_dir="runs/x/ckpt")
    >>> qd.coverage(arch)                           # percent of the 50 x 50 cells filled
    >>> qd.save("perlin.npz", arch); arch = qd.load("perlin.npz")
    >>> both = qd.combine([arch_perlin, arch_cppn])  # cell by cell, highest fitness wins
    >>> bank = qd.to_device(arch, scale)            # qd.TerrainBank, the elites on device
    >>> ok = qd.check_cells(arch)                   # [cells] bool: each elite's genome re-derives its own cell

The pipeline (:mod:`jaxterrain.qd`): :mod:`~jaxterrain.qd.scoring` (render, descriptors, Algorithm 1, fitness;
QDax's scoring contract), :mod:`~jaxterrain.qd.map_elites` (the pure state, ``init`` / ``step``, the
one-winner-per-cell insertion, several treatments at once), :mod:`~jaxterrain.qd.evolution` (the host drivers
``evolve`` / ``evolve_many``) and this module (the host archive's queries). The types and settings are
:mod:`~jaxterrain.qd.config`'s (:class:`EvolveConfig`, :class:`Archive`, :data:`DEFAULT_RANGES`,
``resolve_config``), the grid :mod:`~jaxterrain.qd.grid`'s and the file :mod:`~jaxterrain.qd.archive_io`'s
(``save`` / ``load``, whose format is described below).

The loop (see :mod:`jaxterrain.qd.map_elites`): generation 0 evaluates ``initial_population`` random genomes; every
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

from typing import Any, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from qdax.core.containers.mapelites_repertoire import get_cells_indices

from jaxterrain import features, generators
from jaxterrain.qd.config import Archive, EvolveConfig, resolve_config
from jaxterrain.qd.grid import cell_bins, cell_distance

__all__ = ["render_elites", "rederive_cells", "check_cells", "refused", "reseat", "heightmaps", "coverage", "qd_score",
           "elite", "fitness_grid", "combine", "generator_shares"]

# ----------------------------------------------------------------------------------------------------------------
# Elites: render, re-derive their cells, query
# ----------------------------------------------------------------------------------------------------------------


def render_elites(generator, genomes, filled: np.ndarray, batch: int = 64) -> np.ndarray:
    """Heightmaps ``[cells, H, W]`` uint16 (height * 65535) of the filled cells (zeros elsewhere). With a mixture
    (``generators.mixture``; ``genomes`` a ``MixedGenome``, leaves ``[cells, ...]``) each elite is rendered by its
    own generator, ``genomes.generator[cell]``."""
    if generators.is_mixture(generator):
        out = None
        ids = np.asarray(genomes.generator)
        for k, gen in enumerate(generator.spec.generators):
            part = render_elites(gen, genomes.slots[k], np.asarray(filled) & (ids == k), batch)
            out = part if out is None else out + part  # disjoint cells: zeros elsewhere
        return out
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


def refused(archive: Archive, generator_options: dict | None = None, gens: dict | None = None) -> np.ndarray:
    """``[cells]`` bool: True where the stored genome is one its generator's ``validate`` refuses (e.g. a mixture
    of several offspring's leaves left by the tie bug of QDax 0.5.0's insertion); False for valid and empty
    cells. Each filled cell's genome is checked alone, on the host."""
    out = np.zeros(archive.fitness.shape[0], bool)
    for g, name in enumerate(archive.generator_names):
        gen = gens[name] if gens is not None and name in gens else generators.get(name, **(generator_options or {}))
        for i in np.flatnonzero(archive.source == g):
            try:
                gen.validate(jax.tree.map(lambda x: x[i:i + 1], archive.genomes[g]))
            except ValueError:
                out[i] = True
    return out


def reseat(archive: Archive, fitness: np.ndarray, generator_options: dict | None = None, batch: int = 64,
           gens: dict | None = None, descriptor_fn=None, protocol=None,
           spawn: str | None = None) -> tuple[Archive, dict]:
    """A sound archive from the STORED genomes of ``archive``: each one in the cell its own terrain falls in, with a
    fitness measured on that terrain.

    For archives whose cells, descriptors or fitness may not belong to their genomes (those evolved before the fix
    of tied insertions, ``docs/results/insertion_bug.md``), short of evolving them again. Every filled cell's genome
    is checked with its generator's ``validate`` (:func:`refused` ones are dropped), re-derived
    (:func:`rederive_cells`: rendered, described, clipped, nearest centroid) and inserted into an empty grid of the
    same config with ``fitness[cell]``: per target cell the highest fitness wins, ties to the lowest source cell,
    as :func:`jaxterrain.qd.map_elites.insert` does. A NaN fitness (not measured) drops the elite.

    Args:
      archive: the archive to reseat.
      fitness: [cells] float, a fitness per source cell measured on the terrain of its stored genome (e.g. walked
        again under a :class:`jaxterrain.difficulty.Protocol`); read at filled cells only.
      generator_options, batch, gens, descriptor_fn: as :func:`rederive_cells`.
      protocol: the :class:`jaxterrain.difficulty.Protocol` ``fitness`` was measured under, recorded in the new
        archive's config (``attempts``, ``best``, ``headings``; ``start_spread`` 0 and ``rule`` "mean" only, which
        the config implies); None keeps the archive's.
      spawn: the spawn rule ``fitness`` was walked under (``walker.SPAWNS``), recorded in the new archive's config;
        None keeps the archive's.

    Returns:
      ``(reseated, counts)``: the new archive (``heightmaps`` None: render them with ``qd.from_archive``;
      ``metrics`` empty) and ``{"elites", "refused", "unmeasured", "moved", "displaced", "kept"}``: filled cells
      in, genomes refused, elites without a fitness, elites whose cell changed, elites that lost their target cell
      to a fitter (or equal, earlier) one, and elites in the result.
    """
    n_cells = archive.fitness.shape[0]
    fitness = np.asarray(fitness, np.float32).reshape(-1)
    if fitness.shape[0] != n_cells:
        raise ValueError(f"reseat: fitness must have shape [cells={n_cells}]; got {fitness.shape}")
    config = archive.config
    if protocol is not None:
        if float(protocol.start_spread) != 0.0 or protocol.rule != "mean":
            raise ValueError("reseat: an archive records a protocol's attempts, best and headings only; got "
                             f"start_spread={protocol.start_spread}, rule={protocol.rule!r} (need 0.0 and 'mean')")
        config = resolve_config(config._replace(attempts=int(protocol.attempts), best=int(protocol.best),
                                                headings=int(protocol.headings)))
    if spawn is not None:
        config = resolve_config(config._replace(spawn=spawn))
    bad = refused(archive, generator_options, gens)
    cells, raw = rederive_cells(archive, generator_options, batch, gens, descriptor_fn)
    filled = archive.source >= 0
    ok = filled & ~bad & np.isfinite(fitness)
    rows = np.flatnonzero(ok)
    order = rows[np.lexsort((rows, -fitness[rows]))]  # fittest first, ties to the lowest source cell
    _, first = np.unique(cells[order], return_index=True)
    winners = order[first]  # one source row per target cell
    target = cells[winners]
    source = np.full(n_cells, -1, np.int32)
    source[target] = archive.source[winners]
    fit = np.full(n_cells, -np.inf, np.float32)
    fit[target] = fitness[winners]
    desc = np.zeros_like(archive.descriptors)
    desc[target] = raw[winners]
    genomes = []
    for g, genome in enumerate(archive.genomes):
        mine = winners[archive.source[winners] == g]

        def move(x, mine=mine):
            out = np.zeros_like(x)
            out[cells[mine]] = x[mine]
            return out

        genomes.append(jax.tree.map(move, genome))
    counts = {"elites": int(filled.sum()), "refused": int((filled & bad).sum()),
              "unmeasured": int((filled & ~bad & ~np.isfinite(fitness)).sum()),
              "moved": int((ok & (cells != np.arange(n_cells))).sum()), "displaced": int(rows.size - winners.size),
              "kept": int(winners.size)}
    return Archive(tuple(genomes), archive.generator_names, source, fit, desc, archive.centroids.copy(), None,
                   config, {}), counts


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


def fitness_grid(archive: Archive, values: np.ndarray | None = None) -> np.ndarray:
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
# Who holds the cells: each generator's share per distance band
# ----------------------------------------------------------------------------------------------------------------


def generator_shares(archive: Archive, width: float = 10.0, names: Sequence[str] | None = None) -> dict:
    """Each generator's share of an archive's filled cells per band of distance from cell (0, 0).

    A cell's distance is :func:`jaxterrain.qd.cell_distance` of its bins (to the cell's far corner, 70.71 for the
    last cell of a 50 x 50 grid); band ``b`` holds ``b * width <= distance < (b + 1) * width``, as in
    ``docs/results/gradient.md``; the last band ends past the grid's largest distance.

    Args:
      archive: any archive (one run's, a mixed run's, ``combine``'s).
      width: band width in cells (> 0).
      names: the generators to count, in this order (default ``archive.generator_names``); a name the archive
        lacks counts zero cells.

    Returns:
      ``{"names": tuple, "lo", "hi": [bands] float band edges, "cells": [bands] int cells of the grid in the band,
      "filled": [bands] int filled cells, "count": [bands, G] int cells held by each generator, "share": [bands, G]
      float fraction of the band's FILLED cells held by each generator (NaN for a band with none), "coverage":
      [bands] float percent of the band's cells filled, "total": [G] int cells held by each generator}``.
    """
    if not (isinstance(width, (int, float, np.floating)) and not isinstance(width, bool) and np.isfinite(width)
            and width > 0):
        raise ValueError(f"generator_shares: width must be a finite number > 0 (cells); got {width!r}")
    names = tuple(archive.generator_names) if names is None else tuple(names)
    bins = archive.config.bins
    n_cells = archive.fitness.shape[0]
    distance = cell_distance(cell_bins(np.arange(n_cells), bins)).astype(np.float64)
    band = np.floor(distance / width).astype(np.int64)
    n_bands = int(band.max()) + 1
    filled = archive.source >= 0
    own = {n: i for i, n in enumerate(archive.generator_names)}
    count = np.zeros((n_bands, len(names)), np.int64)
    for j, name in enumerate(names):
        if name in own:
            count[:, j] = np.bincount(band[filled & (archive.source == own[name])], minlength=n_bands)
    cells = np.bincount(band, minlength=n_bands)
    n_filled = np.bincount(band[filled], minlength=n_bands)
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(n_filled[:, None] > 0, count / np.maximum(n_filled, 1)[:, None], np.nan)
    lo = np.arange(n_bands, dtype=np.float64) * width
    return {"names": names, "lo": lo, "hi": lo + width, "cells": cells, "filled": n_filled, "count": count,
            "share": share, "coverage": 100.0 * n_filled / np.maximum(cells, 1), "total": count.sum(axis=0)}
