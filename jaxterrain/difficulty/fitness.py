"""The one table of named fitness functions (``--fitness NAME`` of every command that scores terrains).

A fitness is a traceable ``(heightmaps [B, H, W] in [0, 1], key, needed [B] bool = None) -> [B] float32``, higher
is easier. ``"difficulty"`` is the walker's (the shipped base policy's walks under a :class:`Protocol`,
:func:`jaxterrain.difficulty.fitness_fn`); ``"slope"`` is a cheap stand-in for smoke runs, tests and benchmarks.
:data:`PROTOCOLS` names the walking protocols (``--protocol paper|headings``).
"""

from __future__ import annotations

from typing import Callable, Optional

import jax.numpy as jnp

from jaxterrain.difficulty.evaluation import fitness_fn, smoothness_priority
from jaxterrain.difficulty.protocol import HEADINGS, PAPER, Protocol
from jaxterrain.terrain import TerrainScale

__all__ = ["FITNESSES", "PROTOCOLS", "slope_fitness", "difficulty_fitness", "named_fitness"]

PROTOCOLS: dict[str, Protocol] = {"paper": PAPER, "headings": HEADINGS}
"""``--protocol`` names: :data:`PAPER` (20 walks along +x, best 5) and :data:`HEADINGS` (20 walks in each of 4
headings, best 5 per heading, mean over headings)."""


def slope_fitness(heightmaps, key=None, needed=None):
    """Cheap stand-in fitness for smoke runs, tests and benchmarks: ``1 - mean slope`` in [0, 1].

    ``heightmaps [B, H, W]`` in [0, 1] are scaled to metres with the default ``TerrainScale``; the slope of a pixel is
    ``(|dz/dx| + |dz/dy|) / 2`` (rise over run), clipped to 1. Returns ``[B]`` float32. ``key`` and ``needed`` are
    not used (every terrain is scored), so it fits both ``(heightmaps, key)`` and ``qd.evolve``'s
    ``(heightmaps, key, needed)``.
    """
    scale = TerrainScale()
    h = jnp.asarray(heightmaps, jnp.float32) * (scale.height / scale.cell_size)
    # smoothness_priority = -(mean |dz/dx| + mean |dz/dy|) of the map in metres per pixel: minus twice the slope
    return 1.0 - jnp.clip(-smoothness_priority(h) / 2.0, 0.0, 1.0)


FITNESSES: dict[str, Optional[Callable]] = {"difficulty": None, "slope": slope_fitness}
"""Fitness names -> functions; None is the walker's fitness, which needs a size and a protocol
(:func:`named_fitness`, :func:`difficulty_fitness`; ``qd.evolve`` builds it from its config)."""


def difficulty_fitness(size: int, attempts: int = 20, best: int = 5, scale: Optional[TerrainScale] = None,
                       slots: int | None = None, smooth_first: bool = True, backend: str = "jax",
                       headings: int = 1, robot: str = "humanoid", observation: str = "blind",
                       spawn: str = "feet") -> Callable:
    """The walker's fitness as a pure ``(heightmaps [B, size, size], key, needed [B] bool) -> [B]``:
    ``fitness_fn(size, Protocol(attempts, best, headings), scale, slots, smooth_first, backend)`` (the shipped base
    policy, ``attempts`` rollouts per terrain, mean of the ``best`` distances per heading, mean over ``headings``;
    cached there per argument values). ``slots``: env slots of a rollout pool (None = all at once; terrains not
    ``needed`` are never walked); ``smooth_first``: the pool starts the smoothest terrains' rollouts first (speed
    only); ``backend``: the walker's physics, ``"jax"`` or ``"warp"`` (MuJoCo Warp on terrain tiles); ``robot``:
    whose shipped base policy walks (default the humanoid's); ``observation``: its blind or perceptive twin;
    ``spawn``: how each walker is set down at a reset (``walker.SPAWNS``: ``feet``, the walker's default, or
    ``patch``)."""
    return fitness_fn(int(size), Protocol(attempts, best, headings), scale, slots, smooth_first, backend, robot,
                      observation, spawn)


def named_fitness(name: str, attempts: int, best: int, size: int, slots: int | None = None) -> Callable:
    """``--fitness NAME`` as a traceable ``(heightmaps [B, size, size], key, needed=None) -> [B]``: the function of
    :data:`FITNESSES`, or for ``"difficulty"`` ``fitness_fn(size, Protocol(attempts, best), slots=slots)``.
    ValueError naming ``fitness`` for an unknown name."""
    if name not in FITNESSES:
        raise ValueError(f"fitness: unknown fitness {name!r}; choose from {', '.join(FITNESSES)}")
    fn = FITNESSES[name]
    if fn is not None:
        return fn
    return fitness_fn(int(size), Protocol(int(attempts), int(best)), slots=slots)
