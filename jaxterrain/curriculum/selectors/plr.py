"""``plr``: prioritised level replay over the bank's terrains, and the level buffer that ``accel`` shares.

It keeps JaxUED's ``LevelSampler`` and the defaults of its ``maze_plr.py`` (replay probability 0.8 once the buffer
is half full, rank prioritisation at temperature 0.3, staleness coefficient 0.3, duplicates updated, not added), with
a level = a bank terrain (so the buffer holds at most the bank's N) and three differences: (0) the buffer is sized
to the run (:func:`plr_buffer_capacity`: half full after the first tenth of its chunks; 128 at ``gpu-short``), not
4 000 levels: JaxUED's buffer fills to half in its first 0.2 % of updates, while at 8 new levels a chunk a 4 000
buffer would need 250 chunks, more than a 75-chunk run has; (1) a terrain's score is its *learnability* ``p (1 -
p)`` (p: the fraction of its envs that reached the threshold in the chunk; Rutherford et al. 2024's SFL), not MaxMC
or the positive value loss, which need per-level value estimates that our chunk does not expose; (2) new terrains
are trained on (PLR's "exploratory gradient updates", JaxUED's ``--exploratory_grad_updates``), not only scored as
robust PLR does: a chunk's PPO rollouts are the only rollouts it makes, and scoring without training would spend a
chunk's budget on evaluation. The policy is evaluated on the chunk's first terrain.
"""

from __future__ import annotations

import functools
import math
from typing import Any, NamedTuple, Optional

import jax
import jax.numpy as jnp

from jaxterrain.curriculum.selectors.base import float_in, where_levels
from jaxterrain.curriculum.selectors.protocol import (Assignment, Decision, Selector, register_selector,
                                                      round_robin)
from jaxterrain.runtime.validation import int_at_least

__all__ = ["PLRParams", "PLRState", "LevelBuffer", "plr_selector", "plr_buffer_capacity", "PLR_FILL_FRACTION",
           "plr_weights", "plr_insert", "plr_sample", "same_level", "learnability", "validate_buffer", "validate_plr",
           "FLAT"]

OWNER = "CurriculumConfig.params"


class PLRParams(NamedTuple):
    """``plr``'s parameters (JaxUED's ``maze_plr.py`` defaults 4000, 0.8, 0.3, 0.3, 0.5 for the last five).

    terrains_per_chunk: K terrains a chunk, the envs dealt round-robin over them, >= 1. capacity: level buffer
    entries, >= 1 and at most the bank's terrains; None (the default) sizes the buffer to the run
    (:func:`plr_buffer_capacity`): it reaches ``min_fill`` within the run's first tenth of chunks. JaxUED's 4 000
    fills in its first 0.2 % of updates (32 new mazes an update, 30 000 updates); a chunk here brings only K new
    levels, so 4 000 would fill to half only after 250 chunks at 8 a chunk, never within a ``gpu-short`` run of 75
    (measured: Experiment 3b's first ``accel`` run never replayed). An explicit capacity that cannot reach
    ``min_fill`` within the run is refused. replay_prob: the chance a chunk replays, in [0, 1]. staleness: the
    staleness coefficient, in [0, 1]. temperature: the rank temperature, > 0. min_fill: the buffer's fill before any
    replay, in [0, 1]."""

    terrains_per_chunk: int = 8
    capacity: Optional[int] = None
    replay_prob: float = 0.8
    staleness: float = 0.3
    temperature: float = 0.3
    min_fill: float = 0.5


FLAT = {"terrains_per_chunk": "terrains_per_chunk", "plr_capacity": "capacity", "plr_replay_prob": "replay_prob",
        "plr_staleness": "staleness", "plr_temperature": "temperature", "plr_min_fill": "min_fill"}
"""``learn``'s config keys (and flags) of :class:`PLRParams`; ``accel`` adds its own two."""


PLR_FILL_FRACTION = 0.1
"""``plr_capacity=None``: the buffer reaches ``plr_min_fill`` after this fraction of the run's chunks."""


