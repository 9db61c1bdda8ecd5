"""Where each robot's spawn starts a foot under the terrain, on suite v2 or v1 (CPU, kinematics only, a minute or two).

    PYTHONPATH=. python docs/results/suite_v2/spawn_check.py --out docs/results/suite_v2/spawn_check
    PYTHONPATH=. python docs/results/suite_v2/spawn_check.py --suite v1 --out docs/results/suite_v2/spawn_check_v1

Under ``spawn="patch"`` (every run before 2026-11-29, late) the walker's reset lowers the body until its lowest foot
sphere sits ``spawn_clearance`` above the highest terrain sample of a 0.5 m x 0.5 m patch under the torso
(:mod:`jaxterrain.walker.config`), so a foot that stands further out (the ant's stand about 0.6 m from its torso) can
start under the terrain where the ground rises; ``spawn="feet"`` (the default since) lifts every foot clear of the
terrain under it. ``--spawn`` picks the rules to measure (default both). For every terrain of
``suite.load(--suite, robot=...)`` and each of the HEADINGS protocol's four quarter turns, this resets the walker with
``--keys`` keys (the joint noise moves the feet) and measures each foot's depth: the terrain height under the foot's
centre minus the bottom of its sphere (> 0: the sphere cuts into the ground; > its radius: its centre is under the
surface, the case where MuJoCo Warp's stock heightfield kernel returned contacts metres deep). Writes
``spawn_<robot>.csv`` (spawn, family, level, seed, turn, key, the deepest foot's depth in m) and ``summary.md`` (per
robot, rule and family: resets with a foot cut in by more than 1 cm, with a foot centre under the surface, the
deepest depth).
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

import numpy as np


def depths(robot: str, keys: int, size: int | None, spawn: str, version: str = "v2"):
    """``(suite, [terrains, turns, keys] deepest foot depth in m, foot radius)`` for ``robot``'s v2 suite under the
    spawn rule ``spawn``."""
    import jax
    import jax.numpy as jnp

    from jaxterrain import difficulty, suite
    from jaxterrain.difficulty.protocol import HEADING_TURNS
    from jaxterrain.walker import WalkerEnv

    s = suite.load(version, robot=robot if suite.VERSIONS[version]["robot"] is not None else None, size=size)
    policy = difficulty.robot_base_policy(robot)
    env = WalkerEnv(difficulty.default_env_config(tuple(s.heightmaps.shape[1:]), s.scale, policy)._replace(spawn=spawn))
    feet, radius = env._feet, env._foot_radius

    def one(terrain, key):
        state = env.reset(key, terrain)
        xyz = state.data.geom_xpos[feet]
        ground = jax.vmap(lambda x, y: env.terrain_height(terrain, x, y))(xyz[:, 0], xyz[:, 1])
        return jnp.max(ground - (xyz[:, 2] - radius))

    ks = jax.random.split(jax.random.key(0), keys)
    f = jax.jit(jax.vmap(jax.vmap(one, (None, 0)), (0, None)))
    metres = jnp.asarray(s.heightmaps, jnp.float32) * s.scale.height
    out = np.stack([np.asarray(f(jnp.rot90(metres, k, axes=(-2, -1)), ks)) for k in HEADING_TURNS[4]], axis=1)
    return s, out, float(np.max(radius))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=Path("runs/spawn_check"))
    p.add_argument("--robots", nargs="+", default=["humanoid", "ant"], choices=("humanoid", "ant"))
    p.add_argument("--keys", type=int, default=2, help="reset keys per terrain and turn (default 2)")
    p.add_argument("--suite", default="v2", choices=("v1", "v2"), help="held-out suite (default v2)")
    p.add_argument("--size", type=int, default=None, help="terrain side (a smaller build, for a test)")
    p.add_argument("--spawn", nargs="+", default=["patch", "feet"], choices=("patch", "feet"), help="spawn rules")
    args = p.parse_args(argv)
    if args.keys < 1:
        p.error(f"--keys must be an integer >= 1; got {args.keys}")
    from jaxterrain.runtime.io import atomic_write_csv, atomic_write_text

    args.out.mkdir(parents=True, exist_ok=True)
    lines = [f"# Suite {args.suite}: feet under the terrain at the spawn", "",
             "Written by `docs/results/suite_v2/spawn_check.py` (CPU, kinematics only). Per family: resets (terrains x "
             "4 turns x keys) whose deepest foot cuts into the terrain by more than 1 cm, whose deepest foot's centre "
             "is under the surface, and the deepest depth (m).", ""]
    for robot in args.robots:
        rows, table = [], {}
        for spawn in args.spawn:
            s, d, r = depths(robot, args.keys, args.size, spawn, args.suite)
            table[spawn] = d
            rows += [(spawn, s.family[i], int(s.level[i]), int(s.seed[i]), t, k, f"{d[i, t, k]:.4f}")
                     for i in range(d.shape[0]) for t in range(d.shape[1]) for k in range(d.shape[2])]
            print(f"{robot}, spawn {spawn}: {int((d > 0.01).sum())} of {d.size} resets cut a foot in by > 1 cm, "
                  f"{int((d > r).sum())} with its centre under the surface; deepest {d.max():.3f} m", flush=True)
        atomic_write_csv(args.out / f"spawn_{robot}.csv", ["spawn", "family", "level", "seed", "turn", "key",
                                                           "depth_m"], rows)
        lines += [f"## {robot} (foot radius {r:.3f} m, {d.shape[0]} terrains x 4 turns x {args.keys} keys)", "",
                  "| family | resets | " + " | ".join(f"{sp}: cut in > 1 cm | {sp}: centre under | {sp}: deepest (m)"
                                                     for sp in table) + " |",
                  "|---|---|" + "---|---|---|" * len(table)]
        fams = list(dict.fromkeys(s.family.tolist()))
        for fam in fams + ["all"]:
            cells = []
            for d in table.values():
                m = d if fam == "all" else d[np.asarray(s.family) == fam]
                cells.append(f"{int((m > 0.01).sum())} | {int((m > r).sum())} | {m.max():.3f}")
            lines.append(f"| {fam} | {m.size} | " + " | ".join(cells) + " |")
        lines.append("")
    atomic_write_text(args.out / "summary.md", "\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
