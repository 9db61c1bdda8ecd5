"""``accel``: ACCEL (Parker-Holder et al. 2022; JaxUED's ``accel`` branch), PLR over a generator's genomes whose
replayed levels are edited by the generator's ``mutate``.

It keeps JaxUED's branch structure (a chunk on new levels or, with the replay probability, on buffer replays; the
chunk after a replay on the replayed levels, each edited; new and edited levels scored and inserted, replayed ones
re-scored) with ``plr``'s buffer defaults and its differences (:mod:`.plr`: a buffer sized to the run, learnability
scores, edited and new levels trained on, where robust ACCEL only scores them), and: a level is a genome of
``generator`` (JaxUED: a maze), a new level is the generator's random ``sample`` (JaxUED's ACCEL starts from empty
mazes), an edit is ``edits`` (default 1) applications of the generator's own ``mutate`` (the paper's operator;
JaxUED edits 5 maze tiles; one of our mutations already moves about a third of a vector genome's genes, or grows a
CPPN's network), and the buffer's capacity is :func:`~.plr.plr_buffer_capacity` genomes (not bound by the bank).
The policy is also evaluated each chunk on one bank terrain drawn uniformly (an extra slot no env trains on), so the
paper's "hardest terrain traversed" is recorded on the archive as for ``dr``.
"""

from __future__ import annotations

from typing import Any, NamedTuple, Optional

import jax
import jax.numpy as jnp

from jaxterrain import generators
from jaxterrain.curriculum.selectors.base import take_levels, where_levels
from jaxterrain.curriculum.selectors.plr import (FLAT as PLR_FLAT, LevelBuffer, learnability, plr_buffer_capacity,
                                                 plr_insert, plr_sample, validate_buffer)
from jaxterrain.curriculum.selectors.protocol import (Assignment, Decision, Selector, register_selector,
                                                      round_robin)
from jaxterrain.runtime.validation import int_at_least
from jaxterrain.terrain import TerrainScale

__all__ = ["AccelParams", "AccelState", "ACCEL_NEW", "ACCEL_REPLAY", "ACCEL_EDIT", "accel_selector",
           "accel_generator", "validate_accel", "FLAT"]


class AccelParams(NamedTuple):
    """``accel``'s parameters: :class:`~.plr.PLRParams`' six for its buffer of genomes (the capacity not bounded by
    the bank), and generator: the generator whose genomes are the levels (its ``sample`` makes new levels, its
    ``mutate`` edits them); None = unset (``experiments learn`` sets the archive's generator), must be set to run.
    edits: ``mutate`` applications per edit of a replayed level, >= 1."""

    terrains_per_chunk: int = 8
    capacity: Optional[int] = None
    replay_prob: float = 0.8
    staleness: float = 0.3
    temperature: float = 0.3
    min_fill: float = 0.5
    generator: Optional[str] = None
    edits: int = 1


FLAT = {**PLR_FLAT, "accel_generator": "generator", "accel_edits": "edits"}
"""``learn``'s config keys (and flags) of :class:`AccelParams`."""


ACCEL_NEW, ACCEL_REPLAY, ACCEL_EDIT = 0, 1, 2
"""``AccelState.mode``: this chunk trains on new levels (the generator's fresh samples), on replayed buffer levels,
or on edits (``mutate``) of the levels the previous chunk replayed."""


class AccelState(NamedTuple):
    """``accel``'s state. buffer: :class:`LevelBuffer` of genomes. genomes: the chunk's K levels (leading axis K).
    terrain: [] int32 the bank terrain the policy is evaluated on (the paper's metric; not trained on). entry: [K]
    int32 the replayed levels' buffer entries (-1 for new and edited levels). mode: [] int32 ``ACCEL_NEW``,
    ``ACCEL_REPLAY`` or ``ACCEL_EDIT``. replays, edits: [] int32 chunks of each kind so far."""

    buffer: LevelBuffer
    genomes: Any
    terrain: jax.Array
    entry: jax.Array
    mode: jax.Array
    replays: jax.Array
    edits: jax.Array


def accel_generator(params, size: Optional[int] = None):
    """The :class:`jaxterrain.generators.Generator` whose genomes are ``accel``'s levels (``params.generator``,
    :class:`AccelParams`), rendering ``size`` x ``size`` maps (None: its default, 256); ``ValueError`` naming the
    field when it is unset or unknown."""
    name = params.generator
    if name is None or name not in generators.names():
        raise ValueError(f"CurriculumConfig.params.generator must be one of {', '.join(generators.names())} (the "
                         f"generator whose genomes are accel's levels), got {name!r}")
    return generators.get(name) if size is None else generators.get(name, size=int(size))


