"""Test-process set-up: a persistent XLA compilation cache shared by the pytest process, its xdist workers and the
subprocesses they start.

Many tests run a command twice in one process (a run, then its resume), and each run builds its jitted functions
anew, so the in-memory jit cache misses where the program is the same; the on-disk cache turns those repeat
compilations (the MJX ones take 30-70 s on a CPU) into reads. Test files on different xdist workers compile many of
the same programs (the smoke ``learn`` blocks, the suite walk), and so do the tests' subprocesses (``python -m
experiments ...``, the scripts on forced CPU devices), so the folder is one for the whole session: the pytest process
makes it at import and exports it as ``JAX_COMPILATION_CACHE_DIR`` (with ``JAX_COMPILATION_CACHE_MAX_SIZE``, a never
reached size limit that turns on JAX's lock of its files, with ``filelock``), which JAX reads into its config at import
in every process started after, the xdist workers and the subprocesses alike; a subprocess given its own ``env=`` gets
it through ``devices.child_env``. Without ``filelock`` nothing is exported (two unlocked writers could tear an entry):
each process then keeps its own folder and the subprocesses none. It is set here, at import, before any test module
compiles anything, in a fresh temporary folder removed at exit by the process that made it, and only where
``JAX_COMPILATION_CACHE_DIR`` is not set already (a user's own folder wins, and is left in place). JAX's default
threshold stays: programs that took >= 1 s to compile are written, the smaller ones compile again. The programs, and so
the results, are the same with or without it; a subprocess hits it only where it compiles with the same ``XLA_FLAGS``
(a part of the cache key), so ``devices.child_env`` keeps the test processes' flags and adds the device count.

XLA's CPU compiles are the larger part of the suite's time, so the test processes also compile with the classic
elemental emitter instead of XLA's fusion emitters (``--xla_cpu_use_fusion_emitters=false``, appended to
``XLA_FLAGS`` unless ``XLA_FLAGS`` names that flag already): the default suite on 2 cores took 14:01 with it and
18:47 without (2026-11-27, fresh clones of f105a74). Results may differ from the default emitters' in the last bits;
a test that compares two different programs bit for bit pins the emitters it was checked with in its own compile
options (``tests/rl/test_tiles_ppo.py``). Where the installed XLA no longer knows the flag (jaxlib 0.12), it is not
set (``jaxterrain.runtime.xla.flag_known``, probed once in a subprocess); compile options go through
``xla.known_options`` for the same reason.
"""

import atexit
import os
import shutil
import tempfile

import jax

from jaxterrain.runtime import xla

try:
    import filelock  # noqa: F401  (JAX's cache locks its files with it once a size limit is set)
except ImportError:
    filelock = None

if not os.environ.get("JAX_COMPILATION_CACHE_DIR"):  # set: the user's folder, or the pytest process's (a worker)
    _cache = tempfile.mkdtemp(prefix="jaxterrain-test-xla-cache-")
    atexit.register(shutil.rmtree, _cache, ignore_errors=True)
    jax.config.update("jax_compilation_cache_dir", _cache)  # jax is imported already: its config read the env then
    if filelock is not None:  # a (never reached) size limit turns on JAX's file lock: the xdist workers and the
        jax.config.update("jax_compilation_cache_max_size", 1 << 40)  # subprocesses read and write one folder
        os.environ["JAX_COMPILATION_CACHE_MAX_SIZE"] = str(1 << 40)  # without a torn entry; they are all started
        os.environ["JAX_COMPILATION_CACHE_DIR"] = _cache  # after this import and read both at their jax import

FUSION_FLAG = "--xla_cpu_use_fusion_emitters=false"
if "xla_cpu_use_fusion_emitters" not in os.environ.get("XLA_FLAGS", "") \
        and os.environ.get("JAXTERRAIN_TEST_FUSION_FLAG") != "unknown":  # read when the first backend starts
    if xla.flag_known(FUSION_FLAG):  # jaxlib 0.12 dropped it: there an unknown flag would abort every test process
        os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " " + FUSION_FLAG).strip()
    else:
        os.environ["JAXTERRAIN_TEST_FUSION_FLAG"] = "unknown"  # the workers and subprocesses need not probe again
