"""The ``learn`` and ``curriculum`` commands (``python -m experiments``): bad input (one line, exit 2, nothing left
behind, nothing compiled), the smoke preset end to end, progress and metrics inside a compiled block, resume after a
time limit, the per-env curricula, ``--backend``, the shards and tables of ``curriculum``. The library under them:
tests/curriculum/."""

from __future__ import annotations

import argparse
import json
import re
import warnings
from pathlib import Path

import jax
import numpy as np
import pytest

from curriculum_archives import tiny_archive_file, tree_equal, validated
from gpu_image import image
from jaxterrain.curriculum import outputs, run_config, runner
from jaxterrain.runtime import driver, statistics
from jaxterrain.walker import layout, warp_available

from experiments import common


@pytest.fixture(scope="module")
def tiny_archive(tmp_path_factory):
    """The CPPN archive cut to its first ``k`` filled cells, with stored heightmaps (gentle bumps: no rendering)."""
    folder = tmp_path_factory.mktemp("arch")
    return lambda k, name, **config: tiny_archive_file(folder, k, name, **config)


def cli(*argv):
    from experiments.__main__ import main

    return main(list(argv))


def test_learn_rejects_bad_input_with_one_line_naming_it(tmp_path, tiny_archive, capsys):
    good = tiny_archive(4, "good.npz")
    corrupt = tmp_path / "corrupt.npz"
    corrupt.write_bytes(b"PK\x03\x04 not a zip")
    policy_dir = tmp_path / "policy"
    policy_dir.mkdir()
    from jaxterrain import rl

    meta = json.loads((rl.BASE_POLICY_DIR / "config.json").read_text())
    (policy_dir / "policy.msgpack").write_bytes((rl.BASE_POLICY_DIR / "policy.msgpack").read_bytes())
    (policy_dir / "config.json").write_text(json.dumps({**meta, "observation_size": 53}))
    cases = [
        (["--archive", good, "--trials", "0"], "--trials"),
        (["--archive", good, "--threshold", "1.5"], "threshold"),
        (["--archive", good, "--threshold", "0"], "threshold"),
        (["--archive", str(corrupt)], "corrupt.npz"),
        (["--archive", str(tmp_path / "missing.npz")], "missing.npz"),
        (["--archive", tiny_archive(1, "one.npz")], "one.npz: 1 filled cell"),
        (["--archive", tiny_archive(0, "empty.npz")], "empty.npz: 0 filled cell"),
        (["--archive", tiny_archive(4, "tri.npz", descriptors=("tri", "tpi"))], "tri.npz: descriptors"),
        (["--archive", good, "--eval-lag"], "--eval-lag needs --overlap"),
        (["--archive", good, "--policy", str(policy_dir)], "policy"),
    ]
    for i, (argv, needle) in enumerate(cases):
        out = tmp_path / f"run{i}"
        try:  # the runner's checks return 2; the flag checks before it (experiments.common) exit with 2
            code = cli("learn", "--preset", "smoke", "--out", str(out), *argv)
        except SystemExit as stop:
            code = stop.code
        assert code == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and needle in err[0], (argv, err)
        assert not out.exists()  # nothing left behind
    assert "observations 53" in err[0]
    for value in ("-1", "nan"):  # flag values: argparse's exit status 2, before the run folder exists
        with pytest.raises(SystemExit) as stop:
            cli("learn", "--preset", "smoke", "--out", str(tmp_path / "h"), "--archive", good,
                "--healthy-reward", value)
        assert stop.value.code == 2 and "--healthy-reward must be a finite number >= 0" in capsys.readouterr().err
        assert not (tmp_path / "h").exists()
    for value in ("0", "-1e-4", "inf"):
        with pytest.raises(SystemExit) as stop:
            cli("learn", "--preset", "smoke", "--out", str(tmp_path / "h"), "--archive", good,
                f"--learning-rate={value}")
        assert stop.value.code == 2 and "--learning-rate must be a finite number > 0" in capsys.readouterr().err
        assert not (tmp_path / "h").exists()


@pytest.fixture(scope="module")
def learn_smoke(tmp_path_factory, tiny_archive):
    """``(archive, run folder)``: ONE uninterrupted ``learn --preset smoke`` run on the 4-terrain archive, shared by
    the end-to-end test and the time-limit test (its uninterrupted reference). It runs as on the GPU machine, without
    the packages its image lacks (``tests/gpu_image.py``: rliable among them)."""
    import contextlib
    import io

    from jaxterrain.runtime import driver

    from jaxterrain.curriculum import runner

    archive = tiny_archive(4, "four.npz")
    out = tmp_path_factory.mktemp("learn") / "whole"
    err = io.StringIO()  # not a terminal: plain progress lines (every one: PLAIN_EVERY_S = 0)
    seen = []  # metrics.csv as the per-chunk callback left it, after every chunk
    listen = runner.ChunkMetrics.__call__

    def snapshot(self, *args):
        listen(self, *args)
        seen.append((out / "metrics.csv").read_text() if (out / "metrics.csv").exists() else "")

    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stderr(err):
        mp.setattr(driver, "PLAIN_EVERY_S", 0.0)
        mp.setattr(runner.ChunkMetrics, "__call__", snapshot)
        image(mp)
        assert cli("learn", "--preset", "smoke", "--archive", archive, "--out", str(out)) == 0
    (out.parent / "stderr.txt").write_text(err.getvalue())
    (out.parent / "metrics_seen.json").write_text(json.dumps(seen))
    return archive, out


def test_learn_reports_progress_after_every_chunk_inside_a_compiled_block(learn_smoke):
    """The smoke run's blocks are 2 chunks long (``--chunks-per-call 2``): a line after chunk 1 and after chunk 3
    comes from inside a block (the block's per-chunk host callback), not from between blocks."""
    _, out = learn_smoke
    lines = (out.parent / "stderr.txt").read_text().splitlines()
    chunks = [int(m.group(1)) for m in map(re.compile(r"^map: chunk (\d+) of 4, hardest").match, lines) if m]
    assert chunks == [1, 2, 3, 4], lines