def plr_buffer_capacity(params, max_chunks: int) -> int:
    """Entries of ``plr``'s and ``accel``'s level buffer (``params``: :class:`PLRParams` or ``AccelParams``) in a run
    of ``max_chunks`` chunks: ``params.capacity``, or with None the buffer that the new levels of the run's first
    ``PLR_FILL_FRACTION`` of chunks (``terrains_per_chunk`` each, at least one chunk) fill to ``min_fill``:
    ``ceil(K x ceil(chunks / 10) / min_fill)`` (``gpu-short``, 75 chunks of 8: 128; the
    paper's budget, 750 chunks: 1 200). ``plr`` bounds it further by the bank's terrains."""
    if params.capacity is not None:
        return int(params.capacity)
    new = int(params.terrains_per_chunk) * max(1, math.ceil(max_chunks * PLR_FILL_FRACTION))
    return max(int(params.terrains_per_chunk), math.ceil(new / params.min_fill) if params.min_fill > 0 else new)


class PLRState(NamedTuple):
    """``plr``'s state: JaxUED's level buffer (``LevelSampler``'s ``Sampler``) over bank terrains, and the chunk's
    assignment. levels: [C] int32 bank index of each buffer entry (-1 empty). scores: [C] float32 (-inf empty).
    timestamps: [C] int32 the episode count when the entry was last sampled or inserted. size: [] int32 entries.
    episode_count: [] int32. terrains: [K] int32 this chunk's terrains. entry: [K] int32 their buffer entries
    (replay), -1 for new terrains. replay: [] bool this chunk replays. replays: [] int32 replay chunks so far."""

    levels: jax.Array
    scores: jax.Array
    timestamps: jax.Array
    size: jax.Array
    episode_count: jax.Array
    terrains: jax.Array
    entry: jax.Array
    replay: jax.Array
    replays: jax.Array


def plr_weights(s: PLRState, temperature: float, staleness_coeff: float) -> jax.Array:
    """``[C]`` replay distribution of a buffer: ``(1 - staleness_coeff) x`` rank prioritisation (``(1 / rank) **
    (1 / temperature)``, normalised; rank 1 = highest score) ``+ staleness_coeff x`` staleness (``episode_count -
    timestamps``, normalised; uniform over the entries while all are 0), both over the filled entries only
    (JaxUED ``LevelSampler.level_weights`` with ``prioritization="rank"``)."""
    c = s.scores.shape[0]
    mask = jnp.arange(c) < s.size
    order = jnp.argsort(-jnp.where(mask, s.scores, -jnp.inf))
    ranks = jnp.zeros(c, jnp.int32).at[order].set(jnp.arange(c, dtype=jnp.int32) + 1)
    w_s = jnp.where(mask, 1.0 / ranks, 0.0) ** (1.0 / temperature)
    w_s = w_s / jnp.maximum(w_s.sum(), 1e-30)
    stale = jnp.where(mask, s.episode_count - s.timestamps, 0).astype(jnp.float32)
    w_c = jnp.where(stale.sum() > 0, stale / jnp.maximum(stale.sum(), 1e-30),
                    mask / jnp.maximum(s.size, 1).astype(jnp.float32))
    return (1.0 - staleness_coeff) * w_s + staleness_coeff * w_c


def same_level(levels, level) -> jax.Array:
    """``[C]`` bool: entry c of ``levels`` (a pytree, leading axis C: bank indices [C] or genomes) equals ``level``
    (the same pytree without the C axis) in every leaf."""
    def eq(a, b):
        return jnp.all((a == b).reshape(a.shape[0], -1), axis=1)
    return functools.reduce(jnp.logical_and, jax.tree.leaves(jax.tree.map(eq, levels, level)))


