"""A mixture of generators as ONE generator: the genome of one MAP-Elites run whose offspring of every generator
compete for the same cells (the paper's future work; issue 64, item 3).

    >>> from jaxterrain import generators, qd
    >>> mix = generators.mixture(("perlin", "worley", "cppn"), fresh=1, size=256)
    >>> genomes = mix.sample(key, 6)          # MixedGenome: generator [6] int32 (0 0 1 1 2 2), slots (perlin, ...)
    >>> maps = mix.render(genomes)            # [6, 256, 256], each row by its own generator
    >>> arch = qd.evolve(mix, None, config, key)   # an Archive whose elites record their generator

Genome
------
A :class:`MixedGenome` holds, per row, the slot of EVERY component generator (``slots[k]``: generator ``k``'s genome
pytree, leaves ``[B, ...]``) and ``generator`` [B] int32, the slot that IS the terrain. The other slots are carried
along (they are valid genomes of their generators, mutated with the row) and never rendered; a host archive keeps
only the active slot (``qd.to_archive`` zeroes the others, as ``qd.combine`` does). So MAP-Elites' insertion
(``qd.map_elites.insert``: one winner per cell, every leaf from that winner) moves the generator id with the genome:
a fitter offspring of another generator replaces a cell's elite and the cell records its generator.

Operators
---------
* ``sample(key, n)``: every generator samples all ``n`` rows of its slot; row ``i`` is generator ``i * K // n`` (equal
  blocks in component order, so ``n = K m`` gives ``m`` of each).
* ``mutate(key, genomes)``: every slot of every row is mutated by its own generator (the active one is the child;
  the others cost a mutation each, which is small beside a render); the generator id is the parent's. Then the LAST
  ``fresh * K`` rows are replaced by fresh samples, ``fresh`` of each generator (block order), so that a generator
  that holds no cell keeps entering offspring. MAP-Elites draws the parents uniformly over the filled cells, so a
  generator's share of the mutated offspring is its share of the archive.
* ``render`` (batched, used by the scoring): rows grouped by generator (a stable sort), each group padded to whole
  chunks of ``render_chunk`` rows and rendered chunk by chunk (``lax.map`` over chunks, ``lax.switch`` on the
  chunk's generator, ``vmap`` within it), so each row is rendered once by its own generator, plus at most
  ``K * (render_chunk - 1)`` padding rows; static shapes, any batch. ``render_one``: one genome by
  ``lax.switch``.

Every component renders the same ``size``; the mixture's ``name`` is ``mixed(<names>;fresh=<fresh>)`` (a checkpoint
of another mixture is refused on resume).
"""

from __future__ import annotations

import functools
from typing import NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain.generators import registry
from jaxterrain.generators.base import Generator, check_count

__all__ = ["MixedGenome", "MixtureSpec", "DEFAULT_RENDER_CHUNK", "mixture", "is_mixture", "render_grouped",
           "check_batch", "archive_slots"]

DEFAULT_RENDER_CHUNK = 64
"""Rows per rendered chunk of a mixture's batched render (each chunk one generator)."""


class MixedGenome(NamedTuple):
    """Genomes of a mixture (leaves with a leading batch axis ``B``).

    Attributes:
      generator: [B] int32, which component generator's slot is the terrain (index into ``MixtureSpec.names``).
      slots: tuple with one genome pytree per component generator, leaves ``[B, ...]``.
    """

    generator: jax.Array
    slots: tuple


class MixtureSpec(NamedTuple):
    """The ``spec`` of a mixture :class:`~jaxterrain.generators.base.Generator`.

    Attributes:
      names: the component generators' names (a :class:`MixedGenome`'s ``generator`` indexes them).
      generators: the component ``Generator`` s.
      fresh: fresh samples of EACH generator among every mutated batch (its last ``fresh * K`` rows).
      render_chunk: rows per chunk of the batched render.
      render_batch: ``genomes [B] -> [B, H, W]``, unchecked (:func:`render_grouped`), for use inside ``jit``.
    """

    names: tuple
    generators: tuple
    fresh: int
    render_chunk: int
    render_batch: object


def is_mixture(generator) -> bool:
    """True for a generator made by :func:`mixture`."""
    return isinstance(getattr(generator, "spec", None), MixtureSpec)


