"""``docs/results/exp4/run.py``, Experiment 4's stages, without running one (the stages end to end at CPU size:
``tests/integration/test_exp4_run.py``, slow): its arguments are checked in one line, its humanoid run makes
exactly the five treatments of issue 64 (``curriculum --baseline-archive mixed --no-combined``), ``--plan``'s
arithmetic, and what ``--pack`` leaves out. Seconds, no JAX work."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest
from scripts import load_script

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "docs" / "results" / "exp4" / "run.py"


def fake_learn(calls: list):
    """A stand-in for ``run.cli``: records each command; a fresh ``learn`` run leaves a finished treatment."""

    def learn(argv, args):
        calls.append(argv)
        if argv[0] == "learn" and argv[1] != "--resume":
            folder = Path(argv[argv.index("--out") + 1])
            (folder / "policies").mkdir(parents=True)
            (folder / "summary.json").write_text("{}")
        return 0

    return learn


@pytest.fixture(scope="module")
def run():
    module = load_script(SCRIPT, "exp4_run")
    return module


@pytest.fixture(autouse=True)
def no_stock_warp_here(run, monkeypatch):
    """These tests hold whether or not this machine has MuJoCo Warp: where warp-lang is installed and unpatched, the
    presets' ``auto`` backend would make a train stage refuse the stock heightfield collision (tested on its own)."""
    monkeypatch.setattr(run, "_warp_hfield", lambda: "local-origin patch")


@pytest.mark.parametrize("argv, message", [
    ([], "give a stage (archive, train, evaluate, write) or --plan"),
    (["fly"], "STAGE must be one of archive, train, evaluate, write; got 'fly'"),
    (["archive", "cppn"], "archive takes one generator: steps or mixed; got cppn"),
    (["train", "dog"], "train takes a robot: humanoid or ant; got dog"),
    (["train", "humanoid"], "train humanoid takes an observation set: blind or perceptive; got none"),
    (["train", "ant"], "train ant needs --ant OBS/TREATMENT OBS/TREATMENT"),
    (["train", "ant", "--ant", "blind/steps-map", "blind/steps-map"], "--ant takes the two best treatments (one for "
                                                                      "a check), each OBS/TREATMENT once"),
    (["train", "ant", "--ant", "blind/mixed-accel"], "--ant must be OBS/TREATMENT with OBS one of blind, perceptive"),
    (["train", "ant", "--ant", "a/mixed-map", "blind/steps-map", "perceptive/mixed-dr"], "--ant must be OBS/TREATMENT"),
    (["train", "humanoid", "blind", "--treatments", "mixed-dr"], "--treatments: a mixed-* baseline needs mixed-map"),
    (["evaluate", "--treatments", "mixed-map"], "--treatments chooses the humanoid's treatments of 'train humanoid'"),
    (["evaluate", "--robot", "ant"], "--robot chooses whose archive the archive stage evolves"),
    (["--plan", "write"], "--plan runs no stage; got write"),
    (["write", "--time-limit", "0"], "--time-limit must be a finite number of minutes > 0; got 0.0"),
    (["evaluate", "--pack", "x.zip"], "--pack must name a .tar.gz or .tgz file; got x.zip"),
    (["evaluate", "--keys", "0"], "--keys must be an integer >= 1; got 0"),
    (["evaluate", "--pack", "/x.tar.gz"], "--pack stores --out relative to the current folder"),  # --out: tmp_path
    (["evaluate", "--headings", "3"], "--headings must be one of 1, 2, 4; got 3"),
    (["archive", "mixed", "--archive-size", "16"], "--archive-size must be an integer >= 32; got 16"),
    (["train", "humanoid", "blind", "--shard", "2/2"], "--shard must be I/N with N >= 1 and 0 <= I < N; got '2/2'"),
    (["train", "humanoid", "blind", "--shard", "a"], "--shard must be I/N with N >= 1 and 0 <= I < N; got 'a'"),
    (["evaluate", "--shard", "0/2"], "--shard splits a 'train' stage over processes"),
    (["evaluate", "--part", "2/2"], "--part must be K/N with integers 0 <= K < N; got '2/2'"),
    (["train", "humanoid", "blind", "--part", "0/2"], "--part splits the walks of 'evaluate' over processes"),
    (["evaluate", "--scan-lr-scale", "0.1"], "--scan-lr-scale retrains perceptive humanoid treatments: 'train "
                                             "humanoid perceptive --scan-lr-scale C --treatments T ...'"),
    (["train", "humanoid", "blind", "--scan-lr-scale", "0.1", "--treatments", "mixed-dr"],
     "--scan-lr-scale retrains perceptive humanoid treatments"),
    (["train", "ant", "--ant", "blind/mixed-dr", "--scan-lr-scale", "0.1"],
     "--scan-lr-scale retrains perceptive humanoid treatments"),
    (["train", "humanoid", "perceptive", "--scan-lr-scale", "0.1"], "--scan-lr-scale needs --treatments T [T ...]"),
    *[(["train", "humanoid", "perceptive", "--scan-lr-scale", c, "--treatments", "mixed-dr"],
       "--scan-lr-scale must be a finite number > 0 other than 1 (1: the original run, without the flag); got "
       + str(float(c))) for c in ("0", "-0.1", "1", "1.0", "nan", "inf")],
    (["train", "humanoid", "perceptive", "--scan-lr-scale", "0.1", "--treatments", "mixed-dr", "mixed-dr"],
     "--treatments: each treatment once; got mixed-dr mixed-dr"),
])

