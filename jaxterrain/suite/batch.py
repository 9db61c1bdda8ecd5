"""Many walkers on a held-out suite, resumably: one result file per walker, written the moment it is walked, so a
run cut short (a time limit, a lost machine) continues where it stopped and never walks a walker twice.

    from jaxterrain.suite import batch
    jobs = batch.base_jobs("humanoid", keys=10) + batch.walker_jobs(["docs/results/exp3_gpushort"])
    store = batch.Store("runs/v2eval", batch.settings("v2", protocol, backend="warp", slots=16384))
    report = batch.run(jobs, store, lambda robot: suite.load("v2", robot=robot), time_limit_s=480)
    fitness = store.fitness([j.name for j in jobs if j.group == "base:humanoid"])   # [10, N]

A :class:`Job` is one walk of the suite: a walker folder (``rl.save_policy``'s, as ``learn`` writes
``policies/trial_K``) or a robot's shipped base policy, with an evaluation key. Every walker walks with the key
``evaluate`` gives every policy (:func:`walk_key` 0: ``fold_in(key(seed), 3)``); a base policy's ``keys`` jobs
walk with keys 0 .. keys - 1 (``fold_in`` of it by k), the rows ``base``, ``base:key1``, ... of ``evaluate --keys``.
So a job's fitness is the row ``evaluate`` writes for that policy with the same flags (the same programs, keys and
terrains).

The :class:`Store` (a folder) holds:

- ``settings.json``: what every result in it shares (suite version, protocol, backend, slots, chunk, seed); a run
  with other settings is refused (:class:`StoreMismatch`) rather than mixed in;
- ``suite_<robot>.json``: the suite each robot walked (name, terrains, the sha256 of its heightmaps, each terrain's
  family, level, seed, value, and its mean height, unit per family), recorded at its first build; a later build
  must have the same terrains (same rows, mean heights within 1e-6 m) or the run is refused;
- ``results/<job>.npz``: ``fitness`` [N] float32 in [0, 1] and ``meta`` (JSON: the job, its seconds, whether its
  program was compiled in that process before, the device and commit; under Warp also ``warp_hfield``, which
  heightfield collision the engine ran, :func:`jaxterrain.runtime.provenance.warp_hfield`), written atomically
  (:func:`jaxterrain.runtime.io.atomic_save_npz`) when the walk ends;
- ``builds.jsonl``: one line per suite build (robot, seconds), for the time estimates.

:func:`run` walks the jobs in order, skipping those with a result; under ``time_limit_s`` it starts a job only when
the time it predicts for it (and for building its robot's suite first) still fits: the slowest walk of that robot
through an already compiled program in this process (before there is one, the slowest recorded in the store: another
machine, or several processes sharing one, can be much slower), or, for the first walk of a program in this process,
the slowest such first walk recorded in the store (compile included), else :data:`FIRST_WALK_S`. The first pending job of a process always
runs. Walks of one policy network and walker config share one compiled program
(:func:`jaxterrain.suite.evaluate_policies`), so a robot's base policy and all its walkers compile once per process.
:func:`part` splits the jobs over processes (one per GPU) walking into one store.

Afterwards, on any machine (no suite is built, no GPU needed): :meth:`Store.suite` (the recorded terrains' table),
:func:`write_group` (a group's results as ``evaluate``'s files, ``fitness.csv.gz`` that ``generalise`` reads) and
:func:`pack` (folders into one tar, what a GPU machine hands back).
"""

from __future__ import annotations

import gzip
import hashlib
import io
import json
import os
import re
import tarfile
import time
from pathlib import Path
from typing import Callable, NamedTuple, Sequence

import jax
import numpy as np

