"""Typed run configs (``jaxterrain.runtime.schema``): nested paths, the flat serialised form, declared checks whose
messages name the field, and the shape as text. Standard library only: nothing here imports JAX."""

from __future__ import annotations

from typing import NamedTuple, Optional

import pytest

from jaxterrain.runtime import schema


class Inner(NamedTuple):
    bins: int = 50
    names: tuple = ("a", "b")


class Outer(NamedTuple):
    size: int = 256
    inner: Inner = Inner()
    attempts: int = 20
    best: int = 5
    headings: int = 1
    preset: Optional[str] = None


TABLE = {"size": "size", "bins": "inner.bins", "names": "inner.names", "attempts": "attempts", "best": "best",
         "headings": "headings", "preset": "preset"}


def test_paths_get_and_replace_reach_nested_fields():
    config = Outer()
    assert schema.leaf_paths(config) == ("size", "inner.bins", "inner.names", "attempts", "best", "headings", "preset")
    assert schema.parts(config) == {"inner": Inner()}
    changed = schema.replace(config, {"inner.bins": 10, "size": 32})
    assert (changed.size, changed.inner.bins, changed.inner.names) == (32, 10, ("a", "b"))
    assert schema.get(changed, "inner.bins") == 10 and config.inner.bins == 50  # frozen: a new config
    with pytest.raises(ValueError, match="Inner has no field 'bin'"):
        schema.replace(config, {"inner.bin": 1})


def test_the_flat_form_round_trips_and_reads_older_files():
    config = schema.replace(Outer(), {"inner.names": ("x", "y"), "preset": "smoke"})
    flat = schema.to_flat(config, TABLE)
    assert flat["names"] == ["x", "y"] and flat["bins"] == 50  # JSON's lists; flat keys, not paths
    assert schema.from_flat(Outer, flat, TABLE) == config
    assert schema.from_flat(Outer, {**flat, "command": "evolve"}, TABLE) == config  # who wrote it is no field
    old = {k: v for k, v in flat.items() if k != "headings"}  # a file written before the key existed
    assert schema.from_flat(Outer, old, TABLE, legacy={"headings": 4}).headings == 4
    assert schema.from_flat(Outer, old, TABLE).headings == 1  # else the default
    assert "preset" not in schema.to_flat(Outer(), TABLE, omit_none=("preset",))
    with pytest.raises(ValueError, match=r"Outer: unknown config keys \['bogus'\]"):
        schema.from_flat(Outer, {**flat, "bogus": 1}, TABLE)


def test_checks_name_the_field_and_say_what_it_allows():
    rules = {"size": schema.at_least(1), "inner.bins": (schema.at_least(1), schema.at_most("size")),
             "best": (schema.at_least(1), schema.at_most("attempts")), "headings": schema.walks("attempts", "best")}
    schema.check(Outer(), rules, "Outer")
    cases = [({"size": 0}, "Outer.size must be an integer >= 1; got 0"),
             ({"size": 1.5}, "Outer.size must be an integer >= 1; got 1.5"),
             ({"inner.bins": 300}, "Outer.inner.bins must be <= Outer.size (256); got 300"),
             ({"best": 30}, "Outer.best must be <= Outer.attempts (20); got 30"),
             ({"headings": 3}, "Outer.headings must be 1, 2 or 4; got 3"),
             ({"headings": 4, "attempts": 10, "best": 2}, "Outer.attempts must be a multiple of Outer.headings (4); "
                                                          "got 10"),
             ({"headings": 4, "best": 6}, "Outer.best must be <= Outer.attempts / Outer.headings (5); got 6")]
    for changes, message in cases:
        with pytest.raises(ValueError) as err:
            schema.check(schema.replace(Outer(), changes), rules, "Outer")
        assert str(err.value) == message
    for rule, value, message in ((schema.positive(), 0.0, "must be a finite number > 0; got 0.0"),
                                 (schema.non_negative(), -1.0, "must be a finite number >= 0; got -1.0"),
                                 (schema.unit(), 1.5, "must be a number in (0, 1]; got 1.5"),
                                 (schema.fraction(), -0.1, "must be a number in [0, 1]; got -0.1"),
                                 (schema.one_of(("jax", "warp")), "cuda", "must be one of jax, warp; got 'cuda'"),
                                 (schema.one_of((1, 2)), True, "must be one of 1, 2; got True"),
                                 (schema.int_in(16, 4096), 8, "must be an integer in [16, 4096]; got 8")):
        with pytest.raises(ValueError) as err:
            schema.check(Outer(size=value), {"size": rule}, "Outer")
        assert str(err.value) == f"Outer.size {message}"


def test_fields_are_renamed_and_the_shape_is_printed():
    text = "Outer.inner.bins must be <= Outer.size (256); got 300"
    assert schema.rename_fields(text, "Outer", lambda p: f"--{p.rsplit('.', 1)[-1]}") == \
        "--bins must be <= --size (256); got 300"
    lines = schema.shape_lines(Outer(), "Outer", TABLE, {"": "make", "inner": "inner_of", "size": "size_of"})
    assert lines[0].split() == ["Outer", "make"] and lines[1].split() == ["size", "size", "size_of"]
    assert lines[2].split() == ["inner:", "Inner", "inner_of"] and lines[3].split() == ["bins", "bins"]
    assert lines[3].startswith("    bins")  # a part's fields one level deeper
