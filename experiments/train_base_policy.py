"""``python -m experiments train-base-policy``: train the flat-ground base walker with PPO (``jaxterrain.rl``).

The walker (``jaxterrain.walker.WalkerEnv``) learns on FLAT ground (an all-zero heightfield of the env's shape).
Presets:

- ``smoke``: CPU, seconds to a minute: a tiny heightfield, short episodes, tiny networks, a few updates. Checks the
  plumbing (training, checkpoints, resume, export, evaluation), not the walking.
- ``gpu``: the real run on one H100/H200: brax's MJX-humanoid PPO recipe (``PPOConfig()`` defaults: 3072 envs,
  122 880 env steps per update, see ``jaxterrain.rl.config``), the paper-sized env (``WalkerConfig()``: 256 x 256
  flat hfield, 1000-step episodes), 410 updates = 50.4 M env steps (``--env-steps``), stopping early if
  ``--time-budget`` seconds (default 480) would be overrun. A checkpoint is written after every chunk of 10
  updates: a run stopped by its budget or killed continues with ``--resume --out SAME_DIR``.
  Measured on one H200 (2026-11-21): compile ~20 s, ~315 k env steps/s, 50 M env steps in 218 s, evaluation 26 s,
  the whole device command (wheel install included) 247 s; best-5 / all-20 flat distance 1.00 / 0.93.

Writes into ``--out RUN_DIR``: ``config.json`` (preset, options, env and PPO config), ``checkpoint.msgpack``,
``progress.jsonl`` (one line per chunk), ``policy/`` (``policy.msgpack`` + ``config.json``, loadable with
``jaxterrain.rl.load_policy``) and, once training is complete, ``eval.json``: the normalised distance of the
deterministic policy on flat ground over 20 attempts (random joint initialisations): mean of the best 5 and mean of
all 20 (bar for shipping: >= 0.9 and >= 0.7). ``--export-assets`` copies the policy to
``jaxterrain/assets/base_policy/`` with ``PROVENANCE.md`` (command, steps, commit, device, date, eval).
"""

from __future__ import annotations

import argparse

PRESETS = ("smoke", "gpu")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--preset", choices=PRESETS, default="smoke")
    parser.add_argument("--out", default=None, help="run folder (default runs/train-base-policy-<preset>-<time>)")
    parser.add_argument("--resume", action="store_true", help="continue from OUT/checkpoint.msgpack")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--env-steps", type=float, default=None,
                        help="total env steps to train (default: smoke 4 updates, gpu 410 updates = 50.4e6)")
    parser.add_argument("--time-budget", type=float, default=None,
                        help="seconds of wall time for this process; training stops after the chunk that would "
                             "overrun it, leaving a checkpoint (default: smoke none, gpu 480)")
    parser.add_argument("--updates-per-chunk", type=int, default=None,
                        help="PPO updates per jitted chunk = per checkpoint (default: smoke 2, gpu 10)")
    parser.add_argument("--num-envs", type=int, default=None, help="override PPOConfig.num_envs")
    parser.add_argument("--checkpoint-env-state", action="store_true",
                        help="also checkpoint the batched env state (bit-exact resume; large for the gpu preset)")
    parser.add_argument("--eval-attempts", type=int, default=20)
    parser.add_argument("--eval-best", type=int, default=5)
    parser.add_argument("--skip-eval", action="store_true")
    parser.add_argument("--export-assets", action="store_true",
                        help="write the trained policy to --assets-dir with PROVENANCE.md")
    parser.add_argument("--assets-dir", default=None,
                        help="where --export-assets writes (default jaxterrain/assets/base_policy/)")


def presets():
    """(WalkerConfig, PPOConfig, default env steps, default time budget, default updates per chunk) per preset."""
    from jaxterrain.rl import PPOConfig
    from jaxterrain.walker import TerrainScale, WalkerConfig

    smoke_env = WalkerConfig(terrain_shape=(16, 32), scale=TerrainScale(cell_size=0.2, height=0.5),
                             episode_length=30)
    smoke_ppo = PPOConfig(num_envs=8, unroll_length=5, num_unrolls=1, num_minibatches=2, update_epochs=2,
                          policy_hidden=(16, 16), value_hidden=(32, 32))
    return {
        "smoke": (smoke_env, smoke_ppo, 4 * smoke_ppo.steps_per_update, None, 2),
        # 410 updates = 41 whole chunks of 10 (a shorter last chunk would compile once more, ~25 s)
        "gpu": (WalkerConfig(), PPOConfig(), 410 * PPOConfig().steps_per_update, 480.0, 10),
    }


