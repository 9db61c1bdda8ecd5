"""PPO training throughput on the walker: ``jaxterrain.rl`` against brax 0.14.2's own ``ppo.train``, in one run.

Both train on the SAME env: ``jaxterrain.walker.WalkerEnv`` (same model, same solver options, same terrain size),
wrapped for brax as a ``brax.envs.base.Env`` on one fixed terrain (:class:`BraxWalker`; brax's ``training.wrap``
adds its episode / auto-reset / vmap wrappers as usual). Both use the same PPO shape, mapped field by field by
:func:`brax_kwargs`:

==========================  =============================================================
``jaxterrain.rl.PPOConfig``  ``brax.training.agents.ppo.train``
==========================  =============================================================
num_envs                     num_envs
unroll_length                unroll_length
num_unrolls                  batch_size * num_minibatches / num_envs (unrolls per step)
num_minibatches              num_minibatches (batch_size = num_envs * num_unrolls / mb)
update_epochs                num_updates_per_batch
policy/value_hidden          network_factory=make_ppo_networks(policy/value sizes, act.)
gamma, gae_lambda, ...       discounting, gae_lambda, clipping_epsilon, entropy_cost, ...
==========================  =============================================================

so one of our ``rl.update`` calls and one brax ``training_step`` collect the same env steps
(``num_envs * unroll_length * num_unrolls``) and take the same Adam steps (``update_epochs * num_minibatches``).

Measured (env steps per second of training, compilation excluded):

- ours: ``rl.compiled_chunk`` (``rl.run_updates``: ``--updates`` calls of ``rl.update`` in one jitted
  ``lax.scan``; what ``rl.train`` runs), first call (compile + run) discarded, then ``--repeats`` timed calls;
  terrain shared (``[H, W]``, the one brax gets) and per env (``[num_envs, H, W]``, a bank of Perlin maps tiled);
- brax: ``ppo.train`` with ``num_evals = 3 + repeats`` and ``run_evals=False``, so it runs ``2 + repeats``
  "epochs" of ``--updates`` training steps each (one pmapped ``lax.scan``, like ours); the first TWO epochs are
  discarded (the first compiles; the second compiles again: seen on a CPU with jax 0.10.2, the first epoch's inputs
  come from the host-side set-up and the second's from the pmapped epoch itself), the others give brax's own
  ``training/sps`` (its timer wraps only the epoch call). ``epoch_seconds`` lists every epoch.

brax 0.14.2 calls ``jax.device_put_replicated``, which jax >= 0.10 removed; :func:`patched_device_put_replicated`
puts an equivalent back for the duration of the brax call only (the library never sees it).

Differences that stay (neither changes the env steps or gradient steps done): brax resets a finished env to the
state of its first reset (``AutoResetWrapper``), ours to a fresh reset drawn once per update; brax treats reaching
the goal as terminal, ours bootstraps there; brax keeps an unsigned 64-bit step counter and per-episode metrics in
its wrappers.

    python benchmarks/ppo.py --out runs/ppo.json                 # GPU sizes (2 048 envs, 327 680 steps/update)
    python benchmarks/ppo.py --quick --out /tmp/ppo.json         # tiny CPU sizes, about 3 min on 2 cores

Every run prints one JSON line per measurement (device, date, jax, commit, config, steps/s) and writes them all,
plus the ratio ours / brax, to ``--out``.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import json
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from common import block, environment, write_json  # noqa: E402
from rollouts import terrain_bank  # noqa: E402  (Perlin maps in [0, 1], benchmarks/rollouts.py)
from jaxterrain import rl  # noqa: E402
from jaxterrain.walker import TerrainScale, WalkerConfig, WalkerEnv, parse_solver, solver_label  # noqa: E402

# GPU defaults: the MJX tutorial's humanoid recipe (NOTES.md, "Measured 2026-11-23": brax on its own humanoid,
# 2 048 envs, batch 1 024 x 32 minibatches = 16 unrolls per env, 8 epochs, unroll 10).
GPU = dict(num_envs=2048, unroll=10, unrolls=16, minibatches=32, epochs=8, updates=2, repeats=3, terrain_size=256,
           episode_length=1000, bank=64)
# --quick: tiny CPU sizes (the point is that the whole script runs, not the figure).
QUICK = dict(num_envs=8, unroll=5, unrolls=2, minibatches=2, epochs=2, updates=2, repeats=1, terrain_size=48,
             episode_length=100, bank=4)


WARMUP_EPOCHS = 2  # brax epochs discarded before timing (see the module docstring)


def log(*a):
    print(f"[{time.strftime('%H:%M:%S')}]", *a, flush=True)


# --------------------------------------------------------------------------------------------------------------
# The walker as a brax Env, the config mapping, and the jax >= 0.10 patch
# --------------------------------------------------------------------------------------------------------------
def brax_walker(env: WalkerEnv, terrain: jax.Array):
    """``env`` on the fixed ``terrain`` ([H, W] float32 metres) as a ``brax.envs.base.Env`` (unbatched).

    ``pipeline_state`` is the whole :class:`~jaxterrain.walker.WalkerState` (the physics data and the walker's own
    counters), ``obs [O]``, ``reward []``, ``done []`` and ``metrics`` are the walker's. ``backend`` is ``"mjx"``.
    """
    from brax.envs.base import Env, State

    terrain = jnp.asarray(terrain, jnp.float32)
    if terrain.shape != tuple(env.config.terrain_shape):
        raise ValueError(f"terrain must have shape {tuple(env.config.terrain_shape)} (env.config.terrain_shape), "
                         f"got {terrain.shape}")

    class BraxWalker(Env):
        def reset(self, rng: jax.Array) -> State:
            s = env.reset(rng, terrain)
            return State(pipeline_state=s, obs=s.obs, reward=s.reward, done=s.done, metrics=dict(s.metrics))

        def step(self, state: State, action: jax.Array) -> State:
            s = env.step(state.pipeline_state, action, terrain)
            return state.replace(pipeline_state=s, obs=s.obs, reward=s.reward, done=s.done, metrics=dict(s.metrics))

        @property
        def observation_size(self) -> int:
            return env.observation_size

        @property
        def action_size(self) -> int:
            return env.action_size

        @property
        def backend(self) -> str:
            return "mjx"

    return BraxWalker()


def brax_kwargs(config: rl.PPOConfig, episode_length: int, updates: int, epochs: int, seed: int = 0) -> dict:
    """Keyword arguments of ``brax.training.agents.ppo.train`` for the same PPO as ``config``.

    ``epochs`` brax "epochs" (jitted calls) of ``updates`` training steps each: ``num_timesteps = epochs * updates
    * config.steps_per_update`` and ``num_evals = epochs + 1``. ``ValueError`` when the batch does not split.
    """
    from brax.training.agents.ppo import networks as ppo_networks
    import flax.linen as nn

    rl.validate_config(config)
    if updates < 1 or epochs < 1:
        raise ValueError(f"updates and epochs must be >= 1, got {updates}, {epochs}")
    segments = config.num_envs * config.num_unrolls
    if segments % config.num_minibatches:
        raise ValueError(f"num_minibatches ({config.num_minibatches}) must divide num_envs * num_unrolls "
                         f"({segments})")
    activation = {"swish": nn.swish, "relu": nn.relu, "tanh": nn.tanh, "elu": nn.elu}[config.activation]
    factory = functools.partial(
        ppo_networks.make_ppo_networks, policy_hidden_layer_sizes=tuple(config.policy_hidden),
        value_hidden_layer_sizes=tuple(config.value_hidden), activation=activation,
        distribution_type=config.action_distribution)
    return dict(
        num_timesteps=epochs * updates * config.steps_per_update, num_evals=epochs + 1, run_evals=False,
        num_envs=config.num_envs, episode_length=episode_length, action_repeat=1,
        unroll_length=config.unroll_length, batch_size=segments // config.num_minibatches,
        num_minibatches=config.num_minibatches, num_updates_per_batch=config.update_epochs,
        learning_rate=config.learning_rate, entropy_cost=config.entropy_coef, discounting=config.gamma,
        gae_lambda=config.gae_lambda, clipping_epsilon=config.clip_eps, vf_loss_coefficient=config.vf_coef,
        max_grad_norm=config.max_grad_norm, reward_scaling=config.reward_scaling,
        normalize_observations=config.normalize_observations, normalize_advantage=config.normalize_advantage,
        network_factory=factory, seed=seed)


def _device_put_replicated(x: Any, devices) -> Any:
    """What ``jax.device_put_replicated`` did: every leaf stacked ``len(devices)`` times along a new axis 0, one
    slice per device. Placed by an identity ``jax.pmap`` so that the arrays carry the same sharding as the outputs
    of brax's pmapped training epoch (a device_put to another sharding makes its second epoch compile again)."""
    devices = list(devices)
    stacked = jax.tree.map(lambda a: jnp.stack([jnp.asarray(a)] * len(devices)), x)
    return jax.pmap(lambda t: t, devices=devices)(stacked)


