"""jaxterrain: evolutionary terrain generation and terrain curricula for legged walkers, end to end in JAX.

The subpackages, in the order the data flows (each imports only those before it)::

    runtime       the host loop, devices, files, provenance, config checks
    generators    genome [B, G] -> heightmap [B, 256, 256] in [0, 1]
    terrain       TerrainScale (metres), exports (PNG, npy, MJCF, meshes), real elevation tiles
    features      TRI / TPI / roughness descriptors, the descriptor registry, Algorithm 1
    walker        the robot on MJX heightfields: model, env, terrain layouts, batched walks
    rl            PPO: config, networks, losses, the pure update, the host driver, policy files
    difficulty    the walking protocol, difficulty evaluation, the named fitness functions
    features.learned  the learned traversability descriptor (trained on the walker's walks)
    qd            MAP-Elites archives: scoring, the pure algorithm, host drivers, files, the device bank
    suite         the held-out terrain suite (families x levels x seeds) and walkers evaluated on it
    curriculum    Experiment 2's curricula: the GP, the pure trial loop, the walker harness, the treatment runner
    report        HTML / Markdown pages of run folders
"""

__version__ = "0.1.0"

from jaxterrain import runtime  # noqa: I001  (flow order, not alphabetical)
from jaxterrain import generators
from jaxterrain import terrain
from jaxterrain import features
from jaxterrain import walker
from jaxterrain import rl
from jaxterrain import difficulty
from jaxterrain.features import learned  # noqa: F401  (registers the "traversability" descriptor)
from jaxterrain import qd
from jaxterrain import suite
from jaxterrain import curriculum
from jaxterrain import report

__all__ = ["__version__", "runtime", "generators", "terrain", "features", "walker", "rl", "difficulty", "qd", "suite",
           "curriculum", "report"]
