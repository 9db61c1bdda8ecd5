"""Training the base policy (the flat-ground walker whose walks define difficulty) as one call: a
:class:`~jaxterrain.difficulty.run_config.BasePolicyRun` validated once, PPO on flat ground in checkpointed chunks
(resumable, bit-identical to an uninterrupted run), the policy saved and checked on flat ground.

    from jaxterrain.difficulty import base_policy, run_config as R
    result = base_policy.train_base_policy(R.PRESETS["smoke"], "runs/walker")
    result.evaluation["best_mean"], result.policy_dir       # None evaluation: stopped by the time limit (resumable)
    base_policy.train_base_policy(R.PRESETS["smoke"], "runs/walker", resume=True)   # continues a stopped run

The walker (``jaxterrain.walker.WalkerEnv`` of the preset's shape, :func:`shapes`) learns on an all-zero heightfield.
Writes into the folder: ``run.json`` (the command lines that started and resumed it, the updates, the walker and PPO
configs), ``checkpoint.npz`` + ``metrics.csv`` + ``tb/`` (``runtime.driver.run_chunks``, after every chunk of
``schedule.updates_per_chunk`` updates), ``policy/`` (``rl.save_policy``; ``rl.load_policy`` reads it) and, once
trained, ``eval.json``: the normalised distance of the deterministic policy on flat ground over
``evaluation.attempts`` walks under the nominal physics, the mean of the best ``evaluation.best`` and of all (the bar
for shipping: >= 0.9 and >= 0.7). :func:`export_policy_assets` copies a policy to the package's assets with
``PROVENANCE.md``.
"""

from __future__ import annotations

import datetime
import json
import math
import shutil
import time
from pathlib import Path
from typing import Any, Callable, NamedTuple, Optional

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain.difficulty.evaluation import rollout_distances
from jaxterrain.difficulty.protocol import best_of
from jaxterrain.difficulty.run_config import RULES, BasePolicyRun
from jaxterrain.rl import PPOConfig, chunk_fn, init, load_policy, save_policy, validate_config
from jaxterrain.runtime import driver, schema
from jaxterrain.runtime.estimates import announce
from jaxterrain.runtime.io import atomic_write_text
from jaxterrain.runtime.provenance import git_commit
from jaxterrain.terrain import TerrainScale
from jaxterrain.walker import (Randomisation, WalkerConfig, WalkerEnv, min_terrain_side, observation_fields,
                               parse_randomisation, parse_solver, randomisation_json, resolve_config, robots)

__all__ = ["RUN_INFO", "EVAL_NAME", "shapes", "walker_json", "RunSettings", "Origin", "BasePolicyResult",
           "ResumeMismatch", "validate_base_run", "resolve_settings", "write_run_info", "init_or_resume", "training_origin",
           "train_chunks", "save_run_policy", "evaluate_flat", "write_eval", "bar_verdict", "build_provenance",
           "provenance_markdown", "export_policy_assets", "train_base_policy", "device_name"]

RUN_INFO = "run.json"
EVAL_NAME = "eval.json"
_EVAL_RESERVE_S = 60.0  # the time a time limit leaves the flat-ground evaluation


def shapes(preset: Optional[str], robot: str = "humanoid") -> tuple[WalkerConfig, PPOConfig]:
    """The walker and PPO configs a preset trains, before the run's changes: ``smoke`` (and None) a 16 x 32
    heightfield of 0.2 m cells (widened to the fewest rows ``robot``'s margins take: the ant's 17), 30-step episodes,
    8 envs x 5 steps, tiny networks; the others the paper-sized env (``WalkerConfig()``) and brax's MJX-humanoid
    recipe (``PPOConfig()``: 3 072 envs, 122 880 env steps per update)."""
    if preset in (None, "smoke"):
        env = WalkerConfig(terrain_shape=(16, 32), scale=TerrainScale(cell_size=0.2, height=0.5), episode_length=30)
        need = min_terrain_side(env._replace(robot=robot)) if robot in robots.names() else 0
        if need > 16:
            env = env._replace(terrain_shape=(need, max(32, need)))
        return env, PPOConfig(num_envs=8, unroll_length=5, num_unrolls=1, num_minibatches=2, update_epochs=2,
                              policy_hidden=(16, 16), value_hidden=(32, 32))
    return WalkerConfig(), PPOConfig()