def accel_selector(config) -> Selector:
    """ACCEL (Parker-Holder et al. 2022; JaxUED's ``accel`` branch): PLR whose levels are genomes of
    ``params.generator`` (:class:`AccelParams`). A chunk trains on K = ``terrains_per_chunk`` levels, rendered in the loop (env e on
    level ``e % K``): new levels (``generator.sample``), or with probability ``replay_prob`` (once the buffer is
    ``min_fill`` full) K replays from the buffer; the chunk after a replay trains on the replayed levels each
    edited by ``edits`` applications of the generator's ``mutate``. After a chunk each level's
    :func:`learnability` updates its replayed entry, or the level (new or edited) is inserted with it
    (:func:`plr_insert`). The policy is evaluated on one more slot, a bank terrain drawn uniformly each chunk, not
    trained on: the paper's "hardest terrain traversed" on the archive, as ``dr`` records it. Levels are rendered
    at ``TerrainScale()``'s height (1 m per unit), the scale ``qd.bank.from_archive`` renders the archive at."""
    p = config.params if config.params is not None else AccelParams()
    k, e = int(p.terrains_per_chunk), int(config.ppo.num_envs)
    temperature, stale = float(p.temperature), float(p.staleness)
    threshold = float(config.threshold * config.max_fitness)
    edits, height = int(p.edits), float(TerrainScale().height)

    def fresh(key):
        return accel_generator(p).sample(key, k)

    def edit(key, genomes):
        mutate = accel_generator(p).mutate
        return jax.lax.fori_loop(0, edits, lambda i, g: mutate(jax.random.fold_in(key, i), g), genomes)

    def draw(key, bank):
        return jax.random.randint(key, (), 0, bank.fitness.shape[0], dtype=jnp.int32)

    def init(key, bank):
        new_key, eval_key = jax.random.split(key)
        genomes = fresh(new_key)
        c = plr_buffer_capacity(p, config.max_chunks)
        buffer = LevelBuffer(levels=jax.tree.map(lambda a: jnp.zeros((c,) + a.shape[1:], a.dtype), genomes),
                             scores=jnp.full((c,), -jnp.inf, jnp.float32), timestamps=jnp.zeros((c,), jnp.int32),
                             size=jnp.zeros((), jnp.int32), episode_count=jnp.zeros((), jnp.int32))
        zi = jnp.zeros((), jnp.int32)
        return AccelState(buffer=buffer, genomes=genomes, terrain=draw(eval_key, bank),
                          entry=jnp.full((k,), -1, jnp.int32), mode=jnp.full((), ACCEL_NEW, jnp.int32), replays=zi,
                          edits=zi)

    def assign(s):
        terrains = jnp.concatenate([jnp.full((k,), -1, jnp.int32), s.terrain[None]])
        return Assignment(terrains=terrains, env_slot=round_robin(e, k), evaluated=jnp.full((), k, jnp.int32))

    def maps(s, bank):
        h, w = bank.heightmaps.shape[1:]
        if h != w:
            raise ValueError(f"accel renders square maps; the bank's are {h} x {w}")
        gen = accel_generator(p, None if h == 256 else h)
        rendered = jax.vmap(gen.render_one)(s.genomes).astype(jnp.float32) * height
        return jnp.concatenate([rendered, bank.heightmaps[s.terrain][None]])

    def update(s, key, bank, outcome):
        decide_key, sample_key, new_key, edit_key, eval_key = jax.random.split(key, 5)
        scores = learnability(outcome.progress, round_robin(e, k), k, threshold)
        b = s.buffer
        replayed = b._replace(scores=b.scores.at[jnp.where(s.mode == ACCEL_REPLAY, s.entry, b.scores.shape[0])].set(
            scores, mode="drop"))
        inserted = jax.lax.fori_loop(
            0, k, lambda i, buf: plr_insert(buf, take_levels(s.genomes, i), scores[i], temperature, stale), b)
        buf = where_levels(s.mode == ACCEL_REPLAY, replayed, inserted)
        edit_next = s.mode == ACCEL_REPLAY  # the chunk after a replay trains on its levels, edited
        replay = ~edit_next & ((buf.size / buf.scores.shape[0]) >= p.min_fill) & (
            jax.random.uniform(decide_key) < p.replay_prob)
        sampled, entry = plr_sample(buf, sample_key, k, temperature, stale)
        genomes = where_levels(edit_next, edit(edit_key, s.genomes),
                                where_levels(replay, take_levels(buf.levels, entry), fresh(new_key)))
        mode = jnp.where(edit_next, ACCEL_EDIT, jnp.where(replay, ACCEL_REPLAY, ACCEL_NEW)).astype(jnp.int32)
        new = AccelState(buffer=where_levels(replay, sampled, buf), genomes=genomes, terrain=draw(eval_key, bank),
                         entry=jnp.where(replay, entry, -1), mode=mode,
                         replays=s.replays + replay.astype(jnp.int32), edits=s.edits + edit_next.astype(jnp.int32))
        reached = outcome.fitness >= threshold
        return new, Decision(finished=reached, restart=jnp.ones((), bool), exhausted=jnp.zeros((), bool))

    def summary(s):
        b = s.buffer
        filled = jnp.arange(b.scores.shape[0]) < b.size
        return {"buffer_size": b.size, "replay_chunks": s.replays, "edit_chunks": s.edits,
                "buffer_mean_score": jnp.sum(jnp.where(filled, b.scores, 0.0)) / jnp.maximum(b.size, 1)}

    return Selector("accel", k + 1, init, assign, update, summary, progress=True, maps=maps)


def validate_accel(config, p: AccelParams) -> None:
    """``ValueError`` naming the first bad field of :class:`AccelParams` (``CurriculumConfig.params.<field>``)."""
    validate_buffer(config, p)
    int_at_least("CurriculumConfig.params", p, "edits", 1)
    accel_generator(p)


register_selector("accel", accel_selector, AccelParams, validate_accel, FLAT)
