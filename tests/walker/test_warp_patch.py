"""``jaxterrain.walker.warp_patch``: the local-origin patch of MuJoCo Warp's heightfield collision, applied to a COPY
of the installed mujoco-mjx's vendored ``collision_convex.py`` (the file is there whether or not warp-lang is
installed; the installed file itself is never touched here), and the warning a stock kernel gives a Warp env.
No MJX compile, no Warp env."""

from __future__ import annotations

import shutil
import subprocess
import warnings
from pathlib import Path

import pytest

from jaxterrain.runtime import provenance
from jaxterrain.walker import WalkerConfig, WalkerEnv, warp_patch
from jaxterrain.walker import env as env_module

ROOT = Path(__file__).resolve().parents[2]
DOCS_COPY = ROOT / "docs" / "results" / "sim2sim" / "warp_hfield" / "mjx_vendored_hfield_local_origin.patch"
SOURCE = provenance.warp_hfield_source()
needs_source = pytest.mark.skipif(SOURCE is None, reason="this mujoco-mjx has no vendored MuJoCo Warp")


@pytest.fixture
def stock(tmp_path) -> Path:
    """A copy of the installed vendored ``collision_convex.py`` (mujoco-mjx 3.17.0: the stock kernel)."""
    if SOURCE is None:
        pytest.skip("this mujoco-mjx has no vendored MuJoCo Warp")
    copy = tmp_path / "collision_convex.py"
    shutil.copyfile(SOURCE, copy)
    if provenance.warp_hfield(copy) != warp_patch.STOCK:
        pytest.skip(f"the installed {SOURCE} is not the stock kernel")
    return copy


def test_the_shipped_patch_is_package_data_and_the_documented_one():
    """One content: the package's copy (a wheel installs it: ``pyproject.toml`` ships ``assets/**/*``) is byte for
    byte the one the diagnosis beside it documents, and adds the line ``provenance`` looks for."""
    assert warp_patch.PATCH.is_file() and warp_patch.PATCH.parent.parent.name == "assets"
    assert warp_patch.PATCH.read_bytes() == DOCS_COPY.read_bytes()
    assert '"assets/**/*"' in (ROOT / "pyproject.toml").read_text()
    diff = warp_patch.hunks(warp_patch.PATCH.read_text())
    assert [(len(h.old), len(h.new)) for h in diff] == [(6, 10), (8, 8), (8, 8), (7, 7)]
    assert any(provenance.WARP_HFIELD_MARKER in line for h in diff for line in h.new)
    assert not any(provenance.WARP_HFIELD_MARKER in line for h in diff for line in h.old)


def test_apply_is_idempotent_and_revert_restores_the_file_byte_for_byte(stock):
    original = stock.read_bytes()
    assert warp_patch.apply(path=stock) == warp_patch.PATCHED == warp_patch.status(stock)
    patched = stock.read_bytes()
    assert patched != original and len(patched.splitlines()) == len(original.splitlines()) + 4
    assert warp_patch.apply(path=stock) == warp_patch.PATCHED and stock.read_bytes() == patched  # a no-op
    assert warp_patch.apply(revert=True, path=stock) == warp_patch.STOCK
    assert stock.read_bytes() == original
    assert warp_patch.apply(revert=True, path=stock) == warp_patch.STOCK and stock.read_bytes() == original
    assert sorted(p.name for p in stock.parent.iterdir()) == [stock.name]  # no temporary file left behind
    assert warp_patch.apply(path=stock.parent / "missing.py") == warp_patch.ABSENT


@pytest.mark.skipif(shutil.which("patch") is None, reason="GNU patch is not installed")
def test_apply_writes_what_gnu_patch_writes(stock, tmp_path):
    """The same bytes as ``patch FILE < the .patch`` (and ``patch -R`` back), also where the hunks sit at other line
    numbers than the diff's headers say (lines added above them)."""
    shifted = tmp_path / "shifted"
    shifted.mkdir()
    (shifted / stock.name).write_bytes(b"# a comment\n" * 7 + stock.read_bytes())
    for copy in (stock, shifted / stock.name):
        gnu = copy.with_name("gnu.py")
        shutil.copyfile(copy, gnu)

        def gnu_patch(*flags):
            done = subprocess.run(["patch", "--quiet", *flags, str(gnu)], stdin=warp_patch.PATCH.open("rb"),
                                  capture_output=True, timeout=30)
            assert done.returncode == 0, done.stdout + done.stderr

        gnu_patch()
        warp_patch.apply(path=copy)
        assert copy.read_bytes() == gnu.read_bytes()
        gnu_patch("-R")
        warp_patch.apply(revert=True, path=copy)
        assert copy.read_bytes() == gnu.read_bytes()


