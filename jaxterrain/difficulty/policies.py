"""Which walker a policy walks: the env config built for a policy from what it records (its robot, contact
solver and observation set: :func:`default_env_config`), the check that an env observes what the policy does
(:func:`check_observation`), and the shipped base policies (:func:`default_policy`, :func:`robot_base_policy`,
each loaded once). :mod:`jaxterrain.difficulty.evaluation` and every command that walks a policy build their env
here."""

from __future__ import annotations

import functools
from typing import Callable, Optional

from jaxterrain.rl import base_policy_dir, load_policy
from jaxterrain.terrain import TerrainScale
from jaxterrain.walker import (BACKENDS, OBSERVATIONS, SolverOptions, WalkerConfig, observation_fields,
                               observation_label)
from jaxterrain.walker.robots import get as get_robot

__all__ = ["default_policy", "policy_solver", "policy_robot", "policy_observation", "policy_scan_noise",
           "with_policy_observation", "check_observation", "default_env_config", "robot_base_policy"]


@functools.lru_cache(maxsize=1)
def default_policy() -> Callable:
    """The shipped base policy (``jaxterrain.rl.load_policy()``), loaded once."""
    try:
        return load_policy()
    except FileNotFoundError as err:
        raise RuntimeError(f"policy=None needs the shipped base policy, which is missing ({err}); "
                           "pass policy= explicitly") from err


def policy_solver(policy: Callable) -> Optional[SolverOptions]:
    """The solver options a policy was trained with, when it records them (``policy.meta["walker_config"]
    ["solver"]``, as :func:`jaxterrain.rl.load_policy` policies do), else None. A policy walks as trained only
    under the same contact solver (benchmarks/RESULTS.md), so the default env of :func:`evaluate` uses them."""
    solver = ((getattr(policy, "meta", None) or {}).get("walker_config") or {}).get("solver")
    return None if solver is None else SolverOptions(**solver)


def policy_robot(policy: Callable) -> str:
    """The robot a policy was trained on (``policy.meta["walker_config"]["robot"]``); ``"humanoid"`` for policies
    that do not record one (every policy made before robot specs walked the humanoid)."""
    return ((getattr(policy, "meta", None) or {}).get("walker_config") or {}).get("robot") or "humanoid"


def policy_observation(policy: Callable) -> dict:
    """What a policy observes (:func:`jaxterrain.walker.observation_fields` of its recorded ``walker_config``):
    ``{"observation": "blind"}`` for policies that record none (every policy before observation sets was blind),
    else the set and, when perceptive, its scan grid. ``ValueError`` when the record names an unknown set."""
    return observation_fields(dict((getattr(policy, "meta", None) or {}).get("walker_config") or {}))


def policy_scan_noise(policy: Callable) -> float:
    """The scan noise (m) a policy was trained with (``walker_config.scan_noise``; 0 when it records none)."""
    return float(((getattr(policy, "meta", None) or {}).get("walker_config") or {}).get("scan_noise") or 0.0)


def with_policy_observation(config: WalkerConfig, policy: Callable) -> WalkerConfig:
    """``config`` observing what ``policy`` observes (:func:`policy_observation`; its scan grid and scan noise):
    how every env built to walk a policy gets its observation set."""
    fields = policy_observation(policy)
    config = config._replace(**fields)
    return config._replace(scan_noise=policy_scan_noise(policy)) if fields["observation"] == "perceptive" else config


def check_observation(policy: Callable, env_config: WalkerConfig) -> None:
    """``ValueError``, one line naming both, when ``env_config`` observes another set (or scan grid) than
    ``policy`` records (:func:`policy_observation`); policies without a record (a bare callable) are not checked
    here (their observation size is)."""
    if getattr(policy, "meta", None) is None:
        return
    want, have = policy_observation(policy), observation_fields(env_config)
    if want != have:
        where = getattr(policy, "path", None)
        raise ValueError(f"observation mismatch: the policy{f' {where}' if where else ''} observes "
                         f"{observation_label(want)}, the env {observation_label(have)}")


def default_env_config(shape: tuple[int, int], scale: Optional[TerrainScale] = None, policy: Optional[Callable] = None,
                       backend: str = "jax") -> WalkerConfig:
    """``WalkerConfig(terrain_shape=shape, scale=scale)`` with the policy's own robot and solver options when it
    records them, and its observation set (:func:`with_policy_observation`) (``scale`` None: ``TerrainScale()``;
    ``policy`` None: the shipped base policy).

    ``backend``: ``"jax"`` (MJX-JAX, the classic layout: one heightfield per env) or ``"warp"`` (MuJoCo Warp, on
    tiles: ``tiles=1``, which the rollout loops size to each call, :mod:`jaxterrain.walker.rollout`). Pass the result as
    ``env_config`` to :func:`evaluate` / :func:`rollout_distances`; ``fitness_fn(..., backend=)`` takes the name.
    For MJX-JAX on tiles set ``tiles=1`` yourself (``config._replace(tiles=1)``)."""
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    policy = default_policy() if policy is None else policy
    solver = policy_solver(policy)
    config = WalkerConfig(terrain_shape=tuple(shape), scale=TerrainScale() if scale is None else scale,
                          robot=policy_robot(policy))
    config = config if solver is None else config._replace(solver=solver)
    config = with_policy_observation(config, policy)
    return config if backend == "jax" else config._replace(backend=backend, tiles=1)


def robot_base_policy(robot: str = "humanoid", observation: str = "blind") -> Callable:
    """The shipped base policy of ``robot``: :func:`default_policy` for the blind humanoid, else
    ``rl.base_policy_dir(robot, observation)`` (loaded once). ``ValueError`` naming the robot / observation set when
    it is unknown or has none shipped."""
    get_robot(robot)
    if observation not in OBSERVATIONS:
        raise ValueError(f"observation must be one of {', '.join(OBSERVATIONS)}, got {observation!r}")
    if robot == "humanoid" and observation == "blind":
        return default_policy()
    return _robot_policy(robot, observation)


@functools.lru_cache(maxsize=None)
def _robot_policy(robot: str, observation: str = "blind") -> Callable:
    folder = base_policy_dir(robot, observation)
    if not (folder / "policy.msgpack").is_file():
        how = (f"python -m experiments perceptive-policy --robot {robot} --export-assets"
               if observation == "perceptive" else
               f"python -m experiments train-base-policy --robot {robot} --preset gpu --export-assets")
        which = "perceptive base policy" if observation == "perceptive" else "base policy"
        raise ValueError(f"robot {robot!r}: no {which} is shipped for it ({folder}); make one with `{how}`")
    return load_policy(folder)
