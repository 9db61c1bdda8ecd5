"""The walker's terrain layouts under MJX (issue 48 item 4): can each world have its own heightfield ASSET, and what
does each layout cost the raw physics?

1. check (every backend, CPU too): a model with two heightfield assets of one size (flat; a plateau at half the
   elevation), two worlds whose floor geom selects asset 0 and asset 1 through a per-world ``geom_dataid`` (a
   vmapped model field, the pattern MuJoCo Warp reads as ``geom_dataid[worldid % n, geom]``), the humanoid dropped
   onto each. It works when the feet come to rest half an elevation apart; where MJX refuses, the error is recorded.
2. timing (``--backend warp`` on a GPU): raw ``mjx.step`` with random controls (no policy, env code or reset), in
   one process, at every ``--batch-sizes``, for

   - ``tiles``: the ``--bank`` terrains as tiles of ONE heightfield, env ``i`` on tile ``i % bank`` (today's layout,
     :mod:`jaxterrain.walker.tiles`);
   - ``shared``: one heightfield of one terrain (the bank's first) under every env: no per-env terrains, the peer
     that says what the tiles cost;
   - ``perworld`` (only where 1. passed): ``--bank`` heightfield assets, env ``i``'s floor on asset ``i % bank``.

The walker with the policy in the loop on tiles and shared: ``benchmarks/rollouts.py --layout tiles,shared``.

    python benchmarks/layouts.py --backend warp --out runs/layouts.json
    python benchmarks/layouts.py --backend jax --skip timing     # the check alone, on CPU
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import mujoco  # noqa: E402
from mujoco import mjx  # noqa: E402

from common import environment, first_and_best, markdown_table, write_json  # noqa: E402
from rollouts import terrain_bank  # noqa: E402  (the Perlin bank rollouts.py times)
from jaxterrain import walker  # noqa: E402
from jaxterrain.walker import TILE_AXES, WalkerConfig, WalkerEnv  # noqa: E402
from jaxterrain.walker import model as wm  # noqa: E402


def log(*a):
    print(f"[{time.strftime('%H:%M:%S')}]", *a, flush=True)


def perworld_model(config: WalkerConfig, heights01) -> mujoco.MjModel:
    """The walker's MjModel with ``K = len(heights01)`` heightfield assets of ``config.terrain_shape``, asset ``k``
    holding ``heights01[k]`` ([K, H, W] in [0, 1], MuJoCo's ``hfield_data`` values); the floor geom uses asset 0."""
    shape = tuple(config.terrain_shape)
    spec = wm.build_spec(shape, config.scale, config.solver, config.timestep, config.robot)
    size = [float(v) for v in wm.hfield_size(shape, config.scale)]
    for k in range(1, len(heights01)):
        spec.assets = {**spec.assets, f"terrain{k}.bin": np.array(shape, np.int32).tobytes()
                       + bytes(4 * shape[0] * shape[1])}
        spec.add_hfield(name=f"{wm.HFIELD_NAME}{k}", file=f"terrain{k}.bin", size=size)
    m = spec.compile()
    m.hfield_data[:] = np.asarray(heights01, np.float32).reshape(-1)
    return m


def perworld_step(mx, floor: int):
    """``step(asset [N] int32, data [N])``: ``mjx.step`` vmapped over worlds, world ``n``'s floor on asset
    ``asset[n]`` (a per-world ``geom_dataid``)."""
    base = jnp.asarray(mx.geom_dataid)
    return jax.vmap(lambda a, d: mjx.step(mx.replace(geom_dataid=base.at[floor].set(a)), d))


def check_perworld(backend: str, steps: int = 300) -> dict:
    """1.: ``{"supported": bool, "feet_z": [[..], [..]] (m) or None, "plateau_m": float, "error": str or None}``."""
    config = WalkerConfig(terrain_shape=(64, 64), backend=backend, tiles=1, warp_worlds=2)
    out = {"backend": backend, "supported": False, "feet_z": None, "plateau_m": None, "error": None}
    try:
        env = WalkerEnv(config)
        bank = env.make_bank(jnp.zeros((1, 64, 64), jnp.float32))
        state = jax.jit(jax.vmap(env.reset, in_axes=(0, TILE_AXES)))(
            jax.random.split(jax.random.PRNGKey(1), 2), bank.at(jnp.zeros(2, jnp.int32)))
        m = perworld_model(config, np.stack([np.zeros((64, 64)), np.full((64, 64), 0.5)]))
        floor = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, wm.FLOOR_GEOM)
        feet = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, n) for n in env.robot.foot_geoms]
        plateau = 0.5 * float(m.hfield_size[0, 2])
        out["plateau_m"] = plateau
        mx = mjx.put_model(m, impl=backend)
        d = state.data.replace(qpos=state.data.qpos.at[:, 2].add(plateau))  # both dropped from above the plateau
        step = jax.jit(perworld_step(mx, floor))
        asset = jnp.arange(2, dtype=jnp.int32)
        for _ in range(steps):
            d = step(asset, d)
        z = np.asarray(d.geom_xpos)[:, feet, 2]
        out["feet_z"] = z.round(4).tolist()
        out["supported"] = bool(abs(z[1].min() - z[0].min() - plateau) < 0.05)
        if not out["supported"]:
            out["error"] = f"the feet rest {z[1].min() - z[0].min():.3f} m apart, not {plateau:.3f}"
    except Exception as err:  # noqa: BLE001 - the verdict is the point: record why MJX refuses
        out["error"] = f"{type(err).__name__}: {str(err).splitlines()[0][:300] if str(err) else ''}"
    return out