def test_a_file_the_patch_does_not_fit_is_refused_in_one_line_and_left_as_it_is(stock):
    """Each hunk's old lines must occur exactly once: a changed line (another mujoco-mjx) or a repeated block, and
    nothing is written; the error names the file and the mujoco-mjx version the patch is made for."""
    text = stock.read_text()
    line = "        x = dx * float(cmin) - size[0]\n"
    assert text.count(line) == 1
    for changed in (text.replace(line, "        x = dx * float(cmin) - size[0]  # moved\n"),
                    text + "".join(warp_patch.hunks(warp_patch.PATCH.read_text())[3].old)):
        stock.write_text(changed)
        with pytest.raises(ValueError) as err:
            warp_patch.apply(path=stock)
        message = str(err.value)
        assert "\n" not in message and str(stock) in message and "mujoco-mjx 3.17.0" in message, message
        assert ("occur 0 times" in message) != ("occur 2 times" in message), message
        assert stock.read_text() == changed
    stock.write_text(text.replace(line, line.replace("cmin", "cmin - cmin").replace(" - size[0]", ""), 1) + "# "
                     + provenance.WARP_HFIELD_MARKER + "\n")  # patched by something else: revert cannot undo it
    with pytest.raises(ValueError, match="not once"):
        warp_patch.apply(revert=True, path=stock)


def test_hunks_reads_empty_context_lines_a_missing_final_newline_and_cuts_at_newlines_only():
    diff = "--- a\n+++ b\n@@ -1,3 +1,3 @@\n a\n\n-b\n\\ No newline at end of file\n+c\n\\ No newline at end of file\n"
    (h,) = warp_patch.hunks(diff)
    assert h.old == ("a\n", "\n", "b") and h.new == ("a\n", "\n", "c") and h.header == "@@ -1,3 +1,3 @@"
    with pytest.raises(ValueError, match="ends before"):
        warp_patch.hunks("@@ -1,3 +1,3 @@\n a\n")
    (h,) = warp_patch.hunks("@@ -1 +1 @@\n-a\x0cb\n+c\n")  # lines end at \n only, as patch reads them
    assert h.old == ("a\x0cb\n",) and h.new == ("c\n",)


@pytest.fixture
def fresh(monkeypatch):
    """A process that has not warned yet, and a list of the status checks made."""
    monkeypatch.setattr(warp_patch, "_WARNED", False)
    asked = []
    return asked


def _status(monkeypatch, asked, value):
    monkeypatch.setattr(warp_patch, "status", lambda path=None: asked.append(path) or value)


def test_a_stock_kernel_warns_once_per_process_and_only_for_warp(monkeypatch, fresh):
    _status(monkeypatch, fresh, warp_patch.STOCK)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        assert warp_patch.warn_if_stock("jax") is False and fresh == []  # jax: not even looked up
        assert warp_patch.warn_if_stock("warp") is True
        assert warp_patch.warn_if_stock("warp") is False  # once per process
    (w,) = seen
    text = str(w.message)
    assert w.category is warp_patch.WarpHfieldWarning and issubclass(w.category, RuntimeWarning)
    assert "\n" not in text and "stock" in text and "19 of 73" in text and "python -m experiments warp-patch" in text
    monkeypatch.setattr(warp_patch, "_WARNED", False)
    for quiet in (warp_patch.PATCHED, warp_patch.ABSENT):
        _status(monkeypatch, fresh, quiet)
        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter("always")
            assert warp_patch.warn_if_stock("warp") is False
        assert seen == []


class _Stop(Exception):
    pass


def _stop(*args, **kwargs):
    raise _Stop


@pytest.mark.parametrize("backend,warned", [("warp", True), ("jax", False)])
def test_building_a_walker_env_warns_for_warp_only(monkeypatch, fresh, backend, warned):
    """``WalkerEnv(backend="warp")`` warns before it builds MuJoCo Warp's model (stopped there: no Warp env is
    built, with or without warp-lang); ``backend="jax"`` does not."""
    _status(monkeypatch, fresh, warp_patch.STOCK)
    monkeypatch.setattr(env_module.mjx, "put_model", _stop)
    config = WalkerConfig(terrain_shape=(16, 16), tiles=1, backend=backend)
    with warnings.catch_warnings(record=True) as seen, pytest.raises((_Stop, RuntimeError)):
        warnings.simplefilter("always")
        WalkerEnv(config)
    assert [w.category for w in seen if w.category is warp_patch.WarpHfieldWarning] == (
        [warp_patch.WarpHfieldWarning] if warned else [])
