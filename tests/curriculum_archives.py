"""Helpers shared by the curriculum's library tests and the ``learn`` / ``curriculum`` command tests
(``tests/integration/test_learn_command.py``): tiny archives cut from a stored one, a flat config validated, trees
compared leaf by leaf."""

from __future__ import annotations

from pathlib import Path

import jax
import numpy as np

from jaxterrain.curriculum import run_config, runner

CPPN = "docs/results/exp1b_gpu_sound_cppn_archive.npz"


def validated(cfg: dict):
    """``(CurriculumConfig, archive, policy, env)`` of a flat (``config.json``) run config."""
    return runner.validate(run_config.from_flat(cfg))[1:]


def tree_equal(a, b) -> bool:
    la, lb = jax.tree.leaves(a), jax.tree.leaves(b)
    return len(la) == len(lb) and all(np.array_equal(np.asarray(x), np.asarray(y), equal_nan=True)
                                      for x, y in zip(la, lb))


def tiny_archive_file(folder, k: int, name: str, **config) -> str:
    """The CPPN archive's first ``k`` filled cells with stored gentle bumps as heightmaps (no rendering), saved as
    ``folder/name``; ``config`` replaces fields of its EvolveConfig."""
    from jaxterrain import qd as A

    arch = A.load(CPPN)
    filled = np.flatnonzero(arch.filled)
    keep = np.zeros_like(arch.filled)
    keep[filled[:k]] = True
    x = np.linspace(0, 4 * np.pi, 256, dtype=np.float32)
    bumps = (0.02 * (1 + np.sin(x)[None, :] * np.cos(x)[:, None]) * 65535).astype(np.uint16)
    maps = np.where(keep[:, None, None], bumps[None], np.uint16(0))
    tiny = arch._replace(source=np.where(keep, arch.source, -1).astype(np.int32),
                         fitness=np.where(keep, arch.fitness, -np.inf).astype(np.float32), heightmaps=maps,
                         config=arch.config._replace(**config))
    return str(A.save(Path(folder) / name, tiny))
