"""Rows over devices: 4 forced CPU devices in a subprocess (XLA_FLAGS must precede jax's start)."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest
from devices import child_env, run_on_devices

from jaxterrain.runtime import sharding as S

SCRIPT = textwrap.dedent("""
    import jax, jax.numpy as jnp, numpy as np
    from jaxterrain.runtime import sharding as S
    assert len(jax.devices()) == 4, jax.devices()
    mesh = S.make_mesh()
    def f(x, k, w):
        return {"y": jnp.sin(x).sum(-1) * w + jax.vmap(jax.random.uniform)(k)}
    assert S.default_split(mesh) == "shard_map"  # CPU devices; GPUs dispatch (JAX 0.11.2's shard_map crash)
    for split in ("shard_map", "dispatch"):
        for n in (1, 4, 7, 9):  # uneven batches are padded, never an error
            x = jnp.arange(n * 3, dtype=jnp.float32).reshape(n, 3)
            keys = jax.random.split(jax.random.key(0), n)
            got = S.map_rows(f, mesh, replicated=(2,), split=split)(x, keys, jnp.float32(2.0))["y"]
            want = f(x, keys, 2.0)["y"]
            assert got.shape == (n,) and np.array_equal(np.asarray(got), np.asarray(want)), (split, n, got, want)
        masked = S.map_rows(lambda x, m: jnp.where(m, x, -1.0), mesh, mask=True, split=split)(jnp.arange(5.0))
        assert np.asarray(masked).tolist() == [0.0, 1.0, 2.0, 3.0, 4.0], (split, masked)  # padding cut off
    try:
        S.map_rows(f, mesh, split="threads")
        raise AssertionError("an unknown split was accepted")
    except ValueError as err:
        assert "split must be one of" in str(err)
    t, m = S.shard_rows(jnp.ones((7, 2)), mesh)
    assert t.shape == (8, 2) and np.asarray(m).tolist() == [True] * 7 + [False]
    assert S.padded_length(9, mesh) == 12 and S.make_mesh(2).devices.size == 2
    print("ok")
""")


def test_map_rows_equals_unsharded_and_pads_uneven_batches():
    assert run_on_devices(SCRIPT).strip().endswith("ok")


def test_bad_device_counts_and_initialize_arguments():
    with pytest.raises(ValueError, match="num_devices must be an integer in"):
        S.make_mesh(0)
    with pytest.raises(ValueError, match="together"):
        S.initialize(coordinator="localhost:1234")
    with pytest.raises(ValueError, match="process_id must be in"):
        S.initialize("localhost:1234", 2, 5)


_PROCESS_SCRIPT = textwrap.dedent("""
    import sys
    import jax, jax.numpy as jnp, numpy as np
    from jax.experimental import multihost_utils
    from jaxterrain.runtime import sharding as S
    S.initialize(sys.argv[1], 2, int(sys.argv[2]))
    assert jax.process_count() == 2 and len(jax.devices()) == 4 and len(jax.local_devices()) == 2
    mesh = S.make_mesh()
    def f(x, k, w):
        return {"y": jnp.sin(x).sum(-1) * w + jax.vmap(jax.random.uniform)(k)}
    x = jnp.arange(21, dtype=jnp.float32).reshape(7, 3)
    keys = jax.random.split(jax.random.key(0), 7)
    got = multihost_utils.process_allgather(S.map_rows(f, mesh, replicated=(2,))(x, keys, jnp.float32(2.0))["y"],
                                            tiled=True)
    assert np.array_equal(np.asarray(got), np.asarray(f(x, keys, 2.0)["y"])), got
    print("ok", jax.process_index())
""")


def test_two_processes_through_jax_distributed_equal_one():
    """Two processes on this machine, 2 forced CPU devices each, joined on a localhost coordinator."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = child_env(2)
    procs = [subprocess.Popen([sys.executable, "-c", _PROCESS_SCRIPT, f"127.0.0.1:{port}", str(i)], env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for i in range(2)]
    outs = [p.communicate(timeout=240) for p in procs]
    for p, (out, err) in zip(procs, outs):
        assert p.returncode == 0, err[-3000:]
    assert sorted(o.split()[-1] for o, _ in outs) == ["0", "1"]
