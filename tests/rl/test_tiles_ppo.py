"""PPO (``jaxterrain.rl``) on tiles: the terrain argument may be a ``walker.Tile`` (shared: index [], or per env:
index [num_envs] under ``TILE_AXES``) as well as ``[H, W]`` / ``[N, H, W]`` arrays, and the auto-reset merges env
states with ``env.select``. CPU, tiny sizes.

The plumbing (axes, per-env tiles, select, no re-trace) runs on a cheap point env that reads its terrain through a
REAL tiled walker's tile arithmetic (``make_bank``, ``tile_origin``, ``terrain_height``), so those comparisons are
exact. Two slow tests run PPO on the MJX walker itself (each compiles two MJX programs, over a minute of CPU): on a
one-tile bank, whose tile sits at the origin, the tiled walk is the classic one bit for bit (same heightfield, same
coordinates), so PPO's update is too; on a two-tile bank, whose tiles are shifted by +-1.6 m, float32 rounding of
the shifted coordinates is allowed. The MuJoCo Warp walker runs PPO on tiles in tests/test_tiles_curriculum.py.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxterrain import rl
from jaxterrain.runtime import xla
from jaxterrain.terrain import TerrainScale
from jaxterrain.walker import Tile, WalkerConfig, WalkerEnv

# the exact comparisons below (a tile against its terrain array: two programs) hold with XLA's fusion emitters, which
# tests/conftest.py turns off suite-wide: pinned on here
FAST_COMPILE = xla.known_options({"xla_backend_optimization_level": 0, "xla_llvm_disable_expensive_passes": True,
                "xla_cpu_use_fusion_emitters": True})


# ---------------------------------------------------------------------------------------------------------------
# A point env on terrain heights read through a real tiled walker (no physics)
# ---------------------------------------------------------------------------------------------------------------
SHAPE = (16, 16)
EXACT = TerrainScale(cell_size=0.25, height=1.0)  # tile origins +-2.0 m and 0.25 m cells: exact float32 shifts
PROBE = np.stack(np.meshgrid(np.arange(-1.5, 1.6, 0.5), np.arange(-1.5, 1.6, 0.5)), -1).reshape(-1, 2).astype(
    np.float32)  # tile-local sample points (dyadic, so + origin - origin is exact)


class PointState(NamedTuple):
    obs: jax.Array
    reward: jax.Array
    done: jax.Array
    truncation: jax.Array
    pos: jax.Array
    target: jax.Array
    t: jax.Array


class TilePointEnv:
    """test_rl's 1-D "move to the target" env, target = mean terrain height at PROBE + U(-1, 1). The terrain is an
    ``[H, W]`` array (classic) or a ``walker.Tile``, read with ``walker.terrain_height`` at the tile's world points.
    Counts ``step`` traces and ``select`` calls (PPO's auto-reset must use ``env.select``)."""

    observation_size = 2
    action_size = 1

    def __init__(self, tiles: int, horizon: int = 8):
        self.walker = WalkerEnv(WalkerConfig(terrain_shape=SHAPE, scale=EXACT, tiles=tiles))
        self.plain = WalkerEnv(WalkerConfig(terrain_shape=SHAPE, scale=EXACT))
        self.horizon, self.traces, self.selects = horizon, 0, 0

    def level(self, terrain):
        px, py = jnp.asarray(PROBE[:, 0]), jnp.asarray(PROBE[:, 1])
        if isinstance(terrain, Tile):
            ox, oy = self.walker.tile_origin(terrain.index)
            return jnp.mean(self.walker.terrain_height(terrain, px + ox, py + oy))
        return jnp.mean(self.plain.terrain_height(terrain, px, py))

    def reset(self, key, terrain):
        pos_key, target_key = jax.random.split(key)
        pos = jax.random.uniform(pos_key, (), minval=-1.0, maxval=1.0)
        target = self.level(terrain) + jax.random.uniform(target_key, (), minval=-1.0, maxval=1.0)
        z = jnp.zeros((), jnp.float32)
        return PointState(jnp.stack([pos, target - pos]), z, z, z, pos, target, jnp.zeros((), jnp.int32))

    def step(self, state, action, terrain):
        self.traces += 1
        pos = state.pos + 0.2 * action[0] + 0.0 * self.level(terrain)  # the terrain is read every step
        t = state.t + 1
        done = (t >= self.horizon).astype(jnp.float32)
        return PointState(jnp.stack([pos, state.target - pos]), -jnp.abs(state.target - pos), done, done, pos,
                          state.target, t)

    def select(self, mask, new, old):
        self.selects += 1
        return jax.tree.map(lambda a, b: jnp.where(mask.reshape(mask.shape + (1,) * (a.ndim - 1)), a, b), new, old)


CFG = rl.PPOConfig(num_envs=8, unroll_length=4, num_unrolls=2, num_minibatches=2, update_epochs=2,
                   learning_rate=3e-3, gamma=0.9, reward_scaling=1.0, policy_hidden=(8,), value_hidden=(8,))


def _terrains():
    """Two 16 x 16 terrains in metres: tile 0 a ramp in [0, 0.5], tile 1 flat at 0.875 (exact in float32)."""
    ramp = np.tile(np.arange(16, dtype=np.float32) / 32.0, (16, 1))
    return jnp.asarray(np.stack([ramp, np.full(SHAPE, 0.875, np.float32)]))


def tree_equal(a, b) -> bool:
    la, lb = jax.tree.leaves(a), jax.tree.leaves(b)
    return len(la) == len(lb) and all(np.array_equal(np.asarray(x), np.asarray(y)) for x, y in zip(la, lb))


ENV = TilePointEnv(tiles=2)  # shared by the tests, so that they share compiled programs
KEY = jax.random.PRNGKey(0)
_PROGRAMS: dict = {}


def _train(env, terrain, updates: int = 2):
    """init + ``updates`` PPO updates in one program, compiled once per env and terrain form: (state, metrics)."""
    sig = (id(env), jax.tree.structure(terrain), tuple(jnp.shape(x) for x in jax.tree.leaves(terrain)), updates)
    if sig not in _PROGRAMS:
        def run(key, terrain):
            state = rl.init(key, env, CFG, terrain)
            return rl.run_updates(state, terrain, env=env, config=CFG, num_updates=updates)

        _PROGRAMS[sig] = jax.jit(run).lower(KEY, terrain).compile(FAST_COMPILE)
    return _PROGRAMS[sig](KEY, terrain)


def test_a_shared_tile_trains_as_its_terrain_array():
    """Exact: a Tile shared by all envs (index []) is PPO on that tile's [H, W] terrain, for every tile."""
    terrains = _terrains()
    bank = ENV.walker.make_bank(terrains)
    for i in range(2):
        tiled = _train(ENV, bank.at(i))
        assert tree_equal(tiled, _train(ENV, terrains[i])), i
    assert ENV.selects > 0  # the auto-reset went through env.select
    # the two tiles are different terrains: the targets follow them
    levels = [float(ENV.level(terrains[i])) for i in range(2)]
    assert levels[1] - levels[0] > 0.5
    assert np.all(np.abs(np.asarray(tiled[0].env_state.target) - levels[1]) <= 1.0)


def test_per_env_tiles_give_per_env_terrains():
    """Exact: index [num_envs] under TILE_AXES is PPO on the per-env arrays terrains[idx]; every env's target
    follows its own tile."""
    terrains = _terrains()
    bank = ENV.walker.make_bank(terrains)
    idx = jnp.array([0, 1, 1, 0, 1, 0, 0, 1], jnp.int32)
    tiled = _train(ENV, bank.at(idx))
    assert tree_equal(tiled, _train(ENV, terrains[idx]))
    levels = np.array([float(ENV.level(terrains[i])) for i in range(2)])
    assert levels[1] - levels[0] > 0.5
    target = np.asarray(tiled[0].env_state.target)
    assert np.all(np.abs(target - levels[np.asarray(idx)]) <= 1.0)
    with pytest.raises(ValueError, match="num_envs=8"):
        rl.reset_envs(tiled[0], KEY, bank.at(jnp.zeros(3, jnp.int32)), env=ENV, config=CFG)


def test_no_retrace_when_the_bank_or_the_tiles_change():
    env = TilePointEnv(tiles=2)
    terrains = _terrains()
    bank = env.walker.make_bank(terrains)
    idx = jnp.zeros(CFG.num_envs, jnp.int32)
    state = _train(ENV, bank.at(idx))[0]
    update = jax.jit(functools.partial(rl.update, env=env, config=CFG))
    state, m1 = update(state, jax.random.PRNGKey(1), bank.at(idx))
    traces = env.traces
    other = env.walker.make_bank(terrains[::-1] * 0.5)
    state, m2 = update(state, jax.random.PRNGKey(2), other.at(idx + 1))
    state, m3 = update(state, jax.random.PRNGKey(3), bank.at(jnp.arange(CFG.num_envs, dtype=jnp.int32) % 2))
    assert env.traces == traces
    assert len({float(m["reward"]) for m in (m1, m2, m3)}) == 3


@pytest.mark.slow
def test_train_takes_a_tile():
    """rl.train (the driver loop) on a shared Tile equals rl.train on its terrain array."""
    terrains = _terrains()
    bank = ENV.walker.make_bank(terrains)
    a, ma = rl.train(jax.random.PRNGKey(3), ENV, CFG, 2, bank.at(1), updates_per_chunk=2)
    b, mb = rl.train(jax.random.PRNGKey(3), ENV, CFG, 2, terrains[1], updates_per_chunk=2)
    assert tree_equal(a, b) and tree_equal(ma, mb)


# ---------------------------------------------------------------------------------------------------------------
# The MJX walker
# ---------------------------------------------------------------------------------------------------------------
WALK = TerrainScale(cell_size=0.2, height=1.0)
WALKER = WalkerConfig(terrain_shape=SHAPE, scale=WALK, episode_length=6)  # episodes end within an update
PPO = rl.PPOConfig(num_envs=4, unroll_length=4, num_unrolls=2, num_minibatches=2, update_epochs=1,
                   policy_hidden=(16,), value_hidden=(16,))


def _bumps(seed: int):
    return jnp.asarray(np.random.default_rng(seed).integers(0, 16, SHAPE) / 64.0, jnp.float32)  # [0, 0.23] m


def _walker_update(env, terrain):
    """init + one PPO update of the walker (one compile, fast XLA options): (state, metrics)."""
    def run(key, terrain):
        state = rl.init(key, env, PPO, terrain)
        return rl.update(state, jax.random.PRNGKey(1), terrain, env=env, config=PPO)

    return jax.jit(run).lower(jax.random.PRNGKey(0), terrain).compile(FAST_COMPILE)(jax.random.PRNGKey(0), terrain)


@pytest.mark.slow
def test_walker_ppo_on_a_one_tile_bank_equals_the_classic_terrain_exactly():
    """A one-tile bank's tile lies at the origin on a heightfield of the terrain's own size: the walker's physics,
    heights and observations are the classic ones bit for bit, and so is PPO's update (env states, params, metrics).
    Slow: two MJX programs, about 75 s of CPU to compile."""
    terrain = _bumps(0)
    classic = _walker_update(WalkerEnv(WALKER), terrain)
    tiled_env = WalkerEnv(WALKER._replace(tiles=1))
    tiled = _walker_update(tiled_env, tiled_env.make_bank(terrain[None]).at(0))
    assert tree_equal(tiled, classic)
    assert float(classic[1]["episodes"]) > 0  # some episode ended: the auto-reset (env.select) ran


@pytest.mark.slow
def test_walker_ppo_on_shifted_tiles_equals_per_env_terrains_within_rounding():
    """Two tiles, envs on tiles [0, 1, 1, 0]: the per-env classic terrains, up to float32 rounding of the tiles'
    world coordinates (+-1.6 m): one update (8 env steps of 4 envs) within 1e-4."""
    terrains = jnp.stack([_bumps(1), _bumps(2) + 0.3])
    idx = jnp.array([0, 1, 1, 0], jnp.int32)
    classic = _walker_update(WalkerEnv(WALKER), terrains[idx])
    tiled_env = WalkerEnv(WALKER._replace(tiles=2))
    tiled = _walker_update(tiled_env, tiled_env.make_bank(terrains).at(idx))
    (sc, mc), (st, mt) = classic, tiled
    ox = np.asarray(jax.vmap(tiled_env.tile_origin)(idx)[0])
    np.testing.assert_allclose(np.asarray(st.env_state.data.qpos[:, 0]) - ox, np.asarray(sc.env_state.data.qpos[:, 0]),
                               atol=1e-4)
    np.testing.assert_allclose(np.asarray(st.env_state.obs), np.asarray(sc.env_state.obs), atol=1e-4)
    for a, b in zip(jax.tree.leaves(st.params), jax.tree.leaves(sc.params)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), atol=1e-4)
    for k in ("reward", "episode_return"):
        np.testing.assert_allclose(float(mt[k]), float(mc[k]), atol=1e-3, rtol=1e-4)
    # per-env terrains: the envs on tile 1 (0.3 m higher) stand higher
    z = np.asarray(st.env_state.data.qpos[:, 2])
    assert abs((z[1] + z[2]) / 2 - (z[0] + z[3]) / 2) > 0.2


