"""Terrain feature kernels (paper section 3.2): TRI, TPI and roughness maps and their means.

Per-pixel maps, each over every ``window x window`` window placed with a ``stride`` (VALID: no padding), on
batches ``[B, H, W]`` (a single ``[H, W]`` map is accepted and gives an unbatched result)::

    tri(h, window=3, stride=1)        # Wilson: mean_{i != centre} |w_i - z|   (the paper's "average difference")
    tri(h, ..., algorithm="riley")    # Riley:  sqrt(sum_{i != centre} (w_i - z)^2)
    tpi(h, window=3, stride=1)        # z - mean_{i != centre} w_i
    roughness(h, window=3, stride=1)  # max(w) - min(w), centre included
    faces(h, window=3, stride=1)      # share of w's pixels whose largest step to a 4-neighbour > FACE_THRESHOLD
    max_step(h, window=3, stride=1)   # the largest step to a 4-neighbour of any pixel of w

-> ``[B, H', W']`` float32 with ``H' = (H - window) // stride + 1`` (likewise ``W'``). ``z`` is the window's centre
pixel, which we define as pixel ``(window // 2, window // 2)`` of the window (row, column from its top-left
corner). For odd windows that is the true centre; GDAL's ``gdaldem`` uses ``window = 3`` (centre ``(1, 1)``) and at
``window = 3, stride = 1`` our maps equal ``gdaldem tri -alg Wilson`` / ``tri -alg Riley`` / ``tpi`` /
``roughness`` on interior pixels (``tests/features/test_features.py``). For even windows (the paper's ``window = 30``) there is
no middle pixel: we take the lower-right one of the four central pixels, ``(15, 15)`` for ``window = 30``. Map pixel
``(i, j)`` is the window whose top-left corner is input pixel ``(i * stride, j * stride)``. All features are in the
heightmap's units.

The scalar descriptor of a feature is the mean of its map (paper: window 30, stride 2)::

    descriptors(h, names=("tri", "tpi", "roughness"), window=30, stride=2)   # [B, len(names)] float32

Names come from a registry (:mod:`jaxterrain.features.registry`) that takes any callable
``heightmaps[B, H, W] -> [B]`` (e.g. the learned traversability model, :mod:`jaxterrain.features.learned`).

How it is computed (the fast path is exact; only float32 summation order differs from the reference):

- Wilson / Riley TRI: one shifted difference per window offset. For offset ``(dy, dx)`` the neighbours of all
  windows are one strided slice ``h[dy::stride, dx::stride]`` (cropped to ``[H', W']``); stride > 1 first splits
  the map into its ``stride**2`` polyphase components so that every slice is contiguous. The map is
  ``sum_{(dy, dx) != centre} |slice(dy, dx) - z|``. On GPU/TPU all ``k*k - 1`` terms are one unrolled elementwise
  expression that XLA fuses into a single kernel with the descriptor's mean as its reduction: no
  ``[k*k, H', W']`` patch tensor is ever stored and the heightmap is read from memory once. On CPU a loop over the
  k window rows keeps the program small (fast compiles). Cost: ``(k*k - 1) * H' * W'`` subtract-abs-adds per map,
  899 * 114^2 = 11.7 M at 256^2, k = 30, s = 2 (measured on one H100, jax 0.11.2: ~230 000 terrains/s for
  ``("tri", "tpi", "roughness")`` together, ~255 000 for TRI alone, batch 4096). Batches above 2**29 elements are
  processed in chunks (see ``_MAX_CHUNK_ELEMENTS``).
- TPI is linear: ``tpi = z * k^2 / (k^2 - 1) - boxsum / (k^2 - 1)`` with a separable box sum. The ``tpi``
  descriptor is the mean ABSOLUTE TPI: the mean of the signed map is ~0 on any terrain (it is the map's mean minus
  the mean of its box-filtered copy, up to border effects), so it could not rank terrains; the paper found TPI the
  descriptor best correlated with difficulty, which only a magnitude can be. The signed mean stays available as
  ``tpi_signed``: a fixed weighted sum of the heightmap (each pixel weighted by how many windows contain it), one
  multiply-add per pixel.
- Roughness: separable ``lax.reduce_window`` max of z and of -z (rows, then columns).
- Vertical faces (issue 64): :func:`step_heights` is each pixel's largest absolute height difference to its (up to
  four) 4-neighbours in the map (neighbours outside the window count; a map's border pixels have fewer), one
  elementwise pass. ``faces`` is the share of a window's pixels whose step exceeds :data:`FACE_THRESHOLD` (a
  separable reduce_window sum of the 0 / 1 map over ``k * k``), ``max_step`` the window's largest step (a separable
  reduce_window max). A riser of ``r`` heightmap units marks the pixels on both sides of it (2 per row it crosses)
  with step ``r``; a ramp rising ``g`` per pixel marks none (``g`` <= the threshold) and has ``max_step = g``. Their
  descriptors are the means over the windows, as for the others: ``faces`` is about the density of face pixels
  (weighted as the windows cover them), ``max_step`` the typical tallest face within one window (~1.2 m at k = 30).

:func:`~jaxterrain.features.reference.reference_maps` is a plain NumPy implementation over explicit windows, kept as ground truth for tests and as
the CPU baseline of the benchmark.
"""

