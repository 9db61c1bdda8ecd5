"""Many trials at once: the trials of one treatment (:func:`run_trials`) or of several treatments together, one
population in one compiled program (:func:`run_population`).

    run = make_runner(config, harness)                                   # jitted; re-use it (one compile)
    states = run(states, bank, num_chunks)                               # up to num_chunks chunks of every trial
    states = run_live(run, states, bank, num_chunks)                     # the same, computing running trials only

    run = make_population_runner((config_a, config_b), harness)          # two treatments, one program
    a, b = run((states_a, states_b), (bank_a, bank_b), n [2], rows [R])  # each its own bank, selector, chunks

A population is a tuple of treatments ("members"), each with its own trials (``State`` [T_m]), bank (any number of
terrains), :class:`~jaxterrain.curriculum.CurriculumConfig` and selector, sharing one harness: every chunk, each
member's trials pick their keys and terrain maps from their own bank (:func:`~.core.chunk_keys`,
:func:`~.core.terrain_maps`, vmapped over the member's trials), the maps of all ``T = sum T_m`` trials are laid out
together (one bank of tiles on a tiled walker), ONE vmapped call of :func:`~.core.chunk_physics` trains and
evaluates all of them (``T x num_envs`` envs in each physics call), and each member's selector updates its own
trials (:func:`~.core.chunk_update`, the member's own code and bank: a map curriculum's GP over its own archive).
So a member's trials take the same keys, terrains, starting policies and decisions as in a run of that treatment
alone. On a CPU its states are bit for bit those of the first trials of its run alone with as many trials as the
population has (trial keys do not depend on the count); against its run alone with its own trial count they differ
in the last bits wherever the physics' matrix products sum in blocks that depend on the batch's size (XLA's CPU
matmuls; a fake harness without them: bit for bit, ``tests/curriculum/test_population.py``).

The members must agree on what the harness runs (:func:`check_population`): the same ``Selector.slots``, overlap,
env steps per chunk, evaluation protocol and PPO config; their selectors, banks, budgets, trial counts and
``eval_lag`` (a rule of the update, not of the physics) may differ. Each member runs its own block: ``n[m]``
chunks counted as :func:`run_trials` counts them (its trials stop stepping once it has done its block, while other
members go on), so where its blocks end does not depend on the others.

``rows`` [R] (global trial indices, every running trial among them; :func:`live_rows` of the members' ``done``
concatenated): the physics computes those trials only (the others are done, their states unchanged). The maps are
still laid out for all T trials, and a trial's tile is that of its global index whatever R is, so on a tiled walker
the envs of a trial stay on their tile from block to block. The solo runner computes its running trials the same way
(:func:`run_trials` and :func:`make_runner` take ``rows``, :func:`run_live` passes :func:`live_rows`): the one home
of "compute fewer trials". Until the fix (59440af, 2026-11-29) it cut the states down to the R rows instead, so the
R trials' maps were laid out as tiles ``0..R-1``; since env states ride from block to block (bfe08b4) their envs
stayed on the tiles of their global indices, and after a compaction the moved trials' envs walked on another
trial's tile until their next reset (:func:`tile_moves` says which trials moved; ``docs/results/exp3.md``).
"""

from __future__ import annotations

import functools
from typing import Any, Callable, Optional, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain.curriculum.config import CurriculumConfig
from jaxterrain.curriculum.core import (Harness, State, chunk_keys, chunk_physics, chunk_update, init_trials,
                                        terrain_maps)
from jaxterrain.curriculum.selectors import get_selector
from jaxterrain.qd import TerrainBank
from jaxterrain.runtime import sharding

__all__ = ["init_trials", "run_trials", "make_runner", "mesh_rows", "live_rows", "run_live", "tile_moves", "check_population",
           "population_key", "lay_out", "run_population", "make_population_runner", "population_rows"]

SHARED = ("overlap", "steps_per_chunk", "protocol", "ppo")
"""The :class:`CurriculumConfig` attributes every member of a population shares (the harness's work)."""


