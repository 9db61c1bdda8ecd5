"""``python -m experiments train-base-policy``: train the flat-ground base walker with PPO (``jaxterrain.rl``).

The walker (``jaxterrain.walker.WalkerEnv``) learns on FLAT ground (an all-zero heightfield of the env's shape).
Presets:

- ``smoke``: CPU, seconds to a minute: a tiny heightfield, short episodes, tiny networks, a few updates. Checks the
  plumbing (training, checkpoints, resume, export, evaluation), not the walking.
- ``gpu``: the real run on one H100/H200: brax's MJX-humanoid PPO recipe (``PPOConfig()`` defaults: 3072 envs,
  122 880 env steps per update, see ``jaxterrain.rl.config``), the paper-sized env (``WalkerConfig()``: 256 x 256
  flat hfield, 1000-step episodes), 410 updates = 50.4 M env steps (``--env-steps``), stopping after the chunk in
  which ``--time-budget`` seconds (default 480, less a minute kept for the evaluation) pass. The loop is
  ``jaxterrain.runtime.driver.run_chunks``, as in ``evolve``: after every chunk of 10 updates it writes ``checkpoint.npz``
  (the whole PPO state, env states included, so a resumed run is bit-identical to an uninterrupted one),
  ``metrics.csv`` and TensorBoard events (``tb/``); a run stopped by its budget (or ``--time-limit MIN``) or
  killed (exit code 3 after a time-limit stop, as ``evolve``) continues with ``--resume RUN_DIR`` and the settings
  saved in its ``config.json`` (``experiments.common.setup_resumable_run``: ``--env-steps``, ``--time-budget``,
  ``--updates-per-chunk``, ``--eval-attempts`` and ``--eval-best`` given with it replace the saved ones).
  Measured on one H100 (2026-11-21) under the default solver (``SOLVER_SOUND``, Newton 4 / 16): ~140 k env
  steps/s, 50.4 M env steps in about 6.5 min over two commands (the first stopped by its budget at 46.7 M);
  best-5 / all-20 flat distance 1.00 / 0.98. Under ``--solver fast`` (brax's Newton 1 / 4) an H200 did ~315 k env
  steps/s, 50 M in 218 s, but that policy walks only under the fast solver (``jaxterrain.walker.SOLVER_SOUND``).

``--randomise SPEC`` trains under physics randomisation (``jaxterrain.walker.parse_randomisation``: friction, masses,
motors, observation noise, action delay, pushes, or ``legged-gym``); the policy records it in its ``walker_config``,
and ``eval.json`` walks the nominal physics.

Writes into ``--out RUN_DIR``: ``config.json`` (the settings, as in every command: ``--config RUN/config.json``
re-runs them), ``run.json`` (the command lines that started and resumed it, the updates, the walker and PPO
configs), ``checkpoint.npz``, ``metrics.csv``, ``tb/``, ``policy/`` (``policy.msgpack`` + ``config.json``, loadable with
``jaxterrain.rl.load_policy``) and, once training is complete, ``eval.json``: the normalised distance of the
deterministic policy on flat ground over 20 attempts (random joint initialisations; ``jaxterrain.difficulty``'s
rollouts): mean of the best 5 and mean of all 20 (bar for shipping: >= 0.9 and >= 0.7). ``--export-assets`` copies
the policy to ``jaxterrain/assets/base_policy/`` with ``PROVENANCE.md`` (command, steps, commit, device, date, eval).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, NamedTuple

from experiments import common

# The options of each preset; its walker and PPO configs are :func:`configs`. env_steps: smoke 4 updates of
# 8 envs x 5 steps, gpu 410 updates of PPOConfig().steps_per_update = 122 880 (41 whole chunks of 10; a shorter last
# chunk would compile once more, ~25 s).
PRESETS: dict[str, dict[str, Any]] = common.with_preset_names({
    "smoke": dict(env_steps=4 * 40, time_budget=None, updates_per_chunk=2, num_envs=None, solver=None,
                  eval_attempts=20, eval_best=5, robot="humanoid", observation="blind", scan_noise=0.0, randomise=None),
    "gpu": dict(env_steps=410 * 122_880, time_budget=None, updates_per_chunk=10, num_envs=None, solver=None,
                eval_attempts=20, eval_best=5, robot="humanoid", observation="blind", scan_noise=0.0, randomise=None),
}, {"gpu-short": ("gpu", {"env_steps": 41 * 122_880}), "paper": "gpu"})
# time_budget (seconds, the whole process) is the config key of runs made before --time-limit replaced --time-budget
# (2026-11-28); no preset sets it: --time-limit MIN bounds a process now, on every preset.
# What ``--resume`` may change (how long the run lasts, how it is chunked, how it is evaluated); the rest is the run's.
EXTENDABLE = ("env_steps", "time_budget", "updates_per_chunk", "eval_attempts", "eval_best")
RUN_INFO = "run.json"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    common.add_run_arguments(parser, PRESETS, "smoke")
    common.add_devices_argument(parser)  # data parallel: envs split over the devices, gradients summed
    parser.add_argument("--env-steps", type=float, default=None,
                        help="total env steps to train (default: smoke 4 updates, gpu 410 updates = 50.4e6)")
    parser.add_argument("--time-budget", type=float, default=None, help=argparse.SUPPRESS)  # seconds: --time-limit's
    # predecessor, kept so that older command lines (the base policy's PROVENANCE.md) still run
    parser.add_argument("--updates-per-chunk", type=int, default=None,
                        help="PPO updates per jitted chunk = per checkpoint (default: smoke 2, gpu 10)")
    parser.add_argument("--num-envs", type=int, default=None, help="override PPOConfig.num_envs")
    parser.add_argument("--solver", default=None,
                        help="walker contact solver: sound (default: Newton 4 iterations / 16 line-search), fast, "
                             "xml, or ITERATIONS,LS_ITERATIONS,EULERDAMP such as 4,16,0; recorded with the policy, and "
                             "difficulty.evaluate then walks it under the same options")
    parser.add_argument("--robot", default=None, metavar="NAME",
                        help="the body to train: humanoid (default, the paper's), ant (brax's quadruped) or a robot a "
                             "--plugin registered (jaxterrain.walker.robots); recorded with the policy")
    parser.add_argument("--observation", choices=("blind", "perceptive"), default=None,
                        help="what the walker observes: blind (the paper's: torso height, orientation, joints) or "
                             "perceptive (plus a height scan around and ahead of the torso, the robot's default "
                             "grid); recorded with the policy, and every command walks it with the same set")
    parser.add_argument("--scan-noise", type=float, default=None, metavar="M",
                        help="perceptive: std of Gaussian noise on each scanned height, in metres")
    common.add_randomise_argument(parser, "the training walker (recorded with the policy; the flat-ground "
                                          "evaluation walks the nominal physics)")
    common.add_progress_argument(parser)
    parser.add_argument("--eval-attempts", type=int, default=None, help="flat-ground evaluation walks (default 20)")
    parser.add_argument("--eval-best", type=int, default=None, help="of which the best are averaged (default 5)")
    parser.add_argument("--skip-eval", action="store_true",
                        help="skip the flat-ground evaluation of the trained walker at the end")
    parser.add_argument("--export-assets", action="store_true",
                        help="write the trained policy to --assets-dir with PROVENANCE.md")
    parser.add_argument("--assets-dir", default=None,
                        help="where --export-assets writes (default jaxterrain/assets/base_policy/; another robot's: "
                             "jaxterrain/assets/base_policy_ROBOT/)")


def overrides(args: argparse.Namespace) -> dict:
    """The settings given on the command line (None: not given)."""
    return {name: getattr(args, name) for name in ("env_steps", "time_budget", "updates_per_chunk", "num_envs",
                                                    "solver", "eval_attempts", "eval_best", "robot",
                                                    "observation", "scan_noise", "randomise")}


def configs():
    """``{preset: (WalkerConfig, PPOConfig)}`` before the options of :data:`PRESETS` (``num_envs``, ``solver``)."""
    from jaxterrain.rl import PPOConfig
    from jaxterrain.walker import TerrainScale, WalkerConfig

    smoke_env = WalkerConfig(terrain_shape=(16, 32), scale=TerrainScale(cell_size=0.2, height=0.5),
                             episode_length=30)
    smoke_ppo = PPOConfig(num_envs=8, unroll_length=5, num_unrolls=1, num_minibatches=2, update_epochs=2,
                          policy_hidden=(16, 16), value_hidden=(32, 32))
    full = (WalkerConfig(), PPOConfig())
    return {"smoke": (smoke_env, smoke_ppo), "gpu-short": full, "gpu": full, "paper": full}


def _to_jsonable(x):
    from jaxterrain.walker import Randomisation, randomisation_json

    if hasattr(x, "_asdict"):
        fields = x._asdict()
        if isinstance(fields.get("randomisation"), Randomisation):  # a WalkerConfig's: recorded only when on
            randomised = randomisation_json(fields.pop("randomisation"))
            if randomised is not None:
                fields["randomisation"] = randomised
        return {k: _to_jsonable(v) for k, v in fields.items()}
    if isinstance(x, (list, tuple)):
        return [_to_jsonable(v) for v in x]
    return x


class RunSettings(NamedTuple):
    """The resolved settings of one run (:func:`resolve_settings` of its ``config.json``)."""

    env_config: Any  # jaxterrain.walker.WalkerConfig
    ppo_config: Any  # jaxterrain.rl.PPOConfig
    env_steps: int  # total env steps asked for
    num_updates: int  # PPO updates that reach env_steps
    time_budget: float | None  # seconds of wall time for this process (None: no budget)
    updates_per_chunk: int  # PPO updates per jitted chunk = per checkpoint


class RunFolder(NamedTuple):
    """Where a run lives and how it was started."""

    path: Path  # the run folder (--out / --resume FOLDER)
    command: str  # this process's command line
    info: dict  # what path / "run.json" holds


class TrainOrigin(NamedTuple):
    """Who trained the checkpoint: the devices (``platform:kind``, in order) and the commit of the first process."""

    devices: list[str]
    commit: str


class TrainOutcome(NamedTuple):
    """The result of :func:`train_with_checkpoints`: the last state and whether a time limit stopped it."""

    state: Any  # jaxterrain.rl training state
    stopped: bool


def _solver(text: str):
    """``jaxterrain.walker.parse_solver(text)``; SystemExit naming ``--solver`` when it is not one."""
    from jaxterrain.walker import parse_solver

    try:
        return parse_solver(text)
    except ValueError as err:
        raise SystemExit(f"--solver: {err}") from None


def resolve_settings(cfg: dict) -> RunSettings:
    """The walker and PPO configs and the schedule of a run's settings ``cfg`` (a preset of :data:`PRESETS` with
    the options given, see ``common.setup_resumable_run``). SystemExit names a bad ``--solver``."""
    import math

    from jaxterrain import rl

    from jaxterrain.walker import parse_randomisation, resolve_config

    env_cfg, ppo_cfg = configs()[cfg.get("preset") or "smoke"]
    env_cfg = resolve_config(env_cfg._replace(robot=cfg.get("robot") or "humanoid",  # runs before --robot: humanoid
                                              observation=cfg.get("observation") or "blind",  # before sets: blind
                                              scan_noise=float(cfg.get("scan_noise") or 0.0),
                                              randomisation=parse_randomisation(cfg.get("randomise"))))
    if cfg.get("solver") is not None:
        env_cfg = env_cfg._replace(solver=_solver(cfg["solver"]))
    if cfg.get("num_envs") is not None:
        ppo_cfg = ppo_cfg._replace(num_envs=int(cfg["num_envs"]))
    rl.validate_config(ppo_cfg)
    env_steps = int(cfg["env_steps"])
    budget = None if cfg.get("time_budget") is None else float(cfg["time_budget"])
    num_updates = math.ceil(env_steps / ppo_cfg.steps_per_update)
    return RunSettings(env_cfg, ppo_cfg, env_steps, num_updates, budget, int(cfg["updates_per_chunk"]))


def _command_line() -> str:
    """This process's command as ``python -m experiments train-base-policy ...``."""
    import sys

    return "python -m experiments train-base-policy " + " ".join(sys.argv[2:] if sys.argv[1:2] == [
        "train-base-policy"] else sys.argv[1:])


