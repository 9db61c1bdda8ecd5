"""The compiled programs of the MAP-Elites drivers (:mod:`jaxterrain.qd.evolution`): one treatment's ``init`` and
``chunk`` (:func:`programs`) and several treatments' chunk (:func:`many_program`), each a jitted ``lax.scan`` over
generations; on a mesh whose split is ``"dispatch"`` (GPUs: ``sharding.default_split``) a host loop of jitted parts
around the scoring instead (:func:`host_programs`, :func:`many_host_chunk`). Cached only in a dict the caller owns
(``compile_cache``): nothing is cached behind its back."""

from __future__ import annotations

import functools
from typing import Callable

import jax
import jax.numpy as jnp

from jaxterrain.qd import map_elites as ME, scoring as S
from jaxterrain.runtime import sharding

__all__ = ["compiled", "replicated", "programs", "dispatching", "host_programs", "host_loop", "many_program",
           "many_chunk", "many_host_chunk"]


def compiled(cache: dict | None, key, build):
    if cache is None:
        return build()
    if key not in cache:
        cache[key] = build()
    return cache[key]


def replicated(mesh) -> dict:
    """``jax.jit`` options that leave every output whole on every device of ``mesh`` (none without a mesh)."""
    if mesh is None:
        return {}

    return {"out_shardings": sharding.replicated(mesh)}


def programs(scoring: S.Scoring, emitter: ME.Emitter, cache: dict | None):
    """Jitted ``init(key, centroids, task)`` and ``chunk(state, key, n) -> (state, metrics [n])``; with a mesh
    their outputs (the repertoire, the metrics) are replicated on its devices."""
    fns = (scoring.render_one, scoring.descriptor_fn, scoring.traversable_fn, scoring.fitness_fn, emitter,
           scoring.mesh, scoring.split)
    if dispatching(scoring.mesh, scoring.split):
        return compiled(cache, ("host",) + fns, lambda: host_programs(scoring, emitter))
    out = replicated(scoring.mesh)

    def build_init():
        return jax.jit(lambda key, centroids, task: ME.init(key, scoring, emitter, centroids, task), **out)

    def build_chunk():
        def chunk(state, key, n):
            return jax.lax.scan(lambda s, _: ME.step(s, key, scoring, emitter), state, None, length=n)

        return jax.jit(chunk, static_argnums=2, **out)

    return compiled(cache, ("init",) + fns, build_init), compiled(cache, ("chunk",) + fns, build_chunk)


def dispatching(mesh, split: str | None = None) -> bool:
    """Whether ``mesh`` splits rows by dispatching one program per device (``sharding.default_split``: GPUs), which
    a ``jit``-compiled chunk cannot do: the chunk is then a host loop over generations (:func:`host_programs`)."""
    if mesh is None:
        return False

    return (sharding.default_split(mesh) if split is None else split) == "dispatch"


def host_programs(scoring: S.Scoring, emitter: ME.Emitter):
    """:func:`programs` on a dispatching mesh: ``init`` and ``chunk`` as host loops of jitted parts (offspring,
    finish) around the scoring, whose rows go to every device from the host (``sharding.map_rows``)."""
    make = jax.jit(lambda key, n: emitter.sample(key, n), static_argnums=1)
    empty = jax.jit(ME.empty_repertoire)
    children = jax.jit(lambda state, key: ME.offspring(state, key, emitter))
    finish = jax.jit(ME.finish)

    def init(key, centroids, task):
        sample_key, _, eval_key = ME.generation_keys(key, 0)
        genomes = make(sample_key, emitter.initial_population)
        repertoire = empty(jax.tree.map(lambda x: x[0], genomes), centroids)
        state = ME.MapElitesState(repertoire, jnp.zeros((), jnp.int32), task)
        new, m = finish(state, genomes, scoring(genomes, eval_key, task))
        return state._replace(repertoire=new.repertoire), m

    def generation(state, key):
        genomes, eval_key = children(state, key)
        return finish(state, genomes, scoring(genomes, eval_key, state.task))

    return init, functools.partial(host_loop, generation)


def host_loop(generation: Callable, state, key, n: int):
    """``n`` calls of ``state, metrics = generation(state, key)`` from the host; the metrics stacked ``[n, ...]``
    (what a ``lax.scan`` of them returns)."""
    history = []
    for _ in range(n):
        state, m = generation(state, key)
        history.append(m)
    return state, jax.tree.map(lambda *xs: jnp.stack(xs), *history)


def many_chunk(scorings, emitters, fitness, mesh=None):
    if dispatching(mesh, scorings[0].split):
        return many_host_chunk(scorings, emitters, fitness)

    def chunk(states, keys, key, n):
        def body(st, _):
            fitness_key = jax.random.fold_in(key, st[0].generation[0])
            return ME.multi_step(st, keys, fitness_key, scorings, emitters, fitness)

        return jax.lax.scan(body, states, None, length=n)

    return jax.jit(chunk, static_argnums=3, **replicated(mesh))


def many_host_chunk(scorings, emitters, fitness):
    """:func:`many_chunk` on a dispatching mesh: a host loop over generations of the jitted offspring and finish
    parts of ``map_elites.multi_step`` around its scoring, whose rows go to every device from the host."""
    children = jax.jit(lambda states, keys: ME.many_offspring(states, keys, emitters))
    finish = jax.jit(ME.many_finish)

    def generation(states, run):
        keys, key = run
        kids = children(states, keys)
        fitness_key = jax.random.fold_in(key, states[0].generation[0])
        return finish(states, kids, *ME.many_scores(states, kids, fitness_key, scorings, fitness))

    return lambda states, keys, key, n: host_loop(generation, states, (keys, key), n)


def many_program(scorings, emitters, fitness, mesh, cache: dict | None):
    """The jitted chunk of :func:`evolve_many` (:func:`many_chunk`), kept in ``cache`` under what determines it."""
    fns = tuple((s.render_one, s.descriptor_fn, s.traversable_fn) for s in scorings)
    return compiled(cache, ("many", fns, tuple(emitters), fitness, mesh, scorings[0].split),
                     lambda: many_chunk(tuple(scorings), tuple(emitters), fitness, mesh))
