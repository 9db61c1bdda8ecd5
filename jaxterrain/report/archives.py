"""Stage 2 of a report: an archive as a grid of cells, each with its fitness, descriptors and a terrain thumbnail.

    view = archives.view(qd.load("runs/evolve-x/archive.npz"), thumb=64)
    view.cells        # one ArchiveCell per filled cell: cell, bins, fitness, descriptors, generator, thumbnail
    view.picks        # {"easy": cell, "medium": cell, "hard": cell} (highest, median and lowest fitness)

Heightmaps come from the archive (``archive.heightmaps``) or, for archives saved with genomes only (as
``docs/results`` ships them), are rendered from the elites' genomes by their own generators
(:func:`elite_heightmaps`, in chunks, so a full 50 x 50 archive never needs all its maps in memory at once).
Thumbnails are shaded relief (matplotlib's ``LightSource`` over the ``terrain`` colour map, heights 0..1 on one
fixed scale, so thumbnails compare across cells) encoded as JPEG.
"""

from __future__ import annotations

import io
from typing import NamedTuple, Sequence

import numpy as np

from jaxterrain import generators, qd as A
from jaxterrain.qd.grid import cell_bins

__all__ = ["ArchiveCell", "ArchiveView", "view", "elite_heightmaps", "pick_cells", "thumbnail", "heatmap_png"]


class ArchiveCell(NamedTuple):
    cell: int
    bins: tuple[int, int]  # (bin of descriptor 0, bin of descriptor 1)
    fitness: float
    descriptors: tuple[float, float]
    generator: str
    thumbnail: bytes  # JPEG
    heights: tuple[float, float]  # lowest and highest point, heightmap units


class ArchiveView(NamedTuple):
    """What the report shows of one archive.

    Attributes: ``bins``, ``descriptor_names`` (2), ``ranges`` (2 pairs), ``generator_names``, ``cells`` (the
    filled cells in increasing cell order), ``picks`` (label -> cell), ``coverage`` (percent), ``qd_score``,
    ``shape`` ([H, W] of its heightmaps), ``metrics`` (name -> per-generation history).
    """

    bins: int
    descriptor_names: tuple[str, str]
    ranges: tuple[tuple[float, float], tuple[float, float]]
    generator_names: tuple[str, ...]
    cells: list[ArchiveCell]
    picks: dict[str, int]
    coverage: float
    qd_score: float
    shape: tuple[int, int]
    metrics: dict


def elite_heightmaps(arch, cells: Sequence[int], chunk: int = 64, size: int | None = None) -> np.ndarray:
    """``[len(cells), H, W]`` float32 in [0, 1]: the heightmaps of the elites in ``cells`` (filled cells only).

    From ``arch.heightmaps`` when the archive stores them, else rendered from the stored genomes by their own
    generator (``generators.get(name)``, or ``generators.get(name, size=size)``), ``chunk`` elites per call.
    Raises ``ValueError`` for an empty or out-of-range cell.
    """
    cells = np.asarray(list(cells), np.int64)
    n_cells = arch.fitness.shape[0]
    if cells.size and (cells.min() < 0 or cells.max() >= n_cells):
        raise ValueError(f"cells must be in [0, {n_cells - 1}]; got {cells.tolist()}")
    empty = [int(c) for c in cells if arch.source[c] < 0]
    if empty:
        raise ValueError(f"cell(s) {empty} are empty")
    if arch.heightmaps is not None:
        return np.asarray(arch.heightmaps)[cells].astype(np.float32) / 65535.0
    import jax
    import jax.numpy as jnp


    out = None
    for g, name in enumerate(arch.generator_names):
        rows = np.flatnonzero(arch.source[cells] == g)
        if rows.size == 0:
            continue
        gen = generators.get(name) if size is None else generators.get(name, size=size)
        render = jax.jit(jax.vmap(gen.render_one))
        width = min(chunk, rows.size)
        for s in range(0, rows.size, width):
            part = rows[s:s + width]
            idx = cells[np.concatenate([part, np.repeat(part[-1:], width - part.size)])]  # one compiled shape
            maps = np.asarray(render(jax.tree.map(lambda x: jnp.asarray(np.asarray(x)[idx]), arch.genomes[g])))
            if out is None:
                out = np.zeros((cells.size,) + maps.shape[1:], np.float32)
            out[part] = np.clip(maps[:part.size], 0.0, 1.0)
    return out if out is not None else np.zeros((0, 1, 1), np.float32)