def write_run_info(folder: Path, settings: RunSettings, resumed: bool) -> RunFolder:
    """Write ``run.json``: the command line that started the run (and, after ``--resume``, those that continued it),
    the PPO updates and the walker and PPO configs. On ``--resume`` the configs must be those the run started with
    (SystemExit otherwise: the library's defaults changed since)."""
    import json

    from jaxterrain.runtime.io import atomic_write_text

    command = _command_line()
    info = {"command_line": command, "num_updates": settings.num_updates,
            "walker_config": _to_jsonable(settings.env_config), "ppo_config": settings.ppo_config.to_json_dict()}
    path = folder / RUN_INFO
    if resumed and path.is_file():
        old = json.loads(path.read_text())
        if isinstance(old.get("walker_config"), dict):  # run.json written before robot specs: the humanoid
            old["walker_config"].setdefault("robot", "humanoid")
        for k in ("walker_config", "ppo_config"):
            if _comparable(old.get(k)) != _comparable(info[k]):
                raise SystemExit(f"--resume: {k} differs from the run's {RUN_INFO} (the library's defaults changed "
                                 "since the run started?); resume it with the code that started it")
        info["command_line"] = old.get("command_line", command)  # the command that started the run
        info["resumed_with"] = list(old.get("resumed_with", [])) + [command]
    atomic_write_text(path, json.dumps(info, indent=2) + "\n")
    return RunFolder(folder, command, info)


