"""Checkpoints of a whole :class:`~jaxterrain.rl.state.TrainState` and export / loading of a deterministic policy.

Checkpoint (``save_checkpoint``): the one checkpoint format of the project, ``jaxterrain.runtime.driver``'s npz (every leaf
under its tree path, e.g. ``.params['policy']['params']['mlp']['hidden_0']['kernel']``): params, Adam state,
normaliser, episode counters, key, step counters and (by default) the batched env state, so that a resumed run is
bit-identical to an uninterrupted one. ``done`` is the update step; the header's ``meta`` holds
``{"format": CHECKPOINT_FORMAT, "include_env_state": bool, "metadata": {...}}``. A ``run_dir/checkpoint.npz``
written by ``rl.train(..., run_dir=...)`` or ``jaxterrain.runtime.driver.run_chunks`` loads the same way.

Policy (``save_policy``): a folder with ``policy.msgpack`` (``{"params": {"policy", "value"}, "normaliser"}``)
and ``config.json`` (the :class:`PPOConfig`, observation and action sizes). ``load_policy()`` without a path
loads the shipped base policy from ``jaxterrain/assets/base_policy/``.
"""

from __future__ import annotations

import functools
import json
import os
from pathlib import Path
from typing import Any, Callable, Optional

import jax
import jax.numpy as jnp
import numpy as np
from flax import serialization

from jaxterrain.rl import networks as nets
from jaxterrain.rl.config import PPOConfig, validate_config
from jaxterrain.runtime import driver
from jaxterrain.runtime.io import atomic_write_bytes, atomic_write_text

__all__ = ["CHECKPOINT_FORMAT", "POLICY_FORMAT", "BASE_POLICY_DIR", "base_policy_dir", "save_checkpoint", "checkpoint_metadata",
           "load_checkpoint", "save_policy", "save_actor_only", "load_policy", "policy_fn", "POLICY_FIELDS"]

CHECKPOINT_FORMAT = "jaxterrain.rl.checkpoint/2"
POLICY_FORMAT = "jaxterrain.rl.policy/1"
BASE_POLICY_DIR = Path(__file__).resolve().parent.parent / "assets" / "base_policy"


def base_policy_dir(robot: str = "humanoid", observation: str = "blind") -> Path:
    """Where a robot's shipped base policy lives: :data:`BASE_POLICY_DIR` for the humanoid, ``assets/base_policy_<robot>/``
    for another (``train-base-policy --robot NAME --export-assets`` writes it there; it may not exist).
    ``observation="perceptive"``: its perceptive twin, ``assets/base_policy_perceptive/`` (the humanoid's) or
    ``assets/base_policy_<robot>_perceptive/`` (``python -m experiments perceptive-policy`` writes it)."""
    if observation not in ("blind", "perceptive"):
        raise ValueError(f"observation must be one of blind, perceptive, got {observation!r}")
    name = "base_policy" if robot == "humanoid" else f"base_policy_{robot}"
    return BASE_POLICY_DIR.parent / (name if observation == "blind" else f"{name}_perceptive")
# leaves added to TrainState since checkpoints were first written (read as the template's value when absent)
LEGACY_DEFAULTS = (".episode.progress",)


def save_checkpoint(path: str | os.PathLike, state: Any, include_env_state: bool = True,
                    metadata: Optional[dict] = None) -> Path:
    """Write ``state`` (a TrainState or any pytree of arrays) to ``path`` atomically (``jaxterrain.runtime.driver``'s npz).

    ``include_env_state=False`` leaves out ``state.env_state`` (smaller; :func:`load_checkpoint` then keeps the
    env state of ``like``). ``metadata``: a JSON-serialisable dict stored alongside (e.g. the config).
    """
    if not include_env_state and hasattr(state, "_replace"):
        state = state._replace(env_state=None)
    step = getattr(state, "update_step", None)
    done = int(np.max(np.asarray(step))) if step is not None else 0
    meta = {"format": CHECKPOINT_FORMAT, "include_env_state": bool(include_env_state), "metadata": metadata or {}}
    return driver.save_checkpoint(path, state, done=done, meta=meta)


def _header_meta(path: Path) -> dict:
    """The ``meta`` of a driver checkpoint's header, without a template state."""
    if not path.is_file():
        raise FileNotFoundError(f"checkpoint not found: {path}")
    try:
        with np.load(path, allow_pickle=False) as data:
            header = json.loads(bytes(data["header"]).decode("utf-8"))
    except (OSError, ValueError, KeyError, EOFError) as err:
        raise ValueError(f"{path}: not a readable jaxterrain checkpoint ({err})") from err
    return dict(header.get("meta") or {})


def checkpoint_metadata(path: str | os.PathLike) -> dict:
    """The ``metadata`` dict stored by :func:`save_checkpoint`."""
    return dict(_header_meta(Path(path)).get("metadata") or {})