def raw_rate(step, model, data, b: int, steps: int, repeats: int) -> dict:
    """Physics steps/s of ``steps`` calls of ``step(model, data)`` ([b] worlds, random controls in [-0.4, 0.4])."""

    @jax.jit
    def run(model, data, key):
        def body(d, k):
            ctrl = jax.random.uniform(k, d.ctrl.shape, minval=-0.4, maxval=0.4)
            return step(model, d.replace(ctrl=ctrl)), None

        return jax.lax.scan(body, data, jax.random.split(key, steps))[0]

    first, best, out = first_and_best(lambda i: run(model, data, jax.random.PRNGKey(2 + i)), repeats)
    return {"steps_per_s": b * steps / best, "first_call_s": first,
            "nan_fraction": float(jnp.mean(~jnp.all(jnp.isfinite(out.qpos), axis=1)))}


def time_layouts(args, perworld: bool) -> list[dict]:
    """2.: one row per layout and batch size."""
    rows = []
    size = args.size
    base = WalkerConfig(terrain_shape=(size, size), backend=args.backend)
    bank01 = terrain_bank(jax.random.PRNGKey(11), args.bank, size)
    bank_m = bank01 * base.scale.height
    for b in args.batch_sizes:
        tiled = {}
        for layout, tiles in (("tiles", args.bank), ("shared", 1)):
            env = WalkerEnv(base._replace(tiles=tiles, warp_worlds=b))
            bank = env.make_bank(bank_m[:tiles])
            state = jax.jit(jax.vmap(env.reset, in_axes=(0, TILE_AXES)))(
                jax.random.split(jax.random.PRNGKey(1), b), bank.at(jnp.arange(b) % tiles))
            r = raw_rate(jax.vmap(mjx.step, in_axes=(None, 0)), env.model(bank), state.data, b, args.steps,
                         args.repeats)
            rows.append({"layout": layout, "batch": b, "terrains": tiles, **r})
            log(rows[-1])
            if layout == "tiles":
                tiled = {"env": env, "data": state.data}
        if perworld:
            env, data = tiled["env"], tiled["data"]
            m = perworld_model(base, np.asarray(bank01))
            floor = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, wm.FLOOR_GEOM)
            x0, y0 = env.tile_origin(jnp.arange(b) % args.bank)  # the same starts, at each asset's origin
            data = data.replace(qpos=data.qpos.at[:, 0].add(-x0).at[:, 1].add(-y0))
            step = perworld_step(mjx.put_model(m, impl=args.backend), floor)
            asset = jnp.arange(b, dtype=jnp.int32) % args.bank
            r = raw_rate(step, asset, data, b, args.steps, args.repeats)
            rows.append({"layout": "perworld", "batch": b, "terrains": args.bank, **r})
            log(rows[-1])
    return rows


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--backend", default="warp", help="physics backend: jax or warp")
    p.add_argument("--batch-sizes", default="32768,65536", help="comma list of envs (worlds) stepped together")
    p.add_argument("--bank", type=int, default=256, help="distinct terrains (tiles / assets), >= 2")
    p.add_argument("--size", type=int, default=256, help="terrain samples per side")
    p.add_argument("--steps", type=int, default=500, help="physics steps per timed call")
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--skip", default="", help="comma list of parts to skip: check, timing")
    p.add_argument("--out", default=None, help="JSON result path")
    args = p.parse_args(argv)

    def fail(msg):
        p.exit(2, f"{p.prog}: error: {msg}\n")

    if args.backend not in ("jax", "warp"):
        fail(f"--backend: {args.backend!r} is not jax or warp")
    try:
        args.batch_sizes = [int(v) for v in args.batch_sizes.split(",") if v]
    except ValueError:
        fail(f"--batch-sizes: a comma list of integers >= 1, got {args.batch_sizes!r}")
    if not args.batch_sizes or min(args.batch_sizes) < 1:
        fail(f"--batch-sizes: a comma list of integers >= 1, got {args.batch_sizes}")
    for name, lo in (("bank", 2), ("size", 32), ("steps", 1), ("repeats", 1)):
        if getattr(args, name) < lo:
            fail(f"--{name}: must be >= {lo}, got {getattr(args, name)}")
    unknown = set(filter(None, args.skip.split(","))) - {"check", "timing"}
    if unknown:
        fail(f"--skip: {sorted(unknown)} not among check, timing")
    return args


