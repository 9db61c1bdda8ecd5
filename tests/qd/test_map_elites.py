"""The pure MAP-Elites core: one winner per cell under ties, stored elites re-derive their cells, vmapped and combined
treatments equal runs done one by one."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxterrain import qd as A
from jaxterrain.generators.base import Generator as FakeGen  # the library's bundle, fake functions
from jaxterrain.qd import map_elites as ME
from jaxterrain.qd import scoring as S


class UV(NamedTuple):  # a two-leaf genome: mixing leaves of two offspring gives a third terrain
    u: jax.Array
    v: jax.Array


SIZE = 8
YY, XX = np.mgrid[0:SIZE, 0:SIZE].astype(np.float32)


def uv_gen(name="uv"):
    """Genome (u, v) renders the plane a * x / n + b * y / n with a = (u + v) / 2, b = (u - v) / 2 + 0.5: cells
    are not separable in (u, v), so a genome mixed from two offspring of one cell can land in another cell."""

    def render_one(g):
        a = (g.u[0] + g.v[0]) / 2
        b = (g.u[0] - g.v[0]) / 2 + 0.5
        return a * XX / SIZE + b * YY / SIZE

    def sample(key, n):
        k1, k2 = jax.random.split(key)
        return UV(jax.random.uniform(k1, (n, 1)), jax.random.uniform(k2, (n, 1)))

    def mutate(key, g):
        k1, k2 = jax.random.split(key)
        return UV(jnp.clip(g.u + 0.2 * jax.random.normal(k1, g.u.shape), 0, 1),
                  jnp.clip(g.v + 0.2 * jax.random.normal(k2, g.v.shape), 0, 1))

    return FakeGen(name, None, SIZE, sample, mutate, jax.vmap(render_one), render_one, lambda g: None)


def vec_gen(name="vec"):
    """Genome [a, b] renders the plane a * x / n + b * y / n."""

    def render_one(g):
        return g[0] * XX / SIZE + g[1] * YY / SIZE

    def sample(key, n):
        return jax.random.uniform(key, (n, 2))

    def mutate(key, g):
        return jnp.clip(g + 0.1 * jax.random.normal(key, g.shape), 0.0, 1.0)

    return FakeGen(name, None, SIZE, sample, mutate, jax.vmap(render_one), render_one, lambda g: None)


def desc3(hm):
    """[B, 3]: a, b (read back from the plane) and a * b."""
    n = hm.shape[-1]
    a = (hm[:, 0, 1] - hm[:, 0, 0]) * n
    b = (hm[:, 1, 0] - hm[:, 0, 0]) * n
    return jnp.stack([a, b, a * b], -1)


def desc2(hm):
    return desc3(hm)[:, :2]


def always(hm):
    return jnp.ones(hm.shape[0], bool)


def saturated(hm, key, needed):  # fitness saturates at 1.0: every offspring of a cell ties
    return jnp.minimum(1.0, 2.0 - desc3(hm)[:, 0])


def smooth(hm, key, needed):  # per-terrain deterministic, rarely tied
    return 1.0 - jnp.mean(desc3(hm), -1) / 3


def cfg(**kw):
    base = dict(generations=4, batch_size=12, initial_population=16, bins=4, ranges=((0.0, 1.0), (0.0, 1.0)),
                checkpoint_every=2, store_heightmaps=False, descriptors=("a", "b"))
    base.update(kw)
    return A.resolve_config(A.EvolveConfig(**base))


# ----------------------------------------------------------------------------------------------------------------
# insertion
# ----------------------------------------------------------------------------------------------------------------


def empty(bins=2, genome=UV(jnp.zeros((1,)), jnp.zeros((1,), jnp.int32))):
    c = cfg(bins=bins)
    return ME.empty_repertoire(genome, A.centroids_for(c)), c


def test_ties_store_the_lowest_offspring_index_in_every_leaf():
    rep, _ = empty(genome=UV(jnp.zeros((3,)), jnp.zeros((), jnp.int32)))
    k = np.arange(10)
    genomes = UV(np.float32(k)[:, None] + np.float32([0.0, 0.1, 0.2]), (100 + k).astype(np.int32))
    # cells of the 2 x 2 grid: 0 (low a, low b) and 3 (high a, high b)
    cell = np.where(np.isin(k, [1, 3, 4, 6, 8]), 0, 3)
    cell_desc = (np.where(cell[:, None] == 0, 0.1, 0.9) + np.float32([0.01, 0.02]) * k[:, None]).astype(np.float32)
    fit = np.float32([1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 0.5, 1.0, 1.0])
    fit[1] = 0.5  # cell 0: offspring 1 is worse; 3, 4, 6, 8 tie at 1.0 -> 3; cell 3: 0, 2, 5, 9 tie -> 0
    raw = np.stack([k, -k], -1).astype(np.float32)
    new, inserted = jax.jit(ME.insert)(rep, genomes, cell_desc, fit, raw)
    assert float(inserted) == 2
    for c, w in ((0, 3), (3, 0)):
        np.testing.assert_array_equal(np.asarray(new.genotypes.u)[c], genomes.u[w])
        assert int(np.asarray(new.genotypes.v)[c]) == 100 + w
        assert float(new.fitnesses[c, 0]) == 1.0
        np.testing.assert_array_equal(np.asarray(new.descriptors)[c], cell_desc[w])
        np.testing.assert_array_equal(np.asarray(new.extra_scores["raw"])[c], raw[w])
    assert np.all(np.asarray(new.fitnesses)[[1, 2], 0] == -np.inf)
    # a tie with the elite does not replace it; a better one does, and NaN / -inf never enter
    again, n = jax.jit(ME.insert)(new, genomes, cell_desc, fit, raw)
    assert float(n) == 0 and int(np.asarray(again.genotypes.v)[0]) == 103
    bad = np.float32([np.nan, -np.inf, 2.0, np.nan, np.nan, 1.5, -np.inf, np.nan, np.nan, np.nan])
    b2, n = jax.jit(ME.insert)(new, genomes, cell_desc, bad, raw)
    assert float(n) == 1 and int(np.asarray(b2.genotypes.v)[3]) == 102 and int(np.asarray(b2.genotypes.v)[0]) == 103


def reference_insert(fit_old, cells, fit):
    """NumPy: for each cell, the lowest index among the best finite offspring, if strictly better."""
    winners = {}
    for c in np.unique(cells):
        members = np.flatnonzero((cells == c) & np.isfinite(fit))
        if members.size == 0:
            continue
        best = fit[members].max()
        w = int(members[fit[members] == best].min())
        if best > fit_old[c]:
            winners[int(c)] = w
    return winners


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_batches_with_many_ties_match_the_reference(seed):
    rng = np.random.default_rng(seed)
    rep, _ = empty(bins=3, genome=UV(jnp.zeros((2,)), jnp.zeros((), jnp.int32)))
    insert = jax.jit(ME.insert)
    cents = np.asarray(rep.centroids)
    for step in range(4):
        b = 64
        cells = rng.integers(0, 9, b)
        fit = rng.choice(np.float32([0.25, 0.5, 1.0, np.nan, -np.inf]), b).astype(np.float32)
        genomes = UV(rng.normal(size=(b, 2)).astype(np.float32), (1000 * step + np.arange(b)).astype(np.int32))
        raw = rng.normal(size=(b, 2)).astype(np.float32)
        old_fit = np.asarray(rep.fitnesses)[:, 0].copy()
        old_v = np.asarray(rep.genotypes.v).copy()
        rep, n = insert(rep, genomes, cents[cells], fit, raw)
        winners = reference_insert(old_fit, cells, fit)
        assert float(n) == len(winners)
        v = np.asarray(rep.genotypes.v)
        for c in range(9):
            if c in winners:
                w = winners[c]
                assert v[c] == genomes.v[w]
                np.testing.assert_array_equal(np.asarray(rep.genotypes.u)[c], genomes.u[w])
                np.testing.assert_array_equal(np.asarray(rep.extra_scores["raw"])[c], raw[w])
                assert np.asarray(rep.fitnesses)[c, 0] == fit[w]
            else:
                assert v[c] == old_v[c]


def test_saturated_evolve_elites_re_derive_their_cells():
    gen = uv_gen()
    c = cfg(generations=6, batch_size=32, initial_population=32)
    arch = A.evolve(gen, desc2, c, jax.random.key(0), fitness_fn=saturated, traversable_fn=always, progress=False)
    f = arch.fitness[arch.filled]
    assert A.coverage(arch) > 50 and np.mean(f == 1.0) > 0.5  # saturated: ties everywhere
    assert arch.metrics["inserted"][1:].sum() > 0
    ok = A.check_cells(arch, gens={"uv": gen}, descriptor_fn=desc2)
    assert ok.all()
    cells, raw = A.rederive_cells(arch, gens={"uv": gen}, descriptor_fn=desc2)
    np.testing.assert_array_equal(cells[arch.filled], np.flatnonzero(arch.filled))
    np.testing.assert_allclose(raw[arch.filled], arch.descriptors[arch.filled], atol=1e-6)  # own descriptors


def test_check_cells_flags_a_mixed_genome():
    gen = uv_gen()
    c = cfg(generations=2, batch_size=16, initial_population=16)
    arch = A.evolve(gen, desc2, c, jax.random.key(1), fitness_fn=smooth, traversable_fn=always, progress=False)
    i = int(np.flatnonzero(arch.filled)[0])
    ca, cb = arch.centroids[(i + 5) % arch.fitness.size]  # a genome of another cell written into cell i
    mixed = arch._replace(genomes=(UV(arch.genomes[0].u.copy(), arch.genomes[0].v.copy()),))
    mixed.genomes[0].u[i] = ca + cb - 0.5
    mixed.genomes[0].v[i] = ca - cb + 0.5
    ok = A.check_cells(mixed, gens={"uv": gen}, descriptor_fn=desc2)
    assert not ok[i] and ok.sum() == arch.fitness.size - 1


def test_reseat_moves_refuses_and_resolves_collisions_like_insert():
    c = cfg(generations=3, batch_size=16, initial_population=32)
    arch = A.evolve(uv_gen(), desc2, c, jax.random.key(2), fitness_fn=smooth, traversable_fn=always, progress=False)
    filled = np.flatnonzero(arch.filled)
    assert filled.size >= 4
    i, j, k = (int(x) for x in filled[:3])
    u, v = arch.genomes[0].u.copy(), arch.genomes[0].v.copy()
    u[i], v[i] = u[j], v[j]  # cell i holds a copy of cell j's genome: it belongs in cell j
    v[k] = 7.0  # cell k's genome is refused (out of range for this generator)

    def validate(g):
        if np.any(np.asarray(g.v) > 1.0):
            raise ValueError("v out of range")

    gen = uv_gen()._replace(validate=validate)
    broken = arch._replace(genomes=(UV(u, v),))
    fitness = np.where(arch.filled, 0.5, np.nan).astype(np.float32)
    fitness[i] = 0.9  # the copy in cell i is fitter than the original in cell j: it wins cell j
    out, counts = A.reseat(broken, fitness, gens={"uv": gen}, descriptor_fn=desc2)
    assert counts == {"elites": filled.size, "refused": 1, "unmeasured": 0, "moved": 1, "displaced": 1,
                      "kept": filled.size - 2}
    assert out.source[i] == -1 and out.source[k] == -1 and out.fitness[j] == np.float32(0.9)
    assert out.genomes[0].u[j] == u[j] and out.genomes[0].v[j] == v[j]
    assert A.check_cells(out, gens={"uv": gen}, descriptor_fn=desc2).all()
    rest = [int(x) for x in filled if int(x) not in (i, j, k)]
    np.testing.assert_array_equal(out.fitness[rest], 0.5)
    np.testing.assert_allclose(out.descriptors[rest], arch.descriptors[rest], atol=1e-6)
    # ties: an equal copy loses to the lower source cell; a NaN fitness is not measured and drops the elite
    fitness[i] = 0.5
    fitness[rest[0]] = np.nan
    out2, counts2 = A.reseat(broken, fitness, gens={"uv": gen}, descriptor_fn=desc2)
    assert counts2["unmeasured"] == 1 and out2.source[rest[0]] == -1
    np.testing.assert_array_equal(out2.source[j], 0)  # the winner of cell j is min(i, j)'s genome; both equal
    with pytest.raises(ValueError, match="fitness must have shape"):
        A.reseat(broken, fitness[:3], gens={"uv": gen}, descriptor_fn=desc2)
    from jaxterrain import difficulty

    out3, _ = A.reseat(broken, fitness, gens={"uv": gen}, descriptor_fn=desc2, protocol=difficulty.HEADINGS)
    assert (out3.config.attempts, out3.config.best, out3.config.headings) == (80, 5, 4)  # recorded with the fitness
    assert out3.config.spawn == broken.config.spawn == "feet"  # kept without spawn=, else the rule given
    assert A.reseat(broken, fitness, gens={"uv": gen}, descriptor_fn=desc2, spawn="patch")[0].config.spawn == "patch"
    with pytest.raises(ValueError, match="start_spread"):
        A.reseat(broken, fitness, gens={"uv": gen}, descriptor_fn=desc2, protocol=difficulty.Protocol(start_spread=1.0))


def test_evolve_config_headings_choose_the_walker_fitness_protocol():
    """``EvolveConfig.headings``: checked with attempts and best, default 1 for dicts written before it, and the
    config's walker fitness is ``difficulty.fitness_fn`` under ``Protocol(attempts, best, headings)``."""
    from jaxterrain import difficulty
    from jaxterrain.qd import evolution
    from jaxterrain.qd.config import config_from_dict, config_to_dict

    c = A.resolve_config(A.EvolveConfig(attempts=80, best=5, headings=4))
    assert config_from_dict(config_to_dict(c)) == c
    old = config_to_dict(A.resolve_config(A.EvolveConfig()))
    del old["headings"]
    assert config_from_dict(old).headings == 1
    for bad, match in ((dict(headings=3), r"headings must be one of \(1, 2, 4\)"),
                       (dict(attempts=30, headings=4), "multiple"), (dict(attempts=20, best=6, headings=4),
                                                                    r"attempts / headings \(5\)")):
        with pytest.raises(ValueError, match=match):
            A.resolve_config(A.EvolveConfig(**bad))
    assert evolution.default_fitness(256, c) is difficulty.fitness_fn(256, difficulty.HEADINGS, c.scale)


