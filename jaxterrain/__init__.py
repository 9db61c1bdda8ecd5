"""jaxterrain: evolutionary terrain generation and terrain curricula for legged walkers, end to end in JAX."""

__version__ = "0.1.0"

from jaxterrain import traversability as _traversability  # registers the "traversability" descriptor
