"""Walkers on terrains they never saw: the fitness of policies on a held-out suite (or any heightmaps), and the
highest level of each family they pass with every level below it passed too.

    fitness = evaluate_policies([rl.load_policy(), rl.load_policy(run / "policies/trial_0")], suite.heightmaps, key)
    levels = passed_levels(fitness[1], suite)          # {family: highest level k with levels 0..k passed, or -1}

A level is passed when the mean fitness of its terrains is >= :data:`THRESHOLD` (0.9). A level passed above a failed
one does not count: a walker that fails stairs at 0.09 m and passes them at 0.19 m (a fluke of the seeds) has passed
the stairs up to 0.06 m, not 0.19 m.

Fitness is :func:`jaxterrain.difficulty.evaluate`'s (the walker's normalised distance under a
:class:`~jaxterrain.difficulty.Protocol`, :data:`~jaxterrain.difficulty.HEADINGS` by default), each policy walking
as it was trained: its own contact solver (``config.json``'s ``walker_config``) and the same env otherwise. The
policies' weights (their actor's, the value network left out) are data to ONE compiled program per policy network
and walker config, so a robot's base policy and all its walkers compile once, whatever each was trained with;
every policy walks with the same key (the same start poses and noise: common random numbers, so differences between
policies are the policies').
"""

from __future__ import annotations

from typing import Callable, Sequence

import jax
import numpy as np

from jaxterrain import difficulty
from jaxterrain.difficulty import HEADINGS, Protocol, replay
from jaxterrain.rl.checkpoint import policy_fn
from jaxterrain.runtime.statistics import cvar
from jaxterrain.suite.heldout import Suite
from jaxterrain.terrain import TerrainScale
from jaxterrain.walker.layout import make_env
from jaxterrain.walker.randomisation import Randomisation, is_active as randomisation_active

__all__ = ["THRESHOLD", "CVAR_ALPHA", "cell_scores", "check_policies", "evaluate_policies", "generator_robustness",
           "highest_level_passed", "level_fitness", "passed_levels"]

THRESHOLD = 0.9
"""A level is passed when the mean fitness of its terrains reaches this (the paper's traversability threshold)."""

CVAR_ALPHA = 0.1
"""The robustness figure's tail: the mean fitness of the worst 10 % of a generator's samples."""


def _name(policy) -> str:
    return str(getattr(policy, "path", None) or "the policy")


def check_policies(policies: Sequence[Callable], shape: tuple[int, int], scale: TerrainScale,
                   backend: str = "jax", randomisation: Randomisation | None = None,
                   spawn: str | None = None) -> list:
    """Each policy's walker config for terrains of ``shape``, after checking that it fits the walker: loaded by
    ``rl.load_policy`` (it carries ``params``, ``normaliser``, ``config``), with the env's observation and action
    sizes. ValueError naming the policy's folder otherwise (one line). ``randomisation``: the physics randomisation
    every policy walks under (None: off, whatever the policy trained with); ``spawn``: the reset's rule
    (``jaxterrain.walker.SPAWNS``; None: the walker's default)."""
    configs = []
    for p in policies:
        if not all(hasattr(p, a) for a in ("params", "normaliser", "config", "observation_size", "action_size")):
            raise ValueError(f"policy {_name(p)}: not a policy loaded by rl.load_policy (it needs its weights)")
        cfg = difficulty.default_env_config(tuple(shape), scale, p, backend)
        if randomisation is not None:
            cfg = cfg._replace(randomisation=randomisation)
        if spawn is not None:
            cfg = cfg._replace(spawn=spawn)
        env = make_env(cfg)
        if (int(p.observation_size), int(p.action_size)) != (env.observation_size, env.action_size):
            raise ValueError(f"policy {_name(p)}: observations {p.observation_size} / actions {p.action_size}, but "
                             f"this walker has {env.observation_size} / {env.action_size} (another robot or "
                             f"observation set)")
        configs.append(cfg)
    return configs