def test_learn_writes_metrics_csv_after_every_chunk_inside_a_compiled_block(learn_smoke):
    """metrics.csv gains a row after every chunk, inside a block too (after chunks 1 and 3 of the smoke run's 2-chunk
    blocks), and each of those files is the start of the run's final metrics.csv: the driver's rows at a block's
    end are the ones the callback wrote."""
    _, out = learn_smoke
    seen = json.loads((out.parent / "metrics_seen.json").read_text())
    final = (out / "metrics.csv").read_text().splitlines()
    assert final[0] == "step,evaluation,hardest,trials_running" and len(final) == 1 + 4
    assert [len(text.splitlines()) for text in seen] == [2, 3, 4, 5]
    assert all(text.splitlines() == final[:len(text.splitlines())] for text in seen)


def test_learn_smoke_end_to_end(learn_smoke):
    _, out = learn_smoke
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["trials"] == 2 and cfg["curriculum"] == "map" and cfg["command"] == "learn"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["trials"] == 2 and summary["epochs_max"] <= 4 and summary["bank_terrains"] == 4
    est = statistics.trial_estimates({"x": np.array(summary["hardest"])[:, None]}, reps=2000)["x"]  # trials resampled
    assert summary["hardest_iqm"] == list(est["iqm"]) and summary["hardest_mean_ci"] == [est["mean"].low,
                                                                                        est["mean"].high]
    rows = (out / "history.csv").read_text().splitlines()
    assert rows[0].startswith("trial,chunk,epoch") and len(rows) == 1 + sum(summary["epochs"])
    evals = np.array([float(r.split(",")[9]) for r in rows[1:]])
    assert np.all((evals >= 0) & (evals <= 1)) and evals.max() > 0  # the policy walked
    seq = (out / "sequences.csv").read_text().splitlines()
    assert seq[0].startswith("trial,order,terrain") and len(seq) >= 3
    assert seq[0].endswith(",end_epoch,generator") and all(r.endswith(",cppn") for r in seq[1:])
    gens = summary["generators"]
    assert set(gens) == {"cppn"} and gens["cppn"]["terrains"] == len(seq) - 1
    assert gens["cppn"]["chunks"] == sum(summary["epochs"]) and 0 <= gens["cppn"]["finished"] <= len(seq) - 1
    assert (out / "curve.png").stat().st_size > 0 and (out / "milestones.md").read_text().count("|") > 10
    assert (out / "checkpoint.npz").exists()
    assert cli("learn", "--resume", str(out)) == 0  # a finished run reports its summary again


@pytest.mark.parametrize("curriculum", [pytest.param("levels", marks=pytest.mark.slow),  # default: learn_terrains
                                        pytest.param("dr", marks=pytest.mark.slow),
                                        pytest.param("plr", marks=pytest.mark.slow),
                                        pytest.param("accel", marks=pytest.mark.slow)])
def test_learn_runs_the_per_env_curricula_end_to_end(tmp_path, tiny_archive, curriculum):
    """``learn --curriculum levels|dr|plr|accel --preset smoke``: each env on its own terrain through the real walker and PPO
    (each env's progress read from PPO's episode record), the selector's own summary, every trial's walker."""
    archive = tiny_archive(4, "four.npz")
    out = tmp_path / curriculum
    own = ["--levels", "2"] if curriculum == "levels" else ["--terrains-per-chunk", "3"]  # another's is refused
    assert cli("learn", "--preset", "smoke", "--archive", archive, "--curriculum", curriculum, *own,
               "--out", str(out)) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["epochs"] == [4, 4] and summary["ended_without_terrains"] == [False, False]
    if curriculum == "levels":
        assert all(0 <= v <= 1 for v in summary["max_level"]) and all(m >= 0 for m in summary["level_moves"])
    elif curriculum == "dr":
        assert summary["terrains_drawn"] == [15, 15]  # 3 at the start and after each of the 4 chunks
    elif curriculum == "plr":
        assert all(1 <= n <= 4 for n in summary["buffer_size"]) and all(0 <= r <= 4 for r in summary["replay_chunks"])
    else:  # accel: CPPN genomes (the archive's generator) rendered in the loop, the buffer not bound by the archive
        assert all(3 <= n <= 12 for n in summary["buffer_size"]) and all(0 <= r <= 4 for r in summary["edit_chunks"])
        assert json.loads((out / "config.json").read_text()).get("accel_generator") in (None, "cppn")
    rows = (out / "history.csv").read_text().splitlines()
    assert len(rows) == 1 + 8 and all(0 <= float(r.split(",")[9]) <= 1 for r in rows[1:])
    assert sorted(p.name for p in (out / "policies").iterdir()) == ["trial_0", "trial_1"]
    assert json.loads((out / "config.json").read_text())["curriculum"] == curriculum


def test_curriculum_sequences_take_every_treatments_columns(tmp_path):
    """curriculum's sequences.csv joins the treatments' files under the union of their columns: one written before
    the generator column existed keeps its rows, with that cell empty."""
    from experiments import curriculum as exp

    old, new = tmp_path / "old", tmp_path / "new"
    old.mkdir(), new.mkdir()
    (old / "sequences.csv").write_text("trial,order,terrain\n0,0,5\n")
    (new / "sequences.csv").write_text("trial,order,terrain,generator\n1,0,7,perlin\n1,1,9,cppn\n")
    exp.write_sequences(tmp_path, [("cppn roughness", old), ("combined map", new)])
    assert (tmp_path / "sequences.csv").read_text().splitlines() == [
        "treatment,trial,order,terrain,generator", "cppn roughness,0,0,5,", "combined map,1,0,7,perlin",
        "combined map,1,1,9,cppn"]


