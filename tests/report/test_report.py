"""The report (jaxterrain.report); the report and export commands: tests/integration/test_stage_commands.py."""

import base64
import json
import re

import numpy as np
import pytest

from jaxterrain.report import render
from report_runs import make_smoke_run

render.setup_gl()  # before this module imports mujoco (when it is the first to); harmless otherwise


@pytest.fixture
def smoke_run(tmp_path):
    """A run folder as the commands write them (``report_runs.make_smoke_run``)."""
    return make_smoke_run(tmp_path)


def _write(run, out, **kw):
    from jaxterrain.report import write_report

    return write_report([run], out, progress=lambda s: None, **kw)


def test_report_holds_every_table_and_figure_and_no_network_reference(smoke_run, tmp_path):
    from jaxterrain.report import collect

    path = _write(smoke_run, smoke_run / "report", videos=False)
    page = path.read_text()
    # every figure embedded, byte for byte
    assert base64.b64encode((smoke_run / "archive.png").read_bytes()).decode() in page
    # every table: each CSV cell, the Markdown table's cells, the config's options
    for row in (smoke_run / "metrics.csv").read_text().split():
        for cell in row.split(","):
            assert f">{cell}<" in page, cell
    assert ">perlin<" in page and ">31.25 %<" in page and "<code>code</code>" in page
    assert ">seed<" in page and ">7<" in page
    # the archive: one heatmap cell per elite, with its data (thumbnail, fitness) for hover / click
    assert page.count("data-k=") == 5
    data = json.loads(re.search(r'<script type="application/json" class=cells>(.*?)</script>', page).group(1))
    assert [d["c"] for d in data] == [0, 5, 6, 10, 15]
    assert data[0]["f"] == pytest.approx(0.9) and base64.b64decode(data[0]["t"])[:3] == b"\xff\xd8\xff"  # JPEG
    assert "checkpoint/checkpoint.npz" in page and "state.json" in page  # other files listed
    # self-contained: no network address anywhere, every src / href local (data: URI or in-page anchor)
    assert "http://" not in page and "https://" not in page
    assert all(s.startswith("data:") for s in re.findall(r'src="([^"]*)"', page))
    assert all(h.startswith("#") for h in re.findall(r'href="([^"]*)"', page))
    assert "<link" not in page and "@import" not in page and "url(http" not in page
    # the Markdown twin: the same tables, its images as files beside it
    md = (path.parent / "report.md").read_text()
    assert "| 1 | 31.25 | 2.75 |" in md and "| perlin | 31.25 % |" in md
    images = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", md)
    assert any(i.endswith("archive.png") for i in images) and any(i.endswith("heatmap.png") for i in images)
    assert all((path.parent / i).is_file() for i in images)
    # the report inside the run folder is not part of the run the next time
    again = collect.scan(smoke_run)
    assert [p.name for p in again.figures] == ["archive.png"] and len(again.archives) == 1


def test_report_says_why_renders_were_skipped(smoke_run, tmp_path, monkeypatch):
    reason = "no OpenGL backend for MuJoCo's renderer (MUJOCO_GL=osmesa): test"
    monkeypatch.setattr(render, "gl_status", lambda: (False, reason))
    page = _write(smoke_run, tmp_path / "rep", videos=True).read_text()
    assert f"Renders skipped: {reason}" in page.replace("&#x27;", "'")
    assert page.count("No video: renders skipped") == 3  # easy, medium, hard of the archive
    md = (tmp_path / "rep" / "report.md").read_text()
    assert "Renders skipped" in md


def test_markdown_to_html():
    from jaxterrain.report.page import markdown_to_html

    h = markdown_to_html("# Title\n\ntext with **bold** and [a link](https://x.org)\n\n| a | b |\n|---|---|\n"
                         "| 1 | x |\n\n- one\n- two\n\n```\n<raw>\n```\n")
    assert "<h3>Title</h3>" in h and "<strong>bold</strong>" in h and "a link" in h and "x.org" not in h
    assert "<th>a</th>" in h and "<td class=num>1</td>" in h and "<li>two</li>" in h and "&lt;raw&gt;" in h


