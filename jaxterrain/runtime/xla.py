"""XLA options that differ between jax versions: which compile options and ``XLA_FLAGS`` the installed XLA knows.

XLA renames and drops its options between releases: ``xla_cpu_use_fusion_emitters`` (the CPU's classic elemental
emitter, several times faster to compile the walker's programs) exists in jaxlib 0.10 and is gone in 0.12, where
passing it fails the compile (``No such compile option``) or, in ``XLA_FLAGS``, aborts the process. So options that
only make compiles cheaper go through this module, which keeps the ones the installed XLA accepts:

    compiled = jax.jit(f).lower(x).compile(xla.known_options(xla.FAST_CPU_COMPILE))   # on the CPU backend
    if xla.flag_known("--xla_cpu_use_fusion_emitters=false"): ...                      # before jax starts (tests)

Dropping such an option changes compile time, and results at most in the last bits (another emitter), never what is
computed.
"""

from __future__ import annotations

import functools
import os
import subprocess
import sys

__all__ = ["FAST_CPU_COMPILE", "known_options", "option_known", "flag_known"]

FAST_CPU_COMPILE = {"xla_backend_optimization_level": 0, "xla_llvm_disable_expensive_passes": True,
                    "xla_cpu_use_fusion_emitters": False}
"""Compile options for cheap CPU compiles of programs that need no optimised code (tests, the smoke presets): XLA's
lowest backend optimisation, no expensive LLVM passes, the classic elemental emitter. Pass through
:func:`known_options`."""


@functools.lru_cache(maxsize=64)
def option_known(name: str, value) -> bool:
    """Whether the default backend's XLA accepts compile option ``name`` (set to ``value``): one compile of a
    one-element program, once per (name, value) and process."""
    import jax
    import jax.numpy as jnp

    lowered = jax.jit(lambda x: x + 1).lower(jnp.zeros((), jnp.float32))
    try:
        lowered.compile({name: value})
    except Exception as err:  # noqa: BLE001 - jaxlib raises its own runtime error type
        if "compile option" in str(err):
            return False
        raise
    return True


def known_options(options: dict) -> dict:
    """``options`` without the compile options the installed XLA does not know (:func:`option_known`)."""
    return {name: value for name, value in options.items() if option_known(name, value)}


@functools.lru_cache(maxsize=16)
def flag_known(flag: str) -> bool:
    """Whether ``XLA_FLAGS=flag`` starts jax's CPU backend (an unknown flag aborts the process): a subprocess that
    starts it, about a second, once per flag and process. For code that sets ``XLA_FLAGS`` before jax starts."""
    env = {**os.environ, "XLA_FLAGS": flag, "JAX_PLATFORMS": "cpu"}
    probe = "import jax, jax.numpy as jnp; jnp.zeros(1).block_until_ready()"
    done = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, timeout=120)
    return done.returncode == 0
