"""Typed run configs: frozen NamedTuples nested where the concepts nest, their flat serialised form (``config.json``),
declared checks of their fields, and their shape as text.

A run config (``qd.run_config.EvolveRun``, ``suite.run_config.EvaluateRun``, ...) is a NamedTuple whose fields are
values or other NamedTuples (its parts); a field is named by its dotted path from the top (``map_elites.bins``).
Its serialised form is a flat dict, ``{key: value}``, whose keys are the command line's flag names (``--`` and
dashes): the config module's ``FLAT_FIELDS`` table, ``{flat key: path}``, is the one mapping between the two
(:func:`to_flat`, :func:`from_flat`), and the command line names a field by its flag through the same table.

Checks are declared as ``{path: rule}`` (:func:`at_least`, :func:`positive`, :func:`one_of`, ...) and run by
:func:`check`, whose messages name each field as ``Owner.path`` (``EvolveRun.map_elites.bins must be an integer >=
1; got 0``); :func:`rename_fields` rewrites those names (the command line: into flags).

    run = schema.from_flat(EvolveRun, {"generations": 4, "bins": 10}, FLAT_FIELDS)
    schema.get(run, "map_elites.bins"), schema.replace(run, {"map_elites.bins": 20})
    schema.check(run, RULES, "EvolveRun")                      # ValueError naming EvolveRun.<path>

This module imports only the standard library, and so do the config modules built on it (they import this one by
``from jaxterrain.runtime.schema import ...``): the command line reads them without importing JAX
(``experiments.common.library_file``), so ``--help`` stays fast.
"""

from __future__ import annotations

import math
import re
from typing import Any, Callable, Iterable, Mapping, Optional

__all__ = ["is_config", "parts", "leaf_paths", "get", "replace", "frozen", "jsonable", "to_flat", "from_flat",
           "Rule", "at_least", "int_in", "positive", "non_negative", "unit", "fraction", "one_of", "at_most", "walks",
           "check", "rename_fields", "FIELD_PATTERN", "shape_lines"]


def is_config(value: Any) -> bool:
    """Whether ``value`` is a config part (a NamedTuple instance)."""
    return isinstance(value, tuple) and hasattr(value, "_fields")


def parts(config) -> dict[str, Any]:
    """``{path: part}`` of every nested part of ``config`` (a NamedTuple-valued field), depth first."""
    out = {}
    for name in config._fields:
        value = getattr(config, name)
        if is_config(value):
            out[name] = value
            out.update({f"{name}.{k}": v for k, v in parts(value).items()})
    return out


def leaf_paths(config) -> tuple[str, ...]:
    """The dotted paths of ``config``'s fields that are values (not parts), in field order."""
    out = []
    for name in config._fields:
        value = getattr(config, name)
        out += [f"{name}.{p}" for p in leaf_paths(value)] if is_config(value) else [name]
    return tuple(out)


def get(config, path: str) -> Any:
    """The value of field ``path`` (``"map_elites.bins"``) of ``config``."""
    for name in path.split("."):
        config = getattr(config, name)
    return config


def replace(config, changes: Mapping[str, Any]):
    """``config`` with the fields of ``changes`` (``{path: value}``) replaced, parts rebuilt with ``_replace``;
    ``ValueError`` for a path that is not a field."""
    own, nested = {}, {}
    for path, value in changes.items():
        head, _, rest = path.partition(".")
        if head not in config._fields:
            raise ValueError(f"{type(config).__name__} has no field {head!r} (of {path!r})")
        if rest:
            nested.setdefault(head, {})[rest] = value
        else:
            own[head] = value
    for head, sub in nested.items():
        own[head] = replace(own.get(head, getattr(config, head)), sub)
    return config._replace(**own)


def frozen(value: Any) -> Any:
    """A JSON value made hashable: lists (nested too) as tuples; dicts are left as they are."""
    if isinstance(value, (list, tuple)):
        return tuple(frozen(v) for v in value)
    return value


def jsonable(value: Any) -> Any:
    """A field's value as JSON writes it: tuples (nested too) as lists."""
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, dict):
        return {k: jsonable(v) for k, v in value.items()}
    return value


Codec = tuple[Callable[[Any], Any], Callable[[Any], Any]]
"""``(encode, decode)`` of a field whose flat form is not its typed one (a tuple of pairs kept as a JSON object)."""


