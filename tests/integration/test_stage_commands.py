"""The commands over each stage's library (``python -m experiments``): what a command adds to the library it calls
(its flags, its run folder's files, its exit codes). The library itself is tested under tests/<stage>/; no test
outside tests/integration/ imports ``experiments`` (tests/test_package_layout.py holds it so)."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from curriculum_archives import tree_equal
from experiments.__main__ import main
from jaxterrain import rl
from jaxterrain.rl import onnx as onnx_export
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


# ---- rl: export-policy (the ONNX export: tests/rl/test_onnx.py), train-base-policy
ONNX_POLICIES = {
    "ant": ROOT / "jaxterrain" / "assets" / "base_policy_ant",
    "trained": ROOT / "docs" / "results" / "exp3_gpushort" / "diamond_square-map" / "policies" / "trial_0",
}


def test_export_policy_without_the_extra_one_line_names_it(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "onnx", None)
    with pytest.raises(SystemExit) as exit_:
        main(["export-policy", "--robot", "ant", "--onnx", str(tmp_path / "a.onnx")])
    err = capsys.readouterr().err.strip()
    assert exit_.value.code == 2 and err == ("python -m experiments export-policy: error: " + onnx_export.MISSING_EXTRA)
    assert not (tmp_path / "a.onnx").exists()


def test_export_policy_writes_a_checked_file(tmp_path, capsys):
    pytest.importorskip("onnxruntime", reason="needs the onnx extra: pip install 'jaxterrain[onnx]'")
    out = tmp_path / "sub" / "walker.onnx"
    assert main(["export-policy", "--policy", str(ONNX_POLICIES["trained"]), "--onnx", str(out)]) == 0
    line = capsys.readouterr().out.strip()
    assert line.startswith(f"wrote {out} (") and "humanoid, obs [batch, 45] -> action [batch, 17], dt 0.015 s" in line
    assert "matches the JAX policy" in line
    meta = rl.read_onnx_metadata(out)
    assert meta["provenance"]["source"] == Path(os.path.relpath(ONNX_POLICIES["trained"], out.parent)).as_posix()
    assert main(["export-policy", "--robot", "humanoid", "--onnx", str(tmp_path / "h.onnx"), "--batch", "2",
                     "--no-verify"]) == 0
    assert "not checked (--no-verify)" in capsys.readouterr().out
    assert rl.read_onnx_metadata(tmp_path / "h.onnx")["verification"] is None


@pytest.mark.parametrize("argv,message", [
    (["--policy", "MISSING", "--onnx", "w.onnx"], "--policy 'MISSING': no such folder"),
    (["--policy", ".", "--onnx", "w.onnx"], "--policy '.': not a policy folder (no policy.msgpack or config.json)"),
    (["--robot", "ant", "--onnx", "w.txt"], "--onnx 'w.txt': the file name must end in .onnx"),
    (["--robot", "ant", "--onnx", "DIR.onnx"], "--onnx 'DIR.onnx' is a folder"),
    (["--robot", "ant", "--onnx", "FILE/w.onnx"], "--onnx 'FILE/w.onnx' lies under FILE, which is a file"),
    (["--robot", "spider", "--onnx", "w.onnx"], "--robot: robot must be one of"),
    (["--robot", "ant", "--onnx", "w.onnx", "--batch", "0"], "--batch must be an integer >= 1; got 0"),
    (["--policy", "BROKEN", "--onnx", "w.onnx"], "--policy 'BROKEN': "),
])
def test_export_policy_bad_input_is_one_line_and_exit_2(tmp_path, monkeypatch, capsys, argv, message):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "DIR.onnx").mkdir()
    (tmp_path / "FILE").write_text("a file\n")
    (tmp_path / "BROKEN").mkdir()
    (tmp_path / "BROKEN" / "config.json").write_text("{not json")
    (tmp_path / "BROKEN" / "policy.msgpack").write_bytes(b"\x00")
    with pytest.raises(SystemExit) as exit_:
        main(["export-policy", *argv])
    err = capsys.readouterr().err.strip()
    assert exit_.value.code == 2 and len(err.splitlines()) == 1, err
    assert err.startswith("python -m experiments export-policy: error: ") and message in err, err
    assert not list(tmp_path.rglob("w.*"))


@pytest.mark.slow
def test_train_base_policy_resume_bit_identical(tmp_path):
    """train-base-policy --preset smoke: stopped by --time-limit after one chunk, then --resume FOLDER, ends with
    the same policy bytes and checkpoint as an uninterrupted run (MJX compiles: minutes on 2 CPU cores)."""
    import argparse

    from experiments import train_base_policy as tbp
    from jaxterrain.difficulty import base_policy
    from jaxterrain.runtime import driver

    parser = argparse.ArgumentParser()
    tbp.add_arguments(parser)
    common = ["--preset", "smoke", "--skip-eval", "--no-progress"]
    assert tbp.main(parser.parse_args(common + ["--out", str(tmp_path / "a")])) == 0
    assert tbp.main(parser.parse_args(common + ["--out", str(tmp_path / "b"), "--time-limit", "1e-6"])) == 3
    cfg_b = json.loads((tmp_path / "b" / "config.json").read_text())
    info_b = json.loads((tmp_path / "b" / base_policy.RUN_INFO).read_text())
    assert cfg_b["command"] == "train-base-policy" and info_b["num_updates"] == 4
    # --resume FOLDER alone continues the run with its saved settings (preset, seed, steps), as in evolve
    assert tbp.main(parser.parse_args(["--resume", str(tmp_path / "b"), "--skip-eval", "--no-progress"])) == 0
    for name in ("policy.msgpack", "config.json"):
        assert (tmp_path / "a" / "policy" / name).read_bytes() == (tmp_path / "b" / "policy" / name).read_bytes()
    like = _like_base_policy()
    (sa, da, ha, _), (sb, db, hb, meta) = (driver.restore(tmp_path / r, like=like) for r in ("a", "b"))
    assert da == db == 4 and tree_equal(sa, sb) and ha == hb
    assert meta["command"] == "train-base-policy" and meta["train_devices"]
    assert json.loads((tmp_path / "b" / base_policy.RUN_INFO).read_text())["resumed_with"]


def _like_base_policy():
    """A fresh smoke-preset PPO state (the structure of a train-base-policy checkpoint)."""
    from jaxterrain.difficulty import base_policy
    from jaxterrain.walker import WalkerEnv

    env_cfg, ppo_cfg = base_policy.shapes("smoke")
    env = WalkerEnv(env_cfg)
    return jax.jit(lambda k, t: rl.init(k, env, ppo_cfg, t))(
        jax.random.PRNGKey(0), jnp.zeros(tuple(env_cfg.terrain_shape), jnp.float32))


# ---- walker: train-base-policy --robot ant, evolve --robot


@pytest.mark.slow
def test_train_base_policy_trains_the_ant_and_its_policy_walks_the_ant(tmp_path):
    """``train-base-policy --robot ant`` (smoke): the policy records its robot, and the library's evaluation builds
    the ant's env for it (27 observations, 8 actions)."""
    import json

    from jaxterrain import difficulty, rl

    out = tmp_path / "ant"
    assert main(["train-base-policy", "--robot", "ant", "--out", str(out), "--no-progress"]) == 0
    meta = json.loads((out / "policy" / "config.json").read_text())
    assert meta["walker_config"]["robot"] == "ant" and (meta["observation_size"], meta["action_size"]) == (27, 8)
    policy = rl.load_policy(out / "policy")
    assert difficulty.default_env_config((32, 64), policy=policy).robot == "ant"
    assert 0.0 <= json.loads((out / "eval.json").read_text())["best_mean"] <= 1.0
    # learn starts from a policy of the robot it names, else refuses in one line; an archive of the humanoid's
    # fitness does not serve the ant
    assert main(["learn", "--policy", str(out / "policy"), "--robot", "humanoid", "--out", str(tmp_path / "l")]) == 2
    assert main(["learn", "--policy", str(out / "policy"), "--out", str(tmp_path / "l")]) == 2
    assert not (tmp_path / "l").exists()