def _comparable(walker_config):
    """A run.json config as resume compares it: a walker config's observation fields as
    ``walker.observation_fields`` reads them (run.json written before observation sets said ``height_scan`` and a
    scan grid that no blind walker uses)."""
    if not isinstance(walker_config, dict) or "terrain_shape" not in walker_config:
        return walker_config
    from jaxterrain.walker import observation_fields

    rest = {k: v for k, v in walker_config.items()
            if k not in ("height_scan", "observation", "scan_x", "scan_y", "scan_points", "scan_noise")}
    return rest, observation_fields(walker_config), float(walker_config.get("scan_noise") or 0.0)


def _device_name() -> str:
    """``platform:device_kind`` of the first JAX device."""
    import jax

    device = jax.devices()[0]
    return f"{device.platform}:{device.device_kind}"


def init_or_resume(key, env, ppo_cfg, terrain, run: Path, resume: bool):
    """``(state, updates done, metric history, checkpoint meta)``: a fresh PPO training state (``rl.init``), or
    with ``resume`` the run's ``checkpoint.npz`` (``jaxterrain.runtime.driver`` format, env states included; none yet: a
    fresh state)."""
    import jax

    from jaxterrain.runtime import driver
    from jaxterrain import rl

    state = jax.jit(lambda k, t: rl.init(k, env, ppo_cfg, t))(key, terrain)
    restored = driver.restore(run, like=state) if resume else None
    if restored is None:
        if resume:
            print(f"--resume: no checkpoint in {run}; starting from scratch", flush=True)
        return state, 0, None, {}
    state, done, history, meta = restored
    print(f"resumed at update {done}, {int(state.env_steps):,d} env steps", flush=True)
    return state, done, history, meta