def _to_jsonable(x):
    if hasattr(x, "_asdict"):
        return {k: _to_jsonable(v) for k, v in x._asdict().items()}
    if isinstance(x, (list, tuple)):
        return [_to_jsonable(v) for v in x]
    return x


def _git_commit() -> str:
    import subprocess

    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10)
        return out.stdout.strip() if out.returncode == 0 and out.stdout.strip() else "unknown (no commit)"
    except (OSError, subprocess.SubprocessError):
        return "unknown (git unavailable)"


def evaluate_flat(env, policy, terrain, key, attempts: int = 20, best: int = 5, steps: int | None = None):
    """Normalised distance of ``policy`` on ``terrain`` over ``attempts`` episodes (random initial joints).

    Each attempt's distance is ``state.distance`` at its first ``done`` (or after ``steps``, default the env's
    episode length). Returns a dict with the per-attempt distances and the best-``best`` and all-attempt means.
    """
    import jax
    import jax.numpy as jnp
    import numpy as np

    steps = int(steps or env.config.episode_length)

    @jax.jit
    def rollout(key):
        s = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(key, attempts), terrain)

        def body(carry, _):
            s, alive, dist = carry
            s = jax.vmap(env.step, in_axes=(0, 0, None))(s, policy(s.obs), terrain)
            dist = jnp.where(alive, s.distance, dist)
            alive = alive & (s.done == 0)
            return (s, alive, dist), None

        init = (s, jnp.ones((attempts,), bool), jnp.zeros((attempts,), jnp.float32))
        (_, _, dist), _ = jax.lax.scan(body, init, None, length=steps)
        return jnp.where(jnp.isfinite(dist), dist, 0.0)

    dist = np.asarray(rollout(key))
    top = np.sort(dist)[::-1][:best]
    return {"attempts": attempts, "best": best, "distances": [float(d) for d in dist],
            "best_mean": float(np.mean(top)), "all_mean": float(np.mean(dist))}


