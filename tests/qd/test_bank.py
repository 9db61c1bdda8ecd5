"""The device-side terrain bank: filled cells only, metres, normalised points, cell distances."""

from __future__ import annotations

import numpy as np
import pytest

from jaxterrain import qd as A
from jaxterrain.qd import bank as B
from jaxterrain.terrain import TerrainScale


def tiny_archive(bins=4, size=8):
    cells = bins * bins
    config = A.resolve_config(A.EvolveConfig(bins=bins, ranges=((0.0, 1.0), (0.0, 2.0))))
    source = np.full(cells, -1, np.int32)
    source[[0, 5, 15]] = 0
    fitness = np.full(cells, -np.inf, np.float32)
    fitness[[0, 5, 15]] = [0.9, 0.5, 0.1]
    desc = np.zeros((cells, 2), np.float32)
    desc[[0, 5, 15]] = [[0.1, 0.1], [0.4, 0.7], [1.5, 2.5]]  # the last is out of range (clipped to 1)
    maps = np.zeros((cells, size, size), np.uint16)
    maps[5] = 65535
    maps[15] = 32768
    genomes = (np.zeros((cells, 3), np.float32),)
    return A.Archive(genomes, ("perlin",), source, fitness, desc, np.asarray(A.centroids_for(config)), maps, config,
                     {})


def test_bank_holds_the_filled_cells_in_metres():
    bank = B.from_archive(tiny_archive(), TerrainScale(height=2.0))
    assert bank.size == 3
    np.testing.assert_array_equal(np.asarray(bank.cell), [0, 5, 15])
    np.testing.assert_array_equal(np.asarray(bank.bins), [[0, 0], [1, 1], [3, 3]])
    np.testing.assert_allclose(np.asarray(bank.distance), np.hypot([1, 2, 4], [1, 2, 4]), rtol=1e-6)
    np.testing.assert_allclose(np.asarray(bank.fitness), [0.9, 0.5, 0.1])
    np.testing.assert_allclose(np.asarray(bank.points), [[0.1, 0.05], [0.4, 0.35], [1.0, 1.0]], rtol=1e-6)
    np.testing.assert_allclose(np.asarray(bank.heightmaps[:, 0, 0]), [0.0, 2.0, 2.0 * 32768 / 65535], rtol=1e-6)


def test_paper_maximum_distance():
    assert A.cell_distance(np.array([49, 49])) == pytest.approx(70.71, abs=0.01)
    assert A.MAX_DISTANCE_50 == pytest.approx(70.7107, abs=1e-4)


def test_empty_archive_is_refused():
    arch = tiny_archive()
    empty = arch._replace(source=np.full_like(arch.source, -1))
    with pytest.raises(ValueError, match="no filled cell"):
        B.from_archive(empty)