def population_key(config: CurriculumConfig) -> tuple:
    """What of ``config`` the harness runs: ``(Selector.slots, overlap, env steps per chunk, protocol, PPO config)``.
    Treatments with equal keys (and one walker) can share a population."""
    return (get_selector(config).slots,) + tuple(getattr(config, name) for name in SHARED)


def check_population(configs: Sequence[CurriculumConfig]) -> None:
    """``ValueError`` naming the first attribute where a member's config differs from the first member's in what
    the shared harness runs (:func:`population_key`), or when there is no member."""
    if not configs:
        raise ValueError("a population needs at least one treatment")
    names = ("Selector.slots",) + tuple(f"CurriculumConfig.{name}" for name in SHARED)
    first = population_key(configs[0])
    for m, config in enumerate(configs[1:], 1):
        for name, a, b in zip(names, first, population_key(config)):
            if a != b:
                raise ValueError(f"population member {m} has {name} {b!r}, member 0 {a!r}: treatments that share a "
                                 f"program must agree on what the harness runs")


def lay_out(maps: jax.Array, harness: Harness, slots: int):
    """``(terrain, in_axes)``: the T trials' maps (``[T, H, W]``, or ``[T, K, H, W]`` for K slots) as the
    harness takes them under ``jax.vmap`` over trials: the maps themselves (in_axes 0), or ``harness.layout`` of
    them (one bank of tiles, trial i on its tile; for K slots the layout of ``T x K`` maps with its batched leaves
    split ``[T x K, ...] -> [T, K, ...]``)."""
    if harness.layout is None:
        return maps, 0
    if slots == 1:
        return harness.layout(maps)
    trials = maps.shape[0]
    terrain, axes = harness.layout(maps.reshape((-1,) + maps.shape[2:]))

    def split(a, x):
        if a is None:
            return x
        return jax.tree.map(lambda v: v.reshape(v.shape[:a] + (trials, slots) + v.shape[a + 1:]), x)

    return jax.tree.map(split, axes, terrain, is_leaf=lambda a: a is None), axes


def _rows(tree, axes, rows):
    """``tree``'s entries ``rows`` along ``axes`` (a vmap in_axes prefix; None = shared, kept whole)."""
    return jax.tree.map(lambda a, x: x if a is None else jax.tree.map(lambda v: jnp.take(v, rows, axis=a), x), axes,
                        tree, is_leaf=lambda a: a is None)


def _concat(trees):
    return jax.tree.map(lambda *xs: jnp.concatenate(xs), *trees)


def _where_rows(pred, on_true, on_false, where: Optional[Callable] = None):
    """Per trial (``pred`` [T] bool): ``on_true`` where ``pred`` else ``on_false`` (``where`` merges one trial's
    pair, default ``jnp.where`` leaf by leaf)."""
    one = where or (lambda p, a, b: jax.tree.map(lambda x, y: jnp.where(p, x, y), a, b))
    return jax.vmap(one)(pred, on_true, on_false)