# ---- qd: coverage --batched


@pytest.mark.slow  # about 40 s on 2 CPU cores; the unbatched coverage command: tests/test_experiments.py
def test_batched_coverage_command_writes_the_tables(tmp_path):
    """coverage --batched (evolve_many under the command: smoke preset, two generators) writes the coverage table,
    the batched run's checkpoint and one archive per treatment."""
    out = tmp_path / "cov"
    assert main(["coverage", "--preset", "smoke", "--batched", "--generators", "perlin", "diamond_square",
                 "--generations", "1", "--out", str(out)]) == 0
    assert "Perlin Noise" in (out / "coverage.md").read_text() and (out / "batched" / "checkpoint.npz").exists()
    assert len(list((out / "archives").glob("*/archive.npz"))) == 6


def test_evolve_refuses_a_robot_without_a_base_policy(tmp_path, monkeypatch, capsys):
    """``evolve --robot dog --fitness difficulty``: one line naming the robot, exit 2, no run folder."""
    from jaxterrain.walker import robots

    monkeypatch.setattr(robots, "_REGISTRY", dict(robots._REGISTRY))
    robots.register_robot(robots.ANT._replace(name="dog"))  # a robot nobody trained
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as stop:
        main(["evolve", "--robot", "dog", "--fitness", "difficulty"])
    assert stop.value.code == 2
    assert "--robot: robot 'dog': no base policy" in capsys.readouterr().err and not (tmp_path / "runs").exists()