@contextlib.contextmanager
def patched_device_put_replicated():
    """``jax.device_put_replicated`` present inside the block (jax >= 0.10 removed it; brax 0.14.2 calls it), and
    exactly as before afterwards. On a jax that still has it, nothing changes."""
    missing = not hasattr(jax, "device_put_replicated")
    if missing:
        jax.device_put_replicated = _device_put_replicated
    try:
        yield
    finally:
        if missing:
            del jax.device_put_replicated


# --------------------------------------------------------------------------------------------------------------
# Measurements
# --------------------------------------------------------------------------------------------------------------
def _rates(times: list[float], steps: int) -> dict:
    return {"steps_per_s": steps / statistics.median(times), "best_steps_per_s": steps / min(times),
            "seconds": times}


def bench_ours(env: WalkerEnv, config: rl.PPOConfig, terrains: jax.Array, updates: int, repeats: int,
               seed: int = 0) -> dict:
    """Env steps/s of ``updates`` jitted ``rl.update`` calls per call (``rl.compiled_chunk``), ``repeats`` calls
    timed after a first one that compiles. ``terrains``: ``[H, W]`` shared or ``[num_envs, H, W]`` per env."""
    t0 = time.perf_counter()
    state = block(jax.jit(lambda k, t: rl.init(k, env, config, t))(jax.random.PRNGKey(seed), terrains))
    init_s = time.perf_counter() - t0
    chunk = rl.compiled_chunk(env, config, updates)
    t0 = time.perf_counter()
    state, metrics = block(chunk(state, terrains))
    first = time.perf_counter() - t0
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        state, metrics = block(chunk(state, terrains))
        times.append(time.perf_counter() - t0)
    return dict(_rates(times, updates * config.steps_per_update), init_s=init_s, first_call_s=first,
                env_steps=int(state.env_steps), episode_return=float(metrics["episode_return"][-1]),
                finite=bool(np.all(np.isfinite(np.asarray(metrics["loss"])))))


