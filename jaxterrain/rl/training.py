r"""The host-side PPO driver: chunks of jitted ``lax.scan``\ s of :func:`~jaxterrain.rl.ppo.run_updates`, a
callback between chunks (progress, checkpoints) through ``jaxterrain.runtime.driver.run_chunks``: :func:`compiled_chunk`,
:func:`chunk_fn`, :func:`train` and the :class:`Progress` callback, over the pure :mod:`jaxterrain.rl.ppo` (which
imports nothing from here)."""

from __future__ import annotations

import functools
import time
from typing import Any, Callable, Optional

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain.rl.config import PPOConfig, validate_config
from jaxterrain.rl.ppo import init, run_updates
from jaxterrain.rl.state import EnvLike, TrainState, raw_key
from jaxterrain.runtime import driver, sharding
from jaxterrain.walker.tiles import Tile

__all__ = ["compiled_chunk", "chunk_fn", "train", "Progress"]


def _build_chunk(env, config, num_updates, batched, terrain_seed_axis, mesh=None, collect=None):
    fn = functools.partial(run_updates, env=env, config=config, num_updates=num_updates, mesh=mesh, collect=collect)
    if batched:
        fn = jax.vmap(fn, in_axes=(0, terrain_seed_axis))
    if mesh is None:
        return jax.jit(fn)

    return jax.jit(fn, out_shardings=sharding.replicated(mesh))


@functools.lru_cache(maxsize=32)
def _cached_chunk(env, config, num_updates, batched, terrain_seed_axis, mesh=None, collect=None):
    return _build_chunk(env, config, num_updates, batched, terrain_seed_axis, mesh, collect)


def compiled_chunk(env, config, num_updates: int, batched: bool = False, terrain_seed_axis=None, mesh=None,
                   collect: Optional[str] = None):
    """The jitted ``(state, terrains) -> (state, metrics)`` running ``num_updates`` updates; cached per
    (env, config, num_updates, batched, mesh, collect) so repeated :func:`train` calls do not re-compile. With
    ``mesh`` (data parallel, :func:`update`; ``collect``: how, ``rl.collect.collect_mode``) the returned state is
    replicated on every device of the mesh."""
    try:
        return _cached_chunk(env, config, num_updates, batched, terrain_seed_axis, mesh, collect)
    except TypeError:  # unhashable env
        return _build_chunk(env, config, num_updates, batched, terrain_seed_axis, mesh, collect)


def _is_seed_batch(key) -> bool:
    key = jnp.asarray(key) if not hasattr(key, "dtype") else key
    if jnp.issubdtype(key.dtype, jax.dtypes.prng_key):
        return key.ndim == 1
    return key.ndim == 2


def chunk_fn(env: EnvLike, config: PPOConfig, terrains: jax.Array, batched: bool = False,
             terrain_seed_axis: Optional[int] = None,
             mesh=None, collect: Optional[str] = None) -> Callable[[TrainState, int, int], tuple[TrainState, dict]]:
    """The ``jaxterrain.runtime.driver.run_chunks`` chunk of PPO: ``(state, start, stop) -> (state, metrics)`` runs
    ``stop - start`` updates (:func:`compiled_chunk`, cached per length) on ``terrains``; metrics are numpy arrays
    [stop - start] (or [S, stop - start] for a batch of seeds, ``batched``). ``mesh``: data parallel
    (:func:`update`; ``collect``: how, ``rl.collect.collect_mode``)."""

    def chunk(state: TrainState, start: int, stop: int):
        fn = compiled_chunk(env, config, stop - start, batched, terrain_seed_axis, mesh, collect)
        if mesh is not None:  # a state or terrains placed on one device (e.g. a jitted init's) go whole on the mesh
            state, data = sharding.replicate((state, terrains), mesh)
        else:
            data = terrains
        state, metrics = fn(state, data)
        return state, jax.tree_util.tree_map(np.asarray, metrics)

    return chunk


