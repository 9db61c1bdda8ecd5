"""One ``--resume`` rule in every command that keeps a run folder (``experiments.common.setup_run`` /
``resume_folder``), and one table of ``--fitness`` names (``difficulty.FITNESSES``). CPU, no JAX work: each command is
stopped right after its run folder is resolved."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from experiments import __main__ as cli
from experiments import common

COMMANDS = ["evolve", "coverage", "learn", "curriculum", "gradient", "features", "train-gan", "train-base-policy",
            "train-traversability"]


class Resolved(Exception):
    """Raised by the spied ``common.prepare_run`` with its ``(folder, config)``: the command stops before any work."""


def _usage_error(argv, capsys) -> str:
    with pytest.raises(SystemExit) as exc:
        cli.main(argv)
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 2 and len(err.splitlines()) == 1, err
    assert err.startswith(f"python -m experiments {argv[0]}: error: "), err
    return err


@pytest.mark.parametrize("command", COMMANDS)
def test_out_with_resume_means_the_same_in_every_command(tmp_path, monkeypatch, capsys, command):
    """``--out RUN --resume`` continues RUN (not the newest run of the command), ``--resume`` alone the newest,
    ``--resume ./RUN/ --out RUN`` (one folder) RUN; ``--resume A --out B``, a folder without config.json and
    another command's run are one line naming the flags, exit 2, before the command does anything."""
    monkeypatch.chdir(tmp_path)
    if command not in cli.COMMANDS:
        pytest.skip(f"no command {command}")
    saved = {"command": command, "seed": 7, "preset": "smoke"}
    for folder in ("mine", f"runs/{command}-99991231-000000"):  # the second is the newest run of the command
        Path(folder).mkdir(parents=True)
        common.write_config(Path(folder), saved)
    Path("other").mkdir()
    common.write_config(Path("other"), {"command": "report", "seed": 0})
    Path("empty").mkdir()
    real = common.prepare_run  # every command's settings are resolved there (setup_run, setup_typed)

    def spy(command, args, presets, default_preset, overrides, extendable, settle, preset_by_flag):
        unchecked = lambda config, where, resumed, changed: config  # noqa: E731  (the folder, not the values)
        raise Resolved(real(command, args, presets, default_preset, overrides, extendable, unchecked, preset_by_flag))

    monkeypatch.setattr(common, "prepare_run", spy)

    def resolved(*argv):
        with pytest.raises(Resolved) as stop:
            cli.main([command, *argv])
        folder, config = stop.value.args[0]
        assert config == saved
        return folder

    assert resolved("--out", "mine", "--resume") == Path("mine")
    assert resolved("--resume", "mine") == Path("mine")
    assert resolved("--resume", "./mine/", "--out", "mine") == Path("mine")
    assert resolved("--resume") == Path(f"runs/{command}-99991231-000000")
    capsys.readouterr()
    assert "--resume mine and --out elsewhere name different runs" in _usage_error(
        [command, "--resume", "mine", "--out", "elsewhere"], capsys)
    assert "--out 'empty' --resume: no config.json in 'empty', so no run to continue; start one with --out empty" \
        in _usage_error([command, "--out", "empty", "--resume"], capsys)
    assert "--resume 'missing': no config.json" in _usage_error([command, "--resume", "missing"], capsys)
    assert "--out 'other' --resume is a run of" in _usage_error([command, "--out", "other", "--resume"], capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty", "mine", "other", "runs"]  # nothing made
    assert common.load_config("mine") == saved  # nothing rewritten
    lines = [json.loads(line) for line in (Path("mine") / common.PROVENANCE_NAME).read_text().splitlines()]
    assert [(line["options"].get("resume"), line["options"].get("out")) for line in lines][1:] == [
        ("mine", None), ("./mine/", "mine")] and lines[0]["options"]["out"] == "mine"  # one per resume, its options
    assert all(line["resumed"] and line["command"] == command and "cpu" in line["devices"] for line in lines)


def test_every_start_and_resume_appends_a_provenance_line(tmp_path, monkeypatch):
    """``provenance.jsonl``: a fresh start, then a resume, each one line naming the commit, devices and jax; on a
    tree without git, ``$JAXTERRAIN_COMMIT`` names the commit."""
    import argparse

    import jax

    monkeypatch.chdir(tmp_path)
    presets = {"default": {"seed": 0}}
    args = dict(resume=None, config=None, preset=None, seed=None, out="run")
    folder, _ = common.setup_run("gradient", argparse.Namespace(**args), presets, "default", {})
    monkeypatch.setenv("JAXTERRAIN_COMMIT", "abc1234")
    common.setup_run("gradient", argparse.Namespace(**{**args, "resume": "run", "out": None}), presets, "default", {})
    first, second = [json.loads(line) for line in (folder / common.PROVENANCE_NAME).read_text().splitlines()]
    assert not first["resumed"] and second["resumed"] and second["commit"] == "abc1234" != first["commit"]
    assert first["commit"] and first["jax"] == jax.__version__ and first["processes"] == 1
    assert first["command"] == "gradient" and first["time"].endswith("+00:00")


def test_resume_without_any_run_is_one_line(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert "--resume: no run of 'evolve' with a config.json under runs/" in _usage_error(["evolve", "--resume"],
                                                                                       capsys)


def test_one_table_of_fitness_names(tmp_path, monkeypatch, capsys):
    """``difficulty.FITNESSES`` is the one list of names: evolve's and features' functions come from it, and a bad name
    in a saved config is one line naming its key before the run folder."""
    import jax

    from jaxterrain import difficulty
    from jaxterrain.qd import run_config, runs

    assert list(difficulty.FITNESSES) == ["difficulty", "slope"] == list(run_config._FITNESSES)  # evolve's literal
    assert runs.fitness_of("difficulty") is None  # qd.evolve builds the walker fitness from its config
    assert runs.fitness_of("slope") is difficulty.slope_fitness is difficulty.named_fitness("slope", 2, 1, 32)
    assert difficulty.named_fitness("difficulty", 2, 1, 64, slots=8) is difficulty.fitness_fn(
        64, difficulty.Protocol(2, 1), slots=8)  # the library's factory, same (cached) function
    maps = np.linspace(0, 0.2, 2 * 8 * 8, dtype=np.float32).reshape(2, 8, 8)
    np.testing.assert_array_equal(difficulty.slope_fitness(maps, jax.random.key(0), np.array([True, False])),
                                  difficulty.slope_fitness(maps))  # (heightmaps, key, needed) as (heightmaps, key)
    with pytest.raises(common.UsageError, match="--fitness: unknown fitness 'walk'; choose from difficulty, slope"):
        common.fitness_of("walk")
    monkeypatch.chdir(tmp_path)
    Path("bad.json").write_text(json.dumps({"fitness": "walk"}))
    err = _usage_error(["evolve", "--config", "bad.json", "--out", "run"], capsys)
    assert "bad.json: key 'fitness' must be one of difficulty, slope; got 'walk'" in err
    assert not Path("run").exists()