def check_batch(generator, batch_size: int, what: str = "batch_size") -> None:
    """``ValueError`` naming ``what`` unless a mixture's batches of ``batch_size`` leave room for mutated offspring
    beside its fresh samples (``batch_size > fresh * K``)."""
    need = generator.spec.fresh * len(generator.spec.names)
    if batch_size <= need:
        raise ValueError(f"{what} must be > {need} for {generator.name} (its fresh samples: {generator.spec.fresh} "
                         f"of each of {len(generator.spec.names)} generators); got {batch_size}")


def archive_slots(genomes: MixedGenome, filled: np.ndarray) -> tuple[np.ndarray, tuple]:
    """Host form of a repertoire's mixed genomes (leaves ``[cells, ...]``): ``(source [cells] int32, slots)``, the
    generator of each filled cell (-1 where empty) and each generator's slot with zeros where it does not hold the
    cell (the form of ``qd.combine``'s archives)."""
    source = np.where(np.asarray(filled), np.asarray(genomes.generator, np.int32), -1).astype(np.int32)

    def keep(x, k):
        x = np.asarray(x)
        return np.where((source == k).reshape(source.shape + (1,) * (x.ndim - 1)), x, np.zeros_like(x))

    return source, tuple(jax.tree.map(lambda x, k=k: keep(x, k), slot) for k, slot in enumerate(genomes.slots))


