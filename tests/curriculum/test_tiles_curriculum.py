"""The curriculum on tiles (``Harness.layout``): every chunk the T trials' current terrains become one bank of T
tiles, built outside the trial vmap, and trial i walks tile i. CPU, tiny sizes.

- Toy banks with a fake harness that reads its terrain through a REAL tiled walker's tile arithmetic (``make_bank``
  via ``curriculum.walker.tile_layout``, ``tile_origin``, ``terrain_height``; no physics, so these compile in
  seconds): a block of chunks on tiles equals the classic block exactly (dyadic cell sizes and heights, so the
  shifted coordinates are exact), trials keep their own terrains, nothing re-traces when terrains change.
- MuJoCo Warp (skipped with the reason where ``warp-lang`` / MJX's MuJoCo Warp do not import): one tiny curriculum
  block of the real walker harness (PPO + evaluation) on tiles.
- Slow: the MJX walker harness on a one-tile bank (one trial) equals the classic harness bit for bit.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxterrain import curriculum as C
from jaxterrain.qd import TerrainBank, cell_distance
from jaxterrain.curriculum import walker as W
from jaxterrain.terrain import TerrainScale
from jaxterrain.walker import Tile, WalkerConfig, WalkerEnv, warp_available
from jaxterrain.curriculum import run_config, runner
from jaxterrain.walker import layout
from jaxterrain.runtime import xla
from scripts import ROOT, load_script


def validated(cfg: dict):
    """``(CurriculumConfig, archive, policy, env)`` of a flat (``config.json``) run config."""
    return runner.validate(run_config.from_flat(cfg))[1:]

WARP_OK, WARP_WHY = warp_available()
FAST_COMPILE = xla.known_options({"xla_backend_optimization_level": 0, "xla_llvm_disable_expensive_passes": True})

SHAPE = (16, 16)
EXACT = TerrainScale(cell_size=0.25, height=1.0)  # tile origins multiples of 2 m, 0.25 m cells: exact shifts
PROBE = np.stack(np.meshgrid(np.arange(-1.5, 1.6, 0.5), np.arange(-1.5, 1.6, 0.5)), -1).reshape(-1, 2).astype(
    np.float32)  # tile-local sample points


def toy_bank(grid: int = 3, shape=SHAPE) -> TerrainBank:
    """Every cell of a grid x grid map: prior fitness ``1 - d`` with d = (b0 + b1) / (2 grid) (harder away from the
    origin), terrain = a ``shape`` map of constant height d (a multiple of 1/8 for grid <= 4: exact)."""
    b0, b1 = np.meshgrid(np.arange(grid), np.arange(grid))
    bins = np.stack([b0.ravel(), b1.ravel()], -1).astype(np.int32)
    d = ((bins[:, 0] + bins[:, 1]) / (2.0 * grid)).astype(np.float32)
    d = np.round(d * 8) / 8
    points = (bins / max(grid - 1, 1)).astype(np.float32)
    maps = np.broadcast_to(d[:, None, None], (d.size,) + tuple(shape)).astype(np.float32)
    return TerrainBank(jnp.asarray(maps), jnp.asarray(1.0 - d), jnp.asarray(points), jnp.asarray(points),
                       jnp.asarray(bins), jnp.asarray(cell_distance(bins)), jnp.arange(d.size, dtype=jnp.int32),
                       jnp.zeros(d.size, jnp.int32))


TRACES = {"train": 0}


def fake_harness(env: WalkerEnv, plain: WalkerEnv, tiled: bool, gain: float = 0.1) -> C.Harness:
    """Policy {"skill", "resets", "seen"}: a chunk adds ``gain`` to the skill; fitness = clip(1 - level + skill,
    0, 1), level = mean terrain height at PROBE read through the walker (a Tile of ``env`` on tiles, an [H, W]
    array of ``plain`` otherwise); ``seen`` accumulates the levels trained on (a wrong tile changes it)."""

    def level(terrain):
        px, py = jnp.asarray(PROBE[:, 0]), jnp.asarray(PROBE[:, 1])
        if isinstance(terrain, Tile):
            ox, oy = env.tile_origin(terrain.index)
            return jnp.mean(env.terrain_height(terrain, px + ox, py + oy))
        return jnp.mean(plain.terrain_height(terrain, px, py))

    def train(policy, key, terrain):
        TRACES["train"] += 1
        return dict(policy, skill=policy["skill"] + gain, seen=policy["seen"] + level(terrain))

    def evaluate(policy, key, terrain):
        return jnp.clip(1.0 - level(terrain) + policy["skill"], 0.0, 1.0)

    def reset(policy, key, terrain):
        return dict(policy, resets=policy["resets"] + 1)

    if not tiled:
        return C.Harness(train, evaluate, reset)
    return C.Harness(train, evaluate, reset, layout=W.tile_layout(env))


START = {"skill": jnp.zeros((), jnp.float32), "resets": jnp.zeros((), jnp.int32), "seen": jnp.zeros((), jnp.float32)}


def small(selector="random", **kw) -> C.CurriculumConfig:
    base = dict(selector=selector, epochs_per_chunk=1, steps_per_epoch=8, max_epochs=40, max_evals=3,
                num_envs=2, unroll_length=2, num_unrolls=2, num_minibatches=1)
    return C.validate_config(C.CurriculumConfig.from_json_dict({**base, **kw}))  # the PPO fields flat, as learn


def tree_equal(a, b) -> bool:
    la, lb = jax.tree.leaves(a), jax.tree.leaves(b)
    return len(la) == len(lb) and all(np.array_equal(np.asarray(x), np.asarray(y), equal_nan=True)
                                      for x, y in zip(la, lb))


def _envs(tiles: int):
    cfg = WalkerConfig(terrain_shape=SHAPE, scale=EXACT)
    return WalkerEnv(cfg._replace(tiles=tiles)), WalkerEnv(cfg)


def test_a_block_on_tiles_equals_the_classic_block_on_a_toy_bank():
    """3 trials of the random selector (each its own terrain sequence) for 12 chunks: the tiled layout gives every
    trial exactly the classic result (trial i reads tile i of the chunk's bank)."""
    bank = toy_bank()
    env, plain = _envs(3)
    config = small("random", max_evals=2, max_epochs=12)
    keys = jax.random.split(jax.random.key(4), 3)
    out = {}
    for tiled in (False, True):
        harness = fake_harness(env, plain, tiled, gain=0.05)
        states = C.init_trials(keys, bank, START, config=config, harness=harness)
        out[tiled] = C.make_runner(config, harness)(states, bank, 12)
    assert tree_equal(out[True], out[False])
    terrain = np.asarray(out[True].history.terrain)
    assert len({tuple(t) for t in terrain}) == 3  # the trials walked different sequences
    assert np.all(np.asarray(out[True].policy["seen"]) > 0)  # non-flat terrains were trained on


def test_a_single_trial_step_on_tiles_and_more_tiles_than_trials():
    """``step`` on one trial lays out its terrain alone (tile 0, the other tiles flat) and equals the classic step;
    a runner of 2 trials on a 3-tile walker (e.g. one device's share) equals the classic one; more trials than tiles
    is a ValueError naming tiles."""
    bank = toy_bank()
    env, plain = _envs(3)
    config = small("map", max_evals=2)
    key = jax.random.key(1)
    one = {}
    for tiled in (False, True):
        harness = fake_harness(env, plain, tiled)
        state = C.init(key, bank, START, config=config, harness=harness)
        step = jax.jit(lambda s, k, h=harness: C.step(s, k, bank, config=config, harness=h))
        for c in range(3):
            state = step(state, jax.random.fold_in(key, c))
        one[tiled] = state
    assert tree_equal(one[True], one[False]) and int(one[True].chunk) == 3
    keys = jax.random.split(jax.random.key(2), 2)
    two = [C.make_runner(config, h)(C.init_trials(keys, bank, START, config=config, harness=h), bank, 4)
           for h in (fake_harness(env, plain, False), fake_harness(env, plain, True))]
    assert tree_equal(*two)
    small_env = _envs(1)[0]
    harness = fake_harness(small_env, plain, True)
    with pytest.raises(ValueError, match="tiles=1"):
        C.make_runner(config, harness)(C.init_trials(keys, bank, START, config=config, harness=harness), bank, 1)


def test_no_retrace_on_tiles_when_the_terrain_changes():
    bank = toy_bank()
    env, plain = _envs(2)
    config = small("map", max_evals=2)
    harness = fake_harness(env, plain, True, gain=0.05)
    run = C.make_runner(config, harness)
    states = C.init_trials(jax.random.split(jax.random.key(0), 2), bank, START, config=config, harness=harness)
    TRACES["train"] = 0
    seen = set()
    for block in (3, 4, 5):
        states = run(states, bank, block)
        seen |= set(np.asarray(states.terrain).tolist())
    assert len(seen) >= 3 and TRACES["train"] == 1


def placed_harness(env: WalkerEnv, gain: float = 0.05) -> C.Harness:
    """A tiled fake harness whose "envs" stay where they were spawned, as a walker's do: ``reset`` records the tile
    its envs stand on (``home``, the Tile's index at the restart), and ``train`` / ``evaluate`` read the chunk's bank
    at ``home`` (the heightfield under the bodies), whichever tile the chunk's layout gives the trial. ``seen``
    accumulates the levels trained on, ``wrong`` counts the chunks where ``home`` is not the trial's tile."""

    def level(terrain, home):
        px, py = jnp.asarray(PROBE[:, 0]), jnp.asarray(PROBE[:, 1])
        ox, oy = env.tile_origin(home)
        return jnp.mean(env.terrain_height(Tile(terrain.bank, home), px + ox, py + oy))

    def train(policy, key, terrain):
        return dict(policy, skill=policy["skill"] + gain, seen=policy["seen"] + level(terrain, policy["home"]),
                    wrong=policy["wrong"] + (policy["home"] != terrain.index).astype(jnp.int32))

    def evaluate(policy, key, terrain):
        return jnp.clip(1.0 - level(terrain, policy["home"]) + policy["skill"], 0.0, 1.0)

    def reset(policy, key, terrain):
        return dict(policy, resets=policy["resets"] + 1, home=jnp.asarray(terrain.index, jnp.int32))

    return C.Harness(train, evaluate, reset, layout=W.tile_layout(env))


PLACED_START = {**START, "home": jnp.zeros((), jnp.int32), "wrong": jnp.zeros((), jnp.int32)}


def test_compact_blocks_keep_each_running_trial_on_its_own_tile():
    """The compact-on-tiles bug (docs/results/exp3.md, "Training bug"): 3 trials of the random selector on tiles,
    trial 0 forced done after 2 chunks; then blocks of the running trials only (``run_live``: rows [1, 2]) must
    give the states of blocks of all three, and no envs may walk off their tile. Before the fix the compact block
    laid trials 1 and 2 out on tiles 0 and 1 while their envs stood on tiles 1 and 2 (trial 1 on trial 2's terrain,
    trial 2 on a flat tile) until their next reset."""
    bank = toy_bank(3)
    env, _ = _envs(3)
    config = small("random", max_evals=3, max_epochs=14)
    harness = placed_harness(env)
    run = C.make_runner(config, harness)
    init = lambda: C.init_trials(jax.random.split(jax.random.key(5), 3), bank, PLACED_START,  # noqa: E731
                                 config=config, harness=harness)
    whole, live = run(init(), bank, 2), run(init(), bank, 2)
    assert tree_equal(whole, live) and np.asarray(whole.policy["home"]).tolist() == [0, 1, 2]
    stop = lambda s: s._replace(done=s.done.at[0].set(True))  # noqa: E731 - trial 0's map emptied early
    whole, live = stop(whole), stop(live)
    assert C.live_rows(live.done).tolist() == [1, 2]
    while not np.all(np.asarray(whole.done)):
        whole, live = run(whole, bank, 3), C.run_live(run, live, bank, 3)
        assert tree_equal(live, whole)
    assert np.asarray(live.policy["wrong"]).tolist() == [0, 0, 0]
    terrain = np.asarray(live.history.terrain)
    assert len({tuple(t[2:]) for t in terrain[1:]}) == 2 and np.all(np.asarray(live.policy["seen"])[1:] > 0)


def test_tile_moves_counts_the_trials_the_old_compact_block_moved():
    """``tile_moves``: the running trials whose row in a compact block (``live_rows``) is not their index: those
    the runner before the fix laid out on another trial's tile."""
    done = np.array([True, False, False, True, False, True])
    assert C.live_rows(done).tolist() == [0, 1, 2, 4]  # 3 running -> 4 rows: finished trial 0 pads
    assert C.tile_moves(done).tolist() == [False, False, False, False, True, False]  # trial 4 on tile 3
    assert C.tile_moves(np.array([True, False, False])).tolist() == [False, True, True]
    assert not C.tile_moves(np.zeros(4, bool)).any()  # every row computed: nothing moves
    assert not C.tile_moves(np.array([False, False, True])).any()  # 2 running of 3 -> 2 rows [0, 1]: in place
    assert not C.tile_moves(np.ones(3, bool)).any()


# ---------------------------------------------------------------------------------------------------------------
# The walker harness (PPO + evaluation) on tiles
# ---------------------------------------------------------------------------------------------------------------
WALK = TerrainScale(cell_size=0.2, height=1.0)  # 16 x 16: a 3 m square, 2 m track


def _walker_run(backend: str, trials: int, tiles: int, chunks: int = 1, episode_length: int = 20, headings: int = 1,
                selector: str = "map", grid: int = 2, relief: float = 0.5, **kw):
    """``chunks`` chunks of ``trials`` trials of the real walker harness (base policy, 2 envs, 2 walks of
    ``episode_length`` steps per evaluation, in ``headings`` headings) on a ``grid`` x ``grid`` toy bank of 16 x 16
    terrains (heights x ``relief``): (start states, end states). ``tiles`` counts tiles, ``trials x headings`` for
    every trial on its own. ``kw``: more CurriculumConfig fields (``overlap=True``: Warp worlds for envs + walks)."""
    policy = W.load_policy(None)
    config = small(selector, **{**dict(num_envs=2, attempts=2, best=1, headings=headings, max_evals=2,
                                       update_epochs=1), **kw})
    walks = config.ppo.num_envs + config.attempts if config.overlap else max(config.ppo.num_envs, config.attempts)
    env = W.walker_env(policy, SHAPE, WALK, episode_length, backend=backend, tiles=tiles, worlds=trials * walks)
    ppo = config.ppo_config(policy.config)
    harness = W.walker_harness(env, ppo, config)
    bank = toy_bank(grid)._replace(heightmaps=toy_bank(grid).heightmaps * relief)  # steps of up to 0.19 m
    start = W.start_state(env, ppo, policy, SHAPE)
    keys = jax.random.split(jax.random.key(3), trials)
    states = jax.jit(lambda k, b, s: C.init_trials(k, b, s, config=config, harness=harness))(keys, bank, start)
    run = jax.jit(lambda s, b: C.run_trials(s, b, jnp.int32(chunks), config=config, harness=harness))
    return states, run.lower(states, bank).compile(FAST_COMPILE)(states, bank)


@pytest.mark.skipif(not WARP_OK, reason=WARP_WHY or "warp available")
@pytest.mark.parametrize("headings", [1, 2])
def test_warp_walker_curriculum_chunk_on_tiles(headings):
    """MuJoCo Warp: two trials, each on its own tile(s) of the chunk's bank (one per heading), train PPO (2 envs)
    and are evaluated (2 walks, one per heading with headings=2); the evaluations are real walks (in (0, 1]), PPO
    changed every trial's policy, and nothing failed."""
    start, end = _walker_run("warp", trials=2, tiles=2 * headings, chunks=1, headings=headings)
    ev = np.asarray(end.history.evaluation[:, 0])
    assert np.all((ev > 0.0) & (ev <= 1.0)), ev
    assert np.all(np.asarray(end.chunk) == 1) and np.all(np.asarray(end.epoch) == 1)
    p0, p1 = (jax.tree.leaves(s.policy.params)[0] for s in (start, end))
    for t in range(2):
        assert not np.allclose(np.asarray(p1[t]), np.asarray(p0[t]))
    assert np.all(np.isfinite(np.asarray(end.policy.env_state.obs)))
    assert float(np.max(np.asarray(end.policy.env_state.failed))) == 0.0


@pytest.mark.slow
@pytest.mark.parametrize("headings", [1, 2])
def test_jax_walker_curriculum_on_one_tile_equals_the_classic_one(headings):
    """MJX: one trial on a one-tile bank (the tile at the origin) runs the classic chunks bit for bit: PPO on its
    Tile, the restart and the evaluation walks (``tile_distances``). With 2 headings (a second tile, off the origin,
    holds the turned terrain; PPO env 1 and walk 1 on it) against ``difficulty.protocol_distances`` and per-env
    turned terrains: the same choices, and evaluations and parameters equal up to the float rounding of the tile's
    shifted coordinates. Two MJX programs each: minutes of CPU."""
    _, classic = _walker_run("jax", trials=1, tiles=0, chunks=2, headings=headings)
    _, tiled = _walker_run("jax", trials=1, tiles=headings, chunks=2, headings=headings)
    assert np.all(np.asarray(classic.history.evaluation[0, :2]) > 0)
    if headings == 1:
        assert tree_equal(tiled, classic)
        return
    for name in ("terrain", "epoch", "hardest"):
        np.testing.assert_array_equal(np.asarray(getattr(tiled.history, name)),
                                      np.asarray(getattr(classic.history, name)))
    np.testing.assert_allclose(np.asarray(tiled.history.evaluation), np.asarray(classic.history.evaluation),
                               atol=1e-5)
    for a, b in zip(jax.tree.leaves(tiled.policy.params), jax.tree.leaves(classic.policy.params)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), atol=1e-4)


