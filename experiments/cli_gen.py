"""The command line generated from a run config's declaration: one flag per config field, made in one place.

A long command's settings are a typed run config of the library (``jaxterrain.qd.run_config.EvolveRun``, ...) whose
serialised form is a flat dict (``config.json``); its keys are the flags' names (:func:`experiments.common.flag`:
``batch_size`` -> ``--batch-size``, the few renamed ones in ``common.FLAG_NAMES``). :func:`add_flags` makes the
argparse option of each key a command exposes from what the library declares:

- the value's type, from the field's declared rule (``schema.at_least(1)``: an integer; ``schema.unit()``: a number;
  ``schema.one_of((True, False))``: a ``--x / --no-x`` switch), else from the field's annotation (``Optional[int]``;
  ``tuple``: ``nargs="+"``), else from the presets' values;
- its choices, from a ``schema.one_of`` rule (``--headings``: ``schema.walks``' 1, 2, 4);
- its allowed range in the help (``", >= 1"``, or where the help text says ``{range}``), in the words the rule's
  error uses, so ``--help`` and the error cannot drift apart;
- the help text, the field's documentation (the config module's ``HELP``: ``{flat key: text}``; the phrases every
  command shares written ``{backend}``, ``{randomise}``, ``{slots}``: ``common.PHRASES``), to which ``--help`` adds
  every preset's value (``common.show_preset_values``).

The default of every generated option is None (not given): the preset's value, a ``--config`` file's or a resumed
run's stands (``common.prepare_run``). :func:`given` reads the parsed values back as ``{flat key: value}``. The
library validates the resolved typed config once (``common.setup_typed``); ``learn`` / ``curriculum``, whose typed
config imports JAX, declare their rules by flat key (``jaxterrain.curriculum.presets.RULES``), run on the resolved
flat config by ``common.check_rules``; either way each message names the flag (or the preset / file the value came
from). Standard library only: ``--help`` stays fast.
"""

from __future__ import annotations

import argparse
from typing import Any, Callable, Mapping, NamedTuple, Optional

from experiments import common

__all__ = ["Flag", "rules_by_key", "annotations_of", "derive", "add_flags", "add_typed_flags", "given"]


class Flag(NamedTuple):
    """One generated option: ``key`` (the flat config key and argparse dest), ``option`` (``--key``), ``kind``
    (argparse type; None: text), ``choices``, ``nargs``, ``boolean`` (a ``--x / --no-x`` switch), ``help``."""

    key: str
    option: str
    kind: Optional[Callable] = None
    choices: Optional[tuple] = None
    nargs: Any = None
    boolean: bool = False
    help: str = ""


def rules_by_key(rules: Mapping[str, Any], fields: Mapping[str, str]) -> dict[str, tuple]:
    """A config's declared rules (``{field path: rule or (rule, ...)}``) by flat key (``fields``: ``{flat key:
    field path}``), each a tuple."""
    inverse = {path: key for key, path in fields.items()}
    return {inverse.get(path, path): rule if isinstance(rule, tuple) else (rule,) for path, rule in rules.items()}


def annotations_of(config, fields: Mapping[str, str]) -> dict[str, str]:
    """``{flat key: the field's annotation as written}`` (``"int"``, ``"Optional[tuple]"``) of a config instance's
    fields (``fields``: ``{flat key: field path}``)."""
    out = {}
    for key, path in fields.items():
        *parts, name = path.split(".")
        part = config
        for p in parts:
            part = getattr(part, p)
        annotation = type(part).__annotations__.get(name, "")
        out[key] = getattr(annotation, "__forward_arg__", annotation if isinstance(annotation, str) else "")
    return out


_ANNOTATED = {"int": int, "float": float, "bool": bool, "str": str}


def _annotated(annotation: str) -> tuple[Optional[type], bool]:
    """``(type, many)`` of an annotation as written: ``"Optional[int]"`` -> ``(int, False)``, ``"tuple"`` ->
    ``(None, True)``; ``(None, False)`` where it says neither."""
    inner = annotation.removeprefix("Optional[").removesuffix("]") if annotation.startswith("Optional[") else annotation
    return _ANNOTATED.get(inner), inner.split("[")[0] in ("tuple", "list")


def _range_text(rules: tuple, flag_of: Callable[[str], str]) -> str:
    """The allowed range of ``rules`` in words (``>= 1``, ``in (0, 1]``, ``<= --attempts``)."""
    parts = [r.text for r in rules if getattr(r, "text", "")]
    parts += [f"<= {flag_of(r.bound)}" for r in rules if getattr(r, "bound", None)]
    return ", ".join(parts)


