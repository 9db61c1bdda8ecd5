"""The commands over each stage's library (``python -m experiments``): what a command adds to the library it calls
(its flags, its run folder's files, its exit codes). The library itself is tested under tests/<stage>/; no test
outside tests/integration/ imports ``experiments`` (tests/test_package_layout.py holds it so)."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest

from experiments.__main__ import main
from report_runs import make_smoke_run

ROOT = Path(__file__).resolve().parents[2]


# ---- runtime: the run folder's config.json, --help without JAX


def test_a_run_config_records_no_absolute_path_and_reads_back(tmp_path):
    """``config.json`` written from now on holds its paths relative to the run folder (or <jaxterrain>/...); read
    back, they name the same files; an older config's absolute paths read as they are."""
    import json

    from experiments import common

    run = tmp_path / "runs" / "learn-1"
    run.mkdir(parents=True)
    asset = common.shipped("archives/cppn_headings.npz")
    mine = str(tmp_path / "mine" / "a.npz")
    config = {"archive": asset, "policy": str(tmp_path / "p"), "archives": {"cppn": mine}, "curriculum": "map",
              "data": None, "out": str(run)}
    common.write_config(run, config)
    text = (run / "config.json").read_text()
    assert str(tmp_path) not in text and "/work/" not in text
    saved = json.loads(text)
    assert saved["archive"] == "<jaxterrain>/assets/archives/cppn_headings.npz" and saved["out"] == "."
    assert saved["archives"] == {"cppn": "../../mine/a.npz"} and saved["policy"] == "../../p"
    assert common.load_config(run) == config  # the same values as written, on this machine
    old = {"archive": "/root/exp3/combined_archive.npz", "policy": "runs/x/policies/trial_0"}
    (run / "config.json").write_text(json.dumps(old))
    assert common.load_config(run) == old  # an older file: as it is


def test_help_reads_the_table_without_importing_jax():
    code = ("import sys; from experiments import common; print(common.smoke_minutes('learn')); "
            "print('jax' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.stdout.split("\n")[:2] == ["about 6-10 min on 2 CPU cores", "False"], done.stderr[-2000:]


# ---- report: the report and export commands
@pytest.fixture
def smoke_run(tmp_path):
    """A run folder as the commands write them (``report_runs.make_smoke_run``)."""
    return make_smoke_run(tmp_path)


def test_report_command_and_export_command(smoke_run, tmp_path, capsys):
    import trimesh

    from jaxterrain import qd as A
    from jaxterrain import terrain as T

    assert main(["report", str(smoke_run), "--no-videos"]) == 0
    assert (smoke_run / "report" / "report.html").is_file() and (smoke_run / "report" / "report.md").is_file()

    out = tmp_path / "terrains"
    assert main(["export", str(smoke_run / "archive.npz"), "--cells", "easy,10,hard", "--format", "obj", "stl",
                 "png", "npy", "mjcf", "--out", str(out)]) == 0
    names = sorted(p.name for p in out.iterdir())
    for cell in (0, 10, 15):  # easy = highest fitness (cell 0), hard = lowest (cell 15)
        for ext in (".obj", ".stl", ".png", ".npy", ".xml", ".hfield.bin"):
            assert f"cell{cell:04d}_perlin{ext}" in names
    arch = A.load(smoke_run / "archive.npz")
    expected = arch.heightmaps[10].astype(np.float32) / 65535.0
    np.testing.assert_allclose(T.load_npy(out / "cell0010_perlin.npy"), expected, atol=1e-6)
    mesh = trimesh.load(out / "cell0010_perlin.obj", process=False)
    assert len(mesh.vertices) == 16 * 16
    np.testing.assert_allclose(mesh.vertices[:, 2], expected.ravel(), atol=1e-5)
    rows = (out / "cells.csv").read_text().splitlines()
    assert rows[0] == "cell,generator,fitness,roughness,tpi,file" and len(rows) == 1 + 3 * 5
    with pytest.raises(SystemExit) as stop:  # one line naming the problem, exit status 2
        main(["export", str(smoke_run / "archive.npz"), "--cells", "1", "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert stop.value.code == 2 and err == "python -m experiments export: error: --cells: cell 1 is empty"
