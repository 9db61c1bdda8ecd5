"""How long the first call of each long program takes (tracing and XLA compiling, plus MuJoCo Warp's kernels on a
GPU), in one table, so that every command says so before it goes quiet.

A command wraps the call that compiles in :func:`compiling`, which prints :func:`first_call_note` before it and the
seconds it took after, e.g.::

    compiling the curriculum block, PPO fine-tuning and evaluations of every trial in one call (2 trials, jax
    physics; cpu): about 5-9 min on 2 CPU cores, 30 s-2 min on a GPU
    compiled curriculum-block in 496 s

:data:`ESTIMATES` maps ``(program, platform)`` (platform: ``"cpu"`` or ``"gpu"``, JAX's default backend) to
:class:`Estimate` (seconds, low and high, and where the figure comes from); :data:`SMOKE_MINUTES` gives the whole
``--preset smoke`` command on 2 CPU cores where it was measured (the presets' ``--help`` quotes it).

This module imports nothing but the standard library (``python -m experiments --help`` reads it by file, without
importing JAX); :func:`first_call_note` asks JAX for the platform only when none is given.
"""

from __future__ import annotations

import contextlib
import sys
import time
from typing import Iterator, NamedTuple, Optional

__all__ = ["Estimate", "PROGRAMS", "CPU_NOTE", "ESTIMATES", "SMOKE_MINUTES", "WARP_FIRST_CHUNK", "platform_of",
           "first_chunk_note", "first_call_note", "announce", "compiling"]


class Estimate(NamedTuple):
    """The first call of a program on one platform: ``low_s`` to ``high_s`` seconds; ``source`` says how it is
    known (a measurement and where it is recorded, or ``"rough"``)."""

    low_s: float
    high_s: float
    source: str


PROGRAMS = {
    "curriculum-block": "the curriculum block, PPO fine-tuning and evaluations of every trial in one call",
    "suite-walk": "the walks of the held-out suite",
    "map-elites": "a MAP-Elites generation with the walker's fitness",
    "map-elites-slope": "a MAP-Elites generation, slope fitness without walking",
    "ppo-chunk": "a PPO chunk of the walker",
    "walks": "the base policy's walks",
    "gan-step": "the GAN's training step",
}
"""What each program of :data:`ESTIMATES` is, as the note names it."""

CPU_NOTE = "2 CPU cores"
"""The CPU the ``"cpu"`` figures were measured on (more cores compile faster)."""

ESTIMATES: dict[tuple[str, str], Estimate] = {
    # learn --preset smoke, 2 CPU cores, 2026-11 (issue 59): 532 s in all, 36 s of them chunks
    ("curriculum-block", "cpu"): Estimate(300, 540, "measured: learn --preset smoke, 532 s in all on 2 cores"),
    # one H200: block set-up and compile 22-47 s, first chunk 87 s on a bare machine while Warp builds its kernels
    ("curriculum-block", "gpu"): Estimate(30, 150, "measured: benchmarks/RESULTS.md, learn block on one H200"),
    # evaluate --preset smoke, 2 CPU cores: the first call 210 s
    ("suite-walk", "cpu"): Estimate(150, 240, "measured: evaluate --preset smoke, first call 210 s on 2 cores"),
    ("suite-walk", "gpu"): Estimate(30, 120, "rough"),
    ("map-elites", "cpu"): Estimate(120, 360, "rough"),
    # one H200: about 70-90 s of compile for generations 0 and 1 (benchmarks/RESULTS.md)
    ("map-elites", "gpu"): Estimate(60, 120, "measured: benchmarks/RESULTS.md, evolve --preset gpu-short"),
    ("map-elites-slope", "cpu"): Estimate(10, 60, "rough"),
    ("map-elites-slope", "gpu"): Estimate(10, 40, "rough"),
    ("ppo-chunk", "cpu"): Estimate(60, 240, "rough"),
    # one H200: rl.compiled_chunk's first call 41.5 s (benchmarks/RESULTS.md, PPO against brax)
    ("ppo-chunk", "gpu"): Estimate(30, 60, "measured: benchmarks/RESULTS.md, first PPO chunk on one H200"),
    # quickstart on 2 cores: about 2 min in all, most of it the walker's compile (README)
    ("walks", "cpu"): Estimate(60, 180, "measured: quickstart, about 2 min in all on 2 cores"),
    ("walks", "gpu"): Estimate(20, 90, "rough"),
    ("gan-step", "cpu"): Estimate(20, 90, "rough"),
    ("gan-step", "gpu"): Estimate(20, 60, "rough"),
}
"""``(program, platform) -> Estimate`` of the first call, the one table every command reads."""