def test_setup_gl_never_picks_a_backend_whose_library_is_missing(monkeypatch):
    """``MUJOCO_GL=osmesa`` without libOSMesa breaks ``import mujoco``: setup_gl leaves such a backend unset and
    gl_status says why (install libosmesa6)."""
    import os

    monkeypatch.delenv("MUJOCO_GL", raising=False)
    monkeypatch.delenv("PYOPENGL_PLATFORM", raising=False)
    monkeypatch.setattr(render, "_loadable", lambda *names: None)
    assert render.setup_gl() == "" and "MUJOCO_GL" not in os.environ
    ok, why = render._probe.__wrapped__("")
    assert not ok and "libosmesa6" in why
    monkeypatch.setenv("MUJOCO_GL", "osmesa")
    assert render.setup_gl() == "" and "MUJOCO_GL" not in os.environ
    ok, why = render._probe.__wrapped__("")
    assert not ok and "MUJOCO_GL=osmesa was set" in why and "libosmesa6" in why


def _gl_or_skip():
    ok, why = render.gl_status()
    if not ok:
        print(f"SKIP render test: {why}")
        pytest.skip(why)


def test_render_frames_of_the_walker_on_a_heightfield():
    """MuJoCo's offscreen renderer draws the walker on the terrain (OSMesa on a CPU machine): a few frames of
    replayed states, encoded as an animated GIF."""
    import io

    from PIL import Image

    from jaxterrain.walker import WalkerConfig, build_model

    _gl_or_skip()
    config = WalkerConfig(terrain_shape=(48, 48))
    model = build_model(config.terrain_shape, config.scale, config.solver, config.timestep)
    yy, xx = np.mgrid[0:48, 0:48] / 47.0
    terrain = (0.3 * np.sin(6 * xx) * np.cos(4 * yy) + 0.3).astype(np.float32)
    qpos = np.repeat(np.asarray(model.qpos0, np.float32)[None], 4, axis=0)
    qpos[:, 0] = np.linspace(-0.4, 0.4, 4)  # the torso moves along +x
    qpos[:, 2] = 1.3 + terrain.max()
    walk = render.Walk(terrain=terrain, qpos=qpos, length=3, distance=0.5, fell=False, env_config=config, dt=0.015)
    frames = render.render_walk(walk, width=96, height=72, frames=4)
    assert frames.shape == (4, 72, 96, 3) and frames.dtype == np.uint8
    assert frames.std() > 10  # a scene, not a blank image
    assert np.abs(frames[0].astype(int) - frames[-1].astype(int)).mean() > 1  # the walker moved
    gif = render.gif_bytes(frames, fps=render.fps_of(walk, len(frames)))
    with Image.open(io.BytesIO(gif)) as im:
        assert im.format == "GIF" and im.n_frames == 4 and im.size == (96, 72)


@pytest.mark.slow
def test_mjx_rollout_replayed_by_the_renderer():
    """End to end: states recorded from an MJX rollout of the shipped base policy, replayed into frames (about a
    minute on 2 CPU cores, nearly all of it the rollout's compile)."""
    import jax

    _gl_or_skip()
    terrains = np.zeros((2, 48, 48), np.float32)
    terrains[1, :, 30:] = 0.15  # a step
    walks = render.record_walks(terrains, jax.random.key(0), steps=40)
    assert len(walks) == 2
    for w in walks:
        assert w.qpos.shape == (w.length + 1, 24) and 1 <= w.length <= 40 and 0.0 <= w.distance <= 1.0
        assert np.all(np.isfinite(w.qpos))
    assert walks[0].qpos[-1, 0] > walks[0].qpos[0, 0]  # it walks along +x
    frames = render.render_walk(walks[1], width=64, height=48, frames=3)
    assert frames.shape == (3, 48, 64, 3)
    # the report's path: same shapes and steps, so the compiled rollout is reused
    videos = render.make_videos([("flat", "a flat terrain", terrains[0]), ("step", "a step", terrains[1])],
                                steps=40, frames=3, width=64, height=48)
    assert [v.label for v in videos] == ["flat", "step"]
    assert all(v.gif is not None and v.gif[:6] == b"GIF89a" and "walked" in v.outcome for v in videos)


def test_record_walks_tells_one_raw_key_from_a_batch_of_keys():
    """``record_walks``' key rule: a batch of B keys (typed ``[B]``, raw ``[B, 2]``) is used as given; one key is
    split B ways, also a raw ``PRNGKey`` ``[2]`` when B is 2 (it was taken for two keys and failed inside vmap)."""
    import jax

    assert render._key_batch(jax.random.split(jax.random.key(0), 2), 2)
    assert render._key_batch(jax.random.split(jax.random.PRNGKey(0), 2), 2)
    assert not render._key_batch(jax.random.PRNGKey(0), 2)
    assert not render._key_batch(jax.random.key(0), 2)
    assert not render._key_batch(jax.random.split(jax.random.key(0), 3), 2)