def evaluate_policies(policies: Sequence[Callable], heightmaps, key: jax.Array, protocol: Protocol = HEADINGS,
                      backend: str = "jax", scale: TerrainScale | None = None, slots: int | None = None,
                      chunk: int | None = None, engine: str = "mjx", workers: int = 1,
                      randomisation: Randomisation | None = None, spawn: str | None = None) -> np.ndarray:
    """Fitness ``[P, N]`` float32 in [0, 1] of ``P`` policies on ``heightmaps`` [N, H, W] in [0, 1].

    ``protocol``: the walks (default :data:`HEADINGS`: 20 in each of 4 headings, best 5 per heading, mean over
    headings); ``backend``: ``"jax"`` (MJX) or ``"warp"`` (MuJoCo Warp on tiles); ``slots`` / ``chunk``: a rollout
    pool and terrains per call (:func:`jaxterrain.difficulty.evaluate`), to bound device memory on large suites.
    ``engine``: ``"mjx"`` (default) or ``"mujoco"``: MuJoCo's C engine on ``workers`` CPU processes
    (:mod:`jaxterrain.difficulty.replay`: the same starts and protocol; ``backend`` must then be ``"jax"`` and
    ``slots`` / ``chunk`` None). ``randomisation``: a randomised protocol (every walk draws its physics from its
    reset key, so every policy meets the same draws; None: the nominal physics; MJX only). ``spawn``: how every
    walker is set down at a reset (``jaxterrain.walker.SPAWNS``; None: the walker's default, ``feet``). Every
    policy walks with ``key``. ValueError for no policy at all."""
    if isinstance(policies, (str, bytes)) or len(policies) == 0:
        raise ValueError(f"policies: give at least one policy (a sequence of rl.load_policy policies); got "
                         f"{policies!r}")
    if engine not in replay.ENGINES:
        raise ValueError(f"engine must be one of {replay.ENGINES}, got {engine!r}")
    if engine == "mujoco" and (backend != "jax" or slots is not None or chunk is not None):
        raise ValueError(f"engine 'mujoco' steps MuJoCo C on the CPU: backend must be 'jax' and slots / chunk None "
                         f"(got backend={backend!r}, slots={slots!r}, chunk={chunk!r})")
    h = difficulty.validate_heightmaps(heightmaps)
    scale = TerrainScale() if scale is None else scale
    if engine == "mujoco" and randomisation is not None and randomisation_active(randomisation):
        raise ValueError("engine 'mujoco' walks the nominal physics (MuJoCo C steps one model for every walk); "
                         "randomisation needs engine 'mjx'")
    configs = check_policies(policies, tuple(h.shape[1:]), scale, backend, randomisation, spawn)
    if engine == "mujoco":
        if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
            raise ValueError(f"workers must be an int >= 1, got {workers!r}")
        pool = replay.make_pool(workers) if workers > 1 else None
        try:
            return np.stack([replay.mujoco_evaluate(h, key, p, protocol, env_config=cfg, pool=pool)
                             for p, cfg in zip(policies, configs)]).astype(np.float32)
        finally:
            if pool is not None:
                pool.terminate()
    out = []
    for p, cfg in zip(policies, configs):
        apply = policy_fn(p.config, int(p.action_size))  # weights as data: one program per network and walker config
        weights = ({"policy": p.params["policy"]}, p.normaliser)  # the actor alone: a base policy's value net too
        out.append(np.asarray(difficulty.evaluate(h, key, policy=apply, policy_params=weights,  # would re-compile
                                                  env_config=cfg, protocol=protocol, slots=slots, chunk=chunk)))
    return np.stack(out).astype(np.float32)


def level_fitness(fitness, suite: Suite) -> dict[str, np.ndarray]:
    """``{family: [levels] float64}``: the mean fitness of each level's terrains (NaN for a level the suite lacks,
    e.g. a generator sample band no random genome reached). ``fitness``: [N], one policy's."""
    f = np.asarray(fitness, np.float64)
    out = {}
    for fam in suite.families():
        rows = suite.family == fam
        levels = int(suite.level[rows].max()) + 1
        out[fam] = np.array([f[rows & (suite.level == lv)].mean() if np.any(rows & (suite.level == lv)) else np.nan
                             for lv in range(levels)])
    return out