def to_flat(config, table: Mapping[str, str], codecs: Optional[Mapping[str, Codec]] = None,
            omit_none: Iterable[str] = ()) -> dict:
    """The flat, serialised form of ``config``: ``{flat key: value}`` for every key of ``table`` (``{flat key:
    path}``), the values as JSON writes them, through ``codecs[key][0]`` where given. Keys of ``omit_none`` are left
    out when None (``preset`` of a config made without one)."""
    out = {}
    for key, path in table.items():
        value = get(config, path)
        if value is None and key in omit_none:
            continue
        if codecs and key in codecs and value is not None:
            value = codecs[key][0](value)
        out[key] = jsonable(value)
    return out


def from_flat(cls, flat: Mapping[str, Any], table: Mapping[str, str], legacy: Optional[Mapping[str, Any]] = None,
              codecs: Optional[Mapping[str, Codec]] = None, owner: Optional[str] = None,
              ignore: Iterable[str] = ("command",)):
    """The config of class ``cls`` of a flat dict (``config.json``, a preset's flat form, a command line's values):
    every key of ``table`` it holds, its lists as tuples (:func:`frozen`), through ``codecs[key][1]`` where given; a
    key it lacks takes ``legacy``'s value (what the runs written before that key existed ran with), else the
    default. ``ValueError`` naming the keys ``table`` does not know (``ignore``: keys that are no field, such as
    ``command``, the command that wrote it)."""
    owner = owner or cls.__name__
    unknown = sorted(set(flat) - set(table) - set(ignore))
    if unknown:
        raise ValueError(f"{owner}: unknown config keys {unknown}; known: {sorted(table)}")
    legacy = legacy or {}
    changes = {}
    for key, path in table.items():
        if key in flat:
            value = flat[key]
        elif key in legacy:
            value = legacy[key]
        else:
            continue
        if codecs and key in codecs and value is not None:
            value = codecs[key][1](value)
        changes[path] = frozen(value)
    return replace(cls(), changes)


# ----------------------------------------------------------------------------------------------------------------
# Declared checks: a rule is ``rule(value, path, config, name)``, where ``name(path)`` words a field in a message
# ----------------------------------------------------------------------------------------------------------------

Rule = Callable[[Any, str, Any, Callable[[str], str]], None]


def _declared(rule: Rule, kind: Optional[type] = None, text: str = "", choices: Optional[tuple] = None,
              bound: Optional[str] = None) -> Rule:
    """``rule`` with what it allows as attributes, so that a command line can be generated from the declaration
    (``experiments.cli_gen``): ``kind`` (the value's type: int, float, bool, str), ``text`` (the allowed range in
    words, as its message says it: ``">= 1"``, ``"in (0, 1]"``), ``choices`` (the allowed values), ``bound`` (the
    path of the field it is at most)."""
    rule.kind, rule.text, rule.choices, rule.bound = kind, text, choices, bound
    return rule


def _numbers(value) -> list:
    return list(value) if isinstance(value, (list, tuple)) else [value]


def _many(value) -> bool:
    return isinstance(value, (list, tuple))


def at_least(low: int) -> Rule:
    """An integer (or a sequence of them) ``>= low``."""

    def rule(value, path, config, name):
        for v in _numbers(value):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v != int(v) or v < low:
                raise ValueError(f"{name(path)} must be {'integers' if _many(value) else 'an integer'} >= {low}; "
                                 f"got {value!r}")

    return _declared(rule, int, f">= {low}")


def int_in(low: int, high: int) -> Rule:
    """An integer in ``[low, high]``."""

    def rule(value, path, config, name):
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
            raise ValueError(f"{name(path)} must be an integer in [{low}, {high}]; got {value!r}")

    return _declared(rule, int, f"in [{low}, {high}]")


def _real(bound: str, ok: Callable[[float], bool]) -> Rule:
    """A finite number (or a sequence of them) ``bound`` (``"> 0"``) where ``ok``."""

    def rule(value, path, config, name):
        for v in _numbers(value):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not ok(v):
                what = "finite numbers" if _many(value) else "a finite number"
                raise ValueError(f"{name(path)} must be {what} {bound}; got {value!r}")

    return _declared(rule, float, bound)


def positive() -> Rule:
    """A finite number (or a sequence of them) ``> 0``."""
    return _real("> 0", lambda v: v > 0)


def non_negative() -> Rule:
    """A finite number (or a sequence of them) ``>= 0``."""
    return _real(">= 0", lambda v: v >= 0)


def _interval(text: str, ok: Callable[[float], bool]) -> Rule:
    def rule(value, path, config, name):
        for v in _numbers(value):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not ok(v):
                raise ValueError(f"{name(path)} must be a number in {text}; got {value!r}")

    return _declared(rule, float, f"in {text}")


