"""jaxterrain.curriculum.selectors: the selector protocol. The paper's curricula in it reproduce the histories of the
loop before it bit for bit; domain randomisation and terrain levels against NumPy versions of their rules; per-env
terrains reach the envs they were assigned to, on the classic layout and on tiles alike; a selector of the user's
own runs through ``CurriculumConfig.selector`` without editing the library."""

from __future__ import annotations

import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxterrain import curriculum as C
from jaxterrain.curriculum import selectors as S
from jaxterrain.curriculum import walker as W
from jaxterrain.terrain import TerrainScale
from jaxterrain.walker import Tile, WalkerConfig, WalkerEnv

DATA = Path(__file__).resolve().parents[1] / "data"
sys.path.insert(0, str(DATA))
from make_selector_reference import CASES, run as reference_case  # noqa: E402


def leaf(tree, path: str):
    for part in path.split("."):
        tree = tree[part] if isinstance(tree, dict) else getattr(tree, part)
    return np.asarray(tree)


@pytest.mark.parametrize("case", sorted(CASES))
def test_the_papers_curricula_reproduce_the_loop_before_the_protocol(case):
    """map (two settings, and overlapped), roughness, random (and overlapped): 3 trials to the end with a keyed
    fake harness, every history entry, counter, policy leaf, key and GP observation as stored at commit cb463e4:
    integers (terrains chosen, counters, keys) exactly, floats within 1e-5 relative (a stored reference: float32
    reductions and the GP's Cholesky may differ in the last bits on another CPU or jax version)."""
    ref = np.load(DATA / "selector_reference.npz")
    states = reference_case(*CASES[case])
    names = [k.split("/", 1)[1] for k in ref.files if k.startswith(case + "/")]
    assert len(names) == 19
    for name in names:
        got, want = leaf(states, name), ref[f"{case}/{name}"]
        if np.issubdtype(want.dtype, np.floating):  # float32 sums and the GP's Cholesky: last bits vary by CPU
            np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6, err_msg=name)
        else:  # decisions, counters and keys: exact
            np.testing.assert_array_equal(got, want, err_msg=name)


# ---------------------------------------------------------------------------------------------------------------
# The rules against NumPy
# ---------------------------------------------------------------------------------------------------------------
def numpy_levels_rule(level, progress, levels, promote, demote, top):
    up = progress >= promote
    down = ~up & (progress < demote)
    moved = level + up.astype(int) - down.astype(int)
    return np.where(moved >= levels, top, np.maximum(moved, 0))


def test_levels_rule_promotes_demotes_clips_and_sends_the_top_to_a_random_level():
    rng = np.random.default_rng(0)
    level = rng.integers(0, 10, 4000).astype(np.int32)
    progress = rng.uniform(0, 1, 4000).astype(np.float32)
    key = jax.random.key(3)
    got = np.asarray(S.levels_rule(jnp.asarray(level), jnp.asarray(progress), key, 10, 0.9, 0.5))
    top = np.asarray(jax.random.randint(key, (4000,), 0, 10, dtype=jnp.int32))
    np.testing.assert_array_equal(got, numpy_levels_rule(level, progress, 10, 0.9, 0.5, top))
    # the cases one by one: up, down, stay, floor, past the top
    assert np.all(got[(progress >= 0.9) & (level < 9)] == level[(progress >= 0.9) & (level < 9)] + 1)
    assert np.all(got[(progress < 0.5) & (level > 0)] == level[(progress < 0.5) & (level > 0)] - 1)
    mid = (progress >= 0.5) & (progress < 0.9)
    assert np.all(got[mid] == level[mid]) and np.all(got[(progress < 0.5) & (level == 0)] == 0)
    past = (progress >= 0.9) & (level == 9)
    assert past.sum() > 30 and len(set(got[past])) >= 8 and np.all((got[past] >= 0) & (got[past] < 10))


def test_level_bands_split_the_bank_into_equal_bands_by_hardness():
    hardness = jnp.asarray([5.0, 1.0, 3.0, 2.0, 4.0, 0.0, 6.0])
    order, start = S.level_bands(hardness, 3)
    np.testing.assert_array_equal(np.asarray(order), [5, 1, 3, 2, 4, 0, 6])
    np.testing.assert_array_equal(np.asarray(start), [0, 2, 4, 7])


