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
    assert small.name.startswith("v1-custom(size=64") and "families=1," in small.name
    assert small.families()[0] == "flat" and set(small.dropped) == {"stairs_up", "gaps"}  # too small for them
    fams = suite.load("v1", size=128, seeds=2, families=("flat", "stairs_up", "gaps"), generator_names=())
    assert fams.families() == ("flat", "stairs_up", "gaps") and fams.dropped == {}
    for fam, levels in (("flat", 1), ("stairs_up", 10), ("gaps", 10)):
        rows = fams.family == fam
        assert sorted(set(fams.level[rows])) == list(range(levels))
        assert rows.sum() == levels * (1 if fam == "flat" else 2)
    stairs = fams.family == "stairs_up"
    np.testing.assert_allclose(fams.value[stairs & (fams.level == 9)], 0.21)
    assert fams.unit["gaps"] == "m width" and small.unit["gen:perlin"] == "cells" and "gaps" not in small.unit


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


# ----------------------------------------------------------------------------------------------------------------
# Families at their physical size: a map too small for a family's features drops the family; v1 is unchanged.


def test_each_familys_extent_is_what_its_hardest_level_needs():
    fam = F.FAMILIES
    assert fam["flat"].extent == 0.0
    for name in ("slope_up", "slope_down"):
        assert fam[name].extent == pytest.approx(F.TOP / fam[name].hi) == pytest.approx(2.0)  # 0.5 grade to 1 m
    for name in ("stairs_up", "stairs_down"):  # 4 risers of 0.21 m (0.84 m, below the 1 m top) on 3 whole treads
        assert fam[name].extent == pytest.approx((np.floor(F.TOP / fam[name].hi) - 1) * F.TREAD) == pytest.approx(0.93)
    assert fam["gaps"].extent == pytest.approx(F.TRENCH_START + fam["gaps"].hi + 0.3) == pytest.approx(1.2)
    assert fam["stepping_stones"].extent == pytest.approx(F.STONE + fam["stepping_stones"].hi) == pytest.approx(1.1)
    assert (fam["boxes"].extent, fam["obstacles"].extent, fam["rough"].extent) == pytest.approx((0.8, 1.0, 0.48))
    assert fam["waves"].extent == pytest.approx(F.FADE_IN + F.WAVELENGTH / 2) == pytest.approx(2.0)
    assert all(f.holds for n, f in fam.items() if n != "flat")


def test_room_and_which_families_fit_at_each_size():
    assert F.room(64, SCALE) == pytest.approx(0.26) and F.room(128, SCALE) == pytest.approx(1.54)
    assert F.room(256, SCALE) == pytest.approx(4.1) and F.room(16, SCALE) < 0
    fits = {size: [n for n in F.FAMILIES if F.misfit(n, size, SCALE) is None] for size in (64, 96, 128, 160, 256)}
    assert fits[64] == ["flat"]
    assert fits[96] == ["flat", "boxes", "rough"]
    assert fits[128] == ["flat", "stairs_up", "stairs_down", "boxes", "obstacles", "stepping_stones", "gaps", "rough"]
    assert fits[160] == fits[256] == list(F.FAMILIES)
    coarse = TerrainScale(cell_size=0.16)  # 64 pixels of 16 cm: 10.08 m across, room for every family
    assert [n for n in F.FAMILIES if F.misfit(n, 64, coarse) is None] == list(F.FAMILIES)
    why = F.misfit("gaps", 64, SCALE)
    assert why.startswith("needs 1.20 m inside the start strip") and why.endswith("64 pixels of 0.04 m have 0.26 m")


def test_a_family_that_does_not_fit_has_lost_its_features_and_one_that_fits_has_them():
    # at 64 pixels: no trench begins inside 0.26 m and the stairs are a single step (what smoke walked before)
    assert np.ptp(build("gaps", 0.6, size=64)) == 0.0
    assert np.unique(build("stairs_up", 0.21, size=64)).tolist() == pytest.approx([0.0, 0.21])
    # at 128 pixels: a whole trench of the widest level on either side, and the tallest stairs' whole flight
    row = centre_row(build("gaps", 0.6, size=128))
    runs = np.diff(np.flatnonzero(np.diff(np.r_[0, (row == 0).astype(int), 0])))[::2] * SCALE.cell_size
    assert np.all(np.abs(runs[[0, -1]] - 0.6) <= SCALE.cell_size + 1e-9), runs  # (the centre cuts the next one short)
    assert np.unique(build("stairs_up", 0.21, size=128)) == pytest.approx(0.21 * np.arange(5))  # 4 risers to 0.84 m