from __future__ import annotations

import functools
from typing import Callable, NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax


__all__ = [
    "HEIGHT_RANGE",
    "BUILTIN",
    "check_heights",
    "as_batch",
    "check_window",
    "tri",
    "tpi",
    "roughness",
    "roughness_core",
    "FACE_THRESHOLD",
    "step_heights",
    "faces",
    "max_step",
    "builtin_descriptors",
    "chunked_builtin_descriptors",
    "output_shape",
    "window_centre",
]

_WILSON, _RILEY = "wilson", "riley"
_UNROLL: bool | None = None  # force the TRI offset-sum strategy (see _offset_sum); None = by backend


# ----------------------------------------------------------------------------------------------------------------
# Input handling and validation (host side, static shapes only: also fine under jit)


def as_batch(heightmaps) -> tuple[jax.Array, bool]:
    """``[B, H, W]`` or ``[H, W]`` -> (``[B, H, W]`` float32, was_single)."""
    try:
        h = jnp.asarray(heightmaps)
    except (TypeError, ValueError) as err:
        raise ValueError(f"heightmaps must be a real-valued array [B, H, W] or [H, W]; got "
                         f"{type(heightmaps).__name__} ({err})") from None
    if h.dtype.kind not in "biuf":
        raise ValueError(f"heightmaps must be a real-valued array [B, H, W] or [H, W]; got dtype {h.dtype}")
    if h.ndim == 2:
        return h[None].astype(jnp.float32), True
    if h.ndim != 3:
        raise ValueError(f"heightmaps must have shape [B, H, W] or [H, W]; got shape {tuple(h.shape)}")
    return h.astype(jnp.float32), False


HEIGHT_RANGE = (0.0, 1.0)
"""Heights accepted by :func:`descriptors` and :func:`is_traversable`: heightmap units in [0, 1] (generators' range;
metres come from a :class:`~jaxterrain.terrain.TerrainScale`)."""


@jax.jit
def _value_stats(h: jax.Array):
    """Per map of ``[B, H, W]``: (any NaN, min, max) ignoring NaN; three ``[B]`` arrays, one pass on device."""
    nan = jnp.any(jnp.isnan(h), axis=(1, 2))
    lo = jnp.min(jnp.where(jnp.isnan(h), jnp.inf, h), axis=(1, 2))
    hi = jnp.max(jnp.where(jnp.isnan(h), -jnp.inf, h), axis=(1, 2))
    return nan, lo, hi


def check_heights(h: jax.Array, single: bool = False) -> None:
    """Host-side check of concrete heightmaps ``[B, H, W]``: every value finite and in [0, 1], else a ``ValueError``
    naming ``heightmaps``, the first bad map and the allowed range. Skipped for traced values (inside jit / vmap /
    scan: MAP-Elites computes features inside ``lax.scan``) and for empty batches."""
    if len(getattr(h, "shape", ())) != 3:
        raise ValueError(f"heightmaps must have shape [B, H, W]; got "
                         f"{tuple(h.shape) if hasattr(h, 'shape') else type(h).__name__}")
    if isinstance(h, jax.core.Tracer) or h.size == 0:
        return
    nan, lo, hi = (np.asarray(a) for a in _value_stats(h))
    lo_r, hi_r = HEIGHT_RANGE
    where = (lambda i: "") if single else (lambda i: f" (map {i})")
    if nan.any():
        i = int(np.argmax(nan))
        raise ValueError(f"heightmaps{where(i)} hold NaN; heights must be finite, in [{lo_r:g}, {hi_r:g}]")
    bad = ~((lo >= lo_r) & (hi <= hi_r))  # -inf / +inf land here too
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"heightmaps{where(i)} hold values in [{lo[i]:g}, {hi[i]:g}]; heights must be in "
                         f"[{lo_r:g}, {hi_r:g}] (heightmap units: scale to metres with a TerrainScale)")