def render_grouped(gens: Sequence[Generator], genomes: MixedGenome, chunk: int = DEFAULT_RENDER_CHUNK) -> jax.Array:
    """``[B, H, W]`` float32: each row of ``genomes`` rendered once by its own generator (rows grouped by generator,
    each group padded to whole chunks of ``min(chunk, B)`` rows; see the module docstring). Traceable."""
    ids = jnp.asarray(genomes.generator, jnp.int32)
    b, k = ids.shape[0], len(gens)
    c = max(1, min(int(chunk), b))
    n_chunks = -(-(b + k * (c - 1)) // c)  # static: enough for every group padded to whole chunks
    order = jnp.argsort(ids, stable=True)  # rows grouped by generator
    counts = jnp.bincount(ids, length=k)
    starts = jnp.cumsum(counts) - counts  # first sorted row of each generator
    padded = -(-counts // c) * c
    ends = jnp.cumsum(padded)  # end of each generator's region in the padded layout
    sorted_ids = ids[order]
    pos = (ends - padded)[sorted_ids] + jnp.arange(b) - starts[sorted_ids]  # padded slot of each sorted row
    chunk_start = jnp.arange(n_chunks) * c
    chunk_gen = jnp.sum(chunk_start[:, None] >= ends[None, :], axis=1)  # K: past every region (skipped)
    slot_gen = jnp.repeat(jnp.minimum(chunk_gen, k - 1), c)
    src = order[jnp.minimum(starts[slot_gen], b - 1)]  # padding renders a row of its own generator
    src = src.at[pos].set(order).reshape(n_chunks, c)
    size = gens[0].size

    def branch(g, slot):
        def render(rows):
            return jax.vmap(g.render_one)(jax.tree.map(lambda x: x[rows], slot)).astype(jnp.float32)

        return render

    branches = [branch(g, s) for g, s in zip(gens, genomes.slots)]
    branches.append(lambda rows: jnp.zeros((c, size, size), jnp.float32))
    maps = jax.lax.map(lambda a: jax.lax.switch(a[0], branches, a[1]), (chunk_gen, src))
    maps = maps.reshape((n_chunks * c, size, size))
    where = jnp.zeros((b,), jnp.int32).at[order].set(pos.astype(jnp.int32))  # padded slot of each row
    return maps[where]


def mixture(components: Sequence[str | Generator], fresh: int = 1, size: int | None = None,
            render_chunk: int = DEFAULT_RENDER_CHUNK) -> Generator:
    """One generator whose genomes may be any of ``components``' (module docstring).

    Args:
      components: two or more distinct generator names (``generators.get(name, size=size)``) or ``Generator`` s,
        all rendering one size.
      fresh: fresh samples of each generator in every mutated batch (>= 0); a batch must hold more than
        ``fresh * len(components)`` rows (``qd.evolve`` checks it against ``EvolveConfig.batch_size``).
      size: heightmap side for components given by name (None: each generator's default).
      render_chunk: rows per chunk of the batched render (>= 1).

    Returns:
      a ``Generator`` named ``mixed(<names>;fresh=<fresh>)`` whose ``spec`` is a :class:`MixtureSpec`; built once
      per arguments when every component is given by name.
    """
    if isinstance(components, str) or not isinstance(components, (list, tuple)) or len(components) < 2:
        raise ValueError(f"mixture: components must be two or more generator names; got {components!r}")
    fresh = int(fresh) if isinstance(fresh, (int, np.integer)) and not isinstance(fresh, bool) else fresh
    if not isinstance(fresh, int) or fresh < 0:
        raise ValueError(f"mixture: fresh must be an integer >= 0 (fresh samples per generator); got {fresh!r}")
    check_count(render_chunk, "mixture", "render_chunk")
    if all(isinstance(c, str) for c in components):
        return _named(tuple(components), fresh, size, int(render_chunk))
    gens = tuple(registry.get(c, **({} if size is None else {"size": size})) if isinstance(c, str) else c
                 for c in components)
    return _build(gens, fresh, int(render_chunk))


@functools.lru_cache(maxsize=32)
def _named(names: tuple, fresh: int, size, render_chunk: int) -> Generator:
    return _build(tuple(registry.get(n, **({} if size is None else {"size": size})) for n in names), fresh,
                  render_chunk)


def _build(gens: tuple, fresh: int, render_chunk: int) -> Generator:
    names = tuple(g.name for g in gens)
    if len(set(names)) != len(names):
        raise ValueError(f"mixture: components must be distinct generators; got {list(names)}")
    sizes = {g.size for g in gens}
    if len(sizes) != 1:
        raise ValueError(f"mixture: every component must render one size; got "
                         f"{dict(zip(names, (g.size for g in gens)))}")
    k = len(gens)

    def sample(key, n):
        n = check_count(n, "mixture.sample")
        keys = jax.random.split(key, k)
        slots = tuple(g.sample(kk, n) for g, kk in zip(gens, keys))
        return MixedGenome((jnp.arange(n, dtype=jnp.int32) * k) // n, slots)

    def mutate(key, genomes):
        b = genomes.generator.shape[0]
        keys = jax.random.split(key, k + 1)
        slots = tuple(g.mutate(kk, s) for g, kk, s in zip(gens, keys, genomes.slots))
        out = MixedGenome(jnp.asarray(genomes.generator, jnp.int32), slots)
        n_fresh = min(fresh * k, b)
        if n_fresh == 0:
            return out
        new = sample(keys[k], n_fresh)
        return jax.tree.map(lambda o, f: o.at[b - n_fresh:].set(f.astype(o.dtype)), out, new)

    def render_batch(genomes):
        return render_grouped(gens, genomes, render_chunk)

    def render_one(genome):
        branches = [lambda slots, i=i, g=g: g.render_one(slots[i]).astype(jnp.float32) for i, g in enumerate(gens)]
        return jax.lax.switch(jnp.clip(jnp.asarray(genome.generator, jnp.int32), 0, k - 1), branches, genome.slots)

    def validate(genomes):
        if not isinstance(genomes, MixedGenome) or len(genomes.slots) != k:
            raise ValueError(f"mixture: genomes must be a MixedGenome with {k} slots ({', '.join(names)})")
        ids = np.asarray(genomes.generator)
        if ids.ndim != 1 or np.any(ids < 0) or np.any(ids >= k):
            raise ValueError(f"mixture: genomes.generator must be [B] ids in [0, {k - 1}]; got {ids}")
        for i, g in enumerate(gens):
            rows = np.flatnonzero(ids == i)
            if rows.size:
                g.validate(jax.tree.map(lambda x: np.asarray(x)[rows], genomes.slots[i]))

    compiled = jax.jit(render_batch)

    def render(genomes):
        if not any(isinstance(x, jax.core.Tracer) for x in jax.tree.leaves(genomes)):
            validate(genomes)
        return compiled(genomes)

    spec = MixtureSpec(names, gens, fresh, render_chunk, render_batch)
    return Generator(f"mixed({','.join(names)};fresh={fresh})", spec, gens[0].size, sample, mutate, render,
                     render_one, validate)