_MESH_SCRIPT = """
import sys
sys.path.insert(0, TESTS)
import jax, jax.numpy as jnp, numpy as np
from jaxterrain import rl
from jaxterrain.runtime import sharding as SH
from test_tiles_ppo import CFG, TilePointEnv, _terrains

assert len(jax.devices()) == 4
env, config = TilePointEnv(tiles=2), CFG._replace(num_envs=6)
bank = env.walker.make_bank(_terrains())
tiles = bank.at(jnp.array([0, 1, 1, 0, 1, 0], jnp.int32))
one, m1 = rl.train(jax.random.PRNGKey(0), env, config, 1, tiles)
four, m4 = rl.train(jax.random.PRNGKey(0), env, config, 1, tiles, mesh=SH.make_mesh())
for a, b in zip(jax.tree.leaves(one), jax.tree.leaves(four)):
    np.testing.assert_allclose(np.asarray(b), np.asarray(a), rtol=1e-5, atol=1e-6)
np.testing.assert_allclose(m4["loss"], m1["loss"], rtol=1e-5, atol=1e-6)
print("ok")
""".replace("TESTS", repr(str(__import__("pathlib").Path(__file__).resolve().parent)))


@pytest.mark.slow
def test_per_env_tiles_data_parallel_equal_one_device():
    """rl.train(mesh=) with a Tile per env (index [6] split over 4 forced CPU devices, padded) equals one device up
    to float rounding (the minibatch gradients are summed across devices)."""
    from devices import run_on_devices

    assert run_on_devices(_MESH_SCRIPT).strip().endswith("ok")
