"""MAP-Elites archives: insertion, Algorithm 1, mutation, resume, combine, save/load, evolve end to end.

A fake generator makes every quantity exact: genome [a, b, count] renders to the plane a * x / n + b * y / n, whose
two "descriptors" read back a and b, fitness is 1 - (a + b) / 2, and mutate adds exactly 1 to ``count``.
"""

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




class PairGenome(NamedTuple):  # a pytree genome, like the CPPN's
    ab: jax.Array
    count: jax.Array


def make_gen(size=8, name="fake", spread=1.0):
    return _make_gen(size, name, spread)


import functools  # noqa: E402
from jaxterrain import difficulty


@functools.lru_cache(maxsize=None)
def _make_gen(size, name, spread):
    yy, xx = np.mgrid[0:size, 0:size].astype(np.float32)

    def render_one(g):
        return g[0] * xx / size + g[1] * yy / size

    def sample(key, n):
        return jnp.concatenate([jax.random.uniform(key, (n, 2)) * spread, jnp.zeros((n, 1))], axis=1)

    def mutate(key, g):
        noise = 0.1 * jax.random.normal(key, g[:, :2].shape)
        return jnp.concatenate([jnp.clip(g[:, :2] + noise, 0.0, 1.0), g[:, 2:] + 1.0], axis=1)

    return FakeGen(name, None, size, sample, mutate, jax.vmap(render_one), render_one, lambda g: None)


def desc(hm):
    n = hm.shape[-1]
    return jnp.stack([(hm[:, 0, 1] - hm[:, 0, 0]) * n, (hm[:, 1, 0] - hm[:, 0, 0]) * n], -1)


def fitness(hm, key):
    return 1.0 - desc(hm).mean(-1)


FITNESS = S.ignore_needed(fitness)
CACHE: dict = {}  # compiled programs shared by the runs of these tests


def always(hm):
    return jnp.ones(hm.shape[0], bool)


CFG = A.EvolveConfig(generations=6, batch_size=8, initial_population=10, bins=4, ranges=((0.0, 1.0), (0.0, 1.0)),
                     checkpoint_every=2, store_heightmaps=False, descriptors=("a", "b"))


def run(cfg=CFG, key=0, gen=None, **kw):
    kw.setdefault("traversable_fn", always)
    kw.setdefault("compile_cache", CACHE)
    kw.setdefault("progress", False)
    return A.evolve(gen or make_gen(), desc, cfg, jax.random.key(key), fitness_fn=FITNESS, **kw)


def fixed_problem(genomes, fit, trav, cfg):
    """(scoring, emitter) whose evaluation returns given values (descriptors = genome a, b)."""
    gen = make_gen()
    scoring = S.Scoring(gen.render_one, desc, lambda hm: jnp.asarray(trav),
                        S.ignore_needed(lambda hm, k: jnp.asarray(fit, jnp.float32)), S.task_for(cfg))
    return scoring, ME.Emitter(lambda k, n: genomes, gen.mutate, len(genomes), len(genomes))


def init_rep(cfg, genomes, fit, trav):
    scoring, emitter = fixed_problem(jnp.asarray(genomes, jnp.float32), fit, trav, cfg)
    state, metrics = jax.jit(lambda k: ME.init(k, scoring, emitter, A.centroids_for(cfg)))(jax.random.key(0))
    return state.repertoire, metrics


def insert(rep, cfg, genomes, fit, trav=None):
    genomes = jnp.asarray(genomes, jnp.float32)
    trav = np.ones(len(genomes), bool) if trav is None else trav
    scoring, _ = fixed_problem(genomes, fit, trav, cfg)
    f, cell, extras = scoring(genomes, jax.random.key(0))
    return jax.jit(ME.insert)(rep, genomes, cell, f, extras["raw"])[0], extras