@pytest.mark.parametrize("backend", [pytest.param("jax", marks=pytest.mark.slow), pytest.param(
    "warp", marks=pytest.mark.skipif(not WARP_OK, reason=WARP_WHY or "warp available"))])
def test_overlapped_walker_harness_makes_the_plain_choices(backend):
    """Two trials, 2 headings, 6 chunks of the random selector on a 3 x 3 bank, a terrain left at fitness 0.085 (so
    some are left after one evaluation and some stay for two): with ``overlap`` the evaluation walks ride along the
    next chunk's PPO envs (``rl.ride_updates``, the rest walked on by ``finish_walks``), and the trials take the
    same terrains in the same order with the same records; evaluations and parameters agree up to the float
    rounding of the larger batches (the classic loop's walks step 2 + 2 envs, not 4 + 4). On MJX (``jax``) the two
    programs take about 4 minutes of a 2-core CPU (a tenth of the default suite), so that case is ``slow``; the
    default suite keeps the property on the toy harness (tests/test_curriculum.py,
    ``test_overlap_runs_the_same_curriculum_as_the_plain_loop``) and on the walker where MuJoCo Warp imports."""
    kw = dict(selector="random", grid=3, relief=0.3, threshold=0.085, max_epochs=6, headings=2)
    _, plain = _walker_run(backend, trials=2, tiles=4, chunks=100, **kw)
    _, over = _walker_run(backend, trials=2, tiles=4, chunks=100, overlap=True, **kw)
    terrain = np.asarray(plain.history.terrain)
    assert np.all(np.asarray(plain.done)) and np.all(np.asarray(over.done)) and terrain.min() >= 0
    assert np.sum(terrain[:, 1:] != terrain[:, :-1]) >= 4 and np.sum(terrain[:, 1:] == terrain[:, :-1]) >= 2
    for name in ("terrain", "epoch", "hardest"):
        np.testing.assert_array_equal(np.asarray(getattr(over.history, name)), np.asarray(getattr(plain.history,
                                                                                                 name)))
    np.testing.assert_allclose(np.asarray(over.history.evaluation), np.asarray(plain.history.evaluation),
                               atol=2e-4)
    assert np.all(np.asarray(over.history.evaluation) > 0)
    for a, b in zip(jax.tree.leaves(over.policy.params), jax.tree.leaves(plain.policy.params)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), atol=1e-4)
    assert not np.any(np.asarray(over.pending))