def load_checkpoint(path: str | os.PathLike, like: Any) -> Any:
    """Read a checkpoint into the structure of ``like`` (e.g. a fresh ``init(...)`` state of the same config).

    Every leaf must be present with the same shape and dtype; otherwise ``ValueError`` names the leaf.
    """
    path = Path(path)
    meta = _header_meta(path)
    if meta.get("format", CHECKPOINT_FORMAT) != CHECKPOINT_FORMAT:  # no format: a driver run's checkpoint
        raise ValueError(f"{path}: not a {CHECKPOINT_FORMAT} file (format={meta.get('format')!r})")
    keep_env = not meta.get("include_env_state", True) and hasattr(like, "_replace")
    target = like._replace(env_state=None) if keep_env else like
    restored, _, _, _ = driver.load_checkpoint(path, target, defaults=LEGACY_DEFAULTS)
    if keep_env:
        restored = restored._replace(env_state=like.env_state)
    return restored


# ----------------------------------------------------------------------------------------------------------------
# Policy export
# ----------------------------------------------------------------------------------------------------------------
def save_policy(path: str | os.PathLike, params: Any, normaliser: nets.RunningStats, config: PPOConfig,
                observation_size: int, action_size: int, extra: Optional[dict] = None,
                actor_only: bool = False) -> Path:
    """Write ``path/policy.msgpack`` and ``path/config.json`` (atomically). ``extra`` is merged into config.json
    (e.g. the env config). ``actor_only``: keep the policy network and drop the value network (``config.json`` says
    ``"actor_only": true``): enough to walk and evaluate, not to go on training; the base walker's is 24 KB instead
    of 1.1 MB, which is how released walkers are shipped. Returns the folder."""
    path = Path(path)
    if actor_only:
        params = {"policy": params["policy"]}
    blob = {
        "format": POLICY_FORMAT,
        "params": jax.tree_util.tree_map(lambda x: np.asarray(jax.device_get(x)), params),
        "normaliser": {k: np.asarray(jax.device_get(v)) for k, v in normaliser._asdict().items()},
    }
    atomic_write_bytes(path / "policy.msgpack", serialization.msgpack_serialize(blob))
    meta = {
        "format": POLICY_FORMAT,
        "observation_size": int(observation_size),
        "action_size": int(action_size),
        "ppo_config": config.to_json_dict(),
    }
    meta.update(extra or {})
    meta["actor_only"] = bool(actor_only)
    atomic_write_text(path / "config.json", json.dumps(meta, indent=2, sort_keys=True) + "\n")
    return path


def save_actor_only(src: str | os.PathLike, dst: str | os.PathLike) -> Path:
    """Copy the policy folder ``src`` (:func:`save_policy`'s) to ``dst`` without its value network (``actor_only``):
    the same deterministic actions, ~24 KB instead of ~1.1 MB for the humanoid's walker; enough to walk, evaluate
    and export, not to go on training. ``config.json`` keeps every other field of ``src``'s. Returns ``dst``."""
    policy = load_policy(src)
    extra = {k: v for k, v in policy.meta.items() if k != "actor_only"}
    return save_policy(dst, policy.params, policy.normaliser, policy.config, policy.observation_size,
                       policy.action_size, extra=extra, actor_only=True)


def _to_jnp(tree):
    return jax.tree_util.tree_map(jnp.asarray, tree)


def load_policy(path: str | os.PathLike | None = None) -> Callable[[jax.Array], jax.Array]:
    """Load a policy saved by :func:`save_policy`; without ``path`` the shipped base policy
    (``jaxterrain/assets/base_policy/``).

    Returns ``policy(obs [..., O]) -> action [..., A]`` in [-1, 1], the deterministic (mean) action, a pure
    function (jit / vmap it). Attributes: ``.params`` (``{"policy", "value"}``; ``{"policy"}`` alone for a policy
    saved with ``actor_only``), ``.normaliser``, ``.config``
    (:class:`PPOConfig`), ``.observation_size``, ``.action_size``, ``.meta`` (config.json), ``.path``.
    """
    folder = Path(path) if path is not None else BASE_POLICY_DIR
    if folder.is_file():
        folder = folder.parent
    weights = folder / "policy.msgpack"
    if not weights.is_file():
        if path is None:
            raise FileNotFoundError(
                f"the base policy is not shipped yet ({weights} is missing); train it with "
                "`python -m experiments train-base-policy --preset gpu --export-assets`")
        raise FileNotFoundError(f"no policy.msgpack in {folder}")
    config, meta, action_size, params, normaliser = _read_policy(folder, weights)

    def policy(obs: jax.Array) -> jax.Array:
        return nets.deterministic_action(config, action_size, params, normaliser, jnp.asarray(obs, jnp.float32))

    policy.params, policy.normaliser, policy.config = params, normaliser, config
    policy.observation_size, policy.action_size = int(meta["observation_size"]), action_size
    policy.meta, policy.path = meta, folder
    return policy


