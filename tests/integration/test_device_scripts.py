"""benchmarks/device/: the scripts that run the long GPU work (the tree shrunk and restored, one command line per
GPU under one deadline, actor-only walkers back)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tarfile
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
DEVICE = ROOT / "benchmarks" / "device"

pytestmark = pytest.mark.skipif(shutil.which("git") is None or shutil.which("bash") is None
                                or not (ROOT / ".git").exists(), reason="needs git, bash and a git checkout")


def test_ship_writes_actor_only_walkers_that_act_the_same(tmp_path):
    from jaxterrain import rl

    trial = tmp_path / "six" / "cppn-map" / "policies" / "trial_0"
    shutil.copytree(ROOT / "jaxterrain" / "assets" / "base_policy", trial)
    unfinished = tmp_path / "six" / "gan-map" / "policies" / "trial_0"
    shutil.copytree(trial, unfinished)
    (tmp_path / "six" / "cppn-map" / "summary.json").write_text("{}")  # only finished treatments ship
    out = subprocess.run([sys.executable, str(DEVICE / "ship.py"), str(tmp_path / "six"), "--to",
                          str(tmp_path / "ship")], capture_output=True, text=True, check=True).stdout
    assert "1 walkers" in out
    shipped = tmp_path / "ship" / "six" / "cppn-map" / "policies" / "trial_0"
    assert not (tmp_path / "ship" / "six" / "gan-map").exists()
    full, actor = rl.load_policy(trial), rl.load_policy(shipped)
    assert actor.meta["actor_only"] and set(actor.params) == {"policy"}
    assert (shipped / "policy.msgpack").stat().st_size < (trial / "policy.msgpack").stat().st_size / 10
    obs = np.random.default_rng(0).normal(size=(16, full.observation_size)).astype(np.float32)
    np.testing.assert_array_equal(np.asarray(actor(obs)), np.asarray(full(obs)))


def test_pair_runs_one_line_per_gpu_and_drops_warp_solver_cap_lines(tmp_path):
    spam = ("echo 'solver iterations limit reached - please increase iterations beyond 4'; echo 'To disable the print "
            "warning: m.opt.warn_overflow &= ~mjw.OverflowType.ITERATIONS (or = 0 for all)'; echo 'CCD overflow - "
            "please increase naccdmax beyond 8'")
    out = subprocess.run(["bash", str(DEVICE / "pair.sh"), "100", f"echo gpu=$CUDA_VISIBLE_DEVICES left=$(left); {spam}",
                          "echo gpu=$CUDA_VISIBLE_DEVICES; exit 3"], cwd=tmp_path, capture_output=True, text=True,
                         check=True).stdout
    assert "pair: GPU 0 exited 0" in out and "pair: GPU 1 exited 3" in out
    log0 = (tmp_path / "runs" / "gpu0.log").read_text().splitlines()
    assert log0[0].startswith("gpu=0 left=")
    assert 0.8 < float(log0[0].split("left=")[1]) <= (100 - 45) / 60  # minutes before the deadline
    assert log0[1:] == ["CCD overflow - please increase naccdmax beyond 8"]  # buffer overflows stay
    assert (tmp_path / "runs" / "gpu1.log").read_text() == "gpu=1\n"


def test_state_shrinks_the_tracked_tree_and_restores_it(tmp_path):
    repo = tmp_path / "repo"
    subprocess.run(["git", "clone", "-q", "--local", str(ROOT), str(repo)], check=True)
    subprocess.run(["git", "checkout", "-q", subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, text=True,
                    capture_output=True, check=True).stdout.strip()], cwd=repo, check=True)
    (repo / "runs").mkdir()
    (repo / "runs" / "kept.txt").write_text("ignored files are not touched")
    env = {"JT_STASH": str(tmp_path / "stash.tar"), "PATH": "/usr/bin:/bin"}
    state = DEVICE / "state.sh"  # this tree's script, run in the clone

    def tracked_present():
        files = subprocess.run(["git", "ls-files"], cwd=repo, capture_output=True, text=True, check=True).stdout.split()
        return {f for f in files if (repo / f).exists()}

    everything = tracked_present()
    subprocess.run(["bash", str(state), "medium"], cwd=repo, env=env, check=True, capture_output=True)
    medium = tracked_present()
    assert {".gitignore", "pyproject.toml", "docs/results/exp4/run.py"} <= medium
    assert all(f.split("/")[0] in {".gitignore", "pyproject.toml", "jaxterrain", "experiments", "benchmarks", "docs"}
               for f in medium)
    assert "README.md" not in medium and not any(f.startswith("tests/") for f in medium)
    subprocess.run(["bash", str(state), "tiny"], cwd=repo, env=env, check=True, capture_output=True)
    assert tracked_present() == {f for f in everything if f == ".gitignore" or f.startswith("benchmarks/device/")}
    subprocess.run(["bash", str(state), "restore"], cwd=repo, env=env, check=True, capture_output=True)
    assert tracked_present() == everything
    assert not (tmp_path / "stash.tar").exists() and (repo / "runs" / "kept.txt").exists()
    status = subprocess.run(["git", "status", "--porcelain"], cwd=repo, capture_output=True, text=True).stdout
    assert status == ""


def test_exp4_script_parses_and_refuses_a_bad_observation_set(tmp_path):
    """``exp4.sh`` (Experiment 4's training on a 2 x H200): valid bash, and a bad OBS refused in one line before
    anything runs or unpacks."""
    subprocess.run(["bash", "-n", str(DEVICE / "exp4.sh")], check=True)
    got = subprocess.run(["bash", str(DEVICE / "exp4.sh"), "100", "sighted"], cwd=tmp_path, capture_output=True,
                         text=True)
    assert got.returncode == 2 and got.stderr == "exp4.sh: OBS must be blind or perceptive, got sighted\n"
    assert not (tmp_path / "runs").exists()


def test_exp4_ant_script_parses_and_refuses_a_third_treatment(tmp_path):
    """``exp4_ant.sh`` (the ant's two treatments, one per GPU, then its walks): valid bash, and anything but two
    treatments refused in one line before anything runs or unpacks."""
    subprocess.run(["bash", "-n", str(DEVICE / "exp4_ant.sh")], check=True)
    got = subprocess.run(["bash", str(DEVICE / "exp4_ant.sh"), "100", "blind/mixed-dr"], cwd=tmp_path,
                         capture_output=True, text=True)
    assert got.returncode == 2
    assert got.stderr == "exp4_ant.sh: give two OBS/TREATMENT (the ant's treatments), got: blind/mixed-dr\n"
    assert not (tmp_path / "runs").exists()


@pytest.mark.parametrize("argv, message", [
    (["0.1", "mixed-dr", "mixed-plr", "mixed-map"], "give one or two treatments (one per GPU), got: mixed-dr "
                                                    "mixed-plr mixed-map"),
    (["mixed-accel"], "TREATMENT must be one of steps-map mixed-map mixed-dr mixed-plr mixed-levels, got mixed-accel"),
    (["1", "mixed-dr"], "C must be a finite number > 0 other than 1, got 1"),
    (["0", "mixed-dr"], "C must be a finite number > 0 other than 1, got 0"),
])
def test_exp4_scan_script_parses_and_refuses_bad_arguments(tmp_path, argv, message):
    """``exp4_scan.sh LIMIT_S [C] [T1 [T2]]`` (the perceptive humanoid retrained with --scan-lr-scale C, one
    treatment per GPU, then its walks): valid bash, and a bad scale, an unknown treatment or a third one refused in
    one line before anything runs or unpacks."""
    subprocess.run(["bash", "-n", str(DEVICE / "exp4_scan.sh")], check=True)
    got = subprocess.run(["bash", str(DEVICE / "exp4_scan.sh"), "100", *argv], cwd=tmp_path, capture_output=True,
                         text=True)
    assert got.returncode == 2 and got.stderr == f"exp4_scan.sh: {message}\n"
    assert not (tmp_path / "runs").exists()


def test_heldout_script_parses_and_needs_walkers_for_a_new_folder(tmp_path):
    """``heldout.sh OUT POLICY...``: valid bash; a new folder without walkers is refused in one line (a folder with
    a config.json resumes instead)."""
    subprocess.run(["bash", "-n", str(DEVICE / "heldout.sh")], check=True)
    got = subprocess.run(["bash", str(DEVICE / "heldout.sh"), "runs/h"], cwd=tmp_path, capture_output=True, text=True)
    assert got.returncode == 2 and got.stderr == "heldout.sh: no POLICY_DIR given\n"


@pytest.mark.parametrize("argv, message", [
    (["both", "100"], "the first argument must be split or orders, got 'both'"),
    (["split", "9m"], "LIMIT_S must be a whole number of seconds, got '9m'"),
    ([], "the first argument must be split or orders, got ''"),
])
def test_split_script_parses_and_refuses_bad_arguments(tmp_path, argv, message):
    """``split.sh split|orders LIMIT_S`` (issue 63's two-GPU split and interleaved orders): valid bash; a bad
    argument is refused in one line before anything runs."""
    subprocess.run(["bash", "-n", str(DEVICE / "split.sh")], check=True)
    got = subprocess.run(["bash", str(DEVICE / "split.sh"), *argv], cwd=tmp_path, capture_output=True, text=True)
    assert got.returncode == 2 and got.stderr == f"split.sh: {message}\n"
    assert not (tmp_path / "runs").exists()


def test_separate_resumes_a_partial_set_and_runs_first_lines(tmp_path):
    """``separate.sh`` on a fresh folder unpacks ``PARTIAL`` (an earlier call's ``separate.tar.gz``): a run it marks
    done is not evolved again; ``GENS0``/``GENS1`` choose each GPU's generators, ``FIRST0`` runs before them on GPU 0
    (with ``left``), and ``EXTRA_OUT`` travels in the returned tar."""
    done = tmp_path / "seed" / "runs" / "sep-perlin"
    done.mkdir(parents=True)
    (done / "done.json").write_text("{}")
    with tarfile.open(tmp_path / "partial.tar.gz", "w:gz") as tar:
        tar.add(done, arcname="runs/sep-perlin")
    work, out = tmp_path / "work", tmp_path / "out"
    work.mkdir()
    out.mkdir()
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}", "OUT": str(out),
           "PARTIAL": str(tmp_path / "partial.tar.gz"), "MIXED": "none", "GENS0": "perlin", "GENS1": "",
           "FIRST0": 'echo "first0 $(left)" > runs/first0.txt', "EXTRA_OUT": "runs/first0.txt"}
    subprocess.run(["bash", str(DEVICE / "separate.sh"), "100"], cwd=work, env=env, check=True, capture_output=True)
    assert "separate perlin: done (runs/sep-perlin)" in (work / "runs" / "gpu0.log").read_text()
    assert (work / "runs" / "first0.txt").read_text().startswith("first0 0.")  # minutes left of a 100-s deadline
    with tarfile.open(out / "separate.tar.gz") as tar:
        names = tar.getnames()
    assert "runs/first0.txt" in names and "runs/sep-perlin/done.json" in names and not (work / "runs" / "shares").exists()


@pytest.mark.slow
def test_separate_runs_five_archives_and_their_shares_at_smoke_size(tmp_path):
    """``separate.sh`` (issue 64 item 3's separate archives over two GPUs) at smoke size on the CPU: the five paper
    generators' ``evolve`` runs, each marked done, then ``shares`` of a mixed run against their combination with a
    ``steps`` run; everything in ``separate.tar.gz``; a second call starts no ``evolve`` again (about 6 min)."""
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}"}
    for gen in ("mixed", "steps"):
        subprocess.run([sys.executable, "-m", "experiments", "evolve", "--preset", "smoke", "--generator", gen,
                        "--out", f"sm-{gen}"], cwd=tmp_path, env=env, check=True, capture_output=True)
    out = tmp_path / "out"
    out.mkdir()
    env = {**env, "OUT": str(out), "PRESET": "smoke", "MIXED": "sm-mixed", "STEPS": "sm-steps"}
    subprocess.run(["bash", str(DEVICE / "separate.sh"), "600"], cwd=tmp_path, env=env, check=True,
                   capture_output=True)
    gens = ("perlin", "worley", "gan", "diamond_square", "cppn")
    assert all((tmp_path / "runs" / f"sep-{g}" / "done.json").is_file() for g in gens)
    shares = (tmp_path / "runs" / "shares" / "shares.md").read_text()
    assert "Cells filled in both:" in shares
    with tarfile.open(out / "separate.tar.gz") as tar:
        names = tar.getnames()
    assert all(f"runs/sep-{g}/archive.npz" in names for g in gens) and "runs/shares/shares.csv" in names
    subprocess.run(["bash", str(DEVICE / "separate.sh"), "600"], cwd=tmp_path, env=env, check=True,
                   capture_output=True)
    logs = (tmp_path / "runs" / "gpu0.log").read_text() + (tmp_path / "runs" / "gpu1.log").read_text()
    assert all(logs.count(f"separate {g}: done") == 2 for g in gens)  # the second call: done, nothing evolved
    assert logs.count("compiling a MAP-Elites generation") == 5


def test_exp4_unpack_takes_the_marker_not_the_folder_for_done(tmp_path):
    """``exp4_unpack.sh``: a ``runs/exp4`` that holds only ``separate.sh``'s mixed archive does not pass for the whole
    store (every shipped archive is unpacked, then the marker written); once the marker is there, a second call
    unpacks nothing (it would overwrite the walks of a run in progress); a tar that cannot be read fails in one line."""
    seed = tmp_path / "seed" / "runs" / "exp4" / "train" / "humanoid-blind"
    seed.mkdir(parents=True)
    (seed / "summary.json").write_text("shipped")
    archives = tmp_path / "work" / "docs" / "results" / "exp4" / "archives"
    archives.mkdir(parents=True)
    with tarfile.open(archives / "humanoid-blind.tar.gz", "w:gz") as tar:
        tar.add(tmp_path / "seed" / "runs", arcname="runs")
    work = tmp_path / "work"
    (work / "runs" / "exp4" / "archive" / "humanoid-mixed").mkdir(parents=True)  # what separate.sh leaves
    env = {k: v for k, v in os.environ.items() if k != "EXP4_TAR"}
    run = lambda **extra: subprocess.run(["bash", str(DEVICE / "exp4_unpack.sh")], cwd=work,  # noqa: E731
                                         env={**env, **extra}, capture_output=True, text=True)
    assert run().returncode == 0
    shipped = work / "runs" / "exp4" / "train" / "humanoid-blind" / "summary.json"
    assert shipped.read_text() == "shipped" and (work / "runs" / "exp4" / ".unpacked").is_file()
    shipped.write_text("in progress")
    assert run().returncode == 0 and shipped.read_text() == "in progress"
    (work / "runs" / "exp4" / ".unpacked").unlink()
    (tmp_path / "bad.tar.gz").write_text("not a tar")
    got = run(EXP4_TAR=str(tmp_path / "bad.tar.gz"))
    assert got.returncode == 1 and f"exp4_unpack.sh: could not unpack {tmp_path / 'bad.tar.gz'}" in got.stderr
    assert not (work / "runs" / "exp4" / ".unpacked").exists()