def main(argv=None) -> dict:
    args = parse_args(argv)
    skip = set(filter(None, args.skip.split(",")))
    if args.backend == "warp" and not walker.warp_available()[0]:
        raise SystemExit(f"layouts.py: error: --backend warp: {walker.warp_available()[1]}")
    result = {"environment": environment(), "backend": args.backend, "check": None, "timing": []}
    log("environment", result["environment"])
    if "check" not in skip:
        result["check"] = check_perworld(args.backend)
        log("per-world heightfield assets:", result["check"])
        write_json(args.out, result)
    if "timing" not in skip:
        perworld = bool(result["check"] and result["check"]["supported"])
        result["timing"] = time_layouts(args, perworld)
        for r in result["timing"]:
            peer = next(t for t in result["timing"] if t["layout"] == "tiles" and t["batch"] == r["batch"])
            r["vs_tiles"] = r["steps_per_s"] / peer["steps_per_s"]
        write_json(args.out, result)
        print(markdown_table([{"layout": r["layout"], "batch": r["batch"], "terrains": r["terrains"],
                               "M steps/s": r["steps_per_s"] / 1e6, "vs tiles": r["vs_tiles"],
                               "compile+1st s": r["first_call_s"]} for r in result["timing"]],
                             ["layout", "batch", "terrains", "M steps/s", "vs tiles", "compile+1st s"]))
    check = result["check"]
    if check is not None:
        print(f"per-world heightfield assets ({args.backend}): "
              f"{'supported' if check['supported'] else 'NOT supported: ' + str(check['error'])}")
    return result


if __name__ == "__main__":
    main()