def unit() -> Rule:
    """A number in (0, 1]."""
    return _interval("(0, 1]", lambda v: 0.0 < v <= 1.0)


def fraction() -> Rule:
    """A number in [0, 1]."""
    return _interval("[0, 1]", lambda v: 0.0 <= v <= 1.0)


def one_of(options: Iterable[Any]) -> Rule:
    """One of ``options``."""
    options = tuple(options)

    def rule(value, path, config, name):
        if isinstance(value, bool) != any(isinstance(o, bool) for o in options) or value not in options:
            raise ValueError(f"{name(path)} must be one of {', '.join(map(str, options))}; got {value!r}")

    kinds = {type(o) for o in options}
    return _declared(rule, kinds.pop() if len(kinds) == 1 else None, choices=options)


def at_most(bound: str) -> Rule:
    """At most the value of field ``bound`` (each of a sequence), where both are integers."""

    def rule(value, path, config, name):
        b = get(config, bound)
        for v in _numbers(value):
            if isinstance(v, int) and isinstance(b, int) and not isinstance(v, bool) and v > b:
                raise ValueError(f"{name(path)} must be <= {name(bound)} ({b}); got {value}")

    return _declared(rule, int, bound=bound)


def walks(attempts: str, best: str) -> Rule:
    """The rule of a walker protocol's ``headings`` field: 1, 2 or 4, the walks in total (field ``attempts``) a
    multiple of it, the best walks averaged per heading (field ``best``) at most ``attempts / headings``."""

    def rule(heads, path, config, name):
        n, b = get(config, attempts), get(config, best)
        if isinstance(heads, bool) or heads not in (1, 2, 4):
            raise ValueError(f"{name(path)} must be 1, 2 or 4; got {heads!r}")
        if isinstance(n, int) and n % heads:
            raise ValueError(f"{name(attempts)} must be a multiple of {name(path)} ({heads}); got {n}")
        if isinstance(n, int) and isinstance(b, int) and b > n // heads:
            raise ValueError(f"{name(best)} must be <= {name(attempts)} / {name(path)} ({n // heads}); got {b}")

    return _declared(rule, int, choices=(1, 2, 4))


def check(config, rules: Mapping[str, Rule | tuple], owner: str) -> None:
    """Run ``rules`` (``{path: rule or (rule, ...)}``, in order) on ``config``'s fields; a None value passes.
    ``ValueError`` naming the field as ``owner.path``."""
    name = lambda path: f"{owner}.{path}"  # noqa: E731
    for path, rule in rules.items():
        value = get(config, path)
        if value is not None:
            for one in rule if isinstance(rule, tuple) else (rule,):
                one(value, path, config, name)


FIELD_PATTERN = r"\b{owner}\.([a-z_][a-z0-9_]*(?:\.[a-z_][a-z0-9_]*)*)"
"""The regular expression of a field named in a message, ``Owner.path`` (``{owner}`` is the config's name)."""


def rename_fields(text: str, owner: str, rename: Callable[[str], str]) -> str:
    """``text`` with every ``owner.path`` replaced by ``rename(path)`` (the command line: the field's flag)."""
    return re.sub(FIELD_PATTERN.format(owner=re.escape(owner)), lambda m: rename(m.group(1)), text)


def shape_lines(config, owner: str, table: Mapping[str, str], consumers: Mapping[str, str]) -> list[str]:
    """The shape of ``config`` (an instance; its defaults) as text: one line per part and field, indented by depth,
    with the field's flat key (``config.json``'s and the flag's name; ``-`` for none) and where it is consumed
    (``consumers[path]``, or the nearest part's entry above it)."""
    flat = {path: key for key, path in table.items()}
    rows = [(owner, "", consumers.get("", ""))]

    def walk(part, prefix: str, depth: int) -> None:
        for field in part._fields:
            path = f"{prefix}{field}"
            value = getattr(part, field)
            indent = "  " * depth
            if is_config(value):
                rows.append((f"{indent}{field}: {type(value).__name__}", "", consumers.get(path, "")))
                walk(value, path + ".", depth + 1)
            else:
                rows.append((f"{indent}{field}", flat.get(path, "-"), consumers.get(path, "")))

    walk(config, "", 1)
    width = max(len(r[0]) for r in rows) + 2
    key_width = max(len(r[1]) for r in rows) + 2
    return [f"{r[0]:<{width}}{r[1]:<{key_width}}{r[2]}".rstrip() for r in rows]
