"""The one host loop of every long run: chunks of a jitted step, one checkpoint format, progress and metric logs.

    def chunk(state, start, stop):                  # the caller's jitted work for steps [start, stop)
        state, metrics = jitted_scan(state, jnp.arange(start, stop))
        return state, metrics                       # metrics: dict name -> [stop - start] array
    state, done, history = driver.run_chunks(chunk, state, total=5000, every=100, run_dir="runs/x",
                                             key_metric="coverage", time_limit_s=600)
    restored = driver.restore("runs/x", like=state) # (state, done, history, meta) or None
    meta = driver.read_meta("runs/x")               # the meta dict alone (the header member), or None

A "step" is whatever the caller counts (a MAP-Elites generation, a PPO update, a curriculum chunk). After every chunk
of ``every`` steps the driver

* extends ``history`` (name -> list of floats, one per step);
* writes ``run_dir/checkpoint.npz`` atomically (:func:`save_checkpoint`: the state pytree, ``done``, the history and
  a JSON ``meta`` dict), so a killed run loses at most one chunk; ``restore`` + ``run_chunks(start=done,
  history=history)`` continues it, and when the chunk function depends only on ``(state, start, stop)`` the result
  is the same as an uninterrupted run's. The checkpoint before it is kept as ``checkpoint.prev.npz`` until the new
  one is complete, so a latest checkpoint damaged after the fact still leaves one to resume from (``restore`` says
  how);
* rewrites ``run_dir/metrics.csv`` (one row per step) atomically and appends the chunk's scalars to TensorBoard
  event files in ``run_dir/tb`` (tensorboardX);
* moves a tqdm progress bar (ETA, steps per second, the ``key_metric``'s latest value), or without a terminal
  writes the same as plain lines (a log file gets no carriage returns);
* stops early (``done < total``; resume later) once ``time_limit_s`` has passed, or before a chunk that would end
  past it: the next chunk is predicted from the fastest rate (seconds per step) of the chunks so far, so a first
  chunk that compiled makes the prediction cautious; at least one chunk always runs. With ``fit_to_limit`` (a
  chunk function that takes any length without re-compiling) the first chunk under a time limit is ONE step (a
  probe of the rate) and later chunks are cut to the steps that fit, so the limit holds to within one step from
  the first chunk on.

Checkpoint format (``checkpoint.npz``, uncompressed npz): ``header`` = uint8 UTF-8 JSON ``{"format":
"jaxterrain-checkpoint", "version": 1, "done": int, "meta": {...}, "leaves": [names], "keys": [names of typed-key
leaves], "history": [names]}``; one member ``leaf:<keystr>`` per pytree leaf (``jax.tree_util.keystr`` of its path;
typed PRNG keys stored as their key data); one member ``history:<name>`` per metric ([done] float64).
:func:`load_checkpoint` reads it into the structure of a template pytree (``like``) and names the file and the leaf in
every ``ValueError``.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import shutil
import sys
import time
import zipfile
from pathlib import Path
from typing import Any, Callable, Optional

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain.runtime.io import atomic_save_npz, atomic_write_text

__all__ = ["CHECKPOINT_NAME", "METRICS_NAME", "PLAIN_EVERY_S", "MetricLog", "load_checkpoint", "read_meta", "restore", "run_chunks",
           "save_checkpoint", "write_checkpoint", "write_metrics_csv"]

FORMAT = "jaxterrain-checkpoint"
VERSION = 1
CHECKPOINT_NAME = "checkpoint.npz"
PREVIOUS_NAME = "checkpoint.prev.npz"
METRICS_NAME = "metrics.csv"
ChunkFn = Callable[[Any, int, int], tuple[Any, dict]]


# ----------------------------------------------------------------------------------------------------------------
# Checkpoints
# ----------------------------------------------------------------------------------------------------------------
def _is_key(x) -> bool:
    return hasattr(x, "dtype") and jnp.issubdtype(x.dtype, jax.dtypes.prng_key)


def _leaves(tree) -> list[tuple[str, Any]]:
    return [(jax.tree_util.keystr(path), leaf) for path, leaf in jax.tree_util.tree_flatten_with_path(tree)[0]]


def save_checkpoint(path: str | os.PathLike, state: Any, *, done: int, history: Optional[dict] = None,
                    meta: Optional[dict] = None) -> Path:
    """Write ``state`` (any pytree of arrays), ``done`` steps, ``history`` and ``meta`` to ``path`` atomically."""
    arrays, names, keys = {}, [], []
    for name, leaf in _leaves(jax.device_get(state)):
        if _is_key(leaf):
            keys.append(name)
            leaf = jax.random.key_data(leaf)
        names.append(name)
        arrays[f"leaf:{name}"] = np.asarray(leaf)
    history = history or {}
    for name, values in history.items():
        arrays[f"history:{name}"] = np.asarray(values, np.float64)
    header = {"format": FORMAT, "version": VERSION, "done": int(done), "meta": meta or {}, "leaves": names,
              "keys": keys, "history": list(history)}
    arrays["header"] = np.frombuffer(json.dumps(header).encode("utf-8"), np.uint8)
    return atomic_save_npz(path, **arrays)


_UNREADABLE = (zipfile.BadZipFile, EOFError, OSError, KeyError, ValueError, UnicodeDecodeError)


def _read(path: Path, header_only: bool = False) -> tuple[dict, dict]:
    """``(header, members)`` of a checkpoint file (``members`` empty with ``header_only``: npz reads lazily)."""
    if not path.is_file():
        raise FileNotFoundError(f"checkpoint {str(path)!r} does not exist")
    try:
        with np.load(path, allow_pickle=False) as data:
            members = {} if header_only else {name: data[name] for name in data.files if name != "header"}
            header = json.loads(bytes(data["header"]).decode("utf-8"))
    except _UNREADABLE as err:
        raise ValueError(f"checkpoint {str(path)!r} is not readable (truncated or corrupt?): {err}") from err
    if not isinstance(header, dict) or header.get("format") != FORMAT or header.get("version") != VERSION:
        raise ValueError(f"{str(path)!r} is not a {FORMAT} file of version {VERSION}")
    return header, members


def load_checkpoint(path: str | os.PathLike, like: Any, *, aliases: Optional[dict] = None,
                    defaults: tuple = (), optional: tuple = ()) -> tuple[Any, int, dict, dict]:
    """Read a :func:`save_checkpoint` file into the structure of ``like``: ``(state, done, history, meta)``.

    Every leaf of ``like`` must be stored with the same shape and dtype (``ValueError`` naming the file and leaf
    otherwise); typed PRNG keys come back typed. ``history`` maps names to lists of floats.

    Files of an older state layout: ``aliases`` maps a leaf's name (``jax.tree_util.keystr`` of its path) to the
    name an older version stored it under (read when the name itself is absent); a leaf whose name ends with one of
    ``defaults``, or starts with one of ``optional`` (a subtree added since, e.g. ``".policy.env_state"``), and is
    absent takes ``like``'s value (a field added since, e.g. ``".episode.progress"``).
    """
    path = Path(path)
    header, members = _read(path)
    typed = set(header.get("keys", []))
    leaves = []
    for name, ref in _leaves(like):
        stored = members.get(f"leaf:{name}")
        if stored is None and aliases and name in aliases:
            stored = members.get(f"leaf:{aliases[name]}")
        if stored is None and (any(name.endswith(d) for d in defaults)
                               or any(name == o or name.startswith(o + ".") or name.startswith(o + "[")
                                      for o in optional)):
            leaves.append(ref)
            continue
        if stored is None:
            raise ValueError(f"checkpoint {str(path)!r} has no leaf {name!r}: it was written for another state")
        want = jax.random.key_data(ref) if _is_key(ref) else np.asarray(ref)
        if stored.shape != want.shape or stored.dtype != want.dtype:
            raise ValueError(f"checkpoint {str(path)!r}: leaf {name!r} is {stored.shape} {stored.dtype}, the state "
                             f"needs {want.shape} {want.dtype}")
        if _is_key(ref):
            if name not in typed:
                raise ValueError(f"checkpoint {str(path)!r}: leaf {name!r} is not a PRNG key")
            leaves.append(jax.random.wrap_key_data(jnp.asarray(stored), impl=jax.random.key_impl(ref)))
        else:
            leaves.append(jnp.asarray(stored))
    state = jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(like), leaves)
    history = {name: [float(v) for v in members[f"history:{name}"]] for name in header["history"]}
    return state, int(header["done"]), history, dict(header.get("meta") or {})


def read_meta(run_dir: str | os.PathLike) -> Optional[dict]:
    """The ``meta`` dict of ``run_dir/checkpoint.npz`` without reading its state (only the header member is read),
    or None when the folder holds no checkpoint; ``ValueError`` naming the file when it is not readable."""
    path = Path(run_dir) / CHECKPOINT_NAME
    if not path.exists():
        return None
    return dict(_read(path, header_only=True)[0].get("meta") or {})


def restore(run_dir: str | os.PathLike, like: Any, **compat) -> Optional[tuple[Any, int, dict, dict]]:
    """:func:`load_checkpoint` of ``run_dir/checkpoint.npz``, or None when the folder holds no checkpoint.

    A damaged latest checkpoint raises ``ValueError`` naming it and, when ``checkpoint.prev.npz`` (one chunk
    earlier) exists, saying to move that one into its place to resume from it."""
    path = Path(run_dir) / CHECKPOINT_NAME
    if not path.exists():
        return None
    try:
        return load_checkpoint(path, like, **compat)
    except ValueError as err:
        previous = Path(run_dir) / PREVIOUS_NAME
        if previous.exists():
            raise ValueError(f"{err}. The checkpoint one chunk earlier is kept: to resume from it, run "
                             f"`mv {previous} {path}` and resume again") from err
        raise


def write_checkpoint(run_dir: str | os.PathLike, state, done: int, history: dict, meta: Optional[dict]) -> None:
    """Write ``checkpoint.npz`` and keep the one it replaces as ``checkpoint.prev.npz``.

    The new checkpoint is complete (written to a temporary file and fsynced) before anything is renamed, the old
    one is linked to ``checkpoint.prev.npz`` first, and the new one then replaces it with one ``os.replace``: a kill
    at any moment leaves ``checkpoint.npz`` readable (the old or the new one). :func:`run_chunks` writes its
    checkpoints with it; a loop of its own (several runs in one program) may too."""
    run_dir = Path(run_dir)
    tmp = run_dir / f".{CHECKPOINT_NAME}.next"
    save_checkpoint(tmp, state, done=done, history=history, meta=meta)
    latest = run_dir / CHECKPOINT_NAME
    if latest.exists():
        prev_tmp = run_dir / f".{PREVIOUS_NAME}.next"
        prev_tmp.unlink(missing_ok=True)
        try:
            os.link(latest, prev_tmp)
        except OSError:  # a file system without hard links
            shutil.copyfile(latest, prev_tmp)
        os.replace(prev_tmp, run_dir / PREVIOUS_NAME)
    os.replace(tmp, latest)


# ----------------------------------------------------------------------------------------------------------------
# Metric logs
# ----------------------------------------------------------------------------------------------------------------
class MetricLog:
    """``run_dir/metrics.csv`` (rewritten atomically from the whole history) and TensorBoard events in
    ``run_dir/tb`` (appended; tensorboardX). Steps are numbered from 1 (step ``s`` = after the s-th step)."""

    def __init__(self, run_dir: str | os.PathLike, offset: int = 0):
        self.run_dir = Path(run_dir)
        self.offset = offset
        self._tb = None
        try:
            from tensorboardX import SummaryWriter

            self._tb = SummaryWriter(str(self.run_dir / "tb"))
        except ImportError:  # pragma: no cover - tensorboardX is a dependency; the CSV is enough
            pass

    def write(self, history: dict, start: int, stop: int) -> None:
        """Log steps ``[start, stop)`` of ``history`` (name -> list with one value per step from 0)."""
        names = sorted(history)
        write_metrics_csv(self.run_dir, history, self.offset)
        if self._tb is not None:
            for name in names:
                for i in range(start, min(stop, len(history[name]))):
                    value = history[name][i]
                    if math.isfinite(value):
                        self._tb.add_scalar(name, value, self.offset + i + 1)
            self._tb.flush()

    def close(self) -> None:
        if self._tb is not None:
            self._tb.close()


def write_metrics_csv(run_dir: str | os.PathLike, history: dict, offset: int = 0) -> None:
    """``run_dir/metrics.csv``, atomically: a ``step`` column (from ``offset + 1``) and one per name of ``history``
    (name -> list with one value per step from 0), sorted by name. :class:`MetricLog` writes it after every chunk; a
    caller that knows rows inside a chunk (e.g. a compiled block's per-chunk callback) may write more of them."""
    names = sorted(history)
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["step"] + names)
    n = max((len(v) for v in history.values()), default=0)
    for i in range(n):
        w.writerow([offset + i + 1] + [_fmt(history[k][i]) if i < len(history[k]) else "" for k in names])
    atomic_write_text(Path(run_dir) / METRICS_NAME, buf.getvalue())