def run_population(states: Sequence[State], banks: Sequence[TerrainBank], num_chunks, rows=None, *,
                   configs: Sequence[CurriculumConfig], harness: Harness,
                   on_chunk: Optional[Callable] = None) -> tuple[State, ...]:
    """Up to ``num_chunks`` chunks of every member's trials, all members' trials in one vmapped physics call per
    chunk (see the module docstring). Pure; ``num_chunks`` ([] or [M] int, one per member) and ``rows`` may be
    traced (nothing re-compiles per value; a new R does).

    ``states[m]``: member m's trials (``State`` [T_m]); ``banks[m]``, ``configs[m]``: its bank and config
    (:func:`check_population`). Member m stops stepping once it has done ``num_chunks[m]`` chunks as
    :func:`run_trials` counts them: until every running trial of it has done that many more than its least
    advanced one had (with overlap at most ``2 n + 1`` steps); the loop ends when every member has. ``rows``: None
    (every trial's physics) or [R] int32 global trial indices (members' trials concatenated in order) holding every
    running trial. ``on_chunk``: a host function of one tuple, per member ``(chunk [T_m], hardest [T_m], done
    [T_m], history)``, after every loop step (``jax.debug.callback``; it changes no result)."""
    states, banks, configs = tuple(states), tuple(banks), tuple(configs)
    if not len(states) == len(banks) == len(configs):
        raise ValueError(f"run_population: {len(states)} states, {len(banks)} banks, {len(configs)} configs")
    check_population(configs)
    selectors = [get_selector(c) for c in configs]
    slots, overlap, members = selectors[0].slots, bool(configs[0].overlap), len(states)
    progress = any(s.progress for s in selectors) and not overlap
    sizes = [int(s.done.shape[0]) for s in states]
    edges = np.cumsum([0] + sizes)
    n = jnp.broadcast_to(jnp.asarray(num_chunks, jnp.int32), (members,))
    big = jnp.iinfo(jnp.int32).max
    targets = [jnp.min(jnp.where(s.done, big, s.chunk)) + n[m] for m, s in enumerate(states)]
    limits = [2 * n[m] + 1 if overlap else n[m] for m in range(members)]
    whole = _concat([s.policy for s in states])
    policy = whole if rows is None else jax.tree.map(lambda x: x[rows], whole)
    pick = (lambda x: x) if rows is None else (lambda tree: jax.tree.map(lambda x: x[rows], tree))  # noqa: E731
    physics = functools.partial(chunk_physics, config=configs[0], harness=harness, progress=progress)
    where_policy = None if harness.where is None else harness.where

    def stepping(i, ms):
        return [(i < limits[m]) & jnp.any(~s.done & (s.chunk < targets[m])) for m, s in enumerate(ms)]

    def cond(carry):
        return functools.reduce(jnp.logical_or, stepping(carry[0], carry[2]))

    def body(carry):
        i, pol, ms = carry
        on = stepping(i, ms)
        keys = [jax.vmap(functools.partial(chunk_keys, config=c))(s) for s, c in zip(ms, configs)]
        maps = _concat([jax.vmap(functools.partial(terrain_maps, bank=b, config=c))(s)
                        for s, b, c in zip(ms, banks, configs)])
        assigned = _concat([jax.vmap(sel.assign)(s.selector) for sel, s in zip(selectors, ms)])
        hold = [s.done | ~on[m] for m, s in enumerate(ms)]
        terrain, axes = lay_out(maps, harness, slots)
        terrain = terrain if rows is None else _rows(terrain, axes, rows)
        restart, all_keys, held = (pick(jnp.concatenate(x)) for x in ([s.restart for s in ms], keys, hold))
        out = jax.vmap(physics, in_axes=(0, 0, 0, axes, 0))(pol, restart, all_keys, terrain, pick(assigned))
        fitness, prog = out.fitness, out.progress
        if rows is not None:  # back on all T trials (the others are done: their updates are dropped)
            fitness = jnp.zeros((edges[-1],), fitness.dtype).at[rows].set(fitness)
            prog = None if prog is None else jnp.zeros((edges[-1],) + prog.shape[1:], prog.dtype).at[rows].set(prog)
        new, used = [], []
        for m, (s, b, c) in enumerate(zip(ms, banks, configs)):
            part = slice(int(edges[m]), int(edges[m + 1]))
            u, use = jax.vmap(functools.partial(chunk_update, config=c), in_axes=(0, 0, 0, 0, None))(
                s, fitness[part], None if prog is None else prog[part], keys[m], b)
            new.append(_where_rows(hold[m], s, u))
            used.append(use)
        trained = out.trained
        if overlap:
            trained = _where_rows(pick(jnp.concatenate(used)), out.trained, out.start, where_policy)
        pol = _where_rows(held, pol, trained, where_policy)
        new = tuple(new)
        if on_chunk is not None:
            jax.debug.callback(on_chunk, tuple((s.chunk, s.hardest, s.done, s.history) for s in new))
        return i + 1, pol, new

    bare = tuple(s._replace(policy=None) for s in states)
    _, policy, bare = jax.lax.while_loop(cond, body, (jnp.zeros((), jnp.int32), policy, bare))
    if rows is not None:
        policy = jax.tree.map(lambda full, part: full.at[rows].set(part), whole, policy)
    return tuple(s._replace(policy=jax.tree.map(lambda x: x[int(edges[m]):int(edges[m + 1])], policy))
                 for m, s in enumerate(bare))


