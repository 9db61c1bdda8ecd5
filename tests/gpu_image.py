"""Run a test's commands as the GPU machine would: :func:`image` makes the packages its image lacks (:data:`MISSING`)
unimportable in the test's process and in every child process it starts (``gpu_site/sitecustomize.py`` on
``PYTHONPATH``). The commands that run there (``learn``, ``curriculum``, ``evolve``, ``evaluate``, the result scripts'
GPU stages, the benchmarks) must write their files without them.

The image has jax, flax, optax, chex, numpy, scipy, matplotlib, tqdm, rich, pytest, pillow and orbax-checkpoint
(``../shared/tools/device-wheels``); the wheels of ``.whl/`` add mujoco, mujoco-mjx, brax, qdax, jaxopt,
ml-collections, tensorboardX and trimesh. On 2026-11-30 a 60-trial population ran there to its last chunk and died at
``import rliable`` while writing its files."""

from __future__ import annotations

import os
import sys
from pathlib import Path

SITE = Path(__file__).resolve().parent / "gpu_site"

MISSING = ("rliable", "arch", "pandas", "statsmodels", "seaborn", "patsy", "tifffile", "onnx", "onnxruntime",
           "imageio_ffmpeg")
"""jaxterrain's dependencies and extras that the GPU image lacks and ``.whl/`` does not bring (``hypothesis`` too, but
a test process needs it)."""


def image(monkeypatch) -> None:
    """Through ``monkeypatch`` (undone with it): :data:`MISSING` unimportable here and in child processes."""
    for name in MISSING:
        monkeypatch.setitem(sys.modules, name, None)
    monkeypatch.setenv("JAXTERRAIN_TEST_MISSING", ",".join(MISSING))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(p for p in (str(SITE), os.environ.get("PYTHONPATH", "")) if p))