@pytest.mark.slow
def test_lagged_walker_records_each_chunks_own_evaluation():
    """``eval_lag`` on the MJX walker (tiles; two trials, 2 headings, the random selector on a 3 x 3 bank, a terrain
    left at fitness 0.085): stepped one chunk at a time, each evaluation recorded for chunk c equals a direct
    ``harness.evaluate`` of the policy chunk c ended with, on chunk c's terrain, with chunk c's evaluation key, within
    2e-4 (the riding walks step in a larger batch than the direct ones, so XLA's CPU products round otherwise); each
    terrain switch leaves one unevaluated chunk on the terrain left. Two MJX programs: minutes of CPU."""
    policy = W.load_policy(None)
    config = small("random", num_envs=2, attempts=2, best=1, headings=2, max_evals=2, update_epochs=1,
                   threshold=0.085, max_epochs=6, overlap=True, eval_lag=True)
    env = W.walker_env(policy, SHAPE, WALK, 20, backend="jax", tiles=4, worlds=2 * 4)
    harness = W.walker_harness(env, config.ppo_config(policy.config), config)
    bank = toy_bank(3)._replace(heightmaps=toy_bank(3).heightmaps * 0.3)
    start = W.start_state(env, config.ppo_config(policy.config), policy, SHAPE)
    states = jax.jit(lambda k, b, s: C.init_trials(k, b, s, config=config, harness=harness))(
        jax.random.split(jax.random.key(3), 2), bank, start)
    step = jax.jit(lambda s, b: C.run_trials(s, b, jnp.int32(1), config=config, harness=harness))
    evaluate = jax.jit(lambda p, k, t: harness.evaluate(p, k, C.core._current_terrain(bank, t, harness)))
    checked = 0
    for _ in range(20):
        before = jax.tree.map(np.array, states)
        states = step(states, bank)
        for t in range(2):
            c = int(before.chunk[t])
            if before.done[t] or not before.pending[t]:
                continue  # nothing evaluated in this step (the start, or the chunk after a switch trained)
            mine = jax.tree.map(lambda x: x[t], before)
            eval_key = jax.random.split(jax.random.fold_in(jax.random.wrap_key_data(mine.key), c), 4)[1]
            want = float(evaluate(mine.policy, eval_key, mine.terrain))
            assert int(states.history.terrain[t, c]) == int(mine.terrain)
            assert abs(float(states.history.evaluation[t, c]) - want) <= 2e-4, (t, c)
            checked += 1
        if np.all(np.asarray(states.done)):
            break
    assert np.all(np.asarray(states.done)) and checked >= 6
    ev, terrain = np.asarray(states.history.evaluation), np.asarray(states.history.terrain)
    switched = (terrain[:, 1:] != terrain[:, :-1]) & (terrain[:, 1:] >= 0)
    assert switched.sum() >= 2 and np.all(np.isnan(ev[:, :-1][switched]))  # the chunk before each switch