def test_a_small_build_drops_the_families_that_do_not_fit_and_keeps_the_rest_as_they_were():
    s = suite.load("v1", size=128, seeds=1, families=("slope_up", "boxes", "waves", "gaps"), generator_names=())
    assert s.families() == ("boxes", "gaps") and list(s.dropped) == ["slope_up", "waves"]
    assert "needs 2.00 m" in s.dropped["slope_up"] and "128 pixels of 0.04 m have 1.54 m" in s.dropped["waves"]
    assert set(s.unit) == {"boxes", "gaps"} and "families=2," in s.name
    boxes = s.heightmaps[s.family == "boxes"]  # seeded by its place in `families` (1), the dropped slope counted
    for lv, v in enumerate(F.FAMILIES["boxes"].values()):
        want = F.build_terrain("boxes", v, 128, SCALE, np.random.default_rng((suite.SEED, 1, lv, 0)))
        np.testing.assert_array_equal(boxes[lv], want)
    with pytest.raises(ValueError, match=r"^size 64 pixels holds none of the families asked for: gaps needs 1.20 m"):
        suite.load("v1", size=64, families=("gaps",), generator_names=())
    assert "cell_size=0.16" in suite.load("v1", size=64, families=("flat",), generator_names=(),
                                          scale=TerrainScale(cell_size=0.16)).name


# sha256 of each v1 family's heightmaps (float32 bytes, in suite order) at its default size, computed with the code
# before families could be dropped (2026-11-29). Families built from numpy's exactly rounded operations (+ - * /,
# floor, %, comparisons, PCG64 draws) are the same bytes on any CPU; waves use np.sin, whose SIMD kernels may differ
# by an ulp between CPUs, so they are checked by their moments to a tolerance instead.
V1_SHA256 = {
    "flat": "8a39d2abd3999ab73c34db2476849cddf303ce389b35826850f9a700589b4a90",
    "slope_up": "5753985f36a82be88df15caa4868c05ef3c516f169a4a8f49b2e3d45d4930a66",
    "slope_down": "1d4ba5f23e26e70d2b4b9464f96f85306f151924203868bd85b4cf1b24299f53",
    "stairs_up": "47a74e863b4d3124a344ab6f5595e611c96e5e61a471d51932ce8ca860607c2a",
    "stairs_down": "801d50b639fe5b5344afeea8c5e0f92444a62a47c4c42aad223cc6785d647757",
    "boxes": "8a9b10c12aa6610112608e55186f5defae86d4e7acbc0235bad65ba1e6315e86",
    "obstacles": "8c94dd3f32a6ce0fb08e91f171eca2a45e4557bef99bf07c79a46a458ddea86a",
    "stepping_stones": "16d6dc96f70377c942c9e3547c39969d414c863a324bea7d39e69ad0cfce79a2",
    "gaps": "999a1b061fbd2e9914142d07f804fb645754af92cc61fc84913f9d96f7f95a18",
    "rough": "313c9cfae1fbf1756c6d66ee066e8721c9153dd6ef921f5b7576dbfe1c2cba66",
}
V1_WAVES_MOMENTS = (982518.852233842, 498462.7699334241)  # sum and sum of squares of the 30 wave maps


def test_v1_families_at_the_default_size_are_unchanged():
    import hashlib

    s = suite.load("v1", generator_names=())  # v1's family terrains (the generators' samples are JAX, not here)
    assert s.dropped == {} and s.heightmaps.shape == (301, 256, 256) and s.families() == tuple(F.FAMILIES)
    for fam, digest in V1_SHA256.items():
        maps = np.ascontiguousarray(s.heightmaps[s.family == fam], np.float32)
        assert hashlib.sha256(maps.tobytes()).hexdigest() == digest, fam
    waves = s.heightmaps[s.family == "waves"].astype(np.float64)
    assert (waves.sum(), (waves ** 2).sum()) == pytest.approx(V1_WAVES_MOMENTS, rel=1e-9)
    assert all(F.misfit(f, suite.VERSIONS["v1"]["size"], SCALE) is None for f in suite.VERSIONS["v1"]["families"])