# ---------------------------------------------------------------------------------------------------------------
# Per-env terrains with a fake harness on the walker's tiles
# ---------------------------------------------------------------------------------------------------------------
SHAPE = (16, 16)
EXACT = TerrainScale(cell_size=0.25, height=1.0)
PROBE = np.stack(np.meshgrid(np.arange(-1.5, 1.6, 0.5), np.arange(-1.5, 1.6, 0.5)), -1).reshape(-1, 2).astype(
    np.float32)
ENVS = 6


def toy_bank(n: int = 12):
    """n terrains of constant heights d_i = i / 16 (exact in float32), harder in order; prior 1 - d."""
    from jaxterrain.qd import TerrainBank

    d = (np.arange(n) / 16.0).astype(np.float32)
    bins = np.stack([np.arange(n), np.zeros(n, int)], -1).astype(np.int32)
    maps = np.broadcast_to(d[:, None, None], (n,) + SHAPE).astype(np.float32)
    points = np.stack([d, d], -1)
    return TerrainBank(jnp.asarray(maps), jnp.asarray(1.0 - d), jnp.asarray(points), jnp.asarray(points),
                       jnp.asarray(bins), jnp.asarray(np.arange(n, dtype=np.float32) + 1.0),
                       jnp.arange(n, dtype=jnp.int32), jnp.zeros(n, jnp.int32))


