"""An ``evolve`` run as one call: an :class:`~jaxterrain.qd.run_config.EvolveRun` validated once, its archive
evolved into a folder (checkpointed, resumable, stopped cleanly at a time limit) and its files written.

    from jaxterrain.qd import run_config as R, runs
    run = runs.validate_evolve(R.PRESETS["smoke"])    # ValueError naming EvolveRun.<path>, before anything compiles
    archive = runs.evolve_run(run, "runs/mine")       # the Archive; None when the time limit stopped it (resumable)

Writes into the folder: ``checkpoint/`` (``runtime.driver``'s, every ``map_elites.checkpoint_every`` generations),
``archive.npz`` (:func:`jaxterrain.qd.save`), ``metrics.csv`` (a row per generation), ``archive.png`` and, for a
mixed run, ``shares.csv`` / ``.md`` / ``.png`` (:mod:`jaxterrain.qd.shares`). A folder holding ``archive.npz`` is
done: its archive is read back, not evolved again.
"""

from __future__ import annotations

import csv
import io
import time
from pathlib import Path
from typing import Callable, Optional

import jax
from matplotlib.figure import Figure

from jaxterrain import generators
from jaxterrain.difficulty import FITNESSES, robot_base_policy
from jaxterrain.features import descriptor_names
from jaxterrain.qd.archive import coverage, fitness_grid, qd_score
from jaxterrain.qd.archive_io import load, save
from jaxterrain.qd.config import Archive, EvolveConfig, resolve_config
from jaxterrain.qd.evolution import evolve, progress_printer
from jaxterrain.qd.run_config import EVOLVE_RULES, MIX_DEFAULT, EvolveRun
from jaxterrain.qd.shares import write_all as write_shares
from jaxterrain.runtime import schema
from jaxterrain.runtime.estimates import announce
from jaxterrain.runtime.io import atomic_write_text, save_figure
from jaxterrain.walker import WalkerConfig, min_terrain_side, resolve_backend, robots

__all__ = ["TimeUp", "Deadline", "fitness_of", "generator_of", "evolve_config", "check_generators", "check_walker",
           "check_descriptors", "check_evolve_config", "validate_evolve", "announce_compile", "evolve_run",
           "write_metrics_csv", "plot_archive", "write_archive_figure", "summary_line"]


class TimeUp(Exception):
    """Raised by :meth:`Deadline.check` once the time limit has passed (after a checkpoint: the run resumes)."""


class Deadline:
    """A time limit of ``seconds`` from now (None: none); :meth:`check` raises :class:`TimeUp` past it. One
    deadline may span several archives (``qd.coverage.coverage_run``'s treatments)."""

    def __init__(self, seconds: Optional[float]):
        self.start = time.perf_counter()
        self.limit = seconds

    def check(self) -> None:
        if self.limit is not None and time.perf_counter() - self.start > self.limit:
            raise TimeUp


def fitness_of(name: str):
    """The ``fitness_fn`` of ``qd.evolve`` for fitness ``name``: ``difficulty.FITNESSES[name]`` (None, the walker's
    ``"difficulty"``: ``qd.evolve`` builds it from the config's walks and its ONE scale)."""
    return FITNESSES[name]


def generator_of(run: EvolveRun):
    """The generator ``qd.evolve`` evolves: ``run.generator``'s name, or for ``mixed`` the
    ``generators.mixture`` of ``run.mixture`` at ``run.size``."""
    if run.generator != "mixed":
        return run.generator
    return generators.mixture(tuple(run.mixture.generators or MIX_DEFAULT), fresh=int(run.mixture.fresh),
                              size=int(run.size))


def evolve_config(run: EvolveRun) -> EvolveConfig:
    """The :class:`~jaxterrain.qd.EvolveConfig` of ``run`` (its ``map_elites``, ``walks``, ``descriptors`` and
    ``ranges``; ``walks.backend`` ``auto`` resolved on this machine, ``walker.resolve_backend``)."""
    m, w = run.map_elites, run.walks
    return EvolveConfig(
        generations=int(m.generations), batch_size=int(m.batch_size), initial_population=int(m.initial_population),
        bins=int(m.bins), descriptors=tuple(run.descriptors),
        ranges=None if run.ranges is None else tuple(tuple(map(float, r)) for r in run.ranges),
        window=int(m.window), stride=int(m.stride), attempts=int(w.attempts), best=int(w.best),
        headings=int(w.headings), checkpoint_every=int(m.checkpoint_every), robot_height=m.robot_height,
        out_of_range=m.out_of_range, store_heightmaps=bool(m.store_heightmaps),
        rollout_slots=None if w.rollout_slots is None else int(w.rollout_slots),
        rollout_backend=str(w.backend) if w.backend != "auto" else resolve_backend("auto"),
        robot=str(w.robot or "humanoid"), observation=str(w.observation or "blind"), spawn=w.spawn)


