"""Host drivers of MAP-Elites: :func:`evolve` (one treatment) and :func:`evolve_many` (several at once).

Both build a :class:`jaxterrain.qd.scoring.Scoring` and a :class:`jaxterrain.qd.map_elites.Emitter` from a generator,
descriptor names and an :class:`~jaxterrain.qd.EvolveConfig` (whose ONE ``scale`` feeds Algorithm 1 and the
walker fitness), run :mod:`jaxterrain.qd.map_elites` in jitted ``lax.scan`` chunks of ``config.checkpoint_every``
generations, and return host :class:`~jaxterrain.qd.Archive` s. Exported by :mod:`jaxterrain.qd`.

The loop and the checkpoints are :func:`jaxterrain.runtime.driver.run_chunks`'s. Compiled programs: a run compiles its
init and one chunk per chunk length. Pass ``compile_cache={}`` (any dict the caller owns) to reuse them across runs
of the same problem; nothing is cached behind the caller's back.

Several devices: ``mesh=sharding.make_mesh()`` (``--devices`` of the commands) splits every generation's offspring
batch over the mesh's devices (render, descriptors, Algorithm 1 and the walker's rollouts, each device its own
rows; a batch that does not divide is padded and the padding masked out, see :mod:`jaxterrain.qd.scoring`) while the
repertoire stays replicated on every device (selection, mutation and insertion run on each, identically). Rows
are scored with per-row keys, so the same key gives the same archive on 1 and on N devices up to float rounding
(bit for bit when the functions compile the same for any batch size, as the tests' fakes do; XLA may round a
reduction, e.g. a descriptor's mean, one bit differently at another local batch size: :mod:`jaxterrain.qd.scoring`).
``mesh=None`` keeps the one-device program and its one key per batch (archives made before sharding reproduce).
"""

from __future__ import annotations

import functools
import os
import time
from pathlib import Path
from typing import Callable, NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain import difficulty, features, generators as _generators
from jaxterrain.generators import mixed as _mixed
from jaxterrain.qd import config as A, map_elites as ME, programs as P, scoring as S
from jaxterrain.qd.archive import render_elites
from jaxterrain.qd.grid import centroids_for
from jaxterrain.runtime import driver

__all__ = ["CHECKPOINT_NAME", "descriptor_fn", "traversable_fn", "default_fitness", "problem", "evolve", "Treatment",
           "evolve_many", "to_archive", "progress_printer"]

CHECKPOINT_NAME = driver.CHECKPOINT_NAME


# ----------------------------------------------------------------------------------------------------------------
# The problem: scoring + emitter from a generator and a config
# ----------------------------------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=64)
def descriptor_fn(names: Sequence[str], window: int, stride: int) -> Callable:
    """``heightmaps [B, H, W] -> [B, len(names)]``: ``features.descriptors`` with these settings (one function
    object per settings VALUES, so compiled programs built on it can be looked up by value)."""

    names = tuple(names)

    def describe(heightmaps):
        return features.descriptors(heightmaps, names=names, window=window, stride=stride)

    return describe


def traversable_fn(config: A.EvolveConfig) -> Callable:
    """``heightmaps [B, H, W] -> [B] bool``: Algorithm 1 with the config's robot height, window and scale (one
    function object per those VALUES)."""
    return _traversable_fn(config.robot_height, config.traversable_window, config.scale)


@functools.lru_cache(maxsize=64)
def _traversable_fn(robot_height, window, scale) -> Callable:
    kwargs = {"window": window, "scale": scale}
    if robot_height is not None:
        kwargs["robot_height"] = robot_height

    def traversable(heightmaps):
        return features.is_traversable(heightmaps, **kwargs)

    return traversable


def default_fitness(size: int, config: A.EvolveConfig) -> A.FitnessFn:
    """The walker fitness of a config: :func:`jaxterrain.difficulty.difficulty_fitness` at the config's attempts,
    best, headings, scale, slots, backend, robot, observation set and spawn rule."""
    return difficulty.difficulty_fitness(int(size), config.attempts, config.best, config.scale, config.rollout_slots,
                                         backend=config.rollout_backend, headings=config.headings,
                                         robot=config.robot, observation=config.observation, spawn=config.spawn)


