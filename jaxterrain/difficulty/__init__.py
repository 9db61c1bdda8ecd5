"""Terrain difficulty by the base policy (paper 3.3): fitness = mean of the best ``best`` of ``attempts`` normalised
distances walked; difficulty = 1 - fitness.

- :mod:`~jaxterrain.difficulty.protocol`: :class:`Protocol` (how many walks, which count, in which headings),
  :data:`PAPER`, :data:`HEADINGS`, and the pure functions from distances to fitness;
- :mod:`~jaxterrain.difficulty.evaluation`: :func:`evaluate` (host, cached compiled programs), :func:`fitness_fn`
  (pure, for MAP-Elites), the base policy and its env;
- :mod:`~jaxterrain.difficulty.replay`: the same protocol walked by MuJoCo's C engine on the CPU cores (sim2sim:
  :func:`~jaxterrain.difficulty.replay.mujoco_evaluate`);
- :mod:`~jaxterrain.difficulty.fitness`: the one table of named fitness functions (``--fitness``) and of protocol
  names (``--protocol``).

The rollout loops themselves are the walker's (:mod:`jaxterrain.walker.rollout`).
"""

from jaxterrain.difficulty.evaluation import (
    evaluate,
    fitness_fn,
    keyed_distances,
    protocol_distances,
    rollout_distances,
    timed_distances,
    validate_heightmaps,
)
from jaxterrain.difficulty.policies import (
    check_observation,
    default_env_config,
    default_policy,
    policy_observation,
    policy_robot,
    policy_scan_noise,
    policy_solver,
    robot_base_policy,
    with_policy_observation,
)
from jaxterrain.difficulty.fitness import FITNESSES, PROTOCOLS, difficulty_fitness, named_fitness, slope_fitness
from jaxterrain.difficulty.protocol import (
    HEADINGS,
    HEADING_TURNS,
    PAPER,
    Protocol,
    RULES,
    aggregate,
    best_of,
    heading_scores,
    protocol_env_config,
    rotate_headings,
)
from jaxterrain.difficulty import replay  # noqa: E402  (after evaluation, which it imports)
from jaxterrain.difficulty.replay import ENGINES, mujoco_evaluate
from jaxterrain.difficulty import base_policy, run_config  # noqa: E402  (the base policy's training run)
from jaxterrain.difficulty.base_policy import BasePolicyResult, train_base_policy, validate_base_run
from jaxterrain.difficulty.run_config import BasePolicyRun

__all__ = [
    "base_policy",
    "run_config",
    "BasePolicyRun",
    "BasePolicyResult",
    "train_base_policy",
    "validate_base_run",
    "replay",
    "ENGINES",
    "mujoco_evaluate",
    "Protocol",
    "PAPER",
    "HEADINGS",
    "RULES",
    "HEADING_TURNS",
    "aggregate",
    "best_of",
    "heading_scores",
    "rotate_headings",
    "protocol_env_config",
    "evaluate",
    "rollout_distances",
    "timed_distances",
    "fitness_fn",
    "protocol_distances",
    "keyed_distances",
    "validate_heightmaps",
    "default_policy",
    "default_env_config",
    "policy_robot",
    "policy_observation",
    "policy_scan_noise",
    "with_policy_observation",
    "check_observation",
    "robot_base_policy",
    "policy_solver",
    "FITNESSES",
    "PROTOCOLS",
    "slope_fitness",
    "difficulty_fitness",
    "named_fitness",
]
