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
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain.generators import register
from jaxterrain.generators.base import (
    RENDER_CHUNK,
    Generator,
    PRNGKey,
    _mark,
    check_count,
    chunked_render,
    is_traced,
)

ACTIVATIONS: tuple[str, ...] = ("identity", "sine", "cosine", "gaussian", "sigmoid", "tanh", "abs", "square")
"""Activation ids (Picbreeder's smooth set, plus abs and square as in Enhanced POET):

identity ``x``; sine ``sin x``; cosine ``cos x``; gaussian ``exp(-x^2)``; sigmoid ``1 / (1 + exp(-x))``;
tanh ``tanh x``; abs ``|x|``; square ``x^2``.
"""
ACT_IDENTITY, ACT_SINE, ACT_COSINE, ACT_GAUSSIAN, ACT_SIGMOID, ACT_TANH, ACT_ABS, ACT_SQUARE = range(8)
NUM_ACTIVATIONS = len(ACTIVATIONS)

INPUT_NAMES: tuple[str, ...] = ("x", "y", "d", "bias")
NUM_INPUTS = len(INPUT_NAMES)  # nodes 0..3
OUTPUT = NUM_INPUTS  # node 4
MIN_NODES = NUM_INPUTS + 1
KIND_INPUT, KIND_BIAS, KIND_OUTPUT, KIND_HIDDEN = 0, 1, 2, 3
VALUE_LIMIT = 1.0e4

_NODE_FIELDS = ("node_act", "node_bias", "node_used")
_CONN_FIELDS = ("conn_src", "conn_dst", "conn_weight", "conn_enabled", "conn_used")


class CPPNConfig(NamedTuple):
    """NEAT mutation settings (Picbreeder / NEAT-like defaults). Static, hashable.

    Every call of ``mutate`` applies, in this order, to each genome independently:

    Attributes:
      weight_replace_prob: per used connection (and per bias of a used output / hidden node): probability that
        the value is replaced by a fresh draw N(0, weight_init_std^2).
      weight_perturb_prob: per value, otherwise: probability that it moves by N(0, weight_perturb_sigma^2).
        (NEAT: 80 % of weights perturbed, 10 % replaced.) ``replace + perturb <= 1``.
      weight_perturb_sigma: standard deviation of a perturbation.
      weight_init_std: standard deviation of new weights (sampling, replacement, add connection).
      weight_limit: weights and biases are clipped to ``[-weight_limit, weight_limit]``.
      add_connection_prob: per genome: add one connection between a random pair of used nodes that keeps the
        network acyclic and does not duplicate an existing connection; skipped when none exists or all
        ``max_connections`` slots are used.
      add_node_prob: per genome: split a random enabled connection a -> b: disable it, add a hidden node h
        with a random activation and bias 0, and connections a -> h (weight 1, or ``weight_limit`` if smaller) and
        h -> b (the old weight);
        skipped when no node slot or fewer than two connection slots are free, or no connection is enabled.
      activation_prob: per genome: one random output / hidden node gets a different random activation.
      toggle_enable_prob: per genome: one random used connection flips its ``enabled`` flag.
      init_mutations: ``sample`` applies ``mutate`` this many times to the minimal Picbreeder start genomes
        (all inputs -> output) so that the initial population already differs in topology.
    """

    weight_replace_prob: float = 0.1
    weight_perturb_prob: float = 0.8
    weight_perturb_sigma: float = 0.5
    weight_init_std: float = 1.0
    weight_limit: float = 3.0
    add_connection_prob: float = 0.3
    add_node_prob: float = 0.2
    activation_prob: float = 0.1
    toggle_enable_prob: float = 0.05
    init_mutations: int = 3


class CPPNGenome(NamedTuple):
    """A padded NEAT genome (see the module docstring). Leaves ``[..., N]`` / ``[..., C]``; leading axes batch."""

    node_act: jax.Array  # [N] int32
    node_bias: jax.Array  # [N] float32
    node_used: jax.Array  # [N] bool
    conn_src: jax.Array  # [C] int32
    conn_dst: jax.Array  # [C] int32
    conn_weight: jax.Array  # [C] float32
    conn_enabled: jax.Array  # [C] bool
    conn_used: jax.Array  # [C] bool


