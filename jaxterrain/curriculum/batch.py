"""Several treatments in one compiled program (``experiments curriculum``'s default): their trials run as one
population (:func:`jaxterrain.curriculum.population.run_population`), and each treatment's folder gets the files a
run of it alone writes (:func:`jaxterrain.curriculum.runner.run_treatment`).

    treatments = [batch.Treatment("cppn map", run_a, Path("runs/x/cppn-map")), batch.Treatment(...), ...]
    summaries = batch.run_treatments(treatments, time_limit_s=540, say=print)   # None: stopped by the time limit

Groups (:func:`plan_groups`). Treatments share a program when the walker and the harness's work agree
(:func:`group_key`: ``Selector.slots``, overlap, env steps per chunk, evaluation protocol, fine-tuning PPO, the
walker env's config, the terrain size, the physics backend, and the run's compile options, ``compact`` and
``chunks_per_call``); their archives, selectors, seeds, trial counts and budgets may differ (a map curriculum on six
archives, or map, roughness and random on one). A group holds at most ``max_envs`` envs stepped together
(``trials x max(num_envs, attempts)``, with overlap ``trials x (num_envs + attempts)``; :data:`DEFAULT_ENVS`), and a
group whose compiled program needs more memory than the device has (XLA's ``memory_analysis`` against the device's
``bytes_limit``, or the host's memory on a CPU) is split in two, said in one line.

Files. After every block each member writes its own ``checkpoint.npz`` (its trials' states, as its solo run's:
``learn --report`` / ``curriculum --report`` read it; its meta records ``population``, where its trials sat), its
``metrics.csv`` and ``tb/``; at its end ``policies/``, ``history.csv``, ``sequences.csv``, ``milestones.*``,
``curve.png`` and ``summary.json`` (``seconds``: the wall time of the commands that ran its population). A killed
or time-limited population resumes each member from its own checkpoint at its own chunk (members need not agree:
each runs its own blocks), to the result of an uninterrupted run; a treatment finished meanwhile is read from its
``summary.json``. On a tiled walker (MuJoCo Warp, or ``overlap``) a trial's envs live on its tile, so a member
restored where it sat in another population (or alone) restarts its envs on its current terrains (one line).

Equal to a run alone: each member's trials take the keys, terrains, starting policies and choices of its solo run
(:mod:`.population`). On a CPU its checkpoint and history are bit for bit those of the first trials of its run alone
with the population's trial count; against its run alone with its own trials, the same terrain sequences and
evaluations within 0.05 (``tests/integration/test_population_command.py``).

Blocks: ``chunks_per_call`` chunks at most, shortened so that one takes about ``block_seconds`` at the rate
measured in the blocks before (a population chunk is longer than a treatment's); under a time limit the first block
is one chunk (a probe of the rate) and later ones are cut to the chunks that fit, as :func:`driver.run_chunks` does.
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
import time
from pathlib import Path
from typing import Callable, NamedTuple, Optional, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain.curriculum import runner
from jaxterrain.curriculum import walker as W
from jaxterrain.curriculum.checkpoints import restore_states
from jaxterrain.curriculum.outputs import export_policies, write_outputs
from jaxterrain.curriculum.own_terrains import OwnTerrains, rank_terrains
from jaxterrain.curriculum.population import population_key, population_rows, run_population
from jaxterrain.curriculum.progress import ChunkMetrics, ChunkProgress, chunk_metrics
from jaxterrain.curriculum.run_config import LearnConfig, to_flat
from jaxterrain.runtime import driver, estimates, xla

__all__ = ["Treatment", "Member", "DEFAULT_ENVS", "BLOCK_SECONDS", "group_key", "envs_of", "plan_groups",
           "device_memory", "program_bytes", "drive", "population", "run_treatments", "FIXED_TRIALS", "shard_groups"]

DEFAULT_ENVS = 131_072
"""Envs stepped together in one program at most (``max_envs``), unless set: the top of the range where the
humanoid's walker reaches its peak physics rate on one H200 (32 768-131 072 envs, ``benchmarks/RESULTS.md``); more
only makes each physics call longer. Memory bounds a group too (:func:`run_treatments`)."""
BLOCK_SECONDS = 300.0
"""A population block's target wall time (seconds between checkpoints), unless set."""
GIB = 2.0 ** 30


