"""Tile banks (one heightfield holding per-env terrains) under MJX-JAX and MJX-Warp, on CPU.

Tiny tiles: 16 x 16 samples at 0.2 m (a 3 m square, track 2 m), 2 tiles, 2 envs per tile, the shipped base policy.
Warp-only tests run where ``warp-lang`` and MJX's MuJoCo Warp import (``pip install 'jaxterrain[warp]'``) and are
skipped with the reason elsewhere; warp-lang's CPU backend runs them when there is no GPU.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxterrain.terrain import TerrainScale
from jaxterrain.walker import TILE_AXES, Tile, TileBank, WalkerConfig, WalkerEnv, sample_heights, warp_available
from jaxterrain.runtime import xla

WARP_OK, WARP_WHY = warp_available()
needs_warp = pytest.mark.skipif(not WARP_OK, reason=WARP_WHY or "warp available")

SHAPE = (16, 16)
SCALE = TerrainScale(cell_size=0.2, height=1.0)
STEPS = 100  # env steps (1.5 s): the base policy covers the 2 m track on flat ground in about 80
# cheap XLA CPU compiles (lowest backend optimisation, the classic elemental emitter instead of the fusion emitters)
FAST_COMPILE = xla.known_options({"xla_backend_optimization_level": 0, "xla_llvm_disable_expensive_passes": True,
                "xla_cpu_use_fusion_emitters": False})


def _policy():
    from jaxterrain.rl import load_policy

    return load_policy()


def _config(policy, **kw):
    from jaxterrain import difficulty

    cfg = difficulty.default_env_config(SHAPE, SCALE, policy)  # the policy's own solver options
    return cfg._replace(episode_length=STEPS, **kw)


def _terrains():
    """Tile 0 flat at 0 m; tile 1 flat with a 1 m wall across the track at x = 0.3 m (0.65 of the way)."""
    flat = np.zeros(SHAPE, np.float32)
    wall = flat.copy()
    wall[:, 9:11] = 1.0  # columns 9, 10: x = 0.3, 0.5 m
    return jnp.asarray(np.stack([flat, wall]))


def _rollout(env, policy):
    """2 envs on each of 2 tiles, STEPS env steps of the deterministic policy: (final distance [4], torso xyz
    [STEPS, 4, 3] tile-local, first done step [4], failed [4])."""
    bank = env.make_bank(_terrains())
    idx = jnp.array([0, 0, 1, 1], jnp.int32)
    keys = jax.random.split(jax.random.PRNGKey(3), 4)

    def run(bank, keys):
        tiles = bank.at(idx)
        ox, oy = jax.vmap(env.tile_origin)(idx)
        state = jax.vmap(env.reset, in_axes=(0, TILE_AXES))(keys, tiles)

        def body(carry, _):
            state, ended, final, failed = carry
            state = jax.vmap(env.step, in_axes=(0, 0, TILE_AXES))(state, jax.vmap(policy)(state.obs), tiles)
            final = jnp.where(ended, final, state.distance)
            failed = jnp.maximum(failed, jnp.where(ended, 0.0, state.failed))
            ended = ended | (state.done > 0)
            xyz = jnp.stack([state.data.qpos[:, 0] - ox, state.data.qpos[:, 1] - oy, state.data.qpos[:, 2]], -1)
            return (state, ended, final, failed), (xyz, ended)

        zeros = jnp.zeros(4, jnp.float32)
        (_, _, final, failed), (xyz, ended) = jax.lax.scan(body, (state, jnp.zeros(4, bool), zeros, zeros), None,
                                                            length=STEPS)
        return final, xyz, ended, failed

    final, xyz, ended, failed = jax.jit(run).lower(bank, keys).compile(FAST_COMPILE)(bank, keys)
    ended = np.asarray(ended)
    first_done = np.where(ended.any(0), ended.argmax(0), STEPS)
    return np.asarray(final), np.asarray(xyz), first_done, np.asarray(failed)


@pytest.fixture(scope="module")
def policy():
    return _policy()


@pytest.fixture(scope="module")
def jax_run(policy):
    return _rollout(WalkerEnv(_config(policy, tiles=2)), policy)


@pytest.fixture(scope="module")
def warp_run(policy):
    return _rollout(WalkerEnv(_config(policy, tiles=2, backend="warp", warp_worlds=4)), policy)


# --- layout, no physics ---------------------------------------------------------------------------------------
def test_bank_layout_roundtrip_and_heights():
    env = WalkerEnv(WalkerConfig(terrain_shape=SHAPE, scale=SCALE, tiles=5))
    assert env.grid == (2, 3)  # near-square grid of 5 tiles
    assert (int(env.mj_model.hfield_nrow[0]), int(env.mj_model.hfield_ncol[0])) == (32, 48)
    rng = np.random.default_rng(0)
    terrains = jnp.asarray(rng.uniform(-0.2, 1.2, (5,) + SHAPE).astype(np.float32))
    bank = env.make_bank(terrains)
    np.testing.assert_allclose(env.bank_terrains(bank), np.clip(terrains, 0, 1), atol=1e-6)
    # the hfield itself: tile 4 (grid row 1, column 1) sits at rows 16..31, columns 16..31
    np.testing.assert_allclose(bank.data[16:, 16:32], np.clip(terrains[4], 0, 1), atol=1e-6)
    # tile centres cell_size * tile size apart, symmetric about the origin
    xs, ys = zip(*(map(float, env.tile_origin(i)) for i in range(6)))
    np.testing.assert_allclose(xs, [-3.2, 0, 3.2] * 2, atol=1e-5)
    np.testing.assert_allclose(ys, [-1.6] * 3 + [1.6] * 3, atol=1e-5)
    # heights on a tile = sample_heights of that terrain alone, at world points shifted by the tile's origin
    px = jnp.asarray(rng.uniform(-1.7, 1.7, 50), jnp.float32)
    py = jnp.asarray(rng.uniform(-1.7, 1.7, 50), jnp.float32)
    for i in range(5):
        want = sample_heights(terrains[i], px, py, env.radius_x, env.radius_y, env.elevation_z)
        ox, oy = env.tile_origin(i)
        np.testing.assert_allclose(env.terrain_height(bank.at(i), px + ox, py + oy), want, atol=2e-6)
    # set_tile changes one tile only, under jit
    new = jax.jit(env.set_tile)(bank, jnp.int32(2), jnp.full(SHAPE, 0.5))
    got = env.bank_terrains(new)
    np.testing.assert_allclose(got[2], 0.5, atol=1e-6)
    np.testing.assert_allclose(np.delete(np.asarray(got), 2, 0), np.delete(np.asarray(env.bank_terrains(bank)), 2, 0))


def test_config_checks():
    with pytest.raises(ValueError, match="backend must be"):
        WalkerEnv(WalkerConfig(terrain_shape=SHAPE, scale=SCALE, backend="cuda"))
    with pytest.raises(ValueError, match="needs tiles >= 1"):
        WalkerEnv(WalkerConfig(terrain_shape=SHAPE, scale=SCALE, backend="warp"))
    tiled = WalkerEnv(WalkerConfig(terrain_shape=SHAPE, scale=SCALE, tiles=2))
    with pytest.raises(TypeError, match="walker.Tile"):
        tiled.reset(jax.random.PRNGKey(0), jnp.zeros(SHAPE))
    with pytest.raises(ValueError, match="shape"):
        tiled.make_bank(jnp.zeros((3,) + SHAPE))
    plain = WalkerEnv(WalkerConfig(terrain_shape=SHAPE, scale=SCALE))
    with pytest.raises(TypeError, match="not tiled"):
        plain.reset(jax.random.PRNGKey(0), Tile(TileBank(jnp.zeros(SHAPE)), jnp.int32(0)))


# --- physics ----------------------------------------------------------------------------------------------------
def _check_wall(run):
    final, xyz, first_done, failed = run
    assert not failed.any()
    assert np.all(final[:2] > 0.9), final  # flat tile: the whole track
    assert np.all(final[2:] < 0.7), final  # wall tile: stopped at the wall (0.65 of the track)
    assert np.all(np.abs(xyz[:, :, 1]) < 1.2)  # every walker stays on its own tile (tile-local |y| < radius_y)


def test_jax_tiles_each_env_its_own_terrain(jax_run):
    _check_wall(jax_run)


@needs_warp
def test_warp_tiles_each_env_its_own_terrain(warp_run):
    _check_wall(warp_run)


@needs_warp
def test_warp_matches_jax_on_a_short_rollout(jax_run, warp_run):
    """Same keys, tiles and policy: the same walk. Warp's Newton solver is another implementation (its own
    linesearch and summation order, float32; it reports "solver iterations limit reached" at 4 iterations), so the
    trajectories part slowly and chaotically. Measured on CPU (2026-11-23): the torsos stay within 0.05 mm for 10 env
    steps, 2.2 mm for 20, 3.5 mm for 30, 3.7 cm for 50 and 29 cm for 100; the final distances within 0.002. The bars,
    2 cm over the first 20 env steps and 0.05 in final distance, leave ~10x / ~25x room for another device's
    rounding while still catching a wrong terrain, spawn offset or solver setting (mm-scale drift vs the 0.3-0.4
    drop of a wall, or a fall)."""
    fj, xj, dj, _ = jax_run
    fw, xw, dw, _ = warp_run
    np.testing.assert_allclose(xw[:20], xj[:20], atol=0.02)
    np.testing.assert_allclose(fw, fj, atol=0.05)


@needs_warp
def test_warp_model_prints_no_solver_cap_warnings():
    """The walker's Warp model keeps MuJoCo Warp's overflow warnings of buffers (contacts, constraints, CCD,
    heightfield) and drops those of the solver's iteration caps, which it reaches by design: one printed line per
    world and step otherwise (GBs of log per GPU run)."""
    from mujoco.mjx.third_party.mujoco_warp import OverflowType

    policy = _policy()
    env = WalkerEnv(_config(policy, backend="warp", tiles=2, warp_worlds=4))
    flags = OverflowType(env.mjx_model.opt._impl.warn_overflow)
    assert not flags & (OverflowType.ITERATIONS | OverflowType.LS_ITERATIONS)
    kept = OverflowType.ALL & ~(OverflowType.ITERATIONS | OverflowType.LS_ITERATIONS)
    assert flags == kept