SMOKE_MINUTES: dict[str, tuple[float, float]] = {
    "learn": (6, 10),        # 532 s on 2 cores (issue 59)
    "curriculum": (8, 20),   # learn's block compiled once, then every treatment's chunks
    "evaluate": (4, 6),      # first call 210 s, then the policies' walks and figures
}
"""Minutes of a whole ``--preset smoke`` command on :data:`CPU_NOTE`, for the commands where it was measured or
follows from a measured one; the presets' ``--help`` quotes it."""


def platform_of(platform: Optional[str] = None) -> str:
    """``"cpu"`` or ``"gpu"``: ``platform`` if given (``"cuda"`` / ``"rocm"`` count as ``"gpu"``), else JAX's default
    backend (a TPU counts as a GPU here)."""
    if platform is None:
        import jax

        platform = jax.default_backend()
    return "cpu" if platform == "cpu" else "gpu"


def _span(e: Estimate) -> str:
    def one(s: float) -> str:
        return f"{s:.0f} s" if s < 90 else f"{s / 60:.0f} min"

    low, high = one(e.low_s), one(e.high_s)
    if low[-1] == high[-1]:  # one unit: "2-4 min"
        return f"{low.split()[0]}-{high}"
    return f"{low}-{high}"


WARP_FIRST_CHUNK = ("on a fresh machine the first chunk also builds MuJoCo Warp's kernels: about 65-90 s more on "
                    "an H200, none once cached")
"""What a curriculum block's first chunk adds under MuJoCo Warp (its kernels build at their first launch, after the
XLA compile that :func:`compiling` times): measured, Experiment 4's first chunks on a fresh 2 x H200, 89.8 s and
72.4 s (blind) and 93.2 s and 77.9 s (perceptive) against 5.0-5.6 s for later ones (2026-11-30,
``docs/results/exp4/logs/``)."""


def first_chunk_note(physics: str) -> str:
    """What a curriculum block's first run adds after its compile on this ``physics`` (:data:`WARP_FIRST_CHUNK` for
    ``"warp"``, else nothing): the ``then`` of its :func:`compiling`."""
    return WARP_FIRST_CHUNK if physics == "warp" else ""


def first_call_note(program: str, detail: str = "", platform: Optional[str] = None, then: str = "") -> str:
    """One line before ``program``'s first (compiling) call: what compiles, and about how long it takes on this
    platform and on the other one, e.g. ``compiling the walks of the held-out suite (jax physics, cpu): about 2-4 min
    on 2 CPU cores, 30 s-2 min on a GPU``. ``detail`` (sizes, backend) goes in the brackets; ``then`` (what the first
    run adds after the compile, e.g. :func:`first_chunk_note`) after a semicolon. KeyError for a program not in
    :data:`PROGRAMS`."""
    what = PROGRAMS[program]
    here = platform_of(platform)
    mine, other = ESTIMATES[(program, here)], ESTIMATES[(program, "gpu" if here == "cpu" else "cpu")]
    where = {"cpu": f"on {CPU_NOTE}", "gpu": "on a GPU"}
    inside = "; ".join(x for x in (detail, here) if x)
    return (f"compiling {what} ({inside}): about {_span(mine)} {where[here]}, {_span(other)} "
            f"{where['gpu' if here == 'cpu' else 'cpu']}" + (f"; {then}" if then else ""))


def announce(program: str, detail: str = "", platform: Optional[str] = None, file=None, then: str = "") -> None:
    """Print :func:`first_call_note` (to stdout, flushed)."""
    print(first_call_note(program, detail, platform, then), file=file or sys.stdout, flush=True)


@contextlib.contextmanager
def compiling(program: str, detail: str = "", platform: Optional[str] = None, file=None,
              then: str = "") -> Iterator[None]:
    """Around the first call of ``program``: :func:`announce` before it (``then``: what its first run adds later),
    ``compiled ... in N s`` after it (the call's whole time, its first run included)."""
    out = file or sys.stdout
    announce(program, detail, platform, out, then)
    t0 = time.perf_counter()
    yield
    print(f"compiled {program} in {time.perf_counter() - t0:.0f} s", file=out, flush=True)
