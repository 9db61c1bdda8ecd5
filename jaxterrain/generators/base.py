"""The interface shared by every terrain generator.

A generator is an immutable bundle of pure functions (the optax / evosax shape)::

    gen = jaxterrain.generators.get("perlin")
    genomes = gen.sample(key, 8)                 # [8, G] float32
    children = gen.mutate(key, genomes)          # [8, G] float32, same bounds
    maps = gen.render(genomes)                   # [8, 256, 256] float32 in [0, 1]

``render`` checks concrete genomes on the host (shape, NaN, gene ranges) and raises a ``ValueError`` that names
the gene and its range; under ``jit`` / ``vmap`` (traced values) it skips the value checks and only renders.
``render_one`` is the raw, unchecked ``genome -> [H, W]`` function for use inside your own transformations.

Vector genomes (Perlin, diamond-square, Worley, GAN) are float32 arrays ``[B, G]`` described by a
:class:`GenomeSpec`; integer genes are stored as whole floats. Genomes of other generators (CPPN) are pytrees whose
leaves have a leading batch axis; they bring their own ``sample`` / ``mutate`` / ``validate``.
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

Genome = Any  # an array [B, G] or a pytree of arrays with leading axis B
PRNGKey = jax.Array


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
    g = np.asarray(genomes, dtype=np.float64)
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
        bad = (col < lo) | (col > hi)
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
) -> Generator:
    """Assemble a :class:`Generator` for a vector genome from its unbatched ``render_one(genome[G]) -> [H, W]``.

    Args:
      repair: optional ``genomes[B, G] -> genomes[B, G]`` applied after sampling and mutation to enforce
        constraints between genes (e.g. Worley's D <= N / 4).
      extra_check: optional host-side check of concrete genomes ``[B, G]`` float64 for such constraints.
    """
    repair = repair or (lambda g: g)
    batched = jax.jit(jax.vmap(render_one))

    def sample(key: PRNGKey, n: int) -> jax.Array:
        return repair(uniform_genomes(key, n, gspec))

    def mutate(key: PRNGKey, genomes: jax.Array) -> jax.Array:
        return repair(gaussian_mutation(key, genomes, gspec, mutation_prob, mutation_sigma))

    def validate(genomes: Any) -> None:
        g = check_vector_genomes(genomes, gspec, name)
        if extra_check is not None:
            extra_check(g)

    def render(genomes: Any) -> jax.Array:
        if not is_traced(genomes):
            validate(genomes)
        genomes = jnp.asarray(genomes, jnp.float32)
        if genomes.ndim == 1:
            return batched(genomes[None])[0]
        return batched(genomes)

    return Generator(name, gspec, size, sample, mutate, render, render_one, validate)
