"""GIF against MP4 for the same video of two walkers: file size and seconds to encode, at ``evaluate --videos``'
default size (two 320 x 240 panels under the label bar: 644 x 274 pixels, at most 75 frames at 15 a second).

    python benchmarks/video_formats.py --out runs/bench-video      # a CPU will do; needs OpenGL and jaxterrain[video]

The walk pair: the shipped blind humanoid base policy beside the shipped perceptive one, walked once along +x on one
Perlin terrain (``--size`` pixels, seed ``--seed``, its heights times ``--relief``: at 1 both walkers fall within
2 s, a 28-frame video; at 0.25 they walk on) from the same start for up to ``--steps`` env steps
(``jaxterrain.report.compare.record_pairs``: an MJX rollout each, compile included) and drawn by MuJoCo's renderer
(``compare.pair_frames``). The frames are saved (``frames.npz``); a second run with the same ``--out`` reuses them
and only encodes. Each encoder (``render.gif_bytes``, Pillow; ``render.mp4_bytes``, H.264 through imageio-ffmpeg)
encodes the same frames ``--repeats`` times (median seconds, the bytes of every repeat equal); the MP4 is read back
(``imageio_ffmpeg.read_frames``) for its frame count, size and mean absolute pixel difference from the frames (the
GIF's, decoded by Pillow, beside it: its 255-colour palette). Writes ``result.json``, ``video.gif`` and
``video.mp4`` into ``--out``.
"""

from __future__ import annotations

import argparse
import io
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402


def _frames(args, out: Path) -> tuple[np.ndarray, dict]:
    """The pair's frames [F, 274, 644, 3] uint8 (saved in ``out/frames.npz``; reused when there)."""
    saved = out / "frames.npz"
    walk = {k: getattr(args, k) for k in ("size", "seed", "relief", "steps", "frames", "width", "height", "fps")}
    if saved.is_file():
        with np.load(saved) as z:
            was = json.loads(str(z["recorded"]))
            if was["walk"] != walk:
                raise SystemExit(f"video_formats: {saved} holds frames of {was['walk']}, not {walk}: give another "
                                 "--out")
            return z["frames"], {**was, "reused": str(saved)}
    import jax

    from jaxterrain import generators
    from jaxterrain.difficulty import robot_base_policy
    from jaxterrain.report import compare
    from jaxterrain.runtime.io import atomic_write_bytes

    gen = generators.get("perlin")
    maps = np.asarray(gen.render(gen.sample(jax.random.key(args.seed), 1)), np.float32)
    if maps.shape[1] != args.size:
        maps = np.asarray(jax.image.resize(maps, (1, args.size, args.size), "linear"), np.float32)
    maps = maps * np.float32(args.relief)
    policies = [robot_base_policy("humanoid", "blind"), robot_base_policy("humanoid", "perceptive")]
    t0 = time.perf_counter()
    walks = compare.record_pairs(policies, maps, jax.random.key(args.seed), [0], steps=args.steps)
    record_s = time.perf_counter() - t0
    pair = [walks[0][0], walks[1][0]]
    n = compare.pair_frame_count(pair, args.frames, args.fps)
    t1 = time.perf_counter()
    frames = compare.pair_frames(pair, ["base policy (blind)", "base policy (perceptive)"], args.width, args.height, n)
    draw_s = time.perf_counter() - t1
    recorded = {"walk": walk, "record_s": round(record_s, 1), "draw_s": round(draw_s, 2),
                "walks": [compare.outcome(w) for w in pair]}
    buf = io.BytesIO()
    np.savez_compressed(buf, frames=frames, recorded=json.dumps(recorded))
    atomic_write_bytes(saved, buf.getvalue())
    return frames, recorded


