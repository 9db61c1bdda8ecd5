"""PPO hyperparameters: one typed, immutable config (optax / evosax style)."""

from __future__ import annotations

import math
from typing import NamedTuple, Optional, Tuple

from jaxterrain.runtime.validation import int_at_least, known_fields, one_of

__all__ = ["ACTIVATIONS", "DISTRIBUTIONS", "TRUNCATIONS", "PPOConfig", "validate_config"]

ACTIVATIONS = ("swish", "relu", "tanh", "elu")
DISTRIBUTIONS = ("tanh_normal", "normal")
TRUNCATIONS = ("mask", "bootstrap")


class PPOConfig(NamedTuple):
    """Hyperparameters of :mod:`jaxterrain.rl` PPO. Static: changing one re-compiles.

    Defaults reproduce brax's PPO recipe for the MJX humanoid, which trains a walking humanoid in 20 M env steps:
    the MuJoCo MJX tutorial (``mjx/tutorial.ipynb``, "Training a Policy with MJX") calls ``brax.training.agents.ppo.
    train`` with ``num_timesteps=20_000_000, reward_scaling=0.1, episode_length=1000, normalize_observations=True,
    action_repeat=1, unroll_length=10, num_minibatches=24, num_updates_per_batch=8, discounting=0.97,
    learning_rate=3e-4, entropy_cost=1e-3, num_envs=3072, batch_size=512``; the rest are brax 0.14.2's own defaults
    (``brax/training/agents/ppo/train.py``, ``losses.py``, ``networks.py``): ``gae_lambda=0.95,
    clipping_epsilon=0.3, vf_loss_coefficient=0.5`` (times 0.5 inside the loss), ``normalize_advantage=True``,
    ``max_grad_norm=None``, Adam, policy MLP ``(32,) * 4``, value MLP ``(256,) * 5``, swish, LeCun-uniform init,
    tanh-squashed Gaussian with state-dependent scale ``softplus(x) + 0.001``.

    Brax's ``batch_size`` x ``num_minibatches`` (512 x 24 = 12 288 trajectories of ``unroll_length``) is spelled
    here as ``num_unrolls`` x ``num_envs`` (4 x 3072): each update collects ``num_unrolls`` consecutive unrolls of
    ``unroll_length`` steps from all ``num_envs`` envs = 122 880 env steps, then runs ``update_epochs`` passes of
    ``num_minibatches`` Adam steps over shuffled trajectory segments (192 gradient steps per update).

    For comparison, SpinningUp's PPO defaults (gamma 0.99, lambda 0.97, clip 0.2, lr 3e-4, 4000 steps per epoch,
    80 policy iterations with target KL 0.01, (64, 64) tanh MLPs) are tuned for single-env CPU gym; they are not
    what makes a massively parallel MJX humanoid learn in minutes, so they are not the defaults.

    Fields:
      num_envs: parallel environments.
      unroll_length: env steps per trajectory segment (GAE horizon; the value bootstraps after it).
      num_unrolls: consecutive segments collected per update (per env).
      num_minibatches: minibatches per epoch; must divide ``num_unrolls * num_envs``.
      update_epochs: passes over the collected data per update.
      learning_rate: Adam step size.
      gamma: discount.
      gae_lambda: GAE lambda.
      clip_eps: PPO ratio clipping epsilon.
      entropy_coef: entropy bonus weight.
      vf_coef: value loss weight (the loss is ``vf_coef * 0.5 * mean((target - V)^2)``, as brax).
      max_grad_norm: global-norm gradient clipping, ``None`` = off (brax default).
      reward_scaling: rewards are multiplied by this inside the loss (episode returns are reported unscaled).
      normalize_observations: running (Welford) mean/std normalisation of observations for both networks.
      update_normaliser: with ``normalize_observations``, merge each update's observations into the running
        statistics (brax); False keeps the given statistics fixed, e.g. when fine-tuning a trained policy on data
        that would shift them.
      normalize_advantage: standardise advantages per minibatch.
      policy_hidden: hidden layer sizes of the policy MLP.
      value_hidden: hidden layer sizes of the value MLP.
      activation: one of ``swish, relu, tanh, elu``.
      action_distribution: ``tanh_normal`` (brax: tanh-squashed Gaussian, state-dependent scale
        ``softplus + min_std``, entropy estimated at one sample) or ``normal`` (Gaussian with a state-independent
        learned log-std initialised at ``log(init_std)``, actions clipped to [-1, 1] before the env).
      min_std: floor of the Gaussian scale (``tanh_normal``).
      init_std: initial scale of the ``normal`` distribution.
      truncation: what a step that ended at a time limit or the goal (``s.truncation = 1``) teaches the value.
        ``mask`` (brax): the step gets advantage 0 and target ``V(s_t)``, so its state's value is never trained,
        yet the step before bootstraps from it. ``bootstrap`` (SB3, Pardo et al. 2018): the step is a terminal one
        worth ``r_t + gamma V(s_final)``, with ``s_final`` the observation before the auto-reset and ``V`` the
        collecting params (one more value-net call per env step). Where those last states are unlike any other
        (the walker over a drop at the goal line), ``mask`` lets the value diverge: ``docs/results/
        exp2_paper.md``, "Why fine-tuning collapses".
      scan_inputs: how many trailing observation entries are a height scan (0: none; a perceptive walker's
        ``WalkerEnv`` appends its scan last). Only :attr:`scan_lr_scale` reads it.
      scan_lr_scale: Adam's step on the first-layer weights that read those ``scan_inputs`` entries, in both
        networks, as a multiple of every other weight's (1.0: no difference). Many correlated scan inputs under
        per-weight Adam steps move the first layer several times as far as the rest of the observation does
        (``docs/results/exp4/scan_diag/``: 7.7-9.8x for the humanoid's 153-entry scan); about
        ``1 / sqrt(scan_inputs)`` evens that out.
    """

    num_envs: int = 3072
    unroll_length: int = 10
    num_unrolls: int = 4
    num_minibatches: int = 24
    update_epochs: int = 8
    learning_rate: float = 3e-4
    gamma: float = 0.97
    gae_lambda: float = 0.95
    clip_eps: float = 0.3
    entropy_coef: float = 1e-3
    vf_coef: float = 0.5
    max_grad_norm: Optional[float] = None
    reward_scaling: float = 0.1
    normalize_observations: bool = True
    update_normaliser: bool = True
    normalize_advantage: bool = True
    policy_hidden: Tuple[int, ...] = (32, 32, 32, 32)
    value_hidden: Tuple[int, ...] = (256, 256, 256, 256, 256)
    activation: str = "swish"
    action_distribution: str = "tanh_normal"
    min_std: float = 1e-3
    init_std: float = 1.0
    truncation: str = "mask"
    scan_inputs: int = 0
    scan_lr_scale: float = 1.0

    @property
    def steps_per_update(self) -> int:
        """Env steps collected by one :func:`jaxterrain.rl.update` call."""
        return self.num_envs * self.unroll_length * self.num_unrolls

    @property
    def minibatch_segments(self) -> int:
        """Trajectory segments (of ``unroll_length`` steps) per minibatch."""
        return self.num_envs * self.num_unrolls // self.num_minibatches

    def to_json_dict(self) -> dict:
        """A JSON-serialisable dict (tuples become lists)."""
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self._asdict().items()}

    @classmethod
    def from_json_dict(cls, d: dict) -> "PPOConfig":
        """Inverse of :meth:`to_json_dict`; unknown keys raise ``ValueError``."""
        known_fields("PPOConfig", cls._fields, d)
        return cls(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items()})


