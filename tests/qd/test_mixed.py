"""One mixed archive (issue 64, item 3): a MAP-Elites run whose offspring of several generators compete for the same
cells. A mixture renders each genome by its own generator; insertion moves the generator with the genome (a fitter
elite of another generator takes the cell and the cell records it); the run is keyed, resumable and saved as an
ordinary multi-generator archive; old single-generator archives load as before."""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxterrain import generators, qd as A
from jaxterrain.generators.base import Generator as FakeGen  # the library's bundle, fake functions
from jaxterrain.generators.mixed import render_grouped
from jaxterrain.qd import map_elites as ME
from jaxterrain.qd import scoring as S

SIZE = 8
YY, XX = np.mgrid[0:SIZE, 0:SIZE].astype(np.float32)


class Pair(NamedTuple):  # a pytree genome of another shape than the vector one
    a: jax.Array
    b: jax.Array


@functools.lru_cache(maxsize=None)
def plane_gen():
    """Genome [a, b]: the plane a * x / n + b * y / n, a and b in [0, 0.5] (the lower-left of the grid)."""

    def render_one(g):
        return g[0] * XX / SIZE + g[1] * YY / SIZE

    def sample(key, n):
        return jax.random.uniform(key, (n, 2)) * 0.5

    def mutate(key, g):
        return jnp.clip(g + 0.05 * jax.random.normal(key, g.shape), 0.0, 0.5)

    return FakeGen("plane", None, SIZE, sample, mutate, jax.vmap(render_one), render_one, lambda g: None)


@functools.lru_cache(maxsize=None)
def pair_gen():
    """Genome Pair(a [1], b [1]): the same planes, a and b in [0, 1], rendered 0.01 higher (so renders differ)."""

    def render_one(g):
        return g.a[0] * XX / SIZE + g.b[0] * YY / SIZE + 0.01

    def sample(key, n):
        k1, k2 = jax.random.split(key)
        return Pair(jax.random.uniform(k1, (n, 1)), jax.random.uniform(k2, (n, 1)))

    def mutate(key, g):
        k1, k2 = jax.random.split(key)
        return Pair(jnp.clip(g.a + 0.1 * jax.random.normal(k1, g.a.shape), 0, 1),
                    jnp.clip(g.b + 0.1 * jax.random.normal(k2, g.b.shape), 0, 1))

    return FakeGen("pair", None, SIZE, sample, mutate, jax.vmap(render_one), render_one, lambda g: None)


@functools.lru_cache(maxsize=None)
def mix(fresh=1):
    return generators.mixture((plane_gen(), pair_gen()), fresh=fresh)


def desc(hm):
    n = hm.shape[-1]
    return jnp.stack([(hm[:, 0, 1] - hm[:, 0, 0]) * n, (hm[:, 1, 0] - hm[:, 0, 0]) * n], -1)


def fitness(hm, key):
    return 1.0 - desc(hm).mean(-1) + hm[:, 0, 0]  # the pair generator's +0.01 makes it fitter in a shared cell


def always(hm):
    return jnp.ones(hm.shape[0], bool)


CFG = A.EvolveConfig(generations=6, batch_size=8, initial_population=10, bins=4, ranges=((0.0, 1.0), (0.0, 1.0)),
                     checkpoint_every=2, store_heightmaps=True, descriptors=("a", "b"))
CACHE: dict = {}


def run(cfg=CFG, key=0, **kw):
    kw.setdefault("compile_cache", CACHE)
    kw.setdefault("progress", False)
    return A.evolve(mix(), desc, cfg, jax.random.key(key), fitness_fn=S.ignore_needed(fitness),
                    traversable_fn=always, **kw)


