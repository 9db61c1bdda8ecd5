"""Experiment 4's perceptive walkers: what their height scan does to their walks (issue 64; CPU, MJX-JAX, minutes).

Walks (8 envs, 400 env steps, +x, one key) a policy variant on a few terrains and records the distance and, at every
step a walk is alive, the RMS over the 32 first-layer units of the scan block's pre-activation contribution
``z_scan @ W_scan`` against the blind block's ``z_blind @ W_blind`` (z: the walker's own normaliser). Variants:

- ``trained``: as packed;
- ``zeroscan``: the first layer's 153 scan rows set to 0 (everything else as trained);
- ``cm0``: the scan's common mode (the torso's height above the ground under it, which every scan entry carries)
  held at the base policy's flat-ground mean, the terrain's shape kept: scan' = scan + obs[0] - 1.2319;
- ``shape0``: the terrain's shape removed, the common mode kept: scan' = -obs[0] at every point (what the scan would
  read on flat ground at the same torso height).

Run from the repository root after ``tar xzf docs/results/exp4/archives/humanoid-perceptive.tar.gz`` (and, for
``--archive``, ``humanoid-mixed.tar.gz``):

    PYTHONPATH=. python docs/results/exp4/scan_diag/walks.py suite --trials 2 --variants trained,zeroscan,cm0,shape0
    PYTHONPATH=. python docs/results/exp4/scan_diag/walks.py archive --trials 2 --treatments mixed-dr,mixed-levels
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain import rl, suite
from jaxterrain.rl import networks as nets
from jaxterrain.walker import WalkerConfig, WalkerEnv
from jaxterrain.walker.surface import yaw

B = 45  # blind entries of the perceptive observation (198 = 45 + 17 x 9)
M0 = -1.2319372  # the perceptive base policy's scan mean (flat ground, config.json "surgery")
BASE = Path(__file__).resolve().parents[4] / "jaxterrain" / "assets" / "base_policy_perceptive"
RUN = Path("runs/exp4/train/humanoid-perceptive")
TREATMENTS = ("mixed-map", "steps-map", "mixed-dr", "mixed-plr", "mixed-levels")
SUITE_CELLS = (("stairs_up", 0), ("stairs_up", 2), ("slope_down", 2), ("rough", 3), ("gaps", 2))


def suite_terrains() -> dict:
    out = {"flat": np.zeros((256, 256), np.float32)}
    for fam, lv in SUITE_CELLS:
        s = suite.load("v2", families=[fam], seeds=1, generator_names=[])
        out[f"{fam}{lv}"] = s.heightmaps[int(np.flatnonzero(s.level == lv)[0])] * s.scale.height
    return out


def archive_terrains(treatment: str, trial: int, last: int = 6) -> dict:
    """The last ``last`` distinct archive cells the trial trained on (history.csv), rendered in metres."""
    from jaxterrain.qd import archive_io
    from jaxterrain.qd.bank import _render_filled
    arch = archive_io.load("runs/exp4/archive/humanoid-mixed/archive.npz")
    cells = []
    for r in reversed([r for r in csv.DictReader(open(RUN / treatment / "history.csv")) if r["trial"] == str(trial)]):
        if int(r["cell"]) not in cells:
            cells.append(int(r["cell"]))
        if len(cells) == last:
            break
    maps = np.asarray(_render_filled(arch, np.asarray(cells), 8))
    maps = maps.astype(np.float32) / 65535.0 if maps.dtype == np.uint16 else maps.astype(np.float32)
    return {f"cell{c}": m * np.float32(arch.config.scale.height) for c, m in zip(cells, maps)}


def zero_scan(params):
    k = params["policy"]["params"]["mlp"]["hidden_0"]["kernel"]
    layer = dict(params["policy"]["params"]["mlp"]["hidden_0"], kernel=k.at[B:].set(0.0))
    mlp = dict(params["policy"]["params"]["mlp"], hidden_0=layer)
    return dict(params, policy=dict(params["policy"], params=dict(params["policy"]["params"], mlp=mlp)))


def transform(obs, mode: str):
    h0 = obs[:, :1]  # the torso's height above the terrain under it
    if mode == "cm0":
        return obs.at[:, B:].set(obs[:, B:] + h0 + M0)
    if mode == "shape0":
        return obs.at[:, B:].set(jnp.broadcast_to(-h0, obs[:, B:].shape))
    return obs


def make_walk(env, config, action_size, mode: str, envs: int = 8, steps: int = 400):
    def walk(params, norm, terrain, key):
        w = params["policy"]["params"]["mlp"]["hidden_0"]["kernel"]
        s0 = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(key, envs), terrain)

        def body(carry, _):
            s, alive = carry
            obs = transform(s.obs, mode)
            z = nets.normalize(norm, obs)
            cs, cb = z[:, B:] @ w[B:], z[:, :B] @ w[:B]
            rec = dict(alive=alive, cs=jnp.sqrt(jnp.mean(cs ** 2, 1)), cb=jnp.sqrt(jnp.mean(cb ** 2, 1)),
                       zmax=jnp.max(jnp.abs(z[:, B:]), 1), yaw=jax.vmap(lambda q: yaw(q[3:7]))(s.data.qpos))
            a = nets.deterministic_action(config, action_size, params, norm, obs)
            s2 = jax.vmap(env.step, in_axes=(0, 0, None))(s, a, terrain)
            return (s2, alive & (s2.done == 0)), (rec, s2.distance)

        _, (rec, dist) = jax.lax.scan(body, (s0, jnp.ones((envs,), bool)), None, length=steps)
        return jnp.max(jnp.where(rec["alive"], dist, 0.0), 0), rec
    return jax.jit(walk)


def summary(d, rec) -> dict:
    a = np.asarray(rec["alive"], np.float64)
    mean = lambda k: float((np.asarray(rec[k]) * a).sum() / a.sum())  # noqa: E731
    return dict(dist=float(np.mean(d)), cs=mean("cs"), cb=mean("cb"), zmax=float(np.max(np.asarray(rec["zmax"]) * a)),
                abs_yaw=float((np.abs(np.asarray(rec["yaw"])) * a).sum() / a.sum()))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("terrains", choices=("suite", "archive"))
    ap.add_argument("--trials", type=int, default=2)
    ap.add_argument("--treatments", default=",".join(TREATMENTS))
    ap.add_argument("--variants", default="trained,zeroscan")
    ap.add_argument("--out", default="scan_walks.jsonl")
    args = ap.parse_args()
    env = WalkerEnv(WalkerConfig(observation="perceptive"))
    base = rl.load_policy(BASE)
    variants = args.variants.split(",")
    walks = {m: make_walk(env, base.config, base.action_size, m) for m in {"trained", "cm0", "shape0"} & {*variants, "trained"}}
    with open(args.out, "a") as out:
        def record(name, variant, params, norm, terrains):
            fn = walks["trained" if variant in ("trained", "zeroscan", "base") else variant]
            for tn, t in terrains.items():
                row = dict(policy=name, variant=variant, terrain=tn,
                           **summary(*fn(params, norm, jnp.asarray(t), jax.random.PRNGKey(7))))
                out.write(json.dumps(row) + "\n"); out.flush()
                print(json.dumps({k: round(v, 3) if isinstance(v, float) else v for k, v in row.items()}), flush=True)
        for t in args.treatments.split(","):
            for k in range(args.trials):
                terrains = suite_terrains() if args.terrains == "suite" else archive_terrains(t, k)
                p = rl.load_policy(RUN / t / "policies" / f"trial_{k}")
                for v in variants:
                    params = zero_scan(p.params) if v == "zeroscan" else p.params
                    record(f"{t}/{k}", v, params, p.normaliser, terrains)
                if args.terrains == "archive" or (t, k) == (args.treatments.split(",")[0], 0):
                    record(f"{t}/{k}" if args.terrains == "archive" else "base", "base", base.params, base.normaliser,
                           terrains)


if __name__ == "__main__":
    main()
