"""Tests of the CPPN generator: topological order, rendering against a numpy reference, NEAT mutation validity."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxterrain import generators
from jaxterrain.generators import cppn as C

SIZE = 16
N, NC = 10, 24  # small static sizes: cheap to compile, and mutation fills them within 200 rounds
# Aggressive structural mutation so that 200 rounds hit full genomes, toggles and activation changes.
WILD = C.CPPNConfig(add_connection_prob=0.6, add_node_prob=0.4, activation_prob=0.5, toggle_enable_prob=0.3)

NP_ACTS = {
    "identity": lambda x: x,
    "sine": np.sin,
    "cosine": np.cos,
    "gaussian": lambda x: np.exp(-x * x),
    "sigmoid": lambda x: 1.0 / (1.0 + np.exp(-x)),
    "tanh": np.tanh,
    "abs": np.abs,
    "square": lambda x: x * x,
}


# Compilation dominates the run time on CPU: tests share these jitted functions and use batches of 16.
@pytest.fixture(scope="module")
def gen():
    return generators.get("cppn", size=SIZE, max_nodes=N, max_connections=NC, config=WILD)


@pytest.fixture(scope="module")
def mutate(gen):
    return jax.jit(gen.mutate)


@pytest.fixture(scope="module")
def sample(gen):
    return jax.jit(gen.sample, static_argnums=1)


@pytest.fixture(scope="module")
def population(sample, mutate):
    """16 genomes after 3 + 12 rounds of mutation: many different topologies."""
    g = sample(jax.random.key(0), 16)
    for i in range(12):
        g = mutate(jax.random.key(100 + i), g)
    return g


def make_genome(conns, acts=None, biases=None, n=N, c=NC, used_nodes=None):
    """One genome: conns = [(src, dst, weight, enabled)], acts = {node: name}, biases = {node: value}."""
    acts, biases = acts or {}, biases or {}
    node_act = np.zeros(n, np.int32)
    node_bias = np.zeros(n, np.float32)
    node_used = np.zeros(n, bool)
    node_used[: C.OUTPUT + 1] = True
    for k, name in acts.items():
        node_act[k] = C.ACTIVATIONS.index(name)
    for k, b in biases.items():
        node_bias[k] = b
    src, dst = np.zeros(c, np.int32), np.zeros(c, np.int32)
    w, en, cu = np.zeros(c, np.float32), np.zeros(c, bool), np.zeros(c, bool)
    for i, (s, d, wt, e) in enumerate(conns):
        src[i], dst[i], w[i], en[i], cu[i] = s, d, wt, e, True
        node_used[s] = node_used[d] = True
    if used_nodes is not None:
        node_used[list(used_nodes)] = True
    return C.CPPNGenome(*(jnp.asarray(a) for a in (node_act, node_bias, node_used, src, dst, w, en, cu)))


def stack(genomes):
    return jax.tree.map(lambda *xs: jnp.stack(xs), *genomes)


def reference_height(genome, size=SIZE):
    """Independent numpy evaluation: recursive over the graph, no topological sort."""
    g = jax.tree.map(np.asarray, genome)
    c = np.linspace(-1.0, 1.0, size)
    x, y = np.broadcast_to(c[None, :], (size, size)), np.broadcast_to(c[:, None], (size, size))
    d = np.sqrt(x**2 + y**2) / math.sqrt(2.0)
    memo = {0: x, 1: y, 2: d, 3: np.ones_like(x)}

    def value(k):
        if k not in memo:
            pre = np.full_like(x, float(g.node_bias[k]))
            for i in np.flatnonzero(g.conn_used & g.conn_enabled & (g.conn_dst == k)):
                pre = pre + float(g.conn_weight[i]) * value(int(g.conn_src[i]))
            memo[k] = NP_ACTS[C.ACTIVATIONS[int(g.node_act[k])]](pre)
        return memo[k]

    with np.errstate(over="ignore"):  # exp(-x) of the sigmoid may overflow to inf: 1 / (1 + inf) = 0 is right
        return (np.tanh(value(C.OUTPUT)) + 1.0) / 2.0


# Hand-made graphs. Hidden node indices deliberately out of topological order (9 feeds 5, 7 feeds 6).
CHAIN = dict(
    conns=[(0, 9, 1.5, True), (9, 5, -2.0, True), (5, 7, 0.8, True), (7, 6, 1.2, True), (6, 4, 2.0, True)],
    acts={9: "sine", 5: "gaussian", 7: "tanh", 6: "square", 4: "identity"},
    biases={5: 0.3, 6: -0.5},
)
DIAMOND = dict(
    conns=[(0, 8, 2.0, True), (1, 6, -1.0, True), (8, 6, 0.7, True), (8, 4, 0.5, True), (6, 4, 1.5, True),
           (2, 4, -0.4, True), (3, 8, 0.25, True)],
    acts={8: "sine", 6: "cosine", 4: "sigmoid"},
)
DISABLED = dict(
    conns=[(0, 4, 2.5, False), (1, 5, 1.0, True), (5, 4, -1.3, True), (2, 5, 3.0, False)],
    acts={5: "abs", 4: "tanh"},
    biases={4: 0.2},
)


def positions(order):
    pos = np.empty_like(order)
    pos[order] = np.arange(len(order))
    return pos


# ----------------------------------------------------------------------------------------------------------------


def test_activations_match_numpy():
    x = np.linspace(-4.0, 4.0, 101).astype(np.float32)
    for i, name in enumerate(C.ACTIVATIONS):
        got = np.asarray(C.activate(jnp.int32(i), jnp.asarray(x)))
        np.testing.assert_allclose(got, NP_ACTS[name](x.astype(np.float64)), atol=2e-6, rtol=1e-5, err_msg=name)
    # Saturation is exact and finite: no inf / NaN from exp overflow.
    big = jnp.asarray([-1e30, -1e4, 1e4, 1e30], jnp.float32)
    for i in range(C.NUM_ACTIVATIONS):
        assert np.all(np.isfinite(np.asarray(C.activate(jnp.int32(i), big)))), C.ACTIVATIONS[i]
    np.testing.assert_array_equal(C.activate(jnp.int32(C.ACT_TANH), big), [-1, -1, 1, 1])


@pytest.mark.parametrize("graph", [CHAIN, DIAMOND, DISABLED], ids=["chain", "diamond", "disabled"])
def test_topological_order_on_hand_made_graphs(graph):
    g = make_genome(**graph)
    order = np.asarray(jax.jit(C.topological_order)(g))
    assert sorted(order.tolist()) == list(range(N))  # a permutation
    assert order[:4].tolist() == [0, 1, 2, 3] and order[-1] == C.OUTPUT
    pos = positions(order)
    for s, d, _, _ in graph["conns"]:  # disabled connections too
        assert pos[s] < pos[d], (s, d, order)


def test_topological_order_of_the_chain_is_exact():
    order = np.asarray(C.topological_order(make_genome(**CHAIN)))
    used = [k for k in order if k in (9, 5, 7, 6)]
    assert used == [9, 5, 7, 6]


def test_reachability_transitive_closure():
    adj = np.zeros((N, N), bool)
    path = [0, 9, 5, 7, 6, 8, 4]  # 6 edges: needs 3 squarings
    for a, b in zip(path, path[1:]):
        adj[a, b] = True
    r = np.asarray(C.reachability(jnp.asarray(adj)))
    for i, a in enumerate(path):
        for b in path[i + 1:]:
            assert r[a, b] and not r[b, a]
    assert r.sum() == len(path) * (len(path) - 1) // 2


def test_known_weights_render_known_image(gen):
    c = np.linspace(-1.0, 1.0, SIZE)
    x = np.broadcast_to(c[None, :], (SIZE, SIZE))
    y = np.broadcast_to(c[:, None], (SIZE, SIZE))
    d = np.sqrt(x**2 + y**2) / math.sqrt(2.0)
    ident = make_genome([(0, 4, 1.0, True)], acts={4: "identity"})
    mixed = make_genome([(0, 4, 2.0, True), (1, 4, -1.0, True), (2, 4, 0.5, True), (3, 4, 0.25, True)],
                        acts={4: "sine"}, biases={4: 0.1})
    maps = np.asarray(gen.render(stack([ident, mixed])))
    np.testing.assert_allclose(maps[0], (np.tanh(x) + 1) / 2, atol=1e-6)
    np.testing.assert_allclose(maps[1], (np.tanh(np.sin(2 * x - y + 0.5 * d + 0.25 + 0.1)) + 1) / 2, atol=1e-6)
    # x varies along columns, y along rows; d is 1 at the corners, ~0 near the centre.
    assert maps[0][0, 0] < maps[0][0, -1] and np.allclose(maps[0][0], maps[0][-1])


def test_hand_made_graphs_match_reference(gen):
    genomes = [make_genome(**g) for g in (CHAIN, DIAMOND, DISABLED)]
    maps = np.asarray(gen.render(stack(genomes)))
    for m, g in zip(maps, genomes):
        np.testing.assert_allclose(m, reference_height(g), atol=2e-6)
    # The disabled x -> out (weight 2.5) is ignored: enabling it changes the map.
    on = make_genome(**dict(DISABLED, conns=[(0, 4, 2.5, True)] + DISABLED["conns"][1:]))
    assert np.abs(np.asarray(gen.render(on)) - maps[2]).max() > 0.05


def test_mutated_population_matches_reference_and_one_by_one(gen, population):
    structures = {tuple(map(int, np.asarray(population.conn_used[i]).nonzero()[0])) for i in range(16)}
    assert len(structures) > 2 and int(np.asarray(population.node_used).sum(1).max()) > C.OUTPUT + 1
    maps = np.asarray(gen.render(population))
    assert maps.shape == (16, SIZE, SIZE) and maps.dtype == np.float32
    assert maps.min() >= 0.0 and maps.max() <= 1.0
    for i in range(16):
        one = jax.tree.map(lambda a: a[i], population)
        np.testing.assert_allclose(np.asarray(gen.render(one)), maps[i], atol=1e-6)
        np.testing.assert_allclose(maps[i], reference_height(one), atol=1e-4)


def test_mutation_keeps_genomes_valid_over_200_rounds(gen, mutate):
    g = C.minimal_genomes(jax.random.key(1), 16, N, NC, WILD)
    prev_n, prev_c = np.full(16, C.OUTPUT + 1), np.full(16, 4)
    for t in range(200):
        g = mutate(jax.random.key(1000 + t), g)
        g = jax.tree.map(np.asarray, g)
        gen.validate(g)  # shapes, dtypes, ranges, masks, no duplicate, no cycle
        n_used, c_used = g.node_used.sum(1), g.conn_used.sum(1)
        assert np.all(n_used >= prev_n) and np.all(c_used >= prev_c)
        assert np.all(n_used <= N) and np.all(c_used <= NC)
        # used slots stay a prefix; padding stays zero
        assert np.all(np.diff(g.node_used.astype(int), axis=1) <= 0)
        assert np.all(np.diff(g.conn_used.astype(int), axis=1) <= 0)
        assert np.all(g.conn_weight[~g.conn_used] == 0) and np.all(g.node_bias[~g.node_used] == 0)
        prev_n, prev_c = n_used, c_used
    final = g
    assert np.any(final.conn_used.sum(1) == NC)  # the static sizes were reached...
    assert np.any(final.node_used.sum(1) == N)
    assert np.any(~final.conn_enabled[final.conn_used])  # ...and splits / toggles disabled some connections
    assert len(np.unique(final.node_act[:, C.OUTPUT:][final.node_used[:, C.OUTPUT:]])) >= 6


FULL_CONFIG = C.CPPNConfig(weight_replace_prob=0.0, weight_perturb_prob=0.0, add_connection_prob=1.0,
                           add_node_prob=1.0, activation_prob=0.0, toggle_enable_prob=0.0, init_mutations=0)


@pytest.fixture(scope="module")
def full_gen():
    """Tiny static sizes (2 hidden slots, 9 connections) and structural mutations with probability 1."""
    return C.cppn(size=8, max_nodes=7, max_connections=9, config=FULL_CONFIG)


@pytest.fixture(scope="module")
def full_mutate(full_gen):
    return jax.jit(full_gen.mutate)


def test_growth_stops_at_static_sizes(full_gen, full_mutate):
    mut = full_mutate
    g0 = full_gen.sample(jax.random.key(0), 16)
    counts, hist = [], [g0]
    for i in range(6):
        hist.append(jax.tree.map(np.asarray, mut(jax.random.key(i), hist[-1])))
        full_gen.validate(hist[-1])
        counts.append((hist[-1].node_used.sum(1), hist[-1].conn_used.sum(1)))
    # Round 1: no hidden node, so no new connection is possible (inputs -> output all exist); a split adds node 5.
    # Round 2: one connection into / out of node 5, then a second split fills the nodes and the connections.
    # Later rounds: both additions are skipped and the genome is unchanged.
    for (n_used, c_used), want in zip(counts, [(6, 6), (7, 9), (7, 9), (7, 9), (7, 9), (7, 9)]):
        np.testing.assert_array_equal(n_used, want[0])
        np.testing.assert_array_equal(c_used, want[1])
    for later in hist[3:]:
        jax.tree.map(np.testing.assert_array_equal, hist[2], later)
    # The split: x -> h (weight 1) -> out (old weight), old connection disabled.
    c = hist[1]
    np.testing.assert_array_equal(c.conn_enabled.sum(1), 5)
    for b in range(16):
        split = int(np.flatnonzero(~c.conn_enabled[b, :4])[0])
        assert (c.conn_src[b, 4], c.conn_dst[b, 4], c.conn_weight[b, 4]) == (c.conn_src[b, split], 5, 1.0)
        assert (c.conn_src[b, 5], c.conn_dst[b, 5]) == (5, C.OUTPUT)
        assert c.conn_weight[b, 5] == c.conn_weight[b, split]
    # All weights unchanged (weight mutation probabilities are 0 here).
    np.testing.assert_array_equal(hist[-1].conn_weight[:, :4], np.asarray(g0.conn_weight)[:, :4])


def test_add_connection_picks_the_only_allowed_pair(full_gen, full_mutate):
    # Hidden node 5 used, all pairs but 5 -> out connected, one free slot: only 5 -> out may be added (not
    # out -> 5, not a duplicate, not into an input); afterwards the connections are full and nothing changes.
    conns = [(s, 5, 0.5, True) for s in range(4)] + [(s, 4, 0.5, True) for s in range(4)]
    g = stack([make_genome(conns, n=7, c=9)] * 16)
    mut = full_mutate
    h = jax.tree.map(np.asarray, mut(jax.random.key(3), g))
    full_gen.validate(h)
    assert h.conn_used.all() and np.all(h.conn_src[:, 8] == 5) and np.all(h.conn_dst[:, 8] == 4)
    np.testing.assert_array_equal(h.node_used.sum(1), 6)  # add node skipped: no free connection slot left
    jax.tree.map(np.testing.assert_array_equal, h, mut(jax.random.key(4), h))


def test_determinism(sample, mutate):
    a, b = sample(jax.random.key(7), 16), sample(jax.random.key(7), 16)
    jax.tree.map(np.testing.assert_array_equal, a, b)
    jax.tree.map(np.testing.assert_array_equal, mutate(jax.random.key(8), a), mutate(jax.random.key(8), b))
    c = sample(jax.random.key(9), 16)
    assert not np.array_equal(np.asarray(a.conn_weight), np.asarray(c.conn_weight))


def test_sample_is_minimal_picbreeder_start():
    cfg = C.CPPNConfig(init_mutations=0)
    default = C.cppn(size=8, config=cfg)
    g0 = jax.tree.map(np.asarray, default.sample(jax.random.key(0), 64))
    assert g0.node_used.shape == (64, 32) and g0.conn_used.shape == (64, 128)  # documented defaults
    np.testing.assert_array_equal(g0.node_used.sum(1), 5)
    np.testing.assert_array_equal(g0.conn_src[:, :4], np.tile(np.arange(4), (64, 1)))
    np.testing.assert_array_equal(g0.conn_dst[:, :4], 4)
    assert g0.conn_used[:, :4].all() and not g0.conn_used[:, 4:].any()
    assert 0.6 < g0.conn_weight[:, :4].std() < 1.4 and len(np.unique(g0.node_act[:, 4])) >= 6
    four = jax.tree.map(lambda a: a[:4], g0)
    for m, i in zip(np.asarray(default.render(four)), range(4)):  # the default max_nodes = 32 program
        np.testing.assert_allclose(m, reference_height(jax.tree.map(lambda a: a[i], four), 8), atol=2e-6)


def test_genome_is_a_pytree(gen, population):
    leaves = jax.tree.leaves(population)
    assert len(leaves) == 8 and all(leaf.shape[0] == 16 for leaf in leaves)
    half = jax.tree.map(lambda a: a[::2], population)
    both = jax.tree.map(lambda a, b: jnp.concatenate([a, b]), half, half)
    gen.validate(both)
    maps = np.asarray(gen.render(population))
    np.testing.assert_allclose(np.asarray(jax.jit(jax.vmap(gen.render_one))(half)), maps[::2], atol=1e-6)
    np.testing.assert_allclose(np.asarray(jax.jit(gen.render)(half)), maps[::2], atol=1e-6)  # traced: no checks
    flat, treedef = jax.tree.flatten(population)
    assert isinstance(jax.tree.unflatten(treedef, flat), C.CPPNGenome)


def test_registry_defaults_and_qdax_repertoire(gen, population):
    assert "cppn" in generators.names() and generators.get("cppn", size=SIZE, max_nodes=N, max_connections=NC,
                                                            config=WILD) is gen
    assert gen.name == "cppn" and gen.size == SIZE and gen.spec.max_nodes == N and gen.spec.config == WILD
    spec = generators.get("cppn", size=8).spec
    assert spec.max_nodes == 32 and spec.max_connections == 128 and spec.activations == C.ACTIVATIONS
    g = jax.tree.map(lambda a: a[:4], population)
    from qdax.core.containers.mapelites_repertoire import MapElitesRepertoire

    descriptors = jnp.array([[0.1, 0.1], [0.9, 0.1], [0.1, 0.9], [0.9, 0.9]])
    centroids = jnp.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    rep = jax.jit(MapElitesRepertoire.init)(g, jnp.arange(4.0), descriptors, centroids)
    gen.validate(rep.genotypes)
    jax.tree.map(np.testing.assert_array_equal, rep.genotypes, g)
    back = jax.tree.map(lambda a, b: jnp.concatenate([a, b[4:]]), rep.genotypes, population)  # batch 16: compiled
    np.testing.assert_array_equal(gen.render(back), gen.render(population))


# ----------------------------------------------------------------------------------------------------------------
# Errors


def _bad(g, field, index, value):
    arr = np.asarray(getattr(g, field)).copy()
    arr[index] = value
    return g._replace(**{field: jnp.asarray(arr)})


def _extra(g, src, dst, enabled=True):
    """Genome 0 of ``g`` with an extra used connection src -> dst in slot 10."""
    g = _bad(_bad(g, "conn_src", (0, 10), src), "conn_dst", (0, 10), dst)
    return _bad(_bad(g, "conn_used", (0, 10), True), "conn_enabled", (0, 10), enabled)


def test_validate_errors(gen):
    g = stack([make_genome(**CHAIN), make_genome(**DIAMOND)])
    gen.validate(g)
    gen.validate(make_genome(**CHAIN))
    cases = [
        (_bad(g, "conn_weight", (1, 2), np.nan), r"conn_weight\[2\] of genome 1 is nan; it must be finite"),
        (_bad(g, "conn_weight", (0, 0), 7.0), r"conn_weight\[0\] of genome 0 is 7, outside its range \[-3, 3\]"),
        (_bad(g, "node_bias", (0, 5), np.inf), r"node_bias\[5\] of genome 0 is inf"),
        (_bad(g, "node_act", (0, 6), 8), r"node_act\[6\] of genome 0 is 8, outside \[0, 7\]"),
        (_bad(g, "conn_src", (1, 0), N), r"conn_src\[0\] of genome 1 is 10, outside the node indices \[0, 9\]"),
        (_bad(g, "conn_dst", (1, 0), -1), r"conn_dst\[0\] of genome 1 is -1, outside"),
        (_bad(g, "node_used", (0, 4), False), r"node_used\[4\] of genome 0 is False; the inputs"),
        (_bad(g, "node_used", (0, 7), False), r"conn_src\[3\] of genome 0 is node 7, which is not used"),
        (_bad(g, "conn_enabled", (0, 10), True), r"conn_enabled\[10\] of genome 0 is True for an unused"),
        (_bad(g, "conn_src", (0, 4), 4), r"conn_src\[4\] of genome 0 is the output node 4"),
        (_bad(g, "conn_dst", (0, 0), 2), r"conn_dst\[0\] of genome 0 is input node 2"),
        (_bad(g, "conn_dst", (0, 0), 0), r"conn_dst\[0\] of genome 0 is input node 0"),
        (_bad(_bad(g, "conn_src", (0, 1), 5), "conn_dst", (0, 1), 5), r"equals conn_dst \(5\): self-loops"),
        (_bad(_bad(g, "conn_src", (0, 1), 0), "conn_dst", (0, 1), 9), r"duplicates another used connection 0 -> 9"),
        (_extra(g, 6, 9), r"genome 0 form a cycle"),
        (g._replace(node_act=g.node_act.astype(jnp.float32)), r"node_act must have an integer dtype"),
        (g._replace(conn_used=g.conn_used.astype(jnp.int32)), r"conn_used must have bool"),
        (jax.tree.map(lambda a: a[:, :-1], g), r"must have shape \[2, 10\] \(max_nodes=10"),
        (g.node_act, r"genomes must be a CPPNGenome"),
    ]
    for bad, msg in cases:
        with pytest.raises(ValueError, match=msg):
            gen.validate(bad)
    with pytest.raises(ValueError, match="conn_weight"):
        gen.render(cases[0][0])
    # A disabled edge closing a cycle is still an error (re-enabling it would create a cycle).
    cyc = _extra(g, 6, 9, enabled=False)
    with pytest.raises(ValueError, match="cycle"):
        gen.validate(cyc)


def test_factory_errors():
    with pytest.raises(ValueError, match=r"max_nodes is 4; it must be an integer in \[5, 256\]"):
        C.cppn(max_nodes=4)
    with pytest.raises(ValueError, match=r"max_connections is 3"):
        C.cppn(max_connections=3)
    with pytest.raises(ValueError, match=r"size is 0"):
        C.cppn(size=0)
    with pytest.raises(ValueError, match=r"config.add_node_prob is 1.5"):
        C.cppn(config=C.CPPNConfig(add_node_prob=1.5))
    with pytest.raises(ValueError, match=r"weight_replace_prob \+ config.weight_perturb_prob"):
        C.cppn(config=C.CPPNConfig(weight_replace_prob=0.5, weight_perturb_prob=0.8))
    with pytest.raises(ValueError, match=r"n is 0"):
        C.cppn(size=8).sample(jax.random.key(0), 0)


def test_map_elites_hands_render_one_only_valid_genomes(tmp_path):
    """The library's own path (sample, mutate, insertion of tied offspring, save / load) never gives ``render_one``
    a genome that ``validate`` refuses: inside ``evolve`` every genome rendered goes to the host through
    ``jax.debug.callback`` and through ``validate``. A constant fitness makes every offspring of a cell a tie, the
    case that once mixed offspring leaf by leaf (docs/results/insertion_bug.md)."""
    from jaxterrain import qd as A

    base = C.cppn(size=SIZE, max_nodes=N, max_connections=NC, config=WILD)
    seen, bad = [0], []

    def check(genome):
        g = C.CPPNGenome(*jax.tree.map(np.asarray, genome))
        seen[0] += int(np.prod(g.node_used.shape[:-1], dtype=np.int64))
        try:
            base.validate(g)
        except ValueError as err:
            bad.append(str(err))

    def render_one(genome):
        jax.debug.callback(check, genome)
        return base.render_one(genome)

    gen = base._replace(render_one=render_one)
    config = A.EvolveConfig(generations=3, batch_size=16, initial_population=16, bins=4, window=4, stride=2,
                            ranges=((0.0, 1.0), (0.0, 0.5)), checkpoint_every=3)
    arch = A.evolve(gen, None, config, jax.random.key(0), fitness_fn=lambda h, key, needed=None: jnp.ones(h.shape[0]),
                    traversable_fn=lambda h: jnp.ones(h.shape[0], bool), progress=False)
    assert seen[0] >= 16 + 3 * 16 and not bad, bad[:3]
    filled = arch.source >= 0
    assert filled.sum() >= 2
    elites = jax.tree.map(lambda x: np.asarray(x)[filled], arch.genomes[0])
    base.validate(C.CPPNGenome(*elites))
    A.save(tmp_path / "a.npz", arch)
    again = A.load(tmp_path / "a.npz")
    base.validate(C.CPPNGenome(*jax.tree.map(lambda x: np.asarray(x)[filled], again.genomes[0])))
