"""MAP-Elites as pure functions over a state pytree (paper section 3.3); callers ``jit`` / ``lax.scan`` / ``vmap``.

    >>> from jaxterrain.qd import map_elites as ME, scoring
    >>> score = scoring.make_scoring_fn(generator, descriptor_fn, traversable_fn, fitness_fn, config)
    >>> emitter = ME.Emitter(generator.sample, generator.mutate, batch_size=20, initial_population=100)
    >>> state, metrics = jax.jit(lambda k: ME.init(k, score, emitter, centroids))(key)
    >>> state, metrics = jax.jit(lambda s: ME.step(s, key, score, emitter))(state)       # one generation

The loop
--------
:func:`init` evaluates ``initial_population`` random genomes (``emitter.sample``) into an empty QDax
``MapElitesRepertoire`` over the given centroids. Every :func:`step` draws ``batch_size`` parents uniformly (with
replacement) from the filled cells, mutates them (``emitter.mutate``), scores them and inserts them with
:func:`insert`. When the archive is empty (every terrain so far rejected) the offspring are fresh random genomes.
No QDax emitter is used (``MixingEmitter`` reuses one key for two splits): selection and mutation are written here.

Insertion (:func:`insert`) picks EXACTLY ONE winner per cell before any write: among the batch's offspring in a
cell, the highest fitness, ties broken by the LOWEST offspring index; it enters only if strictly better than the
cell's elite and never when its fitness is NaN or ``-inf``; every leaf (genome leaves, fitness, cell descriptors,
raw descriptors) is then written from that one winner by one scatter of unique cell indices. (QDax 0.5.0's
``MapElitesRepertoire.add`` lets every offspring tied at a cell's best write into the cell, leaf by leaf, with
duplicate indices: stored genomes became mixtures of several offspring; see ``docs/results/insertion_bug.md``.)

Keys
----
The run has one key. Generation 0 (the initial population) uses ``fold_in(key, 0)``; the step that makes offspring
generation ``g >= 1`` uses ``fold_in(key, g - 1)`` (``state.generation`` before the step), each split into
selection / mutation / evaluation keys. (So offspring generation 1 reuses the initial population's keys, as the
archives made so far did; kept for the same seed giving the same archives.) Nothing else is random, so the state
after generation ``g`` depends only on ``(key, problem, g)``, not on how a run was chunked or resumed.

Several treatments
------------------
Everything per treatment is data in the state (the repertoire with its centroids, the scoring :class:`Task`: which
two descriptors, their ranges), so ``jax.vmap(step, in_axes=(0, 0, None, None))(states, keys, score, emitter)``
evolves several seeds and descriptor pairs of ONE generator at once, all with the same shapes. :func:`multi_step`
goes further: one generation of several generators' treatment batches whose offspring are scored by ONE fitness
call on the concatenated heightmaps (e.g. 5 generators x 3 pairs x 20 = 300 terrains), then split back.
"""

from __future__ import annotations

from typing import Callable, NamedTuple, Sequence

import jax
import jax.numpy as jnp

from jaxterrain.qd import scoring as S
from jaxterrain.runtime import sharding as SH

__all__ = ["Emitter", "MapElitesState", "METRIC_NAMES", "init", "step", "offspring", "finish", "insert", "metrics",
           "generation_keys", "empty_repertoire", "multi_step", "many_offspring", "many_scores", "many_finish"]

METRIC_NAMES = ("coverage", "qd_score", "max_fitness", "mean_fitness", "rejected", "out_of_range", "nan", "inserted")


class Emitter(NamedTuple):
    """How offspring are made (static; hashable when its functions are).

    Attributes:
      sample: ``(key, n) -> genomes`` (leaves ``[n, ...]``), random genomes.
      mutate: ``(key, genomes) -> genomes``, same structure and shapes.
      batch_size: offspring per generation (>= 1).
      initial_population: random genomes evaluated by :func:`init` (>= 1).
    """

    sample: Callable
    mutate: Callable
    batch_size: int
    initial_population: int


class MapElitesState(NamedTuple):
    """The state of one MAP-Elites run (a pytree; stack states along a leading axis to ``vmap`` treatments).

    Attributes:
      repertoire: QDax ``MapElitesRepertoire``: ``genotypes`` leaves ``[cells, ...]``, ``fitnesses`` [cells, 1]
        (``-inf`` = empty), ``descriptors`` [cells, 2] (cell descriptors, clipped into the ranges), ``centroids``
        [cells, 2], ``extra_scores["raw"]`` [cells, 2] (raw descriptors).
      generation: [] int32, offspring generations done (0 after :func:`init`).
      task: the :class:`jaxterrain.qd.scoring.Task` of this run (descriptor pair and ranges).
    """

    repertoire: object
    generation: jax.Array
    task: S.Task