def _check_int(name: str, value, low: int, high: int | None) -> int:
    rng = f"[{low}, {high}]" if high is not None else f">= {low}"
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an integer in {rng}; got {value!r}")
    value = int(value)
    if value < low or (high is not None and value > high):
        raise ValueError(f"{name} must be an integer in {rng}; got {value}")
    return value


def check_window(shape, window, stride) -> tuple[int, int]:
    """``(window, stride)`` as ints after checking them against a ``[..., H, W]`` heightmap ``shape``; ``ValueError``
    naming the parameter otherwise."""
    try:
        dims = tuple(shape)
        if len(dims) < 2 or not all(isinstance(d, (int, np.integer)) and not isinstance(d, bool) for d in dims[-2:]):
            raise TypeError
    except TypeError:
        raise ValueError(f"shape must be the [..., H, W] shape of heightmaps (integers); got {shape!r}") from None
    h, w = int(dims[-2]), int(dims[-1])
    if min(h, w) < 2:
        raise ValueError(f"heightmaps of {h} x {w} pixels are too small: every window needs at least 2 x 2")
    window = _check_int("window", window, 2, min(h, w))
    stride = _check_int("stride", stride, 1, None)
    return window, stride


def output_shape(shape: Sequence[int], window: int, stride: int) -> tuple[int, int]:
    """``(H', W')`` of a feature map of a ``[..., H, W]`` heightmap (VALID windows)."""
    window, stride = check_window(shape, window, stride)
    return (int(shape[-2]) - window) // stride + 1, (int(shape[-1]) - window) // stride + 1


def window_centre(window: int) -> int:
    """Row (= column) of the centre pixel inside a window: ``window // 2`` (see the module docstring); ``window`` an
    integer >= 1."""
    return _check_int("window", window, 1, None) // 2


# ----------------------------------------------------------------------------------------------------------------
# Shifted views


class _Views(NamedTuple):
    """Shifted views of a batch: ``view(dy, dx)[b, i, j] = h[b, i * stride + dy, j * stride + dx]``, ``[B, H', W']``."""

    phases: jax.Array  # [B, s, s, ni, nj] polyphase components (or [B, 1, 1, H, W] when stride = 1)
    stride: int
    out_h: int
    out_w: int

    def view(self, dy: int, dx: int) -> jax.Array:
        s = self.stride
        p, q = dy // s, dx // s
        return self.phases[:, dy % s, dx % s, p : p + self.out_h, q : q + self.out_w]


def _views(h: jax.Array, window: int, stride: int) -> _Views:
    b, hh, ww = h.shape
    ho, wo = (hh - window) // stride + 1, (ww - window) // stride + 1
    s = stride
    if s == 1:
        return _Views(h[:, None, None], 1, ho, wo)
    ni, nj = ho + (window - 1) // s, wo + (window - 1) // s
    # Rows/columns beyond s*ni / s*nj are never inside a window; the zero padding (when s*ni > H) is never read.
    h = h[:, : s * ni, : s * nj]
    h = jnp.pad(h, ((0, 0), (0, s * ni - h.shape[1]), (0, s * nj - h.shape[2])))
    phases = h.reshape(b, ni, s, nj, s).transpose(0, 2, 4, 1, 3)
    return _Views(phases, s, ho, wo)


