"""A mixed MAP-Elites run (``generators.mixture``) over 4 forced CPU devices gives the archive of one device bit for
bit: each device renders its rows of the batch by their own generators (a subprocess: XLA_FLAGS must precede jax)."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest
from devices import run_on_devices

TESTS = str(Path(__file__).resolve().parents[1] / "qd")

SCRIPT = textwrap.dedent("""
    import sys
    sys.path.insert(0, TESTS)
    import jax, numpy as np
    from jaxterrain import qd as A
    from jaxterrain.qd import scoring as S
    from jaxterrain.runtime import sharding as SH
    from test_mixed import mix, desc, fitness, always, CFG

    assert len(jax.devices()) == 4

    def noisy(hm, key, needed):  # depends on the key: equal archives need the same key per row on any device count
        return 0.5 * fitness(hm, key) + 0.5 * jax.random.uniform(key, (hm.shape[0],))

    config = CFG._replace(generations=2, batch_size=7, initial_population=6, store_heightmaps=False)
    run = lambda mesh: A.evolve(mix(), desc, config, jax.random.key(0), fitness_fn=noisy, traversable_fn=always,
                                progress=False, mesh=mesh, split=SPLIT)
    a4, a1 = run(SH.make_mesh()), run(SH.make_mesh(1))
    assert A.coverage(a4) > 0 and set(np.unique(a4.source[a4.filled])) == {0, 1}
    for name in ("fitness", "descriptors", "source"):
        np.testing.assert_array_equal(getattr(a4, name), getattr(a1, name))
    for x, y in zip(jax.tree.leaves(a4.genomes), jax.tree.leaves(a1.genomes)):
        np.testing.assert_array_equal(x, y)
    print("ok")
""").replace("TESTS", repr(TESTS))


@pytest.mark.slow  # a subprocess that compiles the mixed run twice (4 devices, 1 device)
@pytest.mark.parametrize("split", ["dispatch", "shard_map"])
def test_sharded_mixed_run_equals_one_device(split):
    assert run_on_devices(SCRIPT.replace("SPLIT", repr(split))).strip().endswith("ok")
