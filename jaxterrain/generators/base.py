"""The interface shared by every terrain generator.

A generator is an immutable bundle of pure functions (the optax / evosax shape)::

    gen = jaxterrain.generators.get("perlin")
    genomes = gen.sample(key, 8)                 # [8, G] float32
    children = gen.mutate(key, genomes)          # [8, G] float32, same bounds
    maps = gen.render(genomes)                   # [8, 256, 256] float32 in [0, 1]

``render`` and ``mutate`` check concrete genomes on the host (shape, NaN / inf, gene ranges) and raise a
``ValueError`` that names the gene (or genome field) and its range; under ``jit`` / ``vmap`` / ``scan`` (traced
values) they skip the value checks and only compute. ``sample(key, n)`` raises a ``ValueError`` naming ``n`` unless it
is an integer >= 1. ``render_one`` is the raw, unchecked ``genome -> [H, W]`` function for use inside your own
transformations.

Memory: ``render`` evaluates batches larger than the generator's render chunk (:data:`RENDER_CHUNK` maps, less for
generators with large per-map temporaries) as ``lax.map`` over chunks of that many maps, so its temporary memory is
that of one chunk at any batch size, and only the ``[B, H, W]`` output grows with the batch.

Vector genomes (Perlin, diamond-square, Worley, GAN) are float32 arrays ``[B, G]`` described by a
:class:`GenomeSpec`; integer genes are stored as whole floats. Genomes of other generators (CPPN) are pytrees whose
leaves have a leading batch axis; they bring their own ``sample`` / ``mutate`` / ``validate``.
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import operator

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["Genome", "PRNGKey", "RENDER_CHUNK", "GenomeSpec", "spec", "Generator", "is_traced", "check_count",
           "check_key", "chunked_render", "mark_checked", "checked", "uniform_genomes", "gaussian_mutation",
           "check_vector_genomes", "vector_generator", "mix32"]

Genome = Any  # an array [B, G] or a pytree of arrays with leading axis B
PRNGKey = jax.Array

RENDER_CHUNK = 1024
"""Maps rendered per step of ``render``'s ``lax.map`` (the archive's chunk too): bounds render's temporaries."""


class GenomeSpec(NamedTuple):
    """Names and closed ranges of the genes of a vector genome. Static (hashable) data."""

    names: tuple[str, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    integer: tuple[bool, ...]

    @property
    def size(self) -> int:
        return len(self.names)

    @property
    def lower_array(self) -> jax.Array:
        return jnp.asarray(self.lower, jnp.float32)

    @property
    def upper_array(self) -> jax.Array:
        return jnp.asarray(self.upper, jnp.float32)

    @property
    def integer_array(self) -> jax.Array:
        return jnp.asarray(self.integer, bool)

    def index(self, name: str) -> int:
        return self.names.index(name)


def spec(*genes: tuple[str, float, float, bool]) -> GenomeSpec:
    """Build a :class:`GenomeSpec` from ``(name, lower, upper, is_integer)`` tuples."""
    names, lower, upper, integer = zip(*genes)
    return GenomeSpec(tuple(names), tuple(map(float, lower)), tuple(map(float, upper)), tuple(map(bool, integer)))


class Generator(NamedTuple):
    """A terrain generator: a genome spec and pure functions over batches of genomes.

    Attributes:
      name: registry name.
      spec: the genome description (:class:`GenomeSpec` for vector genomes).
      size: side of the square heightmap, in pixels.
      sample: ``(key, n) -> genomes[n, ...]``, random valid genomes.
      mutate: ``(key, genomes[B, ...]) -> genomes[B, ...]``, the paper's mutation operator.
      render: ``genomes[B, ...] -> heightmaps[B, size, size]`` float32 in [0, 1]; checks concrete input.
        A single unbatched genome gives a single ``[size, size]`` map.
      render_one: ``genome -> heightmap[size, size]``, unchecked, for use inside jit / vmap / scan.
      validate: ``genomes -> None``; raises ``ValueError`` naming the offending gene and its allowed range.
    """

    name: str
    spec: Any
    size: int
    sample: Callable[[PRNGKey, int], Genome]
    mutate: Callable[[PRNGKey, Genome], Genome]
    render: Callable[[Genome], jax.Array]
    render_one: Callable[[Genome], jax.Array]
    validate: Callable[[Genome], None]


def is_traced(tree: Any) -> bool:
    """True when any leaf of ``tree`` is an abstract tracer (inside jit / vmap / grad)."""
    return any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(tree))


def check_count(n: Any, name: str, what: str = "n") -> int:
    """``n`` as a Python int >= 1, or ``ValueError`` naming ``what`` (sample sizes: ints, numpy ints; no bool or
    float)."""
    try:
        if isinstance(n, (bool, np.bool_)):
            raise TypeError
        value = operator.index(n)
    except TypeError:
        raise ValueError(f"{name}: {what} is {n!r} ({type(n).__name__}); it must be an integer >= 1") from None
    if value < 1:
        raise ValueError(f"{name}: {what} is {value}; it must be an integer >= 1")
    return value