def walker_json(x):
    """A config (NamedTuple, nested) as JSON values; a :class:`~jaxterrain.walker.WalkerConfig`'s randomisation
    recorded only when on."""
    if hasattr(x, "_asdict"):
        fields = x._asdict()
        if isinstance(fields.get("randomisation"), Randomisation):
            randomised = randomisation_json(fields.pop("randomisation"))
            if randomised is not None:
                fields["randomisation"] = randomised
        return {k: walker_json(v) for k, v in fields.items()}
    if isinstance(x, (list, tuple)):
        return [walker_json(v) for v in x]
    return x


class RunSettings(NamedTuple):
    """A run resolved (:func:`resolve_settings`): its walker and PPO configs and its schedule."""

    env_config: WalkerConfig
    ppo_config: PPOConfig
    env_steps: int  # total env steps asked for
    num_updates: int  # PPO updates that reach env_steps
    time_budget: Optional[float]  # seconds for the process (None: none)
    updates_per_chunk: int


class Origin(NamedTuple):
    """Who trained the checkpoint: the devices (``platform:kind``, in order) and the commit of the first process."""

    devices: list
    commit: str


class BasePolicyResult(NamedTuple):
    """What :func:`train_base_policy` made: the last training ``state``, the ``policy_dir``, the flat-ground
    ``evaluation`` (``eval.json``'s content; None when not evaluated), ``stopped`` (a time limit stopped the
    training: call again with ``resume=True``), the env steps trained, the updates asked for and their env steps."""

    state: Any
    policy_dir: Path
    evaluation: Optional[dict]
    stopped: bool
    env_steps: int
    num_updates: int
    target_env_steps: int


def resolve_settings(run: BasePolicyRun) -> RunSettings:
    """The walker and PPO configs (the preset's :func:`shapes` with the run's walker and ``num_envs``) and the
    schedule of ``run``; ``ValueError`` naming ``BasePolicyRun.<path>`` for a bad solver, randomisation or PPO
    config."""
    w = run.walker
    env_cfg, ppo_cfg = shapes(run.preset, w.robot or "humanoid")
    try:
        randomisation = parse_randomisation(w.randomise)
    except ValueError as err:
        raise ValueError(f"BasePolicyRun.walker.randomise: {err}") from None
    env_cfg = resolve_config(env_cfg._replace(robot=w.robot or "humanoid", observation=w.observation or "blind",
                                              scan_noise=float(w.scan_noise or 0.0), randomisation=randomisation,
                                              spawn=w.spawn))
    if w.solver is not None:
        try:
            env_cfg = env_cfg._replace(solver=parse_solver(w.solver))
        except ValueError as err:
            raise ValueError(f"BasePolicyRun.walker.solver: {err}") from None
    if run.ppo.num_envs is not None:
        ppo_cfg = ppo_cfg._replace(num_envs=int(run.ppo.num_envs))
    try:
        validate_config(ppo_cfg)
    except ValueError as err:
        raise ValueError(f"BasePolicyRun.ppo: {err}") from None
    env_steps = int(run.schedule.env_steps)
    budget = None if run.schedule.time_budget is None else float(run.schedule.time_budget)
    num_updates = math.ceil(env_steps / ppo_cfg.steps_per_update)
    return RunSettings(env_cfg, ppo_cfg, env_steps, num_updates, budget, int(run.schedule.updates_per_chunk))


def validate_base_run(run: BasePolicyRun) -> RunSettings:
    """Check ``run`` once, before anything compiles: its fields (``run_config.RULES``), the robot (registered), a
    scan noise only for a perceptive walker, and the settings it resolves to (:func:`resolve_settings`: the solver,
    the randomisation, the PPO config). ``ValueError`` naming ``BasePolicyRun.<path>``; returns the settings."""
    owner = "BasePolicyRun"
    schema.check(run, RULES, owner)
    try:
        robots.get(run.walker.robot)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{owner}.walker.robot: {err}") from None
    if run.walker.scan_noise and run.walker.observation != "perceptive":
        raise ValueError(f"{owner}.walker.scan_noise needs {owner}.walker.observation perceptive (a blind walker "
                         f"scans nothing)")
    settings = resolve_settings(run)
    env = settings.env_config
    need = min_terrain_side(env)
    if min(env.terrain_shape) < need:
        raise ValueError(f"{owner}.walker.robot {env.robot}: the {env.terrain_shape[0]} x {env.terrain_shape[1]} flat "
                         f"ground of preset {run.preset} is narrower than its margins take ({need} samples a side)")
    return settings