def _read_policy(folder: Path, weights: Path):
    """Parse and check a policy folder; every problem is a ``ValueError`` naming the file."""
    cfg_path = folder / "config.json"
    try:
        meta = json.loads(cfg_path.read_text())
        if not isinstance(meta, dict):
            raise ValueError("not a JSON object")
    except (OSError, ValueError, UnicodeDecodeError) as err:
        raise ValueError(f"{cfg_path}: not a readable policy config ({err})") from err
    if meta.get("format") != POLICY_FORMAT:
        raise ValueError(f"{cfg_path}: not a {POLICY_FORMAT} policy (format={meta.get('format')!r})")
    for field in ("observation_size", "action_size"):
        value = meta.get(field)
        if not isinstance(value, int) or isinstance(value, bool) or value < 1:
            raise ValueError(f"{cfg_path}: field {field!r} must be an integer >= 1; got {value!r}")
    action_size, observation_size = meta["action_size"], meta["observation_size"]
    walker = meta.get("walker_config")
    if walker is not None and not isinstance(walker, dict):
        raise ValueError(f"{cfg_path}: field 'walker_config' must be a JSON object (the WalkerConfig the policy was "
                         f"trained in) or absent; got {walker!r}")
    for field, kind, what in (("robot", str, "a robot name"), ("solver", dict, "a JSON object of SolverOptions")):
        value = (walker or {}).get(field)
        if value is not None and not isinstance(value, kind):
            raise ValueError(f"{cfg_path}: field 'walker_config.{field}' must be {what} or absent; got {value!r}")
    try:
        config = validate_config(PPOConfig.from_json_dict(meta["ppo_config"]))
    except (KeyError, TypeError, ValueError) as err:
        raise ValueError(f"{cfg_path}: incomplete policy config ({err!r})") from err
    try:
        blob = serialization.msgpack_restore(weights.read_bytes())
        params, normaliser = _to_jnp(blob["params"]), nets.RunningStats(**_to_jnp(blob["normaliser"]))
    except Exception as err:  # msgpack raises many unrelated types on damaged bytes
        raise ValueError(f"{weights}: damaged policy weights, cannot be decoded ({type(err).__name__}: {err})") from err
    like = jax.eval_shape(lambda: nets.init_params(jax.random.key(0), config, observation_size, action_size))
    if meta.get("actor_only"):
        like = {"policy": like["policy"]}
    shapes = lambda t: [(jax.tree_util.keystr(k), tuple(np.shape(v))) for k, v in  # noqa: E731
                        jax.tree_util.tree_flatten_with_path(t)[0]]
    if shapes(params) != shapes(like) or tuple(np.shape(normaliser.mean)) != (observation_size,):
        raise ValueError(f"{weights}: parameters do not match the networks of {cfg_path} "
                         f"(observations {observation_size}, actions {action_size})")
    return config, meta, action_size, params, normaliser


POLICY_FIELDS = ("normalize_observations", "policy_hidden", "activation", "action_distribution", "min_std",
                 "init_std")
"""The :class:`PPOConfig` fields the deterministic policy depends on (its network and observation normalisation);
the others (envs, unrolls, minibatches, learning rate, truncation, the value network, ...) only shape training."""


def _policy_network(config: PPOConfig) -> PPOConfig:
    """``config``'s policy network on the default training fields: the key of :func:`policy_fn`'s cache."""
    return PPOConfig()._replace(**{f: getattr(config, f) for f in POLICY_FIELDS})


def _make_policy_fn(config: PPOConfig, action_size: int) -> Callable[[Any, jax.Array], jax.Array]:
    def f(policy_params, obs):
        params, normaliser = policy_params
        return nets.deterministic_action(config, action_size, params, normaliser, jnp.asarray(obs, jnp.float32))

    return f


_policy_fn_cached = functools.lru_cache(maxsize=32)(_make_policy_fn)


def policy_fn(config: PPOConfig, action_size: int) -> Callable[[Any, jax.Array], jax.Array]:
    """``f((params, normaliser), obs [..., O]) -> action [..., A]``: the deterministic policy with its parameters
    as an argument, so new parameters (e.g. during a curriculum) do not re-compile a jitted caller
    (``jaxterrain.difficulty.evaluate(..., policy=f, policy_params=(state.params, state.normaliser))``).

    Cached per policy network (the :data:`POLICY_FIELDS` of ``config``, at most 32) and action size: every walker of
    one network gets the SAME function, whatever it was trained with (a fine-tuned walker's envs and minibatches
    differ from its base policy's), so a caller's program cache keyed on it (``difficulty``'s) compiles one program
    for all of them (``suite.evaluate_policies`` compiled one per walker before: 60 s each with MJX on an H200; then
    one per training config: the base policy, the paper recipe's and the wide recipe's walkers apart). ``params``
    needs only its ``"policy"`` entry. ``policy_fn.__wrapped__(config, action_size)``: a new, uncached function."""
    return _policy_fn_cached(_policy_network(config), int(action_size))


policy_fn.__wrapped__ = _make_policy_fn
policy_fn.cache_info = _policy_fn_cached.cache_info