def generation_keys(key, generation):
    """``fold_in(key, generation)`` split into (selection, mutation, evaluation) keys."""
    return jax.random.split(jax.random.fold_in(key, generation), 3)


def empty_repertoire(genome_example, centroids: jax.Array):
    """An empty ``MapElitesRepertoire`` over ``centroids`` [cells, 2] for genomes shaped like ``genome_example``
    (ONE genome, leaves without the batch axis)."""
    from qdax.core.containers.mapelites_repertoire import MapElitesRepertoire

    return MapElitesRepertoire.init_default(
        genotype=genome_example,
        centroids=centroids,
        one_extra_score={"raw": jnp.zeros((centroids.shape[-1],), jnp.float32)},
        keys_extra_scores=("raw",),
    )


def insert(repertoire, genomes, cell_descriptors: jax.Array, fitness: jax.Array, raw: jax.Array):
    """Insert a scored batch: exactly one winner per cell, every leaf from that winner.

    Args:
      repertoire: a ``MapElitesRepertoire`` with ``extra_scores["raw"]``.
      genomes: leaves ``[B, ...]``.
      cell_descriptors: [B, 2], the descriptors that choose the cell (nearest centroid, QDax's
        ``get_cells_indices``).
      fitness: [B]; NaN and ``-inf`` never enter.
      raw: [B, 2], raw descriptors stored in ``extra_scores["raw"]``.

    Returns:
      ``(repertoire, inserted)``: the new repertoire and the number of cells that took a new elite ([] float32).
    """
    from qdax.core.containers.mapelites_repertoire import get_cells_indices

    n_cells, dims = repertoire.centroids.shape
    batch = fitness.shape[0]
    for name, x in (("cell_descriptors", cell_descriptors), ("raw", raw)):
        if tuple(x.shape) != (batch, dims):
            raise ValueError(f"insert: {name} must have shape [B={batch}, {dims}]; got {tuple(x.shape)}")
    fitness = jnp.asarray(fitness, jnp.float32).reshape(-1)
    fitness = jnp.where(jnp.isnan(fitness), -jnp.inf, fitness)
    cells = get_cells_indices(cell_descriptors, repertoire.centroids).astype(jnp.int32)
    best = jax.ops.segment_max(fitness, cells, num_segments=n_cells)  # [cells]
    index = jnp.arange(batch, dtype=jnp.int32)
    candidate = (fitness == best[cells]) & (fitness > -jnp.inf)
    first = jax.ops.segment_min(jnp.where(candidate, index, batch), cells, num_segments=n_cells)  # batch: none
    wins = candidate & (first[cells] == index) & (fitness > repertoire.fitnesses[cells, 0])
    target = jnp.where(wins, cells, n_cells)  # unique cell indices for the winners; n_cells is dropped

    def put(old, new):
        return old.at[target].set(new.astype(old.dtype), mode="drop")

    new = repertoire.replace(
        genotypes=jax.tree.map(put, repertoire.genotypes, genomes),
        fitnesses=put(repertoire.fitnesses, fitness[:, None]),
        descriptors=put(repertoire.descriptors, cell_descriptors),
        extra_scores={**repertoire.extra_scores, "raw": put(repertoire.extra_scores["raw"], raw)},
    )
    return new, jnp.sum(wins).astype(jnp.float32)


def metrics(repertoire, counts: dict, inserted) -> dict:
    """Scalar metrics of a repertoire after a generation: coverage (percent), qd_score, max / mean fitness (NaN
    when empty), ``inserted`` and the scoring's counts (``rejected``, ``out_of_range``, ``nan``)."""
    fit = repertoire.fitnesses.reshape(-1)
    filled = fit > -jnp.inf
    n = jnp.sum(filled)
    safe = jnp.where(filled, fit, 0.0)
    return {
        "coverage": 100.0 * jnp.mean(filled.astype(jnp.float32)),
        "qd_score": jnp.sum(safe),
        "max_fitness": jnp.where(n > 0, jnp.max(fit), jnp.nan),
        "mean_fitness": jnp.where(n > 0, jnp.sum(safe) / jnp.maximum(n, 1), jnp.nan),
        "inserted": inserted,
        **{k: counts[k] for k in S.COUNTS},
    }


def _finish(state: MapElitesState, genomes, scored):
    fitness, cell, extras = scored
    repertoire, inserted = insert(state.repertoire, genomes, cell, fitness, extras["raw"])
    return repertoire, metrics(repertoire, extras, inserted)


