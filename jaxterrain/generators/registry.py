"""The generator registry: names -> factories ``factory(size=256, **options) -> Generator``."""

from __future__ import annotations

import functools
import inspect
import numbers
from typing import Callable

from jaxterrain.generators.base import Generator, checked

__all__ = ["register", "names", "get"]

_FACTORIES: dict[str, Callable[..., Generator]] = {}


def register(name: str) -> Callable[[Callable[..., Generator]], Callable[..., Generator]]:
    """Decorator that registers a generator factory under ``name``."""

    def wrap(factory: Callable[..., Generator]) -> Callable[..., Generator]:
        if name in _FACTORIES:
            raise ValueError(f"a generator named {name!r} is already registered")
        _FACTORIES[name] = factory
        return factory

    return wrap


def names() -> tuple[str, ...]:
    """The registered generator names, sorted."""
    return tuple(sorted(_FACTORIES))


@functools.lru_cache(maxsize=None)
def _cached(name: str, options: tuple) -> Generator:
    return checked(_FACTORIES[name](**dict(options)))


def get(name: str, **options) -> Generator:
    """The generator registered as ``name``, built with ``options`` (e.g. ``size=64``); cached per options.

    Its ``sample`` rejects a count that is not an integer >= 1 and its ``mutate`` checks concrete genomes (as
    ``validate`` does), also for a factory that does not check them itself (:func:`base.checked`)."""
    if not isinstance(name, str):
        raise ValueError(f"generators.get: name must be a generator name (a str, one of {', '.join(names())}); got "
                         f"{name!r}")
    if name not in _FACTORIES:
        raise ValueError(f"unknown generator {name!r}; choose one of {', '.join(names())}")
    size = options.get("size", 1)
    if not isinstance(size, numbers.Integral) or isinstance(size, bool) or size < 1:
        raise ValueError(f"generators.get({name!r}): size must be an integer >= 1 (pixels); got {size!r}")
    params = inspect.signature(_FACTORIES[name]).parameters
    if not any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
        unknown = sorted(set(options) - set(params))
        if unknown:
            raise ValueError(f"generators.get({name!r}): unknown option(s) {unknown}; {name} takes "
                             f"{', '.join(params) or 'no options'}")
    key = tuple(sorted(options.items()))
    try:
        hash(key)
    except TypeError:
        raise ValueError(f"generators.get({name!r}): option values must be hashable (generators are cached per "
                         f"options); got {options!r}") from None
    return _cached(name, key)