def training_origin(meta: dict, done: int, num_updates: int, device_name: str) -> TrainOrigin:
    """The devices and commit that trained the run so far (from the checkpoint's ``meta``), plus this device if
    it will train."""
    from jaxterrain.runtime.provenance import git_commit

    train_devices = list(meta.get("train_devices", []))  # devices that trained this run (a resume may add one)
    train_commit = meta.get("train_commit", git_commit())
    if done < num_updates and device_name not in train_devices:
        train_devices.append(device_name)
    return TrainOrigin(train_devices, train_commit)


def _print_chunk(steps_per_update: int):
    """A ``run_chunks`` progress callable: one line per chunk (updates, env steps/s, return, loss)."""

    def show(info: dict) -> None:
        rate = info["steps_per_s"] * steps_per_update
        print(f"update {info['done']:>6d}/{info['total']}  {rate:>10,.0f} env steps/s  "
              f"return {info.get('episode_return', float('nan')):9.3f}  loss {info.get('loss', float('nan')):8.4f}",
              flush=True)

    return show


def train_with_checkpoints(env, terrain, state, start: int, history, args, settings: RunSettings, run: RunFolder,
                           origin: TrainOrigin, t_start: float, preset: str, mesh=None) -> TrainOutcome:
    """Train updates ``[start, num_updates)`` through ``jaxterrain.runtime.driver.run_chunks``: a checkpoint, metrics.csv
    and TensorBoard events after every chunk; stops at the time limit as ``run_chunks`` does. ``mesh``:
    data parallel over its devices (``rl.update``)."""
    import time

    from jaxterrain.runtime import driver
    from jaxterrain import rl

    limits = []
    if settings.time_budget is not None:  # the process's budget, less what has passed and the evaluation's minute
        reserve = 0.0 if args.skip_eval else 60.0
        limits.append(max(settings.time_budget - (time.perf_counter() - t_start) - reserve, 1e-3))
    if args.time_limit is not None:  # the whole process, as time_budget: training leaves the evaluation its minute
        reserve = 0.0 if args.skip_eval else 60.0
        limits.append(max(args.time_limit * 60.0 - (time.perf_counter() - t_start) - reserve, 1e-3))
    meta = {"preset": preset, "train_devices": origin.devices, "train_commit": origin.commit,
            "command": "train-base-policy", "command_line": run.command}
    cfg = settings.ppo_config
    from jaxterrain.runtime.estimates import announce

    announce("ppo-chunk", f"{cfg.num_envs} envs, {settings.updates_per_chunk} updates")  # its first chunk compiles
    state, done, _ = driver.run_chunks(
        rl.chunk_fn(env, cfg, terrain, mesh=mesh), state, total=settings.num_updates,
        every=settings.updates_per_chunk,
        start=start, history=history, run_dir=run.path, key_metric="episode_return",
        time_limit_s=min(limits) if limits else None,
        progress=True if args.progress else _print_chunk(cfg.steps_per_update),
        desc="train-base-policy", unit="update", meta=meta)
    return TrainOutcome(state, done < settings.num_updates)


