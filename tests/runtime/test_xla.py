"""XLA options the installed jax knows (``jaxterrain.runtime.xla``): an option or flag this XLA does not know is
dropped instead of failing the compile or aborting the process (jaxlib 0.12 dropped the CPU fusion-emitter switch)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxterrain.runtime import xla


def test_known_options_keep_what_compiles_and_drop_what_does_not():
    got = xla.known_options({"xla_backend_optimization_level": 0, "xla_no_such_option_anywhere": True})
    assert got == {"xla_backend_optimization_level": 0}
    assert not xla.option_known("xla_no_such_option_anywhere", True)
    fast = xla.known_options(xla.FAST_CPU_COMPILE)  # whatever survives compiles, and computes the same
    compiled = jax.jit(lambda x: jnp.sin(x) * 2).lower(jnp.arange(4.0)).compile(fast)
    assert jnp.allclose(compiled(jnp.arange(4.0)), jnp.sin(jnp.arange(4.0)) * 2)
    assert set(fast) <= set(xla.FAST_CPU_COMPILE) and "xla_backend_optimization_level" in fast


def test_an_unknown_xla_flag_is_reported_not_fatal():
    assert not xla.flag_known("--xla_no_such_flag_anywhere=true")  # it would abort a process that starts jax
    assert xla.flag_known("--xla_cpu_enable_fast_math=false")  # a flag every supported jaxlib has
