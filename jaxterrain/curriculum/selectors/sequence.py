"""Sequence selectors (``slots = 1``: every env on one terrain until it is finished, the paper's Experiment 2): the
state and the finishing rule that ``map``, ``roughness`` and ``random`` share. A terrain is finished at ``threshold x
max_fitness`` or after ``max_evals`` evaluations; the run ends when no terrain is left. Each algorithm gives only its
first choice and its next one (:func:`sequence_selector`)."""

from __future__ import annotations

from typing import Callable, NamedTuple, Optional

import jax
import jax.numpy as jnp

from jaxterrain.curriculum.selectors.base import select, terrain_hardness
from jaxterrain.curriculum.selectors.protocol import Assignment, Decision, Selector

__all__ = ["SequenceState", "sequence_selector"]


class SequenceState(NamedTuple):
    """A sequence selector's state. current: [] int32 the terrain trained now. available: [N] bool terrains still
    on offer. terrain_evals: [] int32 evaluations spent on ``current``. terrain_best: [] float32 its best so far.
    obs_index: [M] int32 bank index of each GP observation (-1 = empty slot; ``map`` reads them, the others record
    the finished terrains there too). obs_y: [M] float32 observed fitness. obs_count: [] int32 terrains finished."""

    current: jax.Array
    available: jax.Array
    terrain_evals: jax.Array
    terrain_best: jax.Array
    obs_index: jax.Array
    obs_y: jax.Array
    obs_count: jax.Array


def sequence_selector(config, name: str, initial: Callable, following: Callable, gp_evaluation: str = "final",
                      max_observations: Optional[int] = None) -> Selector:
    """The :class:`Selector` ``name`` that trains one terrain at a time. ``initial(bank, key) -> (available [N]
    bool, score [N])``: the terrains on offer and the scores of the first choice. ``following(s, bank, key, trained,
    obs_index, obs_y, hardness) -> (remove [N] bool, score [N])`` after a terrain is finished: what it removes and
    the scores of the next choice (:func:`~jaxterrain.curriculum.selectors.base.select`: ties to the nearest).
    ``gp_evaluation``: ``final`` or ``best`` evaluation of a finished terrain is recorded as its observation;
    ``max_observations``: the observation slots M (None: ``config.observation_slots``)."""

    def init(key, bank):
        n = bank.fitness.shape[0]
        m = config.observation_slots(n, max_observations)
        available, score = initial(bank, key)
        first = select(score, available, terrain_hardness(bank, config.distance_origin))
        zi = jnp.zeros((), jnp.int32)
        return SequenceState(current=first, available=available, terrain_evals=zi,
                             terrain_best=jnp.full((), -jnp.inf, jnp.float32), obs_index=jnp.full((m,), -1, jnp.int32),
                             obs_y=jnp.zeros((m,), jnp.float32), obs_count=zi)

    def assign(s):
        return Assignment(terrains=s.current[None], env_slot=None, evaluated=jnp.zeros((), jnp.int32))

    def update(s, key, bank, outcome):
        hardness = terrain_hardness(bank, config.distance_origin)
        t, fitness = s.current, outcome.fitness
        evals = s.terrain_evals + 1
        best = jnp.maximum(s.terrain_best, fitness)
        finished = (fitness >= config.threshold * config.max_fitness) | (evals >= config.max_evals)
        slot = jnp.where(finished, s.obs_count, s.obs_index.shape[0])  # out of range -> dropped
        y = fitness if gp_evaluation == "final" else best
        obs_index = s.obs_index.at[slot].set(t, mode="drop")
        obs_y = s.obs_y.at[slot].set(y, mode="drop")
        remove, score = following(s, bank, key, t, obs_index, obs_y, hardness)
        available = jnp.where(finished, s.available & ~remove, s.available)
        nxt = select(score, available, hardness)
        switch = finished & jnp.any(available)
        new = SequenceState(current=jnp.where(switch, nxt, t), available=available,
                            terrain_evals=jnp.where(finished, 0, evals),
                            terrain_best=jnp.where(finished, -jnp.inf, best), obs_index=obs_index, obs_y=obs_y,
                            obs_count=s.obs_count + finished.astype(jnp.int32))
        return new, Decision(finished=finished, restart=switch, exhausted=finished & ~jnp.any(available))

    return Selector(name, 1, init, assign, update, lambda s: {"terrains_finished": s.obs_count})