def test_bad_arguments_are_one_line_naming_the_flag(run, argv, message, capsys, tmp_path):
    with pytest.raises(SystemExit) as err:
        run.main([*argv, "--out", str(tmp_path / "out")])
    lines = capsys.readouterr().err.strip().splitlines()
    assert err.value.code == 2 and message in lines[-1], lines
    assert not (tmp_path / "out").exists()


def test_a_warp_stage_refuses_the_stock_heightfield_collision_in_one_line(run, monkeypatch, capsys, tmp_path):
    """evaluate (default --eval-backend warp) and train --backend warp refuse MuJoCo Warp's stock heightfield
    collision before anything runs, naming the patch and the way out; jax, and the patched kernel, pass the check."""
    monkeypatch.setattr(run, "_warp_hfield", lambda: "stock")
    for argv, way_out in ((["evaluate"], "--eval-backend jax"), (["train", "humanoid", "blind", "--backend", "warp"],
                                                                  "--backend jax")):
        with pytest.raises(SystemExit) as err:
            run.main([*argv, "--out", str(tmp_path / "out")])
        line = capsys.readouterr().err.strip().splitlines()[-1]
        assert err.value.code == 2 and "stock heightfield collision" in line and line.endswith(way_out), line
        assert "mjx_vendored_hfield_local_origin.patch" in line and not (tmp_path / "out").exists()
    p = run.parser()
    args = p.parse_args(["evaluate", "--eval-backend", "jax", "--out", str(tmp_path / "out")])
    run.check(p, args)  # no Warp: no refusal
    monkeypatch.setattr(run, "_warp_hfield", lambda: "local-origin patch")
    args = p.parse_args(["evaluate", "--out", str(tmp_path / "out")])
    run.check(p, args)
    argv = run.reevaluate_argv(args, "v2", [], ["humanoid"])
    assert argv[argv.index("--backend") + 1] == "warp"


def test_the_humanoid_run_makes_the_five_treatments(run, tmp_path):
    """The ``curriculum`` command of ``train humanoid OBS``, parsed by ``curriculum``'s own parser, plans exactly
    :data:`TREATMENTS` (the folders the later stages read): the map curriculum on each archive, DR / PLR / levels on
    the mixed one, no combined archive; a subset plans that subset."""
    from experiments import curriculum as exp

    def planned(argv):
        parser = argparse.ArgumentParser()
        exp.add_arguments(parser)
        a = parser.parse_args(argv[1:])
        cfg = {"archives": exp.parse_archives(a.archives), "baseline": a.baseline or "roughness",
               "baseline_archive": a.baseline_archive or "cppn", "combined": a.combined is not False}
        exp.check_baseline_archive(cfg, a.baseline_archive is not None, a.baseline is not None)
        return [f"{name}-{c}" for name, _, c in exp.treatments(cfg, tmp_path)], a

    args = argparse.Namespace(out=tmp_path / "exp4", preset="gpu-short", trials=10, backend=None)
    names, a = planned(run.curriculum_argv(args, "perceptive"))
    assert names == ["mixed-map", "steps-map", "mixed-dr", "mixed-plr", "mixed-levels"]  # archives by name
    assert sorted(names) == sorted(run.TREATMENTS)
    assert a.observation == "perceptive" and a.trials == 10 and a.preset == "gpu-short"
    assert exp.parse_archives(a.archives)["steps"] == str(ROOT / run.SHIPPED_STEPS)  # the shipped gpu-short archive
    assert not (tmp_path / "combined_archive.npz").exists()
    assert planned(run.curriculum_argv(args, "blind", ["mixed-map"]))[0] == ["mixed-map"]
    assert planned(run.curriculum_argv(args, "blind", ["steps-map", "mixed-map", "mixed-plr"]))[0] == [
        "mixed-map", "steps-map", "mixed-plr"]


def test_a_sharded_humanoid_train_passes_its_shard_to_curriculum(run, tmp_path, monkeypatch, capsys):
    """``train humanoid OBS --shard I/N`` runs ``curriculum ... --shard I/N``, fresh and resumed, and says that the
    tables come from the same train without ``--shard``."""
    calls = []
    monkeypatch.setattr(run, "cli", lambda argv, args: calls.append(argv) or 0)
    monkeypatch.setattr(run, "archive_done", lambda *a: True)
    out = tmp_path / "exp4"
    assert run.main(["train", "humanoid", "blind", "--shard", "1/2", "--out", str(out)]) == 0
    assert calls[-1][0] == "curriculum" and "--archives" in calls[-1] and calls[-1][-2:] == ["--shard", "1/2"]
    assert "shard 1/2: done" in capsys.readouterr().out
    folder = run.train_folder(out, "humanoid", "blind")
    folder.mkdir(parents=True)
    (folder / "config.json").write_text("{}")
    assert run.main(["train", "humanoid", "blind", "--shard", "0/2", "--out", str(out)]) == 0
    assert calls[-1] == ["curriculum", "--resume", str(folder), "--shard", "0/2"]
    assert run.main(["train", "humanoid", "blind", "--out", str(out)]) == 0  # the tables: no --shard
    assert calls[-1] == ["curriculum", "--resume", str(folder)]
    assert "train humanoid blind: done" in capsys.readouterr().out


