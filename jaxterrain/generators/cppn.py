"""CPPN terrain generator with NEAT mutation (paper 3.1.5 and 3.3; Picbreeder settings).

A Compositional Pattern-Producing Network maps the coordinates of every pixel to a height. Its topology evolves
with NEAT's mutations (no crossover: MAP-Elites only mutates). To batch networks of different topologies in one
jit-compiled, vmapped call, a genome is a fixed-size, padded pytree (the TensorNEAT pattern)::

    gen = jaxterrain.generators.get("cppn", size=256)
    genomes = gen.sample(key, 8)          # CPPNGenome, every leaf [8, ...]
    children = gen.mutate(key, genomes)   # same shapes, still feed-forward
    maps = gen.render(genomes)            # [8, 256, 256] float32 in [0, 1]

Genome layout (:class:`CPPNGenome`; ``N = max_nodes``, ``C = max_connections``; every leaf has a leading batch
axis ``B`` in a batch, and the arrays below are those of one genome):

* nodes ``[N]``: ``node_act`` int32 activation id (index into :data:`ACTIVATIONS`), ``node_bias`` float32,
  ``node_used`` bool. Node kinds are fixed by position: 0 = x, 1 = y, 2 = d (inputs), 3 = bias input (always 1),
  4 = the output, 5 .. N-1 = hidden slots, taken in order by "add node". See :func:`node_kinds`.
* connections ``[C]``: ``conn_src`` / ``conn_dst`` int32 node indices, ``conn_weight`` float32,
  ``conn_enabled`` bool, ``conn_used`` bool. Padding slots have ``used = enabled = False``, src = dst = 0,
  weight 0. No innovation numbers: they only serve crossover, which the paper's MAP-Elites does not use.

Invariants (checked by ``validate``, kept by ``mutate``): inputs and output are used; a used connection joins two
used nodes, never starts at the output, never ends at an input or the bias, is no self-loop and no duplicate of
another used connection (enabled or not); the graph of ALL used connections (enabled and disabled) is acyclic, so
re-enabling a connection can never close a cycle; ``enabled`` implies ``used``; weights and biases are finite and
within ``[-weight_limit, weight_limit]``; activation ids in ``[0, len(ACTIVATIONS) - 1]``.

Inputs (Picbreeder): ``x`` (column) and ``y`` (row), each ``linspace(-1, 1, size)``; the distance from the centre
``d = sqrt(x^2 + y^2) / sqrt(2)`` in [0, 1] (1 at the corners); and the bias input, always 1. The output node's
value ``o`` becomes the height by the fixed squashing ``h = (tanh(o) + 1) / 2`` in [0, 1] (no per-map min-max, so
a genome's height scale is part of what evolves). A node computes ``act(bias + sum of enabled incoming
weight * value)``; pre-activations are clipped to ``[-VALUE_LIMIT, VALUE_LIMIT]`` so that long chains of
``square`` cannot overflow to inf / NaN.

Evaluation: a jit-able topological order (sort nodes by their number of ancestors, taken from the transitive
closure of the adjacency, which ``ceil(log2(N - 1))`` boolean [N, N] matrix products give; the output goes last),
then one straight-line, fully unrolled program over the nodes in that order, element-wise over all pixels. Under
``vmap`` it is a single element-wise program over ``[B, size * size]`` that XLA fuses into one kernel, with all node
values of a pixel in registers: the cost per pixel is ``sum_{k=4}^{N-1} k`` multiply-adds (490 for N = 32) plus
``N - 4`` activations (one ``sin`` and one ``exp`` each, see :func:`activate`) and the memory traffic is only the
output. (Layered evaluation with a ``[P, N] @ [N, N]`` matmul per depth step is exact too but moves the whole
``[P, N]`` value matrix through memory ``N - 4`` times: memory-bound.)

Measured (jax 0.11.2, 256 x 256, a batch of 1024 genomes after 40 default mutation rounds, float32): one H100,
N = 32: 50 600 terrains/s; the same program selecting among all eight separately computed activations:
40 700/s; layered matmul evaluation: 2 300/s. One H200: N = 32: ~60 000/s, N = 16: ~300 000/s.

Defaults: ``max_nodes = 32`` (27 hidden nodes) and ``max_connections = 128``: 2.5x the 20 000 terrains/s target
with room for networks far larger than Picbreeder's typical ones. The render cost grows as N^2 and does not
depend on C (C only sizes the genome and the mutation operators).

This module is the entry: the generator and every public name. The stages live in private modules beside it:
``_cppn_genome`` (constants, configs, the genome type, host-side checks), ``_cppn_eval`` (activations, topological
order, evaluation) and ``_cppn_neat`` (mutation, start genomes).
"""

from __future__ import annotations

import math
from typing import Any

import jax

from jaxterrain.generators.registry import register