def test_curriculum_tables_put_the_papers_numbers_beside_ours(tmp_path):
    from experiments import curriculum as exp

    def summary(first_two, reached):
        return {"milestone_epochs": list(first_two) + [None] * 8, "milestone_trials": list(reached) + [0] * 8,
                "curve": {"epoch": [0, 40, 80], "mean": [0.0, 4.0, 8.0], "se": [0.0, 1.0, 0.5]}}

    rows = [("cppn map", summary([40.0, 120.0], [2, 1])), ("cppn roughness", summary([80.0, None], [2, 0]))]
    exp.write_table(tmp_path, rows, trials=2)
    exp.write_figures(tmp_path, rows, "roughness")
    md = (tmp_path / "table2.md").read_text().splitlines()
    assert md[2] == "| cppn map (ours) | 40 | 120 (1/2) | - | - | - | - | - | - | - | - |"
    assert md[3] == "| cppn map (paper) | 40 | 80 | 120 | 240 | 960 | 4720 | 7000 | 9880 | 13280 | - |"
    assert md[4].startswith("| cppn roughness (ours) | 80 | - |") and len(md) == 5
    table = (tmp_path / "table2.csv").read_text().splitlines()
    assert table[1].startswith("cppn map,ours,40.0,120.0,,") and table[2].startswith("cppn map,paper,40,80,120")
    assert (tmp_path / "figure7a.png").stat().st_size > 0 and (tmp_path / "figure7b.png").stat().st_size > 0
    partial = {**summary([40.0, None], [1, 0]), "partial": True, "epochs_max": 80}  # learn --report of a checkpoint
    (tmp_path / "p").mkdir()
    exp.write_table(tmp_path / "p", [("cppn map", partial)], trials=2)
    md = (tmp_path / "p" / "table2.md").read_text().splitlines()
    assert md[2].startswith("| cppn map [partial: 80 epochs] (ours) | 40 (1/2) |") and "(paper)" in md[3]
    (tmp_path / "b").mkdir()  # only the baseline so far (shards still running): no empty Figure 7a, no warning
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        exp.write_figures(tmp_path / "b", [("cppn roughness", summary([80.0, None], [2, 0]))], "roughness")
    assert not (tmp_path / "b" / "figure7a.png").exists() and not (tmp_path / "b" / "figure7b.png").exists()


def test_curriculum_shards_share_one_run_folder_and_resume_writes_the_tables(tmp_path, tiny_archive, capsys):
    """``curriculum --shard I/N`` runs only treatments ``t % N == I``; ``--resume`` without it reuses the finished
    treatments (here finished by hand, so nothing compiles) and writes Table 2 and the figures."""
    from experiments import curriculum as exp

    archive = tiny_archive(4, "four.npz")
    run = tmp_path / "exp2"
    fake = {"milestone_epochs": [40.0] + [None] * 9, "milestone_trials": [2] + [0] * 9, "hardest_mean": 3.0,
            "hardest": [2.5, 3.5], "curve": {"epoch": [0, 40], "mean": [0.0, 3.0], "se": [0.0, 0.5]}}
    for sub in ("cppn-map", "cppn-roughness"):  # the plan of one cppn archive: map (t = 0), then the baseline
        (run / sub).mkdir(parents=True)
        (run / sub / "summary.json").write_text(json.dumps(fake))
        (run / sub / "sequences.csv").write_text("trial,order,terrain\n0,0,1\n")
    base = ("curriculum", "--preset", "smoke", "--archives", f"cppn={archive}")
    assert cli(*base, "--out", str(run), "--shard", "1/2") == 0
    out = capsys.readouterr().out
    assert "shard 1/2 done (1 of 2 treatments)" in out and not (run / "table2.md").exists()
    with pytest.raises(SystemExit):
        cli(*base, "--out", str(run / "bad"), "--shard", "2/2")
    assert cli("curriculum", "--resume", str(run), "--report") == 0  # as they stand: here both finished
    assert "| cppn map (ours) | 40 |" in (run / "table2.md").read_text()
    (run / "table2.md").unlink()
    assert cli("curriculum", "--resume", str(run)) == 0
    md = (run / "table2.md").read_text()
    assert "| cppn map (ours) | 40 |" in md and "| cppn roughness (ours) | 40 |" in md
    assert (run / "figure7b.png").exists() and (run / "sequences.csv").read_text().count("cppn") == 2
    hardest = (run / "hardest.md").read_text()  # rliable's intervals beside mean +- s.e.
    assert "| cppn map | 2 | 3.00 +- 0.50 | 3.00 [2.50, 3.50] |" in hardest and "| cppn roughness | 0.50 | - |" in hardest
    # the plan follows the archives' names, not the order given: a fresh shard and a resumed one (config.json has
    # sorted keys) must agree on which treatment is t
    one = exp.treatments({"archives": {"perlin": archive, "cppn": archive}, "descriptors": ["roughness", "tpi"],
                          "baseline": "roughness"}, tmp_path / "p1")
    two = exp.treatments({"archives": {"cppn": archive, "perlin": archive}, "descriptors": ["roughness", "tpi"],
                          "baseline": "roughness"}, tmp_path / "p2")
    assert [t[0] for t in one] == [t[0] for t in two] == ["cppn", "perlin", "combined", "cppn"]
    eight = exp.treatments({"archives": {"perlin": archive, "cppn": archive}, "descriptors": ["roughness", "tpi"],
                            "baseline": ["roughness", "random"]}, tmp_path / "p1")  # Experiment 3's baselines
    assert [(t[0], t[2]) for t in eight] == [("cppn", "map"), ("perlin", "map"), ("combined", "map"),
                                             ("cppn", "roughness"), ("cppn", "random")]
    with pytest.raises(SystemExit):  # a baseline twice would be two treatments in one folder
        cli(*base, "--out", str(tmp_path / "twice"), "--baseline", "random", "random")
    assert not (tmp_path / "twice").exists()


