"""NEAT mutation of CPPN genomes (one genome; the generator vmaps it) and the minimal Picbreeder start genomes.
Part of :mod:`jaxterrain.generators.cppn`; :class:`~jaxterrain.generators.cppn.CPPNConfig` lists the operators."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain.generators._cppn_eval import adjacency, reachability
from jaxterrain.generators._cppn_genome import CPPNConfig, CPPNGenome, NUM_ACTIVATIONS, NUM_INPUTS, OUTPUT
from jaxterrain.generators.base import PRNGKey


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