def plr_insert(s, level, score, temperature: float, staleness_coeff: float):
    """One level into the buffer with its score (JaxUED ``insert`` with ``duplicate_check``): a level already there
    gets the new score and timestamp; else it fills the next empty entry, or, when full, replaces the entry of
    lowest replay weight if its score is lower; the episode count grows by one either way. ``s``: a
    :class:`PLRState` (levels = bank indices [C]) or :class:`LevelBuffer` (levels = a genome pytree [C, ...]);
    ``level`` one level of the same kind."""
    c = s.scores.shape[0]
    found = same_level(s.levels, level) & (jnp.arange(c) < s.size)
    there = jnp.any(found)
    idx = jnp.where(there, jnp.argmax(found),
                    jnp.where(s.size < c, s.size, jnp.argmin(plr_weights(s, temperature, staleness_coeff))))
    write = there | (s.scores[idx] < score)
    count = s.episode_count + 1
    levels = jax.tree.map(lambda a, b: a.at[idx].set(jnp.where(write, b, a[idx])), s.levels, level)
    return s._replace(levels=levels,
                      scores=s.scores.at[idx].set(jnp.where(write, score, s.scores[idx])),
                      timestamps=s.timestamps.at[idx].set(jnp.where(write, count, s.timestamps[idx])),
                      size=jnp.where(write & ~there, jnp.minimum(s.size + 1, c), s.size), episode_count=count)


def plr_sample(s, key, num: int, temperature: float, staleness_coeff: float):
    """``(state, entries [num] int32)``: ``num`` replays drawn one after another from :func:`plr_weights`, each
    marking its entry as just seen (JaxUED ``sample_replay_levels``). ``s``: :class:`PLRState` or
    :class:`LevelBuffer`."""
    def one(s, k):
        idx = jax.random.choice(k, s.scores.shape[0], p=plr_weights(s, temperature, staleness_coeff))
        count = s.episode_count + 1
        return s._replace(timestamps=s.timestamps.at[idx].set(count), episode_count=count), idx.astype(jnp.int32)

    return jax.lax.scan(one, s, jax.random.split(key, num))


def learnability(progress, env_slot, slots: int, threshold: float) -> jax.Array:
    """``[K]`` score of each terrain of a chunk: ``p (1 - p)``, p the fraction of its envs whose furthest progress
    reached ``threshold`` (the learnability of SFL, Rutherford et al. 2024: highest for terrains walked sometimes)."""
    success = (progress >= threshold).astype(jnp.float32)
    count = jnp.zeros(slots, jnp.float32).at[env_slot].add(1.0)
    p = jnp.zeros(slots, jnp.float32).at[env_slot].add(success) / jnp.maximum(count, 1.0)
    return p * (1.0 - p)


