"""Test-session setup shared by every test module.

A compile cache, fresh for every session. Most of the suite's time is XLA compiling on a CPU (MJX's walker above all:
tens of seconds per rollout program). Several tests build the same program through different jitted function objects
(a command run twice to test resume, the same smoke preset driven from two modules), which JAX's in-memory cache,
keyed by function object, cannot see; its persistent compilation cache is keyed by the program itself (canonical
HLO, compile options, backend). It is pointed here at a new empty temporary folder, removed at exit, so the suite
never depends on programs compiled before it started (CI runs on a fresh machine; any ``JAX_COMPILATION_CACHE_DIR``
of the environment is ignored): a hit is always a program compiled earlier in the same session, and the cached
executable is the one a fresh compile of the same program gives. It is set through ``jax.config``, so subprocesses
started by the tests do not use it.

Not done here on purpose: ``XLA_FLAGS=--xla_cpu_use_fusion_emitters=false`` for the whole session compiles the
walker ~35 % faster at the same run time, but changes float rounding from program to program, and the tests that
compare two different programs bit for bit (tests/test_tiles_ppo.py) then fail; tests pass that option per compile
only for programs compared with themselves.
"""

from __future__ import annotations

import atexit
import shutil
import tempfile

import jax

_XLA_CACHE = tempfile.mkdtemp(prefix="jaxterrain-tests-xla-cache-")
atexit.register(shutil.rmtree, _XLA_CACHE, ignore_errors=True)
jax.config.update("jax_compilation_cache_dir", _XLA_CACHE)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)  # small programs: cheaper to compile again
jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
