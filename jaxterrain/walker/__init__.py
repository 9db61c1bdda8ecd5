"""The walker: a robot (default brax's humanoid; ``WalkerConfig(robot="ant")`` brax's quadruped, or any
:class:`RobotSpec` you register) in MuJoCo MJX on a heightfield passed as data (see :mod:`jaxterrain.walker.env`).

Modules: :mod:`.robots` (robot specs and their registry), :mod:`.model` (the MJCF and solver options), :mod:`.env` (reset / step / park), :mod:`.randomisation` (physics randomisation: friction, masses, motors, noise, delay, pushes), :mod:`.tiles` (terrains as
tiles of one heightfield), :mod:`.layout` (classic vs tiles, env sizing, the backend ``auto`` resolves to: the one
home of the layout), :mod:`.rollout` (batched walks and the rollout pool), :mod:`.mujoco_c` (MuJoCo's C engine
stepping the same walks on the CPU: sim2sim) and :mod:`.warp_patch` (the local-origin fix of MuJoCo Warp's heightfield
collision, applied to MJX's vendored copy: ``python -m experiments warp-patch``).

    from jaxterrain.walker import WalkerEnv, WalkerConfig, flat_terrain
    env = WalkerEnv(WalkerConfig())
    terrain = flat_terrain(env.config)                         # [256, 256] float32 metres
    state = env.reset(key, terrain)
    state = env.step(state, action, terrain)                   # action [17] in [-1, 1]

Per-env terrains as tiles of one heightfield (needed by the MuJoCo Warp backend, works under MJX-JAX too):

    env = WalkerEnv(WalkerConfig(tiles=T, backend="warp"))    # or backend="jax"
    bank = env.make_bank(terrains)                             # [T, H, W] metres -> TileBank (device pytree)
    state = jax.vmap(env.reset, in_axes=(0, TILE_AXES))(keys, bank.at(idx))   # idx [N] int32 tile per env
    state = jax.vmap(env.step, in_axes=(0, 0, TILE_AXES))(state, actions, bank.at(idx))
    state = env.select(done, reset_state, state)               # auto-reset (never tree-map jnp.where over data)
"""

from jaxterrain.walker import robots
from jaxterrain.walker.robots import RobotSpec, register_robot
from jaxterrain.walker.config import (BACKENDS, OBSERVATIONS, SCAN_FIELDS, SPAWNS, WalkerConfig, flat_terrain,
                                      min_terrain_side, observation_fields, observation_label, resolve_config,
                                      scan_size, with_observation)
from jaxterrain.walker.env import WalkerEnv, WalkerState
from jaxterrain.walker.surface import sample_heights
from jaxterrain.walker.model import (
    NAMED_SOLVERS,
    SOLVER_FAST,
    SOLVER_SOUND,
    SOLVER_XML,
    SolverOptions,
    TerrainScale,
    build_model,
    build_spec,
    humanoid_xml,
    metres_to_hfield,
    parse_solver,
    solver_label,
    standing_offset,
)
from jaxterrain.walker.tiles import TILE_AXES, Tile, TileBank, warp_available
from jaxterrain.walker import warp_patch
from jaxterrain.walker import randomisation
from jaxterrain.walker.randomisation import (PRESETS as RANDOMISATION_PRESETS, Randomisation, parse_randomisation,
                                             randomisation_from_json, randomisation_json, randomisation_label)
from jaxterrain.walker import layout, rollout  # noqa: E402  (after env / tiles, which they import)
from jaxterrain.walker.layout import (BACKEND_CHOICES, carry_rows, env_for, is_tiled, make_env, resolve_backend,
                                      sized_env, terrain_batch)
from jaxterrain.walker.rollout import batched_distances, job_queue, smoothness_priority
from jaxterrain.walker import mujoco_c  # noqa: E402  (after env, which it imports)
from jaxterrain.walker.mujoco_c import CEngine

__all__ = [
    "robots",
    "RobotSpec",
    "register_robot",
    "resolve_config", "min_terrain_side",
    "layout",
    "rollout",
    "mujoco_c",
    "CEngine",
    "BACKEND_CHOICES",
    "env_for",
    "is_tiled",
    "make_env",
    "resolve_backend",
    "sized_env",
    "terrain_batch",
    "batched_distances",
    "job_queue",
    "smoothness_priority",
    "BACKENDS",
    "OBSERVATIONS",
    "SPAWNS",
    "SCAN_FIELDS",
    "observation_fields",
    "observation_label",
    "scan_size",
    "with_observation",
    "TILE_AXES",
    "Tile",
    "TileBank",
    "warp_available",
    "warp_patch",
    "randomisation",
    "RANDOMISATION_PRESETS",
    "Randomisation",
    "parse_randomisation",
    "randomisation_from_json",
    "randomisation_json",
    "randomisation_label",
    "WalkerConfig",
    "WalkerEnv",
    "WalkerState",
    "carry_rows",
    "flat_terrain",
    "sample_heights",
    "NAMED_SOLVERS",
    "SOLVER_FAST",
    "SOLVER_SOUND",
    "SOLVER_XML",
    "SolverOptions",
    "TerrainScale",
    "build_model",
    "build_spec",
    "humanoid_xml",
    "metres_to_hfield",
    "parse_solver",
    "solver_label",
    "standing_offset",
]
