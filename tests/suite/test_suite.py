"""The held-out suite: each family is the terrain its table row says, in physical units; builds are deterministic;
the generator samples sit in the level of their own descriptor distance; bad input is one ValueError naming it."""

from __future__ import annotations

import numpy as np
import pytest

from jaxterrain import suite
from jaxterrain.suite import families as F
from jaxterrain.terrain import TerrainScale

SCALE = TerrainScale()  # 4 cm pixels, 1 m per unit: heightmap values are metres
SIZE = 128  # 5.08 m across


def build(name, value, seed=0, size=SIZE):
    return F.build_terrain(name, value, size, SCALE, np.random.default_rng(seed))


def centre_row(h):
    return h[h.shape[0] // 2]


def test_every_family_is_flat_on_its_start_strip_and_inside_zero_one():
    strip = F.edge_distance(SIZE, SCALE) < F.START_STRIP
    for name, fam in F.FAMILIES.items():
        for value in (fam.lo, fam.hi):
            h = build(name, value)
            assert h.shape == (SIZE, SIZE) and h.dtype == np.float32
            assert 0.0 <= h.min() and h.max() <= 1.0, name
            assert np.ptp(h[strip]) == 0.0, f"{name}: the walker's start strip is not flat"


def test_slopes_rise_at_their_grade_and_stairs_by_their_step():
    h = centre_row(build("slope_up", 0.2))
    x = np.arange(SIZE) * SCALE.cell_size
    rising = (x > F.START_STRIP + 0.1) & (x < 2.4)
    np.testing.assert_allclose(np.diff(h)[rising[1:]] / SCALE.cell_size, 0.2, atol=1e-4)
    down = centre_row(build("slope_down", 0.2))
    np.testing.assert_allclose(down, down.max() - h, atol=1e-6)  # the same pyramid, inverted
    s = build("stairs_up", 0.1)
    levels = np.unique(np.round(s, 5))
    np.testing.assert_allclose(np.diff(levels), 0.1, atol=1e-5)  # every riser 10 cm
    tread = np.diff(np.flatnonzero(np.diff(centre_row(s)[: SIZE // 2]) > 0)) * SCALE.cell_size
    assert np.all(np.abs(tread - F.TREAD) <= SCALE.cell_size + 1e-9)  # 31 cm treads, to a pixel


def test_gaps_and_stones_have_the_width_of_their_level():
    row = centre_row(build("gaps", 0.4))
    runs = np.diff(np.flatnonzero(np.diff(np.r_[0, (row == 0).astype(int), 0])))[::2]  # lengths of the trenches
    outer = runs[[0, -1]] * SCALE.cell_size  # the outermost trench on either side (the centre may cut one short)
    assert runs.size >= 2 and np.all(np.abs(outer - 0.4) <= SCALE.cell_size + 1e-9), runs
    assert set(np.unique(row)) == {0.0, F.DEEP}
    wide, narrow = build("stepping_stones", 0.5), build("stepping_stones", 0.05)
    inner = F.edge_distance(SIZE, SCALE) >= F.START_STRIP
    assert (wide[inner] == 0).mean() > 2 * (narrow[inner] == 0).mean() > 0  # wider gaps, more of the ground open


def test_random_families_scale_with_their_level_and_follow_their_seed():
    for name in ("boxes", "obstacles", "waves", "rough"):
        lo, hi = F.FAMILIES[name].lo, F.FAMILIES[name].hi
        assert np.ptp(build(name, hi)) > np.ptp(build(name, lo)), name
        np.testing.assert_array_equal(build(name, hi, seed=3), build(name, hi, seed=3))
        assert not np.array_equal(build(name, hi, seed=3), build(name, hi, seed=4)), name
    assert np.ptp(build("rough", 0.05)) <= 0.1 + 1e-6 and np.ptp(build("waves", 0.1)) <= 0.2 + 1e-6


@pytest.fixture(scope="module")
def small():
    return suite.load("v1", size=64, seeds=2, samples=12, families=("flat", "stairs_up", "gaps"),
                      generator_names=("perlin", "diamond_square"))


def test_a_build_is_deterministic_and_says_what_it_holds(small):
    again = suite.load("v1", size=64, seeds=2, samples=12, families=("flat", "stairs_up", "gaps"),
                       generator_names=("perlin", "diamond_square"))
    np.testing.assert_array_equal(small.heightmaps, again.heightmaps)
    assert small.name.startswith("v1-custom") and small.families()[:3] == ("flat", "stairs_up", "gaps")
    for fam, levels in (("flat", 1), ("stairs_up", 10), ("gaps", 10)):
        rows = small.family == fam
        assert sorted(set(small.level[rows])) == list(range(levels))
        assert rows.sum() == levels * (1 if fam == "flat" else 2)
    stairs = small.family == "stairs_up"
    np.testing.assert_allclose(small.value[stairs & (small.level == 9)], 0.21)
    assert small.unit["gaps"] == "m width" and small.unit["gen:perlin"] == "cells"


def test_generator_samples_sit_in_the_level_of_their_descriptor_distance(small):
    gen = np.char.startswith(small.family.astype(str), "gen:")
    assert gen.sum() > 0
    level, dist = suite.descriptor_levels(small.heightmaps[gen])
    np.testing.assert_array_equal(level, small.level[gen])
    np.testing.assert_allclose(dist, small.value[gen], rtol=1e-6)
    assert np.all(np.floor(dist / (70.7107 / 10)) == np.minimum(level, 9))
    for fam in ("gen:perlin", "gen:diamond_square"):  # at most `seeds` per level, numbered from 0
        rows = small.family == fam
        for lv in np.unique(small.level[rows]):
            seeds = small.seed[rows & (small.level == lv)]
            assert list(seeds) == list(range(len(seeds))) and len(seeds) <= 2


def test_an_archive_becomes_a_one_family_suite_banded_by_cell_distance():
    from jaxterrain import qd

    bins, cells = 4, 16
    config = qd.resolve_config(qd.EvolveConfig(bins=bins, ranges=((0.0, 1.0), (0.0, 2.0))))
    source = np.full(cells, -1, np.int32)
    source[[15, 0, 5]] = 0
    fitness = np.where(source >= 0, 0.5, -np.inf).astype(np.float32)
    maps = np.zeros((cells, 32, 32), np.uint16)
    maps[5], maps[15] = 65535, 32768
    arch = qd.Archive((np.zeros((cells, 3), np.float32),), ("perlin",), source, fitness,
                      np.zeros((cells, 2), np.float32), np.asarray(qd.centroids_for(config)), maps, config, {})
    s = suite.archive_suite(arch)
    np.testing.assert_allclose(s.value, np.hypot([1, 2, 4], [1, 2, 4]), rtol=1e-6)  # cells 0, 5, 15: nearest first
    np.testing.assert_array_equal(s.level, [2, 5, 9])  # tenths of the way to the farthest cell, hypot(4, 4)
    np.testing.assert_allclose(s.heightmaps[:, 0, 0], [0.0, 1.0, 32768 / 65535], rtol=1e-6)
    assert s.families() == ("archive",) and s.unit == {"archive": "cells"} and list(s.seed) == [0, 0, 0]


def test_bad_input_is_one_value_error_naming_it():
    with pytest.raises(ValueError, match="suite must be one of v1"):
        suite.load("v0")
    with pytest.raises(ValueError, match="unknown 'nope'"):
        suite.load("v1", families=("nope",))
    with pytest.raises(ValueError, match="size must be an integer >= 32"):
        suite.load("v1", size=16)
    with pytest.raises(ValueError, match="family must be one of"):
        F.build_terrain("pit", 0.1)
