"""Scoring of terrain genomes for MAP-Elites, in QDax's contract ``(genomes, key) -> (fitness, descriptors, extras)``.

    >>> from jaxterrain.qd import scoring
    >>> score = scoring.make_scoring_fn(generator, descriptor_fn, traversable_fn, fitness_fn, config)
    >>> fitness, cells, extras = score(genomes, key)     # [B], [B, 2], {"raw": [B, 2], "rejected": [], ...}

One batch of genomes is rendered (``lax.map`` over chunks of :data:`RENDER_CHUNK` terrains), described
(``descriptor_fn``: ``heightmaps [B, H, W] -> [B, D]``; a :class:`Task` picks the two grid descriptors out of the
``D``), checked by Algorithm 1 (``traversable_fn``: ``[B, H, W] -> [B] bool``) and scored by the fitness function.
The fitness for insertion is ``-inf`` (never inserted) when

* the terrain fails Algorithm 1 (counted in ``extras["rejected"]``);
* its fitness is NaN (counted in ``extras["nan"]``, among the terrains that passed the other checks);
* a descriptor is out of range and the task rejects those (counted in ``extras["out_of_range"]`` either way).

Fitness contract
----------------
A fitness function is ``fitness_fn(heightmaps [B, H, W] float32 in [0, 1], key, needed [B] bool) -> [B]``
(higher = easier; traceable). ``needed`` marks the terrains that can enter the archive (Algorithm 1 passed,
descriptors usable, in range when out-of-range terrains are rejected); the fitness of the others is never used, so a
fitness function may skip them (the walker's rollout pool never starts their rollouts). Wrap a function of
``(heightmaps, key)`` with :func:`ignore_needed`. The physical scale (metres per heightmap unit and per pixel) is
the caller's: build Algorithm 1 and the walker fitness from ONE ``TerrainScale`` (``qd.EvolveConfig.scale``).

Over several devices
--------------------
A :class:`Scoring` with a ``mesh`` (``make_scoring_fn(..., mesh=sharding.make_mesh())``) splits the batch's rows
over the mesh's devices: each device renders, describes, checks and walks its own rows (one ``shard_map``), and
only the per-row results (fitness, descriptors, verdicts) come back whole. The fitness is then called in its
keyed form, ``(heightmaps [B, H, W], keys [B], needed [B] bool) -> [B]``, with ``keys = split(key, B)`` drawn for
the whole batch first, so that row ``i`` is scored with the same key on 1 or N devices (:func:`keyed_fitness`:
the function's own ``keyed`` attribute when it has one, as ``difficulty.fitness_fn``'s walker fitness does, else
:func:`keyed_rows`). A batch that does not divide over the devices is PADDED with copies of its last row; the
padding is never walked (``needed`` False) and is cut off before the counts and the insertion, so it never enters.
The device count then changes results only through float rounding: XLA compiles another program per local batch
size and may round a reduction differently (on CPU, a map's mean over [4, 32, 32] differs in the last bit from the
same maps one at a time), which can change a tie in a cell or, through the walker's chaotic dynamics, a walk.
Functions whose compiled code does not depend on the batch size (the tests' fakes) give the same archive on 1 and
N devices bit for bit. Without a mesh the fitness gets the batch's one key, as before.
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp

from jaxterrain.generators.mixed import is_mixture
from jaxterrain.runtime import sharding

__all__ = ["RENDER_CHUNK", "Task", "Pending", "Scoring", "make_scoring_fn", "ignore_needed", "render_batch",
           "task_for", "count_names", "keyed_rows", "keyed_fitness"]

RENDER_CHUNK = 1024
"""Terrains rendered at once (``lax.map`` over chunks of ``vmap``): bounds the generators' temporaries (the GAN at
batch 4 096 asks XLA for ~139 GiB) at larger GPU batches; below it, it is one ``vmap``."""

COUNTS = ("rejected", "out_of_range", "nan")


def count_names() -> tuple[str, ...]:
    """Names of the scalar counts in a scoring's ``extras`` (besides ``"raw"``)."""
    return COUNTS


class Task(NamedTuple):
    """Per-treatment data of a scoring (a pytree: batch its leaves to ``vmap`` several treatments).

    Attributes:
      pair: [2] int32, indices of the grid's two descriptors in the descriptor function's output ``[B, D]``.
      lo, hi: [2] float32, the grid range of each of the two descriptors.
      reject: [] bool, True: out-of-range terrains never enter; False: they are clipped into the edge cells.
    """

    pair: jax.Array
    lo: jax.Array
    hi: jax.Array
    reject: jax.Array


def task_for(config, pair=(0, 1)) -> Task:
    """The :class:`Task` of a resolved ``qd.EvolveConfig`` (its ``ranges`` and ``out_of_range``); ``pair``:
    indices of its two descriptors in the descriptor function's output (``(0, 1)`` when that output is the pair)."""
    if config.ranges is None:
        raise ValueError("task_for: config.ranges is None; resolve the config first (archive.resolve_config)")
    return Task(
        pair=jnp.asarray(pair, jnp.int32),
        lo=jnp.asarray([r[0] for r in config.ranges], jnp.float32),
        hi=jnp.asarray([r[1] for r in config.ranges], jnp.float32),
        reject=jnp.asarray(config.out_of_range == "reject"),
    )


