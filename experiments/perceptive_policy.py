"""``python -m experiments perceptive-policy``: the perceptive twin of a blind policy (``jaxterrain.rl.perception``).

The twin observes the blind observation plus the robot's height scan (``WalkerConfig(observation="perceptive")``);
its networks' first layers get zero weights for the scan and its normaliser the scan's mean and standard deviation
measured on flat ground (``--walks`` walks of ``--walk-steps`` env steps of the blind policy; the std floored at
``--std-floor`` metres), so it walks exactly like the blind policy until training (``learn --policy FOLDER``) moves
those weights. Then both walk flat ground (``--eval-attempts`` walks, best ``--eval-best``, on a ``--eval-size``
square), and the figures go to ``eval.json`` and ``PROVENANCE.md`` beside the policy.

    python -m experiments perceptive-policy --robot ant --export-assets   # -> jaxterrain/assets/base_policy_ant_perceptive/
    python -m experiments perceptive-policy --from runs/learn-x/policies/trial_0 --out runs/trial_0_perceptive
"""

from __future__ import annotations

import argparse
from pathlib import Path

from experiments.common import UsageError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--robot", default=None, metavar="NAME",
                        help="whose shipped blind base policy to widen (default humanoid)")
    parser.add_argument("--from", dest="source", default=None, metavar="FOLDER",
                        help="a blind policy folder to widen instead of the robot's shipped base policy")
    parser.add_argument("--out", type=Path, default=None, help="where to write the perceptive policy")
    parser.add_argument("--export-assets", action="store_true",
                        help="write to the robot's shipped perceptive folder (jaxterrain/assets/base_policy[_ROBOT]"
                             "_perceptive/) instead of --out")
    parser.add_argument("--scan-noise", type=float, default=0.0, metavar="M",
                        help="std of Gaussian noise on each scanned height (metres) recorded with the policy")
    parser.add_argument("--walks", type=int, default=16, help="flat-ground walks that measure the scan's statistics")
    parser.add_argument("--walk-steps", type=int, default=200, help="env steps of each of those walks")
    parser.add_argument("--std-floor", type=float, default=0.1, metavar="M",
                        help="the smallest standard deviation (metres) the normaliser gets for a scanned height")
    parser.add_argument("--eval-size", type=int, default=None,
                        help="side (pixels, 4 cm) of the flat evaluation square (default: the smallest multiple of 32 "
                             "that holds the robot's track, at least 64: humanoid 64, ant 96)")
    parser.add_argument("--eval-attempts", type=int, default=20, help="flat-ground evaluation walks per policy")
    parser.add_argument("--eval-best", type=int, default=5, help="of which the best are averaged")
    parser.add_argument("--seed", type=int, default=0, help="seed of the statistics walks and the evaluation")


def check_args(args) -> None:
    """UsageError naming the first bad flag (before anything is loaded or built)."""
    import math

    if args.out is None and not args.export_assets:
        raise UsageError("give --out FOLDER or --export-assets")
    if args.out is not None and args.export_assets:
        raise UsageError("--out and --export-assets name two destinations; give one")
    if args.eval_size is not None and args.eval_size < 4:
        raise UsageError(f"--eval-size must be an integer >= 4 pixels, got {args.eval_size}")
    for name in ("walks", "walk_steps", "eval_attempts", "eval_best"):
        v = getattr(args, name)
        if v < 1:
            raise UsageError(f"--{name.replace('_', '-')} must be an integer >= 1, got {v}")
    if args.eval_best > args.eval_attempts:
        raise UsageError(f"--eval-best must be <= --eval-attempts ({args.eval_attempts}), got {args.eval_best}")
    if not (math.isfinite(args.std_floor) and args.std_floor > 0):
        raise UsageError(f"--std-floor must be a finite number > 0 (metres), got {args.std_floor}")
    if not (math.isfinite(args.scan_noise) and args.scan_noise >= 0):
        raise UsageError(f"--scan-noise must be a finite number >= 0 (metres), got {args.scan_noise}")
    if args.source is not None and args.robot is not None:
        raise UsageError("--from and --robot: the folder's policy records its robot; give one of them")