class ResumeMismatch(ValueError):
    """A run resumed by code whose walker or PPO configs differ from those it started with (``run.json``)."""


def write_run_info(folder: Path, settings: RunSettings, resumed: bool, command_line: str) -> dict:
    """Write ``run.json``: the command line that started the run (and, resumed, those that continued it), the PPO
    updates and the walker and PPO configs; returns its content. Resumed, the configs must be those the run started
    with (:class:`ResumeMismatch` otherwise: the library's defaults changed since)."""
    info = {"command_line": command_line, "num_updates": settings.num_updates,
            "walker_config": walker_json(settings.env_config), "ppo_config": settings.ppo_config.to_json_dict()}
    path = Path(folder) / RUN_INFO
    if resumed and path.is_file():
        old = json.loads(path.read_text())
        if isinstance(old.get("walker_config"), dict):  # run.json written before robot specs: the humanoid
            old["walker_config"].setdefault("robot", "humanoid")
        for k in ("walker_config", "ppo_config"):
            if _comparable(old.get(k)) != _comparable(info[k]):
                raise ResumeMismatch(f"resume: {k} differs from the run's {RUN_INFO} (the library's defaults changed "
                                 "since the run started?); resume it with the code that started it")
        info["command_line"] = old.get("command_line", command_line)  # the command that started the run
        info["resumed_with"] = list(old.get("resumed_with", [])) + [command_line]
    atomic_write_text(path, json.dumps(info, indent=2) + "\n")
    return info


def _comparable(walker_config):
    """A run.json config as resume compares it: a walker config's observation fields as
    ``walker.observation_fields`` reads them (run.json written before observation sets said ``height_scan`` and a
    scan grid that no blind walker uses)."""
    if not isinstance(walker_config, dict) or "terrain_shape" not in walker_config:
        return walker_config
    rest = {k: v for k, v in walker_config.items()
            if k not in ("height_scan", "observation", "scan_x", "scan_y", "scan_points", "scan_noise")}
    return rest, observation_fields(walker_config), float(walker_config.get("scan_noise") or 0.0)


def device_name() -> str:
    """``platform:device_kind`` of the first JAX device."""
    device = jax.devices()[0]
    return f"{device.platform}:{device.device_kind}"


def init_or_resume(key, env, ppo_cfg: PPOConfig, terrain, folder: Path, resume: bool, say=print):
    """``(state, updates done, metric history, checkpoint meta)``: a fresh PPO training state (``rl.init``), or
    with ``resume`` the folder's ``checkpoint.npz`` (``runtime.driver``'s, env states included; none yet: a fresh
    state)."""
    state = jax.jit(lambda k, t: init(k, env, ppo_cfg, t))(key, terrain)
    restored = driver.restore(folder, like=state) if resume else None
    if restored is None:
        if resume:
            say(f"--resume: no checkpoint in {folder}; starting from scratch")
        return state, 0, None, {}
    state, done, history, meta = restored
    say(f"resumed at update {done}, {int(state.env_steps):,d} env steps")
    return state, done, history, meta


def training_origin(meta: dict, done: int, num_updates: int, device: str) -> Origin:
    """The devices and commit that trained the run so far (the checkpoint's ``meta``), plus ``device`` if it will
    train."""
    devices = list(meta.get("train_devices", []))
    commit = meta.get("train_commit", git_commit())
    if done < num_updates and device not in devices:
        devices.append(device)
    return Origin(devices, commit)


def _print_chunk(steps_per_update: int, say):
    """A ``run_chunks`` progress callable: one line per chunk (updates, env steps/s, return, loss)."""

    def show(info: dict) -> None:
        rate = info["steps_per_s"] * steps_per_update
        say(f"update {info['done']:>6d}/{info['total']}  {rate:>10,.0f} env steps/s  "
            f"return {info.get('episode_return', float('nan')):9.3f}  loss {info.get('loss', float('nan')):8.4f}")

    return show


