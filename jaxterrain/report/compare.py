"""Walkers on video beside the base policy: which terrains to show, and one GIF per terrain with both walks side by
side, in step.

    from jaxterrain.report import compare, render
    render.setup_gl()                                       # before mujoco is imported
    picks = compare.default_picks(fitness[1], s.family, s.level)     # [(family, level)]: per family the hardest
                                                            # level passed and the first failed
    rows = [compare.terrain_index(s.family, s.level, s.seed, fam, lv) for fam, lv in picks]
    walks = compare.record_pairs([walker, base], s.heightmaps[rows], jax.random.key(0), rows)
    gif = compare.pair_gif([walks[0][0], walks[1][0]], ["trial_0", "base"])          # bytes of an animated GIF
    mp4 = compare.pair_mp4([walks[0][0], walks[1][0]], ["trial_0", "base"])          # an MP4 (jaxterrain[video])
    compare.write_videos("run/videos", names, policies, s, fitness, key)   # what `evaluate --videos` writes

:func:`record_pairs` walks every policy on every terrain with :func:`jaxterrain.report.render.record_walks` (MJX,
the env :func:`jaxterrain.difficulty.evaluate` walks, each policy with its own solver options, one walk along +x
from the reset pose) and gives the policies on one terrain the same reset key (``fold_in(key, terrain id)``): the
same start pose, so what differs between the panels is the policy. :func:`pair_frames` draws the walks with
:func:`jaxterrain.report.render.render_walk` at the same env steps (a walk that ended early holds its last state)
and puts them side by side under a label bar (the policy, how its walk went, the time); :func:`pair_gif` encodes
that as a GIF (Pillow), :func:`pair_mp4` as an MP4 (H.264 through ``imageio-ffmpeg``, the optional extra
``pip install 'jaxterrain[video]'``: :func:`jaxterrain.report.encode.mp4_bytes`). :func:`write_videos` does all of
it for an evaluation (``python -m experiments evaluate --videos --video-format gif|mp4|both``).
"""

from __future__ import annotations

import re
import time
from pathlib import Path
from typing import Callable, Optional, Sequence

import jax
import numpy as np

from jaxterrain import difficulty
from jaxterrain.report import render as R
from jaxterrain.runtime.io import atomic_write_bytes, atomic_write_csv
from jaxterrain.suite.evaluation import THRESHOLD, highest_level_passed, level_fitness
from jaxterrain.suite.outputs import short_names
from jaxterrain.suite.runs import parse_picks, video_picks
from jaxterrain.terrain import TerrainScale
from jaxterrain.walker import resolve_backend

__all__ = ["default_picks", "parse_picks", "terrain_index", "record_pairs", "pair_frames", "pair_gif", "pair_mp4",
           "outcome", "pair_frame_count", "video_files", "write_videos", "evaluation_videos", "VIDEO_COLUMNS",
           "VIDEO_FORMATS", "PANEL_GAP", "LABEL_HEIGHT"]

PANEL_GAP = 4
"""Pixels of white between two panels."""
LABEL_HEIGHT = 34
"""Pixels of the label bar above the panels (two lines of text)."""
VIDEO_FORMATS = {"gif": ("gif",), "mp4": ("mp4",), "both": ("gif", "mp4")}
"""``format`` of :func:`write_videos` (``EvaluateRun.videos.format``, ``evaluate --video-format``): the files each
video is written as."""


