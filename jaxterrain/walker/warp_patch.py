"""The local-origin patch of MuJoCo Warp's heightfield collision, applied to MJX's vendored copy (``backend="warp"``).

MJX 3.17's vendored MuJoCo Warp (``mujoco/mjx/third_party/mujoco_warp/_src/collision_convex.py``,
``ccd_hfield_kernel``) runs GJK / EPA in float32 on prism vertices and the geom's position at absolute heightfield
coordinates (up to the heightfield's half-size, 46 m for the 9 x 9 grid of 73 tiles of 256^2 samples). For a foot
sphere whose centre is under the surface, far from the heightfield's centre, the contact it returns is sometimes
metres deep and the walker is launched (``docs/results/sim2sim/warp_hfield/REPORT.md``). The patch (6 changed lines,
``jaxterrain/assets/patches/mjx_vendored_hfield_local_origin.patch``, :data:`PATCH`) computes the prisms and the
geom relative to the subgrid's first sample and adds that origin back to the contact point, as the file's
non-heightfield kernel already does. Measured: the ant's base policy on held-out suite v2 (701 terrains, 10 keys)
walks 0.7755-0.7799 mean fitness patched against 0.6851-0.6886 stock (2 x H200 host, 2026-11-29, tree 2eb907c,
``docs/results/suite_v2/README.md``); on 73 maps in one call the ant's walks ending within 5 steps fall from 9.0 % to
1.6 % (CPU, Warp's CPU backend). The ant's spawn buries a foot on 19 of the 73 sim2sim maps; the humanoid's mean
fitness on those maps moved 0.2407 -> 0.2390.

    warp_patch.status()              # "stock", "local-origin patch" or "absent" (runtime.provenance.warp_hfield)
    warp_patch.apply()               # patch the installed file (idempotent); returns the new status
    warp_patch.apply(revert=True)    # back to the stock kernel
    warp_patch.apply(path=copy)      # any copy of the file (tests, a patched copy of the mujoco package)

``python -m experiments warp-patch`` is the command line over it. :func:`apply` edits a file of an installed package
(mujoco-mjx) in place, in pure Python (no ``patch`` binary): each hunk's old lines must occur exactly once in the file,
else nothing is written and a one-line ValueError names the file and the mujoco-mjx version the patch is made for;
the result is byte for byte what GNU ``patch`` writes (``tests/walker/test_warp_patch.py``), written atomically.
Warp compiles its kernels from the source, so the next process that imports MuJoCo Warp runs the patched kernel.

:func:`warn_if_stock` is called by :class:`~jaxterrain.walker.env.WalkerEnv` for ``backend="warp"``: one
:class:`WarpHfieldWarning` per process while the installed kernel is stock.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import NamedTuple

from jaxterrain.runtime import provenance
from jaxterrain.runtime.io import atomic_write_bytes

__all__ = ["PATCH", "MJX_VERSION", "PATCHED", "STOCK", "ABSENT", "COMMAND", "Hunk", "WarpHfieldWarning", "hunks",
           "status", "apply", "stock_warning", "warn_if_stock"]

PATCH = Path(__file__).resolve().parents[1] / "assets" / "patches" / "mjx_vendored_hfield_local_origin.patch"
"""The patch (unified diff of ``collision_convex.py``), package data; ``docs/results/sim2sim/warp_hfield/`` keeps the
same file beside the diagnosis."""
MJX_VERSION = "3.17.0"
"""The mujoco-mjx whose vendored ``collision_convex.py`` the patch is made for (``pyproject.toml`` pins it)."""
PATCHED, STOCK, ABSENT = "local-origin patch", "stock", "absent"
"""The statuses of :func:`jaxterrain.runtime.provenance.warp_hfield`."""
COMMAND = "python -m experiments warp-patch"
"""The command that applies the patch to the installed mujoco-mjx."""


class Hunk(NamedTuple):
    """One hunk of a unified diff: ``old`` and ``new`` lines (with their line endings), ``header`` its ``@@`` line."""

    header: str
    old: tuple[str, ...]
    new: tuple[str, ...]


class WarpHfieldWarning(RuntimeWarning):
    """MJX's vendored MuJoCo Warp runs the stock heightfield collision (see :func:`stock_warning`)."""


def _lines(text: str) -> list[str]:
    """``text`` cut after every line feed only (as ``patch`` reads a file; ``str.splitlines`` also cuts at form feeds
    and other separators), each line with its ending; a last line without one as it is."""
    parts = text.split("\n")
    return [p + "\n" for p in parts[:-1]] + ([parts[-1]] if parts[-1] else [])