def train(key: jax.Array, env: EnvLike, config: PPOConfig, num_updates: int, terrains: jax.Array,
          state: Optional[TrainState] = None, callback: Optional[Callable[[TrainState, dict], Any]] = None,
          updates_per_chunk: int = 10, *, run_dir=None, time_limit_s: Optional[float] = None,
          progress: Any = False, meta: Optional[dict] = None, mesh=None, collect: Optional[str] = None):
    """Run ``num_updates`` PPO updates in jitted chunks of ``updates_per_chunk`` (a ``lax.scan`` each), through
    ``jaxterrain.runtime.driver.run_chunks``.

    Args:
      key: PRNG key; seeds :func:`init` when ``state`` is None (otherwise unused: the update keys come from
        ``state.key``, so a resumed run continues the same stream). A batch of keys ([S, 2] raw or [S] typed)
        trains S seeds at once under vmap; the returned state and metrics then lead with [S].
      env, config: the env and :class:`PPOConfig`.
      num_updates: updates to run (env steps = num_updates * config.steps_per_update).
      terrains: [num_envs, H, W] or [H, W], shared by all seeds ([S, num_envs, H, W] gives each seed its own), or
        a ``walker.Tile`` of a tiled env (index [] or [num_envs], shared by all seeds).
      state: continue from this :class:`TrainState` (e.g. a loaded checkpoint).
      callback: ``callback(state, metrics)`` on the host after every chunk, metrics a dict of numpy arrays
        [chunk] (or [S, chunk]).
      updates_per_chunk: updates per jitted call (a last shorter chunk compiles once more).
      run_dir, time_limit_s, progress, meta: as in ``jaxterrain.runtime.driver.run_chunks`` (a checkpoint, metrics.csv
        and TensorBoard events in ``run_dir`` after every chunk; stop after ``time_limit_s``; a progress bar).
      mesh: a ``jax.sharding.Mesh`` (``sharding.make_mesh()``) to train data parallel over its devices
        (:func:`update`: the envs split, the gradients summed, the policy replicated); not with a batch of seeds.
      collect: how the envs' steps go over the mesh (``rl.collect.collect_mode``; None: automatic).

    Returns ``(state, metrics)``: the final state and a dict of numpy arrays [n] ([S, n]), n = the updates run
    (``num_updates`` unless the time limit stopped it earlier).
    """

    if not isinstance(num_updates, int) or num_updates < 0:
        raise ValueError(f"num_updates must be an integer >= 0, got {num_updates!r}")
    if not isinstance(updates_per_chunk, int) or updates_per_chunk < 1:
        raise ValueError(f"updates_per_chunk must be an integer >= 1, got {updates_per_chunk!r}")
    validate_config(config)
    is_tile = isinstance(terrains, Tile)
    if not is_tile:
        terrains = jnp.asarray(terrains, jnp.float32)
    batched = _is_seed_batch(key) if state is None else state.update_step.ndim == 1
    if batched and mesh is not None:
        raise ValueError("train: mesh (data parallel) takes one seed; got a batch of seeds")
    terrain_seed_axis = 0 if (batched and not is_tile and terrains.ndim == 4) else None
    if state is None:
        init_fn = lambda k, tr: init(k, env, config, tr)  # noqa: E731
        if batched:
            init_fn = jax.vmap(init_fn, in_axes=(0, terrain_seed_axis))
        state = jax.jit(init_fn)(raw_key(key) if not batched else key, terrains)
    if mesh is not None:
        state = sharding.replicate(state, mesh)
    history = []
    run = chunk_fn(env, config, terrains, batched, terrain_seed_axis, mesh, collect)

    def chunk(s, start, stop):
        s, metrics = run(s, start, stop)
        history.append(metrics)
        if callback is not None:
            callback(s, metrics)
        return s, metrics

    state, _, _ = driver.run_chunks(chunk, state, total=num_updates, every=updates_per_chunk, run_dir=run_dir,
                                    time_limit_s=time_limit_s, progress=progress, desc="ppo", unit="update",
                                    key_metric="episode_return", meta=meta)
    if history:
        axis = 1 if batched else 0
        metrics = {name: np.concatenate([h[name] for h in history], axis=axis) for name in history[0]}
    else:
        metrics = {}
    return state, metrics


class Progress:
    """A ``callback`` for :func:`train` printing env steps, steps/s and mean episode return after every chunk."""

    def __init__(self, config: PPOConfig, print_fn=print):
        self.config, self.print_fn = config, print_fn
        self.t0 = self.t_last = time.perf_counter()
        self.last_steps = None

    def __call__(self, state: TrainState, metrics: dict) -> dict:
        now = time.perf_counter()
        steps = int(np.max(np.asarray(state.env_steps)))
        prev = self.last_steps if self.last_steps is not None else steps - self.config.steps_per_update * int(
            np.shape(metrics["loss"])[-1])
        rate = (steps - prev) / max(now - self.t_last, 1e-9)
        self.t_last, self.last_steps = now, steps
        line = {
            "env_steps": steps,
            "steps_per_s": rate,
            "episode_return": float(np.mean(np.asarray(metrics["episode_return"])[..., -1])),
            "episode_length": float(np.mean(np.asarray(metrics["episode_length"])[..., -1])),
            "loss": float(np.mean(np.asarray(metrics["loss"])[..., -1])),
            "elapsed_s": now - self.t0,
        }
        self.print_fn(
            f"steps {steps:>11,d}  {rate:>10,.0f} steps/s  return {line['episode_return']:9.3f}  "
            f"len {line['episode_length']:7.1f}  loss {line['loss']:8.4f}  [{line['elapsed_s']:6.0f} s]",
        )
        return line
