"""Worley's ``select="pallas"`` (see ``worley.py``): Pallas kernels over per-tile candidate lists.

* :func:`select_kth`, the selection. One program per ``tile x tile`` tile of one map holds the tile's pixels
  in registers and loops over that tile's own candidates only: the loop bound is the tile's candidate count, not
  the list's capacity, so a tile with 12 candidates costs 12 iterations even when another has 80 (the XLA
  "tiled" pays the capacity, 96, everywhere). It counts ``c_lo = count(d2 < L^2)`` and ``c_hi = count(d2 < U^2)``,
  bisects the whole tile until no pixel has more than ``TOP_K`` candidates in its bracket, then keeps each pixel's
  ``TOP_K`` smallest ``d2 >= L^2`` in sorted registers and returns element ``rank - c_lo``: one of the points'
  squared distances itself, computed as ``dy2 + dx2`` from the same separable terms as "sort", so the two agree
  bit for bit.
* :func:`select_all_points`, the same kernel with every point a candidate of every tile (the overflow fallback),
  and :func:`kth_all_points`, that with the bracket [0, bound]: the exact coarse grid.
* :func:`tile_lists`, the candidate lists (the same values as ``worley._tile_lists``'s XLA version).
* :func:`select_kth_fused` (the default, ``FUSED``): lists and selection in one program, the list written to
  global memory and read back after a barrier.

On a CUDA GPU the kernels are lowered through Triton; elsewhere they run in Pallas's interpreter (slow: for tests).
The choice is made when the computation is lowered (``lax.platform_dependent``), not by the default backend.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax.experimental import pallas as pl

__all__ = ["MAX_ITER", "TOP_K", "NUM_WARPS", "NUM_STAGES", "FUSED", "select_kth", "select_all_points",
           "kth_all_points", "LIST_CHUNK", "tile_lists", "select_kth_fused"]

MAX_ITER = 40  # bisections at most; a float interval stops shrinking after ~30
TOP_K = 4  # bisect until at most this many candidates lie in a pixel's bracket, then keep their sorted values
NUM_WARPS = 1  # a 8 x 8 tile is 64 pixels: 2 per thread of one warp
NUM_STAGES = 1  # Triton software pipelining of the candidate loops
FUSED = True  # lists and selection in one kernel (select_kth_fused): 1.04-1.07x two kernels on an H200


def _insert(top, v):
    """Insert ``v`` into the ascending tuple ``top`` (elementwise), dropping the largest."""
    out = [jnp.minimum(top[0], v)]
    for i in range(1, len(top)):
        out.append(jnp.minimum(top[i], jnp.maximum(top[i - 1], v)))
    return tuple(out)


def _select(d2_of, n, rank, lo, hi, *, max_iter: int, top_k: int):
    """The selection of one tile: ``rank``-th smallest of ``d2_of(k)``, ``k < n``, per pixel, exactly. ``lo``,
    ``hi`` [tile, tile]: each pixel's bracket in pixels."""
    zeros = jnp.zeros(lo.shape, jnp.int32)

    def count_less(t2):
        return jax.lax.fori_loop(0, n, lambda k, c: c + (d2_of(k) < t2).astype(jnp.int32), zeros)

    # The bracket in squared pixels, with the counts at both ends: c_lo = count(d2 < lo2) <= rank < c_hi.
    lo2, hi2 = lo * lo, hi * hi

    def count_both(k, c):
        d2 = d2_of(k)
        return c[0] + (d2 < lo2).astype(jnp.int32), c[1] + (d2 < hi2).astype(jnp.int32)

    c_lo, c_hi = jax.lax.fori_loop(0, n, count_both, (zeros, zeros))

    # Bisection, for the whole tile, until no pixel has more than top_k candidates in [lo2, hi2).
    def wide(state):
        i, _, _, _, _, c_lo, c_hi = state
        return (i < max_iter) & (jnp.max(c_hi - c_lo) > top_k)

    def bisect(state):
        i, lo, hi, lo2, hi2, c_lo, c_hi = state
        mid = 0.5 * (lo + hi)
        t2 = mid * mid
        c = count_less(t2)
        below = c <= rank  # the answer is >= t2
        return (i + 1, jnp.where(below, mid, lo), jnp.where(below, hi, mid), jnp.where(below, t2, lo2),
                jnp.where(below, hi2, t2), jnp.where(below, c, c_lo), jnp.where(below, c_hi, c))

    _, _, _, lo2, _, c_lo, _ = jax.lax.while_loop(wide, bisect, (0, lo, hi, lo2, hi2, c_lo, c_hi))

    # The top_k smallest d2 >= lo2, sorted: exactly c_lo values are below lo2, so the answer is element
    # rank - c_lo (< top_k once the bracket holds at most top_k candidates; clamped in the limit of MAX_ITER,
    # where the bracket is a float or two wide and its values are equal).
    def keep_smallest(k, top):
        d2 = d2_of(k)
        return _insert(top, jnp.where(d2 >= lo2, d2, jnp.inf))

    top = jax.lax.fori_loop(0, n, keep_smallest, (jnp.full(lo.shape, jnp.inf, jnp.float32),) * top_k)
    r = jnp.minimum(rank - c_lo, top_k - 1)
    out = top[0]
    for i in range(1, top_k):
        out = jnp.where(r == i, top[i], out)
    return out


