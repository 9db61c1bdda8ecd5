"""``--spawn feet|patch``: a resumed run keeps its spawn rule, one saved before its command had the key too.
CPU: nothing compiles, no run starts."""

from __future__ import annotations

import json

import pytest

from experiments import __main__ as cli
from experiments import common


def printed(capsys, *argv, notes: list | None = None) -> dict:
    """The resolved config ``--print-config`` prints (nothing is written); its stderr lines appended to ``notes``."""
    with pytest.raises(SystemExit) as exc:
        cli.main([*argv, "--print-config"])
    out, err = capsys.readouterr()
    assert exc.value.code == 0, err
    if notes is not None:
        notes.extend(err.splitlines())
    return json.loads(out)


@pytest.mark.parametrize("command", ["learn", "curriculum", "evaluate"])
def test_a_run_saved_before_the_key_resumes_under_the_rule_it_started_with(tmp_path, monkeypatch, capsys, command):
    """A ``config.json`` without ``spawn`` (saved before the command had the key), resumed, continues under the rule
    its ``provenance.jsonl`` records for the process that started it (the library's default then: ``feet`` since
    2026-11-29) or, where that line names none, its run config's ``LEGACY`` ``patch`` (``common.started_spawn``;
    ``common.spawn_rule``: the rule the typed run reads and the provenance line records)."""
    monkeypatch.chdir(tmp_path)
    flat = {k: v for k, v in printed(capsys, command).items() if k != "spawn"}
    for name, lines, rule in (("unrecorded", [], "patch"), ("feet", [{"resumed": False, "spawn": "feet"}], "feet"),
                              ("patch", [{"resumed": False, "spawn": "patch"}], "patch"),
                              ("older", [{"resumed": False}, {"resumed": True, "spawn": "feet"}], "patch")):
        common.write_config(tmp_path / name, {**flat, "command": command})
        (tmp_path / name / common.PROVENANCE_NAME).write_text("".join(json.dumps(line) + "\n" for line in lines))
        assert common.spawn_rule(command, printed(capsys, command, "--resume", name)) == rule, name
