"""The command line generated from a run config's declaration (``experiments.cli_gen``): each flag's type, choices,
switch and range come from the config's fields and declared rules, so a flag and its config cannot drift apart; a
bad value is one line naming the flag and its range."""

from __future__ import annotations

import argparse
from typing import NamedTuple, Optional

import pytest

from experiments import cli_gen, common
from experiments.__main__ import build_parser
from jaxterrain.runtime import schema

PARSER, COMMANDS = build_parser()


class Part(NamedTuple):
    rate: float = 0.5
    names: Optional[tuple] = None


class Toy(NamedTuple):
    count: int = 3
    mode: str = "a"
    switch: bool = True
    attempts: int = 4
    best: int = 2
    headings: int = 1
    part: Part = Part()
    seed: int = 0


FIELDS = {"count": "count", "mode": "mode", "switch": "switch", "attempts": "attempts", "best": "best",
          "headings": "headings", "rate": "part.rate", "names": "part.names", "seed": "seed"}
HELP = {"count": "how many", "mode": "which way", "switch": "on or off", "attempts": "walks",
        "best": "best walks", "headings": "headings", "rate": "a rate, {range} (the middle)", "names": "names"}


def toy_parser(rules: dict) -> tuple[argparse.ArgumentParser, list]:
    typed = common.Typed("Toy", FIELDS, lambda flat: schema.from_flat(Toy, flat, FIELDS),
                         lambda run: schema.to_flat(run, FIELDS), rules)
    parser = argparse.ArgumentParser(prog="toy", exit_on_error=False)
    presets = {"smoke": schema.to_flat(Toy(), FIELDS)}
    return parser, cli_gen.add_typed_flags(parser, typed, presets, HELP)


RULES = {"count": schema.at_least(1), "mode": schema.one_of(("a", "b")), "switch": schema.one_of((True, False)),
         "attempts": schema.at_least(1), "best": (schema.at_least(1), schema.at_most("attempts")),
         "headings": schema.walks("attempts", "best"), "part.rate": schema.unit()}


def test_the_flags_take_their_type_choices_and_range_from_the_declaration():
    parser, flags = toy_parser(RULES)
    by_key = {f.key: f for f in flags}
    assert [f.option for f in flags] == ["--count", "--mode", "--switch", "--attempts", "--best", "--headings",
                                         "--rate", "--names"]
    assert by_key["count"].kind is int and by_key["count"].help == "how many, >= 1"
    assert by_key["mode"].choices == ("a", "b") and by_key["headings"].choices == (1, 2, 4)
    assert by_key["switch"].boolean and by_key["rate"].kind is float
    assert by_key["rate"].help == "a rate, in (0, 1] (the middle)"  # {range} places it
    assert by_key["best"].help == "best walks, >= 1, <= --attempts"  # a bound is named by its flag
    assert by_key["names"].nargs == "+"  # Optional[tuple]: the field's annotation
    args = parser.parse_args(["--count", "5", "--no-switch", "--rate", "0.25", "--names", "x", "y"])
    assert cli_gen.given(args, HELP) == {"count": 5, "mode": None, "switch": False, "attempts": None, "best": None,
                                         "headings": None, "rate": 0.25, "names": ["x", "y"]}
    assert parser.parse_args([]).switch is None  # not given: the preset's value stands
    with pytest.raises(argparse.ArgumentError, match="invalid choice"):
        parser.parse_args(["--mode", "c"])


def test_a_changed_declaration_changes_the_flag_so_the_two_cannot_drift():
    """The same field declared with other choices / another range gives another flag: nothing is copied."""
    _, flags = toy_parser({**RULES, "mode": schema.one_of(("a", "b", "c")), "count": schema.at_least(7),
                           "part.rate": schema.fraction()})
    by_key = {f.key: f for f in flags}
    assert by_key["mode"].choices == ("a", "b", "c")
    assert by_key["count"].help == "how many, >= 7" and by_key["rate"].help == "a rate, in [0, 1] (the middle)"
    _, bare = toy_parser({})  # no rule: the annotation's type, no range
    assert {f.key: (f.kind, f.choices, f.help) for f in bare}["count"] == (int, None, "how many")


