"""Walkers on video beside the base policy (issue 62 item 4): which terrains ``evaluate --videos`` shows, the GIF of
two walks side by side and in step, the report's section of an evaluation's videos, and no videos (one reason, the
evaluation unharmed) without an OpenGL backend."""

import csv
import io

import numpy as np
import pytest

from jaxterrain.report import render

render.setup_gl()  # before this module imports mujoco (when it is the first to); harmless otherwise

from jaxterrain.report import compare  # noqa: E402


def test_default_picks_are_the_hardest_level_passed_and_the_first_failed_per_family():
    family = ["slope"] * 5 + ["flat"] + ["gaps"] * 3 + ["gen:perlin"] * 3
    level = [0, 1, 2, 3, 4, 0, 0, 1, 2, 0, 2, 3]
    fitness = [1.0, 0.95, 0.5, 0.93, 0.2,  # level 3 passes, but above the failed level 2
               1.0,  # every level passed: the hardest only
               0.4, 0.95, 0.99,  # level 0 fails: the first failed only
               0.99, 0.97, 0.3]  # band 1 empty: stepped over
    assert compare.default_picks(fitness, family, level) == [
        ("slope", 1), ("slope", 2), ("flat", 0), ("gaps", 0), ("gen:perlin", 2), ("gen:perlin", 3)]
    two_seeds = compare.default_picks([0.95, 0.8, 0.91, 0.91], ["s"] * 4, [0, 0, 1, 1])  # level 0's mean: 0.875
    assert two_seeds == [("s", 0)]
    with pytest.raises(ValueError, match="shape"):
        compare.default_picks([1.0, 0.5], ["s"], [0, 1])


def test_parse_picks_reads_families_with_colons_and_refuses_the_rest():
    assert compare.parse_picks("slope_up:5, gen:perlin:3") == [("slope_up", 5), ("gen:perlin", 3)]
    for bad in ("slope_up", "slope_up:", ":3", "slope_up:-1", "slope_up:x", "flat:0,,gaps:1"):
        with pytest.raises(ValueError, match="FAMILY:LEVEL"):
            compare.parse_picks(bad)


def test_terrain_index_is_the_levels_lowest_seed():
    family = np.array(["a", "a", "a", "b"])
    level = np.array([1, 1, 2, 0])
    seed = np.array([1, 0, 0, 0])
    assert compare.terrain_index(family, level, seed, "a", 1) == 1
    assert compare.terrain_index(family, level, seed, "a", 0) is None


def _walk(length, x_end, config):
    """A recorded walk of ``length`` env steps whose torso moves from x = -0.4 to ``x_end``."""
    from jaxterrain.walker import build_model

    model = build_model(config.terrain_shape, config.scale, config.solver, config.timestep)
    qpos = np.repeat(np.asarray(model.qpos0, np.float32)[None], length + 1, axis=0)
    qpos[:, 0] = np.linspace(-0.4, x_end, length + 1)
    qpos[:, 2] = 1.3
    terrain = np.zeros(config.terrain_shape, np.float32)
    return render.Walk(terrain=terrain, qpos=qpos, length=length, distance=0.5, fell=length < 8,
                       env_config=config, dt=0.015)


def _gl_or_skip():
    ok, why = render.gl_status()
    if not ok:
        print(f"SKIP render test: {why}")
        pytest.skip(why)


