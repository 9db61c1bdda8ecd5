"""Diamond-square noise as the paper writes it (section 3.1).

Genome ``[7]`` float32 (integer genes stored as whole floats), in this order:

=========  ==========  =====================================================================================
gene       range       meaning
=========  ==========  =====================================================================================
c00        [-1, 1]     value of the top-left corner of the grid (row 0, column 0)
c01        [-1, 1]     top-right corner (row 0, last column)
c10        [-1, 1]     bottom-left corner (last row, column 0)
c11        [-1, 1]     bottom-right corner (last row, last column)
Z          [0, 50]     percentile: the random percentage P is uniform in [Z, 100 - Z] (then divided by 100)
D          [1, 10]     level: the random offset R is uniform in [-r, r], r = 1 / (steps * D + 1)
seed       [0, 100]    integer; keys every random number (``jax.random.PRNGKey(seed)``)
=========  ==========  =====================================================================================

Algorithm, on a ``(2^n + 1) x (2^n + 1)`` grid with ``2^n = size`` (257 x 257 for the default 256):

* The four corners are the genes ``c00, c01, c10, c11``.
* Iteration ``steps = 0, 1, ..., n - 1`` halves the square side. Diamond step: the midpoint of every square gets
  ``P * mean(its 4 corners) + R``. Square step: the midpoint of every diamond (the edge midpoints of the squares)
  gets ``P * mean(its neighbours) + R``; its neighbours are the two square corners on its edge and the two square
  midpoints on either side. On the border of the grid only 3 of those exist and the mean is over those 3 (no
  wrap-around). ``P`` and ``R`` are drawn afresh for every point; ``R`` is uniform in ``[-r, r]`` with
  ``r = 1 / (steps * D + 1)`` (so ``r = 1`` in the first iteration, as in the paper, then it shrinks).
* Every grid point owns one pair of uniforms from ``jax.random.uniform(PRNGKey(seed), (2, 2^n + 1, 2^n + 1))``,
  indexed by its final grid position.
* Implementation: each iteration is dense and static in shape: the ``(m + 1) x (m + 1)`` grid is spread onto a
  ``(2m + 1) x (2m + 1)`` grid by interior zero padding, then both steps are shifted-neighbour sums masked to the
  new points (static numpy masks / neighbour counts), for ``n`` statically unrolled iterations: no scatter, no
  gather, a handful of fused elementwise kernels per iteration.

Mapping to the heightmap: the grid is ``(size + 1) x (size + 1)``; the heightmap is its first ``size`` rows and
columns (the last row and column are dropped; no resampling). So pixel ``[0, 0]`` is the ``c00`` corner, while the
other three corners lie in the dropped row / column (they still shape the map through the subdivision).
Values are mapped to [0, 1] by the FIXED affine map ``h = clip((v + 1) / 2, 0, 1)`` of the nominal range
[-1, 1] of the corners (values that the random offsets push outside [-1, 1] are clipped). No per-map
normalisation, so maps with small offsets (large D) stay flat. ``size`` must be a power of two.

As written in the paper, every new point is a random *percentage* of its neighbours' mean (P ~ 0.5 on average for
Z = 0), so the corner values and the coarse relief shrink by about P per iteration and the finer iterations'
offsets R dominate the map (the paper notes that diamond-square struggles to reach large TPI values).

Throughput (one H100, jax 0.11.2, ``jit(vmap(render_one))``, 256 x 256): ~600,000 maps/s at B = 1024 to 8192.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain.generators.base import Generator, spec, vector_generator
from jaxterrain.generators.registry import register

__all__ = ["DIAMOND_SQUARE_SPEC", "diamond_square_grid", "render_diamond_square", "diamond_square"]

DIAMOND_SQUARE_SPEC = spec(
    ("c00", -1.0, 1.0, False),
    ("c01", -1.0, 1.0, False),
    ("c10", -1.0, 1.0, False),
    ("c11", -1.0, 1.0, False),
    ("Z", 0.0, 50.0, False),
    ("D", 1.0, 10.0, False),
    ("seed", 0.0, 100.0, True),
)


def _level_constants(m: int):
    """Static masks and neighbour counts for the (2m + 1) x (2m + 1) grid of one iteration (numpy, float32)."""
    n = 2 * m + 1
    odd = np.arange(n) % 2 == 1
    centre = (odd[:, None] & odd[None, :]).astype(np.float32)  # square midpoints (diamond step)
    edge = (odd[:, None] ^ odd[None, :]).astype(np.float32)  # diamond midpoints (square step)
    inside = np.ones((n, n), np.float32)
    count = sum(np.roll(np.pad(inside, 1), s, a)[1:-1, 1:-1] for a in (0, 1) for s in (-1, 1))
    return centre, edge, (edge / count).astype(np.float32)


def _axial_sum(x: jax.Array) -> jax.Array:
    """Sum of the 4 axis neighbours (zero outside the grid). [n, n]."""
    p = jnp.pad(x, 1)
    return p[:-2, 1:-1] + p[2:, 1:-1] + p[1:-1, :-2] + p[1:-1, 2:]


def _diagonal_sum(x: jax.Array) -> jax.Array:
    """Sum of the 4 diagonal neighbours (zero outside the grid). [n, n]."""
    p = jnp.pad(x, 1)
    return p[:-2, :-2] + p[:-2, 2:] + p[2:, :-2] + p[2:, 2:]


def diamond_square_grid(genome: jax.Array, levels: int = 8) -> jax.Array:
    """The raw diamond-square grid ``[2^levels + 1, 2^levels + 1]`` float32 (values around [-1, 1], unclipped)."""
    genome = jnp.asarray(genome, jnp.float32)
    c00, c01, c10, c11, z, d, seed = (genome[i] for i in range(7))
    n = 2**levels + 1
    key = jax.random.PRNGKey(jnp.round(seed).astype(jnp.int32))
    uniforms = jax.random.uniform(key, (2, n, n), jnp.float32)
    del key
    p_all = (z + uniforms[0] * (100.0 - 2.0 * z)) * 0.01  # P in [Z, 100 - Z] / 100
    u_all = uniforms[1] * 2.0 - 1.0  # R / r, in [-1, 1]

    grid = jnp.stack([jnp.stack([c00, c01]), jnp.stack([c10, c11])])  # [2, 2]
    for steps in range(levels):
        m = 2**steps  # squares per side at this iteration
        half = 2 ** (levels - steps - 1)  # spacing of the refined grid in final-grid cells
        r = 1.0 / (steps * d + 1.0)
        centre, edge, edge_weight = _level_constants(m)
        p = p_all[::half, ::half]  # [2m + 1, 2m + 1]: the uniforms of the refined grid's points
        rr = r * u_all[::half, ::half]
        # Refined grid with the known points at even positions and zeros between (interior padding).
        grid = jax.lax.pad(grid, jnp.float32(0), ((0, 0, 1), (0, 0, 1)))
        # Diamond step: square midpoints = P * mean of the 4 diagonal neighbours (the square's corners) + R.
        grid = grid + centre * (p * 0.25 * _diagonal_sum(grid) + rr)
        # Square step: diamond midpoints = P * mean of the 3 or 4 axis neighbours that exist + R.
        grid = grid + edge * rr + edge_weight * p * _axial_sum(grid)
    return grid


def render_diamond_square(genome: jax.Array, size: int = 256) -> jax.Array:
    """One genome ``[7]`` -> heightmap ``[size, size]`` float32 in [0, 1]. Unchecked; jit / vmap friendly."""
    levels = size.bit_length() - 1
    grid = diamond_square_grid(genome, levels)
    return jnp.clip((grid[:size, :size] + 1.0) * 0.5, 0.0, 1.0)


@register("diamond_square")
def diamond_square(size: int = 256) -> Generator:
    """Diamond-square generator producing ``[B, size, size]`` float32 maps in [0, 1]; see the module docstring."""
    size = int(size)
    if size < 2 or size & (size - 1):
        raise ValueError(f"diamond_square: size must be a power of two >= 2 (..., 64, 128, 256, 512, ...: the grid "
                         f"has 2^n + 1 points a side); got {size}")

    def render_one(genome: jax.Array) -> jax.Array:
        return render_diamond_square(genome, size)

    return vector_generator("diamond_square", DIAMOND_SQUARE_SPEC, render_one, size)