@pytest.mark.slow
def test_jax_walker_compact_blocks_keep_each_running_trial_on_its_own_tile():
    """The compact-on-tiles bug on the real MJX walker (tiles, ``backend="jax"``): 3 trials of the random selector,
    one chunk of all three (their envs spawn on tiles 0, 1, 2), trial 0 forced done, then 2 chunks computed on the
    running trials only (``run_live``: rows [1, 2]) against 2 chunks of all three. No terrain finishes (threshold
    above every fitness) and episodes are longer than the 3 chunks, so no env restarts after the first chunk: each
    trial's envs walk where they spawned. Compact must equal the full block (the same choices; PPO parameters,
    evaluations and env positions up to the last bits of the smaller batch's matrix products). Before the fix the
    compact block laid trials 1 and 2 out on tiles 0 and 1, so trial 1's envs walked on trial 2's terrain and trial
    2's on a flat tile: their heights (qpos z) moved by the terrains' height difference. Three MJX programs (all
    rows, 2 rows): minutes of CPU."""
    policy = W.load_policy(None)
    config = small("random", num_envs=2, attempts=2, best=1, max_evals=10, update_epochs=1, threshold=0.99,
                   max_epochs=40)
    env = W.walker_env(policy, SHAPE, WALK, 40, backend="jax", tiles=3, worlds=6)
    ppo = config.ppo_config(policy.config)
    harness = W.walker_harness(env, ppo, config)
    grid = toy_bank(3)
    bank = grid._replace(heightmaps=grid.heightmaps * 0.5)  # 9 flat terrains, 0 to 0.25 m
    start = W.start_state(env, ppo, policy, SHAPE)
    init = jax.jit(lambda k, b, s: C.init_trials(k, b, s, config=config, harness=harness))
    programs = {}

    def run(s, b, n, *rows):  # a runner for run_live, one program per number of rows computed
        key = (int(s.done.shape[0]),) + tuple(int(r.shape[0]) for r in rows if r is not None)
        if key not in programs:
            fn = jax.jit(lambda s, b, n, *r: C.run_trials(s, b, n, *r, config=config, harness=harness))
            programs[key] = fn.lower(s, b, jnp.int32(n), *rows).compile(FAST_COMPILE)
        return programs[key](s, b, jnp.int32(n), *rows)

    first = run(init(jax.random.split(jax.random.key(7), 3), bank, start), bank, 1)
    assert np.all(np.asarray(first.chunk) == 1) and not np.any(np.asarray(first.restart))
    stopped = first._replace(done=first.done.at[0].set(True))
    whole = run(stopped, bank, 2)
    live = C.run_live(run, stopped, bank, 2)
    terrain = np.asarray(whole.history.terrain)
    heights = np.asarray(bank.heightmaps)[terrain[1:, 1], 0, 0]  # trials 1 and 2 walk different heights
    assert terrain[1, 0] == terrain[1, 2] and terrain[2, 0] == terrain[2, 2] and heights[0] != heights[1]
    for name in ("terrain", "epoch", "hardest"):
        np.testing.assert_array_equal(np.asarray(getattr(live.history, name)), np.asarray(getattr(whole.history,
                                                                                                 name)))
    z_live, z_whole = (np.asarray(s.policy.env_state.data.qpos)[1:, :, 2] for s in (live, whole))
    np.testing.assert_allclose(z_live, z_whole, atol=1e-3)
    np.testing.assert_allclose(np.asarray(live.history.evaluation), np.asarray(whole.history.evaluation), atol=1e-3)
    for a, b in zip(jax.tree.leaves(live.policy.params), jax.tree.leaves(whole.policy.params)):
        np.testing.assert_allclose(np.asarray(a)[1:], np.asarray(b)[1:], atol=1e-3)


