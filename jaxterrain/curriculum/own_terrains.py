"""A curriculum run on a folder of your own heightmaps (``LearnConfig.terrains``, ``learn --terrains DIR``): the
folder read and checked where a run's archive is (:class:`OwnTerrains` stands in ``runner.validate``'s ``arch``),
its terrains ranked by hardness (file-name order, or the start policy's fitness on each), and its terrain bank.

    own = check_terrains(run)                       # None without run.terrains; ValueError naming LearnConfig.<field>
    own = rank_terrains(run, own, policy, folder)   # hardness [N]: the rank; terrains.csv in the run folder
    bank = bank_of(own)                             # a qd.TerrainBank (an archive: qd.from_archive)

The errors are ``ValueError`` naming the field (``LearnConfig.terrains ...``); :mod:`.runner` reports them as its
``BadInput``. How a file becomes a terrain: :mod:`jaxterrain.suite.folder`.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple, Optional

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain import difficulty
from jaxterrain.curriculum.run_config import LearnConfig
from jaxterrain.qd.bank import from_archive
from jaxterrain.rl.checkpoint import policy_fn
from jaxterrain.runtime import estimates
from jaxterrain.runtime.io import atomic_write_csv
from jaxterrain.suite.folder import ORDERS, TerrainFolder, difficulty_order, folder_bank, load_folder, name_order
from jaxterrain.terrain import TerrainScale

__all__ = ["GRID_SELECTORS", "TERRAINS_CSV", "FolderProtocol", "OwnTerrains", "load_terrains", "check_terrains",
           "measure_terrains", "rank_terrains", "bank_of"]


GRID_SELECTORS = ("map", "roughness", "accel")
"""The built-in selectors that need an archive (its grid of descriptors, or its generator's genomes): refused with
``LearnConfig.terrains`` (``map``: the GP over descriptor points; ``roughness``: descriptor 0's order; ``accel``: a
generator's genomes). ``dr``, ``plr``, ``levels``, ``random`` and ``module:object`` selectors run on a folder's
terrains (a bank without a grid: descriptors and points are zeros, ``distance`` the rank by hardness)."""

TERRAINS_CSV = "terrains.csv"
"""A folder run's terrains in its run folder: file, sha256, relief (m), base fitness (``difficulty`` order; empty
for ``name``) and hardness (the rank). ``--resume`` / ``--report`` read the measured order back from it."""


class FolderProtocol(NamedTuple):
    """The evaluation protocol of a run on a folder (where an archive's ``EvolveConfig`` gives it): the walks of
    ``difficulty.HEADINGS`` (80 in 4 headings, best 5 per heading), as the default archive's."""

    attempts: int = int(difficulty.HEADINGS.attempts)
    best: int = int(difficulty.HEADINGS.best)
    headings: int = int(difficulty.HEADINGS.headings)


class OwnTerrains(NamedTuple):
    """A folder of heightmaps where a run's archive stands (:func:`validate`'s ``arch``): the folder's terrains
    (:class:`~jaxterrain.suite.folder.TerrainFolder`), the protocol, and once ranked (:func:`rank_terrains`) each
    terrain's hardness [N] and the base policy's fitness [N] (``difficulty`` order; None for ``name``)."""

    folder: TerrainFolder
    config: FolderProtocol = FolderProtocol()
    hardness: Optional[np.ndarray] = None
    fitness: Optional[np.ndarray] = None

    @property
    def generator_names(self) -> tuple:
        """The file names (``sequences.csv``'s ``generator`` column: each terrain its file's)."""
        return self.folder.names

    @property
    def heightmaps(self) -> np.ndarray:
        """[N, S, S] metres."""
        return self.folder.heightmaps


def load_terrains(run: LearnConfig) -> OwnTerrains:
    """``run.terrains`` read (:func:`jaxterrain.suite.folder.load_folder` at ``run.terrain_height``), unranked;
    ``ValueError`` naming ``LearnConfig.terrains`` / ``terrain_height`` and the file."""
    try:
        folder = load_folder(run.terrains, run.terrain_height)
    except ValueError as err:
        msg = str(err).replace("give a terrain height M", "give LearnConfig.terrain_height M")
        if msg.startswith("terrain height"):
            raise ValueError(f"LearnConfig.terrain_height{msg[len('terrain height'):]}") from None
        if msg.startswith("terrains "):
            raise ValueError(f"LearnConfig.{msg}") from None
        raise ValueError(f"LearnConfig.terrains: {msg}") from None
    return OwnTerrains(folder)


def check_terrains(run: LearnConfig) -> Optional[OwnTerrains]:
    """The terrain fields of a run, before anything else is read: with ``terrains``, the folder read
    (:func:`load_terrains`), ``terrain_order`` one of ``ORDERS`` and a selector that needs no archive
    (:data:`GRID_SELECTORS` refused); without, ``terrain_height`` / ``terrain_order`` left at their defaults (else
    they would be ignored). ``ValueError`` naming the field; None without ``terrains``."""
    if run.terrains is None:
        for name, default in (("terrain_height", None), ("terrain_order", "name")):
            if getattr(run, name) != default:
                raise ValueError(f"LearnConfig.{name} applies to LearnConfig.terrains (a folder of heightmaps), "
                                 f"which is not given")
        return None
    if run.terrain_order not in ORDERS:
        raise ValueError(f"LearnConfig.terrain_order must be one of {', '.join(ORDERS)}, got {run.terrain_order!r}")
    selector = run.curriculum.selector
    if selector in GRID_SELECTORS:
        raise ValueError(f"LearnConfig.curriculum.selector {selector} needs an archive (its descriptor grid or "
                         f"generator); on LearnConfig.terrains use dr, plr, levels or random")
    return load_terrains(run)


def measure_terrains(run: LearnConfig, own: OwnTerrains, policy) -> np.ndarray:
    """[N] float32: the start ``policy``'s fitness on each of ``own``'s terrains under the run's (resolved)
    protocol and episode length, on MJX-JAX, with the key ``fold_in(key(seed), 7)``: what ``terrain_order``
    ``difficulty`` ranks by. Compiles one evaluation program (MJX: about as long as a curriculum block's on a CPU)."""
    c = run.curriculum
    shape = tuple(own.heightmaps.shape[1:])
    cfg = difficulty.default_env_config(shape, TerrainScale(), policy)._replace(
        episode_length=int(run.walker.episode_length))
    maps = np.clip(own.heightmaps / np.float32(TerrainScale().height), 0.0, 1.0)
    apply = policy_fn(policy.config, int(policy.action_size))
    protocol = difficulty.Protocol(int(c.attempts), int(c.best), int(c.headings))
    with estimates.compiling("walks", f"{own.folder.size} terrains x {protocol.attempts} walks, the terrain order"):
        fit = difficulty.evaluate(jnp.asarray(maps), jax.random.fold_in(jax.random.key(int(run.seed)), 7),
                                  policy=apply, policy_params=(policy.params, policy.normaliser), env_config=cfg,
                                  protocol=protocol)
    return np.asarray(fit, np.float32)


def rank_terrains(run: LearnConfig, own: OwnTerrains, policy, folder: Path, measure: bool = True) -> OwnTerrains:
    """``own`` with each terrain's hardness: its rank in file-name order (``terrain_order`` ``name``), or by the
    start policy's fitness (``difficulty``: :func:`measure_terrains`, once per run: written to ``folder``'s
    :data:`TERRAINS_CSV` and read back from it on resume when its files' digests are the same). ``measure=False``
    (a report, which compiles nothing) reads it and raises ``ValueError`` when it is not there."""
    f = own.folder
    path = Path(folder) / TERRAINS_CSV
    fitness = None
    if run.terrain_order == "difficulty":
        if path.exists():
            rows = [r.split(",") for r in path.read_text().splitlines()[1:]]
            if [(r[0], r[1]) for r in rows] == list(zip(f.names, f.files_sha256)) and all(r[3] for r in rows):
                fitness = np.asarray([float(r[3]) for r in rows], np.float32)
        if fitness is None:
            if not measure:
                raise ValueError(f"LearnConfig.terrain_order difficulty: {path} holds no measured order of these files")
            fitness = measure_terrains(run, own, policy)
        hardness = difficulty_order(fitness)
    else:
        hardness = name_order(f)
    if measure:
        atomic_write_csv(path, ["file", "sha256", "relief_m", "base_fitness", "hardness"],
                         [[n, h, f"{r:.4f}", "" if fitness is None else f"{x:.6f}", int(k)] for n, h, r, x, k in
                          zip(f.names, f.files_sha256, f.relief, [0.0] * f.size if fitness is None else fitness,
                              hardness)])
    return own._replace(hardness=hardness, fitness=fitness)


def bank_of(arch):
    """The terrain bank of a run's ``arch``: an archive's elites (``qd.from_archive``) or a ranked folder's terrains
    (:func:`jaxterrain.suite.folder.folder_bank`)."""
    if isinstance(arch, OwnTerrains):
        if arch.hardness is None:
            raise ValueError("bank_of: rank the folder's terrains first (rank_terrains)")
        return folder_bank(arch.folder, arch.hardness, arch.fitness)
    return from_archive(arch)
