"""An evaluation a reader can trust (issue 59 item 6), on hand-made fitness tables (no walking): the highest level
passed counts only levels with every level below them passed; summary rows and figure rows carry short, unique
policy labels; the summary names the families dropped at the suite's size; ``levels.png`` colours a one-level family
by its result and keeps its title and colour-bar label inside the figure, clear of the ticks."""

from __future__ import annotations

import csv

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

from jaxterrain import suite
from jaxterrain.suite import outputs
from jaxterrain.terrain import TerrainScale

NAN = float("nan")
# stairs_up, level 0 -> 9: passed up to level 2, failed at 3-6, 0.91 at 7 and 0.95 at 8 (seed luck), failed at 9
STAIRS = [0.95, 0.93, 0.91, 0.5, 0.4, 0.3, 0.2, 0.91, 0.95, 0.1]


def hand_made(dropped=None, missing=None):
    """A suite of flat (one level), stairs_up (levels 0-9) and gen:perlin (levels 1-3: no sample reached level 0),
    one terrain per level; no heightmaps worth walking."""
    fam, lev = [], []
    for f, levels in (("flat", [0]), ("stairs_up", range(10)), ("gen:perlin", [1, 2, 3])):
        for lv in levels:
            fam.append(f), lev.append(lv)
    n = len(fam)
    return suite.Suite("hand-made", np.zeros((n, 64, 64), np.float32), np.array(fam), np.array(lev, np.int64),
                       np.zeros(n, np.int64), np.array(lev, np.float64),
                       {"flat": "-", "stairs_up": "m step", "gen:perlin": "cells"}, TerrainScale(), missing or {},
                       dropped or {})


def test_the_highest_level_passed_needs_every_level_below_it_passed():
    assert suite.highest_level_passed(STAIRS) == 2  # the old rule (any level passed) said 8
    assert suite.highest_level_passed([0.5] + [0.95] * 9) == -1  # level 0 failed: nothing counts
    assert suite.highest_level_passed([0.95] * 10) == 9 and suite.highest_level_passed([0.9]) == 0  # >= threshold
    assert suite.highest_level_passed([NAN, 0.95, 0.92, 0.3]) == 2  # a level the suite lacks is stepped over
    assert suite.highest_level_passed([0.95, NAN, 0.5, 0.99]) == 0
    assert suite.highest_level_passed([NAN, NAN]) == -1
    assert suite.highest_level_passed(STAIRS, threshold=0.5) == 3


def test_passed_levels_and_the_level_table_use_the_contiguous_rule():
    s = hand_made()
    fitness = np.array([1.0] + STAIRS + [0.95, 0.2, 0.95])  # perlin: level 1 passed, 2 failed, 3 passed
    assert suite.passed_levels(fitness, s) == {"flat": 0, "stairs_up": 2, "gen:perlin": 1}
    old = {f: int(np.flatnonzero(np.nan_to_num(p, nan=-1) >= 0.9).max()) for f, p in suite.level_fitness(fitness, s).items()}
    assert old == {"flat": 0, "stairs_up": 8, "gen:perlin": 3}  # what levels.csv said before: the two rules differ
    table = suite.level_table(["base"], s, fitness[None])
    assert [(f, lv) for _, f, lv, _, _ in table] == [("flat", 0), ("stairs_up", 2), ("gen:perlin", 1)]
    np.testing.assert_allclose(table[2][4], [NAN, 0.95, 0.2, 0.95])


def test_short_names_are_unique_and_relative_to_a_common_parent():
    assert suite.short_names(["base", "/r/ln/policies/trial_0", "/r/ln/policies/trial_1"]) == ["base", "trial_0", "trial_1"]
    assert suite.short_names(["base", "/r/runs/cppn/policies/trial_0", "/r/runs/perlin/policies/trial_0"]) == \
        ["base", "cppn/trial_0", "perlin/trial_0"]  # treatment/trial_K
    assert suite.short_names(["/a/b/policies/trial_3"]) == ["trial_3"]  # one folder: its last part
    assert suite.short_names(["runs/x/policies/trial_0", "runs/x/trial_0"]) == \
        ["policies/trial_0", "trial_0"]  # dropping `policies` would repeat a label: kept
    assert suite.short_names(["base", "/r/base"]) == ["base", "/r/base"]  # a folder called base keeps its whole name
    assert suite.short_names(["/r/p", "/r/p"]) == ["/r/p", "/r/p #2"]  # the same folder twice
    assert suite.short_names(["base"]) == ["base"] and suite.short_names([]) == []