def test_a_partial_evaluate_passes_its_part_and_counts_only_its_share(run, tmp_path, monkeypatch, capsys):
    """``evaluate --part K/N`` runs reevaluate.py with ``--part K/N`` on every suite and counts as left only the
    walks of its share (``batch.part`` of reevaluate.py's job order), so that a part done says done while the other
    part still walks."""
    from jaxterrain.suite import batch

    out = tmp_path / "exp4"
    monkeypatch.setattr(run, "treatment_done", lambda f: True)
    monkeypatch.setattr(run, "humanoid_choice", lambda o: list(run.TREATMENTS))
    walkers = [batch.Job(f"{o}/{t}/policies/trial_{k}", "humanoid", f"{o}/{t}/policies/trial_{k}", 0, f"{o}/{t}")
               for o in run.OBSERVATIONS for t in run.TREATMENTS for k in range(2)]
    monkeypatch.setattr(batch, "walker_jobs", lambda folders: list(walkers))  # 20 walkers, no policy files
    calls = []

    class Reevaluate:
        @staticmethod
        def main(argv):
            calls.append(argv)
            jobs = [j for o in run.OBSERVATIONS for j in batch.base_jobs("humanoid", 2, o)] + walkers
            results = out / "eval" / argv[argv.index("--suite") + 1] / "results"
            results.mkdir(parents=True, exist_ok=True)
            for j in batch.part(jobs, 1, 2):  # part 1/2 walked, part 0/2 not
                (results / f"{run._file(j.name)}.npz").write_text("")
            return 0

    monkeypatch.setattr(run, "load_reevaluate", lambda: Reevaluate)
    assert run.main(["evaluate", "--part", "1/2", "--keys", "2", "--out", str(out)]) == 0
    assert [c[c.index("--part") + 1] for c in calls] == ["1/2", "1/2"]  # v2, then v1
    assert "evaluate part 1/2: done" in capsys.readouterr().out
    assert run.main(["evaluate", "--part", "0/2", "--keys", "2", "--out", str(out)]) == 0
    assert "evaluate part 0/2: 24 walks left; run it again" in capsys.readouterr().out  # (4 bases + 20) / 2 x 2


def test_a_sharded_ant_train_runs_only_its_share_of_the_chosen_treatments(run, tmp_path, monkeypatch, capsys):
    """``train ant --ant A B --shard I/2`` trains the I-th of the two chosen treatments (one per GPU); both
    processes save the same choice, and a third process without ``--shard`` finds both done."""
    calls = []
    monkeypatch.setattr(run, "cli", fake_learn(calls))
    monkeypatch.setattr(run, "archive_done", lambda *a: True)
    out = tmp_path / "exp4"
    ant = ["--ant", "blind/mixed-dr", "blind/mixed-levels"]
    assert run.main(["train", "ant", *ant, "--shard", "1/2", "--out", str(out)]) == 0
    assert [c[c.index("--curriculum") + 1] for c in calls] == ["levels"]
    assert run.main(["train", "ant", *ant, "--shard", "0/2", "--out", str(out)]) == 0
    assert [c[c.index("--curriculum") + 1] for c in calls] == ["levels", "dr"]
    assert run.ant_choice(out) == [("blind", "mixed-dr"), ("blind", "mixed-levels")]
    capsys.readouterr()
    assert run.main(["train", "ant", *ant, "--out", str(out)]) == 0 and len(calls) == 2
    assert capsys.readouterr().out.count(": done (") == 2


def test_an_ant_treatment_is_one_learn_run_on_the_ants_archive(run, tmp_path):
    args = argparse.Namespace(out=tmp_path, preset="gpu-short", trials=10, backend="warp", archive_size=None)
    argv = run.learn_argv(args, "ant", "perceptive", "mixed-plr", run.train_folder(tmp_path, "ant", "perceptive"))
    assert argv[:2] == ["learn", "--robot"] and argv[2] == "ant"
    flags = dict(zip(argv[3::2], argv[4::2]))
    assert flags == {"--preset": "gpu-short", "--archive": str(tmp_path / "archive" / "ant-mixed" / "archive.npz"),
                     "--curriculum": "plr", "--observation": "perceptive", "--trials": "10",
                     "--out": str(tmp_path / "train" / "ant-perceptive" / "mixed-plr"), "--backend": "warp"}
    assert run.archive_argv(args, "mixed", "humanoid")[-8:] == run.ARCHIVE_FLAGS["mixed"]
    assert run.archive_argv(args, "steps", "ant")[-2:] == ["--robot", "ant"]