def default_picks(fitness, family, level, threshold: float = THRESHOLD) -> list[tuple[str, int]]:
    """Per family (in order of first appearance): the highest level passed with every level below it passed
    (:func:`jaxterrain.suite.highest_level_passed`; none when level 0 fails) and the first level above it that
    fails (none when every level passes). ``fitness`` / ``family`` / ``level``: [N], one policy's fitness and the
    suite's terrains (``Suite.family`` / ``Suite.level`` or ``read_fitness``'s). Returns ``[(family, level)]``.

    >>> default_picks([1.0, 0.95, 0.3, 0.92], ["slope"] * 4, [0, 1, 2, 3])
    [('slope', 1), ('slope', 2)]
    """
    f = np.asarray(fitness, np.float64)
    fam, lv = np.asarray(family), np.asarray(level)
    if not (f.shape == fam.shape == lv.shape) or f.ndim != 1:
        raise ValueError(f"fitness, family and level must all have shape [N]; got {f.shape}, {fam.shape}, {lv.shape}")
    out = []
    for name in dict.fromkeys(fam.tolist()):
        rows = fam == name
        levels = sorted(set(lv[rows].tolist()))
        means = {k: float(f[rows & (lv == k)].mean()) for k in levels}
        per = [means.get(k, np.nan) for k in range(max(levels) + 1)]
        top = highest_level_passed(per, threshold)
        if top >= 0:
            out.append((name, top))
        failed = [k for k in levels if k > top and means[k] < threshold]
        if failed:
            out.append((name, failed[0]))
    return out


def terrain_index(family, level, seed, name: str, lv: int) -> Optional[int]:
    """The row of the suite's terrain shown for ``(name, lv)``: the level's lowest seed; None when the suite holds
    no terrain of that family and level. ``family`` / ``level`` / ``seed``: [N], the suite's."""
    fam, lvl, sd = np.asarray(family), np.asarray(level), np.asarray(seed)
    rows = np.flatnonzero((fam == name) & (lvl == int(lv)))
    if rows.size == 0:
        return None
    return int(rows[np.argmin(sd[rows])])


def record_pairs(policies: Sequence, heightmaps, key, ids: Sequence[int], steps: int = 1000, scale=None,
                 backend: str = "jax") -> list[list[R.Walk]]:
    """``walks[p][b]``: policy ``p`` walked once on terrain ``b`` of ``heightmaps`` [B, H, W] (in [0, 1]) for up to
    ``steps`` env steps, by :func:`jaxterrain.report.render.record_walks` with terrain ``b``'s reset key
    ``fold_in(key, ids[b])`` for every policy (``ids`` [B]: e.g. the terrains' rows in the suite, so a terrain gets
    the same start whatever else is walked with it). Each policy walks under its own walker config
    (:func:`jaxterrain.difficulty.default_env_config`: its robot and solver options) on ``backend``'s physics."""
    import jax

    maps = np.asarray(heightmaps, np.float32)
    if maps.ndim != 3 or maps.shape[0] != len(ids):
        raise ValueError(f"heightmaps must be [B, H, W] with B = len(ids) = {len(ids)}; got shape {maps.shape}")
    scale = TerrainScale() if scale is None else scale
    keys = jax.vmap(lambda i: jax.random.fold_in(key, i))(np.asarray(ids, np.uint32))
    out = []
    for p in policies:
        cfg = difficulty.default_env_config(tuple(maps.shape[1:]), scale, p, backend)
        out.append(R.record_walks(maps, keys, steps=steps, policy=p, env_config=cfg))
    return out


def outcome(walk: R.Walk) -> str:
    """How a walk went, in a few words: ``0.96 of the track, fell at 4.2 s`` / ``reached the far edge at 9.8 s`` /
    ``0.40 of the track in 15.0 s``."""
    t = walk.length * walk.dt
    if walk.fell:
        return f"{walk.distance:.2f} of the track, fell at {t:.1f} s"
    if walk.distance >= 0.999:
        return f"reached the far edge at {t:.1f} s"
    return f"{walk.distance:.2f} of the track in {t:.1f} s"


def _font(size: int):
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1: a fixed bitmap font
        return ImageFont.load_default()


def _fit(draw, text: str, font, room: float) -> str:
    """``text``, cut at the end with an ellipsis so that it is at most ``room`` pixels wide."""
    if draw.textlength(text, font=font) <= room:
        return text
    while text and draw.textlength(text + "...", font=font) > room:
        text = text[:-1]
    return text + "..."