def per_env_harness(env: WalkerEnv, plain: WalkerEnv, tiled: bool, gain: float = 0.05,
                    spread: float = 0.0) -> C.Harness:
    """Policy {"skill", "resets", "level" [E]}: a chunk adds ``gain`` to the skill and records each env's terrain
    height (read through the walker: a Tile of ``env`` or an [H, W] map of ``plain``); progress of env e =
    clip(1 - height_e + skill + spread x [e >= E / 2], 0, 1); evaluation clip(1 - height + skill, 0, 1) on the
    evaluated terrain."""

    def height(terrain):
        px, py = jnp.asarray(PROBE[:, 0]), jnp.asarray(PROBE[:, 1])
        if isinstance(terrain, Tile):
            ox, oy = env.tile_origin(terrain.index)
            return jnp.mean(env.terrain_height(terrain, px + ox, py + oy))
        return jnp.mean(plain.terrain_height(terrain, px, py))

    def per_env(terrain):  # one terrain for all envs (a one-terrain selector), or one each
        if isinstance(terrain, Tile):
            index = jnp.broadcast_to(terrain.index, (ENVS,))
            return jax.vmap(lambda i: height(Tile(terrain.bank, i)))(index)
        if terrain.ndim == 2:
            return jnp.broadcast_to(height(terrain), (ENVS,))
        return jax.vmap(height)(terrain)

    def train(policy, key, terrain):
        return dict(policy, skill=policy["skill"] + gain, level=per_env(terrain))

    def evaluate(policy, key, terrain):
        return jnp.clip(1.0 - height(terrain) + policy["skill"], 0.0, 1.0)

    def reset(policy, key, terrain):
        return dict(policy, resets=policy["resets"] + 1)

    def progress(policy):
        lift = spread * (jnp.arange(ENVS) >= ENVS // 2)
        return jnp.clip(1.0 - policy["level"] + policy["skill"] + lift, 0.0, 1.0)

    if not tiled:
        return C.Harness(train, evaluate, reset, progress=progress)
    return C.Harness(train, evaluate, reset, layout=W.tile_layout(env), progress=progress,
                     pick=lambda t, i: Tile(t.bank, t.index[i]))


START = {"skill": jnp.zeros((), jnp.float32), "resets": jnp.zeros((), jnp.int32),
         "level": jnp.zeros((ENVS,), jnp.float32)}


def small(selector, **kw) -> C.CurriculumConfig:
    base = dict(selector=selector, epochs_per_chunk=1, steps_per_epoch=6 * 2 * 2, max_epochs=10, num_envs=ENVS,
                unroll_length=2, num_unrolls=2, num_minibatches=1)
    return C.validate_config(C.CurriculumConfig.from_json_dict({**base, **kw}))


def run_chunks(config, harness, bank, trials: int, chunks: int, key: int = 0):
    """Every chunk's (state before, state after) of ``trials`` trials, one jitted chunk at a time."""
    states = C.init_trials(jax.random.split(jax.random.key(key), trials), bank, START, config=config,
                           harness=harness)
    run = C.make_runner(config, harness)
    out = []
    for _ in range(chunks):
        before = states
        states = run(jax.tree.map(jnp.copy, states), bank, 1)
        out.append((before, states))
    return out


def test_dr_deals_the_envs_round_robin_over_fresh_uniform_terrains_every_chunk():
    bank = toy_bank()
    config = small("dr", terrains_per_chunk=3, max_epochs=400)
    harness = per_env_harness(*_envs(3), tiled=False)
    steps = run_chunks(config, harness, bank, trials=1, chunks=400)
    drawn = []
    for before, after in steps:
        terrains = np.asarray(before.selector.terrains[0])
        heights = np.asarray(bank.heightmaps[:, 0, 0])[terrains[np.arange(ENVS) % 3]]
        np.testing.assert_array_equal(np.asarray(after.policy["level"][0]), heights)  # env e on terrain e % 3
        assert int(after.history.terrain[0, int(before.chunk[0])]) == terrains[0]  # evaluated on slot 0
        assert int(after.policy["resets"][0]) == int(before.policy["resets"][0]) + 1  # restarted every chunk
        drawn += terrains.tolist()
    counts = np.bincount(drawn, minlength=12)
    assert counts.sum() == 1200 and counts.min() > 60 and counts.max() < 140  # 100 each expected (sd ~ 9.6)
    assert not bool(steps[-1][1].done[0]) or int(steps[-1][1].epoch[0]) >= 400  # never runs out of terrains


def test_levels_move_each_env_by_legged_gyms_rule_on_its_levels_terrain():
    """12 terrains in 4 levels of 3 (by hardness): every chunk env e trains on its level's terrain, and its next
    level is the NumPy rule of its progress; the evaluation is on the highest level's terrain."""
    bank = toy_bank()
    config = small("levels", levels=4, levels_init=1, levels_promote=0.8, levels_demote=0.6, max_epochs=30)
    harness = per_env_harness(*_envs(4), tiled=False, gain=0.04)
    order, start = (np.asarray(x) for x in S.level_bands(S.terrain_hardness(bank), 4))
    moved = 0
    for before, after in run_chunks(config, harness, bank, trials=1, chunks=30):
        level, terrains = np.asarray(before.selector.level[0]), np.asarray(before.selector.terrains[0])
        for lv in range(4):  # each level's terrain is from its band
            assert terrains[lv] in order[start[lv]:start[lv + 1]]
        heights = np.asarray(bank.heightmaps[:, 0, 0])[terrains[level]]
        np.testing.assert_array_equal(np.asarray(after.policy["level"][0]), heights)
        progress = np.clip(1.0 - heights + np.asarray(after.policy["skill"][0]), 0, 1).astype(np.float32)
        new = np.asarray(after.selector.level[0])
        stay_below_top = new < 4
        expected = numpy_levels_rule(level, progress, 4, 0.8, 0.6, new)  # past the top: whatever was drawn
        np.testing.assert_array_equal(new, expected)
        assert np.all(stay_below_top)
        assert int(after.history.terrain[0, int(before.chunk[0])]) == terrains[level.max()]
        moved += int(np.sum(new != level))
    assert moved > 10  # the levels went somewhere


@pytest.mark.parametrize("selector", ["dr", "levels", "plr"])
def test_per_env_terrains_on_tiles_equal_the_classic_layout(selector):
    """3 trials x K terrains a chunk laid out as one bank of 3 K tiles: every env reads exactly the terrain the
    classic layout gives it ([E, H, W] maps), so every record, level and policy leaf is equal."""
    out = tiled_and_classic(small(selector, terrains_per_chunk=3, levels=4, max_epochs=8, plr_capacity=4))
    assert len({tuple(np.asarray(t)) for t in out[True].history.terrain}) == 3  # trials differ


def tiled_and_classic(config):
    """3 trials of ``config`` for 8 chunks on both layouts (the toy bank, the per-env fake harness); asserts every
    leaf of the final states is equal and returns them ``{tiled: states}``."""
    bank = toy_bank()
    k = S.get_selector(config).slots
    env, plain = _envs(3 * k)
    keys = jax.random.split(jax.random.key(2), 3)
    out = {}
    for tiled in (False, True):
        harness = per_env_harness(env, plain, tiled)
        states = C.init_trials(keys, bank, START, config=config, harness=harness)
        out[tiled] = C.make_runner(config, harness)(states, bank, 8)
    leaves = jax.tree.leaves(out[True]), jax.tree.leaves(out[False])
    assert all(np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True) for a, b in zip(*leaves))
    return out


def _envs(tiles: int):
    cfg = WalkerConfig(terrain_shape=SHAPE, scale=EXACT)
    return WalkerEnv(cfg._replace(tiles=tiles)), WalkerEnv(cfg)


