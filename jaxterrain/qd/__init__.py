"""Quality diversity: MAP-Elites terrain archives (paper section 3.3), from the pure algorithm to host files.

- :mod:`~jaxterrain.qd.config`: :class:`EvolveConfig`, :class:`Archive`, :data:`DEFAULT_RANGES`;
- :mod:`~jaxterrain.qd.grid`: the 50 x 50 grid (centroids, cell <-> bins, distance from cell (0, 0));
- :mod:`~jaxterrain.qd.scoring`: render, descriptors, Algorithm 1 and fitness of a batch (QDax's scoring contract);
- :mod:`~jaxterrain.qd.map_elites`: the pure state, ``init`` / ``step``, one winner per cell, several at once;
- :mod:`~jaxterrain.qd.evolution`: the host drivers :func:`evolve` / :func:`evolve_many` (checkpoints, resume);
- :mod:`~jaxterrain.qd.archive`: host queries (coverage, QD score, re-derive / reseat elites, :func:`combine`,
  :func:`generator_shares` per distance band);
- :mod:`~jaxterrain.qd.archive_io`: the archive file (:func:`save` / :func:`load`);
- :mod:`~jaxterrain.qd.bank`: an archive's elites on the device (:class:`TerrainBank`), the curriculum's input;
- :mod:`~jaxterrain.qd.gradient`: does fitness fall with the distance from cell (0, 0)? (:func:`gradient.gradient`).

    >>> from jaxterrain import qd
    >>> arch = qd.evolve("perlin", None, qd.EvolveConfig(generations=50), key)
    >>> qd.coverage(arch), qd.save("perlin.npz", arch)
"""

from jaxterrain.qd import gradient, grid, map_elites, scoring
from jaxterrain.qd.archive import (
    check_cells,
    combine,
    coverage,
    elite,
    fitness_grid,
    generator_shares,
    heightmaps,
    qd_score,
    rederive_cells,
    refused,
    render_elites,
    reseat,
)
from jaxterrain.qd.archive_io import FORMAT, VERSION, load, save
from jaxterrain.qd.bank import TerrainBank, from_archive, from_heightmaps, to_device
from jaxterrain.qd.config import (
    Archive,
    DEFAULT_RANGES,
    EvolveConfig,
    FitnessFn,
    PRNGKey,
    config_from_dict,
    config_to_dict,
    resolve_config,
)
from jaxterrain.qd.evolution import (
    CHECKPOINT_NAME,
    Treatment,
    default_fitness,
    descriptor_fn,
    evolve,
    evolve_many,
    problem,
    progress_printer,
    to_archive,
    traversable_fn,
)
from jaxterrain.qd.grid import GRID_BINS, MAX_DISTANCE_50, cell_bins, cell_distance, cell_of, centroids_for
from jaxterrain.qd.map_elites import METRIC_NAMES
from jaxterrain.qd import run_config, runs, shares, table1  # noqa: E402  (the evolve and coverage runs)
from jaxterrain.qd.table1 import CoverageResult, coverage_run, validate_coverage
from jaxterrain.qd.run_config import CoverageRun, EvolveRun
from jaxterrain.qd.runs import evolve_run, validate_evolve

__all__ = [
    "scoring",
    "map_elites",
    "DEFAULT_RANGES",
    "Archive",
    "EvolveConfig",
    "FitnessFn",
    "PRNGKey",
    "config_from_dict",
    "config_to_dict",
    "resolve_config",
    "GRID_BINS",
    "MAX_DISTANCE_50",
    "centroids_for",
    "cell_bins",
    "cell_of",
    "cell_distance",
    "METRIC_NAMES",
    "FORMAT",
    "VERSION",
    "load",
    "save",
    "check_cells",
    "combine",
    "coverage",
    "elite",
    "fitness_grid",
    "generator_shares",
    "gradient",
    "grid",
    "heightmaps",
    "qd_score",
    "rederive_cells",
    "refused",
    "render_elites",
    "reseat",
    "TerrainBank",
    "from_archive",
    "from_heightmaps",
    "to_device",
    "CHECKPOINT_NAME",
    "Treatment",
    "default_fitness",
    "descriptor_fn",
    "evolve",
    "evolve_many",
    "problem",
    "progress_printer",
    "to_archive",
    "traversable_fn",
    "run_config",
    "runs",
    "shares",
    "table1",
    "coverage_run",
    "EvolveRun",
    "CoverageRun",
    "CoverageResult",
    "evolve_run",
    "validate_evolve",
    "validate_coverage",
]
