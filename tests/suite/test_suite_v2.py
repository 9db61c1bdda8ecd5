"""Held-out suite v2: each family's physical parameter grows with the level for every robot, start strips are flat,
a seed's random layout is the same at every level (the level alone orders a seed's terrains), builds are
deterministic, v1 is left as it was; the level-curve checks and the choice of levels from a measured grid; the
worst-decile robustness figure against a direct computation."""

from __future__ import annotations

import numpy as np
import pytest

from jaxterrain import suite
from jaxterrain.runtime import statistics
from jaxterrain.suite import calibration
from jaxterrain.suite import families as F
from jaxterrain.terrain import TerrainScale

SCALE = TerrainScale()  # 4 cm pixels, 1 m per unit: heightmap values are metres
SIZE = 128  # 5.08 m across: 1.54 m of room inside the start strips
GRADED = [f for f, fam in F.FAMILIES_V2.items() if fam.levels > 1]


def v2(name, value, seed=0, size=SIZE):
    return suite.v2_terrain(name, value, seed, size, SCALE)


def test_every_robot_has_ten_increasing_levels_of_every_graded_family_inside_its_bounds():
    assert set(suite.V2_LEVELS) == set(suite.ROBOTS) == {"humanoid", "ant"}
    for robot, table in suite.V2_LEVELS.items():
        assert set(table) == set(GRADED), robot
        for f, values in table.items():
            v = np.asarray(values)
            assert v.shape == (10,) and np.all(np.diff(v) > 0), (robot, f)
            assert F.FAMILIES_V2[f].lo <= v[0] and v[-1] <= F.FAMILIES_V2[f].hi, (robot, f)


def test_every_v2_family_is_flat_on_its_start_strip_and_inside_zero_one_at_every_robots_levels():
    strip = F.edge_distance(SIZE, SCALE) < F.START_STRIP
    for f in F.FAMILIES_V2:
        values = {v for t in suite.V2_LEVELS.values() for v in t.get(f, (0.0,))[:: 9]}
        for v in sorted(values):
            h = v2(f, v)
            assert h.dtype == np.float32 and 0.0 <= h.min() and h.max() <= 1.0, f
            assert np.ptp(h[strip]) == 0.0, f"{f} at {v}: the walker's start strip is not flat"


