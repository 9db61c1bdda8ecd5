"""benchmarks/rollouts.py --layout: classic, tiles and shared (one heightfield of one terrain under every env, the
peer that says what a bank of tiles costs); anything else fails in one line naming the flag. No compile here."""

import pytest

from benchmark_loader import load_benchmark

rollouts = load_benchmark("rollouts")


def test_unknown_layout_is_one_line_naming_the_flag(capsys):
    with pytest.raises(SystemExit) as exc:
        rollouts.parse_args(["--layout", "tiles,perworld"])
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 2
    assert len(err.splitlines()) == 1 and err.endswith("error: --layout: 'perworld' is not classic, tiles or shared")


def test_shared_is_a_bank_of_one_tile_the_first_terrain_under_every_env():
    import jax.numpy as jnp

    args = rollouts.parse_args(["--layout", "tiles,shared", "--bank", "3", "--size", "64"])
    bench = rollouts.Bench(args, rollouts.WalkerConfig(terrain_shape=(64, 64)), None, None, None, None, [], [], {})
    bank_m = jnp.stack([jnp.full((64, 64), h, jnp.float32) for h in (0.1, 0.2, 0.3)])
    tiles_env, shared_env = bench.variant_env("jax", "tiles", 5), bench.variant_env("jax", "shared", 5)
    assert (tiles_env.tiles, shared_env.tiles) == (3, 1)
    tiles, _ = rollouts.per_env_terrains(tiles_env, bank_m, 5)
    shared, axes = rollouts.per_env_terrains(shared_env, bank_m, 5)
    assert axes == rollouts.walker.TILE_AXES
    assert tiles.index.tolist() == [0, 1, 2, 0, 1] and shared.index.tolist() == [0] * 5
    assert shared_env.bank_terrains(shared.bank).shape == (1, 64, 64)
    assert float(shared_env.bank_terrains(shared.bank).mean()) == pytest.approx(0.1, abs=1e-3)
