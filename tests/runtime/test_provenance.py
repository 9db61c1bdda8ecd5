"""jaxterrain.runtime.provenance: the commit (environment first, then git of the package's checkout) and the devices."""

from __future__ import annotations

import re
import shutil
import subprocess

import pytest
from pathlib import Path

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
    """A package that sits in no checkout (an installed wheel) names its version; a broken checkout and a machine
    without git say so."""
    monkeypatch.delenv(provenance.COMMIT_ENV, raising=False)
    monkeypatch.setattr(provenance, "_ROOT", tmp_path)
    version = provenance.package_version()
    assert re.fullmatch(r"\d+\.\d+\.\d+\S*", version)
    assert provenance.git_commit() == f"jaxterrain {version} (installed package, no git checkout)"
    (tmp_path / ".git").mkdir()  # a folder that looks like a checkout but is none
    if shutil.which("git") is not None:
        monkeypatch.setenv("GIT_CEILING_DIRECTORIES", str(tmp_path.parent))
        assert provenance.git_commit() == f"unknown (not a git checkout; jaxterrain {version})"
    monkeypatch.setenv("PATH", str(tmp_path / "no-bin"))
    assert provenance.git_commit() == "unknown (git not available)"


def test_recorded_paths_carry_no_machines_layout_and_read_back(tmp_path):
    """What a run's files record: the package's files as <jaxterrain>/..., anything else relative to the run folder;
    both read back to the same file, and an old file's absolute path reads as it is."""
    import jaxterrain

    run = tmp_path / "runs" / "learn-1"
    asset = str(Path(jaxterrain.__file__).parent / "assets" / "archives" / "cppn_headings.npz")
    assert provenance.portable_path(asset, run) == "<jaxterrain>/assets/archives/cppn_headings.npz"
    assert provenance.resolve_recorded("<jaxterrain>/assets/archives/cppn_headings.npz", run) == asset
    mine = tmp_path / "archives" / "a.npz"
    assert provenance.portable_path(mine, run) == "../../archives/a.npz"
    assert provenance.resolve_recorded("../../archives/a.npz", run) == str(mine)
    assert provenance.resolve_recorded("/root/exp3/combined_archive.npz", run) == "/root/exp3/combined_archive.npz"
    assert provenance.portable_path("", run) == "" and provenance.resolve_recorded("", run) == ""
    mine.parent.mkdir(parents=True)
    mine.write_bytes(b"abc")
    assert provenance.file_sha256(mine) == "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
    assert provenance.file_sha256(tmp_path / "missing") is None


def test_device_names_count_kind_and_platform():
    import jax

    text = provenance.device()
    d = jax.devices()[0]
    assert text.startswith(f"{jax.device_count()} x ") and f"({d.platform}" in text
    assert ("CPU cores" in text) == (d.platform == "cpu")


def test_warp_hfield_reads_the_vendored_source_for_the_local_origin_patch(monkeypatch, tmp_path):
    """``warp_hfield`` names the engine's heightfield collision from MJX's vendored MuJoCo Warp source: the patch's
    line marks it patched, its absence stock, no vendored file absent."""
    from importlib import util
    from types import SimpleNamespace

    src = tmp_path / "mjx" / "third_party" / "mujoco_warp" / "_src"
    src.mkdir(parents=True)
    spec = SimpleNamespace(submodule_search_locations=[str(tmp_path / "mjx")])
    monkeypatch.setattr(util, "find_spec", lambda name: spec)
    assert provenance.warp_hfield() == "absent"
    (src / "collision_convex.py").write_text("    x = dx * float(cmin) - size[0]\n")
    assert provenance.warp_hfield() == "stock"
    (src / "collision_convex.py").write_text(f"    {provenance.WARP_HFIELD_MARKER}dx * float(cmin) - size[0])\n")
    assert provenance.warp_hfield() == "local-origin patch"
    patch = Path(__file__).resolve().parents[2] / "docs/results/sim2sim/warp_hfield/mjx_vendored_hfield_local_origin.patch"
    added = [line[1:] for line in patch.read_text().splitlines() if line.startswith("+") and not line.startswith("++")]
    assert any(provenance.WARP_HFIELD_MARKER in line for line in added)