def test_exact_insertion_better_replaces_worse_and_nan_do_not():
    cfg = A.resolve_config(CFG._replace(bins=2))
    # cells of a 2 x 2 grid over [0, 1]^2: cell = 2 * (b >= .5) + (a >= .5)
    rep, metrics = init_rep(cfg, [[0.1, 0.1, 0.0], [0.9, 0.1, 0.0]], [0.5, 0.4], [True, True])
    np.testing.assert_array_equal(np.asarray(rep.fitnesses)[:, 0], np.float32([0.5, 0.4, -np.inf, -np.inf]))
    assert float(metrics["coverage"]) == 50.0 and float(metrics["qd_score"]) == pytest.approx(0.9)
    # better (0.7) replaces cell 0, worse (0.3) does not touch cell 1, NaN never enters cell 2 nor blocks cell 3's
    # valid candidate; within one batch the best of a cell wins (0.7 over 0.6)
    batch = [[0.2, 0.2, 1.0], [0.15, 0.1, 2.0], [0.8, 0.3, 3.0], [0.1, 0.9, 4.0], [0.9, 0.9, 5.0], [0.8, 0.8, 6.0]]
    fit = [0.7, 0.6, 0.3, np.nan, np.nan, 0.2]
    rep, counts = insert(rep, cfg, batch, fit)
    f = np.asarray(rep.fitnesses)[:, 0]
    np.testing.assert_allclose(f, [0.7, 0.4, -np.inf, 0.2])
    g = np.asarray(rep.genotypes)
    np.testing.assert_array_equal(g[0], np.float32([0.2, 0.2, 1.0]))
    np.testing.assert_array_equal(g[1], np.float32([0.9, 0.1, 0.0]))
    np.testing.assert_array_equal(g[3], np.float32([0.8, 0.8, 6.0]))
    assert float(counts["nan"]) == 2
    # equal fitness does not replace (strictly better only)
    rep, _ = insert(rep, cfg, [[0.3, 0.3, 9.0]], [0.7])
    np.testing.assert_array_equal(np.asarray(rep.genotypes)[0], np.float32([0.2, 0.2, 1.0]))


def test_out_of_range_clip_and_reject():
    cfg = A.resolve_config(CFG._replace(bins=2, ranges=((0.0, 0.5), (0.0, 0.5))))
    rep0, _ = init_rep(cfg, [[0.1, 0.1, 0.0]], [0.1], [True])
    rep, counts = insert(rep0, cfg, [[0.9, 0.1, 1.0]], [0.5])  # a = 0.9 > 0.5: clipped into the a-edge cell 1
    assert float(counts["out_of_range"]) == 1
    assert np.asarray(rep.fitnesses)[1, 0] == 0.5
    np.testing.assert_allclose(np.asarray(rep.extra_scores["raw"])[1], [0.9, 0.1])  # raw value kept
    rej = cfg._replace(out_of_range="reject")
    rep, counts = insert(rep0, rej, [[0.9, 0.1, 1.0]], [0.5])
    assert float(counts["out_of_range"]) == 1 and np.asarray(rep.fitnesses)[1, 0] == -np.inf


def test_algorithm1_rejections_counted_and_never_inserted():
    gen = make_gen()

    def trav(hm):  # "not traversable" when a > 0.3
        return desc(hm)[:, 0] <= 0.3

    cfg = CFG._replace(generations=8, initial_population=40)
    arch = run(cfg, key=3, traversable_fn=trav)
    # generation 0 evaluates sample(split(fold_in(key, 0), 3)[0], 40): count the rejections independently
    sample_key = jax.random.split(jax.random.fold_in(jax.random.key(3), 0), 3)[0]
    a = np.asarray(gen.sample(sample_key, 40))[:, 0]
    assert arch.metrics["rejected"][0] == np.sum(a > 0.3) > 0
    elites = arch.genomes[0][arch.filled]
    assert np.all(elites[:, 0] <= 0.3)
    assert np.all(arch.descriptors[arch.filled][:, 0] <= 0.3 + 1e-6)
    assert arch.metrics["rejected"].sum() > arch.metrics["rejected"][0]  # offspring rejected too
    assert arch.metrics["rejected"].shape == (9,)


def test_fitness_is_told_which_offspring_can_enter():
    """A fitness with a ``needed`` keyword gets Algorithm 1's verdict (and, with out_of_range="reject", the range
    check): here it returns NaN for the terrains it was told it need not score, and none of them is needed."""

    def trav(hm):
        return desc(hm)[:, 0] <= 0.3

    seen = []

    def lazy_fitness(hm, key, needed=None):
        seen.append(needed is not None)
        return jnp.where(needed, fitness(hm, key), jnp.nan)

    cfg = CFG._replace(generations=4, initial_population=40)
    arch = A.evolve(make_gen(), desc, cfg, jax.random.key(3), fitness_fn=lazy_fitness, traversable_fn=trav,
                    progress=False, compile_cache=CACHE)
    assert seen and all(seen)
    assert arch.metrics["rejected"].sum() > 0 and arch.metrics["nan"].sum() == 0
    reference = run(cfg, key=3, traversable_fn=trav)
    np.testing.assert_array_equal(arch.fitness, reference.fitness)


