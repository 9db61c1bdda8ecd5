"""Where a result came from: the commit of the code and the devices that ran it.

Shipped models (``jaxterrain/assets/*/PROVENANCE.md``), exported run folders and benchmark results record these
facts; this module is the one place that finds them.

    provenance.git_commit()                 # "3f2a...e1" or "3f2a...e1 (working tree has uncommitted changes)"
    provenance.git_commit(short=True, mark_dirty=False)   # "3f2a9c1" (benchmark tables)
    provenance.device()                     # "1 x NVIDIA H100 80GB HBM3 (gpu)", "1 x cpu (cpu, 2 CPU cores)"
    provenance.warp_hfield()                # "stock", "local-origin patch" or "absent" (MJX's MuJoCo Warp)

A copy of the tree without its ``.git`` folder (e.g. on a GPU machine that receives the working tree only) names its
commit through the environment variable ``JAXTERRAIN_COMMIT``, which wins over git; an installed wheel (no checkout)
names the package's version, ``jaxterrain 0.1.0 (installed package)``.

Paths in the files a run writes carry no machine's layout (:func:`portable_path`): a file of the installed package
is ``<jaxterrain>/assets/...``, anything else is relative to the run folder; :func:`resolve_recorded` reads both
forms back, and the absolute paths of older files as they are.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

__all__ = ["COMMIT_ENV", "PACKAGE_TOKEN", "git_commit", "package_version", "device", "portable_path",
           "resolve_recorded", "file_sha256", "warp_hfield", "warp_hfield_source", "WARP_HFIELD_MARKER"]

COMMIT_ENV = "JAXTERRAIN_COMMIT"
DIRTY_NOTE = " (working tree has uncommitted changes)"
_ROOT = Path(__file__).resolve().parents[2]  # the checkout that holds the package (editable installs)
_PACKAGE = Path(__file__).resolve().parents[1]  # the jaxterrain package folder
PACKAGE_TOKEN = "<jaxterrain>"
"""How a recorded path names the installed package's folder, wherever it is installed."""


def _git(*argv: str) -> subprocess.CompletedProcess:
    return subprocess.run(["git", *argv], cwd=_ROOT, capture_output=True, text=True, timeout=10, check=False)


def git_commit(short: bool = False, mark_dirty: bool = True) -> str:
    """The commit of the code that runs, as text.

    ``$JAXTERRAIN_COMMIT`` when set (returned as it is), else ``git rev-parse HEAD`` of the checkout that holds this
    package (not of the current folder), abbreviated with ``short``; with ``mark_dirty``, followed by
    ``" (working tree has uncommitted changes)"`` when ``git status --porcelain`` lists any change. Never raises:
    ``"jaxterrain 0.1.0 (installed package, no git checkout)"`` (:func:`package_version`) where the package does not
    sit in a checkout (a wheel), ``"unknown (not a git checkout; jaxterrain 0.1.0)"`` when git finds no commit,
    ``"unknown (git not available)"`` when git cannot run.
    """
    given = os.environ.get(COMMIT_ENV, "").strip()
    if given:
        return given
    if not (_ROOT / ".git").exists():  # an installed wheel, or a tree copied without .git
        return f"jaxterrain {package_version()} (installed package, no git checkout)"
    try:
        head = _git("rev-parse", *(["--short"] if short else []), "HEAD")
        commit = head.stdout.strip()
        if head.returncode != 0 or not commit:
            return f"unknown (not a git checkout; jaxterrain {package_version()})"
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


WARP_HFIELD_MARKER = "sub_o = wp.vec3("
"""A line of the local-origin patch of MuJoCo Warp's heightfield collision
(``jaxterrain/assets/patches/mjx_vendored_hfield_local_origin.patch``, applied by :mod:`jaxterrain.walker.warp_patch`):
its presence in the source marks a patched engine."""


def warp_hfield_source() -> Path | None:
    """The source file of the heightfield collision of MJX's vendored MuJoCo Warp,
    ``mujoco/mjx/third_party/mujoco_warp/_src/collision_convex.py`` of the installed mujoco-mjx, found without
    importing MJX or Warp; None where this mujoco-mjx has none (or none is installed)."""
    from importlib import util

    try:
        spec = util.find_spec("mujoco.mjx")
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.submodule_search_locations:
        return None
    for root in spec.submodule_search_locations:
        src = Path(root) / "third_party" / "mujoco_warp" / "_src" / "collision_convex.py"
        if src.is_file():
            return src
    return None


def warp_hfield(path: str | os.PathLike | None = None) -> str:
    """Which heightfield collision MJX's vendored MuJoCo Warp runs (``impl="warp"``), read from its source file
    (:func:`warp_hfield_source`, or ``path``) without importing Warp: ``"local-origin patch"`` (GJK / EPA on
    coordinates local to the heightfield's subgrid, the fix of ``docs/results/sim2sim/warp_hfield/REPORT.md``,
    applied by ``python -m experiments warp-patch``), ``"stock"`` (float32 at absolute coordinates: a buried foot far
    from the heightfield's centre gets contacts metres deep), or ``"absent"`` (no vendored MuJoCo Warp in this
    mujoco-mjx; ``path`` not a file). Recorded with every Warp walk whose figures it can change."""
    src = warp_hfield_source() if path is None else Path(path)
    if src is None or not src.is_file():
        return "absent"
    return "local-origin patch" if WARP_HFIELD_MARKER in src.read_text() else "stock"


def package_version() -> str:
    """The installed jaxterrain's version (its distribution's metadata), or ``"unknown"`` where the package runs
    from a source tree that was never installed (then the git commit names it)."""
    from importlib import metadata

    try:
        return metadata.version("jaxterrain")
    except metadata.PackageNotFoundError:
        return "unknown"


def portable_path(path: str | os.PathLike, base: str | os.PathLike) -> str:
    """``path`` as a run's files record it: a file of the installed package as ``<jaxterrain>/...`` (e.g.
    ``<jaxterrain>/assets/archives/cppn_headings.npz``), anything else relative to ``base`` (the run folder), in
    ``/`` form; ``""`` stays ``""``. No machine's absolute path is written (where no relative path exists, another
    drive on Windows, the path as given)."""
    if str(path) == "":
        return ""
    target = Path(os.path.abspath(path))
    if target == _PACKAGE or _PACKAGE in target.parents:
        return f"{PACKAGE_TOKEN}/{target.relative_to(_PACKAGE).as_posix()}".rstrip("/.")
    try:
        return Path(os.path.relpath(target, os.path.abspath(base))).as_posix()
    except ValueError:
        return str(path)


def resolve_recorded(path: str, base: str | os.PathLike) -> str:
    """The inverse of :func:`portable_path`: ``<jaxterrain>/...`` under this machine's package, a relative path
    against ``base`` (the run folder that recorded it), an absolute path (older files) as it is."""
    text = str(path)
    if text == "" or os.path.isabs(text):
        return text
    if text == PACKAGE_TOKEN or text.startswith(PACKAGE_TOKEN + "/"):
        return str(_PACKAGE / text[len(PACKAGE_TOKEN) + 1:])
    return os.path.normpath(os.path.join(os.path.abspath(base), text))


def file_sha256(path: str | os.PathLike) -> str | None:
    """sha256 (hex) of a file's bytes; None where it cannot be read."""
    import hashlib

    h = hashlib.sha256()
    try:
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
    except OSError:
        return None
    return h.hexdigest()