def test_curriculum_shards_give_each_process_whole_populations(tmp_path, tiny_archive, capsys):
    """With populations, ``--shard I/N`` hands out whole populations (``batch.shard_groups``): Experiment 4's plan
    over two processes puts the two map treatments and terrain levels on process 0, DR and PLR (one population) on
    process 1, so process 1 is done once those two are (finished here by hand: nothing compiles)."""
    archive = tiny_archive(4, "four.npz")
    run = tmp_path / "exp4"
    fake = {"milestone_epochs": [40.0] + [None] * 9, "milestone_trials": [2] + [0] * 9, "hardest_mean": 3.0,
            "hardest": [2.5, 3.5], "curve": {"epoch": [0, 40], "mean": [0.0, 3.0], "se": [0.0, 0.5]}}
    for sub in ("mixed-dr", "mixed-plr"):
        (run / sub).mkdir(parents=True)
        (run / sub / "summary.json").write_text(json.dumps(fake))
    assert cli("curriculum", "--preset", "smoke", "--archives", f"steps={archive}", f"mixed={archive}", "--baseline",
               "dr", "plr", "levels", "--baseline-archive", "mixed", "--no-combined", "--out", str(run),
               "--shard", "1/2") == 0
    assert "shard 1/2 done (2 of 5 treatments)" in capsys.readouterr().out
    assert not any((run / sub).exists() for sub in ("steps-map", "mixed-map", "mixed-levels"))  # process 0's


def test_curriculum_runs_the_baselines_on_the_baseline_archive_and_skips_the_combined_one(tmp_path):
    """``--baseline-archive NAME`` puts the baselines on that archive, ``--no-combined`` drops the combined map
    treatment (Experiment 4's plan: nothing is read or written for it); a config.json written before the keys existed
    plans what it did (baselines on cppn, the combined archive), so old run folders resume unchanged."""
    from experiments import curriculum as exp

    new = {"archives": {"steps": "S.npz", "mixed": "M.npz"}, "descriptors": ["roughness", "tpi"],
           "baseline": ["dr", "plr", "levels"], "baseline_archive": "mixed", "combined": False}
    assert [(n, p, c) for n, p, c in exp.treatments(new, tmp_path)] == [
        ("mixed", "M.npz", "map"), ("steps", "S.npz", "map"), ("mixed", "M.npz", "dr"), ("mixed", "M.npz", "plr"),
        ("mixed", "M.npz", "levels")]
    assert not (tmp_path / "combined_archive.npz").exists()
    old = {"archives": {"cppn": "C.npz"}, "descriptors": ["roughness", "tpi"], "baseline": "roughness"}
    assert exp.baseline_archive(old) == "cppn" and exp.combined(old) is True
    assert exp.treatments(old, tmp_path) == [("cppn", "C.npz", "map"), ("cppn", "C.npz", "roughness")]
    assert exp.treatments({**old, "archives": {"a": "A.npz"}}, tmp_path) == [("a", "A.npz", "map")]  # no cppn: as before
    assert "baseline_archive" not in exp._treatment_cfg({**new, "command": "curriculum"}, "M.npz", "dr")
    assert exp.PRESETS["gpu-short"]["baseline_archive"] == "cppn" and exp.PRESETS["smoke"]["combined"] is True


def test_learn_writes_every_trials_walker_as_a_loadable_policy(tmp_path, learn_smoke):
    """``learn`` ends by writing ``policies/trial_K/``: ``rl.load_policy`` reads each, its parameters and normaliser
    are trial K's in the run's last checkpoint, they moved away from the base policy (PPO trained them), and
    ``config.json`` keeps the base policy's walker config (its solver) and records the trial's curriculum (epochs,
    env steps, the terrains in the order ``sequences.csv`` lists them). ``--resume RUN --export-policies`` writes the
    same weights from the checkpoint."""
    import hashlib
    import os
    import shutil
    from pathlib import Path

    from jaxterrain import rl

    _, out = learn_smoke
    cfg = common.load_config(out)  # its paths as this machine reads them
    states = runner.restored(run_config.from_flat(cfg), out)[6]
    base = rl.load_policy()
    seq = [r.split(",") for r in (out / "sequences.csv").read_text().splitlines()[1:]]
    for t in range(2):
        policy = rl.load_policy(out / "policies" / f"trial_{t}")
        params, normaliser = outputs.trial_policy(states, t)
        assert tree_equal(policy.params, params) and tree_equal(policy.normaliser, normaliser)
        moved = [float(np.max(np.abs(np.asarray(a) - np.asarray(b))))
                 for a, b in zip(jax.tree.leaves(policy.params["policy"]), jax.tree.leaves(base.params["policy"]))]
        assert max(moved) > 0.0, "the trained walker equals the base policy"
        assert (policy.observation_size, policy.action_size) == (base.observation_size, base.action_size)
        assert policy.meta["walker_config"] == base.meta["walker_config"]
        assert policy.meta["provenance"]["spawn"] == "feet"  # the rule its walker spawned by
        c = policy.meta["curriculum"]
        assert c["trial"] == t and c["selector"] == "map" and c["epochs"] == int(np.asarray(states.epoch)[t])
        assert c["env_steps"] == c["epochs"] * cfg["steps_per_epoch"] and c["epochs"] > 0
        assert c["terrains"] == [int(r[2]) for r in seq if int(r[0]) == t]
        assert c["hardest"] == pytest.approx(float(np.asarray(states.hardest)[t]))
        # no machine's absolute path: the archive relative to the run folder, the shipped base policy by package
        assert c["start_policy"] == "<jaxterrain>/assets/base_policy"
        assert c["archive"] == os.path.relpath(cfg["archive"], out) and not os.path.isabs(c["archive"])
        assert c["archive_file_sha256"] == hashlib.sha256(Path(cfg["archive"]).read_bytes()).hexdigest()
    saved = json.loads((out / "config.json").read_text())
    assert saved["archive"] == os.path.relpath(cfg["archive"], out) and str(out.parent) not in json.dumps(saved)
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    shutil.rmtree(copy / "policies")
    assert cli("learn", "--resume", str(copy), "--export-policies") == 0
    for t in range(2):
        assert ((copy / "policies" / f"trial_{t}" / "policy.msgpack").read_bytes()
                == (out / "policies" / f"trial_{t}" / "policy.msgpack").read_bytes())