class Pending(NamedTuple):
    """A batch rendered and described, waiting for its fitness (shapes for a batch of ``B`` terrains).

    Attributes:
      heightmaps: [B, H, W] float32 in [0, 1].
      raw: [B, 2] float32, the two grid descriptors (unclipped).
      traversable: [B] bool, Algorithm 1's verdict.
      outside: [B] bool, a descriptor out of range or not finite.
      needed: [B] bool, the terrains that can enter the archive (their fitness matters).
    """

    heightmaps: jax.Array
    raw: jax.Array
    traversable: jax.Array
    outside: jax.Array
    needed: jax.Array


def render_batch(render_one: Callable, genomes) -> jax.Array:
    """``genomes`` (leaves ``[B, ...]``) -> ``[B, H, W]``, rendered in ``lax.map`` chunks of :data:`RENDER_CHUNK`."""
    return jax.lax.map(render_one, genomes, batch_size=RENDER_CHUNK)


def ignore_needed(fitness_fn: Callable[[jax.Array, Any], jax.Array]) -> Callable:
    """Adapt ``fitness_fn(heightmaps, key) -> [B]`` to the contract ``(heightmaps, key, needed) -> [B]``: the
    ``needed`` hint is dropped and every terrain is scored (the result is the same; only the speed-up is lost)."""

    def fitness(heightmaps, key, needed):
        del needed
        return fitness_fn(heightmaps, key)

    fitness.__wrapped__ = fitness_fn
    return fitness


def keyed_rows(fitness_fn: Callable) -> Callable:
    """The keyed form of a fitness function: ``(heightmaps [B, H, W], keys [B], needed [B] bool) -> [B]`` float32,
    where row ``i`` is scored ALONE with its own key (``fitness_fn(heightmaps[i:i+1], keys[i], needed[i:i+1])``,
    a ``vmap`` of batch-1 calls), so a row's fitness does not depend on which rows share its call or its device."""

    def keyed(heightmaps, keys, needed):
        def one(h, k, n):
            return jnp.asarray(_call_fitness(fitness_fn, h[None], k, n[None]), jnp.float32).reshape(())

        return jax.vmap(one)(heightmaps, keys, jnp.asarray(needed, bool))

    keyed.__wrapped__ = fitness_fn
    return keyed


def keyed_fitness(fitness_fn: Callable) -> Callable:
    """``fitness_fn.keyed`` when the function carries its own keyed form (``(heightmaps, keys [B], needed) -> [B]``,
    e.g. the walker fitness of ``difficulty.fitness_fn``: one rollout pool per device), else :func:`keyed_rows`."""
    keyed = getattr(fitness_fn, "keyed", None)
    return keyed if callable(keyed) else keyed_rows(fitness_fn)


def _call_fitness(fitness_fn, heightmaps, key, needed):
    try:
        return fitness_fn(heightmaps, key, needed)
    except TypeError as err:
        if "positional argument" not in str(err):
            raise
        raise TypeError(
            f"fitness_fn must take (heightmaps [B, H, W], key, needed [B] bool) -> [B]; wrap a function of "
            f"(heightmaps, key) with jaxterrain.qd.scoring.ignore_needed(fn) ({err})"
        ) from err


