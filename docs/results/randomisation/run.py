"""Does training with physics randomisation shrink the sim2sim gap, and what does it cost held out? (issue 62 item 3)

    PYTHONPATH=. python docs/results/randomisation/run.py train legged-gym --out runs/dr     # ~8 min, one H200
    PYTHONPATH=. python docs/results/randomisation/run.py train full --out runs/dr           # ~8 min
    PYTHONPATH=. python docs/results/randomisation/run.py evaluate --out runs/dr             # ~5 min (MJX-JAX)
    PYTHONPATH=. python docs/results/randomisation/run.py sim2sim --out runs/dr              # ~5 min (+ its CPU cores)
    PYTHONPATH=. python docs/results/randomisation/run.py summary --out runs/dr              # seconds
    PYTHONPATH=. python docs/results/randomisation/run.py all --out /tmp/dr --tiny           # the CPU check, ~15 min

Arms (:data:`ARMS`), the humanoid's base walker trained from scratch on flat ground with ``train-base-policy
--preset gpu`` (brax's recipe, 410 PPO updates = 50.4 M env steps, the shipped base policy's budget) under:

- ``nominal``: no randomisation. By default the shipped base policy (``jaxterrain/assets/base_policy``, trained by that
  same command on an H100, 2026-11-21) stands for it; ``train nominal`` trains it again on this machine and code.
- ``legged-gym``: ``--randomise legged-gym`` (friction 0.5-1.25, torso mass +-1 kg, a push of up to 1 m/s per
  horizontal axis every 1000 env steps at a random phase: ``jaxterrain.walker.RANDOMISATION_PRESETS``).
- ``full``: ``legged-gym`` plus body masses x0.9-1.1, motor strength x0.9-1.1, observation noise 0.01 and an action
  delay of 0-1 env steps (15 ms).

``train ARM`` runs ``python -m experiments train-base-policy --preset gpu --randomise SPEC --out OUT/ARM --time-limit
MIN`` and, when OUT/ARM holds a run already, resumes it (``--resume``): call it again until it says ``done``. Its
``eval.json`` is the flat-ground figure (20 walks on nominal physics, best 5 / all).

``evaluate`` walks every trained arm and the base policy (always row ``base``) on suite v1 (``evaluate --preset gpu``:
372 terrains, 80 walks each in 4 headings) twice: under the nominal physics (``OUT/suite``: the held-out cost) and
under the ``legged-gym`` randomised protocol (``OUT/suite_randomised``: what the randomisation buys on randomised
physics). Both on MJX-JAX (``--backend jax``: the randomised model fields are not checked on MuJoCo Warp here).

``sim2sim`` runs ``docs/results/sim2sim/measure.py`` (MJX-JAX beside MuJoCo's C engine, nominal physics, 32 Perlin maps
and suite v1's flat, slope and stairs families, 20 walks, best 5) on the arms instead of its shipped walkers:
``OUT/sim2sim/summary.json`` holds the mean absolute fitness difference per arm. ``warp-check`` steps one randomised
state under MJX-JAX and MuJoCo Warp and prints the largest difference (a GPU with warp-lang: does Warp take the
batched model fields as the sources say).

``summary`` writes ``OUT/summary.md`` / ``summary.json``: per arm the flat-ground eval, the suite's mean fitness per
family (nominal and randomised protocol), the training throughput (median env steps per second of the chunks after
the first, from ``OUT/ARM.log``, which ``train`` writes) and the sim2sim summary.
"""

from __future__ import annotations

import argparse
import csv
import importlib.util
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
ARMS = {
    "nominal": None,
    "legged-gym": "legged-gym",
    "full": "legged-gym,mass=0.9:1.1,motor=0.9:1.1,obs-noise=0.01,delay=0:1",
}
STAGES = ("train", "evaluate", "sim2sim", "warp-check", "summary", "all")


