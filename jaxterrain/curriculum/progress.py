"""A running treatment's progress on the host: its per-chunk metrics (``metrics.csv``, written after every chunk,
inside a compiled block too) and its progress lines, both fed by the block's per-chunk callback
(:mod:`jaxterrain.curriculum.runner`)."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from jaxterrain.runtime import driver

__all__ = ["ChunkMetrics", "ChunkProgress", "chunk_metrics", "history_metrics"]


class ChunkMetrics:
    """A treatment's ``metrics.csv`` inside its compiled blocks: after every chunk, the rows (:func:`chunk_metrics`)
    of the chunks that every trial still running has finished, up to the block's end, from the block's per-chunk
    callback; the driver writes the same rows again at the block's end, with TensorBoard's. Call :meth:`begin`
    before each block (the trials' history so far). The callback sees every trial's state, also in a block that
    computes the running trials only (``compact``: ``population.run_live``). Not for a mesh of several devices (a
    callback there sees one device's progress): there metrics.csv moves per block."""

    def __init__(self, folder: Path):
        self.folder = Path(folder)
        self.history = None
        self.stop = self.written = 0

    def begin(self, states, stop: int) -> None:
        """Before a block that ends at chunk ``stop``: host copies of ``states.history``."""
        self.history = type(states.history)(*(np.array(x) for x in states.history))  # [T, C] each
        self.stop, self.written = int(stop), int(np.min(np.asarray(states.chunk)))

    def __call__(self, chunk, hardest, done, history) -> None:
        if self.history is None or chunk.shape[0] != self.history.hardest.shape[0]:
            return
        self.history = type(self.history)(*(np.array(x) for x in history))
        running = ~np.asarray(done, bool)
        upto = min(int(np.min(chunk[running])) if running.any() else int(np.max(chunk)), self.stop)
        if upto <= self.written:
            return
        self.written = upto
        metrics = history_metrics(self.history, 0, upto)
        driver.write_metrics_csv(self.folder, {k: [float(x) for x in v] for k, v in metrics.items()})


class ChunkProgress:
    """A treatment's progress inside its compiled blocks: one line on stderr at most every ``every_s`` seconds (the
    driver's :data:`~jaxterrain.runtime.driver.PLAIN_EVERY_S`), ``desc: chunk C of N, hardest H cells (mean of the
    trials), S s/chunk``; through ``tqdm.write`` (above a progress bar) when stderr is a terminal. ``unit``: what
    the hardest terrain is measured in (``cells`` of an archive's grid; ``rank`` for a folder of terrains)."""

    def __init__(self, desc: str, total: int, start: int, every_s: float | None = None, unit: str = "cells"):
        self.desc, self.total, self.start, self.unit = desc, int(total), int(start), unit
        self.every_s = float(driver.PLAIN_EVERY_S if every_s is None else every_s)
        self.t0 = self.last = time.perf_counter()
        self.lines: list[str] = []

    def __call__(self, chunk, hardest, done, history=None) -> None:
        now = time.perf_counter()
        reached = int(np.max(chunk)) if chunk.size else self.start
        if now - self.last < self.every_s and reached < self.total:
            return
        self.last = now
        rate = (now - self.t0) / max(reached - self.start, 1)
        line = (f"{self.desc}: chunk {reached} of {self.total}, hardest {float(np.mean(hardest)):.2f} {self.unit} "
                f"(mean of {hardest.size} trials, {int(np.sum(~done))} running), {rate:.1f} s/chunk")
        self.lines.append(line)
        if sys.stderr.isatty():
            try:
                from tqdm import tqdm

                tqdm.write(line, file=sys.stderr)
                return
            except ImportError:
                pass
        print(line, file=sys.stderr, flush=True)


def chunk_metrics(states, start: int, stop: int) -> dict:
    """Per-chunk ``[stop - start]`` metrics over trials: hardest (mean, a finished trial keeps its last value),
    evaluation (mean of the trials still running that were evaluated in that chunk: under ``eval_lag`` a chunk
    after a terrain's last evaluation is not), trials still running."""
    return history_metrics(states.history, start, stop)


def history_metrics(h, start: int, stop: int) -> dict:
    """:func:`chunk_metrics` of the trials' ``History`` ``h`` (leaves ``[T, C]``, host or device arrays)."""
    hardest = np.asarray(h.hardest, np.float64)
    epoch = np.asarray(h.epoch)
    carried = np.zeros_like(hardest)
    for t in range(hardest.shape[0]):
        n = int(np.sum(epoch[t] >= 0))
        carried[t, :n] = hardest[t, :n]
        carried[t, n:] = hardest[t, n - 1] if n else 0.0
    ev = np.asarray(h.evaluation, np.float64)[:, start:stop]
    running = np.sum(epoch[:, start:stop] >= 0, axis=0)
    scored = np.sum(~np.isnan(ev), axis=0)  # a chunk trained but not evaluated (eval_lag) holds NaN
    evaluation = np.where(scored > 0, np.nansum(ev, axis=0) / np.maximum(scored, 1), np.nan)
    return {"hardest": carried[:, start:stop].mean(axis=0), "evaluation": evaluation,
            "trials_running": running.astype(np.float64)}
