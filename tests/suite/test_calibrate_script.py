"""``docs/results/suite_v2/calibrate.py``: its candidate terrains are v2's own (a value picked as a level is that
level's terrain), its page picks levels that pass the checks from measured curves and marks what fails, ``--select``
rewrites the page from the CSVs, and (slow) it walks a robot's base policy at CPU size and resumes without walking
again."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from jaxterrain import suite
from jaxterrain.suite import calibration
from scripts import load_script

SCRIPT = Path(__file__).resolve().parents[2] / "docs" / "results" / "suite_v2" / "calibrate.py"


@pytest.fixture(scope="module")
def cal():
    module = load_script(SCRIPT, "suite_v2_calibrate")
    return module


def test_every_robot_has_a_candidate_range_for_every_graded_family_inside_v2s_bounds(cal):
    graded = [f for f, fam in suite.FAMILIES_V2.items() if fam.levels > 1]
    for robot, grid in [(r, g) for r in suite.ROBOTS for g in (cal.CANDIDATES, cal.REFINED)]:
        assert sorted(grid[robot]) == sorted(graded)
        for f, spec in grid[robot].items():
            v = cal.grid_values(spec, 20)
            assert v.shape == (20,) and np.all(np.diff(v) > 0), (robot, f)
            assert suite.FAMILIES_V2[f].lo <= v[0] and v[-1] <= suite.FAMILIES_V2[f].hi + 1e-12, (robot, f)
    np.testing.assert_allclose(cal.grid_values(("geo", 0.01, 1.0), 3), [0.01, 0.1, 1.0])


def test_the_candidate_terrains_are_v2s_terrains(cal):
    maps, rows = cal.build("ant", "candidates", 3, 2, 96, ["flat", "boxes"])
    assert len(rows) == 1 + 3 * 2 and maps.shape == (7, 96, 96)
    for h, (f, i, v, unit, s) in zip(maps, rows):
        np.testing.assert_array_equal(h, suite.v2_terrain(f, v, s, 96))
    _, rows = cal.build("ant", "refined", 3, 1, 96, ["boxes"])
    np.testing.assert_allclose([r[2] for r in rows], cal.grid_values(cal.REFINED["ant"]["boxes"], 3))
    maps, rows = cal.build("humanoid", "v2", 3, 1, 96, ["boxes"])
    assert [r[2] for r in rows] == list(suite.V2_LEVELS["humanoid"]["boxes"])


def test_a_range_replaces_one_familys_grid_and_bad_ranges_are_one_line(cal, capsys):
    fam, spec = cal.parse_range("slope_up=geo:0.3:1.0")
    assert (fam, spec) == ("slope_up", ("geo", 0.3, 1.0))
    _, rows = cal.build("ant", "candidates", 3, 1, 96, ["slope_up", "boxes"], {fam: spec})
    np.testing.assert_allclose([r[2] for r in rows[:3]], cal.grid_values(spec, 3))
    np.testing.assert_allclose([r[2] for r in rows[3:]], cal.grid_values(cal.CANDIDATES["ant"]["boxes"], 3))
    for text, why in (("flat=lin:0:1", "FAMILY must be one of"), ("slope_up=log:0.3:1", "lin|geo:LO:HI"),
                      ("slope_up=geo:0.3:x", "must be numbers"), ("slope_up=geo:0.3:2", "0.02 <= LO < HI <= 1")):
        with pytest.raises(SystemExit) as stop:
            cal.main(["--range", text])
        assert stop.value.code == 2 and why in capsys.readouterr().err, text


def write_fitness(folder: Path, robot: str, curves: dict, grid: str = "candidates"):
    """``fitness_<robot>.csv`` and ``timing_<robot>.json`` as ``walk`` writes them: ``curves`` {family: (values,
    [values, seeds] fitness)}."""
    folder.mkdir(parents=True, exist_ok=True)
    with (folder / f"fitness_{robot}.csv").open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["robot", "family", "index", "value", "unit", "seed", "fitness"])
        for f, (values, fit) in curves.items():
            for i, (v, row) in enumerate(zip(values, fit)):
                for s, x in enumerate(row):
                    w.writerow([robot, f, i, f"{v:.6g}", "m", s, f"{x:.4f}"])
    (folder / f"timing_{robot}.json").write_text(json.dumps({"robot": robot, "grid": grid, "terrains": 1}))


def test_the_page_picks_measured_levels_that_pass_and_marks_what_cannot(cal, tmp_path):
    values = np.linspace(0.01, 0.3, 25)
    good = np.clip(1.1 - 3.5 * values, 0.0, 1.0)[:, None] + np.array([-0.02, 0.0, 0.02])  # three seeds
    coarse_v = values[::4]  # 7 values: too few for 10 levels, so interpolated (not measured)
    narrow = np.full((25, 3), 0.95)  # never falls: the range must widen
    write_fitness(tmp_path, "humanoid", {"flat": ([0.0], [[1.0]]), "boxes": (values, good),
                                         "rough": (coarse_v, good[::4]), "waves": (values, narrow)})
    assert cal.main(["--select", str(tmp_path)]) == 0
    levels = json.loads((tmp_path / "levels.json").read_text())["humanoid"]
    picked = np.array(levels["boxes"]["values"])
    assert levels["boxes"]["measured"] and picked.shape == (10,) and np.all(np.diff(picked) > 0)
    means = np.interp(picked, values, good.mean(axis=1))
    assert calibration.check_curve(means)["ok"]
    assert not levels["rough"]["measured"] and len(levels["rough"]["values"]) == 10
    assert levels["waves"] == {"values": None, "measured": False}
    literal = (tmp_path / "V2_LEVELS.txt").read_text()
    assert literal.startswith('    "humanoid": {\n        "boxes": (') and "# waves: no values" in literal
    assert "NOT MEASURED" in literal and max(map(len, literal.splitlines())) <= 120
    md = (tmp_path / "calibration_humanoid.md").read_text()
    assert md.startswith("# Held-out suite v2: calibration for the humanoid")
    assert "| boxes | m | 25 |" in md and "pass (measured grid values)" in md
    assert "**not measured**" in md and "**FAIL**: the grid does not span" in md
    rows = list(csv.DictReader((tmp_path / "curves.csv").open()))
    assert len(rows) == 1 + 25 + 7 + 25 and float(rows[1]["mean"]) == pytest.approx(good[0].mean(), abs=1e-4)
    assert (tmp_path / "curves.png").stat().st_size > 1000


def test_a_v2_grid_is_checked_level_by_level_and_failures_are_marked(cal, tmp_path):
    v = np.asarray(suite.V2_LEVELS["ant"]["gaps"])
    fit = np.linspace(0.9, 0.25, 10)
    fit[6] += 0.12  # 0.12 - 0.072 = 0.048 above level 5
    write_fitness(tmp_path, "ant", {"gaps": (v, fit[:, None].repeat(5, 1))}, grid="v2")
    assert cal.main(["--select", str(tmp_path)]) == 0
    md = (tmp_path / "calibration_ant.md").read_text()
    assert "| gaps | m | 10 | 0.900 | 0.250 | +0.048 (6) | **FAIL**: rise > 0.03 (v2's levels) |" in md


def test_bad_flags_are_one_line_naming_them(cal, capsys):
    for argv, text in ((["--robots", "dog"], "--robots: unknown dog"), (["--families", "nope"], "--families"),
                       (["--values", "1"], "--values must be an integer >= 2"),
                       (["--best", "30", "--attempts", "80"], "--best must be <= attempts / headings = 20")):
        with pytest.raises(SystemExit) as stop:
            cal.main(argv)
        assert stop.value.code == 2 and text in capsys.readouterr().err


@pytest.mark.slow
def test_the_script_walks_a_base_policy_at_cpu_size_and_resumes_without_walking_again(cal, tmp_path, capsys):
    """The humanoid's base policy on 5 terrains of 96 pixels, 2 walks each (one MJX compile: a minute or more of
    CPU); a second call finds its fitness file and only rewrites the page."""
    argv = ["--out", str(tmp_path), "--robots", "humanoid", "--size", "96", "--families", "flat", "boxes",
            "--values", "2", "--seeds", "2", "--attempts", "2", "--best", "1", "--headings", "1", "--slots", "0"]
    assert cal.main(argv) == 0
    rows = list(csv.DictReader((tmp_path / "fitness_humanoid.csv").open()))
    assert len(rows) == 5 and all(0.0 <= float(r["fitness"]) <= 1.0 for r in rows)
    assert float(rows[0]["fitness"]) == pytest.approx(1.0)  # flat ground: the walker crosses it
    timing = json.loads((tmp_path / "timing_humanoid.json").read_text())
    assert timing["terrains"] == 5 and timing["grid"] == "candidates" and timing["protocol"]["attempts"] == 2
    capsys.readouterr()
    assert cal.main(argv) == 0
    assert "exists; not walked again" in capsys.readouterr().out
    assert "| boxes |" in (tmp_path / "calibration_humanoid.md").read_text()
