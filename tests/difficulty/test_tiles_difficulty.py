"""Terrain difficulty on TILES (:mod:`jaxterrain.walker.rollout`): the tiled layout walks as the classic one, under MJX-JAX
and MuJoCo Warp, on CPU.

Tiny maps: 16 x 16 samples at 0.2 m (a 3 m square, track 2 m), 100-step episodes, the shipped base policy with its
own solver, 4 attempts per terrain on three terrains whose outcomes are far apart and stable from walk to walk: flat
(the whole track, 1.0), a 1 m wall across the track at x = 0.3 m (stopped before it, ~0.58) and a 0.3 m step up at
the same place (stopped at it, ~0.63). Rough terrains are left out on purpose: there, single walks are chaotic (a fall
one step earlier or later), so 4 attempts measure the physics' rounding, not the layout.

MJX compiles slowly on a CPU (~18 s of CPU per rollout loop with the options below, plus ~5 s to trace it), so the
MJX-JAX rollouts compared share ONE compiled program (classic all at once, tiled pool); MuJoCo Warp compiles in
seconds but steps slowly on warp's CPU backend. The tiled all-at-once loop under MJX-JAX and the Warp pool are the
slow tests (their code paths run in the default tests under the other backend).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxterrain import difficulty
from jaxterrain.terrain import TerrainScale
from jaxterrain.walker import WalkerConfig, warp_available
from jaxterrain import walker
from jaxterrain.walker import layout
from jaxterrain.runtime import xla

WARP_OK, WARP_WHY = warp_available()
needs_warp = pytest.mark.skipif(not WARP_OK, reason=WARP_WHY or "warp available")

SHAPE = (16, 16)
SCALE = TerrainScale(cell_size=0.2, height=1.0)
STEPS = 100
STEPS_SHORT = 10  # the recorded walks: long enough to leave the start, short for Warp's CPU steps
ATTEMPTS, BEST, SLOTS = 4, 2, 5  # 12 walks on 5 pool slots: three rounds of refills
KEY = jax.random.PRNGKey(3)
# cheaper XLA CPU compiles (measured on the classic loop: 12 s instead of 19 s of CPU); every program compared with
# another is compiled with the same options
FAST_COMPILE = xla.known_options({"xla_backend_optimization_level": 0, "xla_llvm_disable_expensive_passes": True,
                "xla_cpu_use_fusion_emitters": False})
# Tiled vs classic MJX-JAX: not bit for bit. A tiled walker's world coordinates are shifted by its tile's origin
# (x = +-1.6 m here), so positions, contact points and the distance's difference x - x_start round differently in
# float32 (ulp 1.2e-7 m at 1.6 m), and the walk's chaotic dynamics grow that to ~1e-5 over a walk. Measured on
# these terrains: 1.0e-5 all at once, 2.2e-5 pooled (the pool also changes the batch); the episode lengths equal.
TILED_ATOL = 1e-4
WARP_FITNESS_ATOL = 0.03  # issue 14's bar; measured here within 0.005 (Warp's own Newton solver arithmetic)


def _maps() -> np.ndarray:
    """[3, 16, 16] heightmaps in [0, 1]: flat, a 1 m wall (columns 9-10: x = 0.3, 0.5 m), a 0.3 m step up there."""
    flat = np.zeros(SHAPE, np.float32)
    wall = flat.copy()
    wall[:, 9:11] = 1.0
    step = flat.copy()
    step[:, 9:] = 0.3
    return np.stack([flat, wall, step])


def _config(policy, **kw) -> WalkerConfig:
    return difficulty.default_env_config(SHAPE, SCALE, policy, **kw)._replace(episode_length=STEPS)


def _check_terrain_outcomes(d):
    """Each row walked its own terrain: flat to the end, stopped by the wall, stopped a little later by the step."""
    d = np.asarray(d)
    assert np.all(d[0] > 0.95), d
    assert np.all((d[1] > 0.5) & (d[1] < 0.61)), d
    assert np.all((d[2] > 0.61) & (d[2] < 0.7)), d


@pytest.fixture(scope="module")
def policy():
    return difficulty.default_policy()


@pytest.fixture(scope="module")
def jax_runs(policy):
    """One compiled program: the classic layout all at once (the reference) and the tiled layout's rollout pool."""
    classic = walker.make_env(_config(policy))
    tiled = walker.make_env(_config(policy)._replace(tiles=1))  # sized to the call: 3 tiles
    terrains = jnp.asarray(_maps()) * SCALE.height

    def run(t, k):
        return (walker.batched_distances(classic, policy, t, k, ATTEMPTS),
                walker.batched_distances(tiled, policy, t, k, ATTEMPTS, slots=SLOTS,
                                             priority=walker.smoothness_priority(t)))

    out = jax.jit(run).lower(terrains, KEY).compile(FAST_COMPILE)(terrains, KEY)
    return jax.tree.map(np.asarray, jax.device_get(out))


