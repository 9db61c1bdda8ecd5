"""PPO in flax + optax whose training step is a pure function of (state, key, terrains).

The pure algorithm is :mod:`jaxterrain.rl.ppo` (the env protocol), its host driver :mod:`jaxterrain.rl.training`,
its files :mod:`jaxterrain.rl.checkpoint`; see :mod:`jaxterrain.rl.ppo` for the env protocol and :class:`PPOConfig` for the hyperparameters (brax's MJX
humanoid recipe). Public API::

    PPOConfig, TrainState, init, update, run_updates, ride_updates, Ride, make_train, train, chunk_fn, reset_envs,
    raw_key, Progress,
    gae, ppo_loss, save_checkpoint, load_checkpoint, save_policy, save_actor_only, load_policy,
    widen_inputs, scan_statistics, perceptive_twin   (a blind policy's perceptive twin: jaxterrain.rl.perception)
    export_onnx, onnx_metadata, read_onnx_metadata   (jaxterrain.rl.onnx; needs the extra jaxterrain[onnx])
"""

from jaxterrain.rl.checkpoint import (
    BASE_POLICY_DIR,
    base_policy_dir,
    checkpoint_metadata,
    load_checkpoint,
    load_policy,
    policy_fn,
    save_actor_only,
    save_checkpoint,
    save_policy,
)
from jaxterrain.rl.config import PPOConfig, validate_config
from jaxterrain.rl.losses import gae, ppo_loss
from jaxterrain.rl.perception import PerceptiveTwin, perceptive_twin, scan_statistics, widen_inputs
from jaxterrain.rl.onnx import export_onnx, onnx_metadata, read_onnx_metadata
from jaxterrain.rl.networks import RunningStats, deterministic_action, init_stats, normalize, update_stats
from jaxterrain.rl.ppo import (
    init,
    loss_fn,
    make_optimizer,
    make_train,
    reset_envs,
    ride_updates,
    run_updates,
    scale_scan_rows,
    update,
)
from jaxterrain.rl.state import EpisodeStats, Ride, TrainState, Transition, raw_key
from jaxterrain.rl.training import Progress, chunk_fn, compiled_chunk, train

__all__ = [
    "BASE_POLICY_DIR", "base_policy_dir", "EpisodeStats", "PPOConfig", "Progress", "RunningStats", "TrainState", "Transition",
    "checkpoint_metadata", "chunk_fn", "compiled_chunk", "deterministic_action", "export_onnx", "gae", "init",
    "init_stats",
    "load_checkpoint", "load_policy", "loss_fn", "make_optimizer", "make_train", "normalize", "policy_fn", "ppo_loss",
    "onnx_metadata", "raw_key", "read_onnx_metadata", "reset_envs", "Ride", "ride_updates", "run_updates", "scale_scan_rows", "save_actor_only", "save_checkpoint", "save_policy", "train", "update",
    "update_stats",
    "validate_config", "PerceptiveTwin", "perceptive_twin", "scan_statistics", "widen_inputs",
]
