"""The walker: brax's humanoid in MuJoCo MJX on a heightfield passed as data (see :mod:`jaxterrain.walker.env`).

    from jaxterrain.walker import WalkerEnv, WalkerConfig, flat_terrain
    env = WalkerEnv(WalkerConfig())
    terrain = flat_terrain(env.config)                         # [256, 256] float32 metres
    state = env.reset(key, terrain)
    state = env.step(state, action, terrain)                   # action [17] in [-1, 1]
"""

from jaxterrain.walker.env import WalkerConfig, WalkerEnv, WalkerState, flat_terrain, sample_heights
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

__all__ = [
    "WalkerConfig",
    "WalkerEnv",
    "WalkerState",
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
