"""Where a result came from: the commit of the code and the devices that ran it.

Shipped models (``jaxterrain/assets/*/PROVENANCE.md``), exported run folders and benchmark results record these
facts; this module is the one place that finds them.

    provenance.git_commit()                 # "3f2a...e1" or "3f2a...e1 (working tree has uncommitted changes)"
    provenance.git_commit(short=True, mark_dirty=False)   # "3f2a9c1" (benchmark tables)
    provenance.device()                     # "1 x NVIDIA H100 80GB HBM3 (gpu)", "1 x cpu (cpu, 2 CPU cores)"

A copy of the tree without its ``.git`` folder (e.g. on a GPU machine that receives the working tree only) names its
commit through the environment variable ``JAXTERRAIN_COMMIT``, which wins over git.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

__all__ = ["COMMIT_ENV", "git_commit", "device"]

COMMIT_ENV = "JAXTERRAIN_COMMIT"
DIRTY_NOTE = " (working tree has uncommitted changes)"
_ROOT = Path(__file__).resolve().parents[2]  # the checkout that holds the package (editable installs)


def _git(*argv: str) -> subprocess.CompletedProcess:
    return subprocess.run(["git", *argv], cwd=_ROOT, capture_output=True, text=True, timeout=10, check=False)


def git_commit(short: bool = False, mark_dirty: bool = True) -> str:
    """The commit of the code that runs, as text.

    ``$JAXTERRAIN_COMMIT`` when set (returned as it is), else ``git rev-parse HEAD`` of the checkout that holds this
    package (not of the current folder), abbreviated with ``short``; with ``mark_dirty``, followed by
    ``" (working tree has uncommitted changes)"`` when ``git status --porcelain`` lists any change. Never raises:
    ``"unknown (not a git checkout)"`` when git finds no commit, ``"unknown (git not available)"`` when git cannot
    run.
    """
    given = os.environ.get(COMMIT_ENV, "").strip()
    if given:
        return given
    try:
        head = _git("rev-parse", *(["--short"] if short else []), "HEAD")
        commit = head.stdout.strip()
        if head.returncode != 0 or not commit:
            return "unknown (not a git checkout)"
        if mark_dirty and _git("status", "--porcelain").stdout.strip():
            commit += DIRTY_NOTE
        return commit
    except (OSError, subprocess.SubprocessError):
        return "unknown (git not available)"


def device() -> str:
    """The JAX devices in words: ``"<count> x <device kind> (<platform>)"``, on a CPU with its core count, e.g.
    ``"1 x cpu (cpu, 2 CPU cores)"``."""
    import jax

    d = jax.devices()[0]
    kind = getattr(d, "device_kind", d.platform)
    cores = f", {os.cpu_count()} CPU cores" if d.platform == "cpu" else ""
    return f"{jax.device_count()} x {kind} ({d.platform}{cores})"