# ---------------------------------------------------------------------------------------------------------------
# A selector of one's own; config errors
# ---------------------------------------------------------------------------------------------------------------
def hardest_first(config) -> S.Selector:
    """A user's selector (this module, named ``tests...:hardest_first``): the hardest terrain, forever."""

    def init(key, bank):
        return jnp.argmax(S.terrain_hardness(bank)).astype(jnp.int32)

    def update(state, key, bank, outcome):
        no = jnp.zeros((), bool)
        return state, S.Decision(finished=no, restart=no, exhausted=no)

    return S.Selector("hardest_first", 1, init, lambda s: S.Assignment(s[None], None, jnp.zeros((), jnp.int32)),
                      update, lambda s: {"hardest_index": s})


def test_a_users_selector_runs_by_module_and_name_without_editing_the_library(monkeypatch):
    bank = toy_bank()
    name = f"{__name__}:hardest_first"
    config = small(name, num_envs=ENVS, max_epochs=3)
    harness = per_env_harness(*_envs(1), tiled=False)
    states = C.make_runner(config, harness)(C.init_trials(jax.random.split(jax.random.key(0), 2), bank, START,
                                                          config=config, harness=harness), bank, 5)
    assert np.all(np.asarray(states.history.terrain)[:, :3] == 11) and np.all(np.asarray(states.chunk) == 3)
    monkeypatch.setattr(S.protocol, "_REGISTRY", dict(S.protocol._REGISTRY))  # registered for this test only
    S.register_selector("hardest_first", hardest_first)
    assert "hardest_first" in S.selector_names()
    again = C.validate_config(config._replace(selector="hardest_first"))
    assert S.get_selector(again).name == "hardest_first"


@pytest.mark.parametrize("fields, message", [
    (dict(selector="nope"), "selector must be one of map, roughness, random, dr, levels, plr"),
    (dict(selector="plr", params=S.PLRParams(temperature=0.0)), r"params.temperature must be in \(0.0, inf\)"),
    (dict(selector="plr", params=S.PLRParams(replay_prob=1.5)), r"params.replay_prob must be in \[0.0, 1.0\]"),
    (dict(selector="no_such_module:thing"), "cannot import it"),
    (dict(selector="levels", params=S.LevelsParams(levels=3, init=3)), r"params.init must be in \[0, levels - 1 = 2\]"),
    (dict(selector="levels", params=S.LevelsParams(promote=1.5)), r"params.promote must be in \(0.0, 1.0\]"),
    (dict(selector="levels", params=S.LevelsParams(demote=-0.1)), r"params.demote must be in \[0.0, 1.0\]"),
    (dict(selector="dr", params=S.DRParams(terrains_per_chunk=0)), "params.terrains_per_chunk must be an integer >= 1"),
    (dict(selector="dr", overlap=True), "overlap needs a one-terrain selector"),
    (dict(selector="accel"), "params.generator must be one of cppn, .*got None"),
    (dict(selector="accel", params=S.AccelParams(generator="nope")), "params.generator must be one of .*got 'nope'"),
    (dict(selector="accel", params=S.AccelParams(generator="perlin", edits=0)), "params.edits must be an integer >= 1"),
    (dict(selector="plr", params=S.PLRParams(capacity=0)), "params.capacity must be an integer >= 1"),
    # JaxUED's 4 000 at gpu-short (75 chunks of 8 new levels): half full after 250 chunks, so it would never replay
    (dict(selector="plr", max_epochs=3000, params=S.PLRParams(capacity=4000)),
     r"params.capacity must be at most 1200 .*never replay"),
    (dict(selector="map", params=S.MapParams(kappa=-1.0)), r"params.kappa must be in \[0.0, inf\)"),
    (dict(selector="roughness", params=S.RoughnessParams(stride=0)), "params.stride must be an integer >= 1"),
    (dict(selector="plr", params=S.LevelsParams()), "params must be a PLRParams for selector 'plr'"),
])
def test_selector_settings_are_refused_with_the_field_and_its_range(fields, message):
    with pytest.raises(ValueError, match=message):
        C.validate_config(C.CurriculumConfig(**fields))


