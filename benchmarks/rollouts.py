"""Walker rollout throughput on the GPU machine, against raw MJX (XML solver options) and MuJoCo C's rollout.

Every part walks / simulates one robot, ``--robot NAME`` (default ``humanoid``; shipped: ``humanoid``, ``ant``,
``jaxterrain.walker.robots``): its ``WalkerConfig(robot=NAME)`` defaults, its MJCF on the heightfield (raw MJX and
MuJoCo C step the same model) and its shipped base policy. The result JSON and the printed header name the robot.

Measures, in one run (every figure after a warm-up / compile, device work waited for with block_until_ready):

1. ours: physics steps/s of the batched walker (``jaxterrain.walker.WalkerEnv``, its default solver
   options ``SOLVER_SOUND``: Newton 4 / 16, no Euler damping) with the policy in the loop (obs -> policy MLP ->
   env.step, auto-reset on done), every env on its own 256 x 256 terrain, at several batch sizes, for every
   ``--backend`` (``jax``: MJX-JAX, ``warp``: MJX-Warp) and ``--layout`` (``classic``: each env carries its own
   heightfield in a batched model field, MJX-JAX only; ``tiles``: one heightfield holding the ``--bank`` terrains
   as tiles, env ``i`` on tile ``i % bank``, see ``jaxterrain.walker.tiles``; ``shared``: one heightfield of ONE
   terrain, the bank's first, under every env, i.e. a bank of one tile: the peer that says what the tiles cost);
   Warp runs the tiles and shared layouts;
2. (a) raw MJX with the XML's solver options (Newton, iterations 8, ls_iterations 50, Euler damping) and random
   actions on the same terrains, plus raw MJX with our options (the policy/env overhead is the difference) and
   any others (``--raw-solvers``, e.g. ``fast``: brax's Newton 1 / 4), per backend / layout as in 1.;
3. (b) MuJoCo C ``mujoco.rollout`` with ``--threads`` threads on the same model and terrains, random controls
   (both solver settings);
4. ``difficulty`` timings: one paper generation (20 terrains x 20 attempts) via ``difficulty.evaluate`` and
   4096 terrains x 20 attempts (the compiled batched rollout), with the number of env steps actually simulated
   (the rollout loop stops when every attempt has ended);
5. solver check: the policy's flat-ground normalised distance (best 5 / all 20 of 20 attempts on 8 flat terrains)
   under our solver options and under the XML's converged ones - with the shipped base policy this is the evidence
   that our settings keep the walking sound;
6. backend check (``--backend`` with more than one backend): the same policy, keys and terrains under every
   backend (tiles layout): flat-ground best 5 / all 20 distance and fitness (best 5 of 20) on ``--check-perlin``
   Perlin terrains, with the largest per-terrain fitness difference against the first backend (issue 14's bar:
   0.03).

The policy is the robot's shipped base policy when ``jaxterrain.difficulty.robot_base_policy(robot)`` finds it (the
humanoid's: ``jaxterrain.rl.load_policy()``), else an MLP of the PPO config's size with random parameters (said in the
output). Terrains: Perlin terrains from ``jaxterrain.generators`` (a bank of ``--bank`` distinct maps, tiled to one
per env), heights ``* scale.height`` metres.

    python benchmarks/rollouts.py --out runs/rollouts.json
    python benchmarks/rollouts.py --robot ant --out runs/rollouts_ant.json

Every batch size is one XLA compile (~0.5-1 min on the GPU machine; MJX-Warp compiles in seconds); to stay inside a
10-minute command, split: ``--skip eval,solver,backend`` (throughput table) and ``--skip ours,raw,c`` (difficulty
timings and checks). Backends: ``--backend jax,warp --layout classic,tiles`` (warp needs ``pip install
'jaxterrain[warp]'``; its rows are skipped with the reason when warp does not import).
"""

from __future__ import annotations

import argparse
import copy
import os
import sys
import time
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import mujoco  # noqa: E402
from mujoco import mjx  # noqa: E402

