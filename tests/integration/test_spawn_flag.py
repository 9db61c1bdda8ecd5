"""``--spawn feet|patch`` of the commands that walk a policy outside a curriculum, as ``learn`` / ``curriculum`` /
``evaluate`` take it: ``evolve`` (the walker fitness) and ``train-base-policy`` (the trained walker). The flag parses
into the run's config (``config.json``), the typed run built from it hands the rule to the walker config the run
walks, a bad value is one argparse line, a resumed run keeps its saved rule (another one given is ignored with a
note, as in ``learn``) and its ``provenance.jsonl`` line says it. CPU: nothing compiles, no run starts."""

from __future__ import annotations

import json

import pytest

from experiments import __main__ as cli
from experiments import common

WALKING = {"evolve": ["--fitness", "difficulty", "--size", "64"], "train-base-policy": []}
"""Each command, with the flags that make its smoke preset walk a policy (evolve's smoke fitness is the slope)."""


def printed(capsys, *argv, notes: list | None = None) -> dict:
    """The resolved config ``--print-config`` prints (nothing is written); its stderr lines appended to ``notes``."""
    with pytest.raises(SystemExit) as exc:
        cli.main([*argv, "--print-config"])
    out, err = capsys.readouterr()
    assert exc.value.code == 0, err
    if notes is not None:
        notes.extend(err.splitlines())
    return json.loads(out)


def walker_spawn(command: str, flat: dict) -> str:
    """The spawn rule of the walker config that ``command``'s typed run (read from its flat config) walks."""
    if command == "evolve":
        from jaxterrain.qd import run_config, runs

        return runs.evolve_config(runs.validate_evolve(run_config.from_flat(flat))).spawn  # -> default_fitness's env
    from jaxterrain.difficulty import base_policy, run_config

    return base_policy.validate_base_run(run_config.from_flat(flat)).env_config.spawn


@pytest.mark.parametrize("command", sorted(WALKING))
def test_the_flag_reaches_the_config_and_the_walker(capsys, command):
    assert printed(capsys, command, *WALKING[command])["spawn"] == "feet"  # every preset's
    for rule in ("feet", "patch"):
        flat = printed(capsys, command, *WALKING[command], "--spawn", rule)
        assert flat["spawn"] == rule and walker_spawn(command, flat) == rule
    with pytest.raises(SystemExit) as exc:
        cli.main([command, "--spawn", "torso"])
    err = capsys.readouterr().err.strip().splitlines()
    assert exc.value.code == 2 and err[-1] == (f"python -m experiments {command}: error: argument --spawn: invalid "
                                               f"choice: 'torso' (choose from 'feet', 'patch')")


@pytest.mark.parametrize("command", sorted(WALKING))
def test_a_resumed_run_keeps_its_rule_and_records_it(tmp_path, monkeypatch, capsys, command):
    """``--resume RUN --spawn patch`` on a run saved with ``feet`` continues under ``feet`` and says it ignored the
    flag (``learn``'s rule for every setting that is not extendable); the provenance line names the run's rule."""
    monkeypatch.chdir(tmp_path)
    flat = printed(capsys, command, *WALKING[command], "--spawn", "feet")
    common.write_config(tmp_path / "run", {**flat, "command": command})
    notes = []
    resumed = printed(capsys, command, "--resume", "run", "--spawn", "patch", notes=notes)
    assert resumed["spawn"] == "feet" and walker_spawn(command, resumed) == "feet"
    assert "--resume: ignoring ['spawn']; the run continues with its saved config" in notes, notes
    assert common.spawn_rule(command, resumed) == "feet"
    assert common.spawn_rule(command, {**resumed, "spawn": "patch"}) == "patch"
    old = {k: v for k, v in resumed.items() if k != "spawn"}  # a config.json written before the key
    assert common.spawn_rule(command, old) == "patch" and walker_spawn(command, old) == "patch"


@pytest.mark.parametrize("command", [*sorted(WALKING), "learn", "curriculum", "evaluate"])
def test_a_run_saved_before_the_key_resumes_under_the_rule_it_started_with(tmp_path, monkeypatch, capsys, command):
    """A ``config.json`` without ``spawn`` (saved before the command had the key), resumed, continues under the rule
    its ``provenance.jsonl`` records for the process that started it (the library's default then: ``feet`` since
    2026-11-29) or, where that line names none, its run config's ``LEGACY`` ``patch`` (``common.started_spawn``;
    ``common.spawn_rule``: the rule the typed run reads and the provenance line records)."""
    monkeypatch.chdir(tmp_path)
    flat = {k: v for k, v in printed(capsys, command, *WALKING.get(command, [])).items() if k != "spawn"}
    for name, lines, rule in (("unrecorded", [], "patch"), ("feet", [{"resumed": False, "spawn": "feet"}], "feet"),
                              ("patch", [{"resumed": False, "spawn": "patch"}], "patch"),
                              ("older", [{"resumed": False}, {"resumed": True, "spawn": "feet"}], "patch")):
        common.write_config(tmp_path / name, {**flat, "command": command})
        (tmp_path / name / common.PROVENANCE_NAME).write_text("".join(json.dumps(line) + "\n" for line in lines))
        assert common.spawn_rule(command, printed(capsys, command, "--resume", name)) == rule, name