def test_offspring_come_from_the_generators_mutate():
    arch = run(CFG._replace(generations=10))
    counts = arch.genomes[0][arch.filled][:, 2]
    # mutate adds exactly 1 per generation of descent: only mutate can make count > 0
    np.testing.assert_array_equal(counts, np.round(counts))
    assert counts.max() >= 1 and counts.max() <= 10
    assert np.asarray(arch.metrics["inserted"][1:]).sum() > 0


def test_all_rejected_archive_restarts_from_random_genomes():
    never = lambda hm: jnp.zeros(hm.shape[0], bool)  # noqa: E731
    arch = run(CFG._replace(generations=3), traversable_fn=never)
    assert A.coverage(arch) == 0.0
    np.testing.assert_array_equal(arch.metrics["rejected"], [10, 8, 8, 8])
    assert np.all(np.isnan(arch.metrics["max_fitness"]))


def test_metrics_match_the_final_archive():
    arch = run()
    m = arch.metrics
    assert m["coverage"].shape == (CFG.generations + 1,)
    assert m["coverage"][-1] == pytest.approx(A.coverage(arch))
    assert m["qd_score"][-1] == pytest.approx(A.qd_score(arch), rel=1e-5)
    assert m["max_fitness"][-1] == pytest.approx(arch.fitness[arch.filled].max())
    assert m["mean_fitness"][-1] == pytest.approx(arch.fitness[arch.filled].mean(), rel=1e-5)
    assert np.all(np.diff(m["qd_score"]) >= -1e-6)  # MAP-Elites never loses quality
    # each elite's fitness is the fitness of its own genome (no mixing of rows)
    g = arch.genomes[0][arch.filled]
    np.testing.assert_allclose(arch.fitness[arch.filled], 1.0 - g[:, :2].mean(1), rtol=1e-5)
    np.testing.assert_allclose(arch.descriptors[arch.filled], g[:, :2], atol=1e-5)


def _assert_same(a, b):
    for x, y in zip(jax.tree.leaves(a.genomes), jax.tree.leaves(b.genomes)):
        np.testing.assert_array_equal(x, y)
    np.testing.assert_array_equal(a.fitness, b.fitness)
    np.testing.assert_array_equal(a.descriptors, b.descriptors)
    np.testing.assert_array_equal(a.source, b.source)
    assert a.metrics.keys() == b.metrics.keys()
    for k in a.metrics:
        np.testing.assert_array_equal(a.metrics[k], b.metrics[k])


def test_resume_equals_uninterrupted(tmp_path, monkeypatch):
    full = run()
    # a run killed after its second checkpoint (generation 2): progress is reported after each checkpoint
    calls = []

    def dying_progress(info):
        calls.append(info)
        if len(calls) == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run(checkpoint_dir=tmp_path, progress=dying_progress)
    assert calls[-1]["generation"] == 2
    # ... resumes with another chunking and ends bit-equal to the uninterrupted run
    resumed = run(CFG._replace(checkpoint_every=3), checkpoint_dir=tmp_path)
    _assert_same(full, resumed)
    # a shorter run extended later is also the same run
    short = run(CFG._replace(generations=3), checkpoint_dir=tmp_path / "b")
    extended = run(checkpoint_dir=tmp_path / "b")
    assert short.metrics["coverage"].shape == (4,)
    _assert_same(full, extended)
    # a different key or config is refused clearly
    with pytest.raises(ValueError, match="another PRNG key"):
        run(key=1, checkpoint_dir=tmp_path)
    with pytest.raises(ValueError, match="another config"):
        run(CFG._replace(batch_size=4), checkpoint_dir=tmp_path)


def _hand_archive(name, fit, genomes, cfg=None):
    cfg = A.resolve_config(cfg or CFG._replace(bins=2))
    fit = np.asarray(fit, np.float32)
    filled = np.isfinite(fit)
    return A.Archive(
        genomes=(genomes,), generator_names=(name,), source=np.where(filled, 0, -1).astype(np.int32),
        fitness=np.where(filled, fit, -np.inf).astype(np.float32),
        descriptors=np.tile(np.float32(np.arange(4))[:, None], (1, 2)) + (0.5 if name == "q" else 0.0),
        centroids=np.asarray(A.centroids_for(cfg)), heightmaps=np.full((4, 3, 3), ord(name[0]), np.uint16),
        config=cfg, metrics={},
    )