def parse(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("stage", choices=STAGES)
    p.add_argument("arm", nargs="?", choices=tuple(ARMS), default=None, help="train: the arm to train")
    p.add_argument("--out", required=True, help="results folder (every stage resumes what is there)")
    p.add_argument("--time-limit", type=float, default=8.0, metavar="MINUTES",
                   help="train / sim2sim: stop (resumably) after this many minutes (default 8)")
    p.add_argument("--tiny", action="store_true",
                   help="a CPU check of every stage: train-base-policy's smoke preset, evaluate's smoke preset, the "
                        "sim2sim script's --tiny")
    args = p.parse_args(argv)
    if args.stage == "train" and args.arm is None:
        p.error(f"train needs an arm: {', '.join(ARMS)}")
    if args.stage != "train" and args.arm is not None:
        p.error("only train takes an arm")
    if not args.time_limit > 0:
        p.error(f"--time-limit must be > 0 minutes; got {args.time_limit}")
    return args


def _cli(argv: list[str], log: Path | None = None) -> int:
    """``python -m experiments ARGV`` from the repository root; its output also appended to ``log``."""
    print("+ python -m experiments " + " ".join(argv), flush=True)
    proc = subprocess.Popen([sys.executable, "-m", "experiments", *argv], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    with open(log, "a") if log is not None else open(os.devnull, "w") as f:
        for line in proc.stdout:
            sys.stdout.write(line)
            f.write(line)
    return proc.wait()


def policy_dir(out: Path, arm: str) -> Path | None:
    """The arm's trained policy (None when not trained yet); ``nominal`` is the shipped base policy until trained."""
    own = out / arm / "policy"
    if (out / arm / "eval.json").is_file():
        return own
    if arm == "nominal":
        from jaxterrain.rl.checkpoint import BASE_POLICY_DIR

        return BASE_POLICY_DIR
    return None


def train(args) -> int:
    out, arm = Path(args.out), args.arm
    run = out / arm
    if (run / "eval.json").is_file():
        print(f"{arm}: done ({run})", flush=True)
        return 0
    argv = ["train-base-policy", "--preset", "smoke" if args.tiny else "gpu", "--no-progress",
            "--time-limit", str(args.time_limit)]
    if args.tiny:
        argv += ["--eval-attempts", "2", "--eval-best", "1"]
    if ARMS[arm] is not None:
        argv += ["--randomise", ARMS[arm]]
    argv += ["--resume", str(run)] if (run / "config.json").is_file() else ["--out", str(run)]
    run.parent.mkdir(parents=True, exist_ok=True)
    rc = _cli(argv, out / f"{arm}.log")
    if rc == 3:
        print(f"{arm}: stopped by the time limit; run `train {arm}` again to continue", flush=True)
    return rc


def evaluate(args) -> int:
    out = Path(args.out)
    arms = [a for a in ARMS if a != "nominal" or (out / a / "eval.json").is_file()]
    pols = [str(policy_dir(out, a)) for a in arms if policy_dir(out, a) is not None]
    rc = 0
    for name, extra in (("suite", []), ("suite_randomised", ["--randomise", "legged-gym"])):
        if (out / name / "fitness.csv").is_file():
            print(f"{name}: done", flush=True)
            continue
        argv = ["evaluate", "--preset", "smoke" if args.tiny else "gpu", "--backend", "jax", "--no-repeat", "--out",
                str(out / name), *extra] + (["--policy", *pols] if pols else [])
        rc = rc or _cli(argv)
    return rc


def _measure_module():
    spec = importlib.util.spec_from_file_location("sim2sim_measure", ROOT / "docs/results/sim2sim/measure.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def sim2sim(args) -> int:
    out = Path(args.out)
    walkers = [(f"humanoid {a}", a, policy_dir(out, a)) for a in ARMS if policy_dir(out, a) is not None]
    measure = _measure_module()
    measure.walkers = lambda n, robots=None: walkers  # the arms instead of its shipped walkers
    argv = ["--out", str(out / "sim2sim"), "--robots", "humanoid", "--walkers", "0", "--time-limit",
            str(args.time_limit)] + (["--tiny"] if args.tiny else [])
    return int(measure.main(argv) or 0)


def warp_check(args) -> int:
    """Does MuJoCo Warp take the randomised model fields? 20 env steps of 4 envs (one flat tile each, every
    randomisation but the delay) from the same reset, randomised and nominal, under MJX-JAX and MuJoCo Warp.

    Warp's trajectory differs from MJX-JAX's anyway (its solver), so the test is within each backend: if Warp ignored
    the batched fields, its randomised and nominal runs would be equal while MJX-JAX's differ. Prints the largest
    |qpos| difference randomised vs nominal per backend, and MJX-JAX vs Warp; exit 1 when Warp's is zero."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from jaxterrain.walker import TILE_AXES, WalkerConfig, WalkerEnv, parse_randomisation, warp_available

    ok, why = warp_available()
    if not ok:
        print(f"warp-check: {why}", file=sys.stderr)
        return 2
    spec = parse_randomisation("friction=0.3:1.5,mass=0.8:1.2,added-mass=-2:2,motor=0.5:1.5")
    res = {}
    for backend in ("jax", "warp"):
        for name, rand in (("randomised", spec), ("nominal", None)):
            cfg = WalkerConfig(terrain_shape=(64, 64), tiles=4, backend=backend, warp_worlds=8)
            env = WalkerEnv(cfg if rand is None else cfg._replace(randomisation=rand))
            bank = env.flat_bank()
            idx = jnp.arange(4, dtype=jnp.int32)
            s = jax.jit(jax.vmap(env.reset, in_axes=(0, TILE_AXES)))(jax.random.split(jax.random.key(0), 4),
                                                                    bank.at(idx))
            step = jax.jit(jax.vmap(env.step, in_axes=(0, 0, TILE_AXES)))
            a = jnp.full((4, env.action_size), 0.5)
            for _ in range(20):
                s = step(s, a, bank.at(idx))
            res[backend, name] = np.asarray(s.data.qpos)
    gap = {b: float(np.max(np.abs(res[b, "randomised"] - res[b, "nominal"]))) for b in ("jax", "warp")}
    across = float(np.max(np.abs(res["jax", "randomised"] - res["warp", "randomised"])))
    print(f"warp-check: 20 env steps, 4 envs; max |qpos| randomised - nominal: MJX-JAX {gap['jax']:.3g}, "
          f"MuJoCo Warp {gap['warp']:.3g}; MJX-JAX - Warp (randomised) {across:.3g}", flush=True)
    if gap["warp"] == 0.0:
        print("warp-check: MuJoCo Warp ignored the randomised model fields", file=sys.stderr)
        return 1
    return 0


def _rows(path: Path) -> list[dict]:
    """A CSV's rows; ``PATH.gz`` where only the gzipped file is there (the shipped results)."""
    import gzip

    if not path.is_file():
        if not path.with_name(path.name + ".gz").is_file():
            return []
        with gzip.open(path.with_name(path.name + ".gz"), "rt", newline="") as f:
            return list(csv.DictReader(f))
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def terrain_interval(diff: dict, reps: int = 10_000, seed: int = 0) -> tuple[float, float, float]:
    """Mean of ``diff`` ({(family, terrain): value}) and its 95 % percentile bootstrap over terrains, resampled within
    each family (the families' sizes kept). The interval is terrain sampling for ONE walker per arm: it says nothing
    about another training seed of the same arm."""
    import numpy as np

    rng = np.random.default_rng(seed)
    fams = sorted({f for f, _ in diff})
    groups = [np.array([v for (f, _), v in diff.items() if f == fam]) for fam in fams]
    n = sum(len(g) for g in groups)
    boots = sum(g[rng.integers(0, len(g), (reps, len(g)))].sum(axis=1) for g in groups) / n
    lo, hi = np.percentile(boots, [2.5, 97.5])
    return float(np.mean(np.concatenate(groups))), float(lo), float(hi)


def _intervals(out: Path, result: dict) -> None:
    """Per arm: the suite mean's difference from the base policy on the same terrains (``suite_vs_base``, nominal
    and randomised protocol) and the sim2sim gap |C - MJX| with its difference from the nominal arm's
    (``sim2sim_gap_ci``, ``sim2sim_vs_nominal``), each ``[mean, lo, hi]`` from :func:`terrain_interval`."""
    per = {}  # (protocol, arm) -> {(family, terrain): fitness}
    for name in ("suite", "suite_randomised"):
        rows = _rows(out / name / "fitness.csv")
        fit = {(x["policy"], x["family"], x["level"], x["seed"]): float(x["fitness"]) for x in rows}
        base = {k[1:]: v for k, v in fit.items() if k[0] == "base"}
        for arm, r in result["arms"].items():
            own = {k[1:]: v for k, v in fit.items() if _is_arm(k[0], arm, Path(r["policy"]), out)}
            per[name, arm] = own
            if own and set(own) == set(base) and not _is_arm("base", arm, Path(r["policy"]), out):
                r[f"{name}_vs_base"] = terrain_interval({(k[0], k[1:]): own[k] - base[k] for k in own})
    nominal = ("suite", "nominal"), ("suite_randomised", "nominal")
    for arm, r in result["arms"].items():  # the randomised protocol's loss, the arm's less the base policy's
        mine = ("suite", arm), ("suite_randomised", arm)
        if arm != "nominal" and all(per.get(k) for k in mine + nominal) \
                and len({frozenset(per[k]) for k in mine + nominal}) == 1:
            r["protocol_loss_vs_base"] = terrain_interval({
                (k[0], k[1:]): (per[mine[1]][k] - per[mine[0]][k]) - (per[nominal[1]][k] - per[nominal[0]][k])
                for k in per[mine[0]]})
    rows = _rows(out / "sim2sim" / "fitness.csv")
    gap: dict = {}
    for x in rows:
        gap.setdefault(x["policy"], {}).setdefault((x["family"], (x["level"], x["terrain"])), {})[x["engine"]] = \
            float(x["fitness"])
    gaps = {arm: {k: abs(v["mujoco"] - v["mjx"]) for k, v in g.items() if {"mujoco", "mjx"} <= set(v)}
            for arm, g in gap.items()}
    for arm, r in result["arms"].items():
        if gaps.get(arm):
            r["sim2sim_gap_ci"] = terrain_interval(gaps[arm])
            if arm != "nominal" and gaps.get("nominal") and set(gaps[arm]) == set(gaps["nominal"]):
                r["sim2sim_vs_nominal"] = terrain_interval({k: gaps[arm][k] - gaps["nominal"][k] for k in gaps[arm]})


def _is_arm(policy: str, arm: str, pol: Path, out: Path) -> bool:
    """Is ``policy`` (a fitness.csv row's) this arm's? The shipped base policy is row ``base``; a trained arm's rows
    name its policy folder as the run gave it (``runs/dr/full/policy``), so the folder's last two parts decide."""
    if arm == "nominal" and pol != out / arm / "policy":
        return policy == "base"
    return Path(policy).parts[-2:] == (arm, "policy")


def _ci(v) -> str:
    return f"{v[0]:+.3f} [{v[1]:+.3f}, {v[2]:+.3f}]" if v else "-"


def summary(args) -> int:
    import numpy as np

    from jaxterrain.runtime.io import atomic_write_text

    out = Path(args.out)
    result = {"arms": {}}
    for arm, spec in ARMS.items():
        pol = policy_dir(out, arm)
        if pol is None:
            continue
        r = {"randomise": spec, "policy": str(pol)}
        ev = out / arm / "eval.json" if arm != "nominal" or (out / arm / "eval.json").is_file() else pol / "eval.json"
        if ev.is_file():
            e = json.loads(ev.read_text())
            r["flat_best"], r["flat_all"] = e["best_mean"], e["all_mean"]
        log = out / f"{arm}.log"  # train-base-policy's chunk lines: "update N/M  R env steps/s ..."
        log = log if log.is_file() else out / arm / "train.log"  # where the shipped results keep it
        rates = [float(v.replace(",", "")) for v in re.findall(r"update +\d+/\d+ +([\d,]+) env steps/s",
                                                               log.read_text())] if log.is_file() else []
        if len(rates) > 1:
            r["env_steps_per_s"] = float(np.median(rates[1:]))  # the first chunk compiles
        for name in ("suite", "suite_randomised"):
            rows = [x for x in _rows(out / name / "fitness.csv") if _is_arm(x["policy"], arm, pol, out)]
            if rows:
                fams = sorted({x["family"] for x in rows})
                r[name] = {f: float(np.mean([float(x["fitness"]) for x in rows if x["family"] == f])) for f in fams}
                r[name]["mean"] = float(np.mean([float(x["fitness"]) for x in rows]))
        result["arms"][arm] = r
    s2s = out / "sim2sim" / "summary.json"
    if s2s.is_file():  # measure.py's groups are "humanoid ARM"; "mujoco-mjx" holds |C - MJX| per group|family
        result["sim2sim"] = json.loads(s2s.read_text())
        pairs = result["sim2sim"].get("pairs", {}).get("mujoco-mjx", {})
        for arm, r in result["arms"].items():
            gap = pairs.get(f"humanoid {arm}|all")
            if gap is not None:
                r["sim2sim_gap"] = gap["mean_abs"]
    _intervals(out, result)
    md = ["# Physics randomisation: held-out cost and sim2sim gap", "",
          f"Written {time.strftime('%Y-%m-%d %H:%M')} from {out}.", "",
          "| arm | flat best-5 / all-20 | suite mean (nominal) | suite mean (legged-gym physics) | sim2sim gap "
          "(mean \\|C - MJX\\|) | env steps/s |",
          "|---|---|---|---|---|---|"]
    for arm, r in result["arms"].items():
        flat = f"{r['flat_best']:.3f} / {r['flat_all']:.3f}" if "flat_best" in r else "-"
        nom = f"{r['suite']['mean']:.3f}" if "suite" in r else "-"
        ran = f"{r['suite_randomised']['mean']:.3f}" if "suite_randomised" in r else "-"
        rate = f"{r['env_steps_per_s']:,.0f}" if "env_steps_per_s" in r else "-"
        gap = f"{r['sim2sim_gap']:.3f}" if "sim2sim_gap" in r else "-"
        md.append(f"| {arm} | {flat} | {nom} | {ran} | {gap} | {rate} |")
    md += ["", "Differences on the same terrains, mean [95 % bootstrap over terrains within families; one walker per "
           "arm, so the interval is terrain sampling, not training seed]:", "",
           "| arm | suite - base (nominal) | suite - base (legged-gym physics) | its change under legged-gym physics, "
           "less the base's | sim2sim gap | gap - nominal's gap |",
           "|---|---|---|---|---|---|"]
    for arm, r in result["arms"].items():
        gap = r.get("sim2sim_gap_ci")
        md.append(f"| {arm} | {_ci(r.get('suite_vs_base'))} | {_ci(r.get('suite_randomised_vs_base'))} | "
                  f"{_ci(r.get('protocol_loss_vs_base'))} | "
                  f"{f'{gap[0]:.3f} [{gap[1]:.3f}, {gap[2]:.3f}]' if gap else '-'} | "
                  f"{_ci(r.get('sim2sim_vs_nominal'))} |")
    if s2s.is_file():
        md += ["", "Sim2sim (MuJoCo C vs MJX-JAX): `sim2sim/summary.md`."]
    atomic_write_text(out / "summary.json", json.dumps(result, indent=2) + "\n")
    atomic_write_text(out / "summary.md", "\n".join(md) + "\n")
    print("\n".join(md), flush=True)
    return 0


def main(argv=None) -> int:
    args = parse(argv)
    if args.stage == "train":
        return train(args)
    if args.stage == "evaluate":
        return evaluate(args)
    if args.stage == "sim2sim":
        return sim2sim(args)
    if args.stage == "warp-check":
        return warp_check(args)
    if args.stage == "summary":
        return summary(args)
    for arm in ("legged-gym", "full"):  # all: the CPU check's order
        rc = train(argparse.Namespace(**{**vars(args), "arm": arm}))
        if rc:
            return rc
    return evaluate(args) or sim2sim(args) or summary(args)


if __name__ == "__main__":
    sys.exit(main())