from jaxterrain import difficulty, rl
from jaxterrain.difficulty import Protocol
from jaxterrain.rl.checkpoint import policy_fn
from jaxterrain.runtime import provenance
from jaxterrain.runtime.io import atomic_save_npz, atomic_write_bytes, atomic_write_text
from jaxterrain.suite.evaluation import evaluate_policies
from jaxterrain.suite.heldout import Suite
from jaxterrain.suite.outputs import write_evaluation
from jaxterrain.terrain import TerrainScale
from jaxterrain.walker import WalkerConfig

__all__ = ["FORMAT", "FIRST_WALK_S", "BUILD_S", "MARGIN", "Job", "StoreMismatch", "Store", "settings", "walk_key",
           "base_jobs", "walker_jobs", "treatment_folders", "part", "run", "write_group", "pack"]

FORMAT = "jaxterrain.suite.batch/1"
FIRST_WALK_S = 120.0
"""Predicted seconds of a program's first walk (compile included) when the store has none recorded."""
BUILD_S = 60.0
"""Predicted seconds of building a robot's suite when the store has none recorded."""
MARGIN = 1.15
"""Predictions are the slowest recorded walk (or build) times this."""


class Job(NamedTuple):
    """One walk of the suite.

    Attributes:
      name: the row name its fitness gets: the walker's folder as given (``.../policies/trial_3``), or
        ``base:<robot>`` / ``base:<robot>:key<k>`` for a base policy's key ``k``.
      robot: the robot it walks (its suite: a per-robot version's levels are that robot's).
      policy: the walker's folder, or None for the robot's shipped base policy.
      key: the evaluation key's index (:func:`walk_key`): 0 for every walker.
      group: what it belongs to: the treatment folder (a walker's ``policies/..`` parent), or ``base:<robot>``.
    """

    name: str
    robot: str
    policy: str | None
    key: int
    group: str


class StoreMismatch(ValueError):
    """A store made with other settings or on other terrains than this run's."""


def settings(suite: str, protocol: Protocol, backend: str = "jax", slots: int | None = None,
             chunk: int | None = None, seed: int = 0, **extra) -> dict:
    """The settings every result of a store shares (JSON-able): the suite version, the protocol's fields, the
    backend, the rollout slots and chunk, the seed of the evaluation key and any ``extra`` (e.g. a suite's build
    arguments for a test's smaller suite)."""
    return {"format": FORMAT, "suite": suite, "protocol": {k: v for k, v in protocol._asdict().items()},
            "backend": backend, "slots": slots, "chunk": chunk, "seed": int(seed), **extra}


def walk_key(seed: int, index: int = 0) -> jax.Array:
    """The evaluation key of ``evaluate --seed SEED``: ``fold_in(key(seed), 3)`` for every walker (``index`` 0),
    ``fold_in`` of that by ``index`` for the base policy's further keys (``base:key<index>``)."""
    key = jax.random.fold_in(jax.random.key(int(seed)), 3)
    return key if index == 0 else jax.random.fold_in(key, int(index))


def base_jobs(robot: str, keys: int, observation: str = "blind") -> list[Job]:
    """``keys`` walks of ``robot``'s shipped base policy, keys 0 .. keys - 1 (names ``base:<robot>``,
    ``base:<robot>:key1``, ...; group ``base:<robot>``). ``observation="perceptive"``: its shipped perceptive twin
    (``rl.base_policy_dir(robot, "perceptive")``, walked as a policy folder), names ``base:<robot>:perceptive``,
    ``base:<robot>:perceptive:key1``, ...; group ``base:<robot>:perceptive``. ValueError for keys < 1, an unknown
    observation set or a robot without that base policy."""
    if isinstance(keys, bool) or not isinstance(keys, int) or keys < 1:
        raise ValueError(f"keys must be an integer >= 1; got {keys!r}")
    difficulty.robot_base_policy(robot, observation)  # ValueError naming the robot / observation set
    if observation == "blind":
        return [Job(f"base:{robot}" + (f":key{k}" if k else ""), robot, None, k, f"base:{robot}")
                for k in range(keys)]
    folder, group = str(rl.base_policy_dir(robot, observation)), f"base:{robot}:{observation}"
    return [Job(group + (f":key{k}" if k else ""), robot, folder, k, group) for k in range(keys)]


