"""``--help`` reads right: every option has help, every boolean setting works both ways under its config key's name,
the value ``--help`` shows for it is the one ``--print-config`` prints, one flag per concept across commands, and the
older spellings still parse (hidden). No command runs past ``--print-config``."""

from __future__ import annotations

import argparse
import json
import re

import pytest

from experiments import common
from experiments.__main__ import build_parser, main

PARSER, COMMANDS = build_parser()


def _visible(parser):
    return [a for a in parser._actions if a.help != argparse.SUPPRESS and a.dest != "help"]


def _help(parser) -> str:
    return parser.format_help()


def _printed(argv, capsys) -> dict:
    with pytest.raises(SystemExit) as exc:
        main(argv)
    out = capsys.readouterr()
    assert exc.value.code == 0, out.err
    return json.loads(out.out)


def _shown(help_text: str, preset: str) -> str:
    """The value a flag's help shows for ``preset``: ``[every preset: V]`` or ``[... preset: V; ...]``."""
    tail = re.search(r"\[([^\[\]]*)\]\s*$", help_text).group(1)
    if tail.startswith("every preset: "):
        return tail[len("every preset: "):]
    return dict(part.split(": ", 1) for part in tail.split("; "))[preset]


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_every_option_has_help_and_nothing_shows_suppress(name):
    parser = COMMANDS[name][1]
    text = _help(parser)
    assert "==SUPPRESS==" not in text and "SUPPRESS" not in text
    for action in _visible(parser):
        assert action.help and action.help.strip() and not action.help.startswith("["), (name, action.dest)


def _boolean_settings():
    for name, (module, parser) in sorted(COMMANDS.items()):
        presets = getattr(module, "PRESETS", None)
        if not presets:
            continue
        keys = sorted({k for p in presets.values() for k, v in p.items() if isinstance(v, bool)})
        for key in keys:
            if any(a.dest == key for a in _visible(parser)):
                yield name, key


BOOLEANS = list(_boolean_settings())


def test_the_boolean_settings_are_the_ones_expected():
    """The list the next test walks is not empty by accident (a renamed key would drop out of it)."""
    assert {("learn", "update_normaliser"), ("learn", "overlap"), ("learn", "compact"), ("curriculum",
            "update_normaliser"), ("evolve", "store_heightmaps"), ("train-traversability", "heldout"),
            ("evaluate", "repeat"), ("coverage", "batched"), ("features", "calibrate"),
            ("gradient", "reseat")} <= set(BOOLEANS)


@pytest.mark.parametrize("name,key", BOOLEANS)
def test_a_boolean_setting_works_both_ways_and_help_shows_the_printed_value(name, key, capsys):
    module, parser = COMMANDS[name]
    (action,) = [a for a in _visible(parser) if a.dest == key]
    positive = common.flag(key)
    assert isinstance(action, argparse.BooleanOptionalAction), (name, key)
    assert action.option_strings == [positive, "--no-" + positive[2:]], "the flag is the config key's name"
    inputs = [common.shipped("archives/cppn_headings.npz")] if name == "gradient" else []  # it needs an archive
    for preset in module.PRESETS:
        printed = _printed([name, *inputs, "--preset", preset, "--print-config"], capsys)[key]
        assert _shown(action.help, preset) == str(printed), (name, key, preset)
    needs = ["--protocol", "paper"] if (name, key) == ("gradient", "reseat") else []  # --reseat walks again
    assert _printed([name, *inputs, positive, *needs, "--print-config"], capsys)[key] is True
    assert _printed([name, *inputs, "--no-" + positive[2:], "--print-config"], capsys)[key] is False


@pytest.mark.parametrize("argv,key,value", [
    (["learn", "--freeze-normaliser"], "update_normaliser", False),
    (["curriculum", "--freeze-normaliser"], "update_normaliser", False),
    (["evolve", "--no-heightmaps"], "store_heightmaps", False),
    (["evolve", "--rollout-backend", "warp", "--preset", "gpu"], "rollout_backend", "warp"),  # a fitness that walks
    (["evaluate", "--slots", "48"], "slots", 48),
    (["gradient", common.shipped("archives/cppn_headings.npz"), "--slots", "all", "--protocol", "paper"], "slots",
     "all"),  # --slots sizes the walks of --protocol (refused without it)
    (["features", "--samples", "12"], "samples", 12),
])
def test_old_spellings_still_parse_hidden_and_name_the_new_one(argv, key, value, capsys):
    assert _printed([*argv, "--print-config"], capsys)[key] == value
    old = next(a for a in argv if a.startswith("--"))
    assert old not in _help(COMMANDS[argv[0]][1]).replace(old + "-", "")  # not in --help (nor the docs' page)
    with pytest.raises(SystemExit):
        main([*argv, "--print-config"])
    assert "is deprecated; use --" in capsys.readouterr().err