def problem(generator, descriptors, config: A.EvolveConfig, fitness_fn=None, traversable=None, names=None,
            mesh=None, split: str | None = None):
    """``(scoring, emitter)`` of one generator under a resolved config.

    Args:
      generator: a ``Generator``.
      descriptors: None (``config.descriptors`` through ``features.descriptors``) or a callable
        ``heightmaps [B, H, W] -> [B, D]``.
      config: a resolved :class:`~jaxterrain.qd.EvolveConfig`.
      fitness_fn: ``(heightmaps, key, needed) -> [B]`` or None for :func:`default_fitness`.
      traversable: ``heightmaps -> [B] bool`` or None for :func:`traversable_fn` (Algorithm 1 at ``config.scale``).
      names: with ``descriptors`` None, the descriptor set to compute (default ``config.descriptors``); the grid
        pair is then ``config.descriptors``' positions in it.
      mesh: None, or a ``jax.sharding.Mesh`` over which the scoring splits its rows.
      split: how (``sharding.map_rows``; None: ``sharding.default_split``).
    """
    pair = (0, 1)
    if descriptors is None:
        names = tuple(config.descriptors) if names is None else tuple(names)
        pair = tuple(names.index(n) for n in config.descriptors)
        descriptors = descriptor_fn(names, int(config.window), int(config.stride))
    if _generators.is_mixture(generator):
        _mixed.check_batch(generator, config.batch_size, "EvolveConfig.batch_size")
    fitness_fn = default_fitness(generator.size, config) if fitness_fn is None else fitness_fn
    traversable = traversable_fn(config) if traversable is None else traversable
    scoring = S.make_scoring_fn(generator, descriptors, traversable, fitness_fn, config, pair, mesh, split)
    emitter = ME.Emitter(generator.sample, generator.mutate, int(config.batch_size), int(config.initial_population))
    return scoring, emitter


# ----------------------------------------------------------------------------------------------------------------
# evolve
# ----------------------------------------------------------------------------------------------------------------


