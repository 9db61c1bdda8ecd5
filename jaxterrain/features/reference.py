"""The features' ground truth: plain NumPy loops over explicit windows (float64 inside), slow and obvious, against
which the JAX kernels of :mod:`jaxterrain.features.kernels` are tested (and the CPU benchmarks' baseline)."""

from __future__ import annotations

import numpy as np

from jaxterrain.features.kernels import FACE_THRESHOLD, check_window, window_centre

__all__ = ["reference_maps"]


def reference_maps(heightmaps, window: int = 3, stride: int = 1) -> dict[str, np.ndarray]:
    """Plain NumPy maps over explicit windows (float64 inside): ``{"tri", "tri_riley", "tpi", "roughness", "faces",
    "max_step"}`` -> ``[B, H', W']`` float64 (``[H', W']`` for a single map). Slow ground truth; keep inputs small."""
    h = np.asarray(heightmaps, np.float64)
    single = h.ndim == 2
    if single:
        h = h[None]
    if h.ndim != 3:
        raise ValueError(f"heightmaps must have shape [B, H, W] or [H, W]; got shape {h.shape}")
    window, stride = check_window(h.shape, window, stride)
    w = np.lib.stride_tricks.sliding_window_view(h, (window, window), axis=(1, 2))[:, ::stride, ::stride]
    c = window_centre(window)
    z = w[..., c, c]
    flat = w.reshape(*w.shape[:3], window * window)
    others = np.delete(flat, c * window + c, axis=-1)
    d = others - z[..., None]
    # Each pixel's largest step to a 4-neighbour, neighbour by neighbour (border pixels have fewer).
    step = np.zeros_like(h)
    for dy, dx in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        for i in range(h.shape[1]):
            for j in range(h.shape[2]):
                if 0 <= i + dy < h.shape[1] and 0 <= j + dx < h.shape[2]:
                    step[:, i, j] = np.maximum(step[:, i, j], np.abs(h[:, i + dy, j + dx] - h[:, i, j]))
    sw = np.lib.stride_tricks.sliding_window_view(step, (window, window), axis=(1, 2))[:, ::stride, ::stride]
    out = {
        "faces": (sw > FACE_THRESHOLD).mean(axis=(-2, -1)),
        "max_step": sw.max(axis=(-2, -1)),
        "tri": np.abs(d).mean(-1),
        "tri_riley": np.sqrt((d * d).sum(-1)),
        "tpi": z - others.mean(-1),
        "roughness": flat.max(-1) - flat.min(-1),
    }
    return {k: v[0] for k, v in out.items()} if single else out