def test_learn_killed_by_its_time_limit_resumes_to_the_uninterrupted_curves(tmp_path, learn_smoke, tiny_archive,
                                                                            capsys, monkeypatch):
    """Issues 13 and 59: a treatment stopped by ``--time-limit`` after its first chunk, INSIDE the uninterrupted
    run's first 2-chunk block (the env states ride in the checkpoint), and resumed ends with the same history,
    sequences and milestones as the uninterrupted one, bit for bit (same device, same seed: the module's smoke
    run). The compiled block is shared with the other smoke runs of this module. A resume whose archive file was replaced meanwhile, or whose `auto` backend would now pick other physics
    than the checkpoint's, is refused in one line, before anything compiles."""
    import shutil

    from jaxterrain import qd as A
    from jaxterrain.runtime import driver

    shared, whole = learn_smoke
    archive = str(shutil.copy(shared, tmp_path / "four.npz"))  # its label names the file; replaced, put back below
    parts = tmp_path / "parts"
    assert cli("learn", "--preset", "smoke", "--archive", archive, "--out", str(parts), "--time-limit", "1e-6") == 3
    assert not (parts / "summary.json").exists() and (parts / "checkpoint.npz").exists()
    digest = runner.archive_digest(A.load(archive))
    meta = driver.read_meta(parts)
    assert meta["archive_sha256"] == digest != runner.archive_digest(A.load(tiny_archive(3, "3.npz")))
    assert meta["backend"] == "jax"  # auto, resolved on this CPU machine; a resume must run on the same physics
    cfg = common.load_config(parts)
    runner.check_resumable(parts, run_config.from_flat(cfg), A.load(archive))
    with monkeypatch.context() as m:  # as if checkpointed on a GPU with MuJoCo Warp: auto must not switch to MJX
        m.setattr(driver, "read_meta", lambda folder: {**meta, "backend": "warp"})
        with pytest.raises(runner.BadInput, match=r"LearnConfig.walker.backend auto: it runs the walker on jax here, but .* on warp"):
            runner.check_resumable(parts, run_config.from_flat(cfg | {"backend": "auto"}), A.load(archive))
        runner.check_resumable(parts, run_config.from_flat(cfg), A.load(archive), physics=False)  # a report reads it on any machine
    shutil.copy(tiny_archive(3, "three.npz"), archive)  # another archive under the run's path
    for extra in ((), ("--report",)):
        capsys.readouterr()
        assert cli("learn", "--resume", str(parts), *extra) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and f"--archive {archive}: it is not the archive" in err[0], err
    shutil.copy(shared, archive)
    with monkeypatch.context() as m:  # a GPU run on MuJoCo Warp, reported where Warp does not import
        from jaxterrain import walker

        m.setattr(walker.tiles, "warp_available", lambda: (False, "MuJoCo Warp is not installed"))
        (parts / "config.json").write_text(json.dumps({**cfg, "backend": "warp"}))
        capsys.readouterr()
        assert cli("learn", "--resume", str(parts)) == 2  # training needs Warp: one line
        assert "--backend warp: MuJoCo Warp is not installed" in capsys.readouterr().err
        assert cli("learn", "--resume", str(parts), "--report") == 0  # the checkpoint's outputs, nothing trained
        (parts / "config.json").write_text(json.dumps(cfg))
    partial = json.loads((parts / "summary_partial.json").read_text())
    assert partial["partial"] and partial["chunks_done"] == 1 and not (parts / "summary.json").exists()
    assert partial["seconds"] > 0  # the wall time so far (checkpoint meta), set-up and compilation included
    rows = (parts / "history.csv").read_text().splitlines()[1:]
    assert rows and all(r.split(",")[1] == "0" for r in rows)  # the probe chunk, half of the first block
    assert any(k.startswith("leaf:" + runner.ENV_STATES + ".") for k in np.load(parts / "checkpoint.npz").files)
    with pytest.raises(SystemExit):
        cli("learn", "--preset", "smoke", "--report", "--out", str(tmp_path / "nothing"))
    assert not (tmp_path / "nothing").exists()
    assert cli("learn", "--resume", str(parts)) == 0
    assert (parts / "summary.json").exists() and not (parts / "summary_partial.json").exists()  # none out of date
    assert json.loads((parts / "summary.json").read_text())["seconds"] > partial["seconds"]  # summed over commands
    for name in ("history.csv", "sequences.csv", "milestones.csv"):
        assert (parts / name).read_text() == (whole / name).read_text(), name
    finished = json.loads((parts / "summary.json").read_text())
    for name in ("summary.json", "history.csv"):  # stopped after its last checkpoint, before its outputs (a crash)
        (parts / name).unlink()
    assert cli("learn", "--resume", str(parts), "--report") == 0  # the finished outputs, from the checkpoint
    assert not (parts / "summary_partial.json").exists()
    again = json.loads((parts / "summary.json").read_text())
    assert again == finished | {"seconds": again["seconds"]} and "partial" not in again
    assert (parts / "history.csv").read_text() == (whole / "history.csv").read_text()


