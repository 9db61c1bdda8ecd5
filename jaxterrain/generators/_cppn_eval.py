"""CPPN evaluation: activations, a jit-able topological order, and one genome's output at every pixel. Part of
:mod:`jaxterrain.generators.cppn` (whose docstring explains the scheme); import the names from there."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from jaxterrain.generators._cppn_genome import (
    ACT_ABS,
    ACT_COSINE,
    ACT_GAUSSIAN,
    ACT_SIGMOID,
    ACT_SINE,
    ACT_SQUARE,
    ACT_TANH,
    CPPNGenome,
    NUM_INPUTS,
    OUTPUT,
    VALUE_LIMIT,
    closure_steps,
)


def activate(act: jax.Array, x: jax.Array) -> jax.Array:
    """Apply activation ``act`` (int id, broadcastable to ``x``) to ``x``, after clipping x to +-VALUE_LIMIT.

    All eight functions cost one ``sin`` and one ``exp``: cosine is ``sin(x + pi/2)``; gaussian is ``exp(-x^2)``;
    sigmoid is ``1 / (1 + exp(-x))`` and tanh is ``2 / (1 + exp(-2x)) - 1`` (exact at +-inf of the exp).
    """
    x = jnp.clip(x, -VALUE_LIMIT, VALUE_LIMIT)
    s = jnp.sin(jnp.where(act == ACT_COSINE, x + (math.pi / 2), x))
    e = jnp.exp(jnp.where(act == ACT_GAUSSIAN, -x * x, jnp.where(act == ACT_TANH, -2.0 * x, -x)))
    r = 1.0 / (1.0 + e)
    out = jnp.where(act == ACT_SQUARE, x * x, x)
    out = jnp.where(act == ACT_ABS, jnp.abs(x), out)
    out = jnp.where(act == ACT_TANH, 2.0 * r - 1.0, out)
    out = jnp.where(act == ACT_SIGMOID, r, out)
    out = jnp.where(act == ACT_GAUSSIAN, e, out)
    out = jnp.where((act == ACT_SINE) | (act == ACT_COSINE), s, out)
    return out


def reachability(adjacency: jax.Array) -> jax.Array:
    """Transitive closure: ``[..., N, N]`` bool adjacency (i -> j) to ``[..., N, N]`` bool "a path i -> j exists".

    ``ceil(log2(N - 1))`` squarings of the 0/1 matrix (paths up to length N - 1); jit- and vmap-able.
    """
    n = adjacency.shape[-1]
    r = adjacency.astype(jnp.float32)
    for _ in range(closure_steps(n)):
        r = jnp.maximum(r, (jnp.matmul(r, r) > 0.5).astype(jnp.float32))
    return r > 0.5


def adjacency(genome: CPPNGenome, enabled_only: bool = False) -> jax.Array:
    """``[N, N]`` bool: a used (and, if ``enabled_only``, enabled) connection i -> j exists. One genome."""
    n = genome.node_used.shape[-1]
    live = genome.conn_used & genome.conn_enabled if enabled_only else genome.conn_used
    return jnp.zeros((n, n), jnp.int32).at[genome.conn_src, genome.conn_dst].add(live.astype(jnp.int32)) > 0


def topological_order(genome: CPPNGenome) -> jax.Array:
    """A topological order of the nodes of one genome: ``[N]`` int32 node indices, jit-able.

    Nodes are sorted (stably) by their number of ancestors in the graph of all used connections: in a DAG an
    ancestor has strictly fewer ancestors than its descendant. The inputs (no ancestors, smallest indices) come
    first, at positions 0..3; the output (which has no outgoing connections) is forced last.
    """
    n = genome.node_used.shape[-1]
    reach = reachability(adjacency(genome))
    key = jnp.sum(reach, axis=0, dtype=jnp.int32)
    key = key.at[OUTPUT].set(n + 1)
    return jnp.argsort(key, stable=True).astype(jnp.int32)


def weight_matrix(genome: CPPNGenome) -> jax.Array:
    """``[N, N]`` float32 weights of the enabled, used connections (i -> j at [i, j]). One genome."""
    n = genome.node_used.shape[-1]
    live = genome.conn_used & genome.conn_enabled
    w = jnp.where(live, genome.conn_weight, 0.0).astype(jnp.float32)
    return jnp.zeros((n, n), jnp.float32).at[genome.conn_src, genome.conn_dst].add(w)


def coordinates(size: int) -> tuple[jax.Array, jax.Array, jax.Array]:
    """The CPPN inputs ``x, y, d``, each ``[size, size]`` float32 (x varies along columns, y along rows)."""
    c = jnp.linspace(-1.0, 1.0, size, dtype=jnp.float32)
    y, x = jnp.meshgrid(c, c, indexing="ij")
    d = jnp.sqrt(x * x + y * y) / math.sqrt(2.0)
    return x, y, d


def evaluate(genome: CPPNGenome, inputs: tuple[jax.Array, ...]) -> jax.Array:
    """Raw output value ``o`` of one genome at every point: ``inputs`` are (x, y, d) arrays of one shape ``S``.

    Unchecked; works under jit / vmap. Returns float32 of shape ``S`` (before the height squashing).
    """
    n = genome.node_used.shape[-1]
    order = topological_order(genome)
    w = weight_matrix(genome)[order][:, order]
    bias = genome.node_bias.astype(jnp.float32)[order]
    act = genome.node_act[order]
    x, y, d = inputs
    values = [x, y, d, jnp.ones_like(x)]
    for k in range(NUM_INPUTS, n):
        pre = bias[k] + values[0] * w[0, k]
        for j in range(1, k):
            pre = pre + values[j] * w[j, k]
        values.append(activate(act[k], pre))
    return values[-1]  # the output, last in the order


def height(raw: jax.Array) -> jax.Array:
    """The fixed squashing of the output value to a height in [0, 1]: ``(tanh(o) + 1) / 2``."""
    return 0.5 * (jnp.tanh(raw) + 1.0)