from common import block, environment, first_and_best, markdown_table, write_json  # noqa: E402
from jaxterrain import difficulty  # noqa: E402
from jaxterrain.difficulty import evaluation
from jaxterrain.terrain import TerrainScale  # noqa: E402
from jaxterrain import walker  # noqa: E402
from jaxterrain.walker import SOLVER_SOUND, SOLVER_XML, SolverOptions, WalkerConfig, WalkerEnv  # noqa: E402


def log(*a):
    print(f"[{time.strftime('%H:%M:%S')}]", *a, flush=True)


def terrain_bank(key, n: int, size: int) -> jax.Array:
    """``[n, size, size]`` heightmaps in [0, 1]: Perlin from the generator registry, else random smooth waves."""
    try:
        from jaxterrain import generators

        gen = generators.get("perlin", size=size)
        maps = gen.render(gen.sample(key, n))
        return jnp.clip(jnp.asarray(maps, jnp.float32), 0.0, 1.0)
    except Exception as err:  # noqa: BLE001 - the benchmark must run without the generators too
        log(f"perlin generator unavailable ({err!r}); using random smooth waves")
        kf, kp = jax.random.split(key)
        freqs = jax.random.uniform(kf, (n, 8, 2), minval=0.5, maxval=4.0)
        phase = jax.random.uniform(kp, (n, 8), maxval=2 * np.pi)
        g = jnp.linspace(0, 2 * np.pi, size)
        yy, xx = jnp.meshgrid(g, g, indexing="ij")
        waves = jnp.sin(freqs[..., 0, None, None] * xx + freqs[..., 1, None, None] * yy + phase[..., None, None])
        h = waves.sum(1)
        h = (h - h.min((1, 2), keepdims=True)) / (h.max((1, 2), keepdims=True) - h.min((1, 2), keepdims=True))
        return h


def make_policy(env: WalkerEnv, key, robot: str = "humanoid"):
    """(policy(obs) -> action, description): ``robot``'s shipped base policy, else a random MLP of the PPO size."""
    from jaxterrain import rl

    try:
        policy = difficulty.robot_base_policy(robot)
        if int(policy.observation_size) == env.observation_size:
            return policy, f"shipped base policy ({policy.path})"
        log("shipped policy has another observation size; using a random MLP")
    except (FileNotFoundError, ValueError, RuntimeError) as err:
        log(f"no shipped policy ({err}); using a random MLP of the PPO size")
    from jaxterrain.rl import networks as nets

    cfg = rl.PPOConfig()

    params = nets.init_params(key, cfg, env.observation_size, env.action_size)
    stats = nets.init_stats(env.observation_size)

    def policy(obs):
        return nets.deterministic_action(cfg, env.action_size, params, stats, obs)

    return policy, f"random-parameter MLP of the PPO size (policy_hidden={tuple(cfg.policy_hidden)})"