def thumbnail(heightmap: np.ndarray, size: int = 64, quality: int = 85, extent: float = 10.2) -> bytes:
    """A ``size`` x ``size`` JPEG of one ``[H, W]`` heightmap: the ``gist_earth`` colour map from the map's lowest
    (dark blue) to its highest point (white), overlaid with relief shading lit from the north-west at the map's true
    proportions (``extent`` metres across, heights in heightmap units = metres at the default scale) exaggerated
    3x; row 0 at the bottom, as in a plot of the walker's +y."""
    import matplotlib
    from matplotlib.colors import LightSource, Normalize
    from PIL import Image

    h = np.asarray(heightmap, np.float32)
    small = np.asarray(Image.fromarray(h).resize((size, size), Image.Resampling.BOX), np.float32)
    lo, hi = float(small.min()), float(small.max())
    ls = LightSource(azdeg=315, altdeg=45)
    rgb = ls.shade(np.flipud(small), cmap=matplotlib.colormaps["gist_earth"], norm=Normalize(lo, max(hi, lo + 1e-6)),
                   blend_mode="overlay", vert_exag=3.0, dx=extent / size, dy=extent / size)[..., :3]
    buf = io.BytesIO()
    Image.fromarray(np.round(np.clip(rgb, 0, 1) * 255).astype(np.uint8)).save(buf, format="JPEG", quality=quality)
    return buf.getvalue()


def pick_cells(fitness: np.ndarray, cells: np.ndarray) -> dict[str, int]:
    """``{"easy", "medium", "hard"}`` -> cell: the elites of highest, median and lowest fitness (fitness = the base
    policy's normalised distance, so high = easy). Fewer labels when there are fewer than three elites."""
    fitness, cells = np.asarray(fitness, np.float64), np.asarray(cells)
    if cells.size == 0:
        return {}
    order = np.argsort(-fitness, kind="stable")  # easiest first
    picks = {"easy": int(cells[order[0]])}
    if cells.size >= 3:
        picks["medium"] = int(cells[order[cells.size // 2]])
    if cells.size >= 2:
        picks["hard"] = int(cells[order[-1]])
    return picks


def view(arch, thumb: int = 64, chunk: int = 64) -> ArchiveView:
    """The :class:`ArchiveView` of an archive: every filled cell with a ``thumb``-pixel thumbnail."""

    config = arch.config
    filled = np.flatnonzero(np.asarray(arch.source) >= 0)
    bins = int(config.bins)
    cells: list[ArchiveCell] = []
    shape = (0, 0)
    for s in range(0, filled.size, 256):  # bounded memory for genome-only archives
        part = filled[s:s + 256]
        maps = elite_heightmaps(arch, part, chunk=chunk)
        shape = tuple(maps.shape[1:])
        for c, hm in zip(part, maps):
            c = int(c)
            b0, b1 = (int(b) for b in cell_bins(c, bins))
            cells.append(ArchiveCell(cell=c, bins=(b0, b1), fitness=float(arch.fitness[c]),
                                     descriptors=tuple(float(v) for v in arch.descriptors[c]),
                                     generator=arch.generator_names[int(arch.source[c])],
                                     thumbnail=thumbnail(hm, thumb), heights=(float(hm.min()), float(hm.max()))))
    picks = pick_cells(np.asarray(arch.fitness)[filled], filled)
    return ArchiveView(bins=bins, descriptor_names=tuple(config.descriptors), ranges=tuple(config.ranges),
                       generator_names=tuple(arch.generator_names), cells=cells, picks=picks,
                       coverage=A.coverage(arch), qd_score=A.qd_score(arch), shape=shape,
                       metrics={k: np.asarray(v) for k, v in arch.metrics.items()})


def heatmap_png(v: ArchiveView, title: str = "") -> bytes:
    """A PNG of the archive's fitness grid (viridis_r over 0..1 as the commands' figures, empty cells white) with
    the picked cells marked, for the Markdown report."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    grid = np.full((v.bins, v.bins), np.nan)
    for c in v.cells:
        grid[c.bins[1], c.bins[0]] = c.fitness
    (x0, x1), (y0, y1) = v.ranges
    fig, ax = plt.subplots(figsize=(4.6, 4))
    fit = grid[np.isfinite(grid)]
    lo, hi = (0.0, 1.0) if fit.size == 0 or (fit.min() >= 0 and fit.max() <= 1) else (fit.min(), fit.max())
    im = ax.imshow(grid, origin="lower", cmap="viridis_r", vmin=lo, vmax=hi, extent=(x0, x1, y0, y1),
                   aspect="auto", interpolation="nearest")
    fig.colorbar(im, ax=ax, label="fitness")
    for label, cell in v.picks.items():
        b0, b1 = (int(b) for b in cell_bins(cell, v.bins))
        ax.text(x0 + (b0 + 0.5) * (x1 - x0) / v.bins, y0 + (b1 + 0.5) * (y1 - y0) / v.bins, label[0].upper(),
                ha="center", va="center", color="red", fontsize=9, fontweight="bold")
    ax.set_xlabel(v.descriptor_names[0]), ax.set_ylabel(v.descriptor_names[1])
    ax.set_title(title or f"coverage {v.coverage:.1f} %, QD score {v.qd_score:.1f}", fontsize=9)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    return buf.getvalue()