def _fmt(v: float) -> str:
    return repr(float(v))


# ----------------------------------------------------------------------------------------------------------------
# The loop
# ----------------------------------------------------------------------------------------------------------------
PLAIN_EVERY_S = 10.0
"""Without a terminal (a log file, a batch job), progress is a plain line on stderr at most this often."""


class _PlainProgress:
    """Progress as plain lines (no carriage returns) where stderr is not a terminal: the first chunk, then at most
    one line every :data:`PLAIN_EVERY_S` seconds, and the last."""

    def __init__(self, total: int, start: int, desc: str, unit: str):
        self.total, self.desc, self.unit = total, desc or "run", unit
        self.t0, self.start, self.last = time.perf_counter(), start, -float("inf")

    def line(self, info: dict, key_metric: Optional[str]) -> None:
        now = time.perf_counter()
        if now - self.last < PLAIN_EVERY_S and info["done"] < self.total:
            return
        self.last = now
        done, total = info["done"], self.total
        rate = (done - self.start) / max(now - self.t0, 1e-9)
        eta = (total - done) / rate if rate > 0 else float("inf")
        metric = f", {key_metric} {info[key_metric]:.4g}" if key_metric and key_metric in info else ""
        print(f"{self.desc}: {done}/{total} {self.unit}s ({100.0 * done / max(total, 1):.0f} %), "
              f"{rate:.3g} {self.unit}s/s, {now - self.t0:.0f} s, ETA {eta:.0f} s{metric}", file=sys.stderr,
              flush=True)