# ---------------------------------------------------------------------------------------------------------------
# The walker of a learn run (the command: tests/integration/test_learn_command.py)
# ---------------------------------------------------------------------------------------------------------------
CPPN = "docs/results/exp1b_gpu_sound_cppn_archive.npz"


@pytest.fixture(scope="module")
def tiny_archive(tmp_path_factory):
    """The CPPN archive cut to its first 4 filled cells, with stored gentle bumps as heightmaps (as
    tests/test_curriculum.py's)."""
    from jaxterrain import qd as A

    arch = A.load(CPPN)
    keep = np.zeros_like(arch.filled)
    keep[np.flatnonzero(arch.filled)[:4]] = True
    x = np.linspace(0, 4 * np.pi, 256, dtype=np.float32)
    bumps = (0.02 * (1 + np.sin(x)[None, :] * np.cos(x)[:, None]) * 65535).astype(np.uint16)
    maps = np.where(keep[:, None, None], bumps[None], np.uint16(0))
    tiny = arch._replace(source=np.where(keep, arch.source, -1).astype(np.int32),
                         fitness=np.where(keep, arch.fitness, -np.inf).astype(np.float32), heightmaps=maps)
    return str(A.save(tmp_path_factory.mktemp("arch") / "four.npz", tiny))


def test_tile_layout_with_headings_puts_each_turned_terrain_on_its_own_tile():
    """``tile_layout(env, 2)``: trial i trains on tile 2 i (its terrain as it is) and heading 1 walks tile 2 i + 1,
    which holds the terrain turned by a quarter (``difficulty.rotate_headings``): read through the walker, both match
    the classic terrain and its turned copy at every probe point; too few tiles is a ValueError naming tiles."""
    from jaxterrain import difficulty

    env, plain = _envs(4)
    x = np.arange(SHAPE[1], dtype=np.float32)
    ramps = np.stack([np.broadcast_to(x / 16.0, SHAPE), np.broadcast_to(x[:, None] / 32.0, SHAPE)]).astype(np.float32)
    tiles, axes = W.tile_layout(env, 2)(jnp.asarray(ramps))
    assert axes == W.TILE_AXES and np.asarray(tiles.index).tolist() == [0, 2]
    turned = np.asarray(difficulty.rotate_headings(jnp.asarray(ramps), 2))
    px, py = jnp.asarray(PROBE[:, 0]), jnp.asarray(PROBE[:, 1])
    for i in range(2):
        for h in range(2):
            ox, oy = env.tile_origin(jnp.int32(2 * i + h))
            got = env.terrain_height(Tile(tiles.bank, jnp.int32(2 * i + h)), px + ox, py + oy)
            want = plain.terrain_height(jnp.asarray(turned[2 * i + h]), px, py)
            np.testing.assert_array_equal(np.asarray(got), np.asarray(want))
    assert not np.array_equal(turned[0], turned[1])  # the ramp along x turned: another terrain
    with pytest.raises(ValueError, match="tiles=4"):
        W.tile_layout(env, 4)(jnp.asarray(ramps))


