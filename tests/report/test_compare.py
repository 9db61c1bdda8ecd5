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
    with open(run / "videos" / "videos.csv", "w", newline="") as fh:  # a run from before MP4s: no mp4 column
        csv.writer(fh).writerows([[c for c in compare.VIDEO_COLUMNS if c != "mp4"], row])
    page = write_report([run], tmp_path / "rep", videos=False, progress=lambda s: None).read_text()
    assert "<h3>Videos (videos)</h3>" in page and "<h3>Figures</h3>" not in page
    assert page.count("data:image/gif;base64,") == 1
    assert "trial_0 on slope_up level 5 (0.3 grade): level fitness 0.9560 vs the base policy&#x27;s 0.1760" in page \
        or "trial_0 on slope_up level 5 (0.3 grade): level fitness 0.9560 vs the base policy's 0.1760" in page
    md = (tmp_path / "rep" / "report.md").read_text()
    assert "### Videos (videos)" in md and "report_files/r0_video_trial_0_slope_up_L5.gif" in md


# ----------------------------------------------------------------------------------------------------------------
# MP4 (issue 62 item 4: evaluate writes GIF / MP4; the optional extra jaxterrain[video])
# ----------------------------------------------------------------------------------------------------------------
def _bar_frames(n=5, h=35, w=47):
    """[n, h, w, 3] uint8: grey, with a white bar 8 columns wide that moves 8 columns right each frame."""
    frames = np.full((n, h, w, 3), 60, np.uint8)
    for k in range(n):
        frames[k, :, 8 * k:8 * k + 8] = 255
    return frames


def _read_mp4(data: bytes, tmp_path) -> tuple[dict, np.ndarray]:
    """``(imageio_ffmpeg's metadata, frames [F, h, w, 3] uint8)`` of an MP4's bytes, decoded by ffmpeg."""
    import warnings

    import imageio_ffmpeg

    path = tmp_path / "back.mp4"
    path.write_bytes(data)
    with warnings.catch_warnings():  # JAX's warning of os.fork(): ffmpeg's child process execs at once
        warnings.filterwarnings("ignore", message=r"os\.fork\(\) was called", category=RuntimeWarning)
        reader = imageio_ffmpeg.read_frames(str(path))
        meta = next(reader)
        w, h = meta["size"]
        return meta, np.stack([np.frombuffer(b, np.uint8).reshape(h, w, 3) for b in reader])


def test_mp4_bytes_is_h264_with_every_frame_and_odd_sides_padded_to_even(tmp_path):
    """Five synthetic 35 x 47 frames: an H.264 MP4 whose ffmpeg read-back has five 36 x 48 frames (one row and one
    column repeated), the moving bar where it was in each (lossy: close, not equal), the same bytes when encoded
    again; bad frames or fps refused by name."""
    pytest.importorskip("imageio_ffmpeg", reason="needs the video extra: pip install 'jaxterrain[video]'")
    frames = _bar_frames()
    mp4 = render.mp4_bytes(frames, fps=10)
    assert mp4[4:8] == b"ftyp" and render.mp4_bytes(frames, fps=10) == mp4
    meta, back = _read_mp4(mp4, tmp_path)
    assert meta["codec"] == "h264" and meta["pix_fmt"].startswith("yuv420p") and meta["fps"] == 10
    assert back.shape == (5, 36, 48, 3)
    assert np.abs(back[:, :35, :47].astype(int) - frames.astype(int)).mean() < 8
    np.testing.assert_array_equal(back[:, :35, 47], back[:, :35, 46])  # the padded column repeats the edge
    for k in range(5):  # the bar: brightest columns of each frame
        assert np.argmax(back[k, 10, :47, 0].astype(int).reshape(-1)[::8][:5]) == k
    with pytest.raises(ValueError, match=r"frames must be \[F >= 1, h, w, 3\] uint8"):
        render.mp4_bytes(frames[..., 0])
    with pytest.raises(ValueError, match="fps must be a number > 0"):
        render.mp4_bytes(frames, fps=0)