def _offset_sum(
    v: _Views, z: jax.Array, window: int, term: Callable[[jax.Array], jax.Array], unroll: bool | None = None
) -> jax.Array:
    """``sum_{(dy, dx) != centre} term(view(dy, dx) - z)`` -> ``[B, H', W']``.

    ``unroll=True``: all ``k*k - 1`` terms as one unrolled elementwise expression, which XLA fuses into a single
    kernel (fastest on GPU/TPU). ``unroll=False``: a ``fori_loop`` over the ``k`` window rows with the ``k`` terms of
    a row unrolled (k times smaller program: XLA:CPU compiles the k = 30 case in ~1 s instead of ~15 s). ``None``
    picks ``unroll = (jax.default_backend() != "cpu")`` unless the module switch ``_UNROLL`` (tests) is set. Both
    give the same values up to float32 summation order.
    """
    if unroll is None:
        unroll = _UNROLL if _UNROLL is not None else jax.default_backend() != "cpu"
    c = window_centre(window)
    if unroll:
        rows = []
        for dy in range(window):
            acc = None
            for dx in range(window):
                if dy == c and dx == c:
                    continue
                t = term(v.view(dy, dx) - z)
                acc = t if acc is None else acc + t
            rows.append(acc)
        while len(rows) > 1:  # pairwise over rows: shorter dependency chains, smaller rounding error
            rows = [rows[i] + rows[i + 1] if i + 1 < len(rows) else rows[i] for i in range(0, len(rows), 2)]
        return rows[0]

    s, ho, wo = v.stride, v.out_h, v.out_w

    def row(dy, acc):
        phase_row = lax.dynamic_index_in_dim(v.phases, dy % s, axis=1, keepdims=False)  # [B, s, ni, nj]
        band = lax.dynamic_slice_in_dim(phase_row, dy // s, ho, axis=2)  # [B, s, H', nj]
        total = None
        for dx in range(window):
            t = term(band[:, dx % s, :, dx // s : dx // s + wo] - z)
            if dx == c:  # the centre itself contributes term(0) = 0 for abs/square, but mask it explicitly
                t = jnp.where(dy == c, jnp.zeros_like(t), t)
            total = t if total is None else total + t
        return acc + total

    return lax.fori_loop(0, window, row, jnp.zeros_like(z))


def _box(h: jax.Array, window: int, stride: int, init, op) -> jax.Array:
    """Separable reduce_window (``op`` associative) over ``[B, H, W]`` -> ``[B, H', W']``."""
    r = lax.reduce_window(h, init, op, (1, 1, window), (1, 1, stride), "VALID")
    return lax.reduce_window(r, init, op, (1, window, 1), (1, stride, 1), "VALID")


# ----------------------------------------------------------------------------------------------------------------
# Per-pixel maps (batched cores: [B, H, W] float32 in, [B, H', W'] out; no validation)


def _tri_core(h, window, stride, algorithm, v: _Views | None = None):
    v = _views(h, window, stride) if v is None else v
    c = window_centre(window)
    z = v.view(c, c)
    n = window * window - 1
    if algorithm == _WILSON:
        return _offset_sum(v, z, window, jnp.abs) / n
    return jnp.sqrt(_offset_sum(v, z, window, jnp.square))


def _tpi_core(h, window, stride, v: _Views | None = None):
    v = _views(h, window, stride) if v is None else v
    c = window_centre(window)
    z = v.view(c, c)
    box = _box(h, window, stride, 0.0, lax.add)
    return z - (box - z) / (window * window - 1)


def roughness_core(h, window, stride):
    hi = _box(h, window, stride, -jnp.inf, lax.max)
    lo = -_box(-h, window, stride, -jnp.inf, lax.max)
    return hi - lo


FACE_THRESHOLD = 0.05
"""Heightmap units (0.05 m at the default ``TerrainScale``; a grade of 1.25 at 4 cm pixels): a pixel whose largest
step to a 4-neighbour exceeds this is part of a vertical face for ``faces``. Above the suite's steepest slope (grade
0.5: 0.02 per pixel) and the ``steps`` generator's noise (at most 0.036 per pixel); the suite's stairs count from
level 2 (0.07 m risers) up, and so do the 8 cm risers of issue 64's check."""


def _step_core(h):
    """``[B, H, W]`` -> ``[B, H, W]``: each pixel's largest |height difference| to its 4-neighbours in the map."""
    dx = jnp.abs(h[:, :, 1:] - h[:, :, :-1])  # [B, H, W-1]: between columns j and j + 1
    dy = jnp.abs(h[:, 1:, :] - h[:, :-1, :])  # [B, H-1, W]
    px = ((0, 0), (0, 0), (1, 0)), ((0, 0), (0, 0), (0, 1))
    py = ((0, 0), (1, 0), (0, 0)), ((0, 0), (0, 1), (0, 0))
    return jnp.maximum(jnp.maximum(jnp.pad(dx, px[0]), jnp.pad(dx, px[1])),
                       jnp.maximum(jnp.pad(dy, py[0]), jnp.pad(dy, py[1])))


def _faces_core(h, window, stride, threshold: float = FACE_THRESHOLD):
    face = (_step_core(h) > threshold).astype(jnp.float32)
    return _box(face, window, stride, 0.0, lax.add) / float(window * window)


def _max_step_core(h, window, stride):
    return _box(_step_core(h), window, stride, -jnp.inf, lax.max)


def _check_algorithm(algorithm: str) -> str:
    a = str(algorithm).lower()
    if a not in (_WILSON, _RILEY):
        raise ValueError(f"algorithm must be one of ('wilson', 'riley'); got {algorithm!r}")
    return a


def tri(heightmaps, window: int = 3, stride: int = 1, algorithm: str = "wilson") -> jax.Array:
    """Terrain Ruggedness Index map.

    Args:
      heightmaps: ``[B, H, W]`` (or ``[H, W]``) float heightmaps.
      window: window size k, 2 <= k <= min(H, W). Centre pixel ``(k // 2, k // 2)``.
      stride: window step, >= 1.
      algorithm: ``"wilson"`` (default; mean_{i != centre} |w_i - z|, the paper's definition and
        ``gdaldem TRI -alg Wilson``) or ``"riley"`` (sqrt(sum_{i != centre} (w_i - z)^2), GDAL's default since 3.3).

    Returns:
      ``[B, H', W']`` float32 (``[H', W']`` for a single map), ``H' = (H - k) // stride + 1``.
    """
    algorithm = _check_algorithm(algorithm)
    return _per_pixel(functools.partial(_tri_core, algorithm=algorithm), heightmaps, window, stride)


def tpi(heightmaps, window: int = 3, stride: int = 1) -> jax.Array:
    """Topographic Position Index map: ``z - mean_{i != centre} w_i`` (``gdaldem TPI`` at k = 3).

    ``[B, H, W]`` (or ``[H, W]``) -> ``[B, H', W']`` float32; window / stride as in :func:`tri`.
    """
    return _per_pixel(_tpi_core, heightmaps, window, stride)


def roughness(heightmaps, window: int = 3, stride: int = 1) -> jax.Array:
    """Roughness map: ``max(w) - min(w)`` over the whole window, centre included (``gdaldem roughness`` at k = 3).

    ``[B, H, W]`` (or ``[H, W]``) -> ``[B, H', W']`` float32; window / stride as in :func:`tri`.
    """
    return _per_pixel(roughness_core, heightmaps, window, stride)


def step_heights(heightmaps) -> jax.Array:
    """Each pixel's largest absolute height difference to its 4-neighbours (up, down, left, right; those in the map).

    ``[B, H, W]`` (or ``[H, W]``) -> the same shape, float32, in the heightmap's units (metres: times
    ``TerrainScale.height``). A step of ``r`` between columns ``j`` and ``j + 1`` gives ``r`` at both."""
    h, single = as_batch(heightmaps)
    out = _step_core(h)
    return out[0] if single else out


def faces(heightmaps, window: int = 3, stride: int = 1, threshold: float = FACE_THRESHOLD) -> jax.Array:
    """Vertical-face density map: the share of each window's pixels whose :func:`step_heights` exceeds
    ``threshold`` (heightmap units, default :data:`FACE_THRESHOLD`).

    ``[B, H, W]`` (or ``[H, W]``) -> ``[B, H', W']`` float32 in [0, 1]; window / stride as in :func:`tri`.
    """
    return _per_pixel(functools.partial(_faces_core, threshold=float(threshold)), heightmaps, window, stride)


def max_step(heightmaps, window: int = 3, stride: int = 1) -> jax.Array:
    """Largest-step map: the largest :func:`step_heights` over each window's pixels (heightmap units).

    ``[B, H, W]`` (or ``[H, W]``) -> ``[B, H', W']`` float32; window / stride as in :func:`tri`.
    """
    return _per_pixel(_max_step_core, heightmaps, window, stride)


def _per_pixel(core, heightmaps, window: int, stride: int) -> jax.Array:
    """``core(h [B, H, W], window, stride)`` on checked heightmaps and window / stride; one map in, one map out."""
    h, single = as_batch(heightmaps)
    window, stride = check_window(h.shape, window, stride)
    out = core(h, window, stride)
    return out[0] if single else out


# ----------------------------------------------------------------------------------------------------------------
# Descriptors


def _tpi_weights(shape, window: int, stride: int) -> np.ndarray:
    """``[H, W]`` weights with ``sum(h * weights) == mean(tpi map)`` (TPI is linear in h)."""
    hh, ww = int(shape[-2]), int(shape[-1])
    ho, wo = (hh - window) // stride + 1, (ww - window) // stride + 1
    c = window_centre(window)
    n = window * window - 1

    def cover(size, out):  # how many windows (along one axis) contain each pixel
        cnt = np.zeros(size, np.float64)
        for i in range(out):
            cnt[i * stride : i * stride + window] += 1
        return cnt

    def centres(size, out):
        m = np.zeros(size, np.float64)
        m[np.arange(out) * stride + c] = 1
        return m

    count = ho * wo
    centre = np.outer(centres(hh, ho), centres(ww, wo))
    covered = np.outer(cover(hh, ho), cover(ww, wo))
    return ((centre * (n + 1) - covered) / (n * count)).astype(np.float32)


BUILTIN = ("tri", "tri_riley", "tpi", "tpi_signed", "roughness", "faces", "max_step")


def builtin_descriptors(h: jax.Array, names: Sequence[str], window: int, stride: int) -> dict[str, jax.Array]:
    """The built-in descriptors of a ``[B, H, W]`` batch, sharing the shifted views: name -> ``[B]``."""
    out = {}
    v = _views(h, window, stride) if ("tri" in names or "tri_riley" in names) else None
    for name in names:
        if name == "tri":
            out[name] = jnp.mean(_tri_core(h, window, stride, _WILSON, v), axis=(1, 2))
        elif name == "tri_riley":
            out[name] = jnp.mean(_tri_core(h, window, stride, _RILEY, v), axis=(1, 2))
        elif name == "tpi":
            out[name] = jnp.mean(jnp.abs(_tpi_core(h, window, stride)), axis=(1, 2))
        elif name == "tpi_signed":
            w = jnp.asarray(_tpi_weights(h.shape, window, stride))
            out[name] = jnp.sum(h * w, axis=(1, 2))
        elif name == "roughness":
            out[name] = jnp.mean(roughness_core(h, window, stride), axis=(1, 2))
        elif name == "faces":
            out[name] = jnp.mean(_faces_core(h, window, stride), axis=(1, 2))
        elif name == "max_step":
            out[name] = jnp.mean(_max_step_core(h, window, stride), axis=(1, 2))
    return out


# Above 2**29 input elements per call (8192 maps of 256 x 256) XLA:GPU's fused TRI kernel slows down ~4.5x
# (measured on an H100: 233k terrains/s at B = 8192, 52k at B = 16384, presumably 64-bit indexing), so larger
# batches are computed with lax.map in chunks of _CHUNK_ELEMENTS (4096 maps of 256 x 256: 189k terrains/s at
# B = 16384; chunks of 8192 maps gave only 116k).
_MAX_CHUNK_ELEMENTS = 2**29
_CHUNK_ELEMENTS = 2**28


def chunked_builtin_descriptors(h, names, window, stride) -> dict[str, jax.Array]:
    if not names:
        return {}
    b, hh, ww = h.shape
    per_map = hh * ww
    if b * per_map <= _MAX_CHUNK_ELEMENTS or b == 1:
        return builtin_descriptors(h, names, window, stride)
    chunk = max(1, min(_CHUNK_ELEMENTS, _MAX_CHUNK_ELEMENTS) // per_map)

    def one(x):  # [H, W] -> name -> []; lax.map vmaps it over chunks of `chunk` maps
        return {k: v[0] for k, v in builtin_descriptors(x[None], names, window, stride).items()}

    return lax.map(one, h, batch_size=chunk)