def test_combine_keeps_max_fitness_and_source():
    inf = np.inf
    p = _hand_archive("p", [0.5, -inf, 0.9, 0.2], np.arange(12, dtype=np.float32).reshape(4, 3))
    q = _hand_archive("q", [0.7, 0.3, 0.1, -inf], PairGenome(np.full((4, 2), 7.0, np.float32),
                                                            np.arange(4, dtype=np.int32)))
    c = A.combine([p, q])
    assert c.generator_names == ("p", "q")
    np.testing.assert_array_equal(c.source, [1, 1, 0, 0])
    np.testing.assert_allclose(c.fitness, [0.7, 0.3, 0.9, 0.2])
    np.testing.assert_allclose(c.descriptors[:, 0], [0.5, 1.5, 2.0, 3.0])
    np.testing.assert_array_equal(c.heightmaps[:, 0, 0], [ord("q"), ord("q"), ord("p"), ord("p")])
    np.testing.assert_array_equal(c.genomes[0][2:], p.genomes[0][2:])
    np.testing.assert_array_equal(c.genomes[0][:2], 0)  # cells now held by q
    np.testing.assert_array_equal(c.genomes[1].count, [0, 1, 0, 0])
    assert A.elite(c, 1)[0] == "q" and A.elite(c, 2)[0] == "p"
    np.testing.assert_array_equal(A.elite(c, 2)[1], [6.0, 7.0, 8.0])
    assert A.coverage(c) == 100.0
    # an empty cell in both stays empty; archives of other grids are refused
    r = _hand_archive("r", [-inf, -inf, -inf, -inf], np.zeros((4, 3), np.float32))
    assert A.coverage(A.combine([r])) == 0.0
    other = _hand_archive("o", [0.1] * 4, np.zeros((4, 3), np.float32), CFG._replace(bins=2, ranges=((0, 2), (0, 1))))
    with pytest.raises(ValueError, match="must share"):
        A.combine([p, other])
    with pytest.raises(ValueError, match="non-empty"):
        A.combine([])


