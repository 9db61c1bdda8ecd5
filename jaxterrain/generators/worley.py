"""Worley (cellular) noise, Worley 1996 (paper section 3.1).

Genome ``[3]`` float32 (all genes are integers stored as whole floats), in this order:

=====  ==========  ========================================================================================
gene   range       meaning
=====  ==========  ========================================================================================
seed   [0, 100]    keys the feature points (``jax.random.PRNGKey(seed)``)
N      [2, 400]    number of feature points
D      [0, 100]    0-based index of the sorted distance returned at each pixel (``F_{D+1}`` in Worley's
                   notation: D = 0 is the distance to the nearest point); constrained to ``D <= floor(N / 4)``
=====  ==========  ========================================================================================

Rendering (``render_one(genome[3]) -> [size, size]`` float32 in [0, 1]):

* 400 candidate points are drawn uniformly in ``[0, size)^2`` (pixel units) from the seed; the first ``N`` are the
  feature points and the rest are masked (at +inf distance). So N varies freely inside one vmapped batch, and
  the first ``N`` points of a seed do not depend on ``N``.
* At each pixel ``(i, j)`` the value is ``F_D = sqrt(d2_(D))``, the D-th smallest (0-based) Euclidean distance to
  the feature points. The map is then divided by its own maximum (the standard Worley texture normalisation:
  the farthest pixel is 1, a feature point is ~0). This per-map normalisation is what makes maps with different
  ``N`` comparable in [0, 1].
* Distances are separable: ``d2[i, j, p] = (i - y_p)^2 + (j - x_p)^2``, so the ``[size, 400]`` row and column terms
  are computed once and the full ``[size, size, 400]`` tensor is never stored.

Selection of the D-th smallest: ``select`` (:data:`SELECT_OPTIONS`); ``"auto"`` (``DEFAULT_SELECT``) is
``"pallas"`` where lowered for a CUDA GPU (exact: Pallas kernels over per-tile candidate lists,
:mod:`~jaxterrain.generators.worley_pallas`) and ``"bracket"`` elsewhere (an exact coarse grid brackets every pixel,
bisection, a snap to a point distance: ``|error| < TOLERANCE`` = 1e-3 px), so a CPU map can differ from a GPU map of
the same genome by less than that; on one backend a genome always gives the same map, bit for bit. Also ``"sort"``
(the exact reference), ``"bisect"`` (exact) and ``"tiled"`` ("bracket" over candidate lists). Each method's design,
the XLA loop behaviours it defeats, the cost model and the exactness of the candidate lists: ``docs/worley.md``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain.generators import worley_pallas
from jaxterrain.generators.base import Generator, spec, vector_generator
from jaxterrain.generators.registry import register

__all__ = ["MAX_POINTS", "MAX_INDEX", "SELECT_OPTIONS", "DEFAULT_SELECT", "TOLERANCE", "WORLEY_SPEC",
           "feature_points", "bracket_iterations", "worley_distance", "render_worley", "repair", "check_d", "worley"]

MAX_POINTS = 400
MAX_INDEX = 100
SELECT_OPTIONS = ("auto", "pallas", "bracket", "tiled", "bisect", "sort")
DEFAULT_SELECT = "auto"  # "pallas" on a GPU (exact; 25x "bracket" on an H200), "bracket" elsewhere
_ROW_BLOCK = 16  # rows of the map per sort call in the "sort" method (bounds memory: block x size x 400)
_SORT_OP = "sort"  # or "top_k" (lax.top_k, k = 101): same result, ~6 % slower on an H100
_COARSE_STEP = 8  # "bracket": pixel spacing of the exact coarse grid
TOLERANCE = 1e-3  # "bracket": bound (pixels) on |F_D error|, reached only where two distances are that close
_MARGIN = 2e-3  # "bracket": pixels added on both sides of the Lipschitz bracket (covers float rounding, ~1e-4 px)
_POINTS_AXIS = "minor"  # layout of the count reductions: points on the minor ([H, W, 400]) or major axis

WORLEY_SPEC = spec(
    ("seed", 0.0, 100.0, True),
    ("N", 2.0, float(MAX_POINTS), True),
    ("D", 0.0, float(MAX_INDEX), True),
)


def feature_points(seed: jax.Array, size: int) -> jax.Array:
    """The 400 candidate feature points of a seed, ``[400, 2]`` float32 (x = column, y = row) in [0, size)."""
    key = jax.random.PRNGKey(jnp.round(seed).astype(jnp.int32))
    return jax.random.uniform(key, (MAX_POINTS, 2), jnp.float32) * size


def _separable_d2(genome: jax.Array, size: int):
    """Row and column terms of the squared distances, ``[size, 400]`` each; masked points at +inf."""
    genome = jnp.asarray(genome, jnp.float32)
    seed, n_points = genome[0], jnp.round(genome[1])
    pts = feature_points(seed, size)
    pix = jnp.arange(size, dtype=jnp.float32)
    valid = jnp.arange(MAX_POINTS) < n_points
    dx2 = jnp.where(valid[None, :], jnp.square(pix[:, None] - pts[None, :, 0]), jnp.inf)  # [W, 400]
    dy2 = jnp.square(pix[:, None] - pts[None, :, 1])  # [H, 400]
    return dy2, dx2


# --- Fused per-pixel reductions over the points -------------------------------------------------------------------
# ``rows`` / ``cols`` are the separable terms in the layout of ``_POINTS_AXIS`` (see ``_layout``). Each function is
# one XLA reduction whose input, the [H, W, 400] (x batch) tensor of squared distances, is computed inside the
# fusion and never stored.


_POINT_GROUPS = (16, 25)  # 400 points as [16, 25]: every reduced dim <= 32, so XLA:CPU's TreeReductionRewriter
# (which splits any longer reduced dim into reduce-window + reduce, materialising the fused input) leaves it
# alone; XLA:GPU regroups adjacent reduced dims into one 400-long reduction.


def _layout(dy2: jax.Array, dx2: jax.Array):
    """Separable terms [H, 400], [W, 400] -> the reduction layout: [H, 16, 25] ("minor") or [16, 25, H] ("major").

    (With ``_POINT_GROUPS = (400,)``: [H, 400] or [400, H].)
    """
    if _POINTS_AXIS == "minor":
        return dy2.reshape(dy2.shape[0], *_POINT_GROUPS), dx2.reshape(dx2.shape[0], *_POINT_GROUPS)
    return dy2.T.reshape(*_POINT_GROUPS, dy2.shape[0]), dx2.T.reshape(*_POINT_GROUPS, dx2.shape[0])


def _d2(rows: jax.Array, cols: jax.Array):
    """The [H, W, 16, 25] (or [16, 25, H, W]) squared distances, the reduced axes and a [H, W] -> broadcast map."""
    g = len(_POINT_GROUPS)
    if _POINTS_AXIS == "minor":
        return rows[:, None] + cols[None, :], tuple(range(-g, 0)), lambda t: t.reshape(t.shape + (1,) * g)
    return rows[..., :, None] + cols[..., None, :], tuple(range(g)), lambda t: t.reshape((1,) * g + t.shape)


def _count_less(rows: jax.Array, cols: jax.Array, t2: jax.Array) -> jax.Array:
    """``count(d2 < t2)`` per pixel, ``[H, W]`` int32."""
    d2, axis, expand = _d2(rows, cols)
    return jnp.sum(d2 < expand(t2), axis=axis, dtype=jnp.int32)


def _min_at_least(rows: jax.Array, cols: jax.Array, t2: jax.Array) -> jax.Array:
    """``min{d2 : d2 >= t2}`` per pixel, ``[H, W]`` float32 (+inf if none)."""
    d2, axis, expand = _d2(rows, cols)
    # As an int32 min over the bit patterns (non-negative floats order like them): same value, and a plain XLA
    # reduction on every backend (XLA:CPU hands a float min to a YNNPACK custom call on a materialised input).
    bits = jax.lax.bitcast_convert_type(d2, jnp.int32)
    big = jnp.int32(0x7F800000)  # +inf
    return jax.lax.bitcast_convert_type(jnp.min(jnp.where(d2 >= expand(t2), bits, big), axis=axis), jnp.float32)


def _tie(arrays, carry):
    """``arrays`` unchanged, but made to depend on the loop ``carry`` (an optimisation barrier).

    Without it XLA's while-loop-invariant code motion hoists the loop-invariant broadcast add
    ``rows[:, None, :] + cols[None, :, :]`` out of the loop, i.e. materialises the [B, H, W, 400] float32 tensor
    once and re-reads it on every iteration (memory-bound; this made the original "bisect" ~120 maps/s).
    """
    return jax.lax.optimization_barrier((arrays, carry))[0]


def _kth_bisect(dy2: jax.Array, dx2: jax.Array, d: jax.Array) -> jax.Array:
    """Exact D-th smallest of ``dy2[i, None, :] + dx2[None, j, :]`` per pixel by a 31-bit greedy search. [H, W]."""
    h, w = dy2.shape[0], dx2.shape[0]
    d = d.astype(jnp.int32)
    rows0, cols0 = _layout(dy2, dx2)

    def body(b, bits):
        rows, cols = _tie((rows0, cols0), bits)
        cand = bits | jnp.left_shift(jnp.int32(1), 30 - b)
        t = jax.lax.bitcast_convert_type(cand, jnp.float32)
        return jnp.where(_count_less(rows, cols, t) <= d, cand, bits)

    bits = jax.lax.fori_loop(0, 31, body, jnp.zeros((h, w), jnp.int32))
    # A zero distance comes out as a subnormal where the backend flushes subnormals to zero in compares (CPU);
    # squared distances are 0 or > 1e-12, so every subnormal result is a 0.
    bits = jnp.where(bits < 0x00800000, 0, bits)
    return jax.lax.bitcast_convert_type(bits, jnp.float32)


def _grid(n: int, step: int) -> np.ndarray:
    """Coarse sample positions along one axis: 0, step, 2 step, ... and the last pixel n - 1."""
    return np.unique(np.append(np.arange(0, n, step), n - 1))


def _corner_setup(n: int, step: int):
    """Static per-pixel coarse-cell indices and offsets along one axis: (grid, k [n], off0 [n], off1 [n])."""
    g = _grid(n, step)
    k = np.minimum(np.searchsorted(g, np.arange(n), side="right") - 1, len(g) - 2)
    pix = np.arange(n)
    return g, k, (pix - g[k]).astype(np.float32), (g[k + 1] - pix).astype(np.float32)


def _iterations(ay, by, ax, bx, tol: float) -> int:
    """``ceil(log2(max bracket width / tol))``: the width is <= 2 x (distance to the nearest coarse corner)."""
    r = np.hypot(np.minimum(ay, by).max(), np.minimum(ax, bx).max())
    return max(int(np.ceil(np.log2((2 * r + 2 * _MARGIN) / tol))), 0)


def bracket_iterations(size: int = 256, step: int = _COARSE_STEP, tol: float = TOLERANCE) -> int:
    """Bisection steps of the "bracket" method at ``size`` x ``size`` (14 at step 8 and tol 1e-3 px)."""
    _, _, ay, by = _corner_setup(size, step)
    return _iterations(ay, by, ay, by, tol)


def _bracket_bounds(dy2: jax.Array, dx2: jax.Array, d: jax.Array, step: int = _COARSE_STEP,
                    tol: float = TOLERANCE, coarse=None):
    """Steps 1-2 of "bracket": per-pixel ``L <= F_D <= U`` (pixels, ``[H, W]`` each, widened by ``_MARGIN``) from
    the exact ``F_D`` on the coarse grid, and the bisection steps to width ``tol``; None if the map is too small."""
    h, w = dy2.shape[0], dx2.shape[0]
    gy, ky, ay, by = _corner_setup(h, step)
    gx, kx, ax, bx = _corner_setup(w, step)
    if len(gy) < 2 or len(gx) < 2:
        return None
    fc = jnp.sqrt((coarse or _kth_bisect)(dy2[gy], dx2[gx], d))  # [ny, nx] exact coarse F_D
    lo = jnp.full((h, w), -jnp.inf)
    hi = jnp.full((h, w), jnp.inf)
    for cy, oy in ((0, ay), (1, by)):
        for cx, ox in ((0, ax), (1, bx)):
            f = fc[ky + cy][:, kx + cx]  # static gathers, [H, W]
            r = jnp.asarray(np.sqrt(oy[:, None] ** 2 + ox[None, :] ** 2))
            lo = jnp.maximum(lo, f - r)
            hi = jnp.minimum(hi, f + r)
    return jnp.maximum(lo - _MARGIN, 0.0), hi + _MARGIN, _iterations(ay, by, ax, bx, tol)


def _bisect_and_snap(terms, count_less, min_at_least, lo, hi, d, n_iter: int):
    """Steps 3-4 of "bracket": ``n_iter`` bisections of ``[lo, hi]`` keeping ``count(d2 < lo^2) <= d``, then the
    snap ``min{d2 : d2 >= lo^2}``, as ``n_iter + 1`` trips of one loop. ``terms`` (a pytree) is what
    ``count_less(terms, t2)`` and ``min_at_least(terms, t2)`` reduce over; it is tied to the carry (``_tie``)."""
    snap_scale = 1.0 - 2.0 ** -20

    def body(k, state):
        tied = _tie(terms, state)

        def bisect(state):
            lo, hi = state
            mid = 0.5 * (lo + hi)
            below = count_less(tied, mid * mid) <= d  # the answer is >= mid^2
            return jnp.where(below, mid, lo), jnp.where(below, hi, mid)

        def snap(state):
            # The threshold is lowered by ~8 ulp: XLA may round ``mid * mid`` differently in the count fusion and
            # here (seen on CPU); without the slack a ``lo`` that converged onto F_D itself would skip it.
            lo, hi = state
            return min_at_least(tied, (lo * lo) * snap_scale), hi

        return jax.lax.cond(k < n_iter, bisect, snap, state)

    # The snap is the last trip of the same loop (a cond on the unbatched trip index, so it stays a cond under
    # vmap): inside the loop the terms are loop-carried buffers; outside it XLA fuses their whole producer
    # (PRNG bits -> points -> squares) into the [H, W, 400] reduction, or materialises it (seen on CPU).
    d2_kth, _ = jax.lax.fori_loop(0, n_iter + 1, body, (lo, hi))
    return d2_kth


def _kth_bracket(dy2: jax.Array, dx2: jax.Array, d: jax.Array, step: int = _COARSE_STEP,
                 tol: float = TOLERANCE) -> jax.Array:
    """D-th smallest per pixel from an exact coarse grid, a Lipschitz bracket, bisection and a snap. [H, W].

    1. Exact ``F_D`` (``_kth_bisect``) on the coarse grid (every ``step``-th pixel and the last one).
    2. ``F_D`` is 1-Lipschitz in the pixel position, so each pixel p gets ``L = max_c (F_c - |p - c|)`` and
       ``U = min_c (F_c + |p - c|)`` over the 4 corners c of its coarse cell (width <= 2 x 4 sqrt 2 px at step 8;
       ~3 px typical), widened by ``_MARGIN``.
    3. Bisection on the distance ``t`` in [L, U] keeping ``count(d2 < L^2) <= D < count(d2 < U^2)``, a fixed
       ``bracket_iterations`` steps of one fused count each, to width < ``tol``.
    4. Snap: ``min{d2 : d2 >= L^2}`` (one fused min). It is the exact answer unless another, different distance
       lies in [L, F_D) (within ``tol`` of it); in that case it is such a distance, so the error is < ``tol``.
    """
    bounds = _bracket_bounds(dy2, dx2, d, step, tol)
    if bounds is None:
        return _kth_bisect(dy2, dx2, d)
    return _bisect_all_points(dy2, dx2, *bounds, d)


def _bisect_all_points(dy2: jax.Array, dx2: jax.Array, lo: jax.Array, hi: jax.Array, n_iter: int, d: jax.Array):
    """Steps 3-4 of "bracket" over all 400 points, from the bounds of :func:`_bracket_bounds`. [H, W]."""
    return _bisect_and_snap(_layout(dy2, dx2), lambda t, t2: _count_less(*t, t2),
                            lambda t, t2: _min_at_least(*t, t2), lo, hi, d.astype(jnp.int32), n_iter)


_TILE = 8  # "tiled": pixels per tile side (the map side must be a multiple; otherwise "bracket" is used)
_CAP_GROUPS = (3, 32)  # "tiled": 96 candidate slots per tile, as [3, 32] (reduced dims <= 32, see _POINT_GROUPS).
# The most candidates in one 8 x 8 tile at 256 x 256: 83, over all 101 seeds x every D at N = 400 (10,201
# genomes; 82 at D = 100, 14 at D = 0), and 82 over all seeds x N = 100, 120, ..., 400 x D = N / 4, 3N / 16, N / 8
# (falling with N); 72 over 400 random genomes. More than 96 sends the map (and its batch) through "bracket" once.


def _tile_extremes(dy2: jax.Array, dx2: jax.Array, lo: jax.Array, hi: jax.Array, tile: int):
    """Per tile row / column the min and max of the separable terms (``rmin``, ``rmax`` [ty, P]; ``cmin``,
    ``cmax`` [tx, P]) and per tile the squared bracket ``lt2``, ``ut2`` [ty, tx] (min L^2 and max U^2)."""
    ty, tx, p = dy2.shape[0] // tile, dx2.shape[0] // tile, dy2.shape[-1]
    r = dy2.reshape(ty, tile, p)
    c = dx2.reshape(tx, tile, p)
    lt = lo.reshape(ty, tile, tx, tile).min(axis=(1, 3))
    ut = hi.reshape(ty, tile, tx, tile).max(axis=(1, 3))
    return r.min(axis=1), r.max(axis=1), c.min(axis=1), c.max(axis=1), lt * lt, ut * ut


def _tile_lists(dy2: jax.Array, dx2: jax.Array, lo: jax.Array, hi: jax.Array, tile: int, cap: int,
                pallas: bool = False):
    """Per-tile candidate lists of the "tiled" method, as point indices.

    A tile's bracket is ``[Lt, Ut]`` = [min L, max U] over its pixels. A point whose squared distance to every
    pixel of the tile is < ``Lt^2`` is nearer than ``F_D`` everywhere in it ("inside", counted); one whose squared
    distance to every pixel is > ``Ut^2`` is farther ("outside", dropped); the others are the candidates. The
    extremes over the tile are exact: ``max_(i, j) (dy2[i] + dx2[j]) = max dy2 + max dx2`` in float too, since a
    float sum is monotonic in each term.

    Returns ``idx [ty, tx, cap]`` int32 (candidate ``k`` of a tile in slot ``k``, in point order; 0 in unused
    slots), ``n_cand [ty, tx]`` int32 (may exceed ``cap``), ``inside [ty, tx]`` int32 and ``overflow`` (a scalar
    bool: some tile had more than ``cap`` candidates, so the lists are incomplete). With ``pallas`` the lists are
    built by a kernel (``worley_pallas.tile_lists``; unused slots then hold anything).
    """
    ext = _tile_extremes(dy2, dx2, lo, hi, tile)
    if pallas:
        idx, n_cand, inside = worley_pallas.tile_lists(*ext, cap)
        return idx, n_cand, inside, jnp.any(n_cand > cap)
    rmin, rmax, cmin, cmax, lt2, ut2 = ext
    p, (ty, tx) = dy2.shape[-1], lt2.shape
    dmin2 = rmin[:, None, :] + cmin[None, :, :]  # [ty, tx, P]
    dmax2 = rmax[:, None, :] + cmax[None, :, :]
    inside = dmax2 < lt2[..., None]
    cand = (dmin2 <= ut2[..., None]) & ~inside  # a masked point has dmin2 = inf: never a candidate
    n_cand = jnp.sum(cand, axis=-1, dtype=jnp.int32)
    # Compaction without a sort: candidate number k of a tile goes to slot k (slots past ``cap`` are dropped).
    slot = jnp.where(cand, jnp.cumsum(cand, axis=-1, dtype=jnp.int32) - 1, cap)
    idx = jnp.zeros((ty, tx, cap), jnp.int32).at[
        jnp.arange(ty)[:, None, None], jnp.arange(tx)[None, :, None], slot].set(
        jnp.broadcast_to(jnp.arange(p, dtype=jnp.int32), slot.shape), mode="drop")  # [ty, tx, cap]
    return idx, n_cand, jnp.sum(inside, axis=-1, dtype=jnp.int32), jnp.any(n_cand > cap)


def _tile_terms(dy2: jax.Array, dx2: jax.Array, idx: jax.Array, n_cand: jax.Array, tile: int):
    """The separable terms of each tile's candidates: ``rows``, ``cols`` ``[ty, tx, tile, cap]`` (+inf in unused
    slots), gathered from ``dy2`` [H, P], ``dx2`` [W, P] by the lists of :func:`_tile_lists`."""
    ty, tx, cap = idx.shape
    r = dy2.reshape(ty, tile, -1)
    c = dx2.reshape(tx, tile, -1)
    valid = (jnp.arange(cap) < n_cand[..., None])[:, :, None, :]
    iy = jnp.arange(ty)[:, None, None, None]
    ix = jnp.arange(tx)[None, :, None, None]
    k = jnp.arange(tile)[None, None, :, None]
    rows = jnp.where(valid, r[iy, k, idx[:, :, None, :]], jnp.inf)
    cols = jnp.where(valid, c[ix, k, idx[:, :, None, :]], jnp.inf)
    return rows, cols


def _tile_d2(terms):
    """The [ty, tx, tile, tile, *_CAP_GROUPS] squared distances of the candidates (inside a fusion), the reduced
    axes and a [ty, tx, tile, tile] -> broadcast map."""
    rows, cols = terms
    g = rows.shape[:3] + _CAP_GROUPS
    n = len(_CAP_GROUPS)
    return (rows.reshape(g)[:, :, :, None] + cols.reshape(g)[:, :, None, :], tuple(range(-n, 0)),
            lambda t: t.reshape(t.shape + (1,) * n))


def _tile_count_less(terms, t2):
    d2, axis, expand = _tile_d2(terms)
    return jnp.sum(d2 < expand(t2), axis=axis, dtype=jnp.int32)


def _tile_min_at_least(terms, t2):
    d2, axis, expand = _tile_d2(terms)
    bits = jax.lax.bitcast_convert_type(d2, jnp.int32)
    big = jnp.int32(0x7F800000)  # +inf
    return jax.lax.bitcast_convert_type(jnp.min(jnp.where(d2 >= expand(t2), bits, big), axis=axis), jnp.float32)


def _tiled_bounds(dy2: jax.Array, dx2: jax.Array, d: jax.Array, step: int, tol: float, tile: int, pallas: bool):
    """:func:`_bracket_bounds`, with the exact coarse grid by the Pallas kernel over all N points when ``pallas``
    (the same values as "bisect")."""
    coarse = None
    if pallas:
        n_points = jnp.sum(jnp.isfinite(dx2[0]), dtype=jnp.int32)
        bound = float(dy2.shape[0] + dx2.shape[0])  # pixels, beyond any distance in the map
        coarse = lambda y, x, d: worley_pallas.kth_all_points(y, x, n_points, d, bound, tile)  # noqa: E731
    return _bracket_bounds(dy2, dx2, d, step, tol, coarse)


def _kth_tiled(dy2: jax.Array, dx2: jax.Array, d: jax.Array, step: int = _COARSE_STEP, tol: float = TOLERANCE,
               tile: int = _TILE, pallas: bool = False) -> jax.Array:
    """"bracket" with per-tile candidate lists: the same bounds, bisection and snap, over at most ``cap`` points
    (``cap`` = 96, the product of ``_CAP_GROUPS``).

    Steps 1-2 of "bracket" give every pixel ``[L, U]``. Each ``tile x tile`` tile then keeps only the points that
    can be its pixels' D-th nearest (:func:`_tile_lists`), and the D-th smallest over all points is the
    ``(D - inside)``-th over the candidates, exactly; steps 3-4 run over ``cap`` candidates instead of 400 (4.2x
    fewer point-pixel pairs at the defaults), so the result equals "bracket"'s up to float rounding. With
    ``pallas`` the coarse grid, the lists and steps 3-4 are Pallas kernels that loop over each tile's own
    candidates only, and the result is exact (``worley_pallas``). If a tile has more than ``cap`` candidates the
    map's steps 3-4 are redone over all points (by "bracket", or by the kernel with ``pallas``), from the same
    bounds, in a ``while_loop`` that runs 0 or 1 times:
    under ``vmap`` it runs once for the whole batch if any map overflowed, and not at all otherwise.
    """
    h, w = dy2.shape[0], dx2.shape[0]
    cap = int(np.prod(_CAP_GROUPS))
    bounds = _tiled_bounds(dy2, dx2, d, step, tol, tile, pallas)
    if bounds is None or h % tile or w % tile:
        return _kth_bracket(dy2, dx2, d, step, tol)
    lo, hi, n_iter = bounds
    d = d.astype(jnp.int32)
    if pallas and worley_pallas.FUSED:
        d2, n_cand = worley_pallas.select_kth_fused(dy2, dx2, _tile_extremes(dy2, dx2, lo, hi, tile), d, lo, hi,
                                                     tile, cap)
        overflow = jnp.any(n_cand > cap)
    elif pallas:
        idx, n_cand, inside, overflow = _tile_lists(dy2, dx2, lo, hi, tile, cap, pallas)
        d2 = worley_pallas.select_kth(dy2, dx2, idx, jnp.minimum(n_cand, cap), d - inside, lo, hi, tile)
    else:
        idx, n_cand, inside, overflow = _tile_lists(dy2, dx2, lo, hi, tile, cap)
        rank = d - inside  # the target rank among a tile's candidates (>= 0: inside < D + 1)
        ty, tx = h // tile, w // tile

        def tiles(x):  # [H, W] -> [ty, tx, tile, tile]
            return x.reshape(ty, tile, tx, tile).transpose(0, 2, 1, 3)

        terms = _tile_terms(dy2, dx2, idx, n_cand, tile)
        d2 = _bisect_and_snap(terms, _tile_count_less, _tile_min_at_least, tiles(lo), tiles(hi),
                              rank[:, :, None, None], n_iter)
        d2 = d2.transpose(0, 2, 1, 3).reshape(h, w)

    def redo(carry):  # the inputs are tied to the carry, or XLA hoists the whole fallback out of the loop
        dy2_, dx2_, lo_, hi_ = _tie((dy2, dx2, lo, hi), carry)
        if not pallas:
            return False, _bisect_all_points(dy2_, dx2_, lo_, hi_, n_iter, d)
        # Every point a candidate of every tile (the masked ones are at +inf).
        return False, worley_pallas.select_all_points(dy2_, dx2_, dy2.shape[-1], d, lo_, hi_, tile)

    return jax.lax.while_loop(lambda carry: carry[0], redo, (overflow, d2))[1]


def _kth_pallas(dy2: jax.Array, dx2: jax.Array, d: jax.Array, **kw) -> jax.Array:
    """"tiled" with steps 3-4 as a Pallas kernel (Triton on a GPU; Pallas's interpreter elsewhere, slow)."""
    return _kth_tiled(dy2, dx2, d, pallas=True, **kw)


def _kth_auto(dy2: jax.Array, dx2: jax.Array, d: jax.Array) -> jax.Array:
    """"pallas" where the computation is lowered for a CUDA GPU, "bracket" on any other platform (Pallas only
    interprets there: 2.2 maps/s against 7.0 on the 2-core CPU). Decided at lowering, not by the default backend."""
    return jax.lax.platform_dependent(dy2, dx2, d, cuda=_kth_pallas, default=_kth_bracket)


def _kth_sort(dy2: jax.Array, dx2: jax.Array, d: jax.Array) -> jax.Array:
    """Exact D-th smallest per pixel by sorting blocks of ``_ROW_BLOCK`` rows (``_SORT_OP``). [H, W]."""
    h, w = dy2.shape[0], dx2.shape[0]
    block = min(_ROW_BLOCK, h)
    pad = (-h) % block
    dy2p = jnp.pad(dy2, ((0, pad), (0, 0))).reshape(-1, block, dy2.shape[1])
    onehot = jnp.arange(MAX_INDEX + 1) == d.astype(jnp.int32)

    def rows(dy2_block):
        d2 = dy2_block[:, None, :] + dx2[None, :, :]  # [block, W, 400]
        if _SORT_OP == "sort":
            kth = jnp.sort(d2, axis=-1)[..., : MAX_INDEX + 1]
        else:
            kth = -jax.lax.top_k(-d2, MAX_INDEX + 1)[0]  # [block, W, 101], ascending
        return jnp.sum(jnp.where(onehot, kth, 0.0), axis=-1)

    return jax.lax.map(rows, dy2p).reshape(-1, w)[:h]


_KTH = {"auto": _kth_auto, "pallas": _kth_pallas, "bracket": _kth_bracket, "tiled": _kth_tiled, "bisect": _kth_bisect,
        "sort": _kth_sort}


def worley_distance(genome: jax.Array, size: int = 256, select: str = DEFAULT_SELECT) -> jax.Array:
    """Unnormalised ``F_D`` map, ``[size, size]`` float32 in pixels (distance to the D-th nearest feature point)."""
    genome = jnp.asarray(genome, jnp.float32)
    dy2, dx2 = _separable_d2(genome, size)
    d = jnp.round(genome[2])
    return jnp.sqrt(_KTH[select](dy2, dx2, d))


def render_worley(genome: jax.Array, size: int = 256, select: str = DEFAULT_SELECT) -> jax.Array:
    """One genome ``[3]`` -> heightmap ``[size, size]`` float32 in [0, 1] (divided by its own max). Unchecked."""
    dist = worley_distance(genome, size, select)
    top = jnp.max(dist)
    # XLA may divide as a multiply by the reciprocal; the farthest pixel is set to exactly 1.
    return jnp.where(dist >= top, 1.0, dist / jnp.maximum(top, 1e-12))


def repair(genomes: jax.Array) -> jax.Array:
    """Clamp D to ``floor(N / 4)``. ``genomes`` [B, 3] (or [3])."""
    n = genomes[..., 1]
    d = jnp.minimum(genomes[..., 2], jnp.floor(n / 4.0))
    return genomes.at[..., 2].set(d)


def check_d(genomes: np.ndarray) -> None:
    """Host check of the constraint ``D <= floor(N / 4)`` on concrete genomes ``[B, 3]`` float64."""
    limit = np.floor(genomes[:, 1] / 4.0)
    bad = genomes[:, 2] > limit
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(
            f"worley: gene 'D' of genome {i} is {genomes[i, 2]:g}; it must be in [0, floor(N / 4)] = "
            f"[0, {limit[i]:g}] for N = {genomes[i, 1]:g}"
        )


@register("worley")
def worley(size: int = 256, select: str = DEFAULT_SELECT) -> Generator:
    """Worley noise generator producing ``[B, size, size]`` float32 maps in [0, 1]; see the module docstring.

    ``select``: how the D-th smallest distance is found, see the module docstring: ``"auto"`` (default:
    ``"pallas"`` on a GPU, ``"bracket"`` elsewhere), ``"pallas"`` (exact; per-tile candidate lists in a Pallas
    kernel), ``"bracket"`` (|error| < ``TOLERANCE`` = 1e-3 px), ``"tiled"`` (the same values as "bracket" over
    per-tile candidate lists), ``"sort"`` (exact, the reference) or ``"bisect"`` (exact).
    """
    size = int(size)
    if size < 1:
        raise ValueError(f"worley: size must be a positive integer; got {size}")
    if select not in SELECT_OPTIONS:
        raise ValueError(f"worley: select must be one of {SELECT_OPTIONS}; got {select!r}")

    def render_one(genome: jax.Array) -> jax.Array:
        return render_worley(genome, size, select)

    return vector_generator("worley", WORLEY_SPEC, render_one, size, repair=repair, extra_check=check_d)