def test_without_the_video_extra_mp4_is_refused_before_anything_walks(monkeypatch, tmp_path):
    """imageio-ffmpeg missing (its ``sys.modules`` entry None: the import raises): one line naming the extra, from
    the encoder and from ``write_videos``, which says it before it looks for OpenGL or walks."""
    import sys

    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)
    with pytest.raises(ImportError) as err:
        render.mp4_bytes(_bar_frames())
    assert str(err.value) == render.MP4_EXTRA and "pip install 'jaxterrain[video]'" in render.MP4_EXTRA
    monkeypatch.setattr(render, "gl_status", lambda: pytest.fail("looked for OpenGL before the extra"))
    for fmt in ("mp4", "both"):
        with pytest.raises(ImportError, match=r"pip install 'jaxterrain\[video\]'"):
            compare.write_videos(tmp_path / "videos", ["base"], [object()], None, np.zeros((1, 3)), None, format=fmt)
    with pytest.raises(ValueError, match="format must be one of gif, mp4, both; got 'webm'"):
        compare.write_videos(tmp_path / "videos", ["base"], [object()], None, np.zeros((1, 3)), None, format="webm")
    assert not (tmp_path / "videos").exists()


def test_write_videos_both_writes_a_gif_and_an_mp4_of_the_same_frames(tmp_path, monkeypatch):
    """``evaluate --videos --video-format both`` at the smallest size of the evaluate videos test (64 x 48 panels, 3
    frames, 2 starts), its MJX walks replaced by made-up ones (no compile): ``<walker>/<family>_L<level>.gif`` and
    ``.mp4`` of the same frames (ffmpeg reads back as many frames of the same size as the GIF holds, close in
    colour), ``videos.csv``'s ``file`` the GIF and ``mp4`` the MP4; ``mp4`` alone: the MP4 is the file."""
    from PIL import Image

    from jaxterrain.suite.heldout import Suite
    from jaxterrain.terrain import TerrainScale
    from jaxterrain.walker import WalkerConfig

    pytest.importorskip("imageio_ffmpeg", reason="needs the video extra: pip install 'jaxterrain[video]'")
    _gl_or_skip()
    config = WalkerConfig(terrain_shape=(48, 48))
    walks = {0: [_walk(8, 0.4, config), _walk(8, 0.3, config)], 1: [_walk(4, 0.0, config), _walk(6, 0.1, config)]}
    monkeypatch.setattr(compare, "record_pairs", lambda policies, maps, key, ids, **kw: [walks[0], walks[1]])
    s = Suite("test", np.zeros((1, 48, 48), np.float32), np.array(["flat"]), np.array([0]), np.array([0]),
              np.array([0.0]), {"flat": "-"}, TerrainScale(), {})
    fitness = np.array([[0.95], [0.2]])
    kw = dict(picks=[("flat", 0)], frames=3, width=64, height=48, starts=2)
    (row,) = compare.write_videos(tmp_path / "both", ["base", "runs/still"], [None, None], s, fitness, None,
                                  format="both", **kw)
    cols = dict(zip(compare.VIDEO_COLUMNS, row))
    assert (cols["file"], cols["mp4"]) == ("still/flat_L0.gif", "still/flat_L0.mp4")
    with open(tmp_path / "both" / "videos.csv", newline="") as fh:
        assert next(csv.DictReader(fh))["mp4"] == "still/flat_L0.mp4"
    gif = []
    with Image.open(tmp_path / "both" / "still" / "flat_L0.gif") as im:
        for k in range(im.n_frames):
            im.seek(k)
            gif.append(np.asarray(im.convert("RGB")))
    meta, mp4 = _read_mp4((tmp_path / "both" / "still" / "flat_L0.mp4").read_bytes(), tmp_path)
    size = (compare.LABEL_HEIGHT + 48, 2 * 64 + compare.PANEL_GAP)
    assert mp4.shape == (len(gif), *size, 3) and len(gif) == int(cols["frames"]) >= 2 and meta["fps"] == 15
    assert np.abs(mp4.astype(int) - np.stack(gif).astype(int)).mean() < 12
    (row,) = compare.write_videos(tmp_path / "mp4", ["base", "runs/still"], [None, None], s, fitness, None,
                                  format="mp4", **kw)
    cols = dict(zip(compare.VIDEO_COLUMNS, row))
    assert (cols["file"], cols["mp4"]) == ("still/flat_L0.mp4", "still/flat_L0.mp4")
    assert sorted(p.name for p in (tmp_path / "mp4" / "still").iterdir()) == ["flat_L0.mp4"]
    assert (tmp_path / "mp4" / "still" / "flat_L0.mp4").read_bytes() == \
        (tmp_path / "both" / "still" / "flat_L0.mp4").read_bytes()