def test_save_load_round_trip_and_corrupt_files(tmp_path):
    arch = run(CFG._replace(store_heightmaps=True))
    assert arch.heightmaps.shape == (16, 8, 8) and arch.heightmaps.dtype == np.uint16
    # stored heightmaps are the renders of the stored genomes
    i = int(np.flatnonzero(arch.filled)[0])
    np.testing.assert_allclose(A.heightmaps(arch)[i], make_gen().render_one(arch.genomes[0][i]), atol=2e-5)
    path = A.save(tmp_path / "a.npz", arch)
    back = A.load(path)
    _assert_same(arch, back)
    np.testing.assert_array_equal(back.heightmaps, arch.heightmaps)
    assert back.config == arch.config and back.generator_names == ("fake",)
    # pytree genomes (NamedTuple) and a combined archive
    q = _hand_archive("q", [0.7, 0.3, 0.1, -np.inf], PairGenome(np.full((4, 2), 7.0, np.float32),
                                                               np.arange(4, dtype=np.int32)))
    p = _hand_archive("p", [0.5, 0.4, 0.9, 0.2], np.arange(12, dtype=np.float32).reshape(4, 3))
    c = A.combine([p, q])
    back = A.load(A.save(tmp_path / "c.npz", c))
    assert isinstance(back.genomes[1], PairGenome) and back.genomes[1].count.dtype == np.int32
    _assert_same(c, back)
    np.testing.assert_array_equal(back.heightmaps, c.heightmaps)
    # truncated, garbage, wrong format
    data = (tmp_path / "a.npz").read_bytes()
    (tmp_path / "t.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="truncated or corrupt"):
        A.load(tmp_path / "t.npz")
    (tmp_path / "g.npz").write_bytes(b"not an archive at all")
    with pytest.raises(ValueError, match=r"g.npz': not an .npz archive file \(no zip header\)"):
        A.load(tmp_path / "g.npz")
    np.savez(tmp_path / "w.npz", header=np.frombuffer(b'{"format": "something-else"}', np.uint8))
    with pytest.raises(ValueError, match="not a jaxterrain archive"):
        A.load(tmp_path / "w.npz")
    z = dict(np.load(tmp_path / "a.npz"))
    z["fitness"] = z["fitness"][:5]
    np.savez(tmp_path / "s.npz", **z)
    with pytest.raises(ValueError, match="'fitness' has shape"):
        A.load(tmp_path / "s.npz")
    with pytest.raises(FileNotFoundError):
        A.load(tmp_path / "missing.npz")


def test_config_validation():
    with pytest.raises(ValueError, match="batch_size"):
        A.resolve_config(CFG._replace(batch_size=0))
    with pytest.raises(ValueError, match="out_of_range"):
        A.resolve_config(CFG._replace(out_of_range="wrap"))
    with pytest.raises(ValueError, match="no default range"):
        A.resolve_config(CFG._replace(ranges=None))
    with pytest.raises(ValueError, match="rollout_slots"):
        A.resolve_config(CFG._replace(rollout_slots=0))
    with pytest.raises(ValueError, match="hi > lo"):
        A.resolve_config(CFG._replace(ranges=((1.0, 0.0), (0.0, 1.0))))
    cfg = A.resolve_config(A.EvolveConfig(descriptors=("tpi", "tri")))
    assert cfg.ranges == (A.DEFAULT_RANGES["tpi"], A.DEFAULT_RANGES["tri"])
    assert A.config_from_dict(A.config_to_dict(cfg)) == cfg


def test_cppn_pytree_genomes_round_trip(tmp_path):
    from jaxterrain import generators

    gen = generators.get("cppn", size=16, max_nodes=8, max_connections=16)
    cfg = A.resolve_config(CFG._replace(bins=3))
    genomes = jax.tree.map(np.asarray, gen.sample(jax.random.key(0), 9))
    fit = np.float32([0.1, -np.inf, 0.3, 0.4, -np.inf, 0.6, 0.7, 0.8, 0.9])
    filled = np.isfinite(fit)
    arch = A.Archive((genomes,), ("cppn",), np.where(filled, 0, -1).astype(np.int32), fit,
                     np.zeros((9, 2), np.float32), np.asarray(A.centroids_for(cfg)),
                     A.render_elites(gen, genomes, filled), cfg, {"coverage": np.float32([1.0, 2.0])})
    back = A.load(A.save(tmp_path / "cppn.npz", arch))
    assert type(back.genomes[0]) is type(genomes)
    _assert_same(arch, back)
    np.testing.assert_array_equal(back.heightmaps[~filled], 0)
    np.testing.assert_allclose(A.heightmaps(back)[5], gen.render_one(jax.tree.map(lambda x: x[5], back.genomes[0])),
                               atol=2e-5)


@pytest.mark.slow
def test_cppn_evolve(tmp_path):
    from jaxterrain import generators

    gen = generators.get("cppn", size=16, max_nodes=8, max_connections=16)

    def cheap(hm, key):
        return 1.0 - jnp.mean(jnp.abs(jnp.diff(hm, axis=-1)), axis=(1, 2)) * 10.0

    def d2(hm):
        return jnp.stack([hm.mean((1, 2)), hm.std((1, 2))], -1)

    cfg = A.EvolveConfig(generations=4, batch_size=4, initial_population=6, bins=3, ranges=((0, 1), (0, 0.5)),
                         checkpoint_every=2, descriptors=("mean", "std"))
    arch = A.evolve(gen, d2, cfg, jax.random.key(0), fitness_fn=S.ignore_needed(cheap), traversable_fn=always,
                    progress=False)
    assert type(arch.genomes[0]).__name__ == "CPPNGenome"
    assert A.coverage(arch) > 0
    _assert_same(arch, A.load(A.save(tmp_path / "cppn.npz", arch)))


def test_evolve_smoke_preset_end_to_end(tmp_path):
    """A smoke-sized run (``evolve --preset smoke``'s grid) with the real generator, descriptors and Algorithm 1,
    cheap fitness."""
    cfg = A.EvolveConfig(generations=4, batch_size=8, initial_population=16, bins=10, window=8, stride=2, attempts=2,
                         best=1, checkpoint_every=2, ranges=((0.0, 0.5), (-0.02, 0.02)))
    arch = A.evolve("perlin", ("roughness", "tpi"), cfg._replace(generations=2), jax.random.key(0),
                    fitness_fn=S.ignore_needed(difficulty.slope_fitness), checkpoint_dir=tmp_path, progress=False,
                    generator_options={"size": 32})
    assert arch.fitness.shape == (cfg.bins**2,) and A.coverage(arch) > 0
    f = arch.fitness[arch.filled]
    assert np.all((f >= 0) & (f <= 1))
    np.testing.assert_allclose(f, difficulty.slope_fitness(jnp.asarray(A.heightmaps(arch)[arch.filled]), None), atol=1e-3)
