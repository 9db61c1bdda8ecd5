"""``python -m experiments evaluate`` at its smoke size (128 pixels) on a CPU: the base policy, a copy of it and a
walker with no policy (zero weights) on two suite families; the files it writes agree with each other and with the
walks, and a policy for another observation set is refused before anything is written."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import jax
import numpy as np
import pytest

from jaxterrain import rl, suite
from jaxterrain.rl import networks as nets


def cli(*argv):
    from experiments.__main__ import main

    return main(list(argv))


@pytest.fixture(scope="module")
def policies(tmp_path_factory):
    """``(copy of the base policy, a walker whose policy net is all zeros, a policy for 53 observations)``."""
    root = tmp_path_factory.mktemp("policies")
    base = rl.load_policy()
    copy = root / "copy"
    shutil.copytree(rl.BASE_POLICY_DIR, copy)
    still = rl.save_policy(root / "still", {**base.params, "policy": jax.tree.map(np.zeros_like, base.params["policy"])},
                           base.normaliser, base.config, base.observation_size, base.action_size,
                           extra={"walker_config": base.meta["walker_config"]})
    other = rl.save_policy(root / "other", nets.init_params(jax.random.key(0), base.config, 53, base.action_size),
                           nets.init_stats(53), base.config, 53, base.action_size)
    return copy, still, other


@pytest.fixture(scope="module")
def run(tmp_path_factory, policies):
    copy, still, _ = policies
    out = tmp_path_factory.mktemp("evaluate") / "run"
    assert cli("evaluate", "--preset", "smoke", "--families", "flat", "gaps", "--generators", "--policy", str(copy),
               str(still), "--keys", "2", "--out", str(out)) == 0
    return out


def read(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def test_every_policy_walks_every_terrain_with_the_same_key(run, policies):
    """... and ``--keys 2`` walks the base policy a second time with another key (``base:key1``)."""
    rows = read(run / "fitness.csv")
    names = ["base", "base:key1", str(policies[0]), str(policies[1])]
    assert [r["policy"] for r in rows[:: len(rows) // 4]] == names
    fit = np.array([float(r["fitness"]) for r in rows]).reshape(4, -1)
    assert fit.shape[1] == 1 + 10  # flat, then gaps at levels 0-9, one terrain each
    np.testing.assert_array_equal(fit[0], fit[2])  # the same weights, the same key: the same walks
    assert not np.array_equal(fit[0], fit[1])  # the same weights, another key: other walks
    flat = [i for i, r in enumerate(rows[: fit.shape[1]]) if r["family"] == "flat"]
    assert fit[0, flat] == pytest.approx(1.0) and fit[3, flat][0] < 0.5  # the walker without a policy falls
    assert [r["unit"] for r in rows[1:11]] == ["m width"] * 10
    np.testing.assert_allclose([float(r["value"]) for r in rows[1:11]], suite.FAMILIES["gaps"].values(), rtol=1e-3)


def test_levels_and_summary_follow_from_the_fitness(run):
    rows = read(run / "fitness.csv")
    levels = read(run / "levels.csv")
    for lv in levels:
        mine = [r for r in rows if r["policy"] == lv["policy"] and r["family"] == lv["family"]]
        per = {}
        for r in mine:
            per.setdefault(int(r["level"]), []).append(float(r["fitness"]))
        highest = -1  # the highest level with every level below it passed too
        while highest + 1 in per and np.mean(per[highest + 1]) >= 0.9:
            highest += 1
        assert int(lv["highest_level_passed"]) == highest
        assert float(lv["mean_fitness"]) == pytest.approx(np.mean([float(r["fitness"]) for r in mine]), abs=1e-4)
    summary = (run / "summary.md").read_text()
    assert summary.count("\n| ") == 5 and "| flat | gaps | mean |" in summary
    assert "\n| copy | " in summary and "\n| still | " in summary  # the folders, relative to their common parent
    assert "Dropped" not in summary  # 128 pixels hold a whole trench of every level of gaps
    assert (run / "levels.png").stat().st_size > 1000 and (run / "suite.png").stat().st_size > 1000
    timing = json.loads((run / "timing.json").read_text())
    assert timing["terrains"] == 11 and timing["policies"] == 3 and timing["walk_s_one_policy"] is None
    assert timing["base_keys"] == 2
    assert timing["backend"] == "jax" and "warp_hfield" not in timing  # recorded for MuJoCo Warp walks only
    assert timing["spawn"] == "feet"  # the walkers spawned by the default rule


def test_a_policy_for_another_robot_is_refused_before_anything_is_written(tmp_path, policies, capsys):
    with pytest.raises(SystemExit) as stop:
        cli("evaluate", "--preset", "smoke", "--policy", str(policies[2]), "--out", str(tmp_path / "x"))
    err = capsys.readouterr().err.strip().splitlines()
    assert stop.value.code == 2 and len(err) == 1
    assert str(policies[2]) in err[0] and "observations 53" in err[0]
    assert not (tmp_path / "x").exists()
    with pytest.raises(ValueError, match="not a policy loaded by rl.load_policy"):
        suite.check_policies([lambda obs: obs], (64, 64), suite.load("v1", size=64, families=("flat",),
                                                                     generator_names=()).scale)


def test_a_size_that_holds_none_of_the_families_is_one_line(tmp_path, capsys):
    """``--size 64`` leaves 0.26 m of ground inside the 1 m start strips: no trench of ``gaps`` fits, so a suite of
    gaps alone is refused, with the reason, before anything walks."""
    with pytest.raises(SystemExit) as stop:
        cli("evaluate", "--preset", "smoke", "--size", "64", "--families", "gaps", "--generators", "--out",
            str(tmp_path / "x"))
    err = capsys.readouterr().err.strip().splitlines()
    assert stop.value.code == 2 and len(err) == 1
    assert "--size 64 pixels holds none of the families asked for: gaps needs 1.20 m" in err[0]


@pytest.mark.slow
def test_videos_show_each_walker_beside_the_base_policy(tmp_path, policies, capsys, monkeypatch):
    """``evaluate --videos`` on flat ground (smoke size): without an OpenGL backend one line says why and the
    evaluation is written all the same; with one, the walker without a policy (it fails flat ground: its first
    failed level) walks beside the base policy in one GIF of two panels, listed in ``videos.csv`` with the
    evaluation's level fitness of both (a few minutes on 2 CPU cores: two compiles); with the video extra
    (``--video-format both``) an MP4 of the same frames beside the GIF."""
    import importlib.util
    import io

    from PIL import Image

    from jaxterrain.report import compare, render

    _, still, _ = policies
    argv = ["evaluate", "--preset", "smoke", "--families", "flat", "--generators", "--policy", str(still), "--videos",
            "--video-frames", "3", "--video-width", "64", "--video-height", "48", "--video-starts", "2"]
    with monkeypatch.context() as m:
        m.setattr(render, "gl_status", lambda: (False, "no OpenGL backend (test)"))
        assert cli(*argv, "--out", str(tmp_path / "nogl")) == 0
    err = capsys.readouterr().err
    assert "evaluate: videos skipped: no OpenGL backend (test)" in err
    assert (tmp_path / "nogl" / "fitness.csv").is_file() and not (tmp_path / "nogl" / "videos").exists()
    ok, why = render.gl_status()
    if not ok:
        pytest.skip(why)
    out = tmp_path / "run"
    mp4 = importlib.util.find_spec("imageio_ffmpeg") is not None  # the video extra (in the test extra)
    assert cli(*argv, *(["--video-format", "both"] if mp4 else []), "--out", str(out)) == 0
    (row,) = read(out / "videos" / "videos.csv")
    assert (row["walker"], row["family"], row["level"], row["file"]) == ("still", "flat", "0", "still/flat_L0.gif")
    levels = {r["policy"]: r for r in read(out / "levels.csv")}
    assert float(row["base_level_fitness"]) == pytest.approx(float(levels["base"]["per_level_fitness"]), abs=1e-3)
    assert float(row["walker_level_fitness"]) < 0.5 and row["starts"] == "2"
    assert "fell" in row["walker_walk"]  # no policy: it falls
    with Image.open(io.BytesIO((out / "videos" / row["file"]).read_bytes())) as im:
        assert im.size == (2 * 64 + compare.PANEL_GAP, compare.LABEL_HEIGHT + 48) and 2 <= im.n_frames <= 3
        n = im.n_frames
    if mp4:
        import imageio_ffmpeg

        assert row["mp4"] == "still/flat_L0.mp4"
        count, _ = imageio_ffmpeg.count_frames_and_secs(str(out / "videos" / row["mp4"]))
        reader = imageio_ffmpeg.read_frames(str(out / "videos" / row["mp4"]))
        meta = next(reader)
        reader.close()
        assert count == n == int(row["frames"]) and meta["size"] == (2 * 64 + compare.PANEL_GAP,
                                                                      compare.LABEL_HEIGHT + 48)
    assert json.loads((out / "timing.json").read_text())["videos_s"] > 0


def test_engine_mujoco_walks_the_suite_with_mujoco_c_beside_mjx(tmp_path, run):
    """``--engine mujoco``: the same outputs, walked by MuJoCo's C engine from the same starts (sim2sim); the base
    policy crosses the flat map under both engines (MJX: the ``run`` fixture, same seed and size)."""
    out = tmp_path / "c"
    assert cli("evaluate", "--preset", "smoke", "--engine", "mujoco", "--families", "flat", "--generators",
               "--workers", "1", "--out", str(out)) == 0
    for name in ("config.json", "fitness.csv", "levels.csv", "summary.md", "timing.json"):
        assert (out / name).is_file(), name
    timing = json.loads((out / "timing.json").read_text())
    assert timing["engine"] == "mujoco" and timing["workers"] == 1
    c = [r for r in read(out / "fitness.csv") if r["policy"] == "base"]
    mjx = [r for r in read(run / "fitness.csv") if r["policy"] == "base" and r["family"] == "flat"]
    assert len(c) == len(mjx) == 1
    assert abs(float(c[0]["fitness"]) - float(mjx[0]["fitness"])) <= 0.05


def test_a_time_limit_stops_between_policies_and_resume_walks_only_the_rows_left(tmp_path, run, policies, capsys,
                                                                                  monkeypatch):
    """``--time-limit`` (here 6 ms: past after the first walk) stops after one policy row with exit code 3, the row
    kept in ``walked.npz`` and no tables written; ``--resume`` (from another directory: the policies were given
    relative to the first) walks the three rows left and writes the same fitness as the ``run`` fixture's one call
    (same policies, keys and terrains, one process). ``--repeat``'s walk (the first row again, compiled) is kept in
    ``walked.npz`` through the stop and reported by the resumed call's ``timing.json``."""
    from jaxterrain.suite import runs

    copy, still, _ = policies
    out = tmp_path / "cut"
    monkeypatch.chdir(copy.parent)
    assert cli("evaluate", "--preset", "smoke", "--families", "flat", "gaps", "--generators", "--policy", copy.name,
               still.name, "--keys", "2", "--repeat", "--out", str(out), "--time-limit", "0.0001") == 3
    monkeypatch.chdir(tmp_path)
    assert "continue with: python -m experiments evaluate --resume" in capsys.readouterr().out
    with np.load(out / runs.PROGRESS) as z:
        assert z["fitness"].shape == (1, 11) and json.loads(str(z["repeat"]))["equal"] is True
    assert not (out / "fitness.csv").exists()
    assert cli("evaluate", "--resume", str(out)) == 0
    assert "resuming: 1 of 4 policy rows already walked" in capsys.readouterr().out
    assert not (out / runs.PROGRESS).exists()
    cut, whole = read(out / "fitness.csv"), read(run / "fitness.csv")
    assert [r["fitness"] for r in cut] == [r["fitness"] for r in whole]
    assert [Path(r["policy"]).name for r in cut] == [Path(r["policy"]).name for r in whole]
    timing = json.loads((out / "timing.json").read_text())
    assert timing["rows_resumed"] == 1 and timing["repeat_equal"] is True and timing["walk_s_one_policy"] > 0