def init(key, scoring: S.Scoring, emitter: Emitter, centroids: jax.Array, task: S.Task | None = None):
    """Generation 0: ``emitter.initial_population`` random genomes into an empty repertoire.

    Args:
      key: the run's key (generation 0 uses ``fold_in(key, 0)``).
      scoring: a :class:`jaxterrain.qd.scoring.Scoring`.
      emitter: an :class:`Emitter`.
      centroids: [cells, 2] grid centroids (``archive.centroids_for``).
      task: the run's :class:`~jaxterrain.qd.scoring.Task` (default ``scoring.task``).

    Returns:
      ``(state, metrics)``: a :class:`MapElitesState` at generation 0 and a dict of scalar metrics.
    """
    task = scoring.task if task is None else task
    sample_key, _, eval_key = generation_keys(key, 0)
    genomes = emitter.sample(sample_key, emitter.initial_population)
    repertoire = empty_repertoire(jax.tree.map(lambda x: x[0], genomes), centroids)
    state = MapElitesState(repertoire, jnp.zeros((), jnp.int32), task)
    repertoire, m = _finish(state, genomes, scoring(genomes, eval_key, task))
    return state._replace(repertoire=repertoire), m


def offspring(state: MapElitesState, key, emitter: Emitter):
    """Parents uniform over the filled cells, mutated; fresh random genomes while the archive is empty.
    Returns (offspring, evaluation key)."""
    select_key, mutate_key, eval_key = generation_keys(key, state.generation)
    repertoire = state.repertoire
    filled = repertoire.fitnesses.reshape(-1) > -jnp.inf
    any_filled = jnp.any(filled)
    p = jnp.where(any_filled, filled.astype(jnp.float32), 1.0)
    idx = jax.random.choice(select_key, filled.shape[0], (emitter.batch_size,), replace=True, p=p / jnp.sum(p))
    parents = jax.tree.map(lambda x: x[idx], repertoire.genotypes)
    offspring = jax.lax.cond(
        any_filled,
        lambda: emitter.mutate(mutate_key, parents),
        lambda: jax.tree.map(lambda f, q: f.astype(q.dtype), emitter.sample(select_key, emitter.batch_size), parents),
    )
    return offspring, eval_key


def step(state: MapElitesState, key, scoring: S.Scoring, emitter: Emitter):
    """One generation: select, mutate, score, insert. ``key`` is the run's key (see the module docstring).

    Returns:
      ``(state, metrics)`` with ``state.generation`` one higher and a dict of scalar metrics.
    """
    genomes, eval_key = offspring(state, key, emitter)
    return finish(state, genomes, scoring(genomes, eval_key, state.task))


def finish(state: MapElitesState, genomes, scored):
    """:func:`step`'s last part (pure): insert the scored ``genomes`` (``scored`` = the scoring's ``(fitness,
    cells, extras)``) and count a generation. ``step = finish(state, g, scoring(g, k, task))`` with ``(g, k) =
    offspring(state, key, emitter)``; the parts let a host loop call the scoring outside ``jit``."""
    repertoire, m = _finish(state, genomes, scored)
    return MapElitesState(repertoire, state.generation + 1, state.task), m


def multi_step(states: Sequence[MapElitesState], keys: Sequence[jax.Array], fitness_key, scorings: Sequence[S.Scoring],
               emitters: Sequence[Emitter], fitness_fn: Callable):
    """One generation of several treatment groups, with ONE fitness call on all their offspring.

    Group ``i`` is a batch of ``T_i`` treatments of one generator: ``states[i]`` has leaves ``[T_i, ...]``,
    ``keys[i]`` is ``[T_i]`` run keys, ``scorings[i]`` / ``emitters[i]`` its (static) scoring and emitter. Each
    treatment selects and mutates with its own key, exactly as :func:`step`; the ``sum_i T_i x batch_size_i``
    offspring heightmaps (all of one size) are concatenated and scored by ``fitness_fn(heightmaps, fitness_key,
    needed)`` once (the scorings' own fitness functions are not called), then split back for insertion. With a
    per-terrain deterministic fitness this equals one :func:`step` per treatment.

    When the scorings carry a ``mesh`` (all the same one), every group's offspring rows are split over its devices
    (each group padded to a multiple of the device count; the padding is never walked and is cut off before
    insertion): each device renders and describes its rows of every group and walks them in ONE keyed fitness
    call (:func:`jaxterrain.qd.scoring.keyed_fitness`) with the per-row keys ``split(fitness_key, total)`` (rows in
    group order), so the states do not depend on the number of devices.

    Returns:
      ``(states, metrics)``: a list of states (one per group, generation one higher) and a list of metric dicts
      whose values are ``[T_i]``.
    """
    if not (len(states) == len(keys) == len(scorings) == len(emitters)) or not states:
        raise ValueError("multi_step: states, keys, scorings and emitters must be non-empty sequences of one length; "
                         f"got {len(states)}, {len(keys)}, {len(scorings)}, {len(emitters)}")
    mesh = scorings[0].mesh
    if any(s.mesh != mesh for s in scorings):
        raise ValueError("multi_step: every scoring must carry the same mesh (or none)")
    children = many_offspring(states, keys, emitters)
    made, parts = many_scores(states, children, fitness_key, scorings, fitness_fn)
    return many_finish(states, children, made, parts)