def test_learn_takes_the_evaluation_protocol_from_the_archive(tmp_path, tiny_archive):
    """``attempts`` / ``best`` / ``headings`` left None (the paper and gpu-short presets) come from the archive's
    config, so the GP's prior and its observations share a protocol; given ones win; Warp gets a tile per trial and
    heading. A protocol that does not divide is one line naming the field."""
    from jaxterrain import qd as A
    from jaxterrain.curriculum.presets import FLAT_PRESETS

    arch = A.load(tiny_archive)
    four = str(A.save(tmp_path / "four_headings.npz", arch._replace(config=arch.config._replace(
        attempts=80, best=5, headings=4))))
    paper = {**FLAT_PRESETS["paper"], "archive": tiny_archive, "seed": 0}
    assert FLAT_PRESETS["paper"]["headings"] is None and FLAT_PRESETS["gpu-short"]["attempts"] is None
    assert validated(paper)[0].protocol == (20, 5, 1, 0.0, "mean")  # an archive saved before headings existed
    assert validated({**paper, "archive": four})[0].protocol == (80, 5, 4, 0.0, "mean")
    assert validated({**paper, "archive": four, "headings": 1, "attempts": 20})[0].protocol[:3] == (20, 5, 1)
    with pytest.raises(runner.BadInput, match="attempts must be a multiple of headings"):
        validated({**paper, "archive": four, "attempts": 30})
    assert runner.walker_layout(run_config.from_flat({**paper, "backend": "jax"})) == {}
    if WARP_OK:
        layout = runner.walker_layout(run_config.from_flat({**paper, "backend": "warp", "headings": 4, "attempts": 80,
                                                            "trials": 3}))
        assert layout == {"backend": "warp", "tiles": 12, "worlds": 3 * 500}


def test_the_compact_audit_counts_mixed_chunks_from_the_trials_chunk_counts():
    """``docs/results/compact_tiles_audit.py`` (the exp3.md "Training bug" table): a chunk is mixed when a trial is
    done (fewer chunks than it + 1) while another runs; the share's bound is the running trials' chunks in mixed
    chunks over all chunks; trials that all end together have none. And the shipped exp3 CPPN map treatment: 10
    trials of 75 chunks, nothing mixed."""
    audit = load_script("docs/results/compact_tiles_audit.py", "compact_tiles_audit")
    assert audit.mixed_share([75] * 10) == (0, 0.0)
    mixed, share = audit.mixed_share([2, 4, 4])  # chunks 2 and 3: trial 0 done, trials 1 and 2 running
    assert mixed == 2 and share == pytest.approx(4 / 10)
    chunks = audit.chunks_per_trial(ROOT / "docs" / "results" / "exp3_gpushort" / "cppn-map")
    assert chunks == [75] * 10 and audit.mixed_share(chunks)[0] == 0