def test_evaluate_and_train_base_policy_take_the_observation_set():
    """``evaluate --observation perceptive`` walks the perceptive base policy beside; ``train-base-policy
    --observation perceptive --scan-noise`` trains on the scan grid of the robot. Host only: nothing compiles."""
    from jaxterrain.difficulty import base_policy, run_config
    from jaxterrain.runtime import schema
    from jaxterrain.suite import runs
    from jaxterrain.suite.run_config import BaseWalker, EvaluateRun

    perceptive = EvaluateRun(base=BaseWalker(observation="perceptive"))
    assert runs.load_policies(perceptive)[0].path == rl.base_policy_dir("humanoid", "perceptive")
    settings = base_policy.validate_base_run(schema.replace(run_config.PRESETS["smoke"], {
        "walker.observation": "perceptive", "walker.scan_noise": 0.02}))
    assert settings.env_config.observation == "perceptive" and settings.env_config.scan_points == (17, 9)
    assert settings.env_config.scan_noise == pytest.approx(0.02)


# ---- features: train-traversability
@pytest.mark.slow
def test_train_traversability_smoke_preset_stops_and_resumes(tmp_path):
    """``train-traversability --preset smoke``: stopped by its time limit after the first generator's walks, resumed
    to the end (walks the second generator, trains, held out); minutes on 2 CPU cores: MJX compiles."""
    from jaxterrain.features import learned as trav

    out = str(tmp_path / "t")
    assert main(["train-traversability", "--preset", "smoke", "--out", out, "--time-limit", "1e-6"]) == 3
    assert (tmp_path / "t" / "data_perlin.npz").exists() and not (tmp_path / "t" / "data_diamond_square.npz").exists()
    assert main(["train-traversability", "--resume", out]) == 0  # walks the second generator, trains, held out
    model = trav.load(tmp_path / "t" / "model")
    assert model.config.channels == (4, 4, 4, 4) and len(model.meta["heldout"]) == 2



# ---- generators: train-gan (the loop: jaxterrain.generators.gan_train.train_gan, tests/generators/test_gan.py)
def test_train_gan_stops_at_its_time_limit_and_resumes_from_the_folder(tmp_path, monkeypatch):
    """``train-gan --time-limit``: exit 3 after the first checkpoint; ``--resume FOLDER`` alone takes the run's
    settings from its config.json (only --steps changes) and ends with final/; a resume into another folder is
    refused."""
    from experiments import common, train_gan

    # a tiny architecture so the test compiles fast; the command itself is unchanged
    monkeypatch.setitem(train_gan.PRESETS, "smoke", dict(
        train_gan.PRESETS["smoke"], channels=(16, 8, 4), disc_channels=(8, 16)))
    parser = argparse.ArgumentParser()
    train_gan.add_arguments(parser)
    out = tmp_path / "c"
    argv = ["--preset", "smoke", "--size", "32", "--batch-size", "2", "--steps", "2", "--out", str(out),
            "--checkpoint-every", "1", "--sample-every", "1", "--log-every", "1", "--quality-samples", "0",
            "--no-progress"]
    assert train_gan.main(parser.parse_args(argv + ["--time-limit", "0.00001"])) == 3  # as evolve
    assert (out / "checkpoint.npz").exists() and not (out / "final").exists()
    with pytest.raises(ValueError, match="different runs"):
        common.resume_folder("train-gan", str(out), str(tmp_path / "d"))
    assert train_gan.main(parser.parse_args(["--resume", str(out), "--steps", "3", "--no-progress"])) == 0
    saved = json.loads((out / "config.json").read_text())
    assert saved["command"] == "train-gan" and saved["batch_size"] == 2 and saved["steps"] == 3
    assert (out / "final" / "generator.msgpack").is_file()
    assert [json.loads(line)["step"] for line in (out / "log.jsonl").read_text().splitlines()] == [1, 2, 3]