# --- sizing, no physics -----------------------------------------------------------------------------------------
def test_envs_are_sized_to_the_call(policy):
    cfg = _config(policy)
    assert difficulty.default_env_config(SHAPE, SCALE, policy, backend="warp") == cfg._replace(
        episode_length=1000, backend="warp", tiles=1)
    assert not layout.is_tiled(cfg) and layout.is_tiled(cfg._replace(tiles=1))
    assert layout.is_tiled(cfg._replace(backend="warp"))  # warp has no classic layout
    classic = layout.make_env(cfg)
    assert layout.env_for(cfg, 7, 7) is classic and layout.sized_env(classic, 7, 7) is classic
    tiled = layout.env_for(cfg._replace(tiles=1), 3, 12)
    assert tiled.tiles == 3 and tiled.grid == (2, 2) and tiled.config.warp_worlds == cfg.warp_worlds  # jax: untouched
    assert layout.sized_env(tiled, 3, 10 ** 6) is tiled and layout.sized_env(tiled, 5, 1).tiles == 5
    # built while a jit traces (as fitness_fn's envs are): the env holds concrete arrays, not the trace's tracers
    sized = jax.jit(lambda t: layout.sized_env(tiled, 4, 4).make_bank(t).data.sum())(jnp.ones((4,) + SHAPE))
    assert float(sized) > 0
    leaves = jax.tree.leaves(layout.env_for(cfg._replace(tiles=1), 4, 4).mjx_model)
    assert leaves and not any(isinstance(v, jax.core.Tracer) for v in leaves)
    for bad in (lambda: difficulty.default_env_config(SHAPE, SCALE, policy, backend="cuda"),
                lambda: difficulty.fitness_fn(16, scale=SCALE, backend="cuda")):
        with pytest.raises(ValueError, match="backend must be one of"):
            bad()
    from jaxterrain import qd as archive
    from jaxterrain.qd import evolution

    with pytest.raises(ValueError, match="rollout_backend"):
        archive.resolve_config(archive.EvolveConfig(rollout_backend="cuda"))
    evolve_cfg = archive.EvolveConfig(attempts=4, best=2, scale=SCALE, rollout_slots=SLOTS)
    # the MAP-Elites fitness of a config is the difficulty factory's, backend included (cached per arguments)
    assert evolution.default_fitness(16, evolve_cfg) is difficulty.fitness_fn(16, difficulty.Protocol(4, 2), SCALE,
                                                                                SLOTS, True, "jax")


@needs_warp
def test_warp_envs_are_sized_to_the_call(policy):
    cfg = _config(policy)._replace(backend="warp")  # tiles = 0: taken as tiles too
    w = layout.env_for(cfg, 3, 12)
    assert w.tiles == 3 and w.config.warp_worlds == 12 and layout.sized_env(w, 3, 12) is w
    assert layout.sized_env(w, 3, 13).config.warp_worlds == 13  # more envs than its worlds: another env
    with pytest.raises(ValueError, match="warp_worlds"):
        layout.check_worlds(w, 13)


# --- MJX-JAX: tiled = classic -----------------------------------------------------------------------------------
@pytest.mark.slow  # 10-70 s on 2 CPU cores; the default suite keeps under 15 min (2026-11-29)
def test_tiled_pool_walks_as_the_classic_layout(jax_runs):
    """The pool on tiles (each slot's tile index refilled with its job, states merged by env.select) gives every
    walk the classic layout's length and, within float32 rounding, its distance."""
    (d_classic, n_classic), (d_pool, n_pool) = jax_runs
    assert len(set(n_classic.ravel().tolist())) > 3  # episodes of many lengths: the slots refill at different times
    np.testing.assert_array_equal(n_pool, n_classic)
    np.testing.assert_allclose(d_pool, d_classic, atol=TILED_ATOL)