def train_chunks(env, terrain, state, start: int, history, settings: RunSettings, folder: Path, meta: dict,
                 time_limit_s: Optional[float] = None, progress: bool = True, mesh=None, say=print):
    """Train updates ``[start, num_updates)`` through ``runtime.driver.run_chunks`` (a checkpoint, ``metrics.csv``
    and TensorBoard events after every chunk), stopping at ``time_limit_s`` as ``run_chunks`` does;
    ``(state, stopped)``. ``mesh``: data parallel over its devices (``rl.update``)."""
    cfg = settings.ppo_config
    announce("ppo-chunk", f"{cfg.num_envs} envs, {settings.updates_per_chunk} updates")  # its first chunk compiles
    state, done, _ = driver.run_chunks(
        chunk_fn(env, cfg, terrain, mesh=mesh), state, total=settings.num_updates, every=settings.updates_per_chunk,
        start=start, history=history, run_dir=folder, key_metric="episode_return", time_limit_s=time_limit_s,
        progress=True if progress else _print_chunk(cfg.steps_per_update, say), desc="train-base-policy",
        unit="update", meta=meta)
    return state, done < settings.num_updates


def save_run_policy(policy_dir: Path, state, settings: RunSettings, env) -> None:
    """Write the policy (``rl.save_policy``) with the walker config and the training progress."""
    save_policy(policy_dir, state.params, state.normaliser, settings.ppo_config, env.observation_size,
                env.action_size, extra={"walker_config": walker_json(settings.env_config),
                                        "env_steps": int(state.env_steps), "updates": int(state.update_step)})


def evaluate_flat(policy_dir: Path, env_cfg: WalkerConfig, seed: int, attempts: int, best: int,
                  steps_done: int) -> dict:
    """``eval.json``'s content: the flat-ground normalised distances of the deterministic policy in ``policy_dir``
    under ``env_cfg`` (``difficulty.rollout_distances``) with its physics randomisation off (the bar is the nominal
    walker's), the mean of the ``best`` largest and of all, and the bar's verdict."""
    env_cfg = env_cfg._replace(randomisation=Randomisation())
    policy = load_policy(policy_dir)
    t_eval = time.perf_counter()
    dist = rollout_distances(jnp.zeros((1,) + tuple(env_cfg.terrain_shape), jnp.float32),
                             jax.random.PRNGKey(seed + 1_000_003), attempts=attempts, policy=policy,
                             scale=env_cfg.scale, env_config=env_cfg)  # [1, attempts]
    row = np.asarray(dist[0])
    result = {"attempts": attempts, "best": best, "distances": [float(d) for d in row],
              "best_mean": float(best_of(dist, best)[0]), "all_mean": float(np.mean(row)),
              "method": "jaxterrain.difficulty.rollout_distances"}
    result.update(env_steps=steps_done, eval_s=time.perf_counter() - t_eval,
                  passes_bar=bool(result["best_mean"] >= 0.9 and result["all_mean"] >= 0.7))
    return result


def bar_verdict(result: dict) -> str:
    """``pass`` or ``FAIL`` of an :func:`evaluate_flat` result."""
    return "pass" if result["passes_bar"] else "FAIL"


def write_eval(folder: Path, result: dict) -> str:
    """Write ``result`` (:func:`evaluate_flat`) to ``folder/eval.json``; its summary line."""
    atomic_write_text(Path(folder) / EVAL_NAME, json.dumps(result, indent=2) + "\n")
    return (f"flat-ground normalised distance: best-{result['best']} mean {result['best_mean']:.3f}, "
            f"all-{result['attempts']} mean {result['all_mean']:.3f} (bar 0.9 / 0.7: {bar_verdict(result)})")


def build_provenance(run: BasePolicyRun, info: dict, state, origin: Origin, device: str, result: dict) -> dict:
    """What ``PROVENANCE.md`` and the exported ``config.json`` record about the run (``info``: ``run.json``'s) and its
    evaluation."""
    return {
        "command": info["command_line"], "resumed_with": info.get("resumed_with", []),
        "preset": run.preset, "seed": run.seed, "env_steps": int(state.env_steps),
        "updates": int(state.update_step), "commit": origin.commit, "export_commit": git_commit(),
        "device": ", ".join(origin.devices) or "unknown", "eval_device": device, "jax": jax.__version__,
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
               f"all-{result['attempts']} mean {result['all_mean']:.3f} (bar 0.9 / 0.7: {bar_verdict(result)}).",
           "", "PPO and walker configs: `config.json` in this folder."]
    return "\n".join(md) + "\n"