def test_the_plan_adds_the_measured_rates(run):
    """Two train runs of 5 and 2 treatments left, one archive, 12 walks of one program and 3 of another on v2: the
    sums of the module docstring's rule, with made-up rates (so the test pins the arithmetic, not the figures)."""
    rates = {**run.RATES, "archive_mixed_s": (600.0, ""), "archive_ant_factor": (0.5, ""),
             "treatment_s_warp": ((400.0, 500.0), ""), "population_factor": (0.8, ""), "v2_first_s": (70.0, ""),
             "v2_walker_s_jax": ((20.0, 30.0), ""), "build_s": (60.0, ""), "ant_eval_factor": (2.0, ""),
             "compile_s": ((10.0, 80.0), "")}
    state = {"archives_left": [("humanoid", "mixed"), ("ant", "mixed")],
             "train_left": {"humanoid blind": 5, "humanoid perceptive": 0, "ant blind": 2},
             "walks_left": {"v2": {("humanoid", "blind"): 12, ("humanoid", "perceptive"): 3, ("ant", "blind"): 0,
                                   ("ant", "perceptive"): 0}},
             "measured": {}, "ant_pending": False, "train_backend": "warp", "eval_backend": "jax", "trials": 10,
             "keys": 10}
    got = run.predict(state, rates)
    assert got == {"archive mixed --robot humanoid": (600.0, 600.0), "archive mixed --robot ant": (300.0, 300.0),
                   # 2 000 s at 400 s a command (480 less the compile): 5 commands, each its compile
                   "train humanoid blind": (5 * 400 * 0.8 + 5 * 10, 5 * 500 * 0.8 + 5 * 80),
                   "train ant blind": (800.0 + 3 * 10, 1000.0 + 3 * 80),
                   "evaluate v2": (60 + 2 * 70 + 13 * 20.0, 60 + 2 * 70 + 13 * 30.0)}
    measured = run.predict({**state, "measured": {"v2": (100.0, (10.0, 11.0))}}, rates)["evaluate v2"]
    assert measured == (60 + 2 * 100 + 13 * 10.0, 60 + 2 * 100 + 13 * 11.0)
    pending = run.predict({**state, "ant_pending": True, "archives_left": []}, rates)
    assert pending["train ant (2 treatments, not chosen yet)"] == (800.0 + 3 * 10, 1000.0 + 3 * 80)
    assert pending["archive steps --robot ant (not chosen yet)"] == (rates["archive_steps_s"][0] * 0.5,) * 2
    ant = 2.0 * (60 + 2 * 70 + (2 * 20 - 2) * 20.0)  # two programs of trials + keys walks each
    assert pending["evaluate v2"][0] == pytest.approx(60 + 2 * 70 + 13 * 20.0 + ant)
    assert run.commands((0.0, 480.0)) == 1 and run.commands((0.0, 481.0)) == 2 and run.commands((0.0, 0.0)) == 1
    for name, (value, source) in run.RATES.items():  # every figure says where it comes from
        assert source.startswith(("measured: ", "assumed: ")), name