# ----------------------------------------------------------------------------------------------------------------
# several treatments
# ----------------------------------------------------------------------------------------------------------------


def problem(gen, fitness, config, pair):
    scoring = S.make_scoring_fn(gen, desc3, always, fitness, config, pair)
    return scoring, ME.Emitter(gen.sample, gen.mutate, config.batch_size, config.initial_population)


def one_run(gen, fitness, config, pair, key, generations):
    scoring, emitter = problem(gen, fitness, config, pair)
    state, _ = ME.init(key, scoring, emitter, A.centroids_for(config))
    state, m = jax.lax.scan(lambda s, _: ME.step(s, key, scoring, emitter), state, None, length=generations)
    return state, m


PAIRS = ((0, 1), (0, 2))
RANGES = {(0, 1): ((0.0, 1.0), (0.0, 1.0)), (0, 2): ((0.0, 1.0), (0.0, 0.5))}


def assert_tree_equal(a, b):
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def test_vmapped_seeds_and_pairs_equal_the_runs_one_by_one():
    gen = uv_gen()
    keys = [jax.random.key(s) for s in (3, 4)]
    treat = [(k, p) for k in keys for p in PAIRS]
    configs = [cfg(ranges=RANGES[p]) for _, p in treat]
    scoring, emitter = problem(gen, saturated, configs[0], (0, 1))
    tasks = jax.tree.map(lambda *x: jnp.stack(x), *[S.task_for(c, p) for c, (_, p) in zip(configs, treat)])
    cents = jnp.stack([A.centroids_for(c) for c in configs])
    ks = jnp.stack([k for k, _ in treat])

    @jax.jit
    def batched(ks, cents, tasks):
        states, _ = jax.vmap(lambda k, c, t: ME.init(k, scoring, emitter, c, t))(ks, cents, tasks)
        step = jax.vmap(lambda s, k: ME.step(s, k, scoring, emitter))
        return jax.lax.scan(lambda s, _: step(s, ks), states, None, length=3)

    states, metrics = batched(ks, cents, tasks)
    for i, ((k, p), c) in enumerate(zip(treat, configs)):
        single, m = jax.jit(lambda k, c=c, p=p: one_run(gen, saturated, c, p, k, 3))(k)
        assert_tree_equal(jax.tree.map(lambda x: x[i], states), single)
        assert_tree_equal(jax.tree.map(lambda x: x[:, i], metrics), m)
    assert len({float(x) for x in np.asarray(metrics["coverage"])[-1]}) > 1  # the treatments differ


