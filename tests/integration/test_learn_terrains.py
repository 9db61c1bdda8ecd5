"""``learn --terrains DIR`` and ``evaluate --terrains DIR``: your own heightmaps in one line (issue 62, item 5).

The levels run compiles its own block (no other test of the default suite runs the levels curriculum through the
real walker): the suite's longest test, 174 s of CPU run alone (2026-11-30: about a third tracing, most of the
rest the XLA compile at the smoke preset's cheap options). It is the default suite's end-to-end test of
``learn --curriculum levels`` (``test_learn_command.py``'s ``levels`` case is slow: the same compile a second
time)."""

import json
import shutil

import numpy as np
import pytest

from terrain_tiles import write_tiles


def cli(*argv):
    from experiments.__main__ import main

    return main(list(argv))


def run_cli(*argv) -> int:
    try:  # the runner's checks return 2; the flag checks before it (experiments.common) exit with 2
        return cli(*argv)
    except SystemExit as stop:
        return stop.code


def test_learn_trains_on_a_folder_of_heightmaps_stops_and_resumes(tmp_path, capsys):
    tiles = write_tiles(tmp_path / "tiles")
    out = tmp_path / "run"
    argv = ("learn", "--preset", "smoke", "--terrains", str(tiles), "--terrain-height", "0.2",
            "--curriculum", "levels", "--levels", "2", "--out", str(out))
    assert cli(*argv, "--time-limit", "0.0001") == 3  # stopped after its first chunk, checkpointed
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["terrains"] == str(tiles) and cfg["terrain_height"] == 0.2 and cfg["terrain_order"] == "name"
    rows = (out / "terrains.csv").read_text().splitlines()
    assert rows[0] == "file,sha256,relief_m,base_fitness,hardness" and [r.split(",")[0] for r in rows[1:]] == [
        "a_ramp.npy", "b_grey8.png", "c_grey16.png", "d_dem.tif"] and [r.split(",")[-1] for r in rows[1:]] == [
        "0", "1", "2", "3"]

    saved = (tiles / "b_grey8.png").read_bytes()  # another file under the same name: refused on resume
    shutil.copy(tiles / "c_grey16.png", tiles / "b_grey8.png")
    capsys.readouterr()
    assert cli("learn", "--resume", str(out)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--terrains" in err[0] and "not the ones" in err[0], err
    (tiles / "b_grey8.png").write_bytes(saved)

    assert cli("learn", "--resume", str(out)) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["epochs"] == [4, 4] and summary["bank_terrains"] == 4
    assert all(0 <= h <= 3 for h in summary["hardest"])  # the hardest traversed: a rank in file-name order
    assert all(0 <= v <= 1 for v in summary["max_level"]) and all(m >= 0 for m in summary["level_moves"])
    assert summary["ended_without_terrains"] == [False, False]  # the levels curriculum end to end (its CLI test)
    seq = (out / "sequences.csv").read_text().splitlines()
    assert all(r.split(",")[-1] in {"a_ramp.npy", "b_grey8.png", "c_grey16.png", "d_dem.tif"} for r in seq[1:])
    evals = [float(r.split(",")[9]) for r in (out / "history.csv").read_text().splitlines()[1:]]
    assert len(evals) == 8 and all(0 <= e <= 1 for e in evals) and max(evals) > 0  # the policy walked
    meta = json.loads((out / "policies" / "trial_0" / "config.json").read_text())["curriculum"]
    assert meta["archive"] is None and meta["terrain_folder"].endswith("tiles")
    assert "done: hardest traversed" in capsys.readouterr().out


@pytest.mark.slow
def test_learn_on_a_folder_defaults_to_domain_randomisation(tmp_path):
    """``learn --terrains DIR --preset smoke``, nothing else: ``dr`` over the folder's terrains."""
    tiles = write_tiles(tmp_path / "tiles")
    (tiles / "d_dem.tif").unlink()  # 40 m of relief: it would need --terrain-height
    out = tmp_path / "dr"
    assert cli("learn", "--preset", "smoke", "--terrains", str(tiles), "--out", str(out)) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert json.loads((out / "config.json").read_text())["curriculum"] == "dr"
    assert summary["terrains_drawn"] == [40, 40] and summary["bank_terrains"] == 3  # 8 at the start and per chunk


def test_learn_refuses_a_bad_folder_in_one_line_before_any_run_folder(tmp_path, capsys):
    tiles = write_tiles(tmp_path / "tiles")
    empty = tmp_path / "empty"
    empty.mkdir()
    nan = tmp_path / "nan"
    nan.mkdir()
    np.save(nan / "hole.npy", np.where(np.eye(6) > 0, np.nan, 0.1))
    cases = [
        (["--terrains", str(tmp_path / "missing")], "--terrains"),
        (["--terrains", str(empty)], "no heightmap files"),
        (["--terrains", str(nan)], "hole.npy: 6 NaN"),
        (["--terrains", str(tiles)], "d_dem.tif: its relief is 39.97 m"),
        (["--terrains", str(tiles), "--terrain-height", "3"], "--terrain-height must be"),
        (["--terrains", str(tiles), "--terrain-height", "0.2", "--curriculum", "map"], "--curriculum map needs an archive"),
        (["--terrains", str(tiles), "--terrain-height", "0.2", "--curriculum", "roughness"], "roughness needs"),
        (["--terrains", str(tiles), "--archive", "x.npz"], "give one"),
        (["--terrain-order", "difficulty"], "--terrain-order applies to --terrains"),
    ]
    for i, (argv, needle) in enumerate(cases):
        out = tmp_path / f"run{i}"
        assert run_cli("learn", "--preset", "smoke", "--out", str(out), *argv) == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and needle in err[0], (argv, err)
        assert not out.exists()


def test_evaluate_refuses_a_bad_folder_in_one_line(tmp_path, capsys):
    tiles = write_tiles(tmp_path / "tiles")
    for i, (argv, needle) in enumerate([
            (["--terrains", str(tmp_path / "missing")], "--terrains"),
            (["--terrains", str(tiles)], "d_dem.tif: its relief is 39.97 m"),
            (["--terrains", str(tiles), "--terrain-height", "0.2", "--archive", "x.npz"], "--archive"),
            (["--terrain-height", "0.2"], "--terrain-height applies to --terrains")]):
        out = tmp_path / f"ev{i}"
        assert run_cli("evaluate", "--preset", "smoke", "--out", str(out), *argv) == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and needle in err[0], (argv, err)
        assert not out.exists()


@pytest.mark.slow
def test_evaluate_walks_a_folder_of_heightmaps(tmp_path):
    """``evaluate --terrains DIR --preset smoke``: the base policy on each file, one family per file, the suite's
    outputs (128 x 128 cells: the smoke preset's --size)."""
    tiles = write_tiles(tmp_path / "tiles")
    out = tmp_path / "ev"
    assert cli("evaluate", "--preset", "smoke", "--terrains", str(tiles), "--terrain-height", "0.2",
               "--out", str(out)) == 0
    rows = [r.split(",") for r in (out / "fitness.csv").read_text().splitlines()[1:]]
    assert [(r[0], r[1], r[5]) for r in rows] == [("base", n, "m relief") for n in
                                                  ("a_ramp.npy", "b_grey8.png", "c_grey16.png", "d_dem.tif")]
    assert all(0 <= float(r[6]) <= 1 for r in rows)
    assert "| base |" in (out / "summary.md").read_text() and (out / "suite.png").stat().st_size > 0


@pytest.mark.slow
def test_learn_levels_by_the_base_policys_difficulty_measures_the_order_once(tmp_path):
    """``--terrain-order difficulty``: the start policy walks every terrain before the run (its fitness and rank in
    terrains.csv); the levels' bands and the hardest traversed read that rank."""
    from jaxterrain import suite

    tiles = write_tiles(tmp_path / "tiles")
    out = tmp_path / "levels"
    assert cli("learn", "--preset", "smoke", "--terrains", str(tiles), "--terrain-height", "0.2", "--curriculum",
               "levels", "--levels", "2", "--terrain-order", "difficulty", "--out", str(out)) == 0
    rows = [r.split(",") for r in (out / "terrains.csv").read_text().splitlines()[1:]]
    fitness = [float(r[3]) for r in rows]
    assert all(0 <= f <= 1 for f in fitness)
    assert [int(r[4]) for r in rows] == suite.difficulty_order(fitness).astype(int).tolist()
    assert json.loads((out / "config.json").read_text())["terrain_order"] == "difficulty"