def highest_level_passed(per_level, threshold: float = THRESHOLD) -> int:
    """The highest level ``k`` such that every level ``0..k`` is passed (mean fitness ``per_level[lv] >=
    threshold``), -1 when the first level fails. ``per_level``: [levels] mean fitness, easiest first; a NaN (a level
    the suite lacks, e.g. a generator band no random genome reached) is neither passed nor failed: it is stepped over.

    >>> highest_level_passed([0.95, 0.93, 0.5, 0.91])   # level 3 passes, but above the failed level 2
    1
    >>> highest_level_passed([float("nan"), 0.95, 0.92])
    2
    """
    k = -1
    for lv, m in enumerate(np.asarray(per_level, np.float64)):
        if np.isnan(m):
            continue
        if m < threshold:
            break
        k = lv
    return k


def passed_levels(fitness, suite: Suite, threshold: float = THRESHOLD) -> dict[str, int]:
    """``{family: the highest level passed with every level below it passed}`` (:func:`highest_level_passed` of
    :func:`level_fitness`; -1: level 0 fails). ``fitness``: [N], one policy's."""
    return {fam: highest_level_passed(per_level, threshold)
            for fam, per_level in level_fitness(fitness, suite).items()}


def cell_scores(fitness, family, level) -> tuple[list, np.ndarray]:
    """The suite's cells as tasks: ``(cells, scores)`` with ``cells`` the ``(family, level)`` pairs in order of first
    appearance and ``scores`` [P, C] the mean fitness of each cell's terrains (its seeds) for each of the ``P``
    policies of ``fitness`` [P, N]. ``family`` / ``level``: [N], the terrains' (``Suite.family``, ``Suite.level``
    or ``read_fitness``'s). ``ValueError`` naming the argument for other shapes or a NaN / inf fitness."""
    try:
        f = np.atleast_2d(np.asarray(fitness, np.float64))
    except (TypeError, ValueError):
        raise ValueError(f"fitness must be a [P, N] array of numbers; got {type(fitness).__name__}") from None
    fam, lv = np.asarray(family), np.asarray(level)
    if f.ndim != 2 or f.shape[1] < 1:
        raise ValueError(f"fitness must have shape [P, N] (or [N]) with N >= 1; got shape {f.shape}")
    if not np.all(np.isfinite(f)):
        raise ValueError("fitness must be finite (a NaN or inf would poison its cell's mean)")
    for name, a in (("family", fam), ("level", lv)):
        if a.shape != (f.shape[1],):
            raise ValueError(f"{name} must have shape [N] = ({f.shape[1]},) like fitness' last axis; got shape "
                             f"{a.shape}")
    cells = list(dict.fromkeys(zip(fam.tolist(), lv.tolist())))
    scores = np.stack([f[:, (fam == c[0]) & (lv == c[1])].mean(axis=1) for c in cells], axis=1)
    return cells, scores


def generator_robustness(fitness, family, alpha: float = CVAR_ALPHA) -> dict[str, dict[str, float]]:
    """``{generator: {"samples", "mean", "cvar"}}`` for one policy's ``fitness`` [N] over the terrains whose
    ``family`` [N] is ``gen:<generator>``: the mean fitness and the CVaR at ``alpha`` (the mean of the worst
    ``alpha`` fraction: :func:`jaxterrain.runtime.statistics.cvar`) of every sample of that generator; empty for a
    suite without generator samples. v2 keeps every draw (a random sample of each generator); v1 kept the first 3
    of each descriptor band, so there the figure is over a band-balanced set, not the generator's distribution."""
    f, fam = np.asarray(fitness, np.float64), np.asarray(family)
    if f.shape != fam.shape:
        raise ValueError(f"fitness and family must both have shape [N]; got {f.shape} and {fam.shape}")
    out = {}
    for g in dict.fromkeys(x for x in fam.tolist() if x.startswith("gen:")):
        x = f[fam == g]
        out[g[4:]] = {"samples": int(x.size), "mean": float(x.mean()), "cvar": cvar(x, alpha)}
    return out