def save_run_policy(policy_dir: Path, state, settings: RunSettings, env) -> None:
    """Write the policy (``rl.save_policy``) with the walker config and training progress."""
    from jaxterrain import rl

    rl.save_policy(policy_dir, state.params, state.normaliser, settings.ppo_config, env.observation_size,
                   env.action_size, extra={"walker_config": _to_jsonable(settings.env_config),
                                           "env_steps": int(state.env_steps), "updates": int(state.update_step)})


def resume_command(command: str, run: Path) -> str:
    """``command`` without its ``--out`` / ``--resume [FOLDER]``, plus ``--resume run``: how to continue the run."""
    tokens, again = command.split(), []
    while tokens:
        tok = tokens.pop(0)
        if tok in ("--out", "--resume") and tokens and (tok == "--out" or not tokens[0].startswith("--")):
            tokens.pop(0)
        elif tok != "--resume" and not tok.startswith(("--out=", "--resume=")):
            again.append(tok)
    return f"{' '.join(again)} --resume {run}"


def evaluate_policy(policy_dir: Path, env_cfg, seed: int, attempts: int, best: int, steps_done: int) -> dict:
    """``eval.json``'s content: the flat-ground normalised distances of the deterministic policy in ``policy_dir``
    under the env config ``env_cfg`` (``jaxterrain.difficulty.rollout_distances``) with its physics randomisation
    off (the bar is the nominal walker's), the mean of the ``best`` largest (``difficulty.best_of``) and of all, and
    the bar verdict."""
    import time

    import jax
    import jax.numpy as jnp
    import numpy as np

    from jaxterrain import difficulty, rl
    from jaxterrain.walker import Randomisation

    env_cfg = env_cfg._replace(randomisation=Randomisation())
    policy = rl.load_policy(policy_dir)
    t_eval = time.perf_counter()
    dist = difficulty.rollout_distances(jnp.zeros((1,) + tuple(env_cfg.terrain_shape), jnp.float32),
                                        jax.random.PRNGKey(seed + 1_000_003), attempts=attempts, policy=policy,
                                        scale=env_cfg.scale, env_config=env_cfg)  # [1, attempts]
    row = np.asarray(dist[0])
    result = {"attempts": attempts, "best": best, "distances": [float(d) for d in row],
              "best_mean": float(difficulty.best_of(dist, best)[0]), "all_mean": float(np.mean(row)),
              "method": "jaxterrain.difficulty.rollout_distances"}
    result.update(env_steps=steps_done, eval_s=time.perf_counter() - t_eval,
                  passes_bar=bool(result["best_mean"] >= 0.9 and result["all_mean"] >= 0.7))
    return result