def evolve(generator, descriptors, config: A.EvolveConfig, key: jax.Array, fitness_fn: A.FitnessFn | None = None,
           checkpoint_dir: str | os.PathLike | None = None, progress: bool | Callable[[dict], None] = True,
           traversable_fn: Callable[[jax.Array], jax.Array] | None = None, generator_options: dict | None = None,
           compile_cache: dict | None = None, mesh=None, split: str | None = None) -> A.Archive:
    """Run MAP-Elites for one generator and one descriptor pair; returns the final :class:`~jaxterrain.qd.Archive`.

    Args:
      generator: a ``Generator`` (see generators/base.py) or a registered generator name; a
        ``generators.mixture`` of several evolves ONE archive whose elites record their generator (each generator's
        offspring compete for the same cells; ``config.batch_size`` must exceed its fresh samples).
      descriptors: None (use ``config.descriptors``), a pair of descriptor names (replaces ``config.descriptors``),
        or a callable ``heightmaps [B, H, W] -> [B, 2]`` (e.g. a learned descriptor; ``config.descriptors`` then only
        names it and ``config.ranges`` must be given unless the names have defaults).
      config: :class:`~jaxterrain.qd.EvolveConfig`.
      key: PRNG key (see :mod:`jaxterrain.qd.map_elites` for how generations use it).
      fitness_fn: ``(heightmaps [B, H, W] float32, key, needed [B] bool) -> fitness [B]``, traceable (higher =
        easier; NaN never enters); ``needed`` marks the offspring that can enter the archive, the others' fitness
        is ignored and may be skipped. Wrap a ``(heightmaps, key)`` function with
        ``jaxterrain.qd.scoring.ignore_needed``. Default: :func:`default_fitness` of the config's attempts, best,
        scale and rollout slots.
      checkpoint_dir: run folder of ``jaxterrain.runtime.driver``: ``checkpoint.npz`` (driver format: the
        :class:`~jaxterrain.qd.map_elites.MapElitesState`, the history, and the run's generator / key / config in its
        meta) after generation 0 and after every chunk of ``config.checkpoint_every`` generations, ``metrics.csv``
        and ``tb/``. When it already holds a checkpoint of the same run (same generator, key and config except the
        run settings and ``generations``) the run continues from it, to the archive of an uninterrupted run.
      progress: True shows the driver's progress bar (ETA, coverage); a callable receives a dict per chunk instead
        (``event``, ``generation``, ``generations``, ``seconds``, ``evaluations_per_s``, the latest metrics,
        ``rejected_total``; :func:`progress_printer` prints them); False is silent.
      traversable_fn: ``heightmaps [B, H, W] -> [B] bool`` replacing Algorithm 1 (default ``features.is_traversable``
        with ``config.robot_height``, ``config.traversable_window`` and ``config.scale``).
      generator_options: options for ``generators.get`` when ``generator`` is a name (e.g. ``{"size": 64}``).
      compile_cache: a dict owned by the caller to keep compiled programs in across runs of the same problem.
      mesh: None (one device, one key per batch) or a ``jax.sharding.Mesh`` (``sharding.make_mesh()``): every
        generation's offspring split over its devices with per-row keys, the repertoire replicated; the same key
        gives the same archive on any number of devices (module docstring). Speed only: a run may resume on
        another device count.
      split: how the rows go over the mesh (``sharding.map_rows``: ``"shard_map"``, one program over the
        devices, or ``"dispatch"``, one per device); None: ``sharding.default_split`` (GPUs dispatch).
    """
    generator, descriptors, config = _resolve_one(generator, descriptors, config, generator_options)
    scoring, emitter = problem(generator, descriptors, config, fitness_fn, traversable_fn, mesh=mesh, split=split)
    init, chunk = P.programs(scoring, emitter, compile_cache)
    meta = {"generator": generator.name, "config": _resume_signature(config), "key": _key_data(key).tolist()}
    run_dir = None if checkpoint_dir is None else Path(checkpoint_dir)
    restored = None if run_dir is None else _restore(run_dir, _template(key, scoring, emitter, config), meta,
                                                     config.generations)
    report = _progress(progress, generator.name, config)
    if restored is None:
        state, history = _start(init, key, scoring.task, config, run_dir, meta, report)
    else:
        state, done, history, _ = restored
        if callable(report):
            report({"event": "resume", "generation": done})
    chunk_fn, on_chunk = _chunk_callbacks(chunk, key, config, history, report)
    state, _, history = driver.run_chunks(
        chunk_fn, state, total=config.generations, every=config.checkpoint_every, start=int(state.generation),
        history=history, run_dir=run_dir, key_metric="coverage", progress=on_chunk if callable(report) else report,
        desc=generator.name, unit="gen", meta=meta)
    return to_archive(generator, state.repertoire, config, history)


def _resolve_one(generator, descriptors, config: A.EvolveConfig, generator_options: dict | None):
    """``(generator, descriptors, config)`` of :func:`evolve`'s arguments: a generator name looked up, a pair of
    descriptor names moved into the config (descriptors then None), the config resolved."""
    if isinstance(generator, str):
        generator = _generators.get(generator, **(generator_options or {}))
    if descriptors is not None and not callable(descriptors):
        config = config._replace(descriptors=tuple(descriptors))
        descriptors = None
    return generator, descriptors, A.resolve_config(config)


def _restore(run_dir: Path, like, meta: dict, generations: int):
    """``driver.restore(run_dir, like)`` (None when the folder holds no checkpoint); a checkpoint of another run
    (``meta`` differs, or it is past ``generations``) is refused with a ``ValueError``."""
    restored = driver.restore(run_dir, like=like)
    if restored is not None:
        _check_meta(run_dir, restored[3], meta, restored[1], generations)
    return restored