def pair_frames(walks: Sequence[R.Walk], labels: Sequence[str], width: int = 320, height: int = 240,
                frames: int = 75) -> np.ndarray:
    """``[F, LABEL_HEIGHT + height, P * width + (P - 1) * PANEL_GAP, 3]`` uint8: the ``P`` walks (one terrain,
    one per policy) drawn at the same ``F <= frames`` env steps, evenly spaced over the longest walk (a walk that
    ended holds its last state), side by side; above each panel its label, :func:`outcome` and the time.
    Raises on a GL failure (check :func:`jaxterrain.report.render.gl_status` first)."""
    from PIL import Image, ImageDraw

    if len(walks) != len(labels) or not walks:
        raise ValueError(f"give one label per walk; got {len(walks)} walks and {len(labels)} labels")
    longest = max(w.length for w in walks)
    at = R.frame_indices(longest, frames)
    panels = [R.render_walk(w, width=width, height=height, at=at) for w in walks]
    n = len(walks)
    canvas = np.full((len(at), LABEL_HEIGHT + height, n * width + (n - 1) * PANEL_GAP, 3), 255, np.uint8)
    font, small = _font(13), _font(11)
    dt = walks[0].dt
    for f, step in enumerate(at):
        bar = Image.new("RGB", (canvas.shape[2], LABEL_HEIGHT), (255, 255, 255))
        draw = ImageDraw.Draw(bar)
        for p, (walk, label) in enumerate(zip(walks, labels)):
            x = p * (width + PANEL_GAP) + 4
            draw.text((x, 2), _fit(draw, str(label), font, width - 68), fill=(0, 0, 0), font=font)
            draw.text((x, 18), outcome(walk), fill=(70, 70, 70), font=small)
            draw.text((x + width - 56, 2), f"t {step * dt:4.1f} s", fill=(0, 0, 0), font=small)
        canvas[f, :LABEL_HEIGHT] = np.asarray(bar)
        for p, panel in enumerate(panels):
            x = p * (width + PANEL_GAP)
            canvas[f, LABEL_HEIGHT:, x:x + width] = panel[f]
    return canvas


def pair_gif(walks: Sequence[R.Walk], labels: Sequence[str], width: int = 320, height: int = 240,
             frames: int = 75, fps: float = 15.0) -> bytes:
    """An animated GIF of :func:`pair_frames` at ``fps``: at most ``frames`` frames (default 75 at 15 fps: a 15-s
    walk plays in 5 s), and no more than one per ``1 / fps`` seconds of the longer walk (a short walk plays in real
    time). The time shown on each frame is the walk's."""
    return R.gif_bytes(pair_frames(walks, labels, width, height, pair_frame_count(walks, frames, fps)), fps=fps)


def pair_mp4(walks: Sequence[R.Walk], labels: Sequence[str], width: int = 320, height: int = 240,
             frames: int = 75, fps: float = 15.0) -> bytes:
    """:func:`pair_gif`'s video as an MP4 (:func:`jaxterrain.report.encode.mp4_bytes`: H.264, an odd side padded to
    even): the same frames at the same ``fps``. ``ImportError`` naming ``pip install 'jaxterrain[video]'`` without
    imageio-ffmpeg (checked before anything is drawn)."""
    R.mp4_encoder()
    return R.mp4_bytes(pair_frames(walks, labels, width, height, pair_frame_count(walks, frames, fps)), fps=fps)


def video_files(format: str) -> tuple[str, ...]:
    """The files a video is written as for ``format`` (a key of :data:`VIDEO_FORMATS`): ``("gif",)``, ``("mp4",)``
    or ``("gif", "mp4")``; ``ValueError`` naming the allowed values; ``ImportError`` naming ``pip install
    'jaxterrain[video]'`` for an MP4 without imageio-ffmpeg."""
    if format not in VIDEO_FORMATS:
        raise ValueError(f"format must be one of {', '.join(VIDEO_FORMATS)}; got {format!r}")
    kinds = VIDEO_FORMATS[format]
    if "mp4" in kinds:
        R.mp4_encoder()
    return kinds


def pair_frame_count(walks: Sequence[R.Walk], frames: int = 75, fps: float = 15.0) -> int:
    """Frames :func:`pair_gif` draws: ``min(frames, 1 + ceil(seconds of the longer walk x fps))``."""
    seconds = max(w.length for w in walks) * walks[0].dt
    n = min(int(frames), 1 + int(np.ceil(seconds * float(fps) - 1e-9)))
    return len(R.frame_indices(max(w.length for w in walks), max(n, 1)))


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", str(text)).strip("_") or "policy"