_EVOLVE_CONFIG_FIELDS = {"descriptors": "descriptors", "ranges": "ranges", "rollout_backend": "walks.backend",
                         **{f: f"walks.{f}" for f in ("attempts", "best", "headings", "robot", "observation",
                                                      "rollout_slots", "spawn")}}


def check_generators(names, size: int, owner: str, field: str, size_field: str = "size") -> None:
    """Every name of ``names`` a registered generator that renders at ``size`` (diamond-square: powers of two; the
    GAN: its weights); ``ValueError`` naming ``owner.field`` / ``owner.size_field``."""
    known = generators.names()
    for name in names:
        if name not in known:
            raise ValueError(f"{owner}.{field}: unknown generator {name!r}; choose from {', '.join(known)} (or one a "
                             f"plugin registers)")
    for name in names:
        try:
            generators.get(name, size=size)
        except (ValueError, OSError) as err:
            text = str(err).splitlines()[0].removeprefix(f"{name}: ")
            raise ValueError(f"{owner}.{size_field} {size} does not suit generator {name!r} ({owner}.{field}): "
                             f"{text}") from None


def check_walker(owner: str, fitness: str, size: int, robot: str, observation: str, prefix: str = "walks.") -> None:
    """The walker fitness's robot: registered, with a shipped base policy of its observation set (where the
    fitness walks), on terrains of ``size`` pixels it has a track on; ``ValueError`` naming the field."""
    try:
        robots.get(robot)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{owner}.{prefix}robot: {err}") from None
    if fitness != "difficulty":
        return
    try:
        robot_base_policy(robot, observation)
    except ValueError as err:
        raise ValueError(f"{owner}.{prefix}{'observation' if observation != 'blind' else 'robot'}: {err}") from None
    need = min_terrain_side(WalkerConfig(robot=robot))
    if size < need:
        raise ValueError(f"{owner}.size must be >= {need} pixels for the walker fitness of robot {robot} (its "
                         f"episode margins at 4 cm a pixel); got {size}")


def check_descriptors(names, owner: str, field: str) -> None:
    """Two different registered descriptor names (``features.descriptor_names``); ``ValueError`` naming
    ``owner.field``."""
    names = tuple(names)
    for name in names:
        if name not in descriptor_names():
            raise ValueError(f"{owner}.{field}: unknown descriptor {name!r}; choose from "
                             f"{', '.join(descriptor_names())}")
    if len(names) != 2 or len(set(names)) != 2:
        raise ValueError(f"{owner}.{field} must be two different descriptor names; got {names!r}")


def check_evolve_config(run: EvolveRun, owner: str = "EvolveRun", renames: Optional[dict] = None) -> None:
    """The :class:`~jaxterrain.qd.EvolveConfig` of ``run`` as ``qd.resolve_config`` checks it (the grid ranges
    too); ``ValueError`` naming ``owner.<path>`` (``renames``: ``{EvolveRun path: owner's path}``)."""
    try:
        resolve_config(evolve_config(run))
    except ValueError as err:
        text = str(err)
        for field, path in _EVOLVE_CONFIG_FIELDS.items():
            text = text.replace(f"EvolveConfig.{field}", f"EvolveRun.{path}")
        text = schema.rename_fields(text, "EvolveConfig", lambda f: f"EvolveRun.map_elites.{f}")
        for path, other in (renames or {}).items():
            text = text.replace(f"EvolveRun.{path}", f"{owner}.{other}")
        raise ValueError(text.replace("EvolveRun.", f"{owner}.")) from None


def validate_evolve(run: EvolveRun) -> EvolveRun:
    """Check ``run`` once, before anything compiles: its fields (``run_config.EVOLVE_RULES``), the descriptors,
    generator(s) and robot against their registries, a size every generator renders and the robot walks, a mixture
    whose fresh samples leave room for offspring, and the :class:`~jaxterrain.qd.EvolveConfig` it makes
    (``qd.resolve_config``). ``ValueError`` naming the field as ``EvolveRun.<path>``; returns ``run``."""
    owner = "EvolveRun"
    schema.check(run, EVOLVE_RULES, owner)
    check_descriptors(run.descriptors, owner, "descriptors")
    check_walker(owner, run.fitness, int(run.size), run.walks.robot, run.walks.observation)
    if run.generator == "mixed":
        mix = tuple(run.mixture.generators or MIX_DEFAULT)
        if len(mix) < 2 or len(set(mix)) != len(mix):
            raise ValueError(f"{owner}.mixture.generators: two or more distinct generator names; got {' '.join(mix)}")
        check_generators(mix, int(run.size), owner, "mixture.generators")
        need = int(run.mixture.fresh) * len(mix)
        if int(run.map_elites.batch_size) <= need:
            raise ValueError(f"{owner}.map_elites.batch_size must be > {need} with {owner}.generator mixed "
                             f"({owner}.mixture.fresh {run.mixture.fresh} of each of {len(mix)} generators); got "
                             f"{run.map_elites.batch_size}")
    else:
        check_generators([run.generator], int(run.size), owner, "generator")
    check_evolve_config(run)
    return run