def test_the_plan_reads_a_run_folder(run, tmp_path, capsys):
    """``--plan`` on an empty folder: the humanoid's steps archive ships, the mixed one is left, nothing trained; a
    finished treatment (summary.json and policies/) counts as done; one recorded walk replaces the rates."""
    out = tmp_path / "exp4"
    assert run.main(["--plan", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "archive steps --robot humanoid: done" in text and "archive mixed --robot humanoid: left" in text
    assert "train humanoid blind: 0/5 treatments done" in text and "evaluate v2: humanoid blind 60 walks left" in text
    done = out / "train" / "humanoid-blind" / "mixed-dr"
    (done / "policies").mkdir(parents=True)
    (done / "summary.json").write_text("{}")
    assert run.main(["--plan", "--out", str(out)]) == 0
    assert "train humanoid blind: 1/5 treatments done" in capsys.readouterr().out


def test_the_plan_counts_an_ant_archive_evolved_early_by_what_is_left(run, tmp_path, capsys):
    """Before the ant's treatments are chosen its archives may already be evolving: a finished one is done (no
    device time), one stopped after 3 of its 5 generations has 2 / 5 of its time left (the checkpoint's
    ``metrics.csv``: a header, the initial population, one row per generation)."""
    out = tmp_path / "exp4"
    steps, mixed = run.archive_folder(out, "ant", "steps"), run.archive_folder(out, "ant", "mixed")
    for folder in (steps, mixed):
        (folder / "checkpoint").mkdir(parents=True)
        (folder / "config.json").write_text(json.dumps({"generations": 5}))
    (steps / "archive.npz").write_text("x")
    (steps / "done.json").write_text("{}")
    (mixed / "checkpoint" / "metrics.csv").write_text("step,coverage\n" + "".join(f"{i},1\n" for i in range(1, 5)))
    assert run.archive_share_left(out, "ant", "steps", "gpu-short") == 0.0
    assert run.archive_share_left(out, "ant", "mixed", "gpu-short") == pytest.approx(0.4)
    assert run.archive_share_left(out, "humanoid", "mixed", "gpu-short") == 1.0  # nothing there yet
    assert run.main(["--plan", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "archive steps --robot ant: done" in text and "archive mixed --robot ant: partial (40% left)" in text
    assert "archive steps --robot ant (not chosen yet)" not in text
    full = run.RATES["archive_mixed_s"][0] * run.RATES["archive_ant_factor"][0]
    assert f"archive mixed --robot ant (not chosen yet): {0.4 * full / 60:.1f}-" in text


def test_the_pack_leaves_out_finished_checkpoints(run, tmp_path):
    out = tmp_path / "exp4"
    files = ["archive/humanoid-mixed/archive.npz", "archive/humanoid-mixed/done.json",
             "archive/humanoid-mixed/checkpoint/ckpt_1/state.npz", "archive/ant-mixed/checkpoint/ckpt_1/state.npz",
             "train/humanoid-blind/mixed-map/summary.json", "train/humanoid-blind/mixed-map/policies/trial_0/p.msgpack",
             "train/humanoid-blind/mixed-map/checkpoint.npz", "train/humanoid-blind/mixed-map/checkpoint.prev.npz",
             "train/humanoid-blind/mixed-dr/checkpoint.npz", "eval/v2/results/base+humanoid.npz", "eval/v2/x.tmp"]
    for f in files:
        (out / f).parent.mkdir(parents=True, exist_ok=True)
        (out / f).write_text("x")
    kept = sorted(str(p.relative_to(out)) for p in run.pack_members(out))
    assert kept == sorted(["archive/humanoid-mixed/archive.npz", "archive/humanoid-mixed/done.json",
                           "archive/ant-mixed/checkpoint/ckpt_1/state.npz",  # unfinished: needed to resume
                           "train/humanoid-blind/mixed-map/summary.json",
                           "train/humanoid-blind/mixed-map/policies/trial_0/p.msgpack",
                           "train/humanoid-blind/mixed-dr/checkpoint.npz", "eval/v2/results/base+humanoid.npz"])
    saved = out / "ant.json"
    saved.write_text(json.dumps({"treatments": [["blind", "steps-map"]]}))
    assert [(r, o, n) for r, o, _, n in run.runs(out)][-1] == ("ant", "blind", ["steps-map"])


def test_a_stage_with_no_time_left_starts_nothing_and_says_how_to_go_on(run, tmp_path, capsys, monkeypatch):
    """Under ``--time-limit`` a stage hands the child command what is left; with nothing left it starts none and
    exits 3 ("run the same command again"); the humanoid's treatments are saved at its first train, and another
    ``--treatments`` on the same ``--out`` is refused in one line."""
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "exp4"
    for gen in ("steps", "mixed"):  # archives as the archive stage leaves them when done
        (out / "archive" / f"humanoid-{gen}").mkdir(parents=True)
        (out / "archive" / f"humanoid-{gen}" / "archive.npz").write_text("x")
        (out / "archive" / f"humanoid-{gen}" / "done.json").write_text("{}")
    monkeypatch.setattr(run, "STARTED", run.time.perf_counter() - 120.0)  # two minutes gone
    argv = ["train", "humanoid", "blind", "--treatments", "steps-map", "mixed-map", "--preset", "smoke", "--out",
            str(out), "--time-limit", "1", "--pack", "exp4.tar.gz"]
    assert run.main(argv) == 3
    text = capsys.readouterr().out
    assert "no time left for curriculum" in text and "run the same command again" in text and "packed" in text
    assert json.loads((out / "humanoid.json").read_text()) == {"treatments": ["steps-map", "mixed-map"]}
    assert run.main([*argv[:3], "--treatments", "mixed-map", *argv[6:]]) == 2
    assert "humanoid.json chose steps-map mixed-map" in capsys.readouterr().err


def test_the_pack_carries_walkers_actor_only(run, tmp_path, monkeypatch):
    """A finished treatment's walkers travel without their value networks (the device returns at most 16 MiB a
    file; 50 full humanoid walkers are ~55 MB): the packed walker acts as the one on disk, which stays whole."""
    import shutil
    import tarfile

    import numpy as np

    from jaxterrain import rl

    monkeypatch.chdir(tmp_path)
    treatment = tmp_path / "exp4" / "train" / "humanoid-blind" / "mixed-map"
    walker = treatment / "policies" / "trial_0"
    walker.mkdir(parents=True)
    for name in ("policy.msgpack", "config.json"):
        shutil.copy(rl.BASE_POLICY_DIR / name, walker / name)
    (treatment / "summary.json").write_text("{}")
    run.pack(argparse.Namespace(out=Path("exp4"), pack=tmp_path / "exp4.tar.gz"))
    with tarfile.open(tmp_path / "exp4.tar.gz") as tar:
        names = tar.getnames()
        tar.extractall(tmp_path / "unpacked")
    assert sorted(names) == ["exp4/train/humanoid-blind/mixed-map/policies/trial_0/config.json",
                             "exp4/train/humanoid-blind/mixed-map/policies/trial_0/policy.msgpack",
                             "exp4/train/humanoid-blind/mixed-map/summary.json"]
    full, packed = rl.load_policy(walker), rl.load_policy(tmp_path / "unpacked" / names[0].rsplit("/", 1)[0])
    assert packed.meta["actor_only"] and not full.meta.get("actor_only") and "value" in full.params
    obs = np.random.default_rng(1).normal(size=(8, full.observation_size)).astype(np.float32)
    np.testing.assert_array_equal(np.asarray(packed(obs)), np.asarray(full(obs)))


def test_the_pack_leaves_out_unfinished_train_checkpoints_that_would_not_come_back(run, tmp_path, monkeypatch,
                                                                                   capsys):
    """Unfinished train checkpoints over ``PACK_TRAIN_CHECKPOINTS`` in all stay out of the pack, said in one line
    (a pack over 16 MiB would not come back at all); under it they go in; an archive's checkpoint always does."""
    import tarfile

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(run, "PACK_TRAIN_CHECKPOINTS", 1000)
    out = Path("exp4")
    files = {"train/humanoid-blind/mixed-dr/checkpoint.npz": 600, "train/humanoid-blind/mixed-plr/checkpoint.npz": 600,
             "archive/ant-mixed/checkpoint/checkpoint.npz": 5000}
    for f, size in files.items():
        (out / f).parent.mkdir(parents=True, exist_ok=True)
        (out / f).write_bytes(b"x" * size)

    def packed():
        run.pack(argparse.Namespace(out=out, pack=tmp_path / "exp4.tar.gz"))
        with tarfile.open(tmp_path / "exp4.tar.gz") as tar:
            return sorted(tar.getnames())

    assert packed() == ["exp4/archive/ant-mixed/checkpoint/checkpoint.npz"]
    assert "left out 2 unfinished train checkpoint(s)" in capsys.readouterr().out
    (out / "train/humanoid-blind/mixed-plr/checkpoint.npz").unlink()  # 600 bytes: under the limit, it goes in
    assert packed() == ["exp4/archive/ant-mixed/checkpoint/checkpoint.npz",
                        "exp4/train/humanoid-blind/mixed-dr/checkpoint.npz"]
    assert "left out" not in capsys.readouterr().out


def test_plan_with_pack_packs_without_running_anything(run, tmp_path, monkeypatch, capsys):
    """``--plan --pack FILE``: the plan, then the pack of what is there (the device script's pack when a train has
    not finished: nothing may start then)."""
    import tarfile

    monkeypatch.chdir(tmp_path)
    done = Path("exp4") / "archive" / "ant-steps"
    done.mkdir(parents=True)
    for name in ("archive.npz", "done.json"):
        (done / name).write_text("x")
    assert run.main(["--plan", "--out", "exp4", "--pack", "exp4.tar.gz"]) == 0
    assert "predicted device time" in capsys.readouterr().out
    with tarfile.open(tmp_path / "exp4.tar.gz") as tar:
        assert sorted(tar.getnames()) == ["exp4/archive/ant-steps/archive.npz", "exp4/archive/ant-steps/done.json"]


def scan_args(run, tmp_path, *extra):
    """``train humanoid perceptive --scan-lr-scale 0.1 --treatments ...`` parsed and checked (nothing runs)."""
    p = run.parser()
    args = p.parse_args(["train", "humanoid", "perceptive", "--scan-lr-scale", "0.1", "--out", str(tmp_path / "exp4"),
                         *extra])
    run.check(p, args)
    return args


def test_a_scan_retrain_treatment_is_one_learn_run_with_the_scale(run, tmp_path):
    """Each retrained treatment is ``learn --robot humanoid --observation perceptive --scan-lr-scale C`` on the
    humanoid's archive of its generator with its curriculum (the shipped steps archive at gpu-short), into
    ``OUT/train/humanoid-perceptive-scan<C>/<T>``; ``learn``'s own parser reads it. A retrain needs no mixed-map
    beside a mixed-* baseline (learn runs, not one curriculum run)."""
    from experiments import learn

    args = scan_args(run, tmp_path, "--treatments", "mixed-dr", "steps-map", "--backend", "jax")
    folder = run.scan_folder(args.out, 0.1)
    assert folder == tmp_path / "exp4" / "train" / "humanoid-perceptive-scan0.1"
    parser = argparse.ArgumentParser()
    learn.add_arguments(parser)
    for treatment, archive, curriculum in (("mixed-dr", args.out / "archive" / "humanoid-mixed" / "archive.npz", "dr"),
                                           ("steps-map", ROOT / run.SHIPPED_STEPS, "map")):
        argv = run.learn_argv(args, "humanoid", "perceptive", treatment, folder, args.scan_lr_scale)
        assert argv[0] == "learn"
        a = parser.parse_args(argv[1:])
        assert (a.robot, a.observation, a.scan_lr_scale, a.curriculum, a.preset, a.trials, a.backend) == (
            "humanoid", "perceptive", 0.1, curriculum, "gpu-short", 10, "jax")
        assert a.archive == str(archive) and a.out == folder / treatment
    ant = run.learn_argv(args, "ant", "blind", "mixed-dr", run.train_folder(args.out, "ant", "blind"))
    assert "--scan-lr-scale" not in ant  # the ant's runs: as before


def test_a_sharded_scan_retrain_trains_its_share_and_keeps_its_choice(run, tmp_path, monkeypatch, capsys):
    """``--shard I/2`` trains the I-th of the saved treatments (one learn run each); the choice lands in
    ``OUT/scan.json`` and another scale or set is refused in one line; a treatment with a config.json resumes; the
    original ``train humanoid perceptive`` (no --scan-lr-scale) still runs its curriculum run and writes no
    scan.json."""
    calls = []
    monkeypatch.setattr(run, "cli", fake_learn(calls))
    monkeypatch.setattr(run, "archive_done", lambda *a: True)
    out = tmp_path / "exp4"
    base = ["train", "humanoid", "perceptive", "--out", str(out)]
    scan = [*base, "--scan-lr-scale", "0.1", "--treatments", "mixed-dr", "mixed-plr"]
    assert run.main([*scan, "--shard", "1/2"]) == 0
    assert [(c[c.index("--curriculum") + 1], c[c.index("--scan-lr-scale") + 1]) for c in calls] == [("plr", "0.1")]
    assert json.loads((out / "scan.json").read_text()) == {"scale": 0.1, "treatments": ["mixed-dr", "mixed-plr"]}
    assert "train humanoid perceptive-scan0.1/mixed-plr: done" in capsys.readouterr().out
    assert run.main([*base, "--scan-lr-scale", "0.1", "--treatments", "mixed-plr", "mixed-dr", "--shard", "0/2"]) == 0
    assert calls[-1][calls[-1].index("--curriculum") + 1] == "dr"  # the saved order splits, not the one given
    assert run.main(scan) == 0 and len(calls) == 2  # both done: nothing runs
    assert capsys.readouterr().out.count(": done (") == 3
    for other in (["--scan-lr-scale", "0.2", "--treatments", "mixed-dr", "mixed-plr"],
                  ["--scan-lr-scale", "0.1", "--treatments", "mixed-dr"]):
        assert run.main([*base, *other]) == 2
        assert "scan.json chose --scan-lr-scale 0.1 --treatments mixed-dr mixed-plr" in capsys.readouterr().err
    (out / "scan.json").unlink()
    folder = run.scan_folder(out, 0.1) / "mixed-levels"
    folder.mkdir(parents=True)
    (folder / "config.json").write_text("{}")
    assert run.main([*base, "--scan-lr-scale", "0.1", "--treatments", "mixed-levels"]) == 0
    assert calls[-1] == ["learn", "--resume", str(folder)]
    assert run.main(base) == 0  # the original run: one curriculum run, its own folder
    assert calls[-1][0] == "curriculum" and calls[-1][calls[-1].index("--out") + 1] == str(
        run.train_folder(out, "humanoid", "perceptive")) and "--scan-lr-scale" not in calls[-1]


def fake_finished(folder: Path, names, trials: int = 2) -> None:
    """Treatments as a finished train leaves them (summary.json, policies/trial_K)."""
    for t in names:
        for k in range(trials):
            (folder / t / "policies" / f"trial_{k}").mkdir(parents=True, exist_ok=True)
        (folder / t / "summary.json").write_text("{}")


def test_the_scan_retrain_is_a_run_of_its_own_in_the_plan(run, tmp_path, capsys):
    """Once ``OUT/scan.json`` exists, :func:`runs` lists the retrain after the others (its own folder, the
    perceptive base policy's walks not counted twice); ``--plan``'s state keys it apart from the original perceptive
    run (train and walks), its learn runs are not counted as a population, and its walkers walk on the perceptive
    program (no second first walk)."""
    out = tmp_path / "exp4"
    out.mkdir()
    (out / "humanoid.json").write_text(json.dumps({"treatments": ["mixed-map", "mixed-dr"]}))
    for obs in run.OBSERVATIONS:
        fake_finished(run.train_folder(out, "humanoid", obs), ["mixed-map", "mixed-dr"])
    args = argparse.Namespace(out=out, preset="gpu-short", backend=None, eval_backend="warp", trials=2, keys=3,
                              suites=["v2"])
    before = run.read_state(args)
    assert before["train_left"] == {"humanoid blind": 0, "humanoid perceptive": 0}
    (out / "scan.json").write_text(json.dumps({"scale": 0.1, "treatments": ["mixed-dr", "steps-map"]}))
    scan = run.scan_folder(out, 0.1)
    assert run.runs(out)[-1] == ("humanoid", "perceptive", scan, ["mixed-dr", "steps-map"])
    assert [f.name for _, _, f, _ in run.runs(out)[:2]] == ["humanoid-blind", "humanoid-perceptive"]
    fake_finished(scan, ["mixed-dr"])
    state = run.read_state(args)
    assert state["train_left"] == {"humanoid blind": 0, "humanoid perceptive": 0, "humanoid perceptive-scan0.1": 1}
    assert state["walks_left"]["v2"] == {("humanoid", "blind"): 4 + 3, ("humanoid", "perceptive"): 4 + 3,
                                         ("humanoid", "perceptive-scan0.1"): 4}  # the base walks once
    assert run.humanoid_generators(out) == ["steps", "mixed"]  # the retrain's steps-map: the shipped archive
    assert state["archives_left"] == [("humanoid", "mixed")]
    rates = {**run.RATES, "treatment_s_warp": ((400.0, 500.0), ""), "population_factor": (0.5, ""),
             "compile_s": ((10.0, 80.0), ""), "v2_first_s": (70.0, ""), "v2_walker_s_warp": ((20.0, 30.0), ""),
             "build_s": (60.0, "")}
    got = run.predict({**state, "ant_pending": False, "measured": {}, "archives_left": []}, rates)
    assert got["train humanoid perceptive-scan0.1"] == (400.0 + 2 * 10, 500.0 + 2 * 80)  # no population factor
    assert got["evaluate v2"] == (60 + 2 * 70 + (18 - 2) * 20.0, 60 + 2 * 70 + (18 - 2) * 30.0)  # two programs
    assert run.main(["--plan", "--out", str(out), "--trials", "2", "--keys", "3", "--suites", "v2"]) == 0
    text = capsys.readouterr().out
    assert "train humanoid perceptive: 2/2 treatments done" in text
    assert "train humanoid perceptive-scan0.1: 1/2 treatments done" in text
    assert "humanoid perceptive 7 walks left" in text and "humanoid perceptive-scan0.1 4 walks left" in text
    assert run.trained(out) == ([run.train_folder(out, "humanoid", o) for o in run.OBSERVATIONS],
                                ["humanoid-perceptive-scan0.1"])
    assert any(p.relative_to(out).parts[:3] == ("train", scan.name, "mixed-dr") for p in run.pack_members(out))


def test_write_puts_the_retrains_pages_in_its_folder_and_compares_it(run, tmp_path, monkeypatch, capsys):
    """``write``: each run's pages in ``--results/<run folder>/<suite>/`` (the original runs' as before), the
    retrain's against the perceptive base policy, then one comparison page per suite (each retrained treatment, the
    same at scale 1 and blind) in ``humanoid-perceptive-scan<C>/<suite>-compare/``, v1 beside v2."""
    out, results = tmp_path / "exp4", tmp_path / "pages"
    out.mkdir()
    (out / "humanoid.json").write_text(json.dumps({"treatments": ["mixed-map", "mixed-dr"]}))
    (out / "scan.json").write_text(json.dumps({"scale": 0.1, "treatments": ["mixed-dr"]}))
    scan = run.scan_folder(out, 0.1)
    folders = [run.train_folder(out, "humanoid", o) for o in run.OBSERVATIONS] + [scan]
    for f in folders:
        fake_finished(f, ["mixed-map", "mixed-dr"] if f != scan else ["mixed-dr"])
        for t in ["mixed-map", "mixed-dr"] if f != scan else ["mixed-dr"]:
            for suite in run.SUITES:
                (f / t / f"heldout_{suite}").mkdir()
                (f / t / f"heldout_{suite}" / "fitness.csv.gz").write_text("")
    for suite in run.SUITES:
        (out / "eval" / suite).mkdir(parents=True)
        (out / "eval" / suite / "settings.json").write_text(json.dumps({"backend": "warp"}))
    walked, calls = [], []

    class Reevaluate:
        @staticmethod
        def main(argv):
            walked.append(argv)
            return 0

    monkeypatch.setattr(run, "load_reevaluate", lambda: Reevaluate)
    monkeypatch.setattr(run, "cli", lambda argv, args: calls.append(argv) or 0)
    assert run.main(["write", "--out", str(out), "--results", str(results)]) == 0
    assert all(str(scan) in argv for argv in walked) and len(walked) == 2  # the retrain's heldout written too
    dests = [Path(c[c.index("--out") + 1]).relative_to(results).as_posix() for c in calls]
    assert dests == ["humanoid-blind/v1", "humanoid-blind/v2", "humanoid-perceptive/v1", "humanoid-perceptive/v2",
                     "humanoid-perceptive-scan0.1/v1", "humanoid-perceptive-scan0.1/v2",
                     "humanoid-perceptive-scan0.1/v1-compare", "humanoid-perceptive-scan0.1/v2-compare"]
    bases = [Path(c[c.index("--base") + 1]).relative_to(out).as_posix() for c in calls]
    assert bases[:2] == ["base_v1/humanoid", "base_v2/humanoid"]
    assert set(bases[2:]) <= {"base_v1/humanoid_perceptive", "base_v2/humanoid_perceptive"}
    assert calls[4][1:3] == [f"mixed-dr={scan / 'mixed-dr'}", "--heldout"]
    assert calls[7][1:4] == [f"perceptive-mixed-dr-scan0.1={scan / 'mixed-dr'}",
                             f"perceptive-mixed-dr={run.train_folder(out, 'humanoid', 'perceptive') / 'mixed-dr'}",
                             f"blind-mixed-dr={run.train_folder(out, 'humanoid', 'blind') / 'mixed-dr'}"]
    assert calls[7][calls[7].index("--heldout") + 1] == "heldout_v2"
    assert calls[7][-2:] == ["--beside", f"v1={results / 'humanoid-perceptive-scan0.1' / 'v1-compare'}"]
    assert all(c[0] == "generalise" for c in calls)