def test_the_summary_says_the_rule_the_labels_and_what_was_dropped(tmp_path):
    s = hand_made(dropped={"gaps": "needs 1.20 m inside the start strip for a trench; 64 pixels of 0.04 m have 0.26 m"},
                  missing={"gan": "no weights"})
    names = ["base", "/r/runs/cppn/policies/trial_0", "/r/runs/perlin/policies/trial_0"]
    fitness = np.array([[1.0] + STAIRS + [0.95, 0.2, 0.95], [1.0] + [0.95] * 10 + [0.9] * 3, [0.2] * 14])
    out = suite.write_evaluation(tmp_path, names, s, fitness)
    assert out == {"base": {"flat": 0, "stairs_up": 2, "gen:perlin": 1},
                   names[1]: {"flat": 0, "stairs_up": 9, "gen:perlin": 3},
                   names[2]: {"flat": -1, "stairs_up": -1, "gen:perlin": -1}}
    with open(tmp_path / "levels.csv") as f:
        rows = list(csv.DictReader(f))
    assert [r["policy"] for r in rows[::3]] == names  # the CSVs keep the whole names
    assert [int(r["highest_level_passed"]) for r in rows] == [0, 2, 1, 0, 9, 3, -1, -1, -1]
    text = (tmp_path / "summary.md").read_text()
    assert "highest level passed with every level below it passed too" in text
    assert "| base | 0 (1.00) | 2 (0.61) | 1 (0.70) | 0.661 |" in text
    assert "| cppn/trial_0 | 0 (1.00) | 9 (0.95) | 3 (0.90) |" in text and "| perlin/trial_0 | - (0.20) |" in text
    assert "- `cppn/trial_0`: `/r/runs/cppn/policies/trial_0`\n" in text
    assert "Dropped at 64 x 64 pixels, not walked" in text and "- gaps: needs 1.20 m" in text
    assert "Left out: gan (no weights)" in text
    assert (tmp_path / "levels.png").stat().st_size > 1000
    robust = list(csv.DictReader((tmp_path / "robustness.csv").open()))  # 3 perlin samples: the worst 0.3 of one
    assert [(r["policy"], r["generator"], r["samples"]) for r in robust] == [(n, "perlin", "3") for n in names]
    assert [float(r["cvar10"]) for r in robust] == [0.2, 0.9, 0.2] and float(robust[0]["mean"]) == pytest.approx(0.7)
    assert "| base | 0.700 / 0.200 |" in text and "CVaR at 0.1" in text
    with pytest.raises(ValueError, match=r"fitness must have shape \[P, N\] = \(3, 14\)"):
        suite.write_evaluation(tmp_path / "bad", names, s, fitness[:2])
    plain = hand_made()
    suite.write_evaluation(tmp_path / "plain", ["base"], plain, fitness[:1])
    assert "Dropped" not in (tmp_path / "plain" / "summary.md").read_text()
    assert "Policies:" not in (tmp_path / "plain" / "summary.md").read_text()


def test_levels_png_colours_by_the_share_of_levels_and_fits_its_text():
    families, levels = ["flat", "stairs_up", "gen:perlin"], [1, 10, 4]
    passed = np.array([[0, 2, 1], [-1, 9, 3]])
    title = ("v1-custom(size=64, seeds=1, samples=4, families=3, generators=1)\nhighest level passed with every level "
             "below it (mean fitness >= 0.9)\ndropped at 64 pixels (too small for them): stairs_down, boxes, "
             "obstacles, stepping_stones, gaps, waves, rough")
    fig = outputs._levels_figure(["base", "cppn/trial_0"], families, passed, title, levels)
    ax, bar = fig.axes
    share = np.asarray(ax.images[0].get_array())
    np.testing.assert_allclose(share, [[1.0, 0.3, 0.5], [0.0, 1.0, 1.0]])  # flat passed: the top colour, not the worst
    assert ax.images[0].norm.vmin == 0.0 and ax.images[0].norm.vmax == 1.0
    assert [t.get_text() for t in ax.texts] == ["0", "2", "1", "-", "9", "3"]
    assert [t.get_text() for t in ax.get_yticklabels()] == ["base", "cppn/trial_0"]
    FigureCanvasAgg(fig).draw()
    r = fig.canvas.get_renderer()
    inside = fig.bbox.expanded(1.0, 1.0)
    for artist in (ax.title, bar.yaxis.label, *ax.get_xticklabels(), *ax.get_yticklabels()):
        box = artist.get_window_extent(r)
        assert box.x0 >= inside.x0 - 1 and box.x1 <= inside.x1 + 1 and box.y0 >= inside.y0 - 1 and box.y1 <= inside.y1 + 1, artist
    assert len(ax.title.get_text().splitlines()) > 3  # the long last line was wrapped, not cut
    label = bar.yaxis.label.get_window_extent(r)
    for tick in bar.get_yticklabels():
        assert not label.overlaps(tick.get_window_extent(r)), tick.get_text()
    assert not ax.title.get_window_extent(r).overlaps(ax.get_window_extent(r))


def test_walkers_of_one_network_config_share_one_evaluation_program():
    """``rl.policy_fn`` is cached per (config, action size), so ``suite.evaluate_policies`` hands ``difficulty`` the
    same function for every walker of one config and its program cache (keyed on that function) builds one program
    for all of them (issue 60: one compile per walker before). Nothing is compiled here."""
    from jaxterrain import difficulty, rl
    from jaxterrain.difficulty import evaluation

    base = rl.load_policy()
    a, b = rl.policy_fn(base.config, int(base.action_size)), rl.policy_fn(base.config, int(base.action_size))
    assert a is b
    other = rl.policy_fn(base.config._replace(policy_hidden=(8,)), int(base.action_size))
    assert other is not a  # another network: another function
    config = difficulty.default_env_config((128, 128), policy=base)
    first = evaluation._program(config, 2, 1, a, True, None, False)
    assert evaluation._program(config, 2, 1, b, True, None, False) is first
    assert evaluation._program(config, 2, 1, other, True, None, False) is not first