def test_each_familys_physical_parameter_grows_with_the_level():
    inner = F.edge_distance(SIZE, SCALE) >= F.START_STRIP
    for robot, table in suite.V2_LEVELS.items():
        for f in GRADED:
            maps = [v2(f, v) for v in table[f]]
            spread = [float(np.ptp(h[inner])) for h in maps]  # the relief the walker meets past the strip
            if f in ("slope_up", "slope_down"):  # grade: the rise over the first metre past the strip
                row = [h[SIZE // 2] for h in maps]
                x = np.arange(SIZE) * SCALE.cell_size
                at = [int(np.searchsorted(x, F.START_STRIP + d)) for d in (0.2, 0.6)]
                rise = [abs(r[at[1]] - r[at[0]]) for r in row]
                assert np.all(np.diff(rise) > 0), (robot, f, rise)
            elif f in ("stairs_up", "stairs_down"):  # the flight is V2_STEPS risers high: it grows with the riser
                np.testing.assert_allclose(spread, F.V2_STEPS * np.asarray(table[f]), atol=1e-5)
            elif f in ("gaps", "stepping_stones"):  # deeper gaps, and wider: 0.1 m + the depth
                np.testing.assert_allclose(spread, table[f], atol=1e-6)
                if f == "gaps":  # the outermost trench's width, to a pixel
                    first = [h[SIZE // 2, :60] for h in maps]  # 2.4 m: the strip and the first trench (1.3-1.9 m)
                    width = [float((r < r.max()).sum()) * SCALE.cell_size for r in first]
                    assert np.all(np.abs(np.array(width) - [F.v2_width(v) for v in table[f]]) <= 1.5 * SCALE.cell_size)
                    assert np.all(np.diff(width) >= 0) and width[-1] > width[0], (robot, width)
                else:
                    open_ = [float((h[inner] < h[inner].max()).mean()) for h in maps]
                    assert open_[-1] > open_[0] > 0, (robot, open_)
            else:  # heights and amplitudes: more relief, level by level
                assert np.all(np.diff(spread) > 0), (robot, f, spread)


def test_a_seeds_random_layout_is_the_same_at_every_level():
    lo, hi = 0.05, 0.2
    for f, base in (("boxes", 0.0), ("rough", 0.5), ("obstacles", F.V2_OBSTACLE_BASE), ("waves", 0.5)):
        a, b = (v2(f, v, seed=3).astype(np.float64) - base for v in (lo, hi))
        np.testing.assert_allclose(a / lo, b / hi, atol=2e-5 / lo, err_msg=f)  # the same draws, scaled by the level
        assert not np.array_equal(v2(f, hi, seed=3), v2(f, hi, seed=4)), f  # another seed, another layout


def test_v2_builds_are_deterministic_per_robot_and_v1_refuses_a_robot():
    kw = dict(size=128, seeds=2, families=("flat", "boxes", "gaps"), generator_names=())
    a, b = suite.load("v2", **kw), suite.load("v2", **kw)
    np.testing.assert_array_equal(a.heightmaps, b.heightmaps)
    assert a.robot == "humanoid" and a.name.startswith("v2:humanoid-custom")
    assert a.size == 1 + 2 * 10 * 2 and sorted(set(a.seed.tolist())) == [0, 1]
    ant = suite.load("v2", robot="ant", **kw)
    assert ant.robot == "ant" and not np.array_equal(ant.value, a.value)
    for s in (a, ant):  # each terrain is v2_terrain of its family, value and seed: the level does not seed it
        for i in (5, 17, 30):
            np.testing.assert_array_equal(s.heightmaps[i], v2(str(s.family[i]), float(s.value[i]), int(s.seed[i])))
    with pytest.raises(ValueError, match="robot"):
        suite.load("v1", robot="ant", **kw)
    with pytest.raises(ValueError, match="robot must be one of"):
        suite.load("v2", robot="cat", **kw)
    assert suite.VERSIONS["v2"]["seeds"] >= 5


def test_v2_keeps_every_generator_draw_and_the_robustness_figure_is_the_worst_decile():
    s = suite.load("v2", size=64, samples=7, families=("flat",), generator_names=("perlin",))
    gen = s.family == "gen:perlin"
    assert gen.sum() == 7  # every draw, whatever its band
    for lv in np.unique(s.level[gen]):
        assert sorted(s.seed[gen & (s.level == lv)].tolist()) == list(range(int((s.level[gen] == lv).sum())))
    fit = np.linspace(0.0, 1.0, s.size)
    r = suite.generator_robustness(fit, s.family)
    x = np.sort(fit[gen])
    assert r == {"perlin": {"samples": 7, "mean": pytest.approx(x.mean()), "cvar": pytest.approx(x[0])}}


def test_cvar_is_the_mean_of_the_worst_fraction():
    x = np.random.default_rng(0).uniform(size=40)
    assert statistics.cvar(x, 0.1) == pytest.approx(np.sort(x)[:4].mean())  # 4 whole values
    assert statistics.cvar(np.arange(15.0), 0.1) == pytest.approx((0.0 + 0.5 * 1.0) / 1.5)  # 1.5 values
    assert statistics.cvar([0.7], 0.1) == pytest.approx(0.7) and statistics.cvar(x, 1.0) == pytest.approx(x.mean())
    for bad in (0.0, 1.5, True):
        with pytest.raises(ValueError, match="alpha"):
            statistics.cvar(x, bad)
    with pytest.raises(ValueError, match="values"):
        statistics.cvar([np.nan])


def test_a_level_curve_is_checked_for_its_ends_and_its_rises():
    good = np.linspace(0.9, 0.2, 10)
    assert calibration.check_curve(good)["ok"]
    c = calibration.check_curve([0.79, 0.7, 0.74, 0.3])
    assert (c["ok_level0"], c["ok_last"], c["ok_rises"], c["rise_at"]) == (False, True, False, 2)
    assert c["max_rise"] == pytest.approx(0.04)
    assert not calibration.check_curve([0.9, 0.5, 0.31])["ok_last"]


def test_levels_picked_from_a_measured_grid_pass_and_spread_evenly():
    values = np.linspace(0.01, 0.3, 30)
    means = np.clip(1.1 - 3.5 * values, 0.0, 1.0) + np.where(np.arange(30) % 7 == 3, 0.05, 0.0)  # a few bumps
    idx = calibration.select_levels(values, means)
    assert idx is not None and idx.shape == (10,) and np.all(np.diff(idx) > 0)
    assert calibration.check_curve(means[idx])["ok"]
    assert calibration.select_levels(values[::5], means[::5]) is None  # 6 values: too coarse for 10 levels
    prop = calibration.propose_values(values[::5], means[::5])
    assert prop is not None and prop.shape == (10,) and np.all(np.diff(prop) >= 0)
    fit = calibration.decreasing_fit(means[::5])
    assert np.all(np.diff(fit) <= 0)
    assert calibration.propose_values(values[:5], means[:5]) is None  # never falls to 0.22: widen the range
