"""Run a script on N forced CPU devices in a subprocess (XLA_FLAGS must be set before jax starts): the sharded
tests' helper."""

from __future__ import annotations

import os
import subprocess
import sys

DEVICE_COUNT = "--xla_force_host_platform_device_count"


def child_env(devices: int | None = None, **environ: str) -> dict[str, str]:
    """The environment of a test's subprocess on CPU: this process's, so the child inherits what ``conftest`` set
    (``JAX_COMPILATION_CACHE_DIR``, the ``XLA_FLAGS`` of the test processes), with ``devices`` forced CPU devices added
    to ``XLA_FLAGS`` (replacing an inherited count) rather than replacing them: the flags are part of the compilation
    cache's key, and the child compiles as the test processes do."""
    flags = [f for f in os.environ.get("XLA_FLAGS", "").split() if f.split("=")[0] != DEVICE_COUNT]
    if devices is not None:
        flags.append(f"{DEVICE_COUNT}={devices}")
    return dict(os.environ, XLA_FLAGS=" ".join(flags), JAX_PLATFORMS="cpu", **environ)


def run_on_devices(script: str, devices: int = 4, timeout: int = 300, **environ: str) -> str:
    out = subprocess.run([sys.executable, "-c", script], env=child_env(devices, **environ), capture_output=True,
                         text=True, timeout=timeout)
    assert out.returncode == 0, out.stderr[-3000:]
    return out.stdout
