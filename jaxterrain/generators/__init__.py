"""Terrain generators and their registry.

    >>> from jaxterrain import generators
    >>> generators.names()
    ('cppn', 'diamond_square', 'gan', 'perlin', 'steps', 'worley')
    >>> gen = generators.get("perlin")           # a Generator (see base.py)

Each module registers a factory ``factory(size=256, **options) -> Generator`` with :func:`register`; ``get`` calls
it. Register your own generator the same way and every experiment command can use it by name once your module
is imported (``python -m experiments --plugin MODULE ...``, or a ``jaxterrain.plugins`` entry point).

:func:`mixture` makes one generator of several (:mod:`~jaxterrain.generators.mixed`): the genome of a MAP-Elites
run whose offspring of every generator compete for one archive (``evolve --generator mixed``).
"""

from __future__ import annotations

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

# Built-in generators register themselves on import.
from jaxterrain.generators import cppn, diamond_square, gan, perlin, steps, worley  # noqa: E402,F401
from jaxterrain.generators.registry import get, names, register  # noqa: E402
from jaxterrain.generators.mixed import MixedGenome, MixtureSpec, is_mixture, mixture  # noqa: E402

BUILTIN = ("perlin", "worley", "diamond_square", "cppn", "gan", "steps")
"""The six built-in generators, in the order a mixture of all of them (``evolve --generator mixed``) takes them."""

__all__ = [
    "BUILTIN",
    "MixedGenome",
    "MixtureSpec",
    "is_mixture",
    "mixture",
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
