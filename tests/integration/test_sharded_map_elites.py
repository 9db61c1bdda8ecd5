"""MAP-Elites over 4 forced CPU devices (a subprocess: XLA_FLAGS must precede jax's start): the offspring rows split
over the devices with per-row keys give the archive of one device bit for bit, for one treatment (evolve) and for
several at once (evolve_many); an uneven batch is padded and the padding never enters."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest
from devices import run_on_devices

TESTS = str(Path(__file__).resolve().parents[1] / "qd")  # the unit tests whose fixtures the script reuses

SCRIPT = textwrap.dedent("""
    import sys
    sys.path.insert(0, TESTS)
    import jax, jax.numpy as jnp, numpy as np
    from jaxterrain import qd as A
    from jaxterrain.qd import scoring as S
    from jaxterrain.runtime import sharding as SH
    from test_map_elites import uv_gen, vec_gen, desc2, desc3, always, smooth, cfg

    assert len(jax.devices()) == 4
    calls = []

    def noisy(hm, key, needed):  # depends on the key: equal archives need the same key per row on any device count
        calls.append(hm.shape[0])
        return 0.5 * smooth(hm, key, needed) + 0.5 * jax.random.uniform(key, (hm.shape[0],))

    def rejects_b(hm):  # Algorithm 1 stand-in that rejects some terrains (counts must not see the padding)
        return desc3(hm)[:, 1] < 0.6

    gen = uv_gen()
    mesh4, mesh1 = SH.make_mesh(), SH.make_mesh(1)

    # the scoring of an uneven batch (7 rows on 4 devices: one padding row) against a hand-made reference
    config = cfg(batch_size=10, initial_population=7, generations=1, checkpoint_every=1)
    scoring = S.make_scoring_fn(gen, desc2, rejects_b, noisy, config, mesh=mesh4, split=SPLIT)
    genomes = gen.sample(jax.random.key(5), 7)
    fitness, cells, extras = jax.jit(lambda g, k: scoring(g, k))(genomes, jax.random.key(6))
    assert calls == [1], calls  # the keyed form scores one row at a time (vmap of batch-1 calls)
    maps = gen.render(genomes)
    keys = jax.random.split(jax.random.key(6), 7)
    ok = np.asarray(rejects_b(maps))
    want = np.asarray(jax.vmap(lambda h, k: noisy(h[None], k, None)[0])(maps, keys))
    assert 0 < ok.sum() < 7
    np.testing.assert_array_equal(np.asarray(fitness), np.where(ok, want, -np.inf))
    assert float(extras["rejected"]) == 7 - ok.sum()  # the padding row (a copy of row 6) is not counted
    np.testing.assert_array_equal(np.asarray(extras["raw"]), np.asarray(desc2(maps)))

    # one treatment: init (7 terrains) and a generation of 10 offspring (padded to 12), 4 devices = 1 device
    run = lambda mesh: A.evolve(gen, desc2, config, jax.random.key(0), fitness_fn=noisy, traversable_fn=rejects_b,
                                progress=False, mesh=mesh, split=SPLIT)
    a4, a1 = run(mesh4), run(mesh1)
    assert A.coverage(a4) > 0 and a4.metrics["inserted"][1] > 0
    for name in ("fitness", "descriptors"):
        np.testing.assert_array_equal(getattr(a4, name), getattr(a1, name))
    np.testing.assert_array_equal(a4.genomes[0].u, a1.genomes[0].u)
    for k in a4.metrics:
        np.testing.assert_array_equal(a4.metrics[k], a1.metrics[k])

    # several treatments of two generators: one keyed fitness call per device per generation
    many = A.EvolveConfig(generations=1, batch_size=5, initial_population=6, bins=4, checkpoint_every=1,
                          store_heightmaps=False)
    treatments = [A.Treatment("uv", ("a", "ab"), jax.random.key(1)), A.Treatment("vec", ("a", "b"), jax.random.key(2))]
    gens = {"uv": uv_gen(), "vec": vec_gen()}
    import jaxterrain.generators as G
    G.get = lambda name, **kw: gens[name]  # the fakes stand in for registered generators
    from jaxterrain.qd import evolution as E
    E.descriptor_fn = lambda names, window, stride: lambda hm: desc3(hm)[:, [("a", "b", "ab").index(n) for n in names]]
    ranges = {"a": (0.0, 1.0), "b": (0.0, 1.0), "ab": (0.0, 0.5)}
    go = lambda mesh: A.evolve_many(treatments, many, jax.random.key(9), fitness_fn=noisy, traversable_fn=always,
                                    progress=False, ranges=ranges, mesh=mesh, split=SPLIT)
    m4, m1 = go(mesh4), go(mesh1)
    for x, y in zip(m4, m1):
        assert A.coverage(x) > 0
        np.testing.assert_array_equal(x.fitness, y.fitness)
        np.testing.assert_array_equal(x.descriptors, y.descriptors)
    assert m4[0].config.descriptors == ("a", "ab") and not np.array_equal(m4[0].fitness, m4[1].fitness)
    print("ok")
""").replace("TESTS", repr(TESTS))


@pytest.mark.parametrize("split", [pytest.param("shard_map", marks=pytest.mark.slow), "dispatch"])
def test_sharded_map_elites_equals_one_device_and_masks_the_padding(split):
    """``dispatch`` (the GPU default): evolve's chunk is a host loop of jitted parts around the scoring, each device
    scoring its rows in its own program; the archives are the same. ``shard_map`` (one program over the devices) is
    in the slow suite: 38 s of the default suite's time on 2 CPU cores."""
    assert run_on_devices(SCRIPT.replace("SPLIT", repr(split))).strip().endswith("ok")


@pytest.mark.parametrize("command", ["evolve", "coverage", "learn", "curriculum", "train-base-policy"])
def test_devices_flag_of_every_long_command(command, tmp_path, capsys):
    """``--devices N`` exists on every long command; more devices than visible, or fewer than 1, is a one-line
    usage error (exit 2) before any run folder is made."""
    from experiments.__main__ import main

    for n, message in (("99", "--devices: num_devices must be an integer in [1, "),
                       ("0", "--devices must be an integer >= 1")):
        with pytest.raises(SystemExit) as exit_:
            main([command, "--devices", n, "--out", str(tmp_path / "run")])
        assert exit_.value.code == 2 and message in capsys.readouterr().err
        assert not (tmp_path / "run").exists()