def _bar_verdict(result: dict) -> str:
    return "pass" if result["passes_bar"] else "FAIL"


def write_eval(run: Path, result: dict) -> None:
    """Write ``result`` (see :func:`evaluate_policy`) to ``run/eval.json`` and print its summary."""
    import json

    from jaxterrain.runtime.io import atomic_write_text

    atomic_write_text(run / "eval.json", json.dumps(result, indent=2) + "\n")
    print(f"flat-ground normalised distance: best-{result['best']} mean {result['best_mean']:.3f}, "
          f"all-{result['attempts']} mean {result['all_mean']:.3f} (bar 0.9 / 0.7: {_bar_verdict(result)})",
          flush=True)


def build_provenance(cfg: dict, run: RunFolder, state, origin: TrainOrigin, device_name: str, result: dict) -> dict:
    """What ``PROVENANCE.md`` and the exported ``config.json`` record about the run and its evaluation."""
    import datetime

    import jax

    from jaxterrain.runtime.provenance import git_commit

    return {
        "command": run.info["command_line"], "resumed_with": run.info.get("resumed_with", []),
        "preset": cfg["preset"], "seed": cfg["seed"], "env_steps": int(state.env_steps),
        "updates": int(state.update_step), "commit": origin.commit, "export_commit": git_commit(),
        "device": ", ".join(origin.devices) or "unknown", "eval_device": device_name, "jax": jax.__version__,
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "eval": {k: result[k] for k in ("best_mean", "all_mean", "attempts", "best", "passes_bar")},
    }


def provenance_markdown(provenance: dict, result: dict) -> str:
    """The text of ``PROVENANCE.md``."""
    md = ["# Base policy provenance", "",
          "Flat-ground PPO walker (`jaxterrain.rl`, brax's MJX-humanoid recipe) for `jaxterrain.walker`.",
          "Load it with `jaxterrain.rl.load_policy()`.", ""]
    md += [f"- {k}: `{v}`" for k, v in provenance.items() if k != "eval"]
    md += ["", f"Evaluation on flat ground ({result['attempts']} attempts, deterministic mean action): "
               f"best-{result['best']} mean normalised distance {result['best_mean']:.3f}, "
               f"all-{result['attempts']} mean {result['all_mean']:.3f} (bar 0.9 / 0.7: {_bar_verdict(result)}).",
           "", "PPO and walker configs: `config.json` in this folder."]
    return "\n".join(md) + "\n"