def hunks(diff: str) -> list[Hunk]:
    """The hunks of a one-file unified diff (``diff -u`` text: ``@@ -a,b +c,d @@`` headers, lines starting with ``' '``,
    ``'-'``, ``'+'``, ``'\\ No newline at end of file'``; an empty line as an empty context line, as GNU ``patch``
    reads it). ValueError for a hunk whose line counts disagree with its header."""
    lines = _lines(diff)
    out, i = [], 0
    while i < len(lines):
        head = lines[i]
        i += 1
        if not head.startswith("@@ "):
            continue
        try:
            spans = head.split("@@")[1].split()
            n_old, n_new = (int(s.split(",")[1]) if "," in s else 1 for s in spans[:2])
        except (IndexError, ValueError):
            raise ValueError(f"patch: cannot read the hunk header {head.strip()!r}") from None
        old, new = [], []
        while len(old) < n_old or len(new) < n_new:
            if i >= len(lines):
                raise ValueError(f"patch: hunk {head.strip()!r} ends before its {n_old} old / {n_new} new lines")
            line = lines[i]
            i += 1
            tag, body = (" ", line) if line in ("\n", "\r\n") else (line[0], line[1:])
            if tag == "\\":
                continue
            if tag not in " -+":
                raise ValueError(f"patch: hunk {head.strip()!r} has a line starting with {tag!r}")
            if tag in " -":
                old.append(body)
            if tag in " +":
                new.append(body)
            if i < len(lines) and lines[i].startswith("\\"):  # "\ No newline at end of file": of this line
                if tag in " -":
                    old[-1] = old[-1].rstrip("\r\n")
                if tag in " +":
                    new[-1] = new[-1].rstrip("\r\n")
        if len(old) != n_old or len(new) != n_new:
            raise ValueError(f"patch: hunk {head.strip()!r} has {len(old)} old / {len(new)} new lines")
        out.append(Hunk(head.strip(), tuple(old), tuple(new)))
    return out


def _mjx_version() -> str:
    from importlib import metadata

    try:
        return metadata.version("mujoco-mjx")
    except metadata.PackageNotFoundError:
        return "not installed"


def _target(path: str | os.PathLike | None) -> Path | None:
    return provenance.warp_hfield_source() if path is None else Path(path)


def status(path: str | os.PathLike | None = None) -> str:
    """:data:`PATCHED`, :data:`STOCK` or :data:`ABSENT`: :func:`jaxterrain.runtime.provenance.warp_hfield` of the
    installed mujoco-mjx's vendored ``collision_convex.py``, or of ``path``."""
    return provenance.warp_hfield(path)


def _replace(lines: list[str], pairs: list[tuple[tuple[str, ...], tuple[str, ...], str]], where: Path) -> list[str]:
    """``lines`` with each ``(find, put, header)``'s ``find`` block (which must occur exactly once, the blocks not
    overlapping) replaced by ``put``; ValueError naming ``where`` otherwise, before anything changes."""
    spans = []
    for find, put, header in pairs:
        at = [k for k in range(len(lines) - len(find) + 1) if tuple(lines[k:k + len(find)]) == find]
        if len(at) != 1:
            raise ValueError(f"{where}: the lines of hunk {header} occur {len(at)} times, not once: the file does not "
                             f"match the local-origin patch, made for mujoco-mjx {MJX_VERSION} (installed: "
                             f"mujoco-mjx {_mjx_version()}); nothing written")
        spans.append((at[0], at[0] + len(find), put, header))
    spans.sort()
    for (_, end, _, h1), (start, _, _, h2) in zip(spans, spans[1:]):
        if start < end:
            raise ValueError(f"{where}: hunks {h1} and {h2} overlap in this file; nothing written")
    for start, end, put, _ in reversed(spans):
        lines[start:end] = list(put)
    return lines


def apply(revert: bool = False, path: str | os.PathLike | None = None) -> str:
    """Patch MJX's vendored MuJoCo Warp heightfield collision (or, ``revert``, restore the stock kernel); the status
    afterwards (:func:`status`).

    ``path``: the ``collision_convex.py`` to edit (default: the installed mujoco-mjx's,
    :func:`jaxterrain.runtime.provenance.warp_hfield_source`). A file already in the asked state is left as it is
    (its status returned); so is a missing one (:data:`ABSENT`). Otherwise every hunk of :data:`PATCH` must find its
    old lines (its new ones to revert) exactly once, else ValueError naming the file and the mujoco-mjx version the
    patch is made for, and nothing is written; the new text replaces the file atomically
    (:func:`jaxterrain.runtime.io.atomic_write_bytes`; OSError, e.g. PermissionError, where its folder is not
    writable)."""
    target = _target(path)
    before = status(target) if target is not None else ABSENT
    if before == ABSENT or before == (STOCK if revert else PATCHED):
        return before
    diff = hunks(PATCH.read_text(encoding="utf-8"))
    pairs = [(h.new, h.old, h.header) if revert else (h.old, h.new, h.header) for h in diff]
    lines = _replace(_lines(target.read_bytes().decode("utf-8")), pairs, target)
    atomic_write_bytes(target, "".join(lines).encode("utf-8"))
    return status(target)


def stock_warning() -> str:
    """The one-line warning of a stock kernel: what is wrong, whom it affects, the command that fixes it."""
    return ("MuJoCo Warp's heightfield collision (MJX's vendored copy) is the stock kernel: float32 at absolute "
            "coordinates gives a foot buried far from the heightfield's centre contacts metres deep, which biases "
            "walks that start with a buried foot (the ant's spawn buries one on 19 of 73 sim2sim maps; its suite v2 "
            f"fitness 0.69 stock against 0.78 patched); run `{COMMAND}` to fix it")


_WARNED = False


def warn_if_stock(backend: str) -> bool:
    """Issue :func:`stock_warning` as a :class:`WarpHfieldWarning` once per process, when ``backend == "warp"`` and
    :func:`status` is :data:`STOCK`; whether it warned now. Never for ``backend="jax"``."""
    global _WARNED
    if backend != "warp" or _WARNED or status() != STOCK:
        return False
    _WARNED = True
    warnings.warn(stock_warning(), WarpHfieldWarning, stacklevel=2)
    return True
