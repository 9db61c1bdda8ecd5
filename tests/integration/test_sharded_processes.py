"""Two processes joined through jax.distributed on a localhost coordinator, 2 forced CPU devices each (a 4-device
mesh over both): a tiny MAP-Elites run (initial population + one generation, rows split over the 4 devices) gives
the archive of one process on one device bit for bit, and one data-parallel PPO update gives its update up to float
rounding. Each process compiles both programs twice: slow."""

from __future__ import annotations

import socket
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from devices import child_env

TESTS = [str(Path(__file__).resolve().parents[1] / d) for d in ("qd", "rl")]  # the unit tests whose fixtures it reuses

SCRIPT = textwrap.dedent("""
    import sys
    sys.path[:0] = TESTS
    import jax, numpy as np
    from jaxterrain.runtime import sharding as SH
    SH.initialize(sys.argv[1], 2, int(sys.argv[2]))
    assert jax.process_count() == 2 and len(jax.devices()) == 4 and len(jax.local_devices()) == 2
    from jaxterrain import qd as A, rl
    from test_map_elites import uv_gen, desc2, smooth, always, cfg
    from test_rl import PointEnv, CFG, TERRAIN

    both, here = SH.make_mesh(), SH.make_mesh(devices=jax.local_devices()[:1])

    def noisy(hm, key, needed):
        return 0.5 * smooth(hm, key, needed) + 0.5 * jax.random.uniform(key, (hm.shape[0],))

    config = cfg(generations=1, batch_size=10, initial_population=7, checkpoint_every=1)
    run = lambda mesh: A.evolve(uv_gen(), desc2, config, jax.random.key(0), fitness_fn=noisy, traversable_fn=always,
                                progress=False, mesh=mesh)
    a, b = run(both), run(here)
    assert A.coverage(a) > 0
    np.testing.assert_array_equal(a.fitness, b.fitness)
    np.testing.assert_array_equal(a.genomes[0].u, b.genomes[0].u)

    env, ppo = PointEnv(), CFG._replace(num_envs=6, num_minibatches=2, update_epochs=2)
    start = jax.jit(lambda k: rl.init(k, env, ppo, TERRAIN))(jax.random.PRNGKey(0))
    two, m2 = rl.train(None, env, ppo, 1, TERRAIN, state=start, mesh=both)
    one, m1 = rl.train(None, env, ppo, 1, TERRAIN, state=start)
    for x, y in zip(jax.tree.leaves(two.params), jax.tree.leaves(one.params)):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(m2["loss"], m1["loss"], rtol=1e-5)
    # values held by this process's devices alone (a jitted init's, a typed key) are replicated over both processes
    local = (jax.device_put(np.arange(6.0), jax.local_devices()[1]), jax.random.key(7))
    placed = SH.replicate(local, both)
    assert all(x.sharding.device_set == set(jax.devices()) for x in jax.tree.leaves(placed))
    np.testing.assert_array_equal(np.asarray(placed[0]), np.arange(6.0))
    assert np.array_equal(jax.random.key_data(placed[1]), jax.random.key_data(jax.random.key(7)))
    print("ok", jax.process_index())
""").replace("TESTS", repr(TESTS))


@pytest.mark.slow
def test_two_processes_map_elites_and_ppo_equal_one_process():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = child_env(2)
    procs = [subprocess.Popen([sys.executable, "-c", SCRIPT, f"127.0.0.1:{port}", str(i)], env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for i in range(2)]
    outs = [p.communicate(timeout=900) for p in procs]
    for p, (out, err) in zip(procs, outs):
        assert p.returncode == 0, err[-3000:]
    assert sorted(o.split()[-1] for o, _ in outs) == ["0", "1"]