def _trial(path: Path) -> int:
    tail = path.name.rsplit("trial_", 1)
    return int(tail[1]) if len(tail) == 2 and tail[1].isdigit() else -1


def treatment_folders(folder: str | Path) -> list[Path]:
    """The treatments of ``folder``: itself when it holds ``policies/trial_K`` walkers, else its direct subfolders
    that do (sorted by name). ValueError naming the folder when there are none."""
    folder = Path(folder)
    if not folder.is_dir():
        raise ValueError(f"{folder}: no such folder")
    has = lambda d: (d / "policies").is_dir() and any(_trial(p) >= 0 for p in (d / "policies").iterdir())  # noqa: E731
    found = [folder] if has(folder) else [d for d in sorted(folder.iterdir()) if d.is_dir() and has(d)]
    if not found:
        raise ValueError(f"{folder}: no policies/trial_K walker in it or in its subfolders")
    return found


def walker_jobs(folders: Sequence[str | Path]) -> list[Job]:
    """A job for every walker ``policies/trial_K`` of every treatment of ``folders`` (:func:`treatment_folders`), in
    the order given, trials in numeric order; its robot is the one the walker records (``rl.load_policy``).
    ValueError naming a folder without walkers, or a walker that does not load, before anything is walked."""
    jobs = []
    for folder in folders:
        for t in treatment_folders(folder):
            for p in sorted((p for p in (t / "policies").iterdir() if _trial(p) >= 0), key=_trial):
                try:
                    robot = difficulty.policy_robot(rl.load_policy(p))
                except (OSError, ValueError) as err:
                    raise ValueError(f"{p}: {str(err).splitlines()[0]}") from None
                jobs.append(Job(str(p), robot, str(p), 0, str(t)))
    return jobs


def part(jobs: Sequence[Job], k: int, n: int) -> list[Job]:
    """Part ``k`` of ``n`` of ``jobs``: every ``n``-th job from the ``k``-th (``jobs[k::n]``), so that ``n``
    processes (one per GPU) walking the parts into one store go through the list in its order together (whole
    groups early, as one process would). ValueError unless ``0 <= k < n``."""
    if isinstance(n, bool) or not isinstance(n, int) or n < 1 or isinstance(k, bool) or not isinstance(k, int) \
            or not 0 <= k < n:
        raise ValueError(f"part: need integers 0 <= k < n; got k={k!r}, n={n!r}")
    return list(jobs)[k::n]


def _file_name(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "+", name).strip("+") + ".npz"


def _suite_record(s: Suite) -> dict:
    maps = np.ascontiguousarray(s.heightmaps, np.float32)
    return {"name": s.name, "robot": s.robot, "terrains": s.size, "shape": list(maps.shape[1:]),
            "sha256": hashlib.sha256(memoryview(maps).cast("B")).hexdigest(),
            "cell_size": s.scale.cell_size, "height": s.scale.height,
            "family": s.family.tolist(), "level": s.level.tolist(), "seed": s.seed.tolist(),
            "value": [float(v) for v in s.value], "unit": dict(s.unit),
            "mean_height_m": [float(m) for m in maps.reshape(len(maps), -1).mean(axis=1, dtype=np.float64)
                              * s.scale.height],
            "missing": dict(s.missing), "dropped": dict(s.dropped)}