def _encode(fn, frames, fps, repeats: int) -> tuple[bytes, float, bool]:
    got, times = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        got.append(fn(frames, fps=fps))
        times.append(time.perf_counter() - t0)
    return got[0], statistics.median(times), all(g == got[0] for g in got)


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="result folder (frames.npz there is reused)")
    parser.add_argument("--size", type=int, default=256, help="terrain side in pixels (evaluate's gpu preset: 256)")
    parser.add_argument("--seed", type=int, default=0, help="the terrain's and the start's key")
    parser.add_argument("--relief", type=float, default=0.25, help="the terrain's heights times this, in (0, 1]")
    parser.add_argument("--steps", type=int, default=1000, help="env steps of each walk (one episode: 1000)")
    parser.add_argument("--frames", type=int, default=75, help="most frames (evaluate --video-frames: 75)")
    parser.add_argument("--width", type=int, default=320, help="panel width (evaluate --video-width: 320)")
    parser.add_argument("--height", type=int, default=240, help="panel height (evaluate --video-height: 240)")
    parser.add_argument("--fps", type=float, default=15.0, help="frames a second (evaluate's: 15)")
    parser.add_argument("--repeats", type=int, default=3, help="encodes per format (median seconds)")
    args = parser.parse_args(argv)
    for name in ("size", "steps", "frames", "width", "height", "repeats"):
        if getattr(args, name) < 1:
            parser.error(f"--{name} must be an integer >= 1; got {getattr(args, name)}")
    if not 0 < args.relief <= 1:
        parser.error(f"--relief must be a number in (0, 1]; got {args.relief}")

    from common import environment, write_json
    from PIL import Image

    from jaxterrain.report import render

    render.setup_gl()
    ok, why = render.gl_status()
    render.mp4_encoder()  # ImportError naming jaxterrain[video] before anything walks
    args.out.mkdir(parents=True, exist_ok=True)
    if not ok and not (args.out / "frames.npz").is_file():
        raise SystemExit(f"video_formats: no OpenGL backend to draw the walks: {why}")
    frames, recorded = _frames(args, args.out)
    fps = args.fps
    gif, gif_s, gif_same = _encode(render.gif_bytes, frames, fps, args.repeats)
    mp4, mp4_s, mp4_same = _encode(render.mp4_bytes, frames, fps, args.repeats)
    (args.out / "video.gif").write_bytes(gif)
    (args.out / "video.mp4").write_bytes(mp4)

    import imageio_ffmpeg

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "v.mp4"
        path.write_bytes(mp4)
        reader = imageio_ffmpeg.read_frames(str(path))
        meta = next(reader)
        w, h = meta["size"]
        back = np.stack([np.frombuffer(b, np.uint8).reshape(h, w, 3) for b in reader])
    with Image.open(io.BytesIO(gif)) as im:
        gif_back = []
        for k in range(im.n_frames):
            im.seek(k)
            gif_back.append(np.asarray(im.convert("RGB")))
    gif_back = np.stack(gif_back)
    f = frames.astype(np.int16)
    result = {
        **environment(), "imageio_ffmpeg": imageio_ffmpeg.__version__, "ffmpeg": meta.get("ffmpeg_version", ""),
        "args": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
        "recorded": recorded, "frames": int(frames.shape[0]), "frame_shape": list(frames.shape[1:]),
        "gif": {"bytes": len(gif), "encode_s": round(gif_s, 3), "same_bytes_each_repeat": gif_same,
                "frames_back": int(gif_back.shape[0]),
                "mean_abs_diff": round(float(np.abs(gif_back.astype(np.int16) - f).mean()), 3)},
        "mp4": {"bytes": len(mp4), "encode_s": round(mp4_s, 3), "same_bytes_each_repeat": mp4_same,
                "frames_back": int(back.shape[0]), "size_back": [int(h), int(w)],
                "mean_abs_diff": round(float(np.abs(back[:, :frames.shape[1], :frames.shape[2]].astype(np.int16)
                                                    - f).mean()), 3)},
    }
    result["gif_over_mp4_bytes"] = round(len(gif) / len(mp4), 2)
    write_json(args.out / "result.json", result)
    print(f"{frames.shape[0]} frames of {frames.shape[2]} x {frames.shape[1]}: GIF {len(gif) / 1024:.0f} KiB in "
          f"{gif_s:.2f} s, MP4 {len(mp4) / 1024:.0f} KiB in {mp4_s:.2f} s ({result['gif_over_mp4_bytes']}x smaller) "
          f"-> {args.out}")
    return result


if __name__ == "__main__":
    main()