def _save_first(run_dir: Path | None, state, history: dict, meta: dict) -> None:
    """Generation 0's checkpoint in ``run_dir`` (created); nothing without a folder."""
    if run_dir is not None:
        run_dir.mkdir(parents=True, exist_ok=True)
        driver.save_checkpoint(run_dir / driver.CHECKPOINT_NAME, state, done=0, history=history, meta=meta)


def _start(init, key, task, config: A.EvolveConfig, run_dir: Path | None, meta: dict, report):
    """Generation 0 of :func:`evolve`: ``(state, history)``, checkpointed and, with a callable ``report``, reported
    (its seconds include the checkpoint)."""
    t0 = time.perf_counter()
    state, metrics0 = init(key, centroids_for(config), task)
    history = {k: [float(v)] for k, v in jax.device_get(metrics0).items()}
    _save_first(run_dir, state, history, meta)
    if callable(report):
        report(_line(0, config.generations, history, time.perf_counter() - t0, config.initial_population))
    return state, history


def _chunk_callbacks(chunk, key, config: A.EvolveConfig, history: dict, report):
    """:func:`evolve`'s ``chunk_fn(state, start, stop)`` and ``on_chunk(info)`` for ``driver.run_chunks``: the jitted
    chunk, whose metrics are kept for the per-chunk :func:`_line` dicts that ``on_chunk`` passes to ``report``."""
    seen = {k: list(v) for k, v in history.items()}  # for the per-chunk lines (the driver keeps its own copy)

    def chunk_fn(state, start, stop):
        state, metrics = chunk(state, key, stop - start)
        for name, values in jax.device_get(metrics).items():
            seen.setdefault(name, []).extend(float(v) for v in np.asarray(values))
        return state, metrics

    def on_chunk(info):
        evaluations = round(info["steps_per_s"] * info["seconds"]) * config.batch_size
        report(_line(info["done"], config.generations, seen, info["seconds"], evaluations))

    return chunk_fn, on_chunk


class Treatment(NamedTuple):
    """One treatment of :func:`evolve_many`: a generator name, a descriptor pair and the treatment's run key."""

    generator: str
    descriptors: tuple[str, str]
    key: jax.Array


def _stack(trees):
    return jax.tree.map(lambda *xs: jnp.stack(xs), *trees)