def main(args: argparse.Namespace) -> int:
    import datetime
    import json
    import math
    import shutil
    import sys
    import time
    from pathlib import Path

    t_start = time.perf_counter()
    import jax
    import jax.numpy as jnp
    import numpy as np

    from jaxterrain import rl
    from jaxterrain.io import atomic_write_text
    from jaxterrain.walker import WalkerEnv

    env_cfg, ppo_cfg, default_steps, default_budget, default_chunk = presets()[args.preset]
    if args.num_envs is not None:
        if args.num_envs < 1:
            raise SystemExit("--num-envs must be >= 1")
        ppo_cfg = ppo_cfg._replace(num_envs=args.num_envs)
    rl.validate_config(ppo_cfg)
    env_steps = int(args.env_steps if args.env_steps is not None else default_steps)
    budget = args.time_budget if args.time_budget is not None else default_budget
    upc = args.updates_per_chunk or default_chunk
    if env_steps < 1:
        raise SystemExit("--env-steps must be >= 1")
    if upc < 1:
        raise SystemExit("--updates-per-chunk must be >= 1")
    if not 1 <= args.eval_best <= args.eval_attempts:
        raise SystemExit("--eval-best must be in [1, --eval-attempts]")
    num_updates = math.ceil(env_steps / ppo_cfg.steps_per_update)

    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y%m%d-%H%M%S")
    run = Path(args.out or f"runs/train-base-policy-{args.preset}-{stamp}")
    ckpt_path = run / "checkpoint.msgpack"
    if args.resume and not ckpt_path.is_file():
        raise SystemExit(f"--resume: no checkpoint at {ckpt_path}")
    run.mkdir(parents=True, exist_ok=True)
    command = "python -m experiments train-base-policy " + " ".join(sys.argv[2:] if sys.argv[1:2] == [
        "train-base-policy"] else sys.argv[1:])
    run_config = {
        "preset": args.preset, "seed": args.seed, "env_steps": env_steps, "num_updates": num_updates,
        "updates_per_chunk": upc, "time_budget_s": budget, "walker_config": _to_jsonable(env_cfg),
        "ppo_config": ppo_cfg.to_json_dict(), "command": command,
    }
    if args.resume and (run / "config.json").is_file():
        old = json.loads((run / "config.json").read_text())
        for k in ("walker_config", "ppo_config", "seed"):
            if old.get(k) != run_config[k]:
                raise SystemExit(f"--resume: {k} differs from the run's config.json; resume with the same options")
        run_config["command"] = old.get("command", command)  # the command that started the run
        run_config["resumed_with"] = list(old.get("resumed_with", [])) + [command]
    atomic_write_text(run / "config.json", json.dumps(run_config, indent=2) + "\n")

    device = jax.devices()[0]
    device_name = f"{device.platform}:{device.device_kind}"
    print(f"train-base-policy: preset {args.preset}, device {device.platform}:{device.device_kind}, "
          f"{ppo_cfg.num_envs} envs, {ppo_cfg.steps_per_update:,d} steps/update, target {num_updates} updates "
          f"({num_updates * ppo_cfg.steps_per_update:,d} env steps), run {run}", flush=True)

    env = WalkerEnv(env_cfg)
    terrain = jnp.zeros(tuple(env_cfg.terrain_shape), jnp.float32)
    key = jax.random.PRNGKey(args.seed)
    state = jax.jit(lambda k, t: rl.init(k, env, ppo_cfg, t))(key, terrain)
    if args.resume:
        state = rl.load_checkpoint(ckpt_path, like=state)
        meta = rl.checkpoint_metadata(ckpt_path)
        if not meta.get("include_env_state", False):  # envs were freshly reset: drop the running episode sums
            zero = jnp.zeros_like(state.episode.ret)
            state = state._replace(episode=state.episode._replace(ret=zero, length=zero))
        print(f"resumed at update {int(state.update_step)}, {int(state.env_steps):,d} env steps", flush=True)

    train_devices = []  # devices that trained this run (a resumed run may add one)
    train_commit = _git_commit()
    if args.resume:
        old_meta = rl.checkpoint_metadata(ckpt_path)
        train_devices = list(old_meta.get("train_devices", []))
        train_commit = old_meta.get("train_commit", train_commit)
    if int(state.update_step) < num_updates and device_name not in train_devices:
        train_devices.append(device_name)
    progress = rl.Progress(ppo_cfg, print_fn=lambda s: print(s, flush=True))
    chunk_times = []

    class _Stop(Exception):
        pass

    last = {"state": state, "t": time.perf_counter()}

    def on_chunk(s, metrics):
        line = progress(s, metrics)
        rl.save_checkpoint(ckpt_path, s, include_env_state=args.checkpoint_env_state,
                           metadata={"include_env_state": args.checkpoint_env_state, "preset": args.preset,
                                     "train_devices": train_devices, "train_commit": train_commit,
                                     "command": command})
        with open(run / "progress.jsonl", "a") as f:
            f.write(json.dumps(line) + "\n")
        now = time.perf_counter()
        chunk_times.append(now - last["t"])
        last["state"], last["t"] = s, now
        if budget is not None:
            typical = min(chunk_times[-3:]) if len(chunk_times) > 1 else chunk_times[-1] * 0.5
            eval_reserve = 0 if args.skip_eval else 60.0
            if now - t_start + typical * 1.1 + eval_reserve > budget and int(s.update_step) < num_updates:
                raise _Stop

    remaining = num_updates - int(state.update_step)
    stopped = False
    if remaining > 0:
        try:
            state, _ = rl.train(key, env, ppo_cfg, remaining, terrain, state=state, callback=on_chunk,
                                updates_per_chunk=upc)
        except _Stop:
            state, stopped = last["state"], True
    steps_done = int(state.env_steps)
    train_s = time.perf_counter() - t_start
    policy_dir = run / "policy"
    walker_json = _to_jsonable(env_cfg)
    rl.save_policy(policy_dir, state.params, state.normaliser, ppo_cfg, env.observation_size, env.action_size,
                   extra={"walker_config": walker_json, "env_steps": steps_done,
                          "updates": int(state.update_step)})
    if stopped:
        tokens, again = command.split(), []
        while tokens:
            tok = tokens.pop(0)
            if tok == "--out" and tokens:
                tokens.pop(0)
            elif tok != "--resume" and not tok.startswith("--out="):
                again.append(tok)
        print(f"time budget reached at {steps_done:,d} / {num_updates * ppo_cfg.steps_per_update:,d} env steps "
              f"({train_s:.0f} s); continue with: {' '.join(again)} --out {run} --resume", flush=True)
        return 0
    print(f"training done: {steps_done:,d} env steps in {train_s:.0f} s", flush=True)
    if args.skip_eval:
        return 0

    policy = rl.load_policy(policy_dir)
    eval_key = jax.random.PRNGKey(args.seed + 1_000_003)
    t_eval = time.perf_counter()
    try:  # the project's official metric (jaxterrain.difficulty), same env config
        from jaxterrain import difficulty

        dist = np.asarray(difficulty.rollout_distances(
            jnp.zeros((1,) + tuple(env_cfg.terrain_shape), jnp.float32), eval_key, attempts=args.eval_attempts,
            policy=policy, scale=env_cfg.scale, env_config=env_cfg)[0])
        top = np.sort(dist)[::-1][:args.eval_best]
        result = {"attempts": args.eval_attempts, "best": args.eval_best, "distances": [float(d) for d in dist],
                  "best_mean": float(np.mean(top)), "all_mean": float(np.mean(dist)),
                  "method": "jaxterrain.difficulty.rollout_distances"}
    except ImportError as err:
        print(f"jaxterrain.difficulty unavailable ({err}); evaluating with the env directly", flush=True)
        result = evaluate_flat(env, policy, terrain, eval_key, args.eval_attempts, args.eval_best)
        result["method"] = "experiments.train_base_policy.evaluate_flat (env directly)"
    result.update(env_steps=steps_done, eval_s=time.perf_counter() - t_eval,
                  passes_bar=bool(result["best_mean"] >= 0.9 and result["all_mean"] >= 0.7))
    atomic_write_text(run / "eval.json", json.dumps(result, indent=2) + "\n")
    print(f"flat-ground normalised distance: best-{args.eval_best} mean {result['best_mean']:.3f}, "
          f"all-{args.eval_attempts} mean {result['all_mean']:.3f} (bar 0.9 / 0.7: "
          f"{'pass' if result['passes_bar'] else 'FAIL'})", flush=True)

    if args.export_assets:
        dest = Path(args.assets_dir) if args.assets_dir else rl.BASE_POLICY_DIR
        provenance = {
            "command": run_config["command"], "resumed_with": run_config.get("resumed_with", []),
            "preset": args.preset, "seed": args.seed, "env_steps": steps_done,
            "updates": int(state.update_step), "commit": train_commit, "export_commit": _git_commit(),
            "device": ", ".join(train_devices) or "unknown", "eval_device": device_name, "jax": jax.__version__,
            "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
            "eval": {k: result[k] for k in ("best_mean", "all_mean", "attempts", "best", "passes_bar")},
        }
        rl.save_policy(dest, state.params, state.normaliser, ppo_cfg, env.observation_size, env.action_size,
                       extra={"walker_config": walker_json, "provenance": provenance})
        shutil.copyfile(run / "eval.json", dest / "eval.json")
        md = ["# Base policy provenance", "",
              "Flat-ground PPO walker (`jaxterrain.rl`, brax's MJX-humanoid recipe) for `jaxterrain.walker`.",
              "Load it with `jaxterrain.rl.load_policy()`.", ""]
        md += [f"- {k}: `{v}`" for k, v in provenance.items() if k != "eval"]
        md += ["", f"Evaluation on flat ground ({result['attempts']} attempts, deterministic mean action): "
                   f"best-{result['best']} mean normalised distance {result['best_mean']:.3f}, "
                   f"all-{result['attempts']} mean {result['all_mean']:.3f} (bar 0.9 / 0.7: "
                   f"{'pass' if result['passes_bar'] else 'FAIL'}).", "",
               "PPO and walker configs: `config.json` in this folder."]
        atomic_write_text(dest / "PROVENANCE.md", "\n".join(md) + "\n")
        for name in ("policy.msgpack", "config.json", "eval.json", "PROVENANCE.md"):
            (dest / name).chmod(0o644)  # atomic writes create 0600 files; package data must be readable
        print(f"exported the base policy to {dest}", flush=True)
    return 0
