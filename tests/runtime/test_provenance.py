"""jaxterrain.runtime.provenance: the commit (environment first, then git of the package's checkout) and the devices."""

from __future__ import annotations

import re
import shutil
import subprocess

import pytest

from jaxterrain.runtime import provenance


def test_environment_variable_wins(monkeypatch):
    monkeypatch.setenv(provenance.COMMIT_ENV, "abc1234 (copied tree)")
    assert provenance.git_commit() == "abc1234 (copied tree)"
    assert provenance.git_commit(short=True, mark_dirty=False) == "abc1234 (copied tree)"


@pytest.mark.skipif(shutil.which("git") is None, reason="git not installed")
def test_git_commit_of_the_package_checkout(monkeypatch, tmp_path):
    monkeypatch.delenv(provenance.COMMIT_ENV, raising=False)
    monkeypatch.chdir(tmp_path)  # the checkout of the package, not of the current folder
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=provenance._ROOT, capture_output=True, text=True)
    if head.returncode != 0:
        pytest.skip("the package is not in a git checkout")
    full = provenance.git_commit()
    assert re.fullmatch(r"[0-9a-f]{40}( \(working tree has uncommitted changes\))?", full), full
    assert full.split()[0] == head.stdout.strip()
    short = provenance.git_commit(short=True, mark_dirty=False)
    assert re.fullmatch(r"[0-9a-f]{7,39}", short) and full.startswith(short)


def test_git_commit_outside_a_checkout_and_without_git(monkeypatch, tmp_path):
    monkeypatch.delenv(provenance.COMMIT_ENV, raising=False)
    monkeypatch.setattr(provenance, "_ROOT", tmp_path)
    if shutil.which("git") is not None:
        monkeypatch.setenv("GIT_CEILING_DIRECTORIES", str(tmp_path.parent))
        assert provenance.git_commit() == "unknown (not a git checkout)"
    monkeypatch.setenv("PATH", str(tmp_path / "no-bin"))
    assert provenance.git_commit() == "unknown (git not available)"


def test_device_names_count_kind_and_platform():
    import jax

    text = provenance.device()
    d = jax.devices()[0]
    assert text.startswith(f"{jax.device_count()} x ") and f"({d.platform}" in text
    assert ("CPU cores" in text) == (d.platform == "cpu")