def evolve_many(treatments: Sequence[Treatment], config: A.EvolveConfig, key: jax.Array,
                fitness_fn: A.FitnessFn | None = None, checkpoint_dir: str | os.PathLike | None = None,
                progress: bool | Callable[[dict], None] = True,
                traversable_fn: Callable[[jax.Array], jax.Array] | None = None, generator_options: dict | None = None,
                ranges: dict | None = None, compile_cache: dict | None = None, mesh=None,
                split: str | None = None) -> list[A.Archive]:
    """Evolve several treatments at once: one jitted generation steps them all (:func:`map_elites.multi_step`).

    Treatments of one generator form a batch (``vmap``; their descriptor pairs are indices into one descriptor
    set, the union of every treatment's names); the offspring heightmaps of all generators are scored by ONE
    fitness call per generation (e.g. 5 generators x 3 pairs x 20 = 300 terrains). Each treatment selects and
    mutates with its own key exactly as :func:`evolve` does; the fitness of the offspring of the step after
    generation ``g`` uses ``fold_in(key, g)``, so with a stochastic fitness (the walker) the archives are
    statistically, not bit-wise, those of separate runs (and descriptors computed as part of a larger set may differ
    from a pair's in the last float bits).

    Args:
      treatments: :class:`Treatment` s (generator name, descriptor pair, run key); all generators render one size.
      config: shared settings (``config.descriptors`` / ``config.ranges`` are replaced per treatment).
      key: the key of the shared fitness calls.
      fitness_fn: ``(heightmaps, key, needed) -> [B]``; default :func:`default_fitness` of ``config``.
      checkpoint_dir: folder of the run's ``checkpoint.npz`` (all treatments), ``metrics.csv`` (columns
        ``<metric>/<treatment index>``) and ``tb/``; a checkpoint of the same run there is resumed.
      progress: True for the driver's progress bar; a callable receives a dict per chunk (``generation``,
        ``generations``, ``seconds``, ``evaluations_per_s``, ``coverage``: list per treatment); False is silent.
      traversable_fn: replaces Algorithm 1 (default: :func:`traversable_fn` of ``config``).
      generator_options: options for ``generators.get`` (e.g. ``{"size": 64}``).
      ranges: ``{descriptor name: (lo, hi)}``, default :data:`~jaxterrain.qd.DEFAULT_RANGES`.
      compile_cache: a caller-owned dict to keep compiled programs in.
      mesh: None or a ``jax.sharding.Mesh``: each generation's offspring of all treatments split over its devices
        (:func:`map_elites.multi_step`), the states replicated; the same archives on any number of devices.
      split: how the rows go over the mesh (as in :func:`evolve`).

    Returns:
      one :class:`~jaxterrain.qd.Archive` per treatment, in order.
    """
    treatments, names, gens, size, configs = _resolve_many(treatments, config, generator_options, ranges)
    config = configs[0]
    fitness = default_fitness(size, config) if fitness_fn is None else fitness_fn
    groups, scorings, emitters, states, keys, history = _init_many(treatments, configs, names, gens, fitness,
                                                                   traversable_fn, compile_cache, mesh, split)
    history["coverage"] = [float(np.mean([history[f"coverage/{i}"][0] for i in range(len(treatments))]))]
    meta = {"treatments": [[t.generator, list(t.descriptors), _key_data(t.key).tolist()] for t in treatments],
            "config": _resume_signature(config._replace(descriptors=("-", "-"), ranges=((0, 1), (0, 1)))),
            "key": _key_data(key).tolist(), "ranges": ranges and {k: list(v) for k, v in ranges.items()}}
    run_dir = None if checkpoint_dir is None else Path(checkpoint_dir)
    restored = None if run_dir is None else _restore(run_dir, states, meta, config.generations)
    done = 0
    if restored is not None:
        states, done, history, _ = restored
    else:
        _save_first(run_dir, states, history, meta)
    chunk = P.many_program(scorings, emitters, fitness, mesh, compile_cache)
    chunk_fn, on_chunk = _many_callbacks(chunk, keys, key, groups, config, len(treatments), progress)
    states, done, history = driver.run_chunks(
        chunk_fn, states, total=config.generations, every=config.checkpoint_every, start=done, history=history,
        run_dir=run_dir, key_metric="coverage", progress=on_chunk if callable(progress) else bool(progress),
        desc=f"{len(treatments)} treatments", unit="gen", meta=meta)
    return _many_archives(states, groups, gens, configs, history)


def _resolve_many(treatments, config: A.EvolveConfig, generator_options: dict | None, ranges: dict | None):
    """``(treatments, names, {generator name: Generator}, size, configs)`` of :func:`evolve_many`'s arguments:
    ``names`` is the union of the treatments' descriptor names (first seen first), ``size`` the one size every
    generator renders, ``configs`` one resolved config per treatment (its pair and ranges)."""

    treatments = [Treatment(t[0], tuple(t[1]), t[2]) for t in treatments]
    if not treatments:
        raise ValueError("evolve_many: treatments must be a non-empty sequence of (generator, (d0, d1), key)")
    names = tuple(dict.fromkeys(n for t in treatments for n in t.descriptors))
    gens = {t.generator: _generators.get(t.generator, **(generator_options or {})) for t in treatments}
    sizes = {g.size for g in gens.values()}
    if len(sizes) != 1:
        raise ValueError(f"evolve_many: every generator must render one size; got {sorted(sizes)}")
    configs = []
    for t in treatments:
        r = None if ranges is None else tuple(tuple(ranges[n]) for n in t.descriptors)
        configs.append(A.resolve_config(config._replace(descriptors=t.descriptors, ranges=r)))
    return treatments, names, gens, sizes.pop(), configs