@pytest.mark.slow
def test_a_warp_checkpoint_is_reported_through_the_mjx_layout(tmp_path, monkeypatch):
    """A `learn --backend warp` run's checkpoint (one block of the smoke preset on MuJoCo Warp's CPU device) is read
    by `--report` into the MJX-JAX layout's states (`runner.report_run`): every leaf has the shape it had on Warp, so
    a GPU run reports on a machine without Warp; resuming it there is refused (the checkpoint records warp)."""
    from jaxterrain.walker import warp_available

    if not warp_available()[0]:
        pytest.skip(warp_available()[1])
    run = tmp_path / "warp"
    assert cli("learn", "--preset", "smoke", "--backend", "warp", "--out", str(run), "--time-limit", "1e-6") == 3
    assert driver.read_meta(run)["backend"] == "warp"
    from jaxterrain import walker

    monkeypatch.setattr(walker.tiles, "warp_available", lambda: (False, "MuJoCo Warp is not installed"))
    assert cli("learn", "--resume", str(run), "--report") == 0
    assert json.loads((run / "summary_partial.json").read_text())["chunks_done"] == 1  # the time limit's probe
    cfg = json.loads((run / "config.json").read_text())
    (run / "config.json").write_text(json.dumps({**cfg, "backend": "auto"}))
    assert cli("learn", "--resume", str(run)) == 2  # auto -> jax here; the checkpoint was written on warp


@pytest.mark.slow
def test_learn_overlap_with_bootstrap_truncation_runs_to_the_end(tmp_path, learn_smoke):
    """``learn --overlap --truncation bootstrap`` (the paper-budget baseline's flags; the bootstrap values come from
    the PPO envs' own rows of a batch the evaluation walks ride in): the run ends with the plain run's chunks and
    epochs, every evaluation in [0, 1], and config.json keeps both flags."""
    import csv

    archive, whole = learn_smoke
    out = tmp_path / "boot"
    assert cli("learn", "--preset", "smoke", "--archive", archive, "--overlap", "--truncation", "bootstrap",
               "--out", str(out)) == 0
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["overlap"] is True and cfg["truncation"] == "bootstrap"

    def rows(folder):
        with open(folder / "history.csv") as f:
            return list(csv.DictReader(f))

    a, b = rows(whole), rows(out)
    assert [(r["trial"], r["chunk"], r["epoch"]) for r in a] == [(r["trial"], r["chunk"], r["epoch"]) for r in b]
    assert all(0.0 <= float(r["evaluation"]) <= 1.0 for r in b)


@pytest.mark.slow
def test_learn_overlap_smoke_makes_the_plain_choices_and_resumes(tmp_path, learn_smoke):
    """``learn --overlap`` (MJX on one tile per trial, the evaluation walks riding along PPO): stopped after its
    first block and resumed, it ends with the uninterrupted plain run's terrain sequences and epochs (evaluations up
    to the float rounding of other batches; each block restarts the envs at another chunk, so the two runs' PPO
    data differ after the first block); config.json keeps overlap. Two more smoke programs: minutes of CPU."""
    import csv

    archive, whole = learn_smoke
    out = tmp_path / "over"
    assert cli("learn", "--preset", "smoke", "--archive", archive, "--overlap", "--out", str(out),
               "--time-limit", "1e-6") == 3
    assert json.loads((out / "config.json").read_text())["overlap"] is True
    assert cli("learn", "--resume", str(out)) == 0

    def rows(folder):
        with open(folder / "history.csv") as f:
            return list(csv.DictReader(f))

    a, b = rows(whole), rows(out)
    assert [(r["trial"], r["chunk"], r["epoch"], r["terrain"]) for r in a] == \
        [(r["trial"], r["chunk"], r["epoch"], r["terrain"]) for r in b]
    np.testing.assert_allclose([float(r["evaluation"]) for r in b], [float(r["evaluation"]) for r in a], atol=0.05)


@pytest.mark.slow
def test_learn_compact_blocks_run_the_same_treatment(tmp_path, learn_smoke):
    """``learn --compact`` (on in the GPU presets): a 3-trial smoke run whose trials end at different chunks (a
    threshold the smoke walker passes on some evaluations only) runs its later blocks on the running trials only
    and writes the history of the run that keeps every trial in every block: the same terrains, cells, epochs and
    hardest cells exactly, evaluations within 1e-3 (the compact program computes the running rows of all trials'
    states, gathered: XLA's CPU fusions of it may differ from the full block's in the last bits, which the history's
    4 decimals can show; 0.3833 against 0.3832 at 59440af); ``--policy-every 4`` adds snapshots of the walkers at
    chunks 4 and 8 and changes nothing else. Minutes of CPU."""
    import csv

    archive, _ = learn_smoke
    runs = {}
    for flag in ("--no-compact", "--compact"):
        out = runs[flag] = tmp_path / flag
        before = {sig: set(blocks) for sig, (_, _, blocks) in runner.PROGRAMS.items()}
        every = ["--policy-every", "4"] if flag == "--compact" else []  # snapshots: no effect on the run
        assert cli("learn", "--preset", "smoke", "--archive", archive, "--trials", "3", "--threshold", "0.348",
                   "--max-epochs", "8", flag, "--out", str(out), *every) == 0
        assert json.loads((out / "config.json").read_text())["compact"] is (flag == "--compact")
        sizes = set().union(*(set(b) - before.get(sig, set()) for sig, (_, _, b) in runner.PROGRAMS.items()))
    epochs = json.loads((runs["--compact"] / "summary.json").read_text())["epochs"]
    assert min(epochs) < max(epochs) and min(sizes, default=3) < 3, (epochs, sizes)  # smaller blocks compiled, ran
    def rows(folder):
        with open(folder / "history.csv") as f:
            return list(csv.DictReader(f))

    a, b = rows(runs["--no-compact"]), rows(runs["--compact"])
    exact = ("trial", "chunk", "epoch", "env_steps", "terrain", "cell", "bin0", "bin1", "distance", "hardest")
    assert [[r[k] for k in exact] for r in b] == [[r[k] for k in exact] for r in a]
    np.testing.assert_allclose([float(r["evaluation"]) for r in b], [float(r["evaluation"]) for r in a], atol=1e-3)
    pol = runs["--compact"] / "policies"
    assert sorted(p.name for p in pol.iterdir()) == ["chunk_00004", "chunk_00008", "trial_0", "trial_1", "trial_2"]
    assert sorted(p.name for p in (pol / "chunk_00004").iterdir()) == ["trial_0", "trial_1", "trial_2"]
    assert not (runs["--no-compact"] / "policies" / "chunk_00004").exists()
    for k in range(3):  # the last snapshot is the final walker
        assert ((pol / "chunk_00008" / f"trial_{k}" / "policy.msgpack").read_bytes()
                == (pol / f"trial_{k}" / "policy.msgpack").read_bytes())