def test_the_report_embeds_an_mp4_in_a_video_element_and_links_the_mp4_beside_a_gif(tmp_path):
    """``videos.csv`` rows of an MP4 alone (``--video-format mp4``) and of a GIF with its MP4 (``both``): the page
    embeds the first in a ``<video>`` element and the GIF as an image with a link to its MP4 in ``report_files/``;
    the Markdown twin links both MP4s; no MP4 is listed again among the figures."""
    from jaxterrain.report import write_report

    pytest.importorskip("imageio_ffmpeg", reason="needs the video extra: pip install 'jaxterrain[video]'")
    run = tmp_path / "evaluate-x"
    (run / "videos" / "trial_0").mkdir(parents=True)
    mp4 = render.mp4_bytes(_bar_frames(3, 8, 12), fps=10)
    (run / "videos" / "trial_0" / "slope_up_L5.mp4").write_bytes(mp4)
    (run / "videos" / "trial_0" / "gaps_L2.mp4").write_bytes(mp4)
    (run / "videos" / "trial_0" / "gaps_L2.gif").write_bytes(render.gif_bytes(_bar_frames(3, 8, 12), fps=10))
    tail = ["0.9560", "0.1760", "reached the far edge at 9.8 s", "0.18 of the track, fell at 2.0 s", "3", "8",
            "0.5 0.4 0.6 1.0 0.9 0.2 0.3 0.7", "0.1 0.1 0.2 0.2 0.1 0.1 0.1 0.2", "3", "10"]
    rows = [["trial_0", "/r/trial_0", "slope_up", "5", "0", "0.3", "grade", "trial_0/slope_up_L5.mp4", *tail,
             "trial_0/slope_up_L5.mp4"],
            ["trial_0", "/r/trial_0", "gaps", "2", "0", "0.4", "m", "trial_0/gaps_L2.gif", *tail,
             "trial_0/gaps_L2.mp4"]]
    with open(run / "videos" / "videos.csv", "w", newline="") as fh:
        csv.writer(fh).writerows([compare.VIDEO_COLUMNS, *rows])
    page = write_report([run], tmp_path / "rep", videos=False, progress=lambda s: None).read_text()
    assert page.count("<video ") == 1 and page.count("data:video/mp4;base64,") == 1
    assert page.count("data:image/gif;base64,") == 1 and "<h3>Figures</h3>" not in page
    assert '<a href="report_files/r0_video_trial_0_gaps_L2.mp4">MP4</a>' in page
    assert (tmp_path / "rep" / "report_files" / "r0_video_trial_0_gaps_L2.mp4").read_bytes() == mp4
    md = (tmp_path / "rep" / "report.md").read_text()
    assert "[trial_0/slope_up_L5.mp4 (MP4)](report_files/r0_video_trial_0_slope_up_L5.mp4)" in md
    assert "([MP4](report_files/r0_video_trial_0_gaps_L2.mp4))" in md
    assert "![trial_0/gaps_L2.gif](report_files/r0_video_trial_0_gaps_L2.gif)" in md
