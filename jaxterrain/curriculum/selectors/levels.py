"""``levels``: legged_gym's terrain curriculum over bands of the bank. Level l is the l-th of ``levels`` bands of
equal size of the bank ordered by hardness (:func:`level_bands`; legged_gym's levels are columns of a terrain grid
made at increasing difficulty), level 0 the easiest; each chunk level l's terrain is drawn uniformly from band l.
Each env moves up when it walked far (``progress >= promote``, default ``threshold``: it crossed the terrain, where
legged_gym asks for more than half its 8 m tile from the tile's centre, i.e. to the tile's edge), down when it
walked less than ``demote`` (0.5) of the course, and past the top it goes to a random level (:func:`levels_rule`).
Envs start at random levels ``0 .. init`` (default ``levels // 2``: legged_gym's ``max_init_terrain_level = 5`` of
10). Levels move at chunk boundaries, not at each env's reset as in legged_gym. The trial is evaluated on the
terrain of the highest level an env stands on."""

from __future__ import annotations

from typing import NamedTuple, Optional

import jax
import jax.numpy as jnp

from jaxterrain.curriculum.selectors.base import float_in, terrain_hardness
from jaxterrain.curriculum.selectors.protocol import Assignment, Decision, Selector, register_selector
from jaxterrain.runtime.validation import int_at_least

__all__ = ["LevelsParams", "LevelsState", "levels_selector", "level_bands", "levels_rule", "validate_levels",
           "FLAT"]

OWNER = "CurriculumConfig.params"


class LevelsParams(NamedTuple):
    """``levels``' parameters. levels: difficulty levels (bands of the bank by hardness; legged_gym: 10), >= 1.
    init: envs start at random levels ``0 .. init``, in [0, levels - 1]; None = ``levels // 2`` (legged_gym: 5 of
    10). promote: an env moves up a level when its furthest normalised distance in the chunk is at least this, in
    (0, 1]; None = ``threshold x max_fitness``. demote: ... and down when it is below this (legged_gym: half the
    course), in [0, 1]."""

    levels: int = 10
    init: Optional[int] = None
    promote: Optional[float] = None
    demote: float = 0.5


FLAT = {"levels": "levels", "levels_init": "init", "levels_promote": "promote", "levels_demote": "demote"}
"""``learn``'s config keys (and flags) of :class:`LevelsParams`."""


class LevelsState(NamedTuple):
    """``levels``' state. level: [E] int32 each env's level (0 = easiest). terrains: [L] int32 this chunk's terrain
    of each level (drawn from its band). moves: [] int32 level changes so far (up or down, over all envs)."""

    level: jax.Array
    terrains: jax.Array
    moves: jax.Array


def level_bands(hardness: jax.Array, levels: int) -> tuple[jax.Array, jax.Array]:
    """``(order [N] int32, start [L + 1] int32)``: the terrains sorted by ``hardness`` (stable: ties by index) and
    band l = ``order[start[l]:start[l + 1]]``, L bands of equal size (``floor(l N / L)``; every band has at least
    one terrain when N >= L, else bands repeat terrains: band l = ``order[floor(l N / L)]``)."""
    n = hardness.shape[0]
    order = jnp.argsort(hardness, stable=True).astype(jnp.int32)
    start = (jnp.arange(levels + 1, dtype=jnp.int32) * n) // levels
    return order, start


def _draw_levels(key, bank, levels: int, origin: str) -> jax.Array:
    """``[L]`` int32: one terrain of each level's band, uniform within the band."""
    order, start = level_bands(terrain_hardness(bank, origin), levels)
    lo, hi = start[:-1], jnp.maximum(start[1:], start[:-1] + 1)
    pos = lo + jnp.floor(jax.random.uniform(key, (levels,)) * (hi - lo)).astype(jnp.int32)
    return order[jnp.minimum(pos, order.shape[0] - 1)]


def levels_rule(level, progress, key, levels: int, promote: float, demote: float) -> jax.Array:
    """legged_gym's ``_update_terrain_curriculum`` over ``level`` [E] int32 with ``progress`` [E] float32: up one
    where ``progress >= promote``, down one where ``progress < demote`` (not both: up wins), clipped at 0, and an env
    moved past the top (``level >= levels``) to ``randint(key, 0, levels)``."""
    up = progress >= promote
    down = ~up & (progress < demote)
    moved = level + up.astype(jnp.int32) - down.astype(jnp.int32)
    top = jax.random.randint(key, level.shape, 0, levels, dtype=jnp.int32)
    return jnp.where(moved >= levels, top, jnp.maximum(moved, 0))


def levels_selector(config) -> Selector:
    """legged_gym's terrain levels of ``config`` (its ``params``: :class:`LevelsParams`, None for the defaults)."""
    p = config.params if config.params is not None else LevelsParams()
    levels, e = int(p.levels), int(config.ppo.num_envs)
    promote = float(config.threshold * config.max_fitness if p.promote is None else p.promote)
    demote = float(p.demote)

    def init(key, bank):
        level_key, draw_key = jax.random.split(key)
        top = levels // 2 if p.init is None else int(p.init)
        level = jax.random.randint(level_key, (e,), 0, top + 1, dtype=jnp.int32)
        return LevelsState(level=level, terrains=_draw_levels(draw_key, bank, levels, config.distance_origin),
                           moves=jnp.zeros((), jnp.int32))

    def assign(s):
        return Assignment(terrains=s.terrains, env_slot=s.level, evaluated=jnp.max(s.level))

    def update(s, key, bank, outcome):
        rule_key, draw_key = jax.random.split(key)
        level = levels_rule(s.level, outcome.progress, rule_key, levels, promote, demote)
        reached = outcome.fitness >= config.threshold * config.max_fitness
        new = LevelsState(level=level, terrains=_draw_levels(draw_key, bank, levels, config.distance_origin),
                          moves=s.moves + jnp.sum(level != s.level).astype(jnp.int32))
        return new, Decision(finished=reached, restart=jnp.ones((), bool), exhausted=jnp.zeros((), bool))

    def summary(s):
        return {"mean_level": jnp.mean(s.level.astype(jnp.float32)), "max_level": jnp.max(s.level),
                "level_moves": s.moves}

    return Selector("levels", levels, init, assign, update, summary, progress=True)


def validate_levels(config, p: LevelsParams) -> None:
    """``ValueError`` naming the first bad field of :class:`LevelsParams` (``CurriculumConfig.params.<field>``)."""
    int_at_least(OWNER, p, "levels", 1)
    if p.init is not None:
        int_at_least(OWNER, p, "init", 0)
        if p.init > p.levels - 1:
            raise ValueError(f"{OWNER}.init must be in [0, levels - 1 = {p.levels - 1}], got {p.init!r}")
    if p.promote is not None:
        float_in(OWNER, p, "promote", 0.0, 1.0, lo_open=True)
    float_in(OWNER, p, "demote", 0.0, 1.0, lo_open=False)


register_selector("levels", levels_selector, LevelsParams, validate_levels, FLAT)
