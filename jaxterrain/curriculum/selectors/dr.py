"""``dr``: domain randomisation. Every chunk ``terrains_per_chunk`` terrains drawn uniformly from the bank (with
replacement), the trial's envs dealt round-robin over them and restarted; evaluated on the first. No terrain is ever
used up: the trial runs to ``max_epochs``."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxterrain.curriculum.selectors.protocol import Decision, Assignment, Selector, register_selector, round_robin
from jaxterrain.runtime.validation import int_at_least

__all__ = ["DRParams", "DRState", "dr_selector", "validate_dr"]


class DRParams(NamedTuple):
    """``dr``'s parameters. terrains_per_chunk: K terrains a chunk, the envs dealt round-robin over them, >= 1."""

    terrains_per_chunk: int = 8


class DRState(NamedTuple):
    """``dr``'s state. terrains: [K] int32 this chunk's terrains (uniform draws from the bank, with replacement).
    draws: [] int32 chunks drawn."""

    terrains: jax.Array
    draws: jax.Array


def dr_selector(config) -> Selector:
    """Domain randomisation of ``config`` (its ``params``: :class:`DRParams`, None for the defaults)."""
    p = config.params if config.params is not None else DRParams()
    k, e = int(p.terrains_per_chunk), int(config.ppo.num_envs)

    def draw(key, bank):
        return jax.random.randint(key, (k,), 0, bank.fitness.shape[0], dtype=jnp.int32)

    def init(key, bank):
        return DRState(terrains=draw(key, bank), draws=jnp.ones((), jnp.int32))

    def assign(s):
        return Assignment(terrains=s.terrains, env_slot=round_robin(e, k), evaluated=jnp.zeros((), jnp.int32))

    def update(s, key, bank, outcome):
        reached = outcome.fitness >= config.threshold * config.max_fitness
        new = DRState(terrains=draw(key, bank), draws=s.draws + 1)
        return new, Decision(finished=reached, restart=jnp.ones((), bool), exhausted=jnp.zeros((), bool))

    return Selector("dr", k, init, assign, update, lambda s: {"terrains_drawn": s.draws * k})


def validate_dr(config, p: DRParams) -> None:
    """``CurriculumConfig.params.terrains_per_chunk`` must be an integer >= 1."""
    int_at_least("CurriculumConfig.params", p, "terrains_per_chunk", 1)


register_selector("dr", dr_selector, DRParams, validate_dr, {"terrains_per_chunk": "terrains_per_chunk"})
