"""Smoke paths of the experiment commands ``evolve``, ``features`` and ``coverage`` (CPU, tiny sizes)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from experiments import common
from jaxterrain import difficulty

ROOT = Path(__file__).resolve().parents[2]


def cli(*argv):
    from experiments.__main__ import main

    return main(list(argv))


def test_slope_fitness_values():
    flat = np.zeros((1, 8, 8), np.float32)
    # rise 0.5 * run -> slope 0.5, at the default scale (0.04 m per pixel, 1.0 m for height 1.0)
    ramp = np.tile(np.arange(8, dtype=np.float32) * 0.04 * 0.5 / 1.0, (8, 1))[None]
    f = np.asarray(difficulty.slope_fitness(np.concatenate([flat, ramp])))
    np.testing.assert_allclose(f, [1.0, 1.0 - 0.5 * 0.5], atol=1e-6)  # (|dx| + |dy|) / 2 = (0.5 + 0) / 2


def test_setup_resumable_run_names_one_run_and_changes_only_what_may_change(tmp_path, monkeypatch, capsys):
    """--resume FOLDER / --out RUN --resume / --resume alone (the newest run); the saved config is the run's, except
    the extendable keys given, which are checked and saved; --resume and --out naming two runs is an error."""
    import argparse

    monkeypatch.chdir(tmp_path)
    presets = {"p": {"steps": 3, "size": 8}}
    parser = argparse.ArgumentParser()
    common.add_run_arguments(parser, presets, "p")

    def setup(argv, steps=None, size=None):
        return common.setup_resumable_run("cmd", parser.parse_args(argv), presets, "p", {"steps": steps, "size": size},
                                          extendable=("steps",))

    folder, cfg = setup(["--out", "runs/cmd-1"], size=16)
    assert folder == Path("runs/cmd-1") and cfg == {"steps": 3, "size": 16, "preset": "p", "seed": 0, "command": "cmd"}
    assert common.load_config(folder) == cfg
    capsys.readouterr()
    folder, cfg = setup(["--out", "runs/cmd-1", "--resume"], steps=5, size=32)
    assert folder == Path("runs/cmd-1") and (cfg["steps"], cfg["size"]) == (5, 16)
    assert "ignoring ['size']" in capsys.readouterr().err
    assert common.load_config(folder)["steps"] == 5
    assert setup(["--resume"])[0] == Path("runs/cmd-1") == setup(["--resume", "runs/cmd-1"])[0]
    assert setup(["--resume"])[1]["steps"] == 5
    with pytest.raises(common.UsageError, match="name different runs"):
        setup(["--resume", "runs/cmd-1", "--out", "runs/cmd-2"])
    with pytest.raises(common.UsageError, match="--steps must be an integer >= 1"):
        setup(["--resume", "runs/cmd-1"], steps=0)
    assert common.load_config("runs/cmd-1")["steps"] == 5  # a refused value is not saved


def test_evolve_smoke_config_and_resume(tmp_path):
    from jaxterrain import qd as A

    out = tmp_path / "ev"
    assert cli("evolve", "--preset", "smoke", "--generations", "2", "--out", str(out)) == 0
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["generations"] == 2 and cfg["preset"] == "smoke" and cfg["command"] == "evolve"
    arch = A.load(out / "archive.npz")
    assert arch.metrics["coverage"].shape == (3,) and A.coverage(arch) > 0
    rows = (out / "metrics.csv").read_text().splitlines()
    assert rows[0].startswith("generation,") and len(rows) == 4
    assert (out / "archive.png").stat().st_size > 0
    # --config re-runs the same settings: same seed -> same archive
    out2 = tmp_path / "ev2"
    assert cli("evolve", "--config", str(out / "config.json"), "--out", str(out2)) == 0
    np.testing.assert_array_equal(A.load(out2 / "archive.npz").fitness, arch.fitness)
    # --resume of a finished run reuses its archive
    assert cli("evolve", "--resume", str(out)) == 0


@pytest.mark.slow  # ~20 s on 2 CPU cores; the smoke evolve above already covers the command in the default suite
def test_evolve_smoke_steps_generator_binned_by_vertical_faces(tmp_path):
    """``evolve --generator steps --preset smoke`` with the vertical-face descriptors (issue 64 item 2): an archive of
    steps terrains whose elites re-render from their genomes, keep the flat edge strips and sit in the cells their
    faces / max_step put them in."""
    from jaxterrain import features, generators
    from jaxterrain import qd as A

    out = tmp_path / "steps"
    assert cli("evolve", "--preset", "smoke", "--generator", "steps", "--descriptors", "max_step", "faces",
               "--out", str(out)) == 0
    arch = A.load(out / "archive.npz")
    assert arch.generator_names == ("steps",) and arch.config.descriptors == ("max_step", "faces")
    assert A.coverage(arch) > 0
    filled = np.flatnonzero(arch.filled)
    gen = generators.get("steps", size=32)
    genomes = np.asarray(arch.genomes[0])[filled]
    gen.validate(genomes)  # mutated genomes within the genome's bounds
    maps = np.asarray(gen.render(genomes))
    stored = np.asarray(arch.heightmaps)[filled].astype(np.int64)  # uint16, height * 65535
    assert np.abs(np.round(maps * 65535).astype(np.int64) - stored).max() <= 1
    assert (maps[:, :, :4] == 0.5).all() and (maps[:, :, -4:] == 0.5).all()  # strips of 32 // 8 pixels
    d = np.asarray(features.descriptors(maps, names=("max_step", "faces"), window=8, stride=2))
    np.testing.assert_allclose(d, np.asarray(arch.descriptors)[filled], rtol=1e-5, atol=1e-6)
    assert d[:, 0].max() > features.FACE_THRESHOLD  # some elite holds a face


def test_evolve_time_limit_stops_at_checkpoints_and_resumes_to_the_same_archive(tmp_path):
    """--time-limit 1e-6 stops after every chunk (exit 3) except the last, which saves the archive; resuming chunk by
    chunk ends with the archive of an uninterrupted run."""
    from jaxterrain import qd as A

    args = ["--preset", "smoke", "--generations", "4", "--checkpoint-every", "2"]
    assert cli("evolve", *args, "--out", str(tmp_path / "whole")) == 0
    out = tmp_path / "cut"
    codes = [cli("evolve", *args, "--out", str(out), "--time-limit", "1e-6")]
    while codes[-1] == 3 and len(codes) < 5:
        codes.append(cli("evolve", "--resume", str(out), "--time-limit", "1e-6"))
    assert codes == [3, 3, 0]  # cut after generation 0 and after 2; the chunk ending at 4 (the last) saves
    np.testing.assert_array_equal(A.load(out / "archive.npz").fitness, A.load(tmp_path / "whole" / "archive.npz").fitness)


def test_features_smoke(tmp_path):
    out = tmp_path / "f"
    assert cli("features", "--preset", "smoke", "--generators", "perlin", "--out", str(out)) == 0
    lines = (out / "correlations.csv").read_text().splitlines()
    assert lines[0] == "generator,feature_a,feature_b,r"
    r = {(a, b): float(v) for g, a, b, v in (line.split(",") for line in lines[1:])}
    assert r[("difficulty", "difficulty")] == pytest.approx(1.0)
    assert r[("tri_5", "difficulty")] == pytest.approx(r[("difficulty", "tri_5")])
    assert (out / "correlations.png").exists() and (out / "correlation_perlin.png").exists()


def test_features_takes_extra_descriptors_from_the_command_line(capsys):
    """``--extra-descriptors`` (e.g. the vertical-face descriptors for their Figure 4 alignment) lands in the config;
    an unknown name is refused in one line."""
    capsys.readouterr()
    with pytest.raises(SystemExit, match="0"):
        cli("features", "--extra-descriptors", "faces", "max_step", "--print-config")
    assert json.loads(capsys.readouterr().out)["extra_descriptors"] == ["faces", "max_step"]
    with pytest.raises(SystemExit):
        cli("features", "--extra-descriptors", "bogus", "--print-config")
    assert "unknown descriptor 'bogus'" in capsys.readouterr().err


def test_features_time_limit_stops_between_batches_and_resumes_to_the_same_values(tmp_path, capsys):
    args = ["features", "--preset", "smoke", "--generators", "perlin", "--terrains", "12", "--mutation-steps", "1",
            "--windows", "5"]
    assert cli(*args, "--out", str(tmp_path / "whole")) == 0
    out = tmp_path / "cut"
    assert cli(*args, "--out", str(out), "--time-limit", "1e-6") == 3  # after the first of two batches of 12 terrains
    assert (out / "checkpoint.npz").exists() and not (out / "values_perlin.csv").exists()
    assert len((out / "metrics.csv").read_text().splitlines()) == 1 + 1  # the driver's log: one batch measured
    capsys.readouterr()
    assert cli("features", "--resume", str(out)) == 0
    printed = capsys.readouterr().out
    assert "resumed after 1 of 2 batches" in printed and "12/24 terrains measured" not in printed  # not measured again
    assert "24/24 terrains measured" in printed and len((out / "metrics.csv").read_text().splitlines()) == 1 + 2
    assert (out / "values_perlin.csv").read_text() == (tmp_path / "whole" / "values_perlin.csv").read_text()
    assert (out / "metrics.csv").read_text() == (tmp_path / "whole" / "metrics.csv").read_text()


@pytest.mark.slow
def test_coverage_smoke_skips_unavailable(tmp_path, monkeypatch):
    """A registered generator that cannot render here (the GAN without its weights, faked) is skipped: said in the
    tables and left out of the combined archive; an unknown name is refused before anything runs."""
    from jaxterrain.qd import table1

    real = table1.generator_available
    monkeypatch.setattr(table1, "generator_available",
                        lambda name, size: (False, "OSError: no weights") if name == "gan" else real(name, size))
    out = tmp_path / "c"
    assert cli("coverage", "--preset", "smoke", "--generators", "perlin", "gan", "--out", str(out)) == 0
    md = (out / "coverage.md").read_text()
    assert "Perlin Noise" in md and "Combined" in md and "gan (OSError: no weights)" in md and "Skipped" in md
    csv_rows = (out / "coverage.csv").read_text().splitlines()
    assert any(row.startswith("gan,,skipped") for row in csv_rows)
    assert (out / "coverage.png").exists() and (out / "archives.png").exists()


def test_coverage_shards_partition_the_treatments_and_resume_writes_the_tables(tmp_path, monkeypatch):
    """--shard I/N runs the treatments t % N == I with the keys of an unsharded run; --resume then reuses every
    archive and writes the same tables. The treatment itself is faked (a hand-made archive derived from its key)."""
    import jax

    from jaxterrain import qd as A
    from jaxterrain.qd import runs, table1

    calls = []

    def fake_treatment(run, folder, time_limit_s=None, mesh=None, key=None, label="", figures=True, deadline=None,
                       say=print):
        done = folder / "archive.npz"
        if done.exists():
            return A.load(done)
        calls.append((folder.name, tuple(np.asarray(jax.random.key_data(key)).ravel())))
        config = A.resolve_config(runs.evolve_config(run))
        generator = run.generator
        rng = np.random.default_rng(calls[-1][1])
        fit = np.where(rng.random(config.bins**2) < 0.3, rng.random(config.bins**2), -np.inf).astype(np.float32)
        filled = np.isfinite(fit)
        arch = A.Archive((np.zeros((fit.size, 3), np.float32),), (generator,), np.where(filled, 0, -1).astype(np.int32),
                         fit, np.zeros((fit.size, 2), np.float32), np.asarray(A.centroids_for(config)), None, config,
                         {"rejected": np.float32([1.0, 2.0])})
        return A.load(A.save(done, arch))

    monkeypatch.setattr(table1, "evolve_run", fake_treatment)
    base = ["coverage", "--preset", "smoke", "--generators", "perlin", "diamond_square"]
    assert cli(*base, "--out", str(tmp_path / "whole")) == 0
    whole = dict(calls)
    assert len(whole) == 6
    calls.clear()
    out = tmp_path / "sharded"
    assert cli(*base, "--out", str(out), "--shard", "1/4") == 0
    assert [name for name, _ in calls] == ["diamond_square__tri-tpi", "diamond_square__tpi-roughness"]  # t = 1, 5
    assert not (out / "coverage.csv").exists()  # a shard writes no tables
    for i in (0, 2, 3):
        assert cli(*base, "--out", str(out), "--shard", f"{i}/4") == 0
    assert sorted(calls) == sorted(whole.items())  # each treatment once, with its unsharded key
    assert cli("coverage", "--resume", str(out)) == 0 and len(calls) == 6  # reuses all six
    assert (out / "coverage.csv").read_text() == (tmp_path / "whole" / "coverage.csv").read_text()
    assert (out / "coverage.md").read_text() == (tmp_path / "whole" / "coverage.md").read_text()
    for bad in ("4/4", "1", "a/b", "0/0"):
        with pytest.raises(SystemExit):
            cli(*base, "--out", str(tmp_path / "bad"), "--shard", bad)
    assert common.parse_shard("2/3") == (2, 3)


def test_help_lists_commands():
    res = subprocess.run([sys.executable, "-m", "experiments", "--help"], cwd=ROOT, capture_output=True, text=True)
    assert res.returncode == 0
    for name in ("evolve", "features", "coverage"):
        assert name in res.stdout


def test_protocol_flag_sets_attempts_best_and_headings_together():
    """``--protocol headings`` = 80 walks, best 5 per heading, 4 headings (difficulty.HEADINGS); single-field flags
    win; evolve and coverage write them into the config (coverage has --protocol only)."""
    import argparse

    from experiments import coverage, evolve

    def parsed(module, argv):
        parser = argparse.ArgumentParser()
        module.add_arguments(parser)
        return module.overrides(parser.parse_args(argv))

    over = parsed(evolve, ["--protocol", "headings", "--best", "4"])
    assert (over["attempts"], over["best"], over["headings"]) == (80, 4, 4)
    assert "headings" not in {k for k, v in parsed(evolve, []).items() if v is not None}
    assert parsed(coverage, ["--protocol", "paper"])["headings"] == 1
    given = {k: v for k, v in over.items() if v is not None}
    from jaxterrain.qd import run_config, runs

    assert runs.evolve_config(run_config.from_flat({**evolve.PRESETS["gpu"], **given})).headings == 4
    old = {k: v for k, v in evolve.PRESETS["gpu"].items() if k != "headings"}  # a config.json before headings
    assert runs.evolve_config(run_config.from_flat(old)).headings == 1
    with pytest.raises(common.UsageError, match="'attempts' must be a multiple of --headings"):
        common.check_values({"attempts": 2, "best": 1, "headings": 4},
                            where=lambda k: f"'{k}'" if k == "attempts" else common.flag(k))
    with pytest.raises(common.UsageError, match="--best must be <= --attempts / --headings"):
        common.check_values({"attempts": 20, "best": 6, "headings": 4})


def test_every_command_prints_its_help(capsys):
    """``python -m experiments CMD --help`` formats (argparse fails on a lone % in a help text) and exits 0."""
    from experiments.__main__ import COMMANDS, main

    for name in COMMANDS:
        with pytest.raises(SystemExit) as err:
            main([name, "--help"])
        assert err.value.code == 0, name
        assert "usage:" in capsys.readouterr().out, name


def test_every_flag_override_is_a_key_of_every_preset():
    """Each command's ``overrides(args)`` keys exist in each of its presets, so that a flag given on the command line
    is not refused as an "unknown config key" (``evolve --rollout-backend`` once was)."""
    import argparse
    import importlib

    from experiments.__main__ import COMMANDS

    checked = 0
    for name, (module_name, _) in COMMANDS.items():
        module = importlib.import_module(module_name)
        if not (hasattr(module, "overrides") and hasattr(module, "PRESETS")):
            continue
        parser = argparse.ArgumentParser()
        module.add_arguments(parser)
        keys = set(module.overrides(parser.parse_args([])))
        for preset, values in module.PRESETS.items():
            assert keys <= set(values), f"{name} --preset {preset}: no key for {sorted(keys - set(values))}"
        checked += 1
    assert checked >= 6