# --------------------------------------------------------------------------------------------------------------
def per_env_terrains(env, bank_m, b):
    """(terrain argument of a vmapped reset/step for ``b`` envs, its in_axes): ``[b, H, W]`` copies of the bank
    (classic layout) or the bank's tiles ``i % bank`` (tiled env)."""
    if env.tiles:  # tiles: env.tiles == the bank's size; shared: one tile, the bank's first terrain
        return env.make_bank(bank_m[:env.tiles]).at(jnp.arange(b) % env.tiles), walker.TILE_AXES
    k = bank_m.shape[0]
    return jnp.tile(bank_m, (-(-b // k), 1, 1))[:b], 0


def bench_ours(env, policy, terrains_m, env_steps, repeats, axes=0):
    """Policy in the loop with auto-reset; returns physics steps/s. ``terrains_m``: ``[B, H, W]`` (``axes=0``) or
    a tiled env's ``Tile`` of B indices (``axes=walker.TILE_AXES``)."""
    b = int(jax.tree.leaves(terrains_m)[-1].shape[0])
    reset = jax.vmap(env.reset, in_axes=(0, axes))
    step = jax.vmap(env.step, in_axes=(0, 0, axes))
    act = jax.vmap(policy)

    @jax.jit
    def run(state, init, terrains):
        def body(s, _):
            s = step(s, act(s.obs), terrains)
            s = env.select(s.done > 0, init, s)  # auto-reset (keeps MJX-Warp's shared contact buffers shared)
            return s, s.distance

        return jax.lax.scan(body, state, None, length=env_steps)

    init = jax.jit(reset)(jax.random.split(jax.random.PRNGKey(1), b), terrains_m)
    t0 = time.perf_counter()
    out = block(run(init, init, terrains_m))
    compile_s = time.perf_counter() - t0
    times = []
    state = out[0]
    for _ in range(repeats):
        t0 = time.perf_counter()
        state, _ = block(run(state, init, terrains_m))
        times.append(time.perf_counter() - t0)
    best = min(times)
    return {"steps_per_s": b * env_steps * env.config.n_frames / best, "seconds": best, "first_call_s": compile_s,
            "finite": bool(jnp.all(jnp.isfinite(state.obs)))}


def bench_raw_mjx(env, terrains_m, phys_steps, repeats, axes=0):
    """Raw mjx.step with random controls (uniform in ctrlrange) on per-env hfields (classic) or on the tiles of one
    shared heightfield (tiled env: ``terrains_m`` a ``Tile``, ``axes=walker.TILE_AXES``); no resets."""
    b = int(jax.tree.leaves(terrains_m)[-1].shape[0])
    mx = env.mjx_model
    lo, hi = env._ctrl_lo, env._ctrl_hi
    init = jax.jit(jax.vmap(env.reset, in_axes=(0, axes)))(jax.random.split(jax.random.PRNGKey(1), b),
                                                            terrains_m).data

    @jax.jit
    def run(data, terrains, key):
        def one(d, m, k):
            def body(d, kk):
                ctrl = jax.random.uniform(kk, (mx.nu,), minval=lo, maxval=hi)
                return mjx.step(m, d.replace(ctrl=ctrl)), None

            return jax.lax.scan(body, d, jax.random.split(k, phys_steps))[0]

        keys = jax.random.split(key, b)
        if env.tiles:  # one model (the whole bank) shared by every env
            m = env.model(terrains.bank)
            return jax.vmap(lambda d, k: one(d, m, k))(data, keys)
        hdata = jnp.clip(terrains / env.elevation_z, 0, 1).reshape(b, -1)
        return jax.vmap(lambda d, h, k: one(d, mx.replace(hfield_data=h), k))(data, hdata, keys)

    compile_s, best, out = first_and_best(lambda i: run(init, terrains_m, jax.random.PRNGKey(2 + i)), repeats)
    return {"steps_per_s": b * phys_steps / best, "seconds": best, "first_call_s": compile_s,
            "nan_fraction": float(jnp.mean(~jnp.all(jnp.isfinite(out.qpos), axis=1)))}


def bench_c_rollout(env, terrains_m_bank, qpos0, nroll, nstep, threads):
    """MuJoCo C multithreaded rollout, one MjModel per distinct terrain, random controls."""
    from mujoco import rollout

    base = env.mj_model
    models = []
    for t in np.asarray(terrains_m_bank):
        m = copy.copy(base)
        m.hfield_data[:] = np.clip(t / env.elevation_z, 0, 1).ravel()
        models.append(m)
    k = len(models)
    model_list = [models[i % k] for i in range(nroll)]
    datas = [mujoco.MjData(base) for _ in range(threads)]
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    d = mujoco.MjData(base)
    states = np.zeros((nroll, mujoco.mj_stateSize(base, spec)))
    for i in range(nroll):
        mujoco.mj_resetData(base, d)
        d.qpos[:] = qpos0[i % k]
        mujoco.mj_getState(base, d, states[i], spec)
    rng = np.random.default_rng(0)
    lo, hi = base.actuator_ctrlrange[:, 0], base.actuator_ctrlrange[:, 1]
    control = rng.uniform(lo, hi, (nroll, nstep, base.nu))
    rollout.rollout(model_list[:threads], datas, states[:threads], control[:threads, :10])  # warm-up
    t0 = time.perf_counter()
    state, _ = rollout.rollout(model_list, datas, states, control)
    sec = time.perf_counter() - t0
    return {"steps_per_s": nroll * nstep / sec, "seconds": sec, "threads": threads, "rollouts": nroll,
            "nstep": nstep, "nan_fraction": float(np.mean(~np.all(np.isfinite(state[:, -1]), axis=1)))}


def bench_difficulty(cfg, policy, heightmaps, attempts, repeats, slots=None):
    """Wall time of ``difficulty.evaluate`` (host validation + the one compiled batched rollout + best-5), after a
    first call that compiles; the episode lengths (env steps simulated) come from that first call. ``slots``: the
    rollout pool size (None = every rollout at once)."""
    b = heightmaps.shape[0]
    fn = evaluation._compiled(cfg, attempts, policy, False, slots)  # the function evaluate() calls (same cache entry)
    t0 = time.perf_counter()
    dist, length = block(fn(heightmaps * cfg.scale.height, jax.random.PRNGKey(7), None))
    first = time.perf_counter() - t0
    length = np.asarray(length)
    times = []
    for r in range(repeats):
        t0 = time.perf_counter()
        fit = block(difficulty.evaluate(heightmaps, jax.random.PRNGKey(8 + r), attempts, 5, policy=policy,
                                        env_config=cfg, slots=slots))
        times.append(time.perf_counter() - t0)
    return {"terrains": b, "attempts": attempts, "slots": slots, "seconds": min(times), "first_call_s": first,
            "loop_iterations": int(length.max()), "mean_episode_steps": float(length.mean()),
            "env_steps": int(length.sum()), "fitness_mean": float(jnp.mean(fit)), "fitness_min": float(jnp.min(fit)),
            "fitness_max": float(jnp.max(fit)), "distance_mean": float(jnp.mean(dist))}


def parse_solver(text: str) -> tuple[str, SolverOptions]:
    """``"sound"``, ``"fast"``, ``"xml"`` or ``"ITERATIONS,LS_ITERATIONS,EULERDAMP"`` -> (label, options); see
    walker.parse_solver."""
    solver = walker.parse_solver(text)
    return (text if text in walker.NAMED_SOLVERS else walker.solver_label(solver)), solver


def solver_check(cfg, policy, solvers=(("sound", SOLVER_SOUND), ("xml", SOLVER_XML)), n_terrains=8, attempts=20):
    """Flat-ground walking of the policy under each of ``solvers`` ((name, SolverOptions) pairs; default ours and
    the XML's): best-5 and all-20 means of the normalised distance."""
    out = {}
    flat = jnp.zeros((n_terrains,) + tuple(cfg.terrain_shape), jnp.float32)
    for name, solver in solvers:
        c = cfg._replace(solver=solver)
        d = np.asarray(block(difficulty.rollout_distances(flat, jax.random.PRNGKey(5), attempts, policy=policy,
                                                          env_config=c)))
        out[name] = {"best5_mean": float(np.mean(np.sort(d, axis=1)[:, -5:])), "all_mean": float(d.mean()),
                     "min": float(d.min()), "max": float(d.max())}
    return out


def tiled_distances(env, policy, terrains_m, key, attempts):
    """``[B, attempts]`` final normalised distances (0 where failed) of ``attempts`` walks on each of ``terrains_m``
    ``[B, H, W]`` on a tiled env (``tiles = B``): walker.rollout.batched_distances' loop with the terrains as tiles."""
    b = terrains_m.shape[0]

    @jax.jit
    def run(terrains_m, key):
        reset_keys = jax.random.split(key, (b, attempts))
        tiles = env.make_bank(terrains_m).at(jnp.arange(b))
        reset = jax.vmap(jax.vmap(env.reset, in_axes=(0, None)), in_axes=(0, walker.TILE_AXES))
        step = jax.vmap(jax.vmap(env.step, in_axes=(0, 0, None)), in_axes=(0, 0, walker.TILE_AXES))
        act = jax.vmap(jax.vmap(policy))
        state = reset(reset_keys, tiles)

        def cond(c):
            return (c[0] < env.config.episode_length) & ~jnp.all(c[2])

        def body(c):
            t, state, ended, final, length = c
            state = step(state, act(state.obs), tiles)
            final = jnp.where(ended, final, jnp.where(state.failed > 0, 0.0, state.distance))
            length = jnp.where(ended, length, state.steps)
            return t + 1, state, ended | (state.done > 0), final, length

        zeros = jnp.zeros((b, attempts), jnp.float32)
        c = jax.lax.while_loop(cond, body, (jnp.int32(0), state, zeros > 0, zeros, zeros.astype(jnp.int32)))
        return c[3], c[4]

    return run(terrains_m, key)


def backend_check(cfg, policy, backends, n_flat, perlin_m, attempts=20, best=5):
    """Per backend (tiles layout; same keys, terrains, policy): flat-ground best-5 / all means of the normalised
    distance over ``n_flat`` flat terrains x ``attempts``, and fitness (mean of the best 5) on the ``perlin_m``
    terrains ``[P, H, W]`` metres, with the largest |fitness difference| against the first backend."""
    flat = jnp.zeros((n_flat,) + tuple(cfg.terrain_shape), jnp.float32)
    terrains = jnp.concatenate([flat, jnp.asarray(perlin_m, jnp.float32)])
    b = terrains.shape[0]
    out, first = {}, None
    for backend in backends:
        env = WalkerEnv(cfg._replace(backend=backend, tiles=b, warp_worlds=b * attempts))
        t0 = time.perf_counter()
        d, length = block(tiled_distances(env, policy, terrains, jax.random.PRNGKey(5), attempts))
        d, length = np.asarray(d), np.asarray(length)
        fit = np.sort(d, axis=1)[:, -best:].mean(1)
        r = {"seconds_incl_compile": time.perf_counter() - t0, "env_steps": int(length.sum()),
             "flat_best5_mean": float(fit[:n_flat].mean()) if n_flat else None,
             "flat_all_mean": float(d[:n_flat].mean()) if n_flat else None,
             "perlin_fitness": fit[n_flat:].tolist(), "perlin_fitness_mean": float(fit[n_flat:].mean())
             if b > n_flat else None}
        if first is None:
            first = fit
        else:
            r["max_abs_fitness_diff_vs_" + backends[0]] = float(np.max(np.abs(fit - first)))
            r["mean_fitness_diff_vs_" + backends[0]] = float(np.mean(fit - first))
        out[backend] = r
    return out


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default=None, help="JSON result path")
    p.add_argument("--robot", default="humanoid", metavar="NAME",
                   help=f"the robot every part walks / simulates: {', '.join(walker.robots.names())}")
    p.add_argument("--batch-sizes", default="8192,32768", help="ours: envs per batch")
    p.add_argument("--raw-batch-sizes", default="32768", help="raw MJX (every --raw-solvers): envs per batch")
    p.add_argument("--env-steps", type=int, default=100, help="env steps per timed call (x5 physics steps)")
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--size", type=int, default=256, help="terrain samples per side")
    p.add_argument("--cell-size", type=float, default=TerrainScale().cell_size, help="metres per sample")
    p.add_argument("--bank", type=int, default=256, help="distinct terrains, tiled over the envs")
    p.add_argument("--threads", type=int, default=os.cpu_count() or 16, help="MuJoCo C rollout threads")
    p.add_argument("--c-rollouts", type=int, default=1024)
    p.add_argument("--c-steps", type=int, default=500, help="physics steps per C rollout")
    p.add_argument("--eval-batches", default="20,4096", help="terrains per difficulty.evaluate timing")
    p.add_argument("--eval-slots", default="none", help="comma list of rollout pool sizes per eval batch ('none': "
                   "all rollouts at once)")
    p.add_argument("--raw-solvers", default="xml;sound", help="';' list of solvers for raw MJX: xml, sound, fast or "
                   "ITERATIONS,LS_ITERATIONS,EULERDAMP")
    p.add_argument("--check-solvers", default="sound;xml", help="';' list of solvers for the flat-ground check")
    p.add_argument("--backend", default="jax", help="comma list of physics backends for ours / raw: jax, warp")
    p.add_argument("--layout", default="classic,tiles", help="comma list of terrain layouts for ours / raw: classic "
                   "(per-env heightfield, jax only), tiles (one heightfield of --bank tiles), shared (one heightfield of one "
                   "terrain under every env)")
    p.add_argument("--check-flat", type=int, default=8, help="backend check: flat terrains (x 20 attempts)")
    p.add_argument("--check-perlin", type=int, default=64, help="backend check: Perlin terrains (x 20 attempts)")
    p.add_argument("--skip", default="", help="comma list of parts to skip: ours,raw,c,eval,solver,backend")
    args = p.parse_args(argv)
    try:
        walker.robots.get(args.robot)
    except ValueError as err:  # one line, before anything compiles
        p.exit(2, f"{p.prog}: error: --robot: {err}\n")
    for v in filter(None, args.backend.split(",")):
        if v not in walker.BACKENDS:
            p.exit(2, f"{p.prog}: error: --backend: {v!r} is not one of {walker.BACKENDS}\n")
    for v in filter(None, args.layout.split(",")):
        if v not in ("classic", "tiles", "shared"):
            p.exit(2, f"{p.prog}: error: --layout: {v!r} is not classic, tiles or shared\n")
    return args


def ints(text: str) -> list[int]:
    """A comma list of ints: '8192,32768' -> [8192, 32768]."""
    return [int(v) for v in text.split(",") if v]


class Bench(NamedTuple):
    """What every part runs on, and where its rows and results go (``save()`` after each row)."""

    args: argparse.Namespace
    cfg: WalkerConfig
    env: WalkerEnv
    policy: object
    bank: jax.Array  # [bank, size, size] heightmaps in [0, 1]
    bank_m: jax.Array  # the same in metres
    variants: list  # [(backend, layout)] that can run here
    rows: list
    result: dict

    def variant_env(self, backend: str, layout: str, b: int, solver=None) -> WalkerEnv:
        c = self.cfg if solver is None else self.cfg._replace(solver=solver)
        if layout in ("tiles", "shared"):
            c = c._replace(backend=backend, tiles=self.args.bank if layout == "tiles" else 1, warp_worlds=max(b, 1))
        return WalkerEnv(c)

    def add(self, row: dict) -> None:
        self.rows.append(row)
        log(row)
        self.save()

    def save(self) -> None:
        write_json(self.args.out, self.result)


def runnable_variants(backends: list[str], layouts: list[str]) -> tuple[list, list[str]]:
    """([(backend, layout)] to run, [why each other one is skipped]): Warp runs the tiles and shared layouts only,
    and only where it imports."""
    warp_ok, warp_why = walker.warp_available()
    variants, skipped = [], []
    for backend in backends:
        for layout in layouts:
            if backend == "warp" and layout == "classic":
                continue  # MuJoCo Warp shares one heightfield across worlds: tiles or shared only
            if backend == "warp" and not warp_ok:
                skipped.append(f"{backend}/{layout}: {warp_why}")
                continue
            variants.append((backend, layout))
    return variants, skipped


def part_ours(bench: Bench) -> None:
    """1. the walker with the policy in the loop, per variant and batch size (stops growing a variant on OOM)."""
    for backend, layout in bench.variants:
        for b in ints(bench.args.batch_sizes):
            try:
                e = bench.variant_env(backend, layout, b)
                terr, axes = per_env_terrains(e, bench.bank_m, b)
                r = bench_ours(e, bench.policy, terr, bench.args.env_steps, bench.args.repeats, axes=axes)
            except Exception as err:  # noqa: BLE001 (out of memory: stop growing)
                log(f"ours {backend}/{layout} at {b} envs failed: {type(err).__name__}: {str(err)[:300]}")
                break
            r.update(batch=b, backend=backend, layout=layout)
            bench.result["ours"].append(r)
            bench.add({"what": f"ours: walker + policy, {walker.solver_label(bench.cfg.solver)}",
                       "backend": f"{backend}/{layout}", "batch": b, "M steps/s": r["steps_per_s"] / 1e6,
                       "compile+1st s": r["first_call_s"]})


def part_raw(bench: Bench) -> None:
    """2. (a) raw MJX, random actions, per --raw-solvers entry, variant and batch size."""
    for text in filter(None, bench.args.raw_solvers.split(";")):
        sname, solver = parse_solver(text)
        name = f"raw_mjx_{sname}" if text in walker.NAMED_SOLVERS else f"raw_mjx {sname}"
        bench.result.setdefault(name, [])
        for backend, layout in bench.variants:
            for b in ints(bench.args.raw_batch_sizes):
                try:
                    e = bench.variant_env(backend, layout, b, solver)
                    terr, axes = per_env_terrains(e, bench.bank_m, b)
                    r = bench_raw_mjx(e, terr, bench.args.env_steps * bench.cfg.n_frames, bench.args.repeats,
                                      axes=axes)
                except Exception as err:  # noqa: BLE001
                    log(f"{name} {backend}/{layout} at {b} envs failed: {type(err).__name__}: {str(err)[:300]}")
                    break
                r.update(batch=b, backend=backend, layout=layout)
                bench.result[name].append(r)
                bench.add({"what": f"(a) {name.replace('_', ' ')}, random actions", "backend": f"{backend}/{layout}",
                           "batch": b, "M steps/s": r["steps_per_s"] / 1e6, "compile+1st s": r["first_call_s"]})


def part_c(bench: Bench) -> None:
    """3. (b) MuJoCo C rollout, XML and our solver options."""
    args = bench.args
    qpos0 = np.asarray(jax.jit(jax.vmap(bench.env.reset))(jax.random.split(jax.random.PRNGKey(1), args.bank),
                                                           bench.bank_m).data.qpos)
    env_xml = WalkerEnv(bench.cfg._replace(solver=SOLVER_XML))
    for name, e in (("xml", env_xml), ("ours", bench.env)):
        r = bench_c_rollout(e, bench.bank_m, qpos0, args.c_rollouts, args.c_steps, args.threads)
        r["solver"] = name
        bench.result["mujoco_c"].append(r)
        bench.add({"what": f"(b) MuJoCo C rollout, {name} solver, {args.threads} threads", "backend": "C",
                   "batch": args.c_rollouts, "M steps/s": r["steps_per_s"] / 1e6})


def part_eval(bench: Bench) -> None:
    """4. difficulty.evaluate timings, per eval batch and rollout pool size."""
    args = bench.args
    pools = [None if v == "none" else int(v) for v in args.eval_slots.split(",") if v]
    for b, slots in [(b, n) for b in ints(args.eval_batches) for n in pools]:
        if slots is not None and slots >= b * 20:
            continue
        hm = jnp.tile(bench.bank, (-(-b // args.bank), 1, 1))[:b]
        r = bench_difficulty(bench.cfg, bench.policy, hm, 20, args.repeats if b <= 512 else 1, slots)
        bench.result["difficulty"].append(r)
        bench.add({"what": f"difficulty.evaluate {b} terrains x 20 attempts, slots {slots or 'all'}",
                   "backend": "jax/classic", "batch": b * 20, "seconds": r["seconds"],
                   "compile+1st s": r["first_call_s"],
                   "M steps/s": r["env_steps"] * bench.cfg.n_frames / r["seconds"] / 1e6,
                   "note": f"{r['env_steps']} env steps, longest {r['loop_iterations']}, "
                           f"fitness mean {r['fitness_mean']:.3f}"})


def part_solver(bench: Bench) -> None:
    """5. the policy's flat-ground distance under each --check-solvers entry."""
    r = solver_check(bench.cfg, bench.policy, [parse_solver(t) for t in bench.args.check_solvers.split(";") if t])
    bench.result["solver_check"] = r
    for name, v in r.items():
        bench.add({"what": f"flat ground, {name} solver: normalised distance best-5 / all-20",
                   "backend": "jax/classic", "note": f"{v['best5_mean']:.3f} / {v['all_mean']:.3f}"})


def part_backend(bench: Bench, backends: list[str]) -> None:
    """6. the same policy, keys and terrains under every backend that runs here."""
    args = bench.args
    chk = [v for v in backends if v == "jax" or walker.warp_available()[0]]
    perlin_m = bench.bank_m[: args.check_perlin] if args.check_perlin <= args.bank else \
        terrain_bank(jax.random.PRNGKey(12), args.check_perlin, args.size) * bench.cfg.scale.height
    r = backend_check(bench.cfg, bench.policy, chk, args.check_flat, perlin_m)
    bench.result["backend_check"] = r
    for name, v in r.items():
        diff = v.get(f"max_abs_fitness_diff_vs_{chk[0]}")
        flat_txt = (f"flat best-5 / all-20 {v['flat_best5_mean']:.3f} / {v['flat_all_mean']:.3f}; "
                    if v["flat_best5_mean"] is not None else "")
        perlin_txt = (f"Perlin fitness mean {v['perlin_fitness_mean']:.3f} over {len(v['perlin_fitness'])}"
                      if v["perlin_fitness_mean"] is not None else "")
        bench.add({"what": f"backend check ({args.check_flat} flat + {len(v['perlin_fitness'])} Perlin x 20)",
                   "backend": f"{name}/tiles", "note": flat_txt + perlin_txt + (
                       f"; max |fitness diff| vs {chk[0]} {diff:.3f}" if diff is not None else "")})


def main(argv=None):
    args = parse_args(argv)
    skip = set(filter(None, args.skip.split(",")))
    backends = [v for v in args.backend.split(",") if v]
    env_info = environment()
    log("environment", env_info)
    scale = TerrainScale(cell_size=args.cell_size)
    cfg = WalkerConfig(terrain_shape=(args.size, args.size), scale=scale, robot=args.robot)
    env = WalkerEnv(cfg)
    log("robot:", args.robot)
    policy, policy_desc = make_policy(env, jax.random.PRNGKey(0), args.robot)
    log("policy:", policy_desc)
    bank = terrain_bank(jax.random.PRNGKey(11), args.bank, args.size)
    variants, skipped = runnable_variants(backends, [v for v in args.layout.split(",") if v])
    for why in skipped:
        log("skipped", why)
    result = {"environment": env_info, "variants": [list(v) for v in variants], "skipped": skipped,
              "robot": args.robot, "policy": policy_desc, "solver_ours": cfg.solver._asdict(),
              "solver_xml": SOLVER_XML._asdict(),
              "terrain": {"shape": [args.size, args.size], "scale": scale._asdict(), "distinct": args.bank},
              "ours": [], "raw_mjx_xml": [], "raw_mjx_sound": [], "mujoco_c": [], "difficulty": []}
    bench = Bench(args, cfg, env, policy, bank, bank * scale.height, variants, [], result)
    parts = {"ours": part_ours, "raw": part_raw, "c": part_c, "eval": part_eval, "solver": part_solver,
             "backend": lambda b: part_backend(b, backends)}
    for name, part in parts.items():
        if name not in skip:
            part(bench)
    best_ours = max((r["steps_per_s"] for r in result["ours"]), default=0.0)
    best_c = max((r["steps_per_s"] for r in result["mujoco_c"] if r["solver"] == "xml"), default=0.0)
    result["summary"] = {"best_ours_steps_per_s": best_ours, "c_xml_steps_per_s": best_c,
                         "speedup_vs_c": best_ours / best_c if best_c else None}
    bench.save()
    print()
    print(f"device: {env_info['device']}; robot: {args.robot}; policy: {policy_desc}; "
          f"terrains: per-env {args.size}x{args.size}")
    print(markdown_table(bench.rows, ["what", "backend", "batch", "M steps/s", "seconds", "compile+1st s", "note"]))
    print(f"\nours best {best_ours / 1e6:.2f} M physics steps/s; vs MuJoCo C (XML solver) "
          f"{(best_ours / best_c) if best_c else float('nan'):.1f}x")


if __name__ == "__main__":
    main()