VIDEO_COLUMNS = ["walker", "policy", "family", "level", "seed", "value", "unit", "file", "walker_level_fitness",
                 "base_level_fitness", "walker_walk", "base_walk", "start", "starts", "walker_distances",
                 "base_distances", "frames", "fps", "mp4"]
"""The columns of ``videos.csv`` (:func:`write_videos`): ``file`` is the video (its GIF, or its MP4 where no GIF was
written), ``mp4`` its MP4 ("" where none was written; a column that runs before MP4 videos lack)."""


def write_videos(folder, names: Sequence[str], policies: Sequence, s, fitness, key,
                 picks: Optional[Sequence[tuple[str, int]]] = None, frames: int = 75, width: int = 320,
                 height: int = 240, fps: float = 15.0, starts: int = 8, steps: int = 1000, backend: str = "jax",
                 labels: Optional[Sequence[str]] = None, progress: Callable[[str], None] = lambda line: None,
                 format: str = "gif"):
    """Videos of an evaluation: each walker (``policies[1:]``) beside the base policy (``policies[0]``; alone when
    there is no walker) on each of its terrains, written atomically to ``folder/<walker>/<family>_L<level>.gif``
    (``format`` ``gif``), ``.mp4`` (``mp4``: H.264, :func:`pair_mp4`) or both (``both``; the same frames) with
    ``folder/videos.csv`` (:data:`VIDEO_COLUMNS`: the level's mean fitness of both from ``fitness`` and how
    each video's walks went).

    ``names`` [P] / ``policies`` [P] / ``fitness`` [P, N]: the evaluation's (``names[0]`` the base policy's);
    ``s``: its :class:`jaxterrain.suite.Suite`; ``labels`` [P]: the policies' names on the videos and their folders
    (default :func:`jaxterrain.suite.short_names` of ``names``); ``picks``: ``[(family, level)]`` for every walker (None: per walker
    :func:`default_picks` of its fitness); each pick is its level's lowest seed (a pick the suite lacks is said
    through ``progress`` and skipped). Every policy walks every picked terrain from ``starts`` reset poses
    (:func:`record_pairs`, one compile per walker config; start ``k`` of the terrain in row ``r`` of the suite has
    the key ``fold_in(key, r * starts + k)`` for every policy) for up to ``steps`` env steps on ``backend``'s
    physics; the video shows the start from which the walker went farthest (the first of equals), the base policy
    from that same start beside it (as the fitness takes the best walks of each heading: the protocol's best 5 of
    20), drawn by :func:`pair_frames` and encoded by :func:`pair_gif` / :func:`pair_mp4`. ``videos.csv`` gives the
    start shown and every start's distance for both, and the files (:data:`VIDEO_COLUMNS`).

    Returns the ``videos.csv`` rows, or a string saying why nothing was made (no OpenGL backend for MuJoCo's
    renderer: :func:`jaxterrain.report.render.gl_status`); never raises for a GL failure. A bad ``format`` or an
    MP4 without imageio-ffmpeg raises (:func:`video_files`) before anything walks.
    """
    folder = Path(folder)
    if not isinstance(starts, int) or starts < 1:
        raise ValueError(f"starts must be an integer >= 1; got {starts!r}")
    kinds = video_files(format)
    ok, why = R.gl_status()
    if not ok:
        return why
    fitness = np.asarray(fitness, np.float64)
    walkers = list(range(1, len(policies))) or [0]
    labels = short_names(names) if labels is None else list(labels)
    wanted: dict[int, list[tuple[str, int, int]]] = {}
    for w in walkers:
        mine = list(picks) if picks is not None else default_picks(fitness[w], s.family, s.level)
        wanted[w] = []
        for fam, lv in mine:
            row = terrain_index(s.family, s.level, s.seed, fam, lv)
            if row is None:
                progress(f"no video of {fam} level {lv}: this suite holds no terrain of it")
                continue
            wanted[w].append((fam, lv, row))
    rows = sorted({r for got in wanted.values() for _, _, r in got})
    if not rows:
        atomic_write_csv(folder / "videos.csv", VIDEO_COLUMNS, [])
        return []
    t0 = time.perf_counter()
    walking = sorted(set(walkers) | {0})
    ids = [r * starts + k for r in rows for k in range(starts)]
    got = record_pairs([policies[p] for p in walking], s.heightmaps[np.repeat(rows, starts)], key, ids, steps=steps,
                       scale=s.scale, backend=backend)
    walks = {p: {r: got[i][j * starts:(j + 1) * starts] for j, r in enumerate(rows)} for i, p in enumerate(walking)}
    progress(f"recorded {len(walking)} policies x {len(rows)} terrains x {starts} starts in "
             f"{time.perf_counter() - t0:.0f} s (compile included)")
    per_level = {p: level_fitness(fitness[p], s) for p in walking}
    out = []
    for w in walkers:
        for fam, lv, row in wanted[w]:
            t1 = time.perf_counter()
            k = int(np.argmax([x.distance for x in walks[w][row]]))
            pair = [walks[w][row][k]] + ([walks[0][row][k]] if w != 0 else [])
            tags = [labels[w]] + (["base policy"] if w != 0 else [])
            n = pair_frame_count(pair, frames, fps)
            clip = pair_frames(pair, tags, width, height, n)
            stem, said = f"{_slug(labels[w])}/{_slug(fam)}_L{lv}", []
            for kind in kinds:
                t2 = time.perf_counter()
                data = R.gif_bytes(clip, fps=fps) if kind == "gif" else R.mp4_bytes(clip, fps=fps)
                atomic_write_bytes(folder / f"{stem}.{kind}", data)
                said.append(f"{kind.upper()} {len(data) / 1024:.0f} KiB in {time.perf_counter() - t2:.1f} s")
            rel = f"{stem}.{kinds[0]}"
            out.append([labels[w], names[w], fam, lv, int(s.seed[row]), f"{float(s.value[row]):.4g}",
                        s.unit.get(fam, "-"), rel, f"{per_level[w][fam][lv]:.4f}", f"{per_level[0][fam][lv]:.4f}",
                        outcome(pair[0]), outcome(walks[0][row][k]), k, starts,
                        " ".join(f"{x.distance:.3f}" for x in walks[w][row]),
                        " ".join(f"{x.distance:.3f}" for x in walks[0][row]), n, f"{fps:g}",
                        f"{stem}.mp4" if "mp4" in kinds else ""])
            progress(f"video {stem}: {n} frames, {', '.join(said)}; {time.perf_counter() - t1:.1f} s in all")
    atomic_write_csv(folder / "videos.csv", VIDEO_COLUMNS, out)
    return out