def _many_callbacks(chunk, keys, key, groups: dict, config: A.EvolveConfig, count: int, progress):
    """:func:`evolve_many`'s ``chunk_fn(states, start, stop)`` (metrics per group -> ``<metric>/<treatment index>``
    columns plus the mean ``coverage``) and ``on_chunk(info)`` (a dict per chunk to a callable ``progress``)."""
    order = [i for members in groups.values() for i in members]

    def chunk_fn(states, start, stop):
        states, metrics = chunk(states, keys, key, stop - start)
        out = {}
        for members, m in zip(groups.values(), metrics):
            for j, i in enumerate(members):
                out.update({f"{k}/{i}": v[:, j] for k, v in m.items()})
        out["coverage"] = jnp.mean(jnp.stack([out[f"coverage/{i}"] for i in order]), axis=0)
        return states, out

    def on_chunk(info):
        progress({"event": "chunk", "generation": info["done"], "generations": config.generations,
                  "seconds": info["seconds"], "evaluations_per_s": info["steps_per_s"] * config.batch_size * count,
                  "coverage": [info[f"coverage/{i}"] for i in range(count)]})

    return chunk_fn, on_chunk


def _init_many(treatments, configs, names, gens, fitness, traversable, cache, mesh=None, split=None):
    """Generation 0 of every treatment, grouped by generator: ``(groups {name: [treatment index]}, scorings,
    emitters, stacked states per group, stacked keys per group, history {"<metric>/<index>": [value]})``."""
    groups: dict[str, list[int]] = {}
    for i, t in enumerate(treatments):
        groups.setdefault(t.generator, []).append(i)
    scorings, emitters, states, keys = [], [], [], []
    history: dict[str, list[float]] = {}
    for name, members in groups.items():
        scoring, emitter = problem(gens[name], None, configs[members[0]], fitness, traversable, names=names,
                                   mesh=mesh, split=split)
        init, _ = P.programs(scoring, emitter, cache)
        group_states = []
        for i in members:
            pair = tuple(names.index(n) for n in configs[i].descriptors)
            state, m0 = init(treatments[i].key, centroids_for(configs[i]), S.task_for(configs[i], pair))
            group_states.append(state)
            for k, v in jax.device_get(m0).items():
                history[f"{k}/{i}"] = [float(v)]
        scorings.append(scoring)
        emitters.append(emitter)
        states.append(_stack(group_states))
        keys.append(jnp.stack([treatments[i].key for i in members]))
    return groups, scorings, emitters, states, keys, history


def _many_archives(states, groups, gens, configs, history) -> list[A.Archive]:
    out = [None] * len(configs)
    for (name, members), group_state in zip(groups.items(), states):
        for j, i in enumerate(members):
            repertoire = jax.tree.map(lambda x, j=j: x[j], group_state.repertoire)
            own = {k.split("/")[0]: v for k, v in history.items() if k.endswith(f"/{i}")}
            out[i] = to_archive(gens[name], repertoire, configs[i], own)
    return out


def to_archive(generator, repertoire, config: A.EvolveConfig, history: dict) -> A.Archive:
    """Host :class:`~jaxterrain.qd.Archive` of one repertoire (elites rendered when ``store_heightmaps``). A
    mixture's repertoire (``generators.mixture``) becomes an archive of its component generators: ``source`` is each
    elite's generator and ``genomes[k]`` generator ``k``'s slot, zero where another generator or nobody holds the
    cell (the form of ``qd.combine``'s archives, so every reader of archives takes it)."""
    fitness = np.asarray(repertoire.fitnesses, np.float32).reshape(-1)
    filled = fitness > -np.inf
    genomes = jax.tree.map(np.asarray, repertoire.genotypes)
    maps = render_elites(generator, genomes, filled) if config.store_heightmaps else None
    if _generators.is_mixture(generator):
        names = tuple(generator.spec.names)
        source, kept = _mixed.archive_slots(genomes, filled)
    else:
        source = np.where(filled, 0, -1).astype(np.int32)
        names, kept = (generator.name,), (genomes,)
    return A.Archive(
        genomes=kept,
        generator_names=names,
        source=source,
        fitness=fitness,
        descriptors=np.asarray(repertoire.extra_scores["raw"], np.float32),
        centroids=np.asarray(repertoire.centroids, np.float32),
        heightmaps=maps,
        config=config,
        metrics={k: np.asarray(v, np.float32) for k, v in history.items()},
    )