def plr_selector(config) -> Selector:
    """Prioritised level replay over the bank's terrains (JaxUED's ``LevelSampler`` and its defaults; see the module
    docstring for where ours differ). Every chunk trains the envs on ``terrains_per_chunk`` terrains, env e on
    terrain ``e % K``: with probability ``plr_replay_prob`` (once the buffer is ``plr_min_fill`` full) K replays
    from the buffer, else K new terrains drawn uniformly from the bank; after the chunk each terrain's score
    (:func:`learnability` of its envs' progress) updates its replayed entry or is inserted (:func:`plr_insert`)."""
    p = config.params if config.params is not None else PLRParams()
    k, e = int(p.terrains_per_chunk), int(config.ppo.num_envs)
    temperature, stale = float(p.temperature), float(p.staleness)
    threshold = float(config.threshold * config.max_fitness)

    def new(key, bank):
        return jax.random.randint(key, (k,), 0, bank.fitness.shape[0], dtype=jnp.int32)

    def init(key, bank):
        c = min(plr_buffer_capacity(p, config.max_chunks), int(bank.fitness.shape[0]))
        zi = jnp.zeros((), jnp.int32)
        return PLRState(levels=jnp.full((c,), -1, jnp.int32), scores=jnp.full((c,), -jnp.inf, jnp.float32),
                        timestamps=jnp.zeros((c,), jnp.int32), size=zi, episode_count=zi, terrains=new(key, bank),
                        entry=jnp.full((k,), -1, jnp.int32), replay=jnp.zeros((), bool), replays=zi)

    def assign(s):
        return Assignment(terrains=s.terrains, env_slot=round_robin(e, k), evaluated=jnp.zeros((), jnp.int32))

    def update(s, key, bank, outcome):
        decide_key, sample_key, new_key = jax.random.split(key, 3)
        scores = learnability(outcome.progress, round_robin(e, k), k, threshold)
        # replayed entries take their new scores; new terrains go in one by one
        replayed = s._replace(scores=s.scores.at[jnp.where(s.replay, s.entry, s.scores.shape[0])].set(
            scores, mode="drop"))
        inserted = jax.lax.fori_loop(0, k, lambda i, b: plr_insert(b, s.terrains[i], scores[i], temperature, stale),
                                     s)
        buf = where_levels(s.replay, replayed, inserted)
        replay = ((buf.size / buf.levels.shape[0]) >= p.min_fill) & (
            jax.random.uniform(decide_key) < p.replay_prob)
        sampled, entry = plr_sample(buf, sample_key, k, temperature, stale)
        nxt = where_levels(replay, sampled, buf)
        nxt = nxt._replace(terrains=jnp.where(replay, buf.levels[entry], new(new_key, bank)),
                           entry=jnp.where(replay, entry, -1), replay=replay,
                           replays=s.replays + replay.astype(jnp.int32))
        reached = outcome.fitness >= threshold
        return nxt, Decision(finished=reached, restart=jnp.ones((), bool), exhausted=jnp.zeros((), bool))

    def summary(s):
        filled = jnp.arange(s.scores.shape[0]) < s.size
        return {"buffer_size": s.size, "replay_chunks": s.replays,
                "buffer_mean_score": jnp.sum(jnp.where(filled, s.scores, 0.0)) / jnp.maximum(s.size, 1)}

    return Selector("plr", k, init, assign, update, summary, progress=True)


class LevelBuffer(NamedTuple):
    """A PLR level buffer whose levels are any pytree (JaxUED's ``Sampler``). levels: genomes, every leaf with a
    leading axis C. scores: [C] float32 (-inf empty). timestamps: [C] int32. size: [] int32 entries filled.
    episode_count: [] int32. :func:`plr_weights`, :func:`plr_insert` and :func:`plr_sample` take it."""

    levels: Any
    scores: jax.Array
    timestamps: jax.Array
    size: jax.Array
    episode_count: jax.Array


def validate_buffer(config, p) -> None:
    """The level-buffer fields ``plr`` and ``accel`` share: ``ValueError`` naming ``CurriculumConfig.params.<field>``;
    an explicit ``capacity`` that the run's new levels cannot fill to ``min_fill`` is refused (it would never
    replay)."""
    int_at_least(OWNER, p, "terrains_per_chunk", 1)
    if p.capacity is not None:
        int_at_least(OWNER, p, "capacity", 1)
    for name in ("replay_prob", "staleness", "min_fill"):
        float_in(OWNER, p, name, 0.0, 1.0, lo_open=False)
    float_in(OWNER, p, "temperature", 0.0, None, lo_open=True)
    if p.capacity is not None:
        fill = math.ceil(p.capacity * p.min_fill)
        seen = p.terrains_per_chunk * config.max_chunks
        if fill > seen:
            raise ValueError(
                f"{OWNER}.capacity must be at most {int(seen / max(p.min_fill, 1e-9))} (or None: sized to the run) "
                f"for {config.selector}: {p.capacity} fills to min_fill={p.min_fill} ({fill} levels) only after more "
                f"than the run's {config.max_chunks} chunks of {p.terrains_per_chunk} new levels ({seen}), so it "
                f"would never replay")


def validate_plr(config, p: PLRParams) -> None:
    """:func:`validate_buffer`."""
    validate_buffer(config, p)


register_selector("plr", plr_selector, PLRParams, validate_plr, FLAT)
