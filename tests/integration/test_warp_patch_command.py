"""``python -m experiments warp-patch`` on a copy of the vendored ``collision_convex.py`` (``--file``; the installed
file is never touched here), and the ``warp_hfield`` a Warp run's ``provenance.jsonl`` records."""

from __future__ import annotations

import argparse
import json
import shutil

import pytest

from experiments import common
from experiments.__main__ import main
from jaxterrain.runtime import provenance
from jaxterrain.walker import warp_patch


@pytest.fixture
def copy(tmp_path):
    source = provenance.warp_hfield_source()
    if source is None or provenance.warp_hfield(source) != warp_patch.STOCK:
        pytest.skip("no stock vendored MuJoCo Warp in this mujoco-mjx")
    path = tmp_path / "collision_convex.py"
    shutil.copyfile(source, path)
    return path


def test_check_apply_revert_and_their_exit_status(copy, capsys):
    """``--check``: the status and the file, exit 0 only when patched; applying twice and reverting twice change the
    file once each."""
    stock = copy.read_bytes()
    assert main(["warp-patch", "--file", str(copy), "--check"]) == 1
    assert capsys.readouterr().out == f"stock: {copy}\n"
    assert main(["warp-patch", "--file", str(copy)]) == 0
    assert capsys.readouterr().out == f"local-origin patch: {copy} (was stock)\n"
    patched = copy.read_bytes()
    assert main(["warp-patch", "--file", str(copy)]) == 0 and copy.read_bytes() == patched
    assert capsys.readouterr().out == f"local-origin patch: {copy} (unchanged)\n"
    assert main(["warp-patch", "--file", str(copy), "--check"]) == 0
    assert capsys.readouterr().out == f"local-origin patch: {copy}\n"
    assert main(["warp-patch", "--file", str(copy), "--revert"]) == 0 and copy.read_bytes() == stock
    assert main(["warp-patch", "--file", str(copy), "--revert"]) == 0 and copy.read_bytes() == stock
    assert capsys.readouterr().out.splitlines() == [f"stock: {copy} (was local-origin patch)",
                                                    f"stock: {copy} (unchanged)"]


def test_a_file_it_does_not_fit_or_a_missing_one_is_one_line(copy, capsys):
    copy.write_text(copy.read_text().replace("pos_local = 0.5 * (w1 + w2)\n", "pos_local = 0.5 * (w2 + w1)\n"))
    changed = copy.read_bytes()
    assert main(["warp-patch", "--file", str(copy)]) == 1 and copy.read_bytes() == changed
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("warp-patch: error: ") and "mujoco-mjx 3.17.0" in err
    with pytest.raises(SystemExit) as stop:
        main(["warp-patch", "--file", str(copy.parent / "missing.py"), "--check"])
    assert stop.value.code == 2 and "--file" in capsys.readouterr().err
    with pytest.raises(SystemExit) as stop:
        main(["warp-patch", "--check", "--revert"])
    assert stop.value.code == 2


def test_help_says_what_it_changes_what_it_measured_and_that_it_edits_an_installed_package(capsys):
    with pytest.raises(SystemExit):
        main(["warp-patch", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "float32 at absolute heightfield coordinates" in text and "0.776-0.780" in text and "0.685-0.689" in text
    assert "EDITS A FILE OF AN INSTALLED PACKAGE" in text and "--revert" in text and "Exit status" in text


@pytest.mark.parametrize("backend,recorded", [("warp", True), ("jax", False), ("auto", False)])
def test_a_warp_runs_provenance_line_names_its_heightfield_collision(tmp_path, monkeypatch, backend, recorded):
    """``provenance.jsonl`` gets ``warp_hfield`` where the run's backend is (or resolves to) warp: ``auto`` on this
    CPU resolves to jax."""
    import jax

    if jax.default_backend() != "cpu" and backend == "auto":
        pytest.skip("auto resolves to jax on a CPU only")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(provenance, "warp_hfield", lambda path=None: "stock")
    presets = {"default": {"seed": 0, "backend": backend}}
    args = dict(resume=None, config=None, preset=None, seed=None, out="run")
    folder, _ = common.setup_run("gradient", argparse.Namespace(**args), presets, "default", {})
    (line,) = [json.loads(x) for x in (folder / common.PROVENANCE_NAME).read_text().splitlines()]
    assert line.get("warp_hfield") == ("stock" if recorded else None) and line["spawn"] == "feet"
    assert common.physics({"backend": "warp", "engine": "mujoco"}) is None
    assert common.physics({"rollout_backend": "warp"}) == "warp"
