"""Run a script on N forced CPU devices in a subprocess (XLA_FLAGS must be set before jax starts): the sharded
tests' helper."""

from __future__ import annotations

import os
import subprocess
import sys


def run_on_devices(script: str, devices: int = 4, timeout: int = 300, **environ: str) -> str:
    env = dict(os.environ, XLA_FLAGS=f"--xla_force_host_platform_device_count={devices}", JAX_PLATFORMS="cpu",
               **environ)
    out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=timeout)
    assert out.returncode == 0, out.stderr[-3000:]
    return out.stdout
