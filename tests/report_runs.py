"""A run folder as the commands write them, shared by the report's library tests and the report / export command
tests (``tests/integration/test_stage_commands.py``)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def tiny_archive(bins=4, size=16, filled=(0, 5, 6, 10, 15)):
    """A ``bins`` x ``bins`` perlin archive with random ``size`` x ``size`` heightmaps in the ``filled`` cells."""
    from jaxterrain import qd as A

    cells = bins * bins
    config = A.resolve_config(A.EvolveConfig(generations=1, batch_size=2, initial_population=2, bins=bins,
                                             ranges=((0.0, 1.0), (0.0, 0.5))))
    rng = np.random.default_rng(0)
    source = np.full(cells, -1, np.int32)
    source[list(filled)] = 0
    fitness = np.full(cells, -np.inf, np.float32)
    fitness[list(filled)] = np.linspace(0.9, 0.1, len(filled))
    maps = np.zeros((cells, size, size), np.uint16)
    maps[list(filled)] = (rng.random((len(filled), size, size)) * 65535).astype(np.uint16)
    descriptors = np.where(source[:, None] >= 0, rng.random((cells, 2)), 0).astype(np.float32)
    b0, b1 = np.meshgrid(np.arange(bins), np.arange(bins))
    centroids = np.stack([(b0.ravel() + 0.5) / bins, (b1.ravel() + 0.5) / bins * 0.5], -1).astype(np.float32)
    return A.Archive(genomes=(np.zeros((cells, 3), np.float32),), generator_names=("perlin",), source=source,
                     fitness=fitness, descriptors=descriptors, centroids=centroids, heightmaps=maps, config=config,
                     metrics={"coverage": np.array([10.0, 31.25], np.float32)})


def make_smoke_run(tmp_path: Path) -> Path:
    """A run folder as the commands write them: config.json, a CSV, a Markdown table, a PNG, an archive, a
    checkpoint (not an archive) and a JSON file in sub-folders."""
    from PIL import Image

    from jaxterrain import qd as A

    run = tmp_path / "evolve-smoke"
    (run / "checkpoint").mkdir(parents=True)
    (run / "config.json").write_text(json.dumps({"generator": "perlin", "bins": 4, "seed": 7}))
    (run / "metrics.csv").write_text("generation,coverage,qd_score\n0,10,1.5\n1,31.25,2.75\n")
    (run / "summary.md").write_text("# smoke\n\n| generator | coverage |\n|---|---|\n| perlin | 31.25 % |\n\n"
                                    "See [the docs](https://example.org/x) and `code`.\n")
    img = np.zeros((20, 30, 3), np.uint8)
    img[:, :15] = (200, 30, 30)
    Image.fromarray(img).save(run / "archive.png")
    A.save(run / "archive.npz", tiny_archive())
    np.savez(run / "checkpoint" / "checkpoint.npz", x=np.arange(3))
    (run / "checkpoint" / "state.json").write_text('{"generation": 1}')
    return run