def make_population_runner(configs: Sequence[CurriculumConfig], harness: Harness, on_chunk: Optional[Callable] = None):
    """The jitted ``(states, banks, num_chunks [M], rows [R] or None) -> states`` of :func:`run_population`
    (``states`` donated). One compile per trial counts and bank shapes, and per R."""
    configs = tuple(configs)
    check_population(configs)
    fn = functools.partial(run_population, configs=configs, harness=harness, on_chunk=on_chunk)
    return jax.jit(lambda s, b, n, rows=None: fn(s, b, jnp.asarray(n, jnp.int32), rows), donate_argnums=(0,))


def population_rows(done: Sequence) -> Optional[np.ndarray]:
    """The global rows a population block computes: :func:`live_rows` of the members' ``done`` ([T_m] each)
    concatenated, as int32; None when that is every trial. Host-side."""
    flat = np.concatenate([np.asarray(d, bool).reshape(-1) for d in done])
    rows = live_rows(flat)
    return None if rows.size == flat.size else rows.astype(np.int32)


# ----------------------------------------------------------------------------------------------------------------
# The trials of one treatment
# ----------------------------------------------------------------------------------------------------------------
def run_trials(states: State, bank: TerrainBank, num_chunks: jax.Array, rows=None, *, config: CurriculumConfig,
               harness: Harness, on_chunk: Optional[Callable] = None) -> State:
    """Up to ``num_chunks`` chunks of every trial ([T]-batched ``states``), all trials in one vmapped step per
    chunk; stops early once every trial is done. ``num_chunks`` may be traced (no re-compile per value). Pure.
    With ``config.overlap``: steps until every running trial has done ``num_chunks`` chunks more than the least
    advanced one had (a trial with fewer terrain switches may do a few more). :func:`run_population` of one member.

    With ``harness.layout`` every chunk first lays out the T trials' current terrains (``bank.heightmaps
    [states.terrain]`` [T, H, W] -> one terrain pytree, e.g. a bank of T tiles) and trial i trains and is evaluated
    on its slice i.

    ``rows``: None (every trial's physics) or [R] int32 trial indices holding every running trial
    (:func:`live_rows`): the physics computes those trials only, each still on the tile of its own index (the maps
    are laid out for all T trials), and the others (done) are returned unchanged. So the result is that of
    ``rows=None``, at the cost of R trials.

    ``on_chunk``: a host function ``(chunk [T] int32, hardest [T] float32, done [T] bool, history) -> None``
    (``history``: the trials' :class:`~jaxterrain.curriculum.core.History`, leaves ``[T, C]``) called after every
    loop step through ``jax.debug.callback`` (progress and metrics inside a compiled block; it changes no result)."""
    listen = None if on_chunk is None else (lambda members: on_chunk(*members[0]))
    return run_population((states,), (bank,), num_chunks, rows, configs=(config,), harness=harness,
                          on_chunk=listen)[0]


def mesh_rows(fn: Callable, mesh) -> Callable:
    """``fn(states [T], bank, n, rows [R] or None) -> states [T]`` (:func:`run_trials` of a config and harness) with
    the rows split over ``mesh``'s devices (``sharding.map_rows``: padded to the devices with copies of the last
    row, cut off again): each device gets the whole ``states`` and ``bank`` and computes its share of ``rows``
    (None: every trial), the other trials marked done there (so its loop counts its own trials, as
    :func:`make_runner` says), and each trial keeps the tile of its own index whatever the split."""
    def part(rows, states, bank, n):
        mine = jnp.zeros(states.done.shape, bool).at[rows].set(True)
        out = fn(states._replace(done=states.done | ~mine), bank, n, rows)
        return jax.tree.map(lambda x: x[rows], out)

    split = sharding.map_rows(part, mesh, replicated=(1, 2, 3))

    def run(states, bank, n, rows=None):
        rows = jnp.arange(states.done.shape[0], dtype=jnp.int32) if rows is None else jnp.asarray(rows, jnp.int32)
        got = split(rows, states, bank, jnp.asarray(n, jnp.int32))
        return jax.tree.map(lambda x, y: x.at[rows].set(y), states, got)

    return run