class Treatment(NamedTuple):
    """One treatment of a population: ``desc`` (its name in lines and progress), ``run`` (its ``LearnConfig``, as
    given: its checkpoints record it) and ``folder`` (its run folder, as ``runner.run_treatment``'s)."""

    desc: str
    run: LearnConfig
    folder: Path


class _Valid(NamedTuple):
    treatment: Treatment
    run: LearnConfig
    config: object
    arch: object
    policy: object
    env: object
    digest: str


def _validate(t: Treatment) -> _Valid:
    run, config, arch, policy, env = runner.validate(t.run)
    return _Valid(t, run, config, arch, policy, env, runner.check_resumable(Path(t.folder), run, arch))


def group_key(run: LearnConfig, config, policy, env) -> tuple:
    """What treatments sharing a program must agree on (a validated run, its ``CurriculumConfig``, start policy and
    walker env: ``runner.validate``'s): :func:`population_key`, the backend, the env's config (tiles and Warp
    worlds aside: the population's env has its own), the fine-tuning PPOConfig and the budget's ``fast_compile``,
    ``compact`` and ``chunks_per_call``."""
    b = run.budget
    return (population_key(config), runner.physics_of(run), env.config._replace(tiles=0, warp_worlds=0),
            W.fine_tuning_ppo(config, policy, env), bool(b.fast_compile), bool(b.compact), int(b.chunks_per_call))


def envs_of(run: LearnConfig) -> int:
    """The envs a (resolved) run's trials step together: ``trials x max(num_envs, attempts)``, with overlap ``trials
    x (num_envs + attempts)`` (``runner.walker_layout``'s worlds)."""
    c = run.curriculum
    envs, attempts = int(c.ppo.num_envs), int(c.attempts)
    return int(run.trials) * (envs + attempts if c.overlap else max(envs, attempts))


def plan_groups(keys: Sequence, envs: Sequence[int], max_envs: int) -> list[list[int]]:
    """Indices of treatments grouped: equal ``keys`` together, groups in order of their first treatment, each
    filled in order while its ``envs`` sum stays <= ``max_envs`` (a treatment over it alone is a group of one)."""
    groups: list[list[int]] = []
    open_by_key: dict = {}
    for i, (key, e) in enumerate(zip(keys, envs)):
        g = open_by_key.get(key)
        if g is None or sum(envs[j] for j in g) + e > max_envs:
            g = []
            groups.append(g)
            open_by_key[key] = g
        g.append(i)
    return groups


FIXED_TRIALS = 20.0
"""A population's cost per chunk in trials' worth (:func:`shard_groups`): ``FIXED_TRIALS + trials``. Measured: a
10-trial treatment 4.09 s a chunk, the 60-trial six 10.87 s (one H200, MuJoCo Warp, 2026-11-30,
``docs/results/population.md``): 2.73 s + 0.136 s a trial, the fixed part worth 20 trials."""


def shard_groups(keys: Sequence, envs: Sequence[int], trials: Sequence[int], count: int,
                 max_envs: int = DEFAULT_ENVS) -> list[int]:
    """The process (``0 .. count - 1``) of each treatment when ``count`` processes share them (``curriculum --shard
    I/N``, one per GPU): populations whole where there are enough of them. The groups of :func:`plan_groups`; while
    there are fewer than ``count``, the costliest with more than one treatment is halved (its treatments
    alternately, as ``t % 2``); then longest first, each to the least loaded process, a population's cost
    ``FIXED_TRIALS + its trials`` (:data:`FIXED_TRIALS`). Pure and deterministic: every process computes the same
    answer from the same plan. Example: map on two archives (10 trials each, one group), DR and PLR (one group),
    terrain levels (its own) over 2 processes: ``[0, 0, 1, 1, 0]``."""
    if count < 1:
        raise ValueError(f"count must be >= 1, got {count}")
    groups = plan_groups(keys, envs, max_envs)

    def cost(g):
        return FIXED_TRIALS + sum(trials[i] for i in g)

    while len(groups) < count:
        splittable = [g for g in groups if len(g) > 1]
        if not splittable:
            break
        big = max(splittable, key=lambda g: (cost(g), -g[0]))
        at = groups.index(big)
        groups[at:at + 1] = [big[0::2], big[1::2]]
    load = [0.0] * count
    shard = [0] * len(keys)
    for g in sorted(groups, key=lambda g: (-cost(g), g[0])):
        k = min(range(count), key=lambda j: (load[j], j))
        load[k] += cost(g)
        for i in g:
            shard[i] = k
    return shard