def export_policy_assets(dest: Path, run: Path, state, settings: RunSettings, env, provenance: dict,
                         result: dict) -> None:
    """Write the policy, ``eval.json`` and ``PROVENANCE.md`` to ``dest`` (world-readable package data)."""
    import shutil

    from jaxterrain import rl
    from jaxterrain.runtime.io import atomic_write_text

    rl.save_policy(dest, state.params, state.normaliser, settings.ppo_config, env.observation_size,
                   env.action_size, extra={"walker_config": _to_jsonable(settings.env_config),
                                           "provenance": provenance})
    shutil.copyfile(run / "eval.json", dest / "eval.json")
    atomic_write_text(dest / "PROVENANCE.md", provenance_markdown(provenance, result))
    for name in ("policy.msgpack", "config.json", "eval.json", "PROVENANCE.md"):
        (dest / name).chmod(0o644)  # atomic writes create 0600 files; package data must be readable
    print(f"exported the base policy to {dest}", flush=True)


def main(args: argparse.Namespace) -> int:
    """Resolve, train (checkpointed, budgeted, resumable), save the policy, evaluate it, optionally export it."""
    import time

    t_start = time.perf_counter()
    import jax
    import jax.numpy as jnp

    from jaxterrain import rl
    from jaxterrain.walker import WalkerEnv

    if args.solver is not None:
        _solver(args.solver)  # a bad --solver stops before the run folder is made
    if args.scan_noise and args.observation != "perceptive":
        raise common.UsageError("--scan-noise needs --observation perceptive (a blind walker scans nothing)")
    if args.robot is not None:
        from jaxterrain.walker import robots

        try:
            robots.get(args.robot)
        except ValueError as err:
            raise common.UsageError(f"--robot: {err}") from None
    mesh = common.device_mesh(args.devices)
    folder, cfg = common.setup_resumable_run("train-base-policy", args, PRESETS, "smoke", overrides(args), EXTENDABLE)
    settings = resolve_settings(cfg)
    run = write_run_info(folder, settings, resumed=args.resume is not None)
    device_name = _device_name()
    ppo_cfg, total_steps = settings.ppo_config, settings.num_updates * settings.ppo_config.steps_per_update
    print(f"train-base-policy: preset {cfg['preset']}, device {device_name}, {ppo_cfg.num_envs} envs, "
          f"{ppo_cfg.steps_per_update:,d} steps/update, target {settings.num_updates} updates "
          f"({total_steps:,d} env steps), run {run.path}", flush=True)

    env = WalkerEnv(settings.env_config)
    terrain = jnp.zeros(tuple(settings.env_config.terrain_shape), jnp.float32)  # flat ground
    state, start, history, meta = init_or_resume(jax.random.PRNGKey(int(cfg["seed"])), env, ppo_cfg, terrain,
                                                 run.path, args.resume is not None)
    origin = training_origin(meta, start, settings.num_updates, device_name)
    outcome = train_with_checkpoints(env, terrain, state, start, history, args, settings, run, origin, t_start,
                                     cfg["preset"], mesh=mesh)
    state, steps_done, train_s = outcome.state, int(outcome.state.env_steps), time.perf_counter() - t_start
    save_run_policy(run.path / "policy", state, settings, env)
    if outcome.stopped:
        print(f"time limit reached at {steps_done:,d} / {total_steps:,d} env steps ({train_s:.0f} s); "
              f"continue with: {resume_command(run.command, run.path)}", flush=True)
        return 3  # as evolve: stopped by the time limit, resumable
    print(f"training done: {steps_done:,d} env steps in {train_s:.0f} s", flush=True)
    if args.skip_eval:
        return 0

    result = evaluate_policy(run.path / "policy", settings.env_config, int(cfg["seed"]), int(cfg["eval_attempts"]),
                             int(cfg["eval_best"]), steps_done)
    write_eval(run.path, result)
    if args.export_assets:
        robot = settings.env_config.robot
        dest = Path(args.assets_dir) if args.assets_dir else rl.base_policy_dir(robot)
        provenance = build_provenance(cfg, run, state, origin, device_name, result)
        export_policy_assets(dest, run.path, state, settings, env, provenance, result)
    return 0