def check_key(key: Any, name: str) -> None:
    """``key`` must be one JAX PRNG key: a typed key ``jax.random.key(seed)`` of shape ``[]``, or a raw ``uint32``
    key ``jax.random.PRNGKey(seed)`` (``[2]``; ``[4]`` for the rbg implementations); ``ValueError`` naming ``key``
    otherwise. Only the (static) dtype and shape are read, so traced keys are checked too."""
    dtype, shape = getattr(key, "dtype", None), getattr(key, "shape", None)
    if dtype is not None and shape is not None:
        if jax.dtypes.issubdtype(dtype, jax.dtypes.prng_key):
            if tuple(shape) == ():
                return
        elif np.dtype(dtype) == np.uint32 and tuple(shape) in ((2,), (4,)):
            return
    what = f"shape {tuple(shape)}, dtype {dtype}" if dtype is not None and shape is not None else repr(key)
    raise ValueError(f"{name}: key must be one JAX PRNG key (jax.random.key(seed)); got {what}")


def chunked_render(render_one: Callable[[Genome], jax.Array], chunk: int = RENDER_CHUNK) -> Callable[[Genome], jax.Array]:
    """``jit`` of ``genomes[B, ...] -> maps[B, H, W]``: ``vmap(render_one)`` for ``B <= chunk``, else ``lax.map`` over
    chunks of ``chunk`` genomes (the last, partial chunk vmapped on its own), so the temporaries are those of one
    chunk whatever ``B``. Genomes may be a pytree with leading axis ``B``."""
    chunk = check_count(chunk, "render", "chunk")

    def render_batch(genomes: Genome) -> jax.Array:
        b = jax.tree_util.tree_leaves(genomes)[0].shape[0]
        if b <= chunk:
            return jax.vmap(render_one)(genomes)
        return jax.lax.map(render_one, genomes, batch_size=chunk)

    return jax.jit(render_batch)


def mark_checked(fn: Callable) -> Callable:
    fn.__jaxterrain_checked__ = True
    return fn


def checked(gen: "Generator") -> "Generator":
    """``gen`` with its public ``sample`` / ``mutate`` checking their input when they do not already (the registry
    applies this to every generator it builds, so a factory that swaps in its own ``sample`` is covered too)."""
    sample, mutate = gen.sample, gen.mutate
    if not getattr(sample, "__jaxterrain_checked__", False):
        @mark_checked
        def sample(key: PRNGKey, n: int, _sample=gen.sample, _name=gen.name):
            n = check_count(n, _name)
            check_key(key, _name)
            return _sample(key, n)

    if not getattr(mutate, "__jaxterrain_checked__", False):
        @mark_checked
        def mutate(key: PRNGKey, genomes: Genome, _mutate=gen.mutate, _validate=gen.validate, _name=gen.name):
            check_key(key, _name)
            if not is_traced(genomes):
                _validate(genomes)
            return _mutate(key, genomes)

    return gen._replace(sample=sample, mutate=mutate)


# ----------------------------------------------------------------------------------------------------------------
# Vector genomes
# ----------------------------------------------------------------------------------------------------------------


def uniform_genomes(key: PRNGKey, n: int, gspec: GenomeSpec) -> jax.Array:
    """``n`` genomes drawn uniformly in the spec's ranges; integer genes uniform over their integers. [n, G]."""
    lo, hi, is_int = gspec.lower_array, gspec.upper_array, gspec.integer_array
    u = jax.random.uniform(key, (n, gspec.size), jnp.float32)
    cont = lo + u * (hi - lo)
    ints = jnp.clip(jnp.floor(lo + u * (hi - lo + 1.0)), lo, hi)
    return jnp.where(is_int, ints, cont)


def gaussian_mutation(
    key: PRNGKey, genomes: jax.Array, gspec: GenomeSpec, prob: float = 0.35, sigma: float = 0.1
) -> jax.Array:
    """The paper's operator: each gene, with probability ``prob``, moves by N(0, (sigma * range)^2).

    The result is clipped to the gene's range and integer genes are rounded. ``genomes`` is [B, G] (or [G]).
    """
    lo, hi, is_int = gspec.lower_array, gspec.upper_array, gspec.integer_array
    mask_key, noise_key = jax.random.split(key)
    mask = jax.random.bernoulli(mask_key, prob, genomes.shape)
    noise = jax.random.normal(noise_key, genomes.shape, genomes.dtype) * sigma * (hi - lo)
    out = jnp.clip(genomes + jnp.where(mask, noise, 0.0), lo, hi)
    return jnp.where(is_int, jnp.round(out), out)