def device_memory() -> Optional[int]:
    """Bytes the default device holds: its ``memory_stats()["bytes_limit"]`` (a GPU), else the host's physical
    memory (a CPU), None where neither is known."""
    stats = jax.devices()[0].memory_stats() or {}
    if stats.get("bytes_limit"):
        return int(stats["bytes_limit"])
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return None


def program_bytes(compiled) -> Optional[int]:
    """Device bytes a compiled program holds while it runs (XLA's ``memory_analysis``: arguments, outputs and
    temporaries, less what outputs alias), None where the backend does not say."""
    try:
        m = compiled.memory_analysis()
        return int(m.argument_size_in_bytes + m.output_size_in_bytes + m.temp_size_in_bytes - m.alias_size_in_bytes)
    except Exception:  # noqa: BLE001 - memory_analysis is optional per backend
        return None


class Member:
    """One treatment of a running population on the host: ``states`` (its trials), ``done`` (its chunks, its own
    count), ``total`` (its ``max_chunks``), the metric ``history``, ``before`` (wall seconds of earlier commands),
    checkpoint ``meta``; ``finish(states, seconds) -> summary`` writes its outputs, ``snapshot(states, chunk)`` its
    walkers every ``policy_every`` chunks. :func:`drive` moves it; ``summary`` is set once it has finished."""

    def __init__(self, desc: str, folder: Path, states, total: int, *, done: int = 0, history: Optional[dict] = None,
                 before: float = 0.0, meta: Optional[dict] = None, finish: Optional[Callable] = None,
                 snapshot: Optional[Callable] = None, policy_every: int = 0):
        self.desc, self.folder, self.states, self.total, self.done = desc, Path(folder), states, int(total), int(done)
        self.history = {k: list(v) for k, v in (history or {}).items()}
        self.before, self.meta, self.finish, self.snapshot = float(before), dict(meta or {}), finish, snapshot
        self.policy_every, self.summary, self.log = int(policy_every or 0), None, None
        self.metrics = ChunkMetrics(self.folder)
        self.folder.mkdir(parents=True, exist_ok=True)

    @property
    def finished(self) -> bool:
        return self.summary is not None

    def ended(self) -> bool:
        """Every chunk done, or every trial."""
        return self.done >= self.total or bool(np.all(np.asarray(self.states.done)))

    def advance(self, chunks: int, wall_s: float) -> None:
        """After a block that moved it ``chunks`` chunks: metrics, checkpoint, snapshots; its outputs at its end. A
        member whose trials are all done moves to its last chunk at once (its run alone would step through empty
        blocks to it: the same metric rows, checkpoint and outputs)."""
        a = self.done
        b = self.total if bool(np.all(np.asarray(self.states.done))) else min(a + int(chunks), self.total)
        for name, values in chunk_metrics(self.states, a, b).items():
            self.history.setdefault(name, []).extend(float(x) for x in np.asarray(values, np.float64))
        self.done = b
        driver.write_checkpoint(self.folder, self.states, b, self.history, {**self.meta, "wall_s": wall_s})
        self.log = self.log or driver.MetricLog(self.folder)
        self.log.write(self.history, a, b)
        if self.snapshot is not None and self.policy_every and b // self.policy_every > a // self.policy_every:
            self.snapshot(self.states, b)
        if self.ended():
            self.close()
            self.summary = self.finish(self.states, wall_s) if self.finish is not None else {"chunks": b}

    def close(self) -> None:
        if self.log is not None:
            self.log.close()
            self.log = None