class Store:
    """A folder of per-job results (the module's docstring gives its files). ``settings``: what this run's results
    share (:func:`settings`); a folder made with other settings raises :class:`StoreMismatch`. ``Store(folder)``
    without settings opens an existing store to read."""

    def __init__(self, folder: str | Path, settings: dict | None = None):
        self.folder = Path(folder)
        path = self.folder / "settings.json"
        old = json.loads(path.read_text()) if path.is_file() else None
        if settings is None:
            if old is None:
                raise StoreMismatch(f"{self.folder}: not a store (no settings.json)")
            settings = old
        settings = json.loads(json.dumps(settings))  # as the file holds it (tuples as lists)
        if old is not None and old != settings:
            diff = sorted(k for k in set(old) | set(settings) if old.get(k) != settings.get(k))
            raise StoreMismatch(f"{self.folder}: made with other settings ("
                                + "; ".join(f"{k} {old.get(k)!r} there, {settings.get(k)!r} here" for k in diff)
                                + "): give another folder, or the same settings")
        if old is None:
            atomic_write_text(path, json.dumps(settings, indent=2) + "\n")
        self.settings = settings

    def path(self, name: str) -> Path:
        """The result file of job ``name``."""
        return self.folder / "results" / _file_name(name)

    def has(self, name: str) -> bool:
        """Whether job ``name`` has its result."""
        return self.path(name).is_file()

    def read(self, name: str) -> tuple[np.ndarray, dict]:
        """``(fitness [N] float32, meta dict)`` of job ``name``; ValueError naming the file when it does not read."""
        path = self.path(name)
        try:
            with np.load(path, allow_pickle=False) as z:
                fitness, meta = np.asarray(z["fitness"], np.float32), json.loads(str(z["meta"]))
        except (OSError, KeyError, ValueError) as err:
            raise ValueError(f"{path}: not a readable result ({type(err).__name__}: {err})") from None
        if meta.get("name") != name:
            raise ValueError(f"{path}: holds the result of {meta.get('name')!r}, not {name!r}")
        return fitness, meta

    def fitness(self, names: Sequence[str]) -> np.ndarray:
        """``[len(names), N]`` float32: the results of ``names``, in order (ValueError naming one that is missing)."""
        rows = []
        for n in names:
            if not self.has(n):
                raise ValueError(f"{self.folder}: no result for {n!r}")
            rows.append(self.read(n)[0])
        return np.stack(rows)

    def write(self, job: Job, fitness: np.ndarray, **meta) -> Path:
        """Write job ``job``'s result atomically (``fitness`` [N] in [0, 1]; ``meta``: what to record with it)."""
        f = np.asarray(fitness, np.float32)
        if f.ndim != 1 or not np.all((f >= 0.0) & (f <= 1.0)):
            raise ValueError(f"fitness of {job.name}: must be [N] values in [0, 1]; got shape {f.shape}")
        record = {**job._asdict(), **meta, "terrains": int(f.shape[0])}
        return atomic_save_npz(self.path(job.name), fitness=f, meta=np.array(json.dumps(record)))

    def suite_record(self, robot: str) -> dict | None:
        """The recorded suite of ``robot`` (``suite_<robot>.json``), or None before its first build."""
        path = self.folder / f"suite_{robot}.json"
        return json.loads(path.read_text()) if path.is_file() else None

    def suite(self, robot: str) -> Suite:
        """The recorded suite of ``robot`` as a :class:`~jaxterrain.suite.Suite` without its heightmaps (shape
        ``[N, 0, 0]``): the table of its terrains (family, level, seed, value, units, scale), enough to write an
        evaluation's files (:func:`write_group`) on a machine that never built it. ValueError before its first
        build."""
        r = self.suite_record(robot)
        if r is None:
            raise ValueError(f"{self.folder}: robot {robot} has walked no suite here yet")
        n = int(r["terrains"])
        return Suite(r["name"], np.zeros((n, 0, 0), np.float32), np.asarray(r["family"]),
                     np.asarray(r["level"], np.int64), np.asarray(r["seed"], np.int64),
                     np.asarray(r["value"], np.float64), dict(r["unit"]), TerrainScale(r["cell_size"], r["height"]),
                     dict(r["missing"]), dict(r["dropped"]), r["robot"])

    def check_suite(self, robot: str, s: Suite, build_s: float | None = None) -> None:
        """Record ``s`` as ``robot``'s suite at its first build; later builds must hold the same terrains (the same
        rows and units, mean heights within 1e-6 m; the sha256 may differ by float rounding across machines), else
        :class:`StoreMismatch`. ``build_s`` is appended to ``builds.jsonl``."""
        new = _suite_record(s)
        old = self.suite_record(robot)
        if old is None:
            atomic_write_text(self.folder / f"suite_{robot}.json", json.dumps(new) + "\n")
        else:
            same = all(old[k] == new[k] for k in ("terrains", "shape", "family", "level", "seed", "unit"))
            same = same and np.allclose(old["value"], new["value"], rtol=1e-9, atol=0.0)
            if not same or not np.allclose(old["mean_height_m"], new["mean_height_m"], rtol=0.0, atol=1e-6):
                raise StoreMismatch(f"{self.folder}: robot {robot}'s suite ({new['name']}, {new['terrains']} "
                                    f"terrains) is not the one its results were walked on ({old['name']}, "
                                    f"{old['terrains']} terrains)")
        if build_s is not None:
            with (self.folder / "builds.jsonl").open("a") as fh:
                fh.write(json.dumps({"robot": robot, "seconds": round(float(build_s), 3),
                                     "device": provenance.device()}) + "\n")

    def metas(self) -> list[dict]:
        """The ``meta`` of every result in the store."""
        out = []
        for p in sorted((self.folder / "results").glob("*.npz")):
            with np.load(p, allow_pickle=False) as z:
                out.append(json.loads(str(z["meta"])))
        return out

    def build_seconds(self, robot: str) -> list[float]:
        """Every recorded build time of ``robot``'s suite (seconds)."""
        path = self.folder / "builds.jsonl"
        if not path.is_file():
            return []
        rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
        return [float(r["seconds"]) for r in rows if r.get("robot") == robot]