def test_each_selector_owns_its_params_and_reads_the_flat_layout_of_old_configs():
    """``CurriculumConfig.params`` is the selector's own NamedTuple (None: its defaults); a flat config (every
    ``config.json`` before the selectors owned their params) gives the run's selector its keys and drops the others'."""
    assert S.selector_params(C.CurriculumConfig(selector="levels")) == S.LevelsParams()
    assert S.selector_params(C.CurriculumConfig(selector="random")) is None
    flat = C.CurriculumConfig.from_json_dict({"selector": "accel", "plr_capacity": 64, "accel_generator": "perlin",
                                             "levels": 3, "kappa": 9.0, "roughness_stride": 2})
    assert flat.params == S.AccelParams(capacity=64, generator="perlin")
    assert C.CurriculumConfig.from_json_dict(flat.to_json_dict()) == flat  # the nested layout reads back
    assert C.CurriculumConfig.from_json_dict({"selector": "map", "kappa": 0.1}).params == S.MapParams(kappa=0.1)
    assert S.flat_name("accel", "capacity") == "plr_capacity" and S.flat_name("levels", "init") == "levels_init"
    assert {"kappa", "levels_init", "plr_capacity", "accel_edits"} <= set(C.config.SELECTOR_FIELDS)
    assert not set(C.config.SELECTOR_FIELDS) & set(C.CurriculumConfig._fields)  # no selector field is the config's


def test_the_default_level_buffer_fills_to_min_fill_in_the_first_tenth_of_the_run():
    """plr_capacity=None: K x ceil(chunks / 10) new levels fill it to plr_min_fill (gpu-short 128, the paper 1 200)."""
    gpu_short = C.CurriculumConfig(selector="plr", max_epochs=3000)  # 75 chunks of 40 epochs, 8 terrains a chunk
    p = S.PLRParams()
    assert gpu_short.max_chunks == 75 and S.plr_buffer_capacity(p, gpu_short.max_chunks) == 128
    assert S.plr_buffer_capacity(p, 750) == 1200
    assert S.plr_buffer_capacity(p._replace(min_fill=0.25), 75) == 256
    assert S.plr_buffer_capacity(p, 1) == 16  # one chunk: at least one chunk's levels
    assert S.plr_buffer_capacity(p._replace(capacity=300), 75) == 300
    C.validate_config(gpu_short._replace(params=p._replace(capacity=1200)))  # fills to half with the last new levels


def test_a_checkpoint_of_the_state_before_the_protocol_restores_into_the_selector_state(tmp_path):
    """Runs checkpointed before the protocol kept the GP's observations and the terrain bookkeeping at the top of
    State and no ``episode.progress``: ``driver.restore(..., **CHECKPOINT_COMPAT)`` reads them into place."""
    from typing import Any, NamedTuple

    from jaxterrain.curriculum.core import CHECKPOINT_COMPAT
    from jaxterrain.runtime import driver

    class Episode(NamedTuple):  # the PPO episode record as it was: no progress
        count: Any

    class OldState(NamedTuple):  # State's fields as they were stored
        policy: Any
        key: Any
        obs_index: Any
        obs_y: Any
        obs_count: Any
        available: Any
        terrain: Any
        terrain_evals: Any
        terrain_best: Any

    class Policy(NamedTuple):  # rl.TrainState's path to the episode record
        episode: Any

    old = OldState(policy=Policy(Episode(jnp.arange(3.0))), key=jnp.asarray([1, 2], jnp.uint32),
                   obs_index=jnp.asarray([4, -1], jnp.int32), obs_y=jnp.asarray([0.5, 0.0]),
                   obs_count=jnp.int32(1), available=jnp.asarray([True, False, True]), terrain=jnp.int32(2),
                   terrain_evals=jnp.int32(3), terrain_best=jnp.float32(0.25))
    driver.save_checkpoint(tmp_path / "checkpoint.npz", old, done=7)

    class NewEpisode(NamedTuple):
        count: Any
        progress: Any

    like = {"policy": Policy(NewEpisode(jnp.zeros(3), jnp.full(3, 9.0))), "key": jnp.zeros(2, jnp.uint32),
            "selector": S.SequenceState(current=jnp.int32(0), available=jnp.zeros(3, bool),
                                        terrain_evals=jnp.int32(0), terrain_best=jnp.float32(0),
                                        obs_index=jnp.zeros(2, jnp.int32), obs_y=jnp.zeros(2),
                                        obs_count=jnp.int32(0)), "terrain": jnp.int32(0)}
    like = NamedTuple("Like", [(k, Any) for k in like])(**like)
    state, done, _, _ = driver.restore(tmp_path, like, **CHECKPOINT_COMPAT)
    assert done == 7 and int(state.terrain) == 2 and int(state.selector.current) == 2
    np.testing.assert_array_equal(np.asarray(state.selector.obs_index), [4, -1])
    np.testing.assert_array_equal(np.asarray(state.selector.available), [True, False, True])
    assert int(state.selector.terrain_evals) == 3 and float(state.selector.terrain_best) == 0.25
    np.testing.assert_array_equal(np.asarray(state.policy.episode.progress), [9.0, 9.0, 9.0])  # the template's
    with pytest.raises(ValueError, match="has no leaf"):
        driver.restore(tmp_path, like)  # without the aliases