def check_vector_genomes(genomes: Any, gspec: GenomeSpec, name: str) -> np.ndarray:
    """Host-side checks of concrete vector genomes; returns them as a float64 numpy array [B, G].

    Raises ``ValueError`` for a wrong shape, a non-finite gene, a gene out of its range or a fractional
    integer gene, naming the gene, the genome index and the allowed range.
    """
    try:
        raw = np.asarray(genomes)
    except (TypeError, ValueError) as err:  # ragged nesting, unconvertible objects
        raise ValueError(f"{name}: genomes must be a float array [B, {gspec.size}]; got {type(genomes).__name__} "
                         f"({err})") from None
    if raw.dtype.kind not in "iuf":
        raise ValueError(f"{name}: genomes must be a real-valued array (float32) [B, {gspec.size}]; got dtype "
                         f"{raw.dtype}")
    g = raw.astype(np.float64)
    if g.ndim not in (1, 2) or g.shape[-1] != gspec.size:
        raise ValueError(
            f"{name}: genomes must have shape [B, {gspec.size}] or [{gspec.size}] "
            f"(genes {', '.join(gspec.names)}); got shape {tuple(g.shape)}"
        )
    g2 = g.reshape(-1, gspec.size)
    for j, gene in enumerate(gspec.names):
        col = g2[:, j]
        lo, hi = gspec.lower[j], gspec.upper[j]
        bad = ~np.isfinite(col)
        if bad.any():
            i = int(np.argmax(bad))
            raise ValueError(f"{name}: gene '{gene}' of genome {i} is {col[i]}; it must be finite in [{lo:g}, {hi:g}]")
        # Genomes are float32: a bound such as 0.02 or 0.6 is the nearest float32 there (0.0199999996, 0.6000000238),
        # which is where sampling and mutation clip to, so that is the bound checked.
        bad = (col < float(np.float32(lo))) | (col > float(np.float32(hi)))
        if bad.any():
            i = int(np.argmax(bad))
            raise ValueError(f"{name}: gene '{gene}' of genome {i} is {col[i]:g}, outside its range [{lo:g}, {hi:g}]")
        if gspec.integer[j]:
            bad = np.abs(col - np.round(col)) > 1e-6
            if bad.any():
                i = int(np.argmax(bad))
                raise ValueError(
                    f"{name}: gene '{gene}' of genome {i} is {col[i]:g}; it must be an integer in [{lo:g}, {hi:g}]"
                )
    return g2


def vector_generator(
    name: str,
    gspec: GenomeSpec,
    render_one: Callable[[jax.Array], jax.Array],
    size: int,
    mutation_prob: float = 0.35,
    mutation_sigma: float = 0.1,
    repair: Callable[[jax.Array], jax.Array] | None = None,
    extra_check: Callable[[np.ndarray], None] | None = None,
    render_chunk: int = RENDER_CHUNK,
) -> Generator:
    """Assemble a :class:`Generator` for a vector genome from its unbatched ``render_one(genome[G]) -> [H, W]``.

    Args:
      repair: optional ``genomes[B, G] -> genomes[B, G]`` applied after sampling and mutation to enforce
        constraints between genes (e.g. Worley's D <= N / 4).
      extra_check: optional host-side check of concrete genomes ``[B, G]`` float64 for such constraints.
      render_chunk: ``render`` evaluates larger batches in ``lax.map`` chunks of this many maps (bounded memory).
    """
    repair = repair or (lambda g: g)
    batched = chunked_render(render_one, render_chunk)
    mutate_jit = jax.jit(lambda key, g: repair(gaussian_mutation(key, g, gspec, mutation_prob, mutation_sigma)))

    sample_jit = jax.jit(lambda key, n: repair(uniform_genomes(key, n, gspec)), static_argnums=1)

    @mark_checked
    def sample(key: PRNGKey, n: int) -> jax.Array:
        n = check_count(n, name)
        check_key(key, name)
        return sample_jit(key, n)

    def validate(genomes: Any) -> None:
        g = check_vector_genomes(genomes, gspec, name)
        if extra_check is not None:
            extra_check(g)

    @mark_checked
    def mutate(key: PRNGKey, genomes: jax.Array) -> jax.Array:
        check_key(key, name)
        if not is_traced(genomes):
            validate(genomes)
        return mutate_jit(key, jnp.asarray(genomes, jnp.float32))

    def render(genomes: Any) -> jax.Array:
        if not is_traced(genomes):
            validate(genomes)
        genomes = jnp.asarray(genomes, jnp.float32)
        if genomes.ndim == 1:
            return batched(genomes[None])[0]
        return batched(genomes)

    return Generator(name, gspec, size, sample, mutate, render, render_one, validate)


def mix32(x: jax.Array) -> jax.Array:
    """``lowbias32`` integer finaliser (C. Wellons): uint32 -> uint32 elementwise, a bijection with good avalanche;
    the integer hash behind the table-free noise of :mod:`~jaxterrain.generators.perlin` and
    :mod:`~jaxterrain.generators.steps`."""
    x = x ^ (x >> 16)
    x = x * jnp.uint32(0x7FEB352D)
    x = x ^ (x >> 15)
    x = x * jnp.uint32(0x846CA68B)
    return x ^ (x >> 16)