def test_the_fine_tuning_flags_and_the_default_archives():
    """``--learning-rate`` / ``--truncation`` give the flat config's keys; without ``--archive(s)`` the commands
    take the five shipped headings archives, the CPPN's the library's ``presets.CPPN_ARCHIVE``."""
    from experiments import curriculum as exp
    from experiments import learn
    from jaxterrain.curriculum import presets

    from experiments import cli_gen

    parser = argparse.ArgumentParser()
    cli_gen.add_flags(parser, learn.PRESETS, learn.RULES, learn.FINE_TUNING_HELP)
    assert learn.fine_tuning_overrides(parser.parse_args(["--learning-rate", "1e-4"]))["learning_rate"] == 1e-4
    assert learn.fine_tuning_overrides(parser.parse_args(["--truncation", "mask"]))["truncation"] == "mask"
    assert sorted(exp.DEFAULT_ARCHIVES) == ["cppn", "diamond_square", "gan", "perlin", "worley"]
    assert exp.DEFAULT_ARCHIVES["cppn"] == learn.CPPN_ARCHIVE == presets.CPPN_ARCHIVE
    assert learn.PRESETS == presets.FLAT_PRESETS


def test_scan_lr_scale_is_saved_handed_to_the_runner_and_kept_on_resume(tmp_path, four_archive, monkeypatch, capsys):
    """``learn`` / ``curriculum --observation perceptive --scan-lr-scale 0.1`` save the scale in ``config.json``
    (each treatment's too) and hand the runner a run whose fine-tuning PPO scales the walker's 153 scan rows by it;
    ``--resume`` continues with the saved value (a flag given then is ignored, with a note). The runner is a
    stand-in (None: stopped by the time limit): nothing compiles."""
    from jaxterrain.curriculum import walker as W

    seen = []
    monkeypatch.setattr(runner, "run_treatment", lambda run, folder, *a, **kw: seen.append((run, Path(folder))))
    out = tmp_path / "learn"
    assert cli("learn", "--preset", "smoke", "--archive", four_archive, "--observation", "perceptive",
               "--scan-lr-scale", "0.1", "--out", str(out)) == 3
    assert json.loads((out / "config.json").read_text())["scan_lr_scale"] == 0.1 and seen[-1][1] == out
    _, config, _, policy, env = runner.validate(seen[-1][0])
    ppo = W.fine_tuning_ppo(config, policy, env)
    assert (ppo.scan_inputs, ppo.scan_lr_scale) == (153, 0.1)
    capsys.readouterr()
    assert cli("learn", "--resume", str(out), "--scan-lr-scale", "0.5") == 3
    assert seen[-1][0] == seen[0][0] and "--resume: ignoring ['scan_lr_scale']" in capsys.readouterr().err
    out = tmp_path / "curriculum"
    assert cli("curriculum", "--preset", "smoke", "--archives", f"cppn={four_archive}", "--observation",
               "perceptive", "--scan-lr-scale", "0.1", "--no-batch-treatments", "--out", str(out)) == 3
    for name in ("cppn-map", "cppn-roughness"):
        assert json.loads((out / name / "config.json").read_text())["scan_lr_scale"] == 0.1
    assert seen[-1][0].curriculum.ppo.scan_lr_scale == 0.1 and seen[-1][0].walker.observation == "perceptive"



def _first_layer(policy) -> np.ndarray:
    """The actor's ``hidden_0/kernel`` ([observation, hidden])."""
    paths = jax.tree_util.tree_flatten_with_path(policy.params["policy"])[0]
    (kernel,) = [leaf for path, leaf in paths if [getattr(k, "key", None) for k in path][-2:] == ["hidden_0", "kernel"]]
    return np.asarray(kernel)


@pytest.mark.slow
def test_a_perceptive_run_with_scan_lr_scale_trains_and_moves_the_scan_rows_less(tmp_path, four_archive):
    """End to end on the CPU (``--preset smoke``, one trial, the same seed): ``learn --observation perceptive
    --scan-lr-scale 0.1`` trains and exports a walker that loads, whose policy file records ``scan_inputs`` 153 and
    ``scan_lr_scale`` 0.1; from the perceptive base policy (zero scan weights) its actor's first-layer scan rows move
    less than a run at scale 1 moves them (Adam's steps on them are a tenth), while the blind rows still move.
    About 3 min on 2 CPU cores: two runs, each compiling its own optimiser."""
    from jaxterrain import rl

    base = _first_layer(rl.load_policy(rl.base_policy_dir("humanoid", "perceptive")))
    moved = {}
    for scale in (0.1, 1.0):
        out = tmp_path / f"scale{scale}"
        flag = ["--scan-lr-scale", str(scale)] if scale != 1.0 else []
        assert cli("learn", "--preset", "smoke", "--archive", four_archive, "--observation", "perceptive",
                   "--trials", "1", *flag, "--out", str(out)) == 0
        policy = rl.load_policy(out / "policies" / "trial_0")
        assert (policy.config.scan_inputs, policy.config.scan_lr_scale) == (153, scale)
        delta = np.abs(_first_layer(policy) - base)
        moved[scale] = (float(delta[-153:].max()), float(delta[:-153].max()))
    assert moved[0.1][1] > 0 and moved[1.0][0] > 0
    assert moved[0.1][0] < 0.5 * moved[1.0][0], moved