class Scoring(NamedTuple):
    """A scoring function in QDax's contract, with its stages exposed (build it with :func:`make_scoring_fn`).

    ``scoring(genomes, key, task=None) -> (fitness [B], cell_descriptors [B, 2], extras)``: ``extras`` holds
    ``"raw"`` ([B, 2] unclipped descriptors) and the scalar counts ``"rejected"``, ``"out_of_range"``, ``"nan"``
    (float32). ``task`` defaults to :attr:`task`. Stages: :meth:`prepare` (render, describe, Algorithm 1, the range
    check) and :meth:`complete` (fitness -> insertion values), so several batches can share one fitness call. With
    a ``mesh`` the rows are split over its devices and scored with per-row keys (module docstring).

    Attributes:
      render_one: ``genome -> [H, W]`` heightmap in [0, 1].
      descriptor_fn: ``[B, H, W] -> [B, D]``.
      traversable_fn: ``[B, H, W] -> [B] bool`` (Algorithm 1).
      fitness_fn: ``(heightmaps [B, H, W], key, needed [B] bool) -> [B]``.
      task: the default :class:`Task`.
      mesh: None (one device), or a ``jax.sharding.Mesh`` (``sharding.make_mesh``) to split the rows over.
      split: how the rows go over the mesh (``sharding.map_rows``: ``"shard_map"`` or ``"dispatch"``; None:
        ``sharding.default_split``).
      batch_render: None (render with :func:`render_batch` of ``render_one``), or ``genomes [B, ...] -> [B, H, W]``
        (a mixture of generators: each row once by its own generator, ``generators.mixture``).
    """

    render_one: Callable
    descriptor_fn: Callable
    traversable_fn: Callable
    fitness_fn: Callable
    task: Task
    mesh: Any = None
    split: str | None = None
    batch_render: Callable | None = None

    def prepare(self, genomes, task: Task | None = None) -> Pending:
        """Render, describe and check a batch (genome leaves ``[B, ...]``); ``task``: one :class:`Task`, or one per
        row (leaves with a leading ``[B]``)."""
        task = self.task if task is None else task
        heightmaps = (render_batch(self.render_one, genomes) if self.batch_render is None
                      else self.batch_render(genomes))
        every = jnp.asarray(self.descriptor_fn(heightmaps), jnp.float32)
        raw = jnp.take_along_axis(every, jnp.broadcast_to(task.pair, every.shape[:-1] + (2,)), axis=-1)
        traversable = jnp.asarray(self.traversable_fn(heightmaps), bool)
        finite = jnp.all(jnp.isfinite(raw), axis=-1)
        outside = jnp.any((raw < task.lo) | (raw > task.hi), axis=-1) | ~finite
        needed = traversable & finite & ~(task.reject & outside)
        return Pending(heightmaps, raw, traversable, outside, needed)

    @staticmethod
    def complete(pending: Pending, fitness: jax.Array, task: Task):
        """``(pending, fitness [B]) -> (fitness for insertion [B], cell descriptors [B, 2], extras)``."""
        fitness = jnp.asarray(fitness, jnp.float32).reshape(-1)
        nan = jnp.isnan(fitness) & pending.needed  # the others' fitness was not needed
        keep = pending.needed & ~nan
        insert_fitness = jnp.where(keep, fitness, -jnp.inf)
        raw = pending.raw
        cell = jnp.clip(jnp.where(jnp.isfinite(raw), raw, task.lo), task.lo, task.hi)
        extras = {
            "raw": raw,
            "rejected": jnp.sum(~pending.traversable).astype(jnp.float32),
            "out_of_range": jnp.sum(pending.outside).astype(jnp.float32),
            "nan": jnp.sum(nan).astype(jnp.float32),
        }
        return insert_fitness, cell, extras

    def prepare_rows(self, genomes, keys, task: Task, mask) -> tuple[Pending, jax.Array]:
        """One device's share of a sharded batch: :meth:`prepare`, then the keyed fitness (:func:`keyed_fitness`)
        of the rows that are ``needed`` and real (``mask`` [b] bool, False on padding). Returns the
        :class:`Pending` without its heightmaps (they stay on the device) and the fitness [b]."""
        pending = self.prepare(genomes, task)
        needed = pending.needed & mask
        fitness = keyed_fitness(self.fitness_fn)(pending.heightmaps, keys, needed)
        return pending._replace(heightmaps=None, needed=needed), jnp.asarray(fitness, jnp.float32)

    def __call__(self, genomes, key, task: Task | None = None):
        task = self.task if task is None else task
        if self.mesh is not None:
            n = jax.tree.leaves(genomes)[0].shape[0]
            pending, fitness = sharding.map_rows(self.prepare_rows, self.mesh, replicated=(2,), mask=True, split=self.split)(
                genomes, sharding.row_keys(key, n), task)
            return self.complete(pending, fitness, task)
        pending = self.prepare(genomes, task)
        fitness = _call_fitness(self.fitness_fn, pending.heightmaps, key, pending.needed)
        return self.complete(pending, fitness, task)


def make_scoring_fn(generator, descriptor_fn: Callable, traversable_fn: Callable, fitness_fn: Callable,
                    config, pair=(0, 1), mesh=None, split: str | None = None) -> Scoring:
    """The scoring function of one generator (see the module docstring).

    Args:
      generator: a ``Generator`` (its ``render_one``: genome -> ``[H, W]`` in [0, 1]; a ``generators.mixture``
        renders its batches with its grouped render).
      descriptor_fn: ``heightmaps [B, H, W] -> [B, D]`` descriptors (``D >= 2``).
      traversable_fn: ``heightmaps [B, H, W] -> [B] bool`` (Algorithm 1, built with the run's ``TerrainScale``).
      fitness_fn: ``(heightmaps [B, H, W], key, needed [B] bool) -> [B]`` (built with the same scale); see
        :func:`ignore_needed`.
      config: a resolved ``qd.EvolveConfig`` (``ranges``, ``out_of_range``).
      pair: indices of the grid's two descriptors in ``descriptor_fn``'s output.
      mesh: None, or a ``jax.sharding.Mesh`` whose devices split every batch's rows (see "Over several devices").

    Returns:
      a :class:`Scoring`, callable as ``(genomes, key) -> (fitness [B], cell descriptors [B, 2], extras)``.
    """
    for name, fn in (("descriptor_fn", descriptor_fn), ("traversable_fn", traversable_fn),
                     ("fitness_fn", fitness_fn)):
        if not callable(fn):
            raise ValueError(f"make_scoring_fn: {name} must be callable; got {type(fn).__name__}")
    batch_render = generator.spec.render_batch if is_mixture(generator) else None
    return Scoring(generator.render_one, descriptor_fn, traversable_fn, fitness_fn, task_for(config, pair), mesh, split,
                   batch_render)