# ---------------------------------------------------------------------------------------------------------------
# PLR: JaxUED's level buffer against NumPy
# ---------------------------------------------------------------------------------------------------------------
def numpy_plr_weights(scores, timestamps, size, count, temperature, rho):
    c = scores.size
    mask = np.arange(c) < size
    order = np.argsort(-np.where(mask, scores, -np.inf), kind="stable")
    ranks = np.empty(c)
    ranks[order] = np.arange(c) + 1
    w_s = np.where(mask, 1.0 / ranks, 0.0) ** (1.0 / temperature)
    w_s /= w_s.sum()
    stale = np.where(mask, count - timestamps, 0).astype(float)
    w_c = stale / stale.sum() if stale.sum() > 0 else mask / size
    return (1 - rho) * w_s + rho * w_c


def buffer(levels, scores, timestamps, count):
    c = len(levels)
    size = int(np.sum(np.asarray(levels) >= 0))
    return S.PLRState(levels=jnp.asarray(levels, jnp.int32), scores=jnp.asarray(scores, jnp.float32),
                      timestamps=jnp.asarray(timestamps, jnp.int32), size=jnp.int32(size),
                      episode_count=jnp.int32(count), terrains=jnp.zeros(2, jnp.int32),
                      entry=jnp.full(2, -1, jnp.int32), replay=jnp.zeros((), bool), replays=jnp.int32(0))


def test_plr_replay_distribution_is_rank_prioritisation_mixed_with_staleness():
    rng = np.random.default_rng(1)
    scores = rng.uniform(0, 0.25, 6).astype(np.float32)
    stamps = np.array([3, 9, 1, 7, 7, 0])
    s = buffer([4, 2, 7, 0, 9, -1], np.where(np.arange(6) < 5, scores, -np.inf), stamps, 10)
    got = np.asarray(S.plr_weights(s, 0.3, 0.3))
    want = numpy_plr_weights(np.where(np.arange(6) < 5, scores, -np.inf), stamps, 5, 10, 0.3, 0.3)
    np.testing.assert_allclose(got, want, rtol=1e-5)
    assert got[5] == 0 and got[np.argmax(scores[:5])] == got.max()  # the best score weighs most; empty: 0
    # drawing: the empirical distribution of many single draws from the same buffer
    keys = jax.random.split(jax.random.key(0), 20000)
    draws = np.asarray(jax.vmap(lambda k: S.plr_sample(s, k, 1, 0.3, 0.3)[1][0])(keys))
    np.testing.assert_allclose(np.bincount(draws, minlength=6) / 20000, want, atol=0.012)
    # sampling marks the entry as just seen: its staleness drops to 0
    after, idx = S.plr_sample(s, jax.random.key(3), 3, 0.3, 0.3)
    assert int(after.episode_count) == 13 and int(after.timestamps[int(idx[-1])]) == 13


def test_plr_insert_updates_duplicates_fills_then_replaces_the_lowest_weight_when_beaten():
    s = buffer([4, 2, -1], [0.1, 0.2, -np.inf], [1, 2, 0], 5)
    s = S.plr_insert(s, jnp.int32(2), jnp.float32(0.05), 0.3, 0.3)  # a duplicate: its score and timestamp change
    assert np.asarray(s.levels).tolist() == [4, 2, -1] and float(s.scores[1]) == pytest.approx(0.05)
    assert int(s.size) == 2 and int(s.timestamps[1]) == 6 == int(s.episode_count)
    s = S.plr_insert(s, jnp.int32(8), jnp.float32(0.15), 0.3, 0.3)  # an empty entry
    assert np.asarray(s.levels).tolist() == [4, 2, 8] and int(s.size) == 3
    weights = numpy_plr_weights(np.asarray(s.scores), np.asarray(s.timestamps), 3, int(s.episode_count), 0.3, 0.3)
    low = int(np.argmin(weights))
    kept = S.plr_insert(s, jnp.int32(5), jnp.float32(float(s.scores[low]) - 0.01), 0.3, 0.3)  # not better: kept
    assert np.asarray(kept.levels).tolist() == [4, 2, 8] and int(kept.episode_count) == int(s.episode_count) + 1
    better = S.plr_insert(s, jnp.int32(5), jnp.float32(0.24), 0.3, 0.3)  # better: replaces the lowest weight
    assert int(better.levels[low]) == 5 and float(better.scores[low]) == pytest.approx(0.24)