def _tile_view(t, n_tx: int, tile: int):
    """Program ``t``'s tile: its row and column slices of the map."""
    return pl.ds((t // n_tx) * tile, tile), pl.ds((t % n_tx) * tile, tile)


def _candidates(dy2t_ref, dx2t_ref, idx_ref, t, rs, cs):
    """``d2_of(k)``: the [tile, tile] squared distances of tile ``t``'s candidate ``k`` to its pixels."""

    def d2_of(k):
        p = idx_ref[t, k]
        return dy2t_ref[p, rs][:, None] + dx2t_ref[p, cs][None, :]

    return d2_of


def _kernel(dy2t_ref, dx2t_ref, idx_ref, n_ref, rank_ref, lo_ref, hi_ref, out_ref, *, tile: int, n_tx: int,
            **select_kw):
    t = pl.program_id(0)
    rs, cs = _tile_view(t, n_tx, tile)
    out_ref[rs, cs] = _select(_candidates(dy2t_ref, dx2t_ref, idx_ref, t, rs, cs), n_ref[t], rank_ref[t],
                              lo_ref[rs, cs], hi_ref[rs, cs], **select_kw)


def _call(kernel, out_shape, name: str, grid: int, num_warps: int, *args, pass_interpret: bool = False):
    """``pallas_call`` lowered through Triton on a CUDA device and run by Pallas's interpreter on any other,
    chosen when the computation is lowered for its platform (``lax.platform_dependent``), so one jitted function
    works on both, whatever the default backend. ``pass_interpret``: call ``kernel`` with ``interpret=``."""

    def call(interpret: bool):
        k = functools.partial(kernel, interpret=interpret) if pass_interpret else kernel
        params = None
        if not interpret:
            from jax.experimental.pallas import triton as plgpu

            params = plgpu.CompilerParams(num_warps=num_warps, num_stages=NUM_STAGES)
        return pl.pallas_call(k, out_shape=out_shape, grid=(grid,), interpret=interpret,
                              compiler_params=params, name=name)

    return jax.lax.platform_dependent(*args, cuda=call(False), default=call(True))


def select_kth(dy2: jax.Array, dx2: jax.Array, idx: jax.Array, n_cand: jax.Array, rank: jax.Array,
               lo: jax.Array, hi: jax.Array, tile: int, max_iter: int = MAX_ITER) -> jax.Array:
    """Squared ``F_D`` per pixel, ``[H, W]`` float32, over per-tile candidate lists (one map; vmap for a batch).

    ``dy2`` [H, P], ``dx2`` [W, P]: the separable squared-distance terms; ``idx`` [ty, tx, cap] int32: candidate
    point indices of each tile (the first ``n_cand`` are used); ``n_cand``, ``rank`` [ty, tx] int32: candidates and
    the target rank among them; ``lo``, ``hi`` [H, W]: the per-pixel bracket in pixels (``L <= F_D <= U``).
    """
    h, w = dy2.shape[0], dx2.shape[0]
    ty, tx, cap = idx.shape
    kernel = functools.partial(_kernel, tile=tile, n_tx=tx, max_iter=max_iter, top_k=TOP_K)
    out_shape = jax.ShapeDtypeStruct((h, w), jnp.float32)
    return _call(kernel, out_shape, "worley_tiles", ty * tx, NUM_WARPS, dy2.T, dx2.T, idx.reshape(ty * tx, cap),
                 n_cand.reshape(-1), rank.reshape(-1).astype(jnp.int32), lo.astype(jnp.float32),
                 hi.astype(jnp.float32))


def select_all_points(dy2: jax.Array, dx2: jax.Array, n_points: jax.Array, d: jax.Array, lo: jax.Array,
                      hi: jax.Array, tile: int) -> jax.Array:
    """:func:`select_kth` with every tile's list the first ``n_points`` points (``rank`` = ``d``): exact for any
    bracket ``lo <= F_D <= hi``. ``H`` and ``W`` must be multiples of ``tile``."""
    ty, tx, p = dy2.shape[0] // tile, dx2.shape[0] // tile, dy2.shape[1]
    every = jnp.broadcast_to(jnp.arange(p, dtype=jnp.int32), (ty, tx, p))
    return select_kth(dy2, dx2, every, jnp.full((ty, tx), n_points, jnp.int32), jnp.full((ty, tx), d, jnp.int32),
                      lo, hi, tile)


def kth_all_points(dy2: jax.Array, dx2: jax.Array, n_points: jax.Array, d: jax.Array, bound: float,
                   tile: int) -> jax.Array:
    """Exact D-th smallest squared distance per pixel over the first ``n_points`` points, ``[H, W]`` float32.

    :func:`select_all_points` with every pixel's bracket ``[0, bound]`` (``bound`` in pixels, beyond any distance
    to a valid point; ``dy2`` [H, P], ``dx2`` [W, P]; the map is padded to whole tiles). Used for the coarse grid of
    "pallas", where it replaces the 31-pass bit search over all 400 points.
    """
    h, w = dy2.shape[0], dx2.shape[0]
    hp, wp = -(-h // tile) * tile, -(-w // tile) * tile
    dy2 = jnp.pad(dy2, ((0, hp - h), (0, 0)))
    dx2 = jnp.pad(dx2, ((0, wp - w), (0, 0)))
    lo = jnp.zeros((hp, wp), jnp.float32)
    hi = jnp.full((hp, wp), bound, jnp.float32)
    return select_all_points(dy2, dx2, n_points, d, lo, hi, tile)[:h, :w]


LIST_CHUNK = 32  # points per loop iteration of the list kernel


def _build_list(t, ty, tx, rmin_ref, rmax_ref, cmin_ref, cmax_ref, lt2, ut2, idx_ref, *, cap: int, chunk: int):
    """Write tile ``t``'s candidates to ``idx_ref[t, :cap]`` in point order; return (count, inside) int32."""

    def body(j, carry):
        count, inside = carry
        ps = pl.ds(j * chunk, chunk)
        is_in = (rmax_ref[ty, ps] + cmax_ref[tx, ps]) < lt2
        cand = ((rmin_ref[ty, ps] + cmin_ref[tx, ps]) <= ut2) & ~is_in
        slot = count + jnp.cumsum(cand.astype(jnp.int32)) - 1
        # Candidates go to their slot, in point order; the others (and any past ``cap``) to the spare slot cap.
        idx_ref[t, jnp.where(cand, jnp.minimum(slot, cap), cap)] = j * chunk + jnp.arange(chunk, dtype=jnp.int32)
        return count + jnp.sum(cand.astype(jnp.int32)), inside + jnp.sum(is_in.astype(jnp.int32))

    return jax.lax.fori_loop(0, rmin_ref.shape[1] // chunk, body, (jnp.int32(0), jnp.int32(0)))


def _lists_kernel(rmin_ref, rmax_ref, cmin_ref, cmax_ref, lt2_ref, ut2_ref, idx_ref, n_ref, inside_ref, *,
                  n_tx: int, cap: int, chunk: int):
    t = pl.program_id(0)
    n_ref[t], inside_ref[t] = _build_list(t, t // n_tx, t % n_tx, rmin_ref, rmax_ref, cmin_ref, cmax_ref,
                                          lt2_ref[t], ut2_ref[t], idx_ref, cap=cap, chunk=chunk)


def _fused_kernel(dy2t_ref, dx2t_ref, rmin_ref, rmax_ref, cmin_ref, cmax_ref, lt2_ref, ut2_ref, d_ref, lo_ref,
                  hi_ref, out_ref, idx_ref, n_ref, *, tile: int, n_tx: int, cap: int, chunk: int, interpret: bool,
                  **select_kw):
    """Lists and selection in one program: the list goes to ``idx_ref`` (global memory) and is read back after a
    barrier, which makes the warp's stores visible to all its threads."""
    t = pl.program_id(0)
    rs, cs = _tile_view(t, n_tx, tile)
    count, inside = _build_list(t, t // n_tx, t % n_tx, rmin_ref, rmax_ref, cmin_ref, cmax_ref, lt2_ref[t],
                                ut2_ref[t], idx_ref, cap=cap, chunk=chunk)
    n_ref[t] = count
    if not interpret:
        from jax.experimental.pallas import triton as plgpu

        plgpu.debug_barrier()

    out_ref[rs, cs] = _select(_candidates(dy2t_ref, dx2t_ref, idx_ref, t, rs, cs), jnp.minimum(count, cap),
                              d_ref[0] - inside, lo_ref[rs, cs], hi_ref[rs, cs], **select_kw)


def _padded(*arrays):
    """Pad the point axis of ``[.., P]`` arrays to whole list chunks with +inf (neither inside nor candidates)."""
    pad = ((0, 0), (0, -arrays[0].shape[1] % LIST_CHUNK))
    return tuple(jnp.pad(a, pad, constant_values=jnp.inf) for a in arrays)


def tile_lists(rmin: jax.Array, rmax: jax.Array, cmin: jax.Array, cmax: jax.Array, lt2: jax.Array, ut2: jax.Array,
               cap: int):
    """The candidate lists of ``worley._tile_lists`` by a kernel (one program per tile, no sort, no scatter).

    ``rmin``, ``rmax`` [ty, P]: min and max of ``dy2`` over each tile row's pixel rows; ``cmin``, ``cmax`` [tx, P]
    likewise for ``dx2``; ``lt2``, ``ut2`` [ty, tx]: each tile's squared bracket. Returns ``idx [ty, tx, cap]``
    int32 (slots past ``n_cand`` hold anything), ``n_cand`` and ``inside`` ``[ty, tx]`` int32, the same values as
    the XLA version.
    """
    ty, tx = rmin.shape[0], cmin.shape[0]
    kernel = functools.partial(_lists_kernel, n_tx=tx, cap=cap, chunk=LIST_CHUNK)
    shapes = (jax.ShapeDtypeStruct((ty * tx, cap + 1), jnp.int32), jax.ShapeDtypeStruct((ty * tx,), jnp.int32),
              jax.ShapeDtypeStruct((ty * tx,), jnp.int32))
    idx, n_cand, inside = _call(kernel, shapes, "worley_lists", ty * tx, 1, *_padded(rmin, rmax, cmin, cmax),
                                lt2.reshape(-1), ut2.reshape(-1))
    return idx[:, :cap].reshape(ty, tx, cap), n_cand.reshape(ty, tx), inside.reshape(ty, tx)


def select_kth_fused(dy2: jax.Array, dx2: jax.Array, extremes, d: jax.Array, lo: jax.Array, hi: jax.Array,
                     tile: int, cap: int, max_iter: int = MAX_ITER):
    """:func:`tile_lists` and :func:`select_kth` in one kernel. ``extremes`` = ``(rmin, rmax, cmin, cmax, lt2,
    ut2)`` as for :func:`tile_lists`; ``d`` the map's D. Returns the squared ``F_D`` ``[H, W]`` and ``n_cand``
    ``[ty, tx]`` (where it exceeds ``cap`` that tile's result is incomplete: the caller redoes the map)."""
    h, w = dy2.shape[0], dx2.shape[0]
    rmin, rmax, cmin, cmax, lt2, ut2 = extremes
    ty, tx = rmin.shape[0], cmin.shape[0]
    kernel = functools.partial(_fused_kernel, tile=tile, n_tx=tx, cap=cap, chunk=LIST_CHUNK, max_iter=max_iter,
                               top_k=TOP_K)
    shapes = (jax.ShapeDtypeStruct((h, w), jnp.float32), jax.ShapeDtypeStruct((ty * tx, cap + 1), jnp.int32),
              jax.ShapeDtypeStruct((ty * tx,), jnp.int32))
    d2, _, n_cand = _call(kernel, shapes, "worley_fused", ty * tx, NUM_WARPS, dy2.T, dx2.T,
                          *_padded(rmin, rmax, cmin, cmax), lt2.reshape(-1), ut2.reshape(-1),
                          jnp.reshape(d, (1,)).astype(jnp.int32), lo.astype(jnp.float32), hi.astype(jnp.float32),
                          pass_interpret=True)
    return d2, n_cand.reshape(ty, tx)
