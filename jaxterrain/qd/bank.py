"""A device-side terrain bank: an archive's filled cells as arrays a jitted curriculum can carry.

    bank = qd.from_archive(arch)                     # host Archive -> device pytree
    terrain = bank.heightmaps[i]                     # [H, W] float32 metres, ready for WalkerEnv.reset / step
    bank.points[i]                                   # [2] descriptors normalised to [0, 1] (the GP's inputs)

Only FILLED cells are stored (``N`` = number of elites), in increasing cell order, so a 50 x 50 archive with 1 000
elites holds 1 000 heightmaps (256 KiB each at 256 x 256), not 2 500. A mesh can shard every field along axis 0.

The one :class:`~jaxterrain.terrain.TerrainScale` given here turns the archive's [0, 1] heightmaps into metres; the
curriculum's walker must use the same scale (``WalkerConfig(scale=bank_scale)``).
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from jaxterrain import generators
from jaxterrain.qd.grid import cell_bins, cell_distance
from jaxterrain.terrain import TerrainScale, validate_scale

__all__ = ["TerrainBank", "from_archive", "from_heightmaps", "to_device"]



class TerrainBank(NamedTuple):
    """The elites of an archive on device (a pytree; every field leads with ``N`` = filled cells).

    Attributes:
      heightmaps: [N, H, W] float32, metres (heightmap x ``scale.height``).
      fitness: [N] float32, the archive's fitness of each elite (the base policy's; the GP's prior mean).
      descriptors: [N, 2] float32, raw (unclipped) descriptor values.
      points: [N, 2] float32, descriptors clipped to the archive's ranges and normalised to [0, 1].
      bins: [N, 2] int32, (bin of descriptor 0, bin of descriptor 1), each in [0, bins).
      distance: [N] float32, :func:`cell_distance` of each elite's cell, in cells.
      cell: [N] int32, flat cell index in the archive (``bin1 * bins + bin0``, QDax's order).
      source: [N] int32, generator id (index into ``Archive.generator_names``).
    """

    heightmaps: jnp.ndarray
    fitness: jnp.ndarray
    descriptors: jnp.ndarray
    points: jnp.ndarray
    bins: jnp.ndarray
    distance: jnp.ndarray
    cell: jnp.ndarray
    source: jnp.ndarray

    @property
    def size(self) -> int:
        """N, the number of terrains."""
        return int(self.fitness.shape[0])


def from_archive(archive, scale: TerrainScale | None = None, render_chunk: int = 256) -> TerrainBank:
    """``qd.Archive`` (host) -> :class:`TerrainBank` (device), the filled cells in increasing cell order.

    ``scale`` (default ``TerrainScale()``) converts heights to metres. An archive saved without heightmaps (genomes
    only, as ``docs/results`` ships them) is rendered here, each elite by its own generator (``generators.get``;
    ``render_chunk`` terrains per call). Raises ``ValueError`` when the archive has no filled cell.
    """
    scale = validate_scale(TerrainScale() if scale is None else scale)
    filled = np.asarray(archive.source) >= 0
    if not filled.any():
        raise ValueError("from_archive: the archive has no filled cell")
    idx = np.flatnonzero(filled)
    config = archive.config
    bins = int(config.bins)
    lo = np.asarray([r[0] for r in config.ranges], np.float32)
    hi = np.asarray([r[1] for r in config.ranges], np.float32)
    desc = np.asarray(archive.descriptors, np.float32)[idx]
    points = np.clip((np.nan_to_num(desc, nan=0.0) - lo) / (hi - lo), 0.0, 1.0).astype(np.float32)
    bins_ = cell_bins(idx, bins)
    maps = _render_filled(archive, idx, render_chunk) if archive.heightmaps is None else np.asarray(archive.heightmaps)[idx]
    if maps.dtype == np.uint16:
        maps = maps.astype(np.float32) / 65535.0
    return TerrainBank(
        heightmaps=jnp.asarray(maps.astype(np.float32) * np.float32(scale.height)),
        fitness=jnp.asarray(np.asarray(archive.fitness, np.float32)[idx]),
        descriptors=jnp.asarray(desc),
        points=jnp.asarray(points),
        bins=jnp.asarray(bins_),
        distance=jnp.asarray(cell_distance(bins_)),
        cell=jnp.asarray(idx.astype(np.int32)),
        source=jnp.asarray(np.asarray(archive.source, np.int32)[idx]),
    )


def from_heightmaps(heightmaps, hardness, fitness=None) -> TerrainBank:
    """A :class:`TerrainBank` of terrains that no archive holds (``suite.folder``: a folder of your own heightmaps):
    ``heightmaps`` [N, H, W] metres; ``hardness`` [N] goes into ``distance`` (what ``levels`` bands and the "hardest
    terrain traversed" read); ``fitness`` [N] (default zeros: unmeasured). There is no grid: descriptors, points and
    bins are zeros, ``cell`` and ``source`` the terrain's index. ``ValueError`` for mismatched shapes or no terrain."""
    maps = np.asarray(heightmaps, np.float32)
    n = maps.shape[0] if maps.ndim == 3 else 0
    hard = np.asarray(hardness, np.float32)
    fit = np.zeros(n, np.float32) if fitness is None else np.asarray(fitness, np.float32)
    if n < 1 or hard.shape != (n,) or fit.shape != (n,):
        raise ValueError(f"from_heightmaps: heightmaps [N >= 1, H, W] with hardness and fitness [N]; got "
                         f"{maps.shape}, {hard.shape}, {fit.shape}")
    index = np.arange(n, dtype=np.int32)
    zeros2 = np.zeros((n, 2), np.float32)
    return TerrainBank(heightmaps=jnp.asarray(maps), fitness=jnp.asarray(fit), descriptors=jnp.asarray(zeros2),
                       points=jnp.asarray(zeros2), bins=jnp.zeros((n, 2), jnp.int32), distance=jnp.asarray(hard),
                       cell=jnp.asarray(index), source=jnp.asarray(index))


def _render_filled(archive, idx: np.ndarray, chunk: int) -> np.ndarray:
    """[len(idx), H, W] float32 in [0, 1]: the elites of cells ``idx`` rendered by their own generators."""
    import jax


    source = np.asarray(archive.source)[idx]
    out = None
    for g, name in enumerate(archive.generator_names):
        rows = np.flatnonzero(source == g)
        if rows.size == 0:
            continue
        gen = generators.get(name)
        render = jax.jit(jax.vmap(gen.render_one))
        for s in range(0, rows.size, chunk):
            part = rows[s:s + chunk]
            cells = idx[np.concatenate([part, np.repeat(part[-1:], chunk - part.size)])]  # one compiled shape
            maps = np.asarray(render(jax.tree.map(lambda x: jnp.asarray(x[cells]), archive.genomes[g])))
            if out is None:
                out = np.zeros((idx.size,) + maps.shape[1:], np.float32)
            out[part] = maps[:part.size]
    return out


def to_device(archive, scale: TerrainScale | None = None) -> TerrainBank:
    """The archive's filled cells on device: :func:`from_archive` at ``scale``, which defaults to the archive's own
    ``config.scale`` (the scale its fitness was measured at)."""
    return from_archive(archive, archive.config.scale if scale is None else scale)