def test_a_bad_value_is_one_line_naming_the_flag_and_the_range_the_help_shows():
    _, flags = toy_parser(RULES)
    rules = cli_gen.rules_by_key(RULES, FIELDS)
    values = schema.to_flat(Toy(), FIELDS)
    for key, bad, shown in (("count", 0, ">= 1"), ("rate", 1.5, "in (0, 1]"), ("best", 9, "<= --attempts")):
        with pytest.raises(common.UsageError) as err:
            common.check_rules({**values, key: bad}, rules)
        text = str(err.value)
        (flag,) = [f for f in flags if f.key == key]
        assert "\n" not in text and text.startswith(f"{flag.option} must be") and shown in text, text
        assert shown in flag.help, flag.help  # the range --help gives is the one the error says


def _generated(name):
    """``{dest: action}`` of a command's options whose flat key has a declared rule, and those rules."""
    module, parser = COMMANDS[name]
    typed = getattr(module, "TYPED", None)
    rules = cli_gen.rules_by_key(typed.rules, typed.fields) if typed is not None else module.RULES
    actions = {a.dest: a for a in parser._actions if a.dest in rules and a.help != argparse.SUPPRESS
               and a.option_strings and a.option_strings[0] == common.flag(a.dest)}
    return actions, rules


@pytest.mark.parametrize("name", ["learn", "curriculum", "evolve", "coverage", "train-base-policy", "evaluate"])
def test_every_long_commands_flags_show_the_choices_and_range_their_config_declares(name):
    actions, rules = _generated(name)
    assert len(actions) >= 5, name
    for key, action in actions.items():
        for rule in rules[key]:
            if rule.choices is not None and rule.kind is not bool:
                assert tuple(action.choices) == rule.choices, (name, key)
            if rule.kind is bool:
                assert isinstance(action, argparse.BooleanOptionalAction), (name, key)
            if rule.text:
                assert rule.text in action.help, (name, key, action.help)
            elif rule.kind in (int, float) and rule.choices is None and rule.bound is None:
                raise AssertionError((name, key))


def _bad_values(rules: tuple) -> list:
    """Values each of ``rules`` refuses (a bound on another field aside)."""
    out = []
    for rule in rules:
        if rule.choices is not None:
            out.append(3 if rule.kind is int else "nope")
        elif rule.text.startswith(">= "):
            out.append(int(rule.text[3:]) - 1)
        elif rule.text == "> 0":
            out.append(0.0)
        elif rule.text == "in (0, 1]":
            out.append(0.0)
        elif rule.text == "in [0, 1]":
            out.append(1.5)
    return out


def test_what_the_learn_flags_refuse_the_library_refuses_too():
    """``jaxterrain.curriculum.presets.RULES`` (the flags' declaration, checked on the resolved config) refuses
    nothing the library's own check of the curriculum (``runner.curriculum_config``) takes: for every key that
    lands in the run's ``CurriculumConfig``, each value a rule refuses is refused by the library as well."""
    from experiments import learn
    from jaxterrain.curriculum import run_config, runner
    from jaxterrain.curriculum.config import SELECTOR_FIELDS

    checked = 0
    for key, rules in learn.RULES.items():
        selector = SELECTOR_FIELDS.get(key, ("map",))[0]
        if not run_config.field_of(key, selector).startswith(("curriculum.", "protocol.")) and key != "recipe":
            continue
        for bad in _bad_values(rules):
            flat = {**learn.PRESETS["smoke"], "curriculum": selector, key: bad}
            with pytest.raises(common.UsageError):
                common.check_rules(flat, learn.RULES)
            with pytest.raises((ValueError, TypeError, runner.BadInput)):
                runner.curriculum_config(run_config.from_flat(flat))
            checked += 1
    assert checked >= 20