def test_learnability_is_p_one_minus_p_of_each_terrains_envs():
    progress = jnp.asarray([1.0, 0.95, 0.2, 0.1, 0.92, 0.3, 0.0, 0.99])
    got = np.asarray(S.learnability(progress, jnp.arange(8) % 4, 4, 0.9))
    # terrain 0: envs 0, 4 (both reached): p 1; 1: envs 1, 5 (one): 0.5; 2: envs 2, 6 (none); 3: envs 3, 7: 0.5
    np.testing.assert_allclose(got, [0.0, 0.25, 0.0, 0.25])


def test_plr_fills_its_buffer_then_replays_and_rescores_on_the_loop():
    bank = toy_bank()
    config = small("plr", terrains_per_chunk=3, plr_capacity=6, plr_min_fill=0.5, max_epochs=40)
    harness = per_env_harness(*_envs(3), tiled=False, gain=0.01)
    replays, new_chunks = 0, 0
    for before, after in run_chunks(config, harness, bank, trials=1, chunks=40):
        b, a = jax.tree.map(lambda x: np.asarray(x[0]), before.selector), jax.tree.map(lambda x: np.asarray(x[0]),
                                                                                      after.selector)
        if b.replay:
            replays += 1
            np.testing.assert_array_equal(b.levels[b.entry], b.terrains)  # replayed terrains are buffer entries
        else:
            new_chunks += 1
            assert set(b.terrains.tolist()) <= set(a.levels[a.levels >= 0].tolist()) or a.size == 6
        assert a.size <= 6 and len(set(a.levels[:a.size].tolist())) == a.size  # no duplicates
        if a.replay:
            assert a.size >= 3  # half full before any replay
    assert replays > 15 and new_chunks >= 2


# ---------------------------------------------------------------------------------------------------------------
# ACCEL: PLR over genomes, replayed levels edited by the generator's mutate
# ---------------------------------------------------------------------------------------------------------------
def toy_level_generator(size: int = 16):
    """A one-gene generator for the tests: genome [h] in [0, 0.75], the map is flat at height h (exact: the fake
    harness reads heights); mutate moves the gene with probability 1 by N(0, (0.1 x 0.75)^2)."""
    from jaxterrain.generators import base

    gspec = base.spec(("h", 0.0, 0.75, False))
    return base.vector_generator("toy_level", gspec, lambda g: jnp.full((size, size), g[0], jnp.float32), size,
                                 mutation_prob=1.0)


@pytest.fixture
def toy_generator(monkeypatch):
    from jaxterrain.generators import registry

    monkeypatch.setitem(registry._FACTORIES, "toy_level", toy_level_generator)
    registry._cached.cache_clear()
    yield "toy_level"
    registry._cached.cache_clear()


def genome_buffer(levels, scores, timestamps, count):
    levels = np.asarray(levels, np.float32).reshape(len(levels), 1)
    return S.LevelBuffer(levels=jnp.asarray(levels), scores=jnp.asarray(scores, jnp.float32),
                         timestamps=jnp.asarray(timestamps, jnp.int32), size=jnp.int32(int(np.sum(levels[:, 0] >= 0))),
                         episode_count=jnp.int32(count))


def test_accel_buffer_of_genomes_updates_duplicates_fills_then_replaces_the_lowest_weight():
    """The buffer of genome levels behaves as the buffer of bank terrains (the same NumPy rule)."""
    s = genome_buffer([0.4, 0.2, -1.0], [0.1, 0.2, -np.inf], [1, 2, 0], 5)
    s = S.plr_insert(s, jnp.asarray([0.2], jnp.float32), jnp.float32(0.05), 0.3, 0.3)  # a duplicate genome
    assert np.asarray(s.levels)[:, 0].tolist() == pytest.approx([0.4, 0.2, -1.0]) and int(s.size) == 2
    assert float(s.scores[1]) == pytest.approx(0.05) and int(s.timestamps[1]) == 6
    s = S.plr_insert(s, jnp.asarray([0.3], jnp.float32), jnp.float32(0.15), 0.3, 0.3)  # an empty entry
    assert int(s.size) == 3 and float(s.levels[2, 0]) == pytest.approx(0.3)
    weights = numpy_plr_weights(np.asarray(s.scores), np.asarray(s.timestamps), 3, int(s.episode_count), 0.3, 0.3)
    low = int(np.argmin(weights))
    better = S.plr_insert(s, jnp.asarray([0.7], jnp.float32), jnp.float32(0.24), 0.3, 0.3)
    assert float(better.levels[low, 0]) == pytest.approx(0.7) and float(better.scores[low]) == pytest.approx(0.24)
    kept = S.plr_insert(s, jnp.asarray([0.7], jnp.float32), jnp.float32(float(s.scores[low]) - 0.01), 0.3, 0.3)
    np.testing.assert_array_equal(np.asarray(kept.levels), np.asarray(s.levels))