def validate_config(config: PPOConfig) -> PPOConfig:
    """Raise ``ValueError`` naming the first bad field and its allowed range; return ``config`` unchanged."""
    if not isinstance(config, PPOConfig):
        raise ValueError(f"config must be an rl.PPOConfig; got {type(config).__name__}")
    for name in ("num_envs", "unroll_length", "num_unrolls", "num_minibatches", "update_epochs"):
        int_at_least("PPOConfig", config, name, 1)
    int_at_least("PPOConfig", config, "scan_inputs", 0)
    if (config.num_envs * config.num_unrolls) % config.num_minibatches:
        raise ValueError(
            f"PPOConfig.num_minibatches ({config.num_minibatches}) must divide num_envs * num_unrolls "
            f"({config.num_envs} * {config.num_unrolls})"
        )
    ranges = {
        "learning_rate": (0.0, None, False),
        "gamma": (0.0, 1.0, True),
        "gae_lambda": (0.0, 1.0, True),
        "clip_eps": (0.0, None, False),
        "reward_scaling": (0.0, None, False),
        "min_std": (0.0, None, True),
        "init_std": (0.0, None, False),
        "scan_lr_scale": (0.0, None, False),
    }
    def number(name):
        raw = getattr(config, name)
        try:
            if isinstance(raw, (bool, str, bytes)):
                raise TypeError
            return float(raw)
        except (TypeError, ValueError):
            raise ValueError(f"PPOConfig.{name} must be a finite number, got {raw!r}") from None

    for name, (lo, hi, lo_inclusive) in ranges.items():
        v = number(name)
        ok = math.isfinite(v) and (v >= lo if lo_inclusive else v > lo) and (hi is None or v <= hi)
        if not ok:
            lo_s = f"{'>=' if lo_inclusive else '>'} {lo}"
            hi_s = f" and <= {hi}" if hi is not None else ""
            raise ValueError(f"PPOConfig.{name} must be a finite number {lo_s}{hi_s}, got {v!r}")
    for name in ("entropy_coef", "vf_coef"):
        v = number(name)
        if not (math.isfinite(v) and v >= 0):
            raise ValueError(f"PPOConfig.{name} must be a finite number >= 0, got {getattr(config, name)!r}")
    if config.max_grad_norm is not None:
        v = number("max_grad_norm")
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"PPOConfig.max_grad_norm must be None (off) or a finite number > 0, got "
                             f"{config.max_grad_norm!r}")
    for name in ("normalize_observations", "update_normaliser", "normalize_advantage"):
        if not isinstance(getattr(config, name), bool):
            raise ValueError(f"PPOConfig.{name} must be True or False, got {getattr(config, name)!r}")
    for name in ("policy_hidden", "value_hidden"):
        v = getattr(config, name)
        if not isinstance(v, tuple) or not all(isinstance(s, int) and not isinstance(s, bool) and s >= 1 for s in v):
            raise ValueError(f"PPOConfig.{name} must be a tuple of integers >= 1, got {v!r}")
    one_of("PPOConfig", config, "activation", ACTIVATIONS)
    one_of("PPOConfig", config, "action_distribution", DISTRIBUTIONS)
    one_of("PPOConfig", config, "truncation", TRUNCATIONS)
    return config