def export_policy_assets(dest: Path, folder: Path, state, settings: RunSettings, env, provenance: dict,
                         result: dict) -> Path:
    """Write the policy, ``eval.json`` and ``PROVENANCE.md`` to ``dest`` (world-readable package data)."""
    dest = Path(dest)
    save_policy(dest, state.params, state.normaliser, settings.ppo_config, env.observation_size, env.action_size,
                extra={"walker_config": walker_json(settings.env_config), "provenance": provenance})
    shutil.copyfile(Path(folder) / EVAL_NAME, dest / EVAL_NAME)
    atomic_write_text(dest / "PROVENANCE.md", provenance_markdown(provenance, result))
    for name in ("policy.msgpack", "config.json", EVAL_NAME, "PROVENANCE.md"):
        (dest / name).chmod(0o644)  # atomic writes create 0600 files; package data must be readable
    return dest


def train_base_policy(run: BasePolicyRun, folder, time_limit_s: Optional[float] = None, resume: bool = False,
                      evaluate: bool = True, export_to: Optional[Path] = None, mesh=None, progress: bool = True,
                      command_line: str = "", started: Optional[float] = None,
                      say: Callable[[str], None] = print) -> BasePolicyResult:
    """Train ``run``'s walker into ``folder`` (module docstring), validated first (:func:`validate_base_run`).

    ``time_limit_s``: seconds from ``started`` (a ``time.perf_counter()`` reading; default: now) for training and
    evaluation, the evaluation's minute kept (``schedule.time_budget`` bounds it too); a run it stops returns
    ``stopped`` and continues with ``resume=True``, the same result as an uninterrupted one. ``evaluate``: write
    ``eval.json`` once trained; ``export_to``: then copy the policy there with ``PROVENANCE.md``. ``mesh``: data
    parallel over its devices; ``progress``: the driver's bar (False: a line per chunk through ``say``);
    ``command_line``: recorded in ``run.json`` and the provenance."""
    started = time.perf_counter() if started is None else started
    settings = validate_base_run(run)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    info = write_run_info(folder, settings, resume, command_line)
    device = device_name()
    ppo_cfg, total_steps = settings.ppo_config, settings.num_updates * settings.ppo_config.steps_per_update
    say(f"train-base-policy: preset {run.preset}, device {device}, {ppo_cfg.num_envs} envs, "
        f"{ppo_cfg.steps_per_update:,d} steps/update, target {settings.num_updates} updates "
        f"({total_steps:,d} env steps), run {folder}")
    env = WalkerEnv(settings.env_config)
    terrain = jnp.zeros(tuple(settings.env_config.terrain_shape), jnp.float32)  # flat ground
    state, start, history, meta = init_or_resume(jax.random.PRNGKey(int(run.seed)), env, ppo_cfg, terrain, folder,
                                                 resume, say)
    origin = training_origin(meta, start, settings.num_updates, device)
    reserve = _EVAL_RESERVE_S if evaluate else 0.0
    limits = [max(limit - (time.perf_counter() - started) - reserve, 1e-3)
              for limit in (settings.time_budget, time_limit_s) if limit is not None]
    meta = {"preset": run.preset, "train_devices": origin.devices, "train_commit": origin.commit,
            "command": "train-base-policy", "command_line": command_line}
    state, stopped = train_chunks(env, terrain, state, start, history, settings, folder, meta,
                                  min(limits) if limits else None, progress, mesh, say)
    steps_done = int(state.env_steps)
    save_run_policy(folder / "policy", state, settings, env)
    result = None
    if not stopped:
        say(f"training done: {steps_done:,d} env steps in {time.perf_counter() - started:.0f} s")
    if not stopped and evaluate:
        result = evaluate_flat(folder / "policy", settings.env_config, int(run.seed), int(run.evaluation.attempts),
                               int(run.evaluation.best), steps_done)
        say(write_eval(folder, result))
        if export_to is not None:
            provenance = build_provenance(run, info, state, origin, device, result)
            say(f"exported the base policy to "
                f"{export_policy_assets(export_to, folder, state, settings, env, provenance, result)}")
    return BasePolicyResult(state, folder / "policy", result, stopped, steps_done, settings.num_updates, total_steps)