def _template(key, scoring: S.Scoring, emitter: ME.Emitter, config: A.EvolveConfig) -> ME.MapElitesState:
    """A zero state of the run's structure, shapes and dtypes (``driver.restore``'s template)."""
    example = jax.eval_shape(lambda k: emitter.sample(k, 1), key)
    genome = jax.tree.map(lambda x: jnp.zeros(x.shape[1:], x.dtype), example)
    return ME.MapElitesState(ME.empty_repertoire(genome, centroids_for(config)), jnp.zeros((), jnp.int32),
                             scoring.task)


def _check_meta(run_dir: Path, saved: dict, meta: dict, done: int, generations: int) -> None:
    """Refuse a checkpoint of another run (generator, key, config except the run settings); one saved before the
    config had ``spawn`` is taken to be of the config's rule (the run's ``config.json`` says which)."""
    where = str(Path(run_dir) / driver.CHECKPOINT_NAME)
    saved = {**saved, "config": {"spawn": meta["config"].get("spawn"), **(saved.get("config") or {})}}
    for name in ("generator", "treatments"):
        if saved.get(name) != meta.get(name):
            raise ValueError(f"checkpoint {where!r} is of {name} {saved.get(name)!r}, not {meta.get(name)!r}")
    if saved.get("key") != meta.get("key"):
        raise ValueError(f"checkpoint {where!r} was made with another PRNG key; use the same key to resume")
    if saved.get("config") != meta.get("config"):
        raise ValueError(f"checkpoint {where!r} was made with another config: {saved.get('config')} != "
                         f"{meta.get('config')}; use another checkpoint folder")
    if done > generations:
        raise ValueError(f"checkpoint {where!r} is at generation {done}, beyond config.generations={generations}")


def _progress(progress, name: str, config: A.EvolveConfig):
    """The driver's progress argument: True (its tqdm bar), False, or a callable of the per-chunk line dicts."""
    if callable(progress) or not progress:
        return progress
    return True


def _line(done, total, history, seconds, evaluations):
    return {
        "event": "chunk",
        "generation": done,
        "generations": total,
        "seconds": seconds,
        "evaluations_per_s": evaluations / max(seconds, 1e-9),
        **{k: v[-1] for k, v in history.items()},
        "rejected_total": float(np.sum(history.get("rejected", [0.0]))),
    }


def progress_printer(name: str):
    """The default progress callback of :func:`evolve`: one line per chunk, prefixed by ``[name]``."""

    def report(info):
        if info["event"] == "resume":
            print(f"[{name}] resuming from checkpoint at generation {info['generation']}", flush=True)
            return
        print(
            f"[{name}] gen {info['generation']}/{info['generations']}  coverage {info['coverage']:.2f}%  "
            f"qd {info['qd_score']:.2f}  max {info['max_fitness']:.3f}  mean {info['mean_fitness']:.3f}  "
            f"rejected {int(info['rejected_total'])}  {info['evaluations_per_s']:.1f} evals/s",
            flush=True,
        )

    return report


def _key_data(key) -> np.ndarray:
    if jnp.issubdtype(key.dtype, jax.dtypes.prng_key):
        return np.asarray(jax.random.key_data(key))
    return np.asarray(key)


# ----------------------------------------------------------------------------------------------------------------
# Checkpoints (one run's repertoire + progress; same npz conventions)
# ----------------------------------------------------------------------------------------------------------------


def _resume_signature(config: A.EvolveConfig) -> dict:
    d = A.config_to_dict(config)
    for speed_only in ("generations", "checkpoint_every", "rollout_slots", "store_heightmaps", "rollout_backend"):
        d.pop(speed_only)
    return d