def load_blind(args):
    """The blind policy to widen; UsageError naming the flag when it does not load or is not blind."""
    from jaxterrain import difficulty, rl
    from jaxterrain.walker import robots

    if args.source is None:
        try:
            robots.get(args.robot or "humanoid")
            return difficulty.robot_base_policy(args.robot or "humanoid")
        except ValueError as err:
            raise UsageError(f"--robot: {err}") from None
    try:
        policy = rl.load_policy(args.source)
    except (OSError, ValueError) as err:
        raise UsageError(f"--from {args.source}: {str(err).splitlines()[0]}") from None
    if difficulty.policy_observation(policy)["observation"] != "blind":
        raise UsageError(f"--from {args.source}: the policy is already perceptive")
    return policy


def flat_eval(policy, config, attempts: int, best: int, seed: int) -> dict:
    """Flat-ground normalised distances of ``policy`` in the env ``config`` (``difficulty.rollout_distances``)."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from jaxterrain import difficulty

    d = difficulty.rollout_distances(jnp.zeros((1,) + tuple(config.terrain_shape), jnp.float32),
                                     jax.random.PRNGKey(seed), attempts=attempts, policy=policy, env_config=config)
    row = np.asarray(d[0], np.float64)
    return {"best_mean": float(np.mean(np.sort(row)[-best:])), "all_mean": float(np.mean(row)),
            "distances": [float(v) for v in row]}


def main(args) -> int:
    import datetime
    import json
    import time

    import jax
    import numpy as np

    from jaxterrain import difficulty, rl
    from jaxterrain.rl.perception import perceptive_twin
    from jaxterrain.runtime.io import atomic_write_text
    from jaxterrain.runtime.provenance import git_commit
    from jaxterrain.terrain import TerrainScale
    from jaxterrain.walker import (WalkerConfig, make_env, min_terrain_side, observation_fields, observation_label,
                                   with_observation)

    check_args(args)
    blind = load_blind(args)
    robot = difficulty.policy_robot(blind)
    out = rl.base_policy_dir(robot, "perceptive") if args.export_assets else Path(args.out)
    side = args.eval_size or max(64, -(-min_terrain_side(WalkerConfig(robot=robot)) // 32) * 32)
    if side < min_terrain_side(WalkerConfig(robot=robot)):
        raise UsageError(f"--eval-size must be >= {min_terrain_side(WalkerConfig(robot=robot))} pixels for the "
                         f"{robot} (its track), got {side}")
    args.eval_size = side
    t0 = time.perf_counter()
    # the statistics: the blind policy's own training env (its recorded walker config), perceptive
    trained = dict((blind.meta or {}).get("walker_config") or {})
    shape = tuple(trained.get("terrain_shape") or (256, 256))
    blind_cfg = difficulty.default_env_config(shape, TerrainScale(), blind)
    seeing_cfg = with_observation(blind_cfg, "perceptive")._replace(scan_noise=float(args.scan_noise))
    env = make_env(seeing_cfg)
    twin = perceptive_twin(blind, env, key=jax.random.PRNGKey(args.seed), envs=args.walks, steps=args.walk_steps,
                           std_floor=args.std_floor)
    walker_config = dict(trained, robot=robot, **{k: list(v) if isinstance(v, tuple) else v
                                                  for k, v in observation_fields(seeing_cfg).items()},
                         scan_noise=float(args.scan_noise))
    walker_config.pop("height_scan", None)
    surgery = {"from": _shown(args.source or rl.base_policy_dir(robot)), "walks": args.walks, "steps": args.walk_steps,
               "samples": twin.samples, "std_floor": args.std_floor, "seed": args.seed,
               "scan_mean": [round(float(v), 5) for v in twin.scan_mean],
               "scan_std": [round(float(v), 5) for v in twin.scan_std]}
    rl.save_policy(out, twin.params, twin.normaliser, twin.config, env.observation_size, env.action_size,
                   extra={"walker_config": walker_config, "surgery": surgery},
                   actor_only=bool((blind.meta or {}).get("actor_only")))
    seeing = rl.load_policy(out)
    size = (side, side)
    flat = {}
    for name, p in (("blind", blind), ("perceptive", seeing)):
        flat[name] = flat_eval(p, difficulty.default_env_config(size, TerrainScale(), p), args.eval_attempts,
                               args.eval_best, args.seed + 1)
    device = f"{jax.devices()[0].platform}:{jax.devices()[0].device_kind}"
    result = {"attempts": args.eval_attempts, "best": args.eval_best, "size": args.eval_size, "flat": flat,
              "best_mean": flat["perceptive"]["best_mean"], "all_mean": flat["perceptive"]["all_mean"],
              "passes_bar": flat["perceptive"]["best_mean"] >= 0.9 and flat["perceptive"]["all_mean"] >= 0.7,
              "method": "jaxterrain.difficulty.rollout_distances", "device": device,
              "seconds": round(time.perf_counter() - t0, 1)}
    atomic_write_text(out / "eval.json", json.dumps(result, indent=2) + "\n")
    date = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    f = lambda r: f"best-{args.eval_best} {r['best_mean']:.3f}, all-{args.eval_attempts} {r['all_mean']:.3f}"  # noqa
    md = ["# Perceptive base policy provenance", "",
          f"The perceptive twin of `{surgery['from']}` ({robot}), made by network surgery "
          "(`jaxterrain.rl.perception.perceptive_twin`): it observes "
          f"{observation_label(observation_fields(seeing_cfg))}, appended to the blind observation. The first "
          "dense layer of the policy and value networks has zero weights for the scan, and the normaliser has the "
          f"scan's mean and std measured on flat ground ({args.walks} walks x {args.walk_steps} env steps of the blind "
          f"policy, {twin.samples} scans; std floored at {args.std_floor:g} m), so it walks exactly like the blind "
          "policy (same actions to float rounding) until training moves those weights.", "",
          f"- command: `python -m experiments perceptive-policy {' '.join(_argv())}`",
          f"- commit: `{git_commit()}`", f"- device: `{device}`", f"- jax: `{jax.__version__}`", f"- date: `{date}`",
          f"- scan noise recorded: {args.scan_noise:g} m", "",
          f"Flat ground ({args.eval_size} x {args.eval_size} at 4 cm, {args.eval_attempts} attempts, deterministic "
          f"mean action, seed {args.seed + 1}): perceptive {f(flat['perceptive'])}; blind {f(flat['blind'])}.", "",
          "Walker and PPO configs: `config.json` (`surgery` holds the scan statistics)."]
    atomic_write_text(out / "PROVENANCE.md", "\n".join(md) + "\n")
    for name in ("policy.msgpack", "config.json", "eval.json", "PROVENANCE.md"):
        (out / name).chmod(0o644)
    diff = abs(flat["perceptive"]["best_mean"] - flat["blind"]["best_mean"])
    print(f"perceptive-policy: {out} ({env.observation_size} observations, {twin.samples} scans); flat ground "
          f"perceptive {f(flat['perceptive'])}, blind {f(flat['blind'])} (|difference| {diff:.3g}); "
          f"{result['seconds']:.0f} s", flush=True)
    return 0 if np.isfinite(diff) else 1


def _shown(folder) -> str:
    """``folder`` relative to the repository when inside it (shipped assets name their source portably)."""
    path = Path(folder).resolve()
    try:
        return str(path.relative_to(Path(__file__).resolve().parents[1]))
    except ValueError:
        return str(folder)


def _argv() -> list[str]:
    import sys

    argv = sys.argv[1:]
    return argv[argv.index("perceptive-policy") + 1:] if "perceptive-policy" in argv else argv
