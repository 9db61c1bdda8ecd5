"""Shared helpers of the benchmark scripts: device/commit facts, timing with warm-up and medians, result files."""

from __future__ import annotations

import datetime
import json
import os
import platform
import statistics
import time
from pathlib import Path
from typing import Any, Callable, Sequence

import jax


def environment() -> dict[str, Any]:
    """Facts every result carries: device, date, commit (``jaxterrain.runtime.provenance.git_commit``: ``$JAXTERRAIN_COMMIT``
    first, else the checkout's short hash), versions."""
    from jaxterrain.runtime.provenance import git_commit

    dev = jax.devices()[0]
    return {
        "device": getattr(dev, "device_kind", str(dev)),
        "platform": dev.platform,
        "cpu_count": os.cpu_count(),
        "host": platform.node(),
        "date": datetime.date.today().isoformat(),
        "commit": git_commit(short=True, mark_dirty=False),
        "jax": jax.__version__,
    }


def block(x: Any) -> Any:
    return jax.block_until_ready(x)


def timed(fn: Callable[[], Any]) -> tuple[Any, float]:
    """``(fn() blocked until ready, seconds it took)``."""
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn())
    return out, time.perf_counter() - t0


def median_time(fn: Callable[[Any], Any], inputs: Sequence[Any], repeats: int = 5, warmup: int = 1) -> float:
    """Median wall time (s) of ``fn(inputs[i])`` over ``repeats`` calls, rotating through ``inputs``.

    ``warmup`` calls first (compilation). Device work is waited for with ``block_until_ready``.
    """
    for i in range(warmup):
        block(fn(inputs[i % len(inputs)]))
    times = []
    for i in range(repeats):
        x = inputs[i % len(inputs)]
        t0 = time.perf_counter()
        block(fn(x))
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def first_and_best(call: Callable[[int], Any], repeats: int) -> tuple[float, float, Any]:
    """``(first_s, best_s, out)``: the wall time of ``call(0)`` (compile and first call), the best of ``call(1)`` ..
    ``call(repeats)``, and the last call's output; device work waited for with ``block_until_ready``."""
    t0 = time.perf_counter()
    out = block(call(0))
    first = time.perf_counter() - t0
    times = []
    for i in range(1, repeats + 1):
        t0 = time.perf_counter()
        out = block(call(i))
        times.append(time.perf_counter() - t0)
    return first, min(times), out


def write_json(path: str | os.PathLike | None, payload: dict[str, Any]) -> None:
    if not path:
        return
    from jaxterrain.runtime.io import atomic_write_text

    atomic_write_text(Path(path), json.dumps(payload, indent=2, default=float))


def markdown_table(rows: list[dict[str, Any]], columns: Sequence[str]) -> str:
    def fmt(v: Any) -> str:
        if isinstance(v, float):
            return f"{v:,.3g}" if abs(v) < 1000 else f"{v:,.0f}"
        return str(v)

    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(fmt(r.get(c, "")) for c in columns) + " |" for r in rows]
    return "\n".join(lines)