class CPPNSpec(NamedTuple):
    """Static description of CPPN genomes (the ``spec`` of the generator)."""

    max_nodes: int
    max_connections: int
    config: CPPNConfig
    inputs: tuple[str, ...] = INPUT_NAMES
    activations: tuple[str, ...] = ACTIVATIONS


def node_kinds(max_nodes: int) -> np.ndarray:
    """Kind of each node slot ``[N]`` int32: KIND_INPUT (x, y, d), KIND_BIAS, KIND_OUTPUT, then KIND_HIDDEN."""
    kinds = np.full((max_nodes,), KIND_HIDDEN, np.int32)
    kinds[: NUM_INPUTS - 1] = KIND_INPUT
    kinds[NUM_INPUTS - 1] = KIND_BIAS
    kinds[OUTPUT] = KIND_OUTPUT
    return kinds


# ----------------------------------------------------------------------------------------------------------------
# Evaluation
# ----------------------------------------------------------------------------------------------------------------


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


def _closure_steps(n: int) -> int:
    return max(1, math.ceil(math.log2(max(n - 1, 2))))


def reachability(adjacency: jax.Array) -> jax.Array:
    """Transitive closure: ``[..., N, N]`` bool adjacency (i -> j) to ``[..., N, N]`` bool "a path i -> j exists".

    ``ceil(log2(N - 1))`` squarings of the 0/1 matrix (paths up to length N - 1); jit- and vmap-able.
    """
    n = adjacency.shape[-1]
    r = adjacency.astype(jnp.float32)
    for _ in range(_closure_steps(n)):
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


# ----------------------------------------------------------------------------------------------------------------
# Mutation (one genome; vmapped by the generator)
# ----------------------------------------------------------------------------------------------------------------


def _choice(u: jax.Array, mask: jax.Array) -> tuple[jax.Array, jax.Array]:
    """A uniformly random index where ``mask`` (any shape, flattened) is True, and whether one exists.

    ``u``: uniform draws in [0, 1) of ``mask``'s size."""
    flat = mask.reshape(-1)
    scores = jnp.where(flat, u, -1.0)
    return jnp.argmax(scores).astype(jnp.int32), jnp.any(flat)


def _randint(u: jax.Array, low: int, high: int) -> jax.Array:
    """An integer in [low, high) from a uniform draw ``u`` in [0, 1)."""
    return jnp.clip(low + jnp.floor(u * (high - low)), low, high - 1).astype(jnp.int32)


class _Draws(NamedTuple):
    """All random numbers of one mutation step of one genome (two threefry calls instead of twenty)."""

    w_u: jax.Array  # [C] uniform: replace / perturb / keep each weight
    w_fresh: jax.Array  # [C] normal
    w_noise: jax.Array  # [C] normal
    b_u: jax.Array  # [N]
    b_fresh: jax.Array  # [N] normal
    b_noise: jax.Array  # [N] normal
    pair: jax.Array  # [N * N] uniform: which new connection
    split: jax.Array  # [C] uniform: which connection to split
    node: jax.Array  # [N] uniform: which node changes activation
    toggle: jax.Array  # [C] uniform: which connection toggles
    scalars: jax.Array  # [8] uniform: [0:4] operator coin flips, [4:6] activation draws, [6:8] unused
    new_weight: jax.Array  # [] normal: weight of an added connection


def _draws(key: PRNGKey, n: int, c: int) -> _Draws:
    u_key, z_key = jax.random.split(key)
    del key
    u_sizes = (c, n, n * n, c, n, c, 8)
    z_sizes = (c, c, n, n, 1)
    u = jax.random.uniform(u_key, (sum(u_sizes),))
    z = jax.random.normal(z_key, (sum(z_sizes),))
    us = jnp.split(u, np.cumsum(u_sizes)[:-1])
    zs = jnp.split(z, np.cumsum(z_sizes)[:-1])
    return _Draws(us[0], zs[0], zs[1], us[1], zs[2], zs[3], us[2], us[3], us[4], us[5], us[6], zs[4][0])