def many_offspring(states, keys, emitters) -> list:
    """:func:`multi_step`'s first part (pure, jittable): every group's offspring ``[T_i, B_i, ...]``."""
    return [jax.vmap(lambda st, k, em=emitter: offspring(st, k, em))(state, keys_i)[0]
            for state, keys_i, emitter in zip(states, keys, emitters)]


def many_scores(states, children, fitness_key, scorings, fitness_fn) -> tuple[list, list]:
    """:func:`multi_step`'s scoring: ``(pendings, fitness)`` per group, ``[T_i, B_i]``. With the scorings' mesh
    the rows go over its devices (:func:`_sharded_scores`); called outside ``jit`` on a mesh whose split is
    ``"dispatch"`` (``sharding.default_split``: GPUs) each device runs its own program."""
    mesh = scorings[0].mesh
    if mesh is None:
        made = [jax.vmap(scoring.prepare)(offspring, state.task)
                for state, scoring, offspring in zip(states, scorings, children)]
        maps = jnp.concatenate([p.heightmaps.reshape((-1,) + p.heightmaps.shape[2:]) for p in made])
        needed = jnp.concatenate([p.needed.reshape(-1) for p in made])
        fitness = S._call_fitness(fitness_fn, maps, fitness_key, needed)
        fitness = jnp.asarray(fitness, jnp.float32).reshape(-1)
        parts, start = [], 0
        for p in made:
            t, b = p.needed.shape
            parts.append(fitness[start:start + t * b].reshape(t, b))
            start += t * b
    else:
        made, parts = _sharded_scores(children, [s.task for s in states], fitness_key, scorings, fitness_fn, mesh)
    return made, parts


def many_finish(states, children, made, parts):
    """:func:`multi_step`'s last part (pure, jittable): complete the scores, insert, count a generation."""
    out_states, out_metrics = [], []
    for state, offspring, pending, part in zip(states, children, made, parts):
        def finish_one(st, genomes, pend, fit):
            scored = S.Scoring.complete(pend, fit, st.task)
            repertoire, m = _finish(st, genomes, scored)
            return MapElitesState(repertoire, st.generation + 1, st.task), m

        new_state, m = jax.vmap(finish_one)(state, offspring, pending, part)
        out_states.append(new_state)
        out_metrics.append(m)
    return out_states, out_metrics


def _sharded_scores(children, tasks, fitness_key, scorings, fitness_fn, mesh):
    """:func:`multi_step`'s scoring over a mesh: ``(pendings, fitness)`` per group, shaped ``[T_i, B_i]`` (the
    pendings without heightmaps, which stay on their devices)."""

    rows, shapes = [], []
    for offspring, task in zip(children, tasks):
        t, b = task.pair.shape[0], jax.tree.leaves(offspring)[0].shape[1]
        flat = jax.tree.map(lambda x, t=t, b=b: x.reshape((t * b,) + x.shape[2:]), offspring)
        rows.append((flat, jax.tree.map(lambda x, b=b: jnp.repeat(x, b, axis=0), task)))
        shapes.append((t, b))
    counts = [t * b for t, b in shapes]
    keys = SH.row_keys(fitness_key, sum(counts))
    groups, start = [], 0
    for (flat, task), n in zip(rows, counts):
        length = SH.padded_length(n, mesh)
        groups.append(SH.pad_rows((flat, task, keys[start:start + n]), length) + (jnp.arange(length) < n,))
        start += n
    keyed = S.keyed_fitness(fitness_fn)

    def local(groups):
        pendings = [scoring.prepare(g, task) for scoring, (g, task, _, _) in zip(scorings, groups)]
        needed = [p.needed & g[3] for p, g in zip(pendings, groups)]
        maps = jnp.concatenate([p.heightmaps for p in pendings])
        fitness = jnp.asarray(keyed(maps, jnp.concatenate([g[2] for g in groups]), jnp.concatenate(needed)),
                              jnp.float32)
        out, begin = [], 0
        for p, nd in zip(pendings, needed):
            out.append((p._replace(heightmaps=None, needed=nd), fitness[begin:begin + nd.shape[0]]))
            begin += nd.shape[0]
        return out

    scored = SH.split_rows(local, mesh, scorings[0].split)(groups)
    made, parts = [], []
    for (pending, fitness), (t, b) in zip(scored, shapes):
        made.append(jax.tree.map(lambda x, t=t, b=b: x[:t * b].reshape((t, b) + x.shape[1:]), pending))
        parts.append(fitness[:t * b].reshape(t, b))
    return made, parts