@pytest.mark.slow  # 10-70 s on 2 CPU cores; the default suite keeps under 15 min (2026-11-29)
def test_each_env_walks_its_own_terrain(jax_runs):
    """Three terrains with three different outcomes: row b of the tiled pool walked tile b = terrain b (not tile 0,
    not a neighbour's)."""
    (d_classic, _), (d_pool, _) = jax_runs
    _check_terrain_outcomes(d_classic)
    _check_terrain_outcomes(d_pool)


@pytest.mark.slow
def test_tiled_all_at_once_walks_as_the_classic_layout(policy, jax_runs):
    """batched_distances on tiles without a pool (bank.at(arange(B)) under TILE_AXES). Slow: one more MJX compile;
    the Warp test below runs the same code path by default."""
    (d_classic, n_classic), _ = jax_runs
    tiled = walker.make_env(_config(policy)._replace(tiles=1))
    terrains = jnp.asarray(_maps()) * SCALE.height
    fn = jax.jit(lambda t, k: walker.batched_distances(tiled, policy, t, k, ATTEMPTS)).lower(
        terrains, KEY).compile(FAST_COMPILE)
    d, n = jax.device_get(fn(terrains, KEY))
    np.testing.assert_array_equal(n, n_classic)
    np.testing.assert_allclose(d, d_classic, atol=TILED_ATOL)


# --- MuJoCo Warp --------------------------------------------------------------------------------------------------
def _warp_fitness(policy, slots=None):
    return np.asarray(difficulty.evaluate(_maps(), KEY, ATTEMPTS, BEST, env_config=_config(policy, backend="warp"),
                                          slots=slots))


@needs_warp
def test_warp_fitness_matches_jax(policy, jax_runs):
    """evaluate with default_env_config(backend="warp") (tiles sized to the 3 terrains, 12 worlds): the same keys
    walk the same walks up to Warp's solver arithmetic; fitness (best 2 of 4) within issue 14's 0.03."""
    (d_classic, _), _ = jax_runs
    fit = _warp_fitness(policy)
    np.testing.assert_allclose(fit, np.asarray(difficulty.best_of(d_classic, BEST)), atol=WARP_FITNESS_ATOL)
    assert fit[0] > 0.95 and 0.5 < fit[1] < 0.61 < fit[2] < 0.7, fit  # each env on its own terrain


@pytest.mark.slow
@needs_warp
def test_warp_pool_matches_jax(policy, jax_runs):
    """The rollout pool under Warp (env.select keeps the shared contact buffers; 5 worlds). Slow: three rounds of
    Warp's CPU steps; the default tests run the pool under MJX-JAX and Warp all at once."""
    (d_classic, _), _ = jax_runs
    fit = _warp_fitness(policy, slots=SLOTS)
    np.testing.assert_allclose(fit, np.asarray(difficulty.best_of(d_classic, BEST)), atol=WARP_FITNESS_ATOL)


@needs_warp
def test_warp_walks_and_recordings_are_on_the_map(policy):
    """traversability.walk and report.render.record_walks under Warp: each terrain on its own tile, positions on
    the map (the tile's origin subtracted): every walk starts at (x_start, 0), as on the classic layout."""
    from jaxterrain.features import learned as traversability
    from jaxterrain.report import render

    env = layout.make_env(_config(policy))
    walks = traversability.walk(KEY, _maps(), attempts=1, horizon=STEPS_SHORT, scale=SCALE, backend="warp")
    xy = np.asarray(walks.xy)  # [3 terrains, 1 attempt, STEPS_SHORT + 1, 2]
    np.testing.assert_allclose(xy[:, :, 0], np.broadcast_to([env.x_start, 0.0], (3, 1, 2)), atol=1e-3)
    advance = xy[:, :, -1, 0] - xy[:, :, 0, 0]
    assert np.all((advance > 0.02) & (advance < 0.5)) and np.all(np.abs(xy[..., 1]) < 0.3), xy[:, :, -1]
    recorded = render.record_walks(_maps()[:2], KEY, steps=STEPS_SHORT,
                                   env_config=difficulty.default_env_config(SHAPE, SCALE, policy, backend="warp"))
    for w in recorded:
        np.testing.assert_allclose(w.qpos[0, :2], [env.x_start, 0.0], atol=1e-3)
        assert 0.02 < w.qpos[-1, 0] - w.qpos[0, 0] < 0.5 and np.all(np.isfinite(w.qpos))
