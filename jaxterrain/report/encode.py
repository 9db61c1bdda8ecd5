"""Encoders of a report's videos: frames [F, h, w, 3] uint8 -> the bytes of an animated GIF or of an MP4.

    from jaxterrain.report import encode
    gif = encode.gif_bytes(frames, fps=15)          # Pillow: always installed
    mp4 = encode.mp4_bytes(frames, fps=15)          # H.264 through imageio-ffmpeg: pip install 'jaxterrain[video]'

:func:`gif_bytes` is lossless against its palette of 255 colours; :func:`mp4_bytes` writes H.264 (yuv420p, x264 CRF
25) through ``imageio-ffmpeg``, which ships its own static ffmpeg binary (the optional extra ``jaxterrain[video]``;
no system ffmpeg needed), and :func:`mp4_encoder` says in one line when that extra is missing, before anything is
drawn. Both give the same bytes for the same frames. One video at ``evaluate --videos``' default size (two 320 x 240
panels under the label bar: 644 x 274 pixels, 15 frames a second; 47 frames of a 3.0-s walk of two walkers) on 2
CPU cores shared with other work (2026-11-29, commit 2ed53e7, median of 5; ``benchmarks/video_formats.py``,
``docs/suite.md``): GIF 984 KiB written in 0.33 s, MP4 81 KiB in 0.96 s (12.1 times smaller; the ffmpeg process
start included). :mod:`jaxterrain.report.render` re-exports these names.
"""

from __future__ import annotations

import io
import os

import numpy as np

__all__ = ["gif_bytes", "mp4_bytes", "mp4_encoder", "MP4_EXTRA"]

MP4_EXTRA = "MP4 videos need imageio-ffmpeg (its own ffmpeg binary): pip install 'jaxterrain[video]'"
"""The one line :func:`mp4_encoder` raises where the optional extra ``jaxterrain[video]`` is not installed."""


def gif_bytes(frames: np.ndarray, fps: float = 15.0, loop: int = 0, optimize: bool = True) -> bytes:
    """An animated GIF (Pillow) of ``frames`` [F, h, w, 3] uint8 at ``fps`` (browsers round each frame to 10 ms and
    slow frames under 20 ms down, so fps is capped at 50). One palette of 255 colours for all frames; ``optimize``
    lets Pillow drop unused palette entries per frame: lossless (the frames decode to the same pixels), and 37 %
    smaller on a 67-frame 644 x 274 video of two walkers (579 KB against 924 KB; 2026-11-29, Pillow 13.0)."""
    from PIL import Image

    frames = np.asarray(frames, np.uint8)
    duration = int(round(1000.0 / min(max(float(fps), 1.0), 50.0)))
    images = [Image.fromarray(f) for f in frames]
    palette = images[0].quantize(colors=255, method=Image.Quantize.MEDIANCUT)
    images = [im.quantize(palette=palette, dither=Image.Dither.NONE) for im in images]
    buf = io.BytesIO()
    images[0].save(buf, format="GIF", save_all=True, append_images=images[1:], duration=duration, loop=loop,
                   optimize=bool(optimize), disposal=1)
    return buf.getvalue()


def mp4_encoder():
    """The ``imageio_ffmpeg`` module (the optional extra ``jaxterrain[video]``), its ffmpeg binary found;
    ``ImportError`` with :data:`MP4_EXTRA` (one line, and why) where it does not import or has no binary. Cheap:
    imageio-ffmpeg runs ``ffmpeg -version`` once per process to find the binary (0.09 s on a 2-core CPU,
    2026-11-29); call it when the arguments are checked, before anything walks."""
    import warnings

    try:
        import imageio_ffmpeg
    except ImportError:
        raise ImportError(MP4_EXTRA) from None
    try:
        with warnings.catch_warnings():  # JAX's warning of os.fork(): the child process execs ffmpeg at once
            warnings.filterwarnings("ignore", message=r"os\.fork\(\) was called", category=RuntimeWarning)
            imageio_ffmpeg.get_ffmpeg_exe()
    except RuntimeError as err:  # installed without a binary, and none on IMAGEIO_FFMPEG_EXE / PATH
        raise ImportError(f"{MP4_EXTRA} (imageio-ffmpeg found no ffmpeg binary: {str(err).splitlines()[0]})") from None
    return imageio_ffmpeg


def mp4_bytes(frames: np.ndarray, fps: float = 15.0, quality: float = 5.0) -> bytes:
    """An MP4 (H.264, yuv420p, ``+faststart`` so that a browser starts playing at once; ``imageio_ffmpeg
    .write_frames`` with its own ffmpeg, one encoder thread) of ``frames`` [F, h, w, 3] uint8 at ``fps``
    (> 0; no cap, unlike :func:`gif_bytes`). yuv420p needs even sides: an odd ``h`` or ``w`` is padded by one row
    or column repeating the edge pixels, so the video is ``2 * ceil(h / 2)`` x ``2 * ceil(w / 2)``; nothing is
    rescaled. ``quality`` in [1, 10] (imageio-ffmpeg's scale: x264's CRF ``int((1 - quality / 10) * 51)``, 25 at
    the default 5). Lossy: the frames read back are close to, not equal to, ``frames``. ``ImportError`` with
    :data:`MP4_EXTRA` without the extra; ``ValueError`` for frames of another shape, an empty clip or a bad
    ``fps`` / ``quality``."""
    import tempfile
    import warnings

    frames = np.asarray(frames)
    if frames.ndim != 4 or frames.shape[-1] != 3 or frames.shape[0] < 1 or frames.dtype != np.uint8:
        raise ValueError(f"frames must be [F >= 1, h, w, 3] uint8; got shape {frames.shape} {frames.dtype}")
    if not np.isfinite(fps) or fps <= 0:
        raise ValueError(f"fps must be a number > 0; got {fps!r}")
    if not 1.0 <= float(quality) <= 10.0:
        raise ValueError(f"quality must be a number in [1, 10]; got {quality!r}")
    ffmpeg = mp4_encoder()
    _, h, w, _ = frames.shape
    frames = np.ascontiguousarray(np.pad(frames, ((0, 0), (0, h % 2), (0, w % 2), (0, 0)), mode="edge"))
    with tempfile.TemporaryDirectory(prefix="jaxterrain-mp4-") as tmp, warnings.catch_warnings():
        # JAX warns of os.fork() in a multithreaded process; ffmpeg's child process execs at once (subprocess)
        warnings.filterwarnings("ignore", message=r"os\.fork\(\) was called", category=RuntimeWarning)
        path = os.path.join(tmp, "video.mp4")
        writer = ffmpeg.write_frames(path, (frames.shape[2], frames.shape[1]), fps=float(fps), quality=float(quality),
                                     codec="libx264", pix_fmt_out="yuv420p", macro_block_size=1,
                                     ffmpeg_log_level="error",
                                     output_params=["-movflags", "+faststart", "-threads", "1"])
        writer.send(None)  # start ffmpeg
        try:
            for frame in frames:
                writer.send(frame)
        finally:
            writer.close()
        with open(path, "rb") as fh:
            return fh.read()