def bench_brax(env: WalkerEnv, config: rl.PPOConfig, terrain: jax.Array, updates: int, repeats: int,
               seed: int = 0) -> dict:
    """brax 0.14.2 ``ppo.train`` on :func:`brax_walker` (``terrain`` [H, W]): ``WARMUP_EPOCHS + repeats`` epochs
    of ``updates`` training steps; the first ``WARMUP_EPOCHS`` (compiles) are discarded, the rest give brax's
    ``training/sps``."""
    from brax.training.agents.ppo import train as ppo

    epochs, records = WARMUP_EPOCHS + repeats, []
    kwargs = brax_kwargs(config, env.config.episode_length, updates, epochs, seed)
    t_last = [time.perf_counter()]

    def progress(step, metrics):
        now = time.perf_counter()
        records.append({"step": int(step), "sps": float(metrics["training/sps"]), "wall": now - t_last[0],
                        "loss": float(metrics.get("training/total_loss", np.nan))})
        t_last[0] = now

    t0 = time.perf_counter()
    with patched_device_put_replicated():
        ppo.train(environment=brax_walker(env, terrain), progress_fn=progress, **kwargs)
    total = time.perf_counter() - t0
    if len(records) != epochs:
        raise RuntimeError(f"brax ppo.train reported {len(records)} epochs, expected {epochs}: {records}")
    steps = updates * config.steps_per_update
    seconds = [steps / r["sps"] for r in records]
    return dict(_rates(seconds[WARMUP_EPOCHS:], steps), first_call_s=seconds[0], epoch_seconds=seconds,
                total_s=total, env_steps=records[-1]["step"],
                host_gap_s=[r["wall"] - t for r, t in zip(records, seconds)][WARMUP_EPOCHS:],
                finite=bool(np.all(np.isfinite([r["loss"] for r in records]))))