def test_combined_generators_step_equals_separate_steps():
    gens = [uv_gen(), vec_gen()]
    keys = [jnp.stack([jax.random.key(10 + 2 * g + t) for t in range(2)]) for g in range(2)]
    configs = [cfg(ranges=RANGES[p]) for p in PAIRS]
    scorings, emitters, states = [], [], []
    for g, gen in enumerate(gens):
        scoring, emitter = problem(gen, smooth, configs[0], (0, 1))
        init = jax.jit(lambda k, c, task, scoring=scoring, emitter=emitter: ME.init(k, scoring, emitter, c, task)[0])
        group = [init(keys[g][t], A.centroids_for(c), S.task_for(c, p))  # one compile per generator
                 for t, (c, p) in enumerate(zip(configs, PAIRS))]
        scorings.append(scoring)
        emitters.append(emitter)
        states.append(jax.tree.map(lambda *x: jnp.stack(x), *group))

    @jax.jit
    def combined(states):
        def body(st, _):
            return ME.multi_step(st, keys, jax.random.key(99), scorings, emitters, smooth)
        return jax.lax.scan(body, states, None, length=3)

    out, metrics = combined(states)
    for g in range(2):
        for t in range(2):
            st = jax.tree.map(lambda x: x[t], states[g])
            single, m = jax.jit(lambda s, k: jax.lax.scan(
                lambda s, _: ME.step(s, k, scorings[g], emitters[g]), s, None, length=3))(st, keys[g][t])
            assert_tree_equal(jax.tree.map(lambda x: x[t], out[g]), single)
            assert_tree_equal(jax.tree.map(lambda x: x[:, t], metrics[g]), m)
    with pytest.raises(ValueError, match="one length"):
        ME.multi_step(states, keys[:1], jax.random.key(0), scorings, emitters, smooth)