def evaluation_videos(ready, folder, names: Sequence[str], s, fitness, say: Callable[[str], None] = print,
                      note: Callable[[str], None] = print):
    """The videos of an ``evaluate`` run (``jaxterrain.suite.runs.evaluate_run``'s ``videos`` hook): each walker
    beside the base policy's first key on ``ready.run.videos``' terrains (:func:`write_videos` into
    ``folder/videos``); ``ready``: the run validated (``suite.runs.Prepared``). ``say`` receives the count made,
    ``note`` the progress lines and why none were made (no OpenGL here). Returns what :func:`write_videos` returns."""
    run = ready.run
    v = run.videos
    own = [0] + list(range(int(run.base.keys), len(names)))  # one row per policy: the base policy's first key
    backend = resolve_backend(run.physics.backend) if run.physics.engine == "mjx" else "jax"
    t0 = time.perf_counter()
    made = write_videos(Path(folder) / "videos", [names[i] for i in own], ready.policies, s,
                        np.asarray(fitness)[own], jax.random.fold_in(jax.random.key(int(run.seed)), 5),
                        picks=video_picks(run), frames=int(v.frames), width=int(v.width), height=int(v.height),
                        starts=int(v.starts), backend=backend, progress=lambda line: note(f"evaluate: {line}"),
                        format=str(v.format))
    if isinstance(made, str):
        note(f"evaluate: videos skipped: {made}")
    else:
        say(f"{len(made)} videos in {time.perf_counter() - t0:.0f} s -> {Path(folder) / 'videos'}")
    return made