# The stages, re-exported: every name below stays importable from jaxterrain.generators.cppn.
from jaxterrain.generators._cppn_eval import (  # noqa: F401
    activate,
    adjacency,
    coordinates,
    evaluate,
    height,
    reachability,
    topological_order,
    weight_matrix,
)
from jaxterrain.generators._cppn_genome import (  # noqa: F401
    ACT_ABS,
    ACT_COSINE,
    ACT_GAUSSIAN,
    ACT_IDENTITY,
    ACT_SIGMOID,
    ACT_SINE,
    ACT_SQUARE,
    ACT_TANH,
    ACTIVATIONS,
    INPUT_NAMES,
    KIND_BIAS,
    KIND_HIDDEN,
    KIND_INPUT,
    KIND_OUTPUT,
    MIN_NODES,
    NUM_ACTIVATIONS,
    NUM_INPUTS,
    OUTPUT,
    VALUE_LIMIT,
    CPPNConfig,
    CPPNGenome,
    CPPNSpec,
    check_config,
    check_genomes,
    node_kinds,
)
from jaxterrain.generators._cppn_neat import minimal_genomes, mutate_one
from jaxterrain.generators.base import (
    RENDER_CHUNK,
    Generator,
    PRNGKey,
    mark_checked,
    check_count,
    check_key,
    chunked_render,
    is_traced,
)


def render_chunk(max_nodes: int) -> int:
    """Maps per ``lax.map`` step of ``render``: 16384 / N rounded down to a power of two, at most
    :data:`RENDER_CHUNK` (512 at N = 32). On a GPU, XLA keeps about N values per pixel (~15 MB per 256 x 256 map at
    N = 32: 60 GiB at B = 4096 before chunking), so a chunk stays near 8 GiB at any N and any batch size."""
    return max(1, min(RENDER_CHUNK, 2 ** int(math.floor(math.log2(16384 / max_nodes)))))


@register("cppn")
def cppn(size: int = 256, max_nodes: int = 32, max_connections: int = 128, config: CPPNConfig = CPPNConfig()
         ) -> Generator:
    """The CPPN generator (see the module docstring).

    Args:
      size: side of the heightmap in pixels, >= 1.
      max_nodes: node slots N per genome (4 inputs + output + N - 5 hidden), in [5, 256]. Render cost ~ N^2.
      max_connections: connection slots C per genome, >= 4.
      config: mutation settings, :class:`CPPNConfig`.
    """
    if int(size) != size or size < 1:
        raise ValueError(f"cppn: size is {size}; it must be an integer >= 1")
    if int(max_nodes) != max_nodes or not MIN_NODES <= max_nodes <= 256:
        raise ValueError(f"cppn: max_nodes is {max_nodes}; it must be an integer in [{MIN_NODES}, 256]")
    if int(max_connections) != max_connections or max_connections < NUM_INPUTS:
        raise ValueError(f"cppn: max_connections is {max_connections}; it must be an integer >= {NUM_INPUTS}")
    check_config(config)
    size, max_nodes, max_connections = int(size), int(max_nodes), int(max_connections)
    gspec = CPPNSpec(max_nodes, max_connections, config)

    def render_one(genome: CPPNGenome) -> jax.Array:
        return height(evaluate(genome, coordinates(size)))

    batched = chunked_render(render_one, render_chunk(max_nodes))

    def mutate_raw(key: PRNGKey, genomes: CPPNGenome) -> CPPNGenome:
        if genomes.node_used.ndim == 1:
            return mutate_one(key, genomes, config)
        keys = jax.random.split(key, genomes.node_used.shape[0])
        return jax.vmap(mutate_one, in_axes=(0, 0, None))(keys, genomes, config)

    mutate_jit = jax.jit(mutate_raw)

    def validate(genomes: Any) -> None:
        check_genomes(genomes, max_nodes, max_connections, config.weight_limit)

    @mark_checked
    def mutate(key: PRNGKey, genomes: CPPNGenome) -> CPPNGenome:
        check_key(key, "cppn")
        if not is_traced(genomes):
            validate(genomes)
        return mutate_jit(key, CPPNGenome(*genomes))

    def sample_raw(key: PRNGKey, n: int) -> CPPNGenome:
        init_key, mut_key = jax.random.split(key)
        del key
        genomes = minimal_genomes(init_key, n, max_nodes, max_connections, config)
        if config.init_mutations == 0:
            return genomes
        return jax.lax.fori_loop(
            0, int(config.init_mutations), lambda i, g: mutate_raw(jax.random.fold_in(mut_key, i), g), genomes
        )

    sample_jit = jax.jit(sample_raw, static_argnums=1)  # one compile per n, not one per call

    @mark_checked
    def sample(key: PRNGKey, n: int) -> CPPNGenome:
        n = check_count(n, "cppn")
        check_key(key, "cppn")
        return sample_jit(key, n)

    def render(genomes: CPPNGenome) -> jax.Array:
        if not is_traced(genomes):
            validate(genomes)
        genomes = CPPNGenome(*genomes)
        if genomes.node_used.ndim == 1:
            return batched(jax.tree.map(lambda a: a[None], genomes))[0]
        return batched(genomes)

    return Generator("cppn", gspec, size, sample, mutate, render, render_one, validate)


__all__ = [
    "ACTIVATIONS",
    "CPPNConfig",
    "CPPNGenome",
    "CPPNSpec",
    "activate",
    "adjacency",
    "check_genomes",
    "coordinates",
    "cppn",
    "evaluate",
    "height",
    "minimal_genomes",
    "mutate_one",
    "node_kinds",
    "reachability",
    "render_chunk",
    "topological_order",
    "weight_matrix",
]