# ---------------------------------------------------------------------------------------------------------------
# learn --backend
# ---------------------------------------------------------------------------------------------------------------
WARP_OK, WARP_WHY = warp_available()


@pytest.fixture(scope="module")
def four_archive(tiny_archive) -> str:
    """The CPPN archive's first 4 filled cells (gentle bumps)."""
    return tiny_archive(4, "four.npz")


def test_learn_backend_builds_the_walker_and_refuses_a_missing_warp(tmp_path, four_archive, monkeypatch, capsys):
    """--backend jax (also a config saved without the key): the classic walker, with --overlap one tile per trial;
    warp: one tile per trial and contact buffers for trials x max(num_envs, attempts) envs (num_envs + attempts with
    --overlap); warp where it does not import: one line, exit 2, nothing left behind."""
    from experiments import learn

    cfg = {**learn.PRESETS["smoke"], "archive": four_archive, "seed": 0}
    assert validated(cfg)[3].config.tiles == 0 and learn.PRESETS["smoke"]["backend"] == "auto"
    assert layout.resolve_backend("auto") == "jax"  # on a CPU; "warp" on a GPU where MuJoCo Warp imports
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    assert layout.resolve_backend("auto") == ("warp" if WARP_OK else "jax") and layout.resolve_backend("jax") == "jax"
    monkeypatch.undo()
    old = {k: v for k, v in cfg.items() if k != "backend"}
    assert validated(old)[3].config == validated(cfg)[3].config
    config, _, _, env = validated({**cfg, "overlap": True, "trials": 3})  # MJX on tiles for the riding walks
    assert config.overlap and (env.config.backend, env.tiles) == ("jax", 3)
    if WARP_OK:
        env = validated({**cfg, "backend": "warp", "trials": 3})[3]
        assert (env.config.backend, env.tiles, env.config.warp_worlds) == ("warp", 3, 3 * 4)  # 4 envs > 2 walks
        env = validated({**cfg, "backend": "warp", "trials": 3, "overlap": True})[3]
        assert env.config.warp_worlds == 3 * (4 + 2)  # the walks step with the PPO envs
    import jaxterrain.walker as walker_pkg

    monkeypatch.setattr(walker_pkg.tiles, "warp_available", lambda: (False, "no warp here"))
    out = tmp_path / "run"
    assert cli("learn", "--preset", "smoke", "--archive", four_archive, "--backend", "warp", "--out", str(out)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--backend warp: no warp here" in err[0] and not out.exists()


@pytest.mark.slow
@pytest.mark.skipif(not WARP_OK, reason=WARP_WHY or "warp available")
def test_learn_smoke_on_warp_end_to_end(tmp_path, four_archive):
    """learn --preset smoke --backend warp: 2 trials of 4 chunks on tiles, the policy walked, config.json keeps
    the backend and --resume reports the finished run."""
    import json

    out = tmp_path / "learn"
    assert cli("learn", "--preset", "smoke", "--archive", four_archive, "--backend", "warp", "--out", str(out)) == 0
    assert json.loads((out / "config.json").read_text())["backend"] == "warp"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["trials"] == 2 and summary["epochs_max"] <= 4
    evals = np.array([float(r.split(",")[9]) for r in (out / "history.csv").read_text().splitlines()[1:]])
    assert np.all((evals >= 0) & (evals <= 1)) and evals.max() > 0
    assert cli("learn", "--resume", str(out)) == 0
    assert json.loads((out / "config.json").read_text())["backend"] == "warp"


def test_provenance_records_the_runs_own_spawn_rule():
    """A run folder's ``provenance.jsonl`` line names the spawn rule its walkers use (``common.spawn_rule``): the
    curriculum run's ``spawn``; ``patch`` for a ``config.json`` written before the key (the rule it ran with); None
    (the library's default) for a command whose walkers take the default."""
    flat = run_config.to_flat(run_config.PRESETS["smoke"])
    old = {k: v for k, v in flat.items() if k != "spawn"}
    assert common.spawn_rule("learn", flat) == "feet" and common.spawn_rule("curriculum", old) == "patch"
    assert common.spawn_rule("learn", {**flat, "spawn": "patch"}) == "patch"
    assert common.spawn_rule("evaluate", {"suite": "v1"}) == "patch"  # an evaluation saved before the key
    assert common.spawn_rule("evolve", {"generator": "cppn"}) == "patch"  # an archive's run saved before the key
    assert common.spawn_rule("gradient", {"band_width": 1.0}) is None



def test_a_warp_run_on_the_stock_heightfield_kernel_is_told_so(tmp_path, monkeypatch, capsys):
    """``record_provenance`` of a Warp run records which heightfield collision MuJoCo Warp runs and, on the stock
    kernel, says in one line on stderr how to apply the fix; a patched kernel, an MJX-JAX run or a machine without
    Warp (whose run is refused in one line of its own) says nothing."""
    from jaxterrain.runtime import provenance

    for kernel, backend, installed, told in (("stock", "warp", True, True), ("local-origin patch", "warp", True, False),
                                             ("stock", "jax", True, False), ("stock", "warp", False, False)):
        monkeypatch.setattr(provenance, "warp_hfield", lambda k=kernel: k)
        monkeypatch.setattr(common, "warp_importable", lambda i=installed: i)
        line = common.record_provenance(tmp_path, "learn", {}, backend=backend, spawn="feet")
        err = capsys.readouterr().err.strip()
        assert (err == common.STOCK_WARP_NOTE) == told and (err == "") == (not told), err
        assert line.get("warp_hfield") == (kernel if backend == "warp" else None) and line["spawn"] == "feet"