def _bar(progress, total: int, start: int, desc: str, unit: str):
    if progress is not True and progress != "plain":
        return None
    if progress == "plain" or not sys.stderr.isatty():  # a command's --no-progress, or a log file
        return _PlainProgress(total, start, desc, unit)
    try:
        from tqdm.auto import tqdm
    except ImportError:  # pragma: no cover
        return _PlainProgress(total, start, desc, unit)
    return tqdm(total=total, initial=start, desc=desc or None, unit=unit, dynamic_ncols=True, file=sys.stderr)


def _extend(history: dict, metrics: dict, n: int) -> None:
    for name, values in jax.device_get(metrics).items():
        v = np.asarray(values, np.float64)
        if v.ndim > 1:  # a batch of runs (trials, seeds): log the mean
            v = np.nanmean(v.reshape(-1, v.shape[-1]), axis=0) if v.size else v
        v = np.broadcast_to(v.reshape(-1), (n,)) if v.size in (1, n) else v.reshape(-1)[-n:]
        history.setdefault(name, []).extend(float(x) for x in v)


def run_chunks(chunk_fn: ChunkFn, state: Any, *, total: int, every: int, start: int = 0,
               history: Optional[dict] = None, run_dir: str | os.PathLike | None = None,
               key_metric: Optional[str] = None, time_limit_s: Optional[float] = None,
               progress: bool | str | Callable[[dict], None] = True, desc: str = "", unit: str = "step",
               meta: Optional[dict] = None, wall_s: float = 0.0, fit_to_limit: bool = False) -> tuple[Any, int, dict]:
    """Run steps ``[start, total)`` as ``chunk_fn(state, a, b)`` calls of at most ``every`` steps.

    Args:
      chunk_fn: ``(state, start, stop) -> (state, metrics)``, metrics a dict of ``[stop - start]`` arrays (or
        scalars, repeated; or ``[..., stop - start]`` for batched runs, averaged over the leading axes).
      state: the pytree carried between chunks (checkpointed whole).
      total, every, start: steps in all, steps per chunk (and between checkpoints), steps already done.
      history: metrics of the steps already done (name -> list of floats), from :func:`restore`.
      run_dir: folder of ``checkpoint.npz``, ``metrics.csv`` and ``tb/``; None writes nothing.
      key_metric: the metric shown beside the progress bar.
      time_limit_s: the seconds (from the call) the run may take: stop after the chunk in which they passed, or
        before a chunk predicted (at the fastest seconds per step so far) to end past them.
      fit_to_limit: ``chunk_fn`` takes any ``stop - start`` without re-compiling (e.g. a traced step count), so
        a chunk predicted to end past the time limit is shortened to the steps that fit instead of skipped, and
        under a time limit the first chunk is one step (the rate is not known before it): the limit is then
        honoured to within one step, not one chunk, from the first chunk on. ``chunk_fn``'s results must not
        depend on where the chunks are cut (the curriculum's blocks carry their env states).
      progress: True for a tqdm bar on stderr (plain lines, at most one per :data:`PLAIN_EVERY_S` seconds, where
        stderr is not a terminal); ``"plain"`` for those plain lines always (a command's ``--no-progress``); a
        callable receives a dict per chunk (``done``, ``total``, ``seconds``, ``steps_per_s`` and the latest value
        of every metric); False is silent.
      meta: a JSON-serialisable dict stored in every checkpoint (e.g. the run's config).
      wall_s: seconds of wall time the run had taken before this call (a restored checkpoint's ``meta["wall_s"]``,
        plus any set-up of this call). Every checkpoint's meta gets ``"wall_s"``: that plus the seconds since this
        call began, so a run resumed across commands knows its whole wall time.

    Returns ``(state, done, history)``; ``done < total`` when the time limit stopped the run.
    """
    for name, value, low in (("total", total, 0), ("every", every, 1), ("start", start, 0)):
        if not isinstance(value, (int, np.integer)) or value < low:
            raise ValueError(f"run_chunks: {name} must be an integer >= {low}; got {value!r}")
    if not (isinstance(wall_s, (int, float, np.floating)) and math.isfinite(wall_s) and wall_s >= 0):
        raise ValueError(f"run_chunks: wall_s must be a finite number of seconds >= 0; got {wall_s!r}")
    if time_limit_s is not None and not time_limit_s > 0:
        raise ValueError(f"run_chunks: time_limit_s must be > 0 seconds or None; got {time_limit_s!r}")
    history = {k: list(v) for k, v in (history or {}).items()}
    log = MetricLog(run_dir) if run_dir is not None else None
    bar = _bar(progress, total, start, desc, unit)
    t0 = time.perf_counter()
    done = start
    rate = float("inf")  # the fastest seconds per step so far
    try:
        while done < total:
            n = min(every, total - done)
            if time_limit_s is not None and fit_to_limit and done == start:
                n = 1  # a probe: the rate is not known yet, and a chunk may be cut anywhere
            if time_limit_s is not None and done > start:  # the rate is known: does the next chunk fit?
                left = time_limit_s - (time.perf_counter() - t0)
                if rate * n > left:
                    n = min(n, int(left // rate)) if fit_to_limit and left > 0 else 0
                if n < 1:
                    break
            stop = done + n
            t1 = time.perf_counter()
            state, metrics = chunk_fn(state, done, stop)
            _extend(history, metrics, stop - done)
            seconds = time.perf_counter() - t1
            if run_dir is not None:
                write_checkpoint(Path(run_dir), state, stop, history,
                            {**(meta or {}), "wall_s": float(wall_s) + time.perf_counter() - t0})
                log.write(history, done, stop)
            info = {"done": stop, "total": total, "seconds": seconds, "steps_per_s": (stop - done) / max(seconds, 1e-9),
                    **{k: v[-1] for k, v in history.items() if v}}
            rate = min(rate, seconds / (stop - done))
            done = stop
            if isinstance(bar, _PlainProgress):
                bar.line(info, key_metric)
            elif bar is not None:
                if key_metric is not None and key_metric in info:
                    bar.set_postfix({key_metric: f"{info[key_metric]:.4g}"}, refresh=False)
                bar.update(stop - bar.n)
            elif callable(progress):
                progress(info)
    finally:
        if bar is not None and not isinstance(bar, _PlainProgress):
            bar.close()
        if log is not None:
            log.close()
    return state, done, history