def test_report_and_quickstart_switches_work_both_ways():
    report = COMMANDS["report"][1]
    assert report.parse_args(["RUN"]).videos is True and report.parse_args(["RUN", "--no-videos"]).videos is False
    assert report.parse_args(["RUN", "--steps", "7"]).video_steps == 7  # the old spelling of --video-steps
    quick = COMMANDS["quickstart"][1]
    assert quick.parse_args([]).report is True and quick.parse_args(["--no-report"]).report is False
    assert quick.parse_args(["--n", "3"]).n == 3 and quick.parse_args(["--terrains", "3"]).n == 3


def test_one_flag_per_concept_across_commands():
    backends, terrains = {}, {}
    for name, (_, parser) in COMMANDS.items():
        shown = {s for a in _visible(parser) for s in a.option_strings}
        assert not shown & {"--slots", "--rollout-backend", "--samples", "--n", "--freeze-normaliser",
                            "--no-heightmaps", "--lr", "--ckpt-every", "--width"}, name
        assert "--height" not in shown or name == "export", name  # export's is metres, not pixels
        for action in _visible(parser):
            if "--backend" in action.option_strings:
                backends[name] = tuple(action.choices)
            if "--terrains" in action.option_strings:
                terrains[name] = action.help
            if "--steps" in action.option_strings:  # training steps wherever it is a flag
                assert "training steps" in action.help, name
    assert set(backends) >= {"learn", "curriculum", "evaluate", "evolve"}
    assert set(backends.values()) == {common.BACKEND_NAMES}
    assert set(terrains) >= {"quickstart", "difficulty-spread", "features", "evaluate", "train-traversability"}
    # --terrains N: terrains sampled per generator; --terrains DIR: a folder of your own heightmaps (learn: only that)
    assert all(h.startswith("terrains sampled per generator") for n, h in terrains.items() if n != "learn")
    assert "or DIR, a folder of heightmaps" in terrains["evaluate"]
    assert terrains["learn"].startswith("DIR, a folder of your own heightmaps")


def test_backend_names_match_the_library():
    from jaxterrain.walker.layout import BACKEND_CHOICES

    assert common.BACKEND_NAMES == BACKEND_CHOICES


def test_every_command_with_a_progress_bar_takes_no_progress(monkeypatch):
    import os

    from jaxterrain.runtime import driver

    for name in ("learn", "curriculum", "features", "train-gan", "train-base-policy"):
        parser = COMMANDS[name][1]
        assert parser.parse_args([]).progress is True and parser.parse_args(["--no-progress"]).progress is False
    assert common.progress_mode(COMMANDS["learn"][1].parse_args(["--no-progress"])) == "plain"
    assert common.progress_mode(COMMANDS["learn"][1].parse_args([])) is True
    assert isinstance(driver._bar("plain", 10, 0, "x", "chunk"), driver._PlainProgress)  # on a terminal too
    assert driver._bar(False, 10, 0, "x", "chunk") is None and "JAXTERRAIN_PROGRESS" not in os.environ


def test_preset_help_gives_the_measured_smoke_times_and_every_presets_meaning():
    learn = _help(COMMANDS["learn"][1])
    assert "about a minute" not in learn and "6-10 min on 2 CPU cores" in re.sub(r"\s+", " ", learn)
    evaluate = re.sub(r"\s+", " ", _help(COMMANDS["evaluate"][1]))
    assert "4-6 min on 2 CPU cores" in evaluate
    for name, (module, parser) in COMMANDS.items():
        (preset,) = [a for a in parser._actions if a.dest == "preset"] or [None]
        if preset is not None and "same settings" not in preset.help:
            for choice in preset.choices:
                assert f"{choice}: " in preset.help, (name, choice)