def make_runner(config: CurriculumConfig, harness: Harness, mesh=None) -> Callable[..., State]:
    """The jitted ``(states [T], bank, num_chunks, rows=None) -> states`` of :func:`run_trials` (``states``
    donated). Build it once per (config, harness) and call it per block of chunks: neither terrain switches nor the
    block length re-compile it (a new trial count, a new bank shape, a new number of ``rows`` does).

    ``mesh`` (a ``jax.sharding.Mesh``): the trials (or ``rows``) are split over its devices (:func:`mesh_rows`:
    the states and the bank whole on every device), each device running its own trials' loop (it stops when ITS
    trials are done). A trial's chunks depend only on its own state and key, so the states are those of the
    one-device runner, except with ``config.overlap``: there a block runs until the least advanced running trial
    has done ``num_chunks`` (trials ahead of it step on meanwhile), and each device counts that among its own
    trials, so a trial's block may end at another chunk than on one device, and its envs restart there (the same
    curriculum rules, other PPO data)."""
    fn = functools.partial(run_trials, config=config, harness=harness)
    if mesh is not None:
        return mesh_rows(lambda s, b, n, rows: fn(s, b, jnp.asarray(n, jnp.int32), rows), mesh)
    return jax.jit(lambda s, b, n, rows=None: fn(s, b, jnp.asarray(n, jnp.int32), rows), donate_argnums=(0,))


def live_rows(done) -> np.ndarray:
    """The trial rows a block has to compute: every running trial (``~done`` [T]), then finished ones up to the next
    power of two, in index order ([k] int, k <= T). Padding to powers of two bounds a run's block sizes (and so its
    compiles) to log2(T) + 2. Host-side: reads ``done``."""
    done = np.asarray(done, bool)
    live = np.flatnonzero(~done)
    size = min(done.size, 1 << max(live.size - 1, 0).bit_length())
    return np.sort(np.concatenate([live, np.flatnonzero(done)[:size - live.size]]))


def tile_moves(done) -> np.ndarray:
    """``[T] bool``: the running trials (``~done``) that the solo runner before the fix (59440af) moved to another
    tile when it computed the :func:`live_rows` only: it cut the states down to those rows, so row r (trial
    ``live_rows(done)[r]``) was laid out on tile r, and a running trial whose index is not its row walked on
    another trial's tile until its envs' next reset (with env states carried across blocks, from bfe08b4). All
    False when every row is computed. Host-side; for the accounting of runs trained with that bug
    (``docs/results/exp3.md``)."""
    done = np.asarray(done, bool)
    rows = live_rows(done)
    moved = np.zeros(done.size, bool)
    if rows.size < done.size:
        moved[rows] = rows != np.arange(rows.size)
    return moved & ~done


def run_live(run: Callable[..., State], states: State, bank: TerrainBank, num_chunks) -> State:
    """``run(states, bank, num_chunks, rows)`` (a :func:`make_runner` runner, or any function of that shape) with
    ``rows`` the :func:`live_rows` of ``states.done`` (None when that is every trial): the running trials only are
    computed, each on its own tile.

    The same states as ``run`` on all T rows (a block leaves a finished trial unchanged, and rows are independent;
    with real physics on a CPU up to the last bits where XLA compiles the smaller batch's products otherwise:
    ``tests/integration/test_learn_command.py``), without the cost of the finished ones: under ``vmap`` a finished trial still takes its share of every physics
    step and evaluation walk, so once trials end at different times (the map curriculum empties some maps early)
    a block of 4 rows instead of 10 is faster. Host-side (reads ``states.done``); a jitted ``run`` compiles once
    per block size. Not exact for a mesh runner under ``config.overlap``: fewer rows regroup the trials over the
    devices, and there each device ends a block by its own trials (:func:`make_runner`)."""
    rows = live_rows(states.done)
    if rows.size == states.done.shape[0]:
        return run(states, bank, num_chunks, None)
    return run(states, bank, num_chunks, jnp.asarray(rows, jnp.int32))
