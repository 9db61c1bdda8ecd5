"""Terrain generators and their registry.

    >>> from jaxterrain import generators
    >>> generators.names()
    ('cppn', 'diamond_square', 'gan', 'perlin', 'worley')
    >>> gen = generators.get("perlin")           # a Generator (see base.py)

Each module registers a factory ``factory(size=256, **options) -> Generator`` with :func:`register`; ``get`` calls
it. Register your own generator the same way and every experiment command can use it by name.
"""

from __future__ import annotations

import functools
from typing import Callable

from jaxterrain.generators.base import (
    RENDER_CHUNK,
    Generator,
    GenomeSpec,
    check_count,
    check_vector_genomes,
    checked,
    chunked_render,
    gaussian_mutation,
    spec,
    uniform_genomes,
    vector_generator,
)

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
    if name not in _FACTORIES:
        raise ValueError(f"unknown generator {name!r}; choose one of {', '.join(names())}")
    return _cached(name, tuple(sorted(options.items())))


# Built-in generators register themselves on import.
from jaxterrain.generators import cppn, diamond_square, gan, perlin, worley  # noqa: E402,F401

__all__ = [
    "RENDER_CHUNK",
    "Generator",
    "GenomeSpec",
    "check_count",
    "check_vector_genomes",
    "checked",
    "chunked_render",
    "gaussian_mutation",
    "get",
    "names",
    "register",
    "spec",
    "uniform_genomes",
    "vector_generator",
]