def _load(job: Job):
    p = difficulty.robot_base_policy(job.robot) if job.policy is None else rl.load_policy(job.policy)
    if difficulty.policy_robot(p) != job.robot:
        raise ValueError(f"{job.policy}: walks robot {difficulty.policy_robot(p)}, not {job.robot}")
    return p


def _program(p, s: Suite, backend: str) -> tuple:
    """What selects a walk's compiled program besides the protocol: the env config and the policy network."""
    cfg = difficulty.default_env_config(tuple(s.heightmaps.shape[1:]), s.scale, p, backend)
    return cfg, policy_fn(p.config, int(p.action_size))


def run(jobs: Sequence[Job], store: Store, suites: Callable[[str], Suite], *, time_limit_s: float | None = None,
        started: float | None = None, walk: Callable | None = None, after: Callable[[Job], None] | None = None,
        log: Callable[[str], None] = print, clock: Callable[[], float] = time.perf_counter) -> dict:
    """Walk every job of ``jobs`` without a result in ``store``, in order, each result written when its walk ends.

    ``suites(robot)``: the suite a robot walks (built once per robot, on its first pending job; recorded, or checked
    against the store's record, :meth:`Store.check_suite`). The protocol, backend, slots, chunk and seed are the
    store's settings. ``time_limit_s``: seconds from ``started`` (a ``clock()`` reading, default now) after which no
    job starts whose predicted time (the module's docstring) would end past it; the first pending job always runs.
    ``walk``: ``(policies, heightmaps, key, protocol, backend, scale, slots, chunk) -> [P, N]`` (default
    :func:`~jaxterrain.suite.evaluate_policies`); ``after(job)``: called after each job's result is written.

    Returns ``{"walked": [names], "skipped": [names already done], "left": [names not walked], "stopped": None or
    why, "seconds": float}``. ValueError for a job whose policy does not load or walks another robot, checked for
    every pending job before anything is walked."""
    cfg = store.settings
    protocol = Protocol(**cfg["protocol"])
    backend, slots, chunk, seed = cfg["backend"], cfg["slots"], cfg["chunk"], cfg["seed"]
    walk = walk or evaluate_policies
    t0 = clock() if started is None else started
    names = [j.name for j in jobs]
    if len(set(names)) != len(names):
        raise ValueError(f"jobs: names must be unique; repeated: {sorted({n for n in names if names.count(n) > 1})}")
    files = [_file_name(n) for n in names]
    if len(set(files)) != len(files):
        raise ValueError("jobs: two names map to one result file; rename them")
    skipped = [j.name for j in jobs if store.has(j.name)]
    pending = [j for j in jobs if not store.has(j.name)]
    policies = {j.name: _load(j) for j in pending}  # every bad folder before the first walk
    metas = store.metas()
    first_s = {r: [m["seconds"] for m in metas if m.get("robot") == r and not m.get("compiled_before")]
               for r in {j.robot for j in jobs}}
    again_s = {r: [m["seconds"] for m in metas if m.get("robot") == r and m.get("compiled_before")]
               for r in {j.robot for j in jobs}}
    here_s: dict[str, list[float]] = {r: [] for r in first_s}  # compiled walks of this process
    built: dict[str, Suite] = {}
    compiled: set = set()
    walked, stopped = [], None
    device, commit = provenance.device(), provenance.git_commit()
    engine = {"warp_hfield": provenance.warp_hfield()} if backend == "warp" else {}
    engine["spawn"] = WalkerConfig().spawn  # the rule evaluate_policies' walkers spawn by (the library default)
    for i, job in enumerate(pending):
        p = policies[job.name]
        need = 0.0
        if job.robot not in built:
            need += max(store.build_seconds(job.robot) or [BUILD_S])
        program = _program(p, built[job.robot], backend) if job.robot in built else None
        if program is not None and program in compiled:
            need += max(here_s[job.robot] or again_s[job.robot] or first_s[job.robot] or [FIRST_WALK_S])
        else:
            need += max(first_s[job.robot] or [FIRST_WALK_S])
        elapsed = clock() - t0
        if time_limit_s is not None and walked and elapsed + MARGIN * need > time_limit_s:
            stopped = (f"time limit: {elapsed:.0f} s of {time_limit_s:.0f} s used; the next job ({job.name}) is "
                       f"predicted to take {need:.0f} s")
            break
        if job.robot not in built:
            tb = clock()
            built[job.robot] = suites(job.robot)
            build_s = clock() - tb
            store.check_suite(job.robot, built[job.robot], build_s)
            log(f"suite {built[job.robot].name}: {built[job.robot].size} terrains, built in {build_s:.1f} s")
        s = built[job.robot]
        program = _program(p, s, backend)
        before = program in compiled
        tw = clock()
        fitness = np.asarray(walk([p], s.heightmaps, walk_key(seed, job.key), protocol, backend, s.scale, slots,
                                  chunk))[0]
        seconds = clock() - tw
        compiled.add(program)
        (again_s if before else first_s)[job.robot].append(seconds)
        if before:
            here_s[job.robot].append(seconds)
        store.write(job, fitness, seconds=round(seconds, 3), compiled_before=before, suite=s.name, device=device,
                    commit=commit, finished=time.strftime("%Y-%m-%dT%H:%M:%S%z"), **engine)
        walked.append(job.name)
        log(f"[{len(skipped) + len(walked)}/{len(jobs)}] {job.name}: mean fitness {float(fitness.mean()):.4f}, "
            f"{seconds:.1f} s{'' if before else ' (first walk of its program: compile included)'}")
        if after is not None:
            after(job)
    left = [j.name for j in pending if j.name not in set(walked)]
    return {"walked": walked, "skipped": skipped, "left": left, "stopped": stopped, "seconds": clock() - t0}