def _mutate_weights(r: _Draws, g: CPPNGenome, cfg: CPPNConfig) -> CPPNGenome:
    lim = cfg.weight_limit

    def step(u, fresh, noise, values, mask):
        replace = mask & (u < cfg.weight_replace_prob)
        perturb = mask & ~replace & (u < cfg.weight_replace_prob + cfg.weight_perturb_prob)
        fresh = fresh * cfg.weight_init_std
        noise = noise * cfg.weight_perturb_sigma
        out = jnp.where(replace, fresh, jnp.where(perturb, values + noise, values))
        return jnp.where(mask, jnp.clip(out, -lim, lim), values).astype(jnp.float32)

    weight = step(r.w_u, r.w_fresh, r.w_noise, g.conn_weight, g.conn_used)
    hidden_or_out = g.node_used & (jnp.arange(g.node_used.shape[-1]) >= OUTPUT)
    bias = step(r.b_u, r.b_fresh, r.b_noise, g.node_bias, hidden_or_out)
    return g._replace(conn_weight=weight, node_bias=bias)


def _add_connection(r: _Draws, g: CPPNGenome, cfg: CPPNConfig) -> CPPNGenome:
    n = g.node_used.shape[-1]
    idx = jnp.arange(n)
    adj = adjacency(g)
    reach = reachability(adj)
    src_ok = g.node_used & (idx != OUTPUT)
    dst_ok = g.node_used & (idx >= OUTPUT)
    # s -> d is allowed unless it exists already, is a self-loop, or d already reaches s (a cycle).
    cand = src_ok[:, None] & dst_ok[None, :] & ~adj & ~reach.T & ~jnp.eye(n, dtype=bool)
    pair, any_cand = _choice(r.pair, cand)
    slot = jnp.argmin(g.conn_used).astype(jnp.int32)
    has_slot = ~jnp.all(g.conn_used)
    do = (r.scalars[0] < cfg.add_connection_prob) & any_cand & has_slot
    weight = jnp.clip(r.new_weight * cfg.weight_init_std, -cfg.weight_limit, cfg.weight_limit)

    def put(arr, value):
        return jnp.where(do & (jnp.arange(arr.shape[-1]) == slot), jnp.asarray(value).astype(arr.dtype), arr)

    return g._replace(
        conn_src=put(g.conn_src, pair // n),
        conn_dst=put(g.conn_dst, pair % n),
        conn_weight=put(g.conn_weight, weight),
        conn_enabled=put(g.conn_enabled, True),
        conn_used=put(g.conn_used, True),
    )


def _add_node(r: _Draws, g: CPPNGenome, cfg: CPPNConfig) -> CPPNGenome:
    c = g.conn_used.shape[-1]
    split, any_live = _choice(r.split, g.conn_used & g.conn_enabled)
    node = jnp.argmin(g.node_used).astype(jnp.int32)
    has_node = ~jnp.all(g.node_used)
    free = ~g.conn_used
    s1 = jnp.argmax(free).astype(jnp.int32)
    s2 = jnp.argmax(free & (jnp.arange(c) != s1)).astype(jnp.int32)
    has_slots = jnp.sum(free) >= 2
    do = (r.scalars[1] < cfg.add_node_prob) & any_live & has_node & has_slots
    act = _randint(r.scalars[4], 0, NUM_ACTIVATIONS)

    def put(arr, at, value):
        return jnp.where(do & (jnp.arange(arr.shape[-1]) == at), jnp.asarray(value).astype(arr.dtype), arr)

    src, dst, w = g.conn_src[split], g.conn_dst[split], g.conn_weight[split]
    enabled = put(g.conn_enabled, split, False)
    return g._replace(
        node_act=put(g.node_act, node, act),
        node_bias=put(g.node_bias, node, 0.0),
        node_used=put(g.node_used, node, True),
        conn_src=put(put(g.conn_src, s1, src), s2, node),
        conn_dst=put(put(g.conn_dst, s1, node), s2, dst),
        conn_weight=put(put(g.conn_weight, s1, min(1.0, cfg.weight_limit)), s2, w),  # 1, within the limit
        conn_enabled=put(put(enabled, s1, True), s2, True),
        conn_used=put(put(g.conn_used, s1, True), s2, True),
    )


def _mutate_activation(r: _Draws, g: CPPNGenome, cfg: CPPNConfig) -> CPPNGenome:
    n = g.node_used.shape[-1]
    node, _ = _choice(r.node, g.node_used & (jnp.arange(n) >= OUTPUT))
    new = (g.node_act[node] + _randint(r.scalars[5], 1, NUM_ACTIVATIONS)) % NUM_ACTIVATIONS
    do = r.scalars[2] < cfg.activation_prob
    return g._replace(node_act=jnp.where(do & (jnp.arange(n) == node), new, g.node_act).astype(jnp.int32))


def _toggle_enable(r: _Draws, g: CPPNGenome, cfg: CPPNConfig) -> CPPNGenome:
    conn, any_used = _choice(r.toggle, g.conn_used)
    do = (r.scalars[3] < cfg.toggle_enable_prob) & any_used
    flip = do & (jnp.arange(g.conn_used.shape[-1]) == conn)
    return g._replace(conn_enabled=g.conn_enabled ^ flip)


def mutate_one(key: PRNGKey, genome: CPPNGenome, config: CPPNConfig = CPPNConfig()) -> CPPNGenome:
    """One NEAT mutation step of one (unbatched) genome; see :class:`CPPNConfig` for the operators and order."""
    r = _draws(key, genome.node_used.shape[-1], genome.conn_used.shape[-1])
    del key
    genome = _mutate_weights(r, genome, config)
    genome = _add_connection(r, genome, config)
    genome = _add_node(r, genome, config)
    genome = _mutate_activation(r, genome, config)
    return _toggle_enable(r, genome, config)


def minimal_genomes(key: PRNGKey, n: int, max_nodes: int, max_connections: int, config: CPPNConfig) -> CPPNGenome:
    """``n`` Picbreeder start genomes: the 4 inputs connected to the output with N(0, weight_init_std^2) weights
    (clipped), a random output activation, no hidden nodes, all biases 0. Leaves ``[n, ...]``."""
    w_key, act_key = jax.random.split(key)
    del key
    nodes = jnp.arange(max_nodes)
    conns = jnp.arange(max_connections)
    first = conns < NUM_INPUTS
    weight = jax.random.normal(w_key, (n, NUM_INPUTS)) * config.weight_init_std
    weight = jnp.clip(weight, -config.weight_limit, config.weight_limit)
    out_act = jax.random.randint(act_key, (n,), 0, NUM_ACTIVATIONS, jnp.int32)
    bcast = lambda a: jnp.broadcast_to(a, (n,) + a.shape)  # noqa: E731
    return CPPNGenome(
        node_act=jnp.zeros((n, max_nodes), jnp.int32).at[:, OUTPUT].set(out_act),
        node_bias=jnp.zeros((n, max_nodes), jnp.float32),
        node_used=bcast(nodes <= OUTPUT),
        conn_src=bcast(jnp.where(first, conns, 0).astype(jnp.int32)),
        conn_dst=bcast(jnp.where(first, OUTPUT, 0).astype(jnp.int32)),
        conn_weight=jnp.zeros((n, max_connections), jnp.float32).at[:, :NUM_INPUTS].set(weight),
        conn_enabled=bcast(first),
        conn_used=bcast(first),
    )


# ----------------------------------------------------------------------------------------------------------------
# Host-side validation
# ----------------------------------------------------------------------------------------------------------------


def check_genomes(genomes: Any, max_nodes: int, max_connections: int, weight_limit: float, name: str = "cppn") -> None:
    """Host-side checks of concrete CPPN genomes (batched or one); raises ``ValueError`` naming field and range."""
    if not (isinstance(genomes, CPPNGenome) or (hasattr(genomes, "_fields") and genomes._fields == CPPNGenome._fields)):
        raise ValueError(f"{name}: genomes must be a CPPNGenome with fields {CPPNGenome._fields}; got {type(genomes)}")
    g = {f: np.asarray(getattr(genomes, f)) for f in CPPNGenome._fields}
    batch_shape = g["node_used"].shape[:-1]
    if g["node_used"].ndim not in (1, 2):
        raise ValueError(f"{name}: node_used must have shape [B, {max_nodes}] or [{max_nodes}]; "
                         f"got {g['node_used'].shape}")
    for f in CPPNGenome._fields:
        want = batch_shape + ((max_nodes,) if f in _NODE_FIELDS else (max_connections,))
        if g[f].shape != want:
            raise ValueError(f"{name}: {f} must have shape {list(want)} (max_nodes={max_nodes}, "
                             f"max_connections={max_connections}); got {list(g[f].shape)}")
    kinds = {"node_act": "i", "conn_src": "i", "conn_dst": "i", "node_bias": "f", "conn_weight": "f",
             "node_used": "b", "conn_enabled": "b", "conn_used": "b"}
    names = {"i": "an integer dtype (int32)", "f": "a float dtype (float32)", "b": "bool"}
    for f, k in kinds.items():
        if g[f].dtype.kind != k and not (k == "i" and g[f].dtype.kind == "u"):
            raise ValueError(f"{name}: {f} must have {names[k]}; got {g[f].dtype}")
    n, c = max_nodes, max_connections
    B = int(np.prod(batch_shape, dtype=np.int64))
    g = {f: v.reshape(B, -1) for f, v in g.items()}

    def fail(field, mask, msg):
        i, j = np.argwhere(mask)[0]
        raise ValueError(f"{name}: {field}[{j}] of genome {i} {msg(i, j)}")

    for f in ("node_bias", "conn_weight"):
        v = g[f]
        bad = ~np.isfinite(v)
        if bad.any():
            fail(f, bad, lambda i, j: f"is {v[i, j]}; it must be finite in [{-weight_limit:g}, {weight_limit:g}]")
        bad = np.abs(v) > weight_limit * (1 + 1e-6)
        if bad.any():
            fail(f, bad, lambda i, j: f"is {v[i, j]:g}, outside its range [{-weight_limit:g}, {weight_limit:g}]")
    act = g["node_act"]
    bad = (act < 0) | (act >= NUM_ACTIVATIONS)
    if bad.any():
        fail("node_act", bad, lambda i, j: f"is {act[i, j]}, outside [0, {NUM_ACTIVATIONS - 1}] "
                                           f"({', '.join(ACTIVATIONS)})")
    used_n = g["node_used"]
    bad = ~used_n[:, :MIN_NODES]
    if bad.any():
        fail("node_used", bad, lambda i, j: f"is False; the inputs {INPUT_NAMES} and the output (nodes 0..{OUTPUT}) "
                                            "must be used")
    for f in ("conn_src", "conn_dst"):
        v = g[f]
        bad = (v < 0) | (v >= n)
        if bad.any():
            fail(f, bad, lambda i, j: f"is {v[i, j]}, outside the node indices [0, {n - 1}]")
    src, dst, cu, ce = g["conn_src"], g["conn_dst"], g["conn_used"], g["conn_enabled"]
    bad = ce & ~cu
    if bad.any():
        fail("conn_enabled", bad, lambda i, j: "is True for an unused connection slot (conn_used False)")
    rows = np.arange(B)[:, None]
    bad = cu & ~used_n[rows, src]
    if bad.any():
        fail("conn_src", bad, lambda i, j: f"is node {src[i, j]}, which is not used (node_used False)")
    bad = cu & ~used_n[rows, dst]
    if bad.any():
        fail("conn_dst", bad, lambda i, j: f"is node {dst[i, j]}, which is not used (node_used False)")
    bad = cu & (src == OUTPUT)
    if bad.any():
        fail("conn_src", bad, lambda i, j: f"is the output node {OUTPUT}; a source must be an input, the bias or "
                                           f"a hidden node (0..{OUTPUT - 1} or {OUTPUT + 1}..{n - 1})")
    bad = cu & (dst < OUTPUT)
    if bad.any():
        fail("conn_dst", bad, lambda i, j: f"is input node {dst[i, j]}; a destination must be in [{OUTPUT}, {n - 1}] "
                                           "(output or hidden)")
    bad = cu & (src == dst)
    if bad.any():
        fail("conn_src", bad, lambda i, j: f"equals conn_dst ({src[i, j]}): self-loops are not allowed")
    pair = np.where(cu, src.astype(np.int64) * n + dst, -1 - np.arange(c))
    order = np.argsort(pair, axis=1, kind="stable")
    sp = np.take_along_axis(pair, order, axis=1)
    dup = (sp[:, 1:] == sp[:, :-1]) & (sp[:, 1:] >= 0)
    if dup.any():
        i, k = np.argwhere(dup)[0]
        j = order[i, k + 1]
        raise ValueError(f"{name}: conn_src/conn_dst[{j}] of genome {i} duplicates another used connection "
                         f"{src[i, j]} -> {dst[i, j]}")
    adj = np.zeros((B, n, n), np.int64)
    np.add.at(adj, (np.repeat(np.arange(B), c), src.reshape(-1), dst.reshape(-1)), cu.reshape(-1).astype(np.int64))
    reach = adj > 0
    for _ in range(_closure_steps(n) + 1):
        reach = reach | (np.matmul(reach.astype(np.int64), reach.astype(np.int64)) > 0)
    cyc = np.diagonal(reach, axis1=1, axis2=2)
    if cyc.any():
        i, j = np.argwhere(cyc)[0]
        raise ValueError(f"{name}: conn_src/conn_dst of genome {i} form a cycle through node {j}; the used "
                         "connections (enabled or not) must be acyclic")


def _check_config(config: CPPNConfig) -> None:
    if not isinstance(config, CPPNConfig):
        raise ValueError(f"cppn: config must be a CPPNConfig; got {type(config)}")
    for f in ("weight_replace_prob", "weight_perturb_prob", "add_connection_prob", "add_node_prob",
              "activation_prob", "toggle_enable_prob"):
        v = getattr(config, f)
        if not 0.0 <= v <= 1.0:
            raise ValueError(f"cppn: config.{f} is {v}; it must be a probability in [0, 1]")
    if config.weight_replace_prob + config.weight_perturb_prob > 1.0 + 1e-9:
        raise ValueError("cppn: config.weight_replace_prob + config.weight_perturb_prob must be in [0, 1]; got "
                         f"{config.weight_replace_prob + config.weight_perturb_prob:g}")
    for f in ("weight_perturb_sigma", "weight_init_std"):
        if not getattr(config, f) >= 0.0:
            raise ValueError(f"cppn: config.{f} is {getattr(config, f)}; it must be >= 0")
    if not (config.weight_limit > 0.0 and math.isfinite(config.weight_limit)):
        raise ValueError(f"cppn: config.weight_limit is {config.weight_limit}; it must be finite and > 0")
    if int(config.init_mutations) != config.init_mutations or config.init_mutations < 0:
        raise ValueError(f"cppn: config.init_mutations is {config.init_mutations}; it must be an integer >= 0")


# ----------------------------------------------------------------------------------------------------------------
# The generator
# ----------------------------------------------------------------------------------------------------------------


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
    _check_config(config)
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

    @_mark
    def mutate(key: PRNGKey, genomes: CPPNGenome) -> CPPNGenome:
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

    @_mark
    def sample(key: PRNGKey, n: int) -> CPPNGenome:
        return sample_jit(key, check_count(n, "cppn"))

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
