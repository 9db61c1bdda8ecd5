"""What every stage runs on: the host loop of long jobs, devices, files, provenance and config checks.

- :mod:`~jaxterrain.runtime.driver`: the one host loop (chunks of a jitted program, checkpoints, resume, time
  limits, metrics);
- :mod:`~jaxterrain.runtime.sharding`: device meshes and row-splitting of batched programs;
- :mod:`~jaxterrain.runtime.io`: atomic file writes;
- :mod:`~jaxterrain.runtime.provenance`: the code's commit and the device, for every result;
- :mod:`~jaxterrain.runtime.validation`: the one-line config checks every config class shares;
- :mod:`~jaxterrain.runtime.xla`: the XLA options the installed jax knows (cheap CPU compiles);
- :mod:`~jaxterrain.runtime.statistics`: scores of several runs aggregated with rliable (IQM, stratified-bootstrap
  intervals, probability of improvement) and rank correlations.
"""

from jaxterrain.runtime import driver, io, provenance, schema, sharding, statistics, validation, xla

__all__ = ["driver", "io", "provenance", "schema", "sharding", "statistics", "validation", "xla"]