_LISTENERS: list = []  # the running population's listeners (compiled programs call _population_done)


def _population_done(members) -> None:
    """Host side of a population block's per-chunk callback: ``members`` (per member ``(chunk, hardest, done,
    history)``) to the running population's listeners."""
    for listen in list(_LISTENERS):
        listen(members)


def drive(members: Sequence[Member], block: Callable, *, every: int, time_limit_s: Optional[float] = None,
          block_seconds: Optional[float] = BLOCK_SECONDS, start: Optional[float] = None, desc: str = "population",
          progress: bool | str = True, compact: bool = True) -> bool:
    """Run a population's blocks until every member has finished or the time limit: ``block(states tuple, chunks
    [M] int32, rows [R] int32 or None) -> states tuple`` (a compiled :func:`run_population`; ``rows``:
    :func:`population_rows` with ``compact``, else None). Each block is ``every`` chunks at most (fewer, to take
    about ``block_seconds`` at the rate measured so far; under ``time_limit_s``, counted from ``start``, the first
    is one chunk and later ones are cut to what fits); member m moves ``min(n, total_m - done_m)`` of them, then
    writes its checkpoint and metrics (:meth:`Member.advance`); a member whose trials are all done moves to its end
    at once. True when every member has finished."""
    t0 = time.perf_counter() if start is None else start
    wall = lambda m: m.before + time.perf_counter() - t0  # noqa: E731
    rate, probed = float("inf"), False
    progress_line = ChunkProgress(desc, max(m.total for m in members), min(m.done for m in members))

    def listen(per_member):
        for m, (chunk, hardest, done, history) in zip(members, per_member):
            m.metrics(chunk, hardest, done, history)
        if progress:
            progress_line(*(np.concatenate([np.asarray(p[i]) for p in per_member]) for i in range(3)))

    def idle():
        for m in members:
            if not m.finished and m.ended():
                m.advance(0, wall(m))

    _LISTENERS[:] = [listen]
    try:
        idle()
        while not all(m.finished for m in members):
            n = int(every)
            if block_seconds and rate < float("inf"):
                n = min(n, max(1, int(block_seconds // rate)))
            if time_limit_s is not None and not probed:
                n = 1  # a probe of the rate (at least one chunk runs, as under driver.run_chunks)
            elif time_limit_s is not None:
                left = time_limit_s - (time.perf_counter() - t0)
                n = n if rate * n <= left else max(int(left // rate), 0)
                if n < 1:
                    break
            chunks = np.array([0 if m.finished else min(n, m.total - m.done) for m in members], np.int32)
            rows = population_rows([m.states.done for m in members]) if compact else None
            for m, k in zip(members, chunks):
                m.metrics.begin(m.states, m.done + int(k))
            t1 = time.perf_counter()
            out = jax.block_until_ready(block(tuple(m.states for m in members), chunks,
                                              None if rows is None else jnp.asarray(rows)))
            rate, probed = min(rate, (time.perf_counter() - t1) / n), True
            for m, s, k in zip(members, out, chunks):
                m.states = s
                if k:
                    m.advance(int(k), wall(m))
            idle()
    finally:
        _LISTENERS.clear()
        for m in members:
            m.close()
    return all(m.finished for m in members)


class _TooBig(Exception):
    def __init__(self, need: int, limit: int):
        super().__init__(f"{need / GIB:.1f} GiB")
        self.need, self.limit = need, limit


_PROGRAMS: dict = {}  # signature -> {rows: compiled population block}


def _setup(valid: Sequence[_Valid], memory_bytes: Optional[int], say: Callable):
    """``(members, block, budget, trials)`` of one group: the population's walker env (every trial's tiles and Warp
    worlds), each member's bank, inputs and states (restored from its checkpoint), and the compiled block of all
    trials, checked against the device's memory (:class:`_TooBig`)."""
    trials = [int(v.run.trials) for v in valid]
    v0, total = valid[0], sum(trials)
    env = runner.make_env(v0.run._replace(trials=total), v0.arch, v0.policy)
    fast = bool(v0.run.budget.fast_compile)
    names = [v.treatment.desc for v in valid]
    members, banks, configs, harness, offset, ppo = [], [], [], None, 0, None
    for v, t in zip(valid, trials):
        arch = rank_terrains(v.run, v.arch, v.policy, v.treatment.folder) if isinstance(v.arch, OwnTerrains) else v.arch
        bank, ppo, h, start, keys, init = runner.inputs(v.run, v.config, arch, v.policy, env)
        harness = harness or h
        states = jax.jit(init)(keys, bank, start)
        placement = {"trials": total, "offset": offset}
        offset += t
        restored = restore_states(Path(v.treatment.folder), states, placement, bool(env.tiles), say)
        done, history, before = 0, None, 0.0
        if restored is not None:
            states, done, history, saved = restored
            before = float(saved.get("wall_s", 0.0))
        meta = {"config": to_flat(v.treatment.run, "learn"), "archive_sha256": v.digest,
                "backend": runner.physics_of(v.run), "population": placement, "population_treatments": names}
        folder, names_of = Path(v.treatment.folder), arch.generator_names
        finish = functools.partial(_finish, folder, v, ppo, bank, names_of)
        snapshot = functools.partial(_snapshot, folder, v, ppo, bank, names_of)
        members.append(Member(v.treatment.desc, folder, states, v.config.max_chunks, done=done, history=history,
                              before=before, meta=meta, finish=finish, snapshot=snapshot,
                              policy_every=v.run.budget.policy_every))
        banks.append(bank)
        configs.append(v.config)
    banks = tuple(banks)
    shapes = tuple((tuple(x.shape), str(x.dtype)) for x in jax.tree.leaves(banks))
    sig = (tuple(configs), ppo, env.config, tuple(trials), shapes, fast)
    fn = functools.partial(run_population, configs=tuple(configs), harness=harness, on_chunk=_population_done)
    blocks = _PROGRAMS.setdefault(sig, {})
    options = xla.known_options(runner.FAST_COMPILE) if fast and jax.default_backend() == "cpu" else None

    def program(rows):
        size = None if rows is None else int(rows.shape[0])
        if size not in blocks:
            like = (tuple(m.states for m in members), banks, np.zeros(len(members), np.int32), rows)
            blocks[size] = jax.jit(fn, donate_argnums=(0,)).lower(*like).compile(options)
        return blocks[size]

    physics = runner.physics_of(v0.run)
    fresh = None not in blocks
    note = estimates.compiling("curriculum-block", f"{total} trials of {len(valid)} treatments, {physics} physics",
                               then=estimates.first_chunk_note(physics)) \
        if fresh else contextlib.nullcontext()
    with note:
        need = program_bytes(program(None))
    limit = device_memory() if memory_bytes is None else int(memory_bytes)
    if need is not None and limit is not None and need > limit and len(valid) > 1:
        raise _TooBig(need, limit)
    return members, (lambda s, n, rows: program(rows)(s, banks, n, rows)), v0.run.budget, total


def population(treatments: Sequence[Treatment], memory_bytes: Optional[int] = None, say: Callable = print):
    """``(members, block, budget, trials)``: ``treatments`` (one group: :func:`group_key` equal) set up as one
    population, its program of all trials compiled: the host :class:`Member` s (states restored from their
    folders' checkpoints where there are any), ``block(states tuple, chunks [M], rows) -> states`` (for
    :func:`drive`, or to time it), the first run's ``Budget`` and the trial count. ``ValueError`` when the program
    needs more than ``memory_bytes`` (None: :func:`device_memory`). Validates first (:class:`runner.BadInput`)."""
    try:
        return _setup([_validate(t) for t in treatments], memory_bytes, say)
    except _TooBig as err:
        raise ValueError(f"the population's program needs {err.need / GIB:.1f} GiB, the device has "
                         f"{err.limit / GIB:.1f} GiB") from None


def _finish(folder, v: _Valid, ppo, bank, names, states, seconds):
    export_policies(folder, v.run, v.config, ppo, v.env, v.policy, bank, states, names=names)
    return write_outputs(folder, v.run, v.config, bank, states, seconds=seconds, names=names)


def _snapshot(folder, v: _Valid, ppo, bank, names, states, chunk):
    export_policies(folder, v.run, v.config, ppo, v.env, v.policy, bank, states, subdir=f"chunk_{chunk:05d}",
                    names=names)


def run_treatments(treatments: Sequence[Treatment], time_limit_s: Optional[float] = None, *,
                   max_envs: Optional[int] = None, block_seconds: Optional[float] = BLOCK_SECONDS,
                   memory_bytes: Optional[int] = None, progress: bool | str = True,
                   say: Callable[[str], None] = print, label: str = "population") -> list[Optional[dict]]:
    """Run (or continue) ``treatments`` in groups, one compiled program each (see the module docstring): their
    summaries in order, None for those the time limit stopped (checkpointed; call again to continue).

    Every treatment is validated first (``runner.validate``, ``runner.check_resumable``: :class:`runner.BadInput`
    naming the field, before anything compiles); a finished one (its ``summary.json``) is read, not run. Groups:
    :func:`plan_groups` under ``max_envs`` (None: :data:`DEFAULT_ENVS`); a group whose program needs more than
    ``memory_bytes`` (None: :func:`device_memory`) is split in two. ``say`` gets one line per group (which
    treatments share a program) and per split. ``time_limit_s`` counts from this call, set-up and compiles
    included (the first population runs at least one chunk, as ``runner.run_treatment`` does); ``block_seconds``:
    :func:`drive`'s. ``label`` starts every line and progress bar (``"<label> <number>: ..."``): name the process
    there when several print to one log (e.g. ``"GPU 1 population"``)."""
    t0 = time.perf_counter()
    out: list[Optional[dict]] = [None] * len(treatments)
    todo = []
    for i, t in enumerate(treatments):
        summary = Path(t.folder) / "summary.json"
        if summary.exists():
            out[i] = json.loads(summary.read_text())
        else:
            todo.append(i)
    valid = {i: _validate(treatments[i]) for i in todo}
    keys = [group_key(v.run, v.config, v.policy, v.env) for v in valid.values()]
    plan = plan_groups(keys, [envs_of(v.run) for v in valid.values()], int(max_envs or DEFAULT_ENVS))
    queue = [[todo[j] for j in g] for g in plan]
    number = 0
    while queue:
        group = queue.pop(0)
        left = None if time_limit_s is None else time_limit_s - (time.perf_counter() - t0)
        if left is not None and left <= 0 and number:  # the first population runs at least its probe chunk
            break
        names = ", ".join(treatments[i].desc for i in group)
        try:
            members, block, budget, trials = _setup([valid[i] for i in group], memory_bytes, say)
        except _TooBig as err:
            half = (len(group) + 1) // 2
            say(f"{label} {names}: its program needs {err.need / GIB:.1f} GiB, the device has "
                f"{err.limit / GIB:.1f} GiB: split into {half} and {len(group) - half} treatments")
            queue[:0] = [group[:half], group[half:]]
            continue
        number += 1
        envs = sum(envs_of(valid[i].run) for i in group)
        say(f"{label} {number} of {number + len(queue)}: {names} ({len(group)} treatment"
            f"{'s' if len(group) > 1 else ''}, {trials} trials, {envs} envs per physics call) in one program")
        if any(m.done for m in members):
            say(f"{label} {number}: resuming " + ", ".join(f"{m.desc} at chunk {m.done} of {m.total}"
                                                           for m in members))
        finished = drive(members, block, every=int(budget.chunks_per_call), start=t0, time_limit_s=time_limit_s,
                         block_seconds=block_seconds, desc=f"{label} {number}", progress=progress,
                         compact=bool(budget.compact))
        for i, m in zip(group, members):
            out[i] = m.summary
        if not finished:
            break
    return out
