"""CPPN genomes: the node and activation constants, :class:`CPPNConfig`, the padded :class:`CPPNGenome` and the
host-side checks of genomes and configs. Part of :mod:`jaxterrain.generators.cppn`; import the names from there."""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import jax
import numpy as np

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



def closure_steps(n: int) -> int:
    """Squarings of an ``[n, n]`` 0/1 adjacency matrix that cover every path (length up to n - 1)."""
    return max(1, math.ceil(math.log2(max(n - 1, 2))))


# ----------------------------------------------------------------------------------------------------------------
# Host-side validation
# ----------------------------------------------------------------------------------------------------------------


def check_genomes(genomes: Any, max_nodes: int, max_connections: int, weight_limit: float, name: str = "cppn") -> None:
    """Host-side checks of concrete CPPN genomes (batched or one); raises ``ValueError`` naming field and range.

    In this order: the type, shapes and dtypes; the values (finite weights and biases within the limit, activation
    ids, inputs and output used); the connections (node indices, used nodes, directions, no self-loops); no
    duplicate connection; no cycle."""
    g = _check_layout(genomes, max_nodes, max_connections, name)
    _check_values(g, weight_limit, name)
    _check_connections(g, max_nodes, name)
    _check_no_duplicates(g, max_nodes, name)
    _check_acyclic(g, max_nodes, name)


def _check_layout(genomes: Any, max_nodes: int, max_connections: int, name: str) -> dict[str, np.ndarray]:
    """The type, every field's shape and dtype; returns the fields as numpy arrays ``[B, N]`` / ``[B, C]``."""
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
    B = int(np.prod(batch_shape, dtype=np.int64))
    return {f: v.reshape(B, -1) for f, v in g.items()}


def _fail(name: str, field: str, mask: np.ndarray, msg) -> None:
    """Raise for the first True of ``mask`` ``[B, K]``: ``msg(i, j)`` says what is wrong with ``field[j]`` of
    genome ``i``."""
    i, j = np.argwhere(mask)[0]
    raise ValueError(f"{name}: {field}[{j}] of genome {i} {msg(i, j)}")


def _check_values(g: dict[str, np.ndarray], weight_limit: float, name: str) -> None:
    """Weights and biases finite and within the limit, activation ids known, inputs and output used."""
    for f in ("node_bias", "conn_weight"):
        v = g[f]
        bad = ~np.isfinite(v)
        if bad.any():
            _fail(name, f, bad,
                  lambda i, j: f"is {v[i, j]}; it must be finite in [{-weight_limit:g}, {weight_limit:g}]")
        bad = np.abs(v) > weight_limit * (1 + 1e-6)
        if bad.any():
            _fail(name, f, bad,
                  lambda i, j: f"is {v[i, j]:g}, outside its range [{-weight_limit:g}, {weight_limit:g}]")
    act = g["node_act"]
    bad = (act < 0) | (act >= NUM_ACTIVATIONS)
    if bad.any():
        _fail(name, "node_act", bad, lambda i, j: f"is {act[i, j]}, outside [0, {NUM_ACTIVATIONS - 1}] "
                                                  f"({', '.join(ACTIVATIONS)})")
    bad = ~g["node_used"][:, :MIN_NODES]
    if bad.any():
        _fail(name, "node_used", bad, lambda i, j: f"is False; the inputs {INPUT_NAMES} and the output (nodes "
                                                   f"0..{OUTPUT}) must be used")


def _check_connections(g: dict[str, np.ndarray], n: int, name: str) -> None:
    """Node indices in range, ``enabled`` only on used slots, used connections between used nodes, never out of
    the output nor into an input or the bias, no self-loops."""
    for f in ("conn_src", "conn_dst"):
        v = g[f]
        bad = (v < 0) | (v >= n)
        if bad.any():
            _fail(name, f, bad, lambda i, j: f"is {v[i, j]}, outside the node indices [0, {n - 1}]")
    used_n, src, dst, cu, ce = g["node_used"], g["conn_src"], g["conn_dst"], g["conn_used"], g["conn_enabled"]
    bad = ce & ~cu
    if bad.any():
        _fail(name, "conn_enabled", bad, lambda i, j: "is True for an unused connection slot (conn_used False)")
    rows = np.arange(src.shape[0])[:, None]
    bad = cu & ~used_n[rows, src]
    if bad.any():
        _fail(name, "conn_src", bad, lambda i, j: f"is node {src[i, j]}, which is not used (node_used False)")
    bad = cu & ~used_n[rows, dst]
    if bad.any():
        _fail(name, "conn_dst", bad, lambda i, j: f"is node {dst[i, j]}, which is not used (node_used False)")
    bad = cu & (src == OUTPUT)
    if bad.any():
        _fail(name, "conn_src", bad, lambda i, j: f"is the output node {OUTPUT}; a source must be an input, the bias "
                                                  f"or a hidden node (0..{OUTPUT - 1} or {OUTPUT + 1}..{n - 1})")
    bad = cu & (dst < OUTPUT)
    if bad.any():
        _fail(name, "conn_dst", bad, lambda i, j: f"is input node {dst[i, j]}; a destination must be in "
                                                  f"[{OUTPUT}, {n - 1}] (output or hidden)")
    bad = cu & (src == dst)
    if bad.any():
        _fail(name, "conn_src", bad, lambda i, j: f"equals conn_dst ({src[i, j]}): self-loops are not allowed")


def _check_no_duplicates(g: dict[str, np.ndarray], n: int, name: str) -> None:
    """No two used connections (enabled or not) join the same pair of nodes."""
    src, dst, cu = g["conn_src"], g["conn_dst"], g["conn_used"]
    c = cu.shape[1]
    pair = np.where(cu, src.astype(np.int64) * n + dst, -1 - np.arange(c))
    order = np.argsort(pair, axis=1, kind="stable")
    sp = np.take_along_axis(pair, order, axis=1)
    dup = (sp[:, 1:] == sp[:, :-1]) & (sp[:, 1:] >= 0)
    if dup.any():
        i, k = np.argwhere(dup)[0]
        j = order[i, k + 1]
        raise ValueError(f"{name}: conn_src/conn_dst[{j}] of genome {i} duplicates another used connection "
                         f"{src[i, j]} -> {dst[i, j]}")


def _check_acyclic(g: dict[str, np.ndarray], n: int, name: str) -> None:
    """The graph of all used connections (enabled or not) has no cycle (boolean transitive closure)."""
    src, dst, cu = g["conn_src"], g["conn_dst"], g["conn_used"]
    B, c = cu.shape
    adj = np.zeros((B, n, n), np.int64)
    np.add.at(adj, (np.repeat(np.arange(B), c), src.reshape(-1), dst.reshape(-1)), cu.reshape(-1).astype(np.int64))
    reach = adj > 0
    for _ in range(closure_steps(n) + 1):
        reach = reach | (np.matmul(reach.astype(np.int64), reach.astype(np.int64)) > 0)
    cyc = np.diagonal(reach, axis1=1, axis2=2)
    if cyc.any():
        i, j = np.argwhere(cyc)[0]
        raise ValueError(f"{name}: conn_src/conn_dst of genome {i} form a cycle through node {j}; the used "
                         "connections (enabled or not) must be acyclic")


def check_config(config: CPPNConfig) -> None:
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



# The public home of these types is jaxterrain.generators.cppn: archive files record a genome's class by module and
# name ("jaxterrain.generators.cppn:CPPNGenome"), and pickles do likewise.
for _cls in (CPPNConfig, CPPNGenome, CPPNSpec):
    _cls.__module__ = "jaxterrain.generators.cppn"
del _cls