def test_accel_edits_the_levels_it_replayed_and_inserts_them_with_their_learnability(toy_generator):
    """Every chunk, against NumPy: env e trains on level e % K (a genome rendered in the loop), the policy is
    evaluated on a bank terrain (slot K); new and edited levels enter the buffer with p (1 - p) of their envs'
    progress, replayed ones are re-scored; the chunk after a replay trains on those levels, each mutated."""
    from jaxterrain.generators import get

    bank = toy_bank()
    k = 3
    config = small("accel", terrains_per_chunk=k, plr_capacity=12, plr_min_fill=0.25, max_epochs=60,
                   accel_generator=toy_generator)
    harness = per_env_harness(*_envs(k + 1), tiled=False, gain=0.01, spread=0.2)
    lift = 0.2 * (np.arange(ENVS) >= ENVS // 2)
    modes, scored = [], 0
    for before, after in run_chunks(config, harness, bank, trials=1, chunks=60):
        b, a = (jax.tree.map(lambda x: np.asarray(x[0]), st.selector) for st in (before, after))
        heights = b.genomes[np.arange(ENVS) % k, 0]
        np.testing.assert_allclose(np.asarray(after.policy["level"][0]), heights, rtol=1e-6)  # env e on level e % K
        assert int(after.history.terrain[0, int(before.chunk[0])]) == int(b.terrain)  # evaluated on a bank terrain
        skill = float(after.policy["skill"][0])
        progress = np.clip(1 - heights + skill + lift, 0, 1)
        p = np.array([np.mean(progress[np.arange(ENVS) % k == j] >= 0.9) for j in range(k)])
        score = p * (1 - p)
        scored += int(np.sum(score > 0))
        if b.mode == S.ACCEL_REPLAY:
            np.testing.assert_allclose(a.buffer.scores[b.entry], score, atol=1e-6)  # re-scored
            assert a.mode == S.ACCEL_EDIT
            edited = np.asarray(get(toy_generator).mutate(jax.random.key(0), jnp.asarray(b.genomes)))
            assert edited.shape == a.genomes.shape and not np.allclose(a.genomes, b.genomes)  # mutated
            assert np.all((a.genomes >= 0) & (a.genomes <= 0.75))
        else:  # new or edited levels: inserted with their scores (unless beaten by a full buffer)
            for j in range(k):
                there = np.flatnonzero(np.isclose(a.buffer.levels[:a.buffer.size, 0], b.genomes[j, 0], atol=0))
                if there.size:
                    assert a.buffer.scores[there[0]] == pytest.approx(score[j], abs=1e-6) or np.sum(
                        np.isclose(b.genomes[:, 0], b.genomes[j, 0], atol=0)) > 1
                else:
                    assert int(a.buffer.size) == 12  # only a full buffer turns a level away
        if a.mode == S.ACCEL_REPLAY:
            np.testing.assert_array_equal(a.genomes, a.buffer.levels[a.entry])  # replays are buffer entries
        modes.append(int(b.mode))
    modes = np.array(modes)
    assert np.all(modes[1:][modes[:-1] == S.ACCEL_REPLAY] == S.ACCEL_EDIT)  # every replay is followed by its edits
    assert np.sum(modes == S.ACCEL_REPLAY) > 5 and np.sum(modes == S.ACCEL_NEW) >= 1 and scored > 10
    summary = S.get_selector(config).summary(jax.tree.map(lambda x: x[0], after.selector))
    assert int(summary["edit_chunks"]) == np.sum(modes[1:] == S.ACCEL_EDIT) + (a.mode == S.ACCEL_EDIT)


def test_accel_on_tiles_equals_the_classic_layout(toy_generator):
    config = small("accel", terrains_per_chunk=3, max_epochs=8, plr_capacity=4, accel_generator=toy_generator)
    assert S.get_selector(config).slots == 4  # 3 levels + the evaluation terrain
    out = tiled_and_classic(config)
    assert len({tuple(np.asarray(g).ravel()) for g in out[True].selector.genomes}) == 3  # trials differ
