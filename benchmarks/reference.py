"""NumPy / SciPy CPU references: the peers that the GPU figures are compared against, in the same run.

They compute the same kinds of functions as jaxterrain (same genes and ranges, same window conventions), written the
way a careful CPU implementation would be: vectorised over pixels with NumPy, one terrain at a time, SciPy's k-d tree
for Worley. The feature references follow jaxterrain.features' conventions exactly (VALID windows of k x k pixels,
window centre at offset (k // 2, k // 2), stride s) and are used to check the JAX kernels' values too.
"""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

# ------------------------------------------------------------------------------------------------ generators

_GRADS = np.array([[1, 1], [-1, 1], [1, -1], [-1, -1], [1, 0], [-1, 0], [0, 1], [0, -1]], np.float64)


def _perlin2(x: np.ndarray, y: np.ndarray, perm: np.ndarray) -> np.ndarray:
    xi, yi = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    xf, yf = x - xi, y - yi
    xi, yi = xi & 255, yi & 255
    fade = lambda t: t * t * t * (t * (t * 6 - 15) + 10)  # noqa: E731
    u, v = fade(xf), fade(yf)

    def dot(h, dx, dy):
        g = _GRADS[h & 7]
        return g[..., 0] * dx + g[..., 1] * dy

    aa, ab = perm[perm[xi] + yi], perm[perm[xi] + yi + 1]
    ba, bb = perm[perm[xi + 1] + yi], perm[perm[xi + 1] + yi + 1]
    x1 = dot(aa, xf, yf) + u * (dot(ba, xf - 1, yf) - dot(aa, xf, yf))
    x2 = dot(ab, xf, yf - 1) + u * (dot(bb, xf - 1, yf - 1) - dot(ab, xf, yf - 1))
    return x1 + v * (x2 - x1)


def perlin(genome: np.ndarray, size: int = 256) -> np.ndarray:
    """Perlin fBM; genome (scale, octaves, persistence, lacunarity, seed) -> [size, size] in [0, 1]."""
    scale, octaves, persistence, lacunarity, seed = genome
    rng = np.random.default_rng(int(seed))
    jj, ii = np.meshgrid(np.arange(size, dtype=np.float64), np.arange(size, dtype=np.float64))
    total, norm, amp, freq = np.zeros((size, size)), 0.0, 1.0, 1.0
    for _ in range(int(octaves)):
        perm = rng.permutation(256)
        perm = np.concatenate([perm, perm])
        total += amp * _perlin2(jj / scale * freq, ii / scale * freq, perm)
        norm += amp
        amp *= persistence
        freq *= lacunarity
    return np.clip((total / norm + 1.0) / 2.0, 0.0, 1.0).astype(np.float32)


def diamond_square(genome: np.ndarray, size: int = 256) -> np.ndarray:
    """Diamond-square as in the paper; genome (c00, c01, c10, c11, Z, D, seed) -> [size, size] in [0, 1]."""
    c00, c01, c10, c11, z, d, seed = genome
    rng = np.random.default_rng(int(seed))
    n = size + 1
    g = np.zeros((n, n))
    g[0, 0], g[0, -1], g[-1, 0], g[-1, -1] = c00, c01, c10, c11
    step, r, it = size, 1.0, 0
    pct = lambda shape: rng.uniform(z, 100 - z, shape) / 100.0  # noqa: E731
    while step > 1:
        h = step // 2
        # diamond: centres of squares
        avg = (g[0:-1:step, 0:-1:step] + g[0:-1:step, step::step] + g[step::step, 0:-1:step] + g[step::step, step::step]) / 4
        g[h::step, h::step] = pct(avg.shape) * avg + rng.uniform(-r, r, avg.shape)
        # square: edge midpoints, averaging the available neighbours
        for oi, oj in ((0, h), (h, 0)):
            ii, jj = np.meshgrid(np.arange(oi, n, step), np.arange(oj, n, step), indexing="ij")
            acc, cnt = np.zeros(ii.shape), np.zeros(ii.shape)
            for di, dj in ((-h, 0), (h, 0), (0, -h), (0, h)):
                a, b = ii + di, jj + dj
                ok = (a >= 0) & (a < n) & (b >= 0) & (b < n)
                acc += np.where(ok, g[np.clip(a, 0, n - 1), np.clip(b, 0, n - 1)], 0.0)
                cnt += ok
            avg = acc / cnt
            g[ii, jj] = pct(avg.shape) * avg + rng.uniform(-r, r, avg.shape)
        it += 1
        r = 1.0 / (it * d + 1.0)
        step = h
    return np.clip((g[:size, :size] + 1.0) / 2.0, 0.0, 1.0).astype(np.float32)


def worley(genome: np.ndarray, size: int = 256) -> np.ndarray:
    """Worley noise; genome (seed, N, D) -> distance to the D-th nearest of N points, / its max, [size, size]."""
    from scipy.spatial import cKDTree

    seed, n, d = (int(v) for v in genome)
    pts = np.random.default_rng(seed).uniform(0, size, (n, 2))
    jj, ii = np.meshgrid(np.arange(size) + 0.5, np.arange(size) + 0.5)
    dist, _ = cKDTree(pts).query(np.stack([ii.ravel(), jj.ravel()], -1), k=d + 1)
    dist = dist.reshape(size, size, -1)[..., d] if d > 0 else dist.reshape(size, size)
    return (dist / dist.max()).astype(np.float32)


GENERATORS = {"perlin": perlin, "diamond_square": diamond_square, "worley": worley}

# ------------------------------------------------------------------------------------------------ features


def _windows(h: np.ndarray, k: int, s: int) -> tuple[np.ndarray, np.ndarray]:
    w = sliding_window_view(np.asarray(h, np.float64), (k, k))[::s, ::s]  # [H', W', k, k]
    return w, w[..., k // 2, k // 2]


def tri(h: np.ndarray, k: int = 3, s: int = 1) -> np.ndarray:
    """Wilson TRI: mean |w_i - centre| over the k*k - 1 other cells of each window."""
    w, c = _windows(h, k, s)
    return np.abs(w - c[..., None, None]).sum((-1, -2)) / (k * k - 1)


def tpi(h: np.ndarray, k: int = 3, s: int = 1) -> np.ndarray:
    """TPI: centre minus the mean of the k*k - 1 other cells."""
    w, c = _windows(h, k, s)
    return c - (w.sum((-1, -2)) - c) / (k * k - 1)


def roughness(h: np.ndarray, k: int = 3, s: int = 1) -> np.ndarray:
    """Roughness: max - min over the whole window."""
    w, _ = _windows(h, k, s)
    return w.max((-1, -2)) - w.min((-1, -2))


FEATURES = {"tri": tri, "tpi": tpi, "roughness": roughness}


def descriptors(h: np.ndarray, names=("tri", "tpi", "roughness"), k: int = 30, s: int = 2) -> np.ndarray:
    """Descriptors of one heightmap [H, W] -> [len(names)]: the mean of each feature map (of |TPI| for "tpi")."""
    return np.array([np.abs(FEATURES[n](h, k, s)).mean() if n == "tpi" else FEATURES[n](h, k, s).mean()
                     for n in names])