@pytest.mark.slow  # its own compile (~90 s); the kept repeat is also checked by the time-limit test above
def test_repeat_is_walked_once_per_run_across_time_limit_stops(tmp_path, policies, capsys, monkeypatch):
    """``--repeat`` walks the first row of a run twice, and the result is kept in ``walked.npz`` through a
    ``--time-limit`` stop: a resume reports it in ``timing.json`` without walking it again. A resumed file without it
    (an older version's) walks the resumed call's first row twice, once: a second resume does not repeat it."""
    from jaxterrain.suite import runs

    walks = []
    walk = runs.evaluate_policies
    monkeypatch.setattr(runs, "evaluate_policies", lambda *a, **k: (walks.append(len(a[0])), walk(*a, **k))[1])
    copy, still, _ = policies
    out = tmp_path / "cut"
    assert cli("evaluate", "--preset", "smoke", "--families", "flat", "--generators", "--policy", str(copy),
               str(still), "--repeat", "--out", str(out), "--time-limit", "0.0001") == 3
    assert len(walks) == 2  # the base policy's row, and again

    def progress():
        with np.load(out / runs.PROGRESS) as z:
            return {k: z[k] for k in z.files}

    saved = progress()
    assert saved["fitness"].shape == (1, 1) and json.loads(str(saved["repeat"]))["equal"] is True
    del saved["repeat"]  # as a run stopped before the repeat walk was kept left it
    np.savez(out / runs.PROGRESS, **saved)
    assert cli("evaluate", "--resume", str(out), "--time-limit", "0.0001") == 3
    assert len(walks) == 4  # the copy's row, and again
    assert progress()["fitness"].shape == (2, 1) and json.loads(str(progress()["repeat"]))["equal"] is True
    capsys.readouterr()
    assert cli("evaluate", "--resume", str(out)) == 0
    assert len(walks) == 5  # the last row, not repeated
    assert "resuming: 2 of 3 policy rows already walked" in capsys.readouterr().out
    timing = json.loads((out / "timing.json").read_text())
    assert timing["repeat_equal"] is True and timing["walk_s_one_policy"] > 0 and timing["rows_resumed"] == 2