# --------------------------------------------------------------------------------------------------------------
def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default=None, help="JSON result path")
    p.add_argument("--quick", action="store_true", help="tiny CPU sizes (defaults below become the QUICK ones)")
    p.add_argument("--num-envs", type=int, help=f"parallel envs (default {GPU['num_envs']})")
    p.add_argument("--unroll", type=int, help=f"unroll_length (default {GPU['unroll']})")
    p.add_argument("--unrolls", type=int, help=f"unrolls per env per update = brax batch_size * num_minibatches / "
                   f"num_envs (default {GPU['unrolls']})")
    p.add_argument("--minibatches", type=int, help=f"num_minibatches (default {GPU['minibatches']})")
    p.add_argument("--epochs", type=int, help=f"update_epochs = brax num_updates_per_batch (default {GPU['epochs']})")
    p.add_argument("--updates", type=int, help=f"PPO updates per timed call (default {GPU['updates']})")
    p.add_argument("--repeats", type=int, help=f"timed calls after the compiling one (default {GPU['repeats']})")
    p.add_argument("--terrain-size", type=int, help=f"terrain samples per side (default {GPU['terrain_size']})")
    p.add_argument("--episode-length", type=int, help=f"env steps per episode (default {GPU['episode_length']})")
    p.add_argument("--bank", type=int, help="distinct Perlin terrains tiled over the envs (per-env mode)")
    p.add_argument("--solver", default="sound", help="walker solver: sound (default), fast, xml or I,LS,DAMP")
    p.add_argument("--skip", default="", help="comma list of: shared, per-env, brax")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    for name, value in (QUICK if args.quick else GPU).items():
        if getattr(args, name) is None:
            setattr(args, name, value)
    for name in ("num_envs", "unroll", "unrolls", "minibatches", "epochs", "updates", "repeats", "bank",
                 "episode_length"):
        if getattr(args, name) < 1:
            raise SystemExit(f"--{name.replace('_', '-')} must be >= 1, got {getattr(args, name)}")
    return args


def settings(args: argparse.Namespace) -> tuple[WalkerConfig, rl.PPOConfig]:
    """The walker and PPO configs of the options (PPOConfig's brax-recipe defaults for everything else)."""
    env_cfg = WalkerConfig(terrain_shape=(args.terrain_size, args.terrain_size), scale=TerrainScale(),
                           solver=parse_solver(args.solver), episode_length=args.episode_length)
    ppo_cfg = rl.PPOConfig(num_envs=args.num_envs, unroll_length=args.unroll, num_unrolls=args.unrolls,
                           num_minibatches=args.minibatches, update_epochs=args.epochs)
    try:
        rl.validate_config(ppo_cfg)
    except ValueError as err:
        raise SystemExit(str(err)) from None
    return env_cfg, ppo_cfg


def main(argv=None) -> dict:
    args = parse_args(argv)
    skip = set(filter(None, args.skip.split(",")))
    env_cfg, ppo_cfg = settings(args)

    env = WalkerEnv(env_cfg)
    bank = terrain_bank(jax.random.PRNGKey(11), args.bank, args.terrain_size) * env_cfg.scale.height
    per_env = jnp.tile(bank, (-(-args.num_envs // args.bank), 1, 1))[:args.num_envs]
    config = {"num_envs": args.num_envs, "unroll_length": args.unroll, "num_unrolls": args.unrolls,
              "num_minibatches": args.minibatches, "update_epochs": args.epochs, "updates_per_call": args.updates,
              "repeats": args.repeats, "steps_per_update": ppo_cfg.steps_per_update,
              "policy_hidden": list(ppo_cfg.policy_hidden), "value_hidden": list(ppo_cfg.value_hidden),
              "terrain_shape": list(env_cfg.terrain_shape), "episode_length": args.episode_length,
              "solver": solver_label(env_cfg.solver), "quick": args.quick}
    env_info = environment()
    result = {"environment": env_info, "config": config, "ppo_config": ppo_cfg.to_json_dict(), "runs": []}
    runs = [("ours, shared terrain", "shared", lambda: bench_ours(env, ppo_cfg, bank[0], args.updates,
                                                                    args.repeats, args.seed)),
            ("ours, per-env terrains", "per-env", lambda: bench_ours(env, ppo_cfg, per_env, args.updates,
                                                                       args.repeats, args.seed)),
            ("brax ppo.train, shared terrain", "brax", lambda: bench_brax(env, ppo_cfg, bank[0], args.updates,
                                                                            args.repeats, args.seed))]
    for what, part, fn in runs:
        if part in skip:
            continue
        log(f"{what}: compiling and timing ...")
        row = {"what": what, **env_info, "config": config, **fn()}
        result["runs"].append(row)
        print(json.dumps(row, default=float), flush=True)
        write_json(args.out, result)
    by = {r["what"]: r["steps_per_s"] for r in result["runs"]}
    brax_sps = by.get("brax ppo.train, shared terrain")
    if brax_sps:
        result["ratio_vs_brax"] = {w: s / brax_sps for w, s in by.items() if not w.startswith("brax")}
    write_json(args.out, result)
    for what, sps in by.items():
        note = f"  ({sps / brax_sps:.2f}x brax)" if brax_sps and not what.startswith("brax") else ""
        print(f"{what:34s} {sps:>12,.0f} env steps/s{note}")
    return result


if __name__ == "__main__":
    main()
