"""Paper Algorithm 1: the traversability filter (no window of the terrain rises more than a third of the robot's
height), and the largest window range it is computed from."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain.features.kernels import as_batch, check_heights, check_window, roughness_core
from jaxterrain.runtime import validation
from jaxterrain.terrain import TerrainScale, validate_scale

__all__ = ["HUMANOID_HEIGHT", "max_window_range", "is_traversable"]

# Standing height of brax's humanoid (brax/envs/assets/humanoid.xml), measured with MuJoCo at the model's initial
# pose: top of the head (sphere "head" at z = 1.59, radius 0.09 -> 1.68 m) minus the sole of the feet (spheres
# "left_foot"/"right_foot" at z = 0.182, radius 0.075 -> 0.107 m) = 1.573 m. (The often-quoted 1.4 m is the
# spawn height of the torso's centre, body "torso" pos="0 0 1.4", not the standing height.)
HUMANOID_HEIGHT = 1.57




def max_window_range(heightmaps, window: int = 26) -> jax.Array:
    """Largest ``max - min`` over all ``window x window`` windows (stride 1, VALID): ``[B, H, W]`` -> ``[B]``."""
    h, single = as_batch(heightmaps)
    window, _ = check_window(h.shape, window, 1)
    out = jnp.max(roughness_core(h, window, 1), axis=(1, 2))
    return out[0] if single else out


def is_traversable(
    heightmaps, robot_height: float = HUMANOID_HEIGHT, window: int = 26, scale: TerrainScale = TerrainScale()
) -> jax.Array:
    """Paper Algorithm 1: a terrain is traversable unless some ``window x window`` patch rises more than
    ``robot_height / 3`` (metres) between its lowest and highest point.

    Returns ``max over windows (max - min) * scale.height <= robot_height / 3``. The paper's loop visits
    ``rows - k`` window rows (``range(0, rows - k)``), which skips the last row/column of windows; we check every
    VALID window (``rows - k + 1`` of them), so a step in the last ``k`` rows is not missed.

    Args:
      heightmaps: ``[B, H, W]`` (or ``[H, W]``) heightmaps in heightmap units, in [0, 1]; concrete input holding NaN
        or values outside [0, 1] raises ``ValueError`` (not checked under jit).
      robot_height: metres, > 0. Default :data:`HUMANOID_HEIGHT` (brax humanoid, 1.57 m).
      window: k, 2 <= k <= min(H, W); paper 26 ("approx. step length of robot"; 1.04 m at the default scale).
      scale: :class:`jaxterrain.terrain.TerrainScale` giving metres per heightmap unit.

    Returns:
      ``[B]`` bool (``[]`` for a single map).
    """
    validation.positive("robot_height (metres)", robot_height)  # concrete values: numbers and [] arrays alike
    validate_scale(scale)
    h, single = as_batch(heightmaps)
    check_heights(h, single)
    rng = max_window_range(h[0] if single else h, window)
    return rng * scale.height <= robot_height / 3.0