def _same(a, b):
    assert a.generator_names == b.generator_names
    for x, y in zip(jax.tree.leaves(a.genomes), jax.tree.leaves(b.genomes)):
        np.testing.assert_array_equal(x, y)
    for name in ("fitness", "descriptors", "source"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert a.metrics.keys() == b.metrics.keys()
    for k in a.metrics:
        np.testing.assert_array_equal(a.metrics[k], b.metrics[k])


def test_each_row_is_rendered_by_its_own_generator():
    m = mix()
    g = m.sample(jax.random.key(0), 7)
    np.testing.assert_array_equal(g.generator, [0, 0, 0, 0, 1, 1, 1])  # equal blocks in component order
    g = g._replace(generator=jnp.asarray([1, 0, 1, 1, 0, 1, 1], jnp.int32))
    want = np.stack([(plane_gen() if k == 0 else pair_gen()).render_one(jax.tree.map(lambda x: x[i], g.slots[k]))
                     for i, k in enumerate(np.asarray(g.generator))])
    for chunk in (1, 2, 3, 64):  # the grouped render: rows sorted by generator, each group in whole chunks
        got = jax.jit(lambda x, c=chunk: render_grouped((plane_gen(), pair_gen()), x, c))(g)
        np.testing.assert_allclose(got, want, atol=1e-6)
    np.testing.assert_allclose(m.render(g), want, atol=1e-6)
    np.testing.assert_allclose(m.render_one(jax.tree.map(lambda x: x[0], g)), want[0], atol=1e-6)
    only = g._replace(generator=jnp.zeros(7, jnp.int32))  # one generator only
    np.testing.assert_allclose(m.render(only)[3], plane_gen().render_one(g.slots[0][3]), atol=1e-6)


def test_mutation_keeps_generators_and_adds_fresh_samples_of_each():
    m = mix(fresh=2)
    parents = m.sample(jax.random.key(0), 8)._replace(generator=jnp.zeros(8, jnp.int32))  # plane only
    kids = m.mutate(jax.random.key(1), parents)
    # the first 4 rows are the parents' mutations (generator kept), the last 2 x 2 fresh samples of each generator
    np.testing.assert_array_equal(kids.generator, [0, 0, 0, 0, 0, 0, 1, 1])
    assert np.all(np.asarray(kids.slots[0][:4]) != np.asarray(parents.slots[0][:4]))
    with pytest.raises(ValueError, match="fresh must be an integer >= 0"):
        generators.mixture(("perlin", "worley"), fresh=-1)
    with pytest.raises(ValueError, match="two or more"):
        generators.mixture(("perlin",))
    with pytest.raises(ValueError, match="distinct"):
        generators.mixture((plane_gen(), plane_gen()))
    with pytest.raises(ValueError, match=r"batch_size must be > 4 for mixed\(plane,pair;fresh=2\)"):
        A.evolve(m, desc, CFG._replace(batch_size=4), jax.random.key(0), fitness_fn=S.ignore_needed(fitness),
                 traversable_fn=always, progress=False)


def test_insertion_across_generators_moves_the_generator_with_the_elite():
    m = mix(fresh=0)
    cfg = A.resolve_config(CFG)
    centroids = A.centroids_for(cfg)
    example = jax.tree.map(lambda x: x[0], m.sample(jax.random.key(0), 2))
    rep = ME.empty_repertoire(example, centroids)
    g = m.sample(jax.random.key(1), 2)  # row 0: plane, row 1: pair
    cell_desc = jnp.asarray([[0.1, 0.1], [0.1, 0.1]], jnp.float32)  # both in cell 0
    insert = jax.jit(ME.insert)
    # the plane elite takes the empty cell
    rep, n = insert(rep, jax.tree.map(lambda x: x[:1], g), cell_desc[:1], jnp.asarray([0.5]), cell_desc[:1])
    assert int(rep.genotypes.generator[0]) == 0 and float(n) == 1
    # a worse pair offspring does not enter; a better one replaces it and the cell records its generator
    rep, n = insert(rep, jax.tree.map(lambda x: x[1:], g), cell_desc[1:], jnp.asarray([0.4]), cell_desc[1:])
    assert int(rep.genotypes.generator[0]) == 0 and float(n) == 0
    rep, n = insert(rep, jax.tree.map(lambda x: x[1:], g), cell_desc[1:], jnp.asarray([0.6]), cell_desc[1:])
    assert int(rep.genotypes.generator[0]) == 1 and float(n) == 1
    np.testing.assert_array_equal(rep.genotypes.slots[1].a[0], g.slots[1].a[1])
    assert float(rep.fitnesses[0, 0]) == pytest.approx(0.6)
    # both in one batch: the fitter one wins, whichever generator it is
    rep2 = ME.empty_repertoire(example, centroids)
    rep2, _ = insert(rep2, g, cell_desc, jnp.asarray([0.9, 0.3]), cell_desc)
    assert int(rep2.genotypes.generator[0]) == 0


def test_mixed_run_archive_records_each_elites_generator(tmp_path):
    arch = run()
    assert arch.generator_names == ("plane", "pair")
    filled = arch.filled
    assert set(np.unique(arch.source[filled])) == {0, 1}  # both generators hold cells
    # every elite re-renders, by its recorded generator, to its own cell and stored heightmap
    gens = {"plane": plane_gen(), "pair": pair_gen()}
    assert A.check_cells(arch, gens=gens, descriptor_fn=desc).all()
    for cell in np.flatnonzero(filled)[:3]:
        name, genome = A.elite(arch, cell)
        np.testing.assert_allclose(A.heightmaps(arch)[cell], gens[name].render_one(genome), atol=2e-5)
    # a slot of a generator that does not hold the cell is zero (the form of qd.combine's archives)
    np.testing.assert_array_equal(arch.genomes[0][arch.source != 0], 0)
    np.testing.assert_array_equal(arch.genomes[1].a[arch.source != 1], 0)
    # the pair generator reaches cells the plane one cannot (a, b > 0.5): only the mixed run's pair elites there
    far = np.asarray(A.centroids_for(A.resolve_config(CFG))).min(axis=1) > 0.5
    assert np.all(arch.source[far & filled] == 1)
    # the file round-trips with the generator of every elite
    back = A.load(A.save(tmp_path / "mixed.npz", arch))
    _same(arch, back)
    np.testing.assert_array_equal(back.heightmaps, arch.heightmaps)
    assert isinstance(back.genomes[1], Pair)
    # same key, same archive; another key, another one
    _same(arch, run())
    assert not np.array_equal(run(key=1).fitness, arch.fitness)


def test_mixed_resume_equals_uninterrupted(tmp_path):
    full = run(CFG._replace(store_heightmaps=False))
    calls = []

    def dying(info):
        calls.append(info)
        if len(calls) == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run(CFG._replace(store_heightmaps=False), checkpoint_dir=tmp_path, progress=dying)
    assert calls[-1]["generation"] == 2
    _same(full, run(CFG._replace(store_heightmaps=False, checkpoint_every=3), checkpoint_dir=tmp_path))
    # a checkpoint of another mixture (other fresh share) is refused
    with pytest.raises(ValueError, match="is of generator"):
        A.evolve(mix(fresh=2), desc, CFG._replace(store_heightmaps=False), jax.random.key(0),
                 fitness_fn=S.ignore_needed(fitness), traversable_fn=always, progress=False, checkpoint_dir=tmp_path)


def test_generator_shares_per_distance_band():
    cfg = A.resolve_config(CFG._replace(bins=4))  # distances hypot(b0 + 1, b1 + 1): 1.41 ... 5.66
    source = np.full(16, -1, np.int32)
    source[[0, 1, 4]] = 0  # near cells (bins (0,0), (1,0), (0,1)): distances 1.41, 2.24, 2.24
    source[[5, 15]] = 1  # bins (1,1): 2.83; (3,3): 5.66
    fit = np.where(source >= 0, 0.5, -np.inf).astype(np.float32)
    arch = A.Archive((np.zeros((16, 2), np.float32), np.zeros((16, 1), np.float32)), ("p", "q"), source, fit,
                     np.zeros((16, 2), np.float32), np.asarray(A.centroids_for(cfg)), None, cfg, {})
    r = A.generator_shares(arch, width=2.5)
    np.testing.assert_array_equal(r["filled"], [3, 1, 1])
    np.testing.assert_array_equal(r["count"], [[3, 0], [0, 1], [0, 1]])
    np.testing.assert_allclose(r["share"], [[1, 0], [0, 1], [0, 1]])
    assert r["cells"].sum() == 16 and list(r["total"]) == [3, 2]
    r = A.generator_shares(arch, width=2.5, names=("q", "x"))  # another order; a generator it lacks counts zero
    np.testing.assert_array_equal(r["count"], [[0, 0], [1, 0], [1, 0]])
    with pytest.raises(ValueError, match="width must be a finite number > 0"):
        A.generator_shares(arch, width=0)


def test_old_single_generator_archive_loads_unchanged():
    """An archive written before mixed runs existed (the shipped Perlin HEADINGS archive): the same format, one
    generator, every elite generator 0; its shares are all Perlin's."""
    from pathlib import Path

    arch = A.load(Path(__file__).resolve().parents[2] / "docs/results/exp2_perlin_headings_archive.npz")
    assert arch.generator_names == ("perlin",) and set(np.unique(arch.source)) <= {-1, 0}
    r = A.generator_shares(arch)
    np.testing.assert_array_equal(r["count"][:, 0], r["filled"])
    assert r["filled"].sum() == arch.filled.sum()