def test_a_pair_gif_has_two_labelled_panels_in_step():
    """Two replayed walks (no MJX rollout: states made up) of different lengths: one GIF, two panels side by side
    under a label bar, the shorter walk holding its last state while the longer one goes on."""
    from PIL import Image

    from jaxterrain.walker import WalkerConfig

    _gl_or_skip()
    config = WalkerConfig(terrain_shape=(48, 48))
    long, short = _walk(8, 0.4, config), _walk(4, 0.0, config)
    w, h = 64, 48
    frames = compare.pair_frames([long, short], ["walker", "base policy"], width=w, height=h, frames=5)
    assert frames.shape == (5, compare.LABEL_HEIGHT + h, 2 * w + compare.PANEL_GAP, 3)
    left, right = frames[:, compare.LABEL_HEIGHT:, :w], frames[:, compare.LABEL_HEIGHT:, w + compare.PANEL_GAP:]
    assert np.abs(left[0].astype(int) - left[-1].astype(int)).mean() > 1  # the walker moves to the end
    np.testing.assert_array_equal(right[2], right[4])  # steps 4 and 8: the short walk ended at step 4
    assert not np.array_equal(right[0], right[2])
    assert frames[:, : compare.LABEL_HEIGHT].min() < 100  # the labels are drawn
    gif = compare.pair_gif([long, short], ["walker", "base policy"], width=w, height=h, frames=5)
    assert compare.pair_frame_count([long, short], 5, fps=15) == 3  # 0.12 s of walk: real time at 15 fps
    assert compare.pair_frame_count([long, short], 5, fps=50) == 5
    with Image.open(io.BytesIO(gif)) as im:
        assert im.format == "GIF" and im.n_frames == 3 and im.size == (2 * w + compare.PANEL_GAP,
                                                                       compare.LABEL_HEIGHT + h)
    assert compare.outcome(short) == "0.50 of the track, fell at 0.1 s"
    assert compare.outcome(long) == "0.50 of the track in 0.1 s"


def test_without_gl_no_videos_are_made_and_the_reason_is_returned(tmp_path, monkeypatch):
    monkeypatch.setattr(render, "gl_status", lambda: (False, "no OpenGL backend here (test)"))
    got = compare.write_videos(tmp_path / "videos", ["base"], [object()], None, np.zeros((1, 3)), None)
    assert got == "no OpenGL backend here (test)" and not (tmp_path / "videos").exists()


def test_the_report_shows_an_evaluations_videos_with_their_fitness(tmp_path):
    """A run folder holding ``videos/videos.csv`` and its GIFs: the page shows them in a Videos section with the
    terrain and both fitness values, and not again among the figures."""
    from PIL import Image

    from jaxterrain.report import write_report

    run = tmp_path / "evaluate-x"
    (run / "videos" / "trial_0").mkdir(parents=True)
    buf = io.BytesIO()
    frames = [Image.fromarray(np.full((8, 12, 3), v, np.uint8)) for v in (0, 255)]
    frames[0].save(buf, format="GIF", save_all=True, append_images=frames[1:], duration=100)
    (run / "videos" / "trial_0" / "slope_up_L5.gif").write_bytes(buf.getvalue())
    row = ["trial_0", "/r/trial_0", "slope_up", "5", "0", "0.3", "grade", "trial_0/slope_up_L5.gif", "0.9560",
           "0.1760", "reached the far edge at 9.8 s", "0.18 of the track, fell at 2.0 s", "3", "8",
           "0.5 0.4 0.6 1.0 0.9 0.2 0.3 0.7", "0.1 0.1 0.2 0.2 0.1 0.1 0.1 0.2", "75", "15"]
    with open(run / "videos" / "videos.csv", "w", newline="") as fh:
        csv.writer(fh).writerows([compare.VIDEO_COLUMNS, row])
    page = write_report([run], tmp_path / "rep", videos=False, progress=lambda s: None).read_text()
    assert "<h3>Videos (videos)</h3>" in page and "<h3>Figures</h3>" not in page
    assert page.count("data:image/gif;base64,") == 1
    assert "trial_0 on slope_up level 5 (0.3 grade): level fitness 0.9560 vs the base policy&#x27;s 0.1760" in page \
        or "trial_0 on slope_up level 5 (0.3 grade): level fitness 0.9560 vs the base policy's 0.1760" in page
    md = (tmp_path / "rep" / "report.md").read_text()
    assert "### Videos (videos)" in md and "report_files/r0_video_trial_0_slope_up_L5.gif" in md