def derive(key: str, presets: Mapping[str, Mapping], rules: tuple = (), help: str = "",
           flag_of: Callable[[str], str] = common.flag, annotation: str = "",
           phrases: Optional[Mapping[str, str]] = None) -> Flag:
    """The option of flat key ``key``: its type and choices from ``rules`` (the field's declared checks; their
    ``kind`` / ``choices``), else from the field's ``annotation`` (``"Optional[int]"``), else from the presets'
    values (a list or tuple: ``nargs="+"``); its help ``help`` with the allowed range (``{range}`` in ``help``
    places it, else it is appended after a comma; ``{backend}`` and the other ``common.PHRASES``, and the
    command's own ``phrases``, are filled in).
    ``flag_of(key)``: a key's flag (a bound's too)."""
    choices = next((r.choices for r in rules if getattr(r, "choices", None) is not None), None)
    kinds = [r.kind for r in rules if getattr(r, "kind", None) is not None]
    annotated, listed = _annotated(annotation)
    values = [p[key] for p in presets.values() if p.get(key) is not None]
    many = listed or any(isinstance(v, (list, tuple)) for v in values)
    items = [x for v in values for x in (v if isinstance(v, (list, tuple)) else [v])]
    kind = kinds[0] if kinds else annotated or (type(items[0]) if items else str)
    boolean = kind is bool
    text = _range_text(rules, flag_of)
    for name, phrase in {**common.PHRASES, **(phrases or {})}.items():
        help = help.replace(f"{{{name}}}", phrase)
    if "{range}" in help:
        help = help.replace("{range}", text)
    elif text:
        help = f"{help}, {text}"
    return Flag(key, flag_of(key), None if boolean or kind is str else kind,
                None if boolean else choices, "+" if many else None, boolean, help)


def add_flags(parser: argparse.ArgumentParser, presets: Mapping[str, Mapping], rules: Mapping[str, tuple],
              help: Mapping[str, str], argparse_kwargs: Optional[Mapping[str, dict]] = None,
              fields: Optional[Mapping[str, str]] = None, annotations: Optional[Mapping[str, str]] = None,
              phrases: Optional[Mapping[str, str]] = None) -> list[Flag]:
    """Add one option per key of ``help`` (``{flat key: the field's help}``, in that order), each :func:`derive`'d
    from ``presets`` and ``rules`` (``{flat key: (rule, ...)}``, :func:`rules_by_key`), default None;
    ``argparse_kwargs[key]`` replaces what argparse is given (``metavar``, ``nargs``, ``type``) where a flag needs
    more than its field says (``--terrains N|DIR``). ``fields`` (``{flat key: field path}``) names a rule's bound
    (a field path) by its flag; ``annotations`` (:func:`annotations_of`) gives the fields' types. Returns the
    flags made. ``phrases``: the command's own ``{name}`` fill-ins of the help texts (:func:`derive`)."""
    inverse = {path: key for key, path in (fields or {}).items()}
    flag_of = lambda name: common.flag(inverse.get(name, name))  # noqa: E731
    made = []
    for key, text in help.items():
        flag = derive(key, presets, rules.get(key, ()), text, flag_of, (annotations or {}).get(key, ""), phrases)
        kwargs = {"dest": key, "default": None, "help": flag.help}
        if flag.boolean:
            kwargs["action"] = argparse.BooleanOptionalAction
        else:
            kwargs.update({k: v for k, v in (("type", flag.kind), ("choices", flag.choices), ("nargs", flag.nargs))
                           if v is not None})
        kwargs.update((argparse_kwargs or {}).get(key, {}))
        parser.add_argument(flag.option, **kwargs)
        made.append(flag)
    return made


def add_typed_flags(parser: argparse.ArgumentParser, typed, presets: Mapping[str, Mapping], help: Mapping[str, str],
                    argparse_kwargs: Optional[Mapping[str, dict]] = None) -> list[Flag]:
    """:func:`add_flags` for a command whose run is a typed config of the library (``typed``:
    :class:`experiments.common.Typed`): the rules its config declares (``typed.rules``), the fields' annotations
    (of the default config, ``typed.from_flat({})``) and its field table."""
    return add_flags(parser, presets, rules_by_key(typed.rules, typed.fields), help, argparse_kwargs, typed.fields,
                     annotations_of(typed.from_flat({}), typed.fields))


def given(args: argparse.Namespace, keys) -> dict:
    """``{flat key: value}`` of the options ``keys`` as parsed (None: not given)."""
    return {key: getattr(args, key, None) for key in keys}