@pytest.mark.slow  # 10-70 s on 2 CPU cores; the default suite keeps under 15 min (2026-11-29)
def test_evolve_many_resumes_to_the_same_archives(tmp_path):
    """evolve_many: one archive per treatment, each elite in its own cell; a killed run resumes to the same
    archives (two generators, 32 x 32, a slope fitness: no walker)."""
    config = A.EvolveConfig(generations=2, batch_size=4, initial_population=6, bins=4, window=8, stride=2,
                            checkpoint_every=1, store_heightmaps=False)
    ranges = {"tri": (0.0, 0.5), "tpi": (-0.02, 0.02), "roughness": (0.0, 1.0)}  # coverage --preset smoke's
    treatments = [A.Treatment(g, p, jax.random.key(i)) for i, (g, p) in
                  enumerate([("perlin", ("tri", "tpi")), ("perlin", ("tpi", "roughness")),
                             ("diamond_square", ("tri", "tpi"))])]
    slope = S.ignore_needed(lambda hm, key: 1.0 - jnp.mean(jnp.abs(jnp.diff(hm, axis=-1)), axis=(1, 2)) * 10)
    kw = dict(fitness_fn=slope, generator_options={"size": 32}, ranges=ranges, compile_cache={})
    archs = A.evolve_many(treatments, config, jax.random.key(9), progress=False, **kw)
    assert [a.generator_names for a in archs] == [("perlin",), ("perlin",), ("diamond_square",)]
    assert archs[1].config.descriptors == ("tpi", "roughness") and archs[1].config.ranges == (ranges["tpi"],
                                                                                                ranges["roughness"])
    for a in archs:
        assert A.coverage(a) > 0 and a.metrics["coverage"].shape == (3,)
        assert A.check_cells(a, generator_options={"size": 32}).all()
    calls = []

    def dying(info):
        calls.append(info)
        if len(calls) == 1:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        A.evolve_many(treatments, config, jax.random.key(9), checkpoint_dir=tmp_path / "ck", progress=dying, **kw)
    resumed = A.evolve_many(treatments, config, jax.random.key(9), checkpoint_dir=tmp_path / "ck", progress=False,
                            **kw)
    for a, b in zip(archs, resumed):
        np.testing.assert_array_equal(a.fitness, b.fitness)
        np.testing.assert_array_equal(a.genomes[0] if not isinstance(a.genomes[0], tuple) else a.genomes[0][0],
                                      b.genomes[0] if not isinstance(b.genomes[0], tuple) else b.genomes[0][0])
        for k in a.metrics:
            np.testing.assert_array_equal(a.metrics[k], b.metrics[k])