def announce_compile(run: EvolveRun, config: EvolveConfig) -> None:
    """Say what the first generations compile and about how long that takes here (``runtime.estimates``)."""
    walks = run.fitness == "difficulty"
    announce("map-elites" if walks else "map-elites-slope",
             f"{config.batch_size} offspring" + (f", {config.rollout_backend} physics" if walks else ""))


def evolve_run(run: EvolveRun, folder, time_limit_s: Optional[float] = None, mesh=None, key=None, label: str = "",
               figures: bool = True, deadline: Optional[Deadline] = None,
               say: Callable[[str], None] = print) -> Optional[Archive]:
    """Evolve ``run``'s archive into ``folder`` (:func:`validate_evolve` it first); returns the
    :class:`~jaxterrain.qd.Archive`, or None when ``time_limit_s`` (seconds from now; or ``deadline``, which raises
    :class:`TimeUp` instead) stopped it after a checkpoint: the same call continues it. ``key``: the root key
    (default ``jax.random.key(run.seed)``); ``mesh``: the devices each generation's offspring are split over
    (``qd.evolve``); ``label`` prefixes its progress lines; ``figures``: write ``archive.png`` (and a mixed run's
    shares)."""
    folder = Path(folder)
    done_path = folder / "archive.npz"
    if done_path.exists():
        say(f"{label}{run.generator} {list(run.descriptors)}: already done ({done_path})")
        arch = load(done_path)
    else:
        config = evolve_config(run)
        announce_compile(run, config)
        printer = progress_printer(label + run.generator)
        clock = deadline or Deadline(time_limit_s)

        def progress(info):
            printer(info)
            if info.get("generation", 0) < info.get("generations", 0):  # the last chunk goes on to save the archive
                clock.check()

        try:
            arch = evolve(generator_of(run), None, config, jax.random.key(run.seed) if key is None else key,
                          fitness_fn=fitness_of(run.fitness), checkpoint_dir=folder / "checkpoint", progress=progress,
                          generator_options={"size": int(run.size)}, mesh=mesh)
        except TimeUp:
            if deadline is not None:
                raise
            return None
        save(done_path, arch)
        write_metrics_csv(folder / "metrics.csv", arch.metrics)
    if figures:
        write_archive_figure(folder / "archive.png", arch)
        if run.generator == "mixed":
            mix = generator_of(run).spec
            write_shares(folder, {"mixed": arch}, 10.0, f"{len(mix.names)} generators, fresh {mix.fresh}, preset "
                                                        f"{run.preset}", say=say)
    return arch


def write_metrics_csv(path: Path, metrics: dict) -> None:
    """An archive's metrics history (``{name: [generations + 1]}``) as ``metrics.csv``: a row per generation."""
    names = sorted(metrics)
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["generation", *names])
    for g in range(len(metrics[names[0]]) if names else 0):
        w.writerow([g, *(f"{float(metrics[n][g]):.6g}" for n in names)])
    atomic_write_text(path, buf.getvalue())


def plot_archive(ax, arch: Archive, title: str = ""):
    """Draw an archive's fitness grid on a matplotlib axis (darker = fitter, like the paper's Figure 6); the image."""
    (lo0, hi0), (lo1, hi1) = arch.config.ranges
    img = ax.imshow(fitness_grid(arch), origin="lower", extent=(lo0, hi0, lo1, hi1), aspect="auto",
                    cmap="viridis_r", vmin=0.0, vmax=1.0, interpolation="nearest")
    ax.set_xlabel(arch.config.descriptors[0])
    ax.set_ylabel(arch.config.descriptors[1])
    ax.set_title(title or f"{'+'.join(arch.generator_names)}: {coverage(arch):.2f}%", fontsize=8)
    return img


def write_archive_figure(path: Path, arch: Archive) -> Path:
    """``archive.png``: the archive's fitness grid with a colour bar."""
    fig = Figure(figsize=(4, 3.5))
    ax = fig.subplots()
    fig.colorbar(plot_archive(ax, arch), ax=ax, label="fitness")
    fig.tight_layout()
    return save_figure(fig, path, dpi=120)


def summary_line(arch: Archive) -> str:
    """The run's result in one line: coverage, QD score and the offspring Algorithm 1 rejected."""
    return (f"coverage {coverage(arch):.2f}%  qd {qd_score(arch):.2f}  rejected by Algorithm 1: "
            f"{int(arch.metrics['rejected'].sum())}")