def write_group(store: Store, names: Sequence[str], folder: str | Path, suite: Suite,
                labels: Sequence[str] | None = None, config: dict | None = None,
                suite_figure: bool = False) -> Path:
    """Write the results ``names`` of ``store`` as one evaluation into ``folder``, in ``evaluate``'s files
    (:func:`~jaxterrain.suite.write_evaluation`: ``levels.csv``, ``summary.md``, ``robustness.csv``, ``levels.png``;
    ``suite.png`` with ``suite_figure``) with ``fitness.csv`` gzipped (``fitness.csv.gz``, what ``generalise``
    reads), rows named ``labels`` (default ``names``); ``config.json``: ``config`` and the store's settings, the
    rows, and the devices and commits that walked them; ``timing.json``: each row's seconds. ``suite``: the one the
    results were walked on, built or as the store recorded it (:meth:`Store.suite`: no heightmaps, so no
    ``suite.png``); ValueError when its size differs from theirs, or its terrains from the store's record. Returns
    the folder."""
    folder = Path(folder)
    if suite_figure and suite.heightmaps.size == 0:
        raise ValueError(f"suite {suite.name}: no heightmaps (a recorded suite): suite_figure must be False")
    labels = list(names if labels is None else labels)
    if len(labels) != len(names):
        raise ValueError(f"labels: one per name ({len(names)}); got {len(labels)}")
    fitness = store.fitness(names)
    if fitness.shape[1] != suite.size:
        raise ValueError(f"suite {suite.name} has {suite.size} terrains; the results have {fitness.shape[1]}")
    record = store.suite_record(suite.robot) if suite.robot is not None else None
    if record is not None and (record["family"] != suite.family.tolist() or record["level"] != suite.level.tolist()):
        raise ValueError(f"suite {suite.name}: not the terrains {store.folder}'s results were walked on")
    metas = [store.read(n)[1] for n in names]
    write_evaluation(folder, labels, suite, fitness, suite_figure=suite_figure)
    raw = (folder / "fitness.csv").read_bytes()
    atomic_write_bytes(folder / "fitness.csv.gz", gzip.compress(raw, mtime=0))
    (folder / "fitness.csv").unlink()
    cfg = {**(config or {}), "walked_with": store.settings, "suite_name": suite.name, "terrains": suite.size,
           "rows": labels, "jobs": list(names),
           "devices": sorted({m.get("device", "?") for m in metas}),
           "commits": sorted({m.get("commit", "?") for m in metas})}
    atomic_write_text(folder / "config.json", json.dumps(cfg, indent=2) + "\n")
    timing = {"rows": {label: m.get("seconds") for label, m in zip(labels, metas)},
              "compiled_before": {label: m.get("compiled_before") for label, m in zip(labels, metas)},
              "walk_s": round(float(sum(m.get("seconds") or 0.0 for m in metas)), 3)}
    atomic_write_text(folder / "timing.json", json.dumps(timing, indent=2) + "\n")
    return folder


def pack(paths: Sequence[str | Path], archive: str | Path, root: str | Path = ".") -> Path:
    """A gzipped tar of ``paths`` (files or folders, each under ``root``, stored relative to it) written atomically
    to ``archive``: what a GPU machine hands back in one file. ValueError naming a path outside ``root`` or
    missing."""
    root = Path(root).resolve()
    members = []
    for p in paths:
        full = Path(p).resolve()
        if not full.exists():
            raise ValueError(f"pack: {p} does not exist")
        rel = os.path.relpath(full, root)
        if rel.startswith(".."):
            raise ValueError(f"pack: {p} is not under {root}")
        members.append((full, rel))
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:gz") as tar:
        for full, rel in members:
            tar.add(full, arcname=rel, filter=lambda t: None if t.name.endswith(".tmp") else t)
    return atomic_write_bytes(archive, buf.getvalue())
