"""The DCGAN generator, the DEM loader and the train-gan command (tiny sizes, CPU)."""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxterrain.terrain import dem
from jaxterrain.generators import gan as G

patches = jax.jit(dem.random_patches, static_argnames=("n", "size", "scales", "augment"))
TINY = G.GanConfig(size=32, base=4, channels=(16, 8, 4), disc_channels=(8, 16))


@pytest.fixture(scope="module")
def tiny_weights(tmp_path_factory):
    """Freshly initialised tiny generator weights saved like a training run's final/ folder."""
    gv, _ = G.init_variables(jax.random.PRNGKey(3), TINY)
    # running variances like those of a trained net (activations are small at N(0, 0.02) init): not 1
    gv["batch_stats"] = {layer: {"mean": s["mean"] + 1e-3, "var": s["var"] * 1e-3}
                         for layer, s in gv["batch_stats"].items()}
    return G.save_generator(tmp_path_factory.mktemp("gan") / "final", TINY, gv)


# ---------------------------------------------------------------------------------------------------------------
# Generator
# ---------------------------------------------------------------------------------------------------------------


def test_forward_shape_range_determinism(tiny_weights):
    gen = G.gan(size=32, weights=tiny_weights)
    z = gen.sample(jax.random.PRNGKey(0), 4)
    assert z.shape == (4, 50) and z.dtype == jnp.float32
    maps = gen.render(z)
    assert maps.shape == (4, 32, 32) and maps.dtype == jnp.float32
    assert float(maps.min()) >= 0.0 and float(maps.max()) <= 1.0
    np.testing.assert_array_equal(np.asarray(maps), np.asarray(gen.render(z)))
    # different latents give different terrains; one genome renders like its row of the batch
    assert float(jnp.abs(maps[0] - maps[1]).max()) > 1e-4
    np.testing.assert_allclose(np.asarray(gen.render(z[2])), np.asarray(maps[2]), atol=1e-6)
    # inference uses running averages: a sample does not depend on the rest of the batch
    np.testing.assert_allclose(np.asarray(gen.render(z[:2])), np.asarray(maps[:2]), atol=1e-6)
    # another output size is a resampled map, still in [0, 1]
    small = G.gan(size=16, weights=tiny_weights).render(z)
    assert small.shape == (4, 16, 16) and 0.0 <= float(small.min()) and float(small.max()) <= 1.0


def test_genome_spec_and_mutation(tiny_weights):
    gen = G.gan(size=32, weights=tiny_weights)
    assert gen.spec.size == 50 and gen.spec.names[0] == "z0"
    assert set(gen.spec.lower) == {-3.0} and set(gen.spec.upper) == {3.0}
    z = gen.sample(jax.random.PRNGKey(1), 4000)
    assert float(jnp.abs(z).max()) <= 3.0
    assert abs(float(z.std()) - 0.986) < 0.02  # truncated N(0, 1), not uniform (std 1.73)
    child = gen.mutate(jax.random.PRNGKey(2), z)
    changed = np.asarray(child != z)
    assert abs(changed.mean() - 0.07) < 0.005  # paper: per-gene probability 0.07
    step = np.asarray(child - z)[changed & (np.abs(np.asarray(child)) < 3.0)]
    assert abs(step.std() - 0.6) < 0.03  # sigma = 10 % of the range 6
    assert float(jnp.abs(child).max()) <= 3.0
    with pytest.raises(ValueError, match="z7"):
        gen.render(z[:1].at[0, 7].set(3.5))


def test_missing_weights_error_says_how_to_train(tmp_path):
    with pytest.raises(FileNotFoundError, match="train-gan"):
        G.gan(weights=tmp_path)


def test_default_architecture_is_small():
    gen, _ = G.make_modules(G.GanConfig())
    gv = jax.eval_shape(lambda: gen.init(jax.random.PRNGKey(0), jnp.zeros((1, 50)), train=False))
    n = G.count_params(gv["params"])
    assert 400_000 < n < 2_000_000
    assert G.generator_flops(G.GanConfig()) == pytest.approx(1.986e8, rel=0.01)


def test_shipped_weights():
    # The package ships them (python -m experiments train-gan --preset gpu --export-assets).
    assert (G.ASSET_DIR / G.WEIGHTS_FILE).is_file()
    assert (G.ASSET_DIR / "PROVENANCE.md").is_file()
    assert (G.ASSET_DIR / G.WEIGHTS_FILE).stat().st_size < 8 * 2**20
    from jaxterrain import generators

    gen = generators.get("gan", size=64)
    maps = gen.render(gen.sample(jax.random.PRNGKey(0), 3))
    assert maps.shape == (3, 64, 64)
    assert 0.0 <= float(maps.min()) and float(maps.max()) <= 1.0
    assert float(maps.std(axis=(1, 2)).min()) > 0.01  # relief, not a flat or collapsed output


# ---------------------------------------------------------------------------------------------------------------
# DEM loader
# ---------------------------------------------------------------------------------------------------------------


def _ramp(h=80, w=90):
    return np.add.outer(np.zeros(h), np.arange(w, dtype=np.float32) * 3.0) + 100.0


def test_read_tif_npy_npz(tmp_path):
    import tifffile

    z = _ramp()
    tifffile.imwrite(tmp_path / "a.tif", z.astype(np.float32))
    np.save(tmp_path / "b.npy", z.astype(np.int16))
    np.savez(tmp_path / "c.npz", elevation=z, x=np.arange(3))
    np.savez(tmp_path / "d.npz", topo=z[None], lon=np.arange(90))  # one-band [1, H, W] and 1-D extras
    z_nan = z.copy()
    z_nan[:5, :5] = np.nan
    tifffile.imwrite(tmp_path / "e.tiff", z_nan.astype(np.float32))
    dems = dem.load_dems(tmp_path)
    assert [n.split("/")[-1] for n, _ in dems] == ["a.tif", "b.npy", "c.npz", "d.npz", "e.tiff"]
    for _, a in dems[:4]:
        np.testing.assert_array_equal(a, z.astype(np.float32))
    assert np.isfinite(dems[4][1]).all() and dems[4][1][0, 0] == z[5:, :].min()


def test_bad_dem_files(tmp_path):
    np.save(tmp_path / "cube.npy", np.ones((4, 80, 80)))
    np.save(tmp_path / "nan.npy", np.full((80, 80), np.nan))
    np.save(tmp_path / "flat.npy", np.full((80, 80), 7.0))
    np.save(tmp_path / "small.npy", _ramp(40, 90))
    (tmp_path / "junk.tif").write_bytes(b"not a tiff")
    (tmp_path / "dem.png").write_bytes(b"")
    np.savez(tmp_path / "many.npz", a=_ramp(), b=_ramp())
    cases = {
        "cube.npy": "2-D", "nan.npy": "NaN", "flat.npy": "constant", "small.npy": "too small",
        "junk.tif": "unreadable", "dem.png": "unknown extension", "many.npz": "elevation",
    }
    for name, message in cases.items():
        with pytest.raises(ValueError, match=message) as err:
            dem.read_dem(tmp_path / name, min_size=64)
        assert name in str(err.value)


def test_random_patches_synthetic_and_augmentation():
    z = _ramp(100, 120)  # rises along columns
    tiles = dem.stack_tiles([z, _ramp(70, 64).T])
    key = jax.random.PRNGKey(0)
    p = patches(key, tiles, 64, size=32, scales=(32, 64))
    assert p.shape == (64, 32, 32)
    assert float(p.min()) == 0.0 and float(p.max()) == 1.0
    np.testing.assert_allclose(np.asarray(p.min(axis=(1, 2))), 0.0)
    np.testing.assert_allclose(np.asarray(p.max(axis=(1, 2))), 1.0)
    # orientation of the ramp: mean gradient along rows / columns
    def directions(maps):
        gy = np.asarray(maps[:, -1, :] - maps[:, 0, :]).mean(1)
        gx = np.asarray(maps[:, :, -1] - maps[:, :, 0]).mean(1)
        return {(int(np.sign(round(a, 3))), int(np.sign(round(b, 3)))) for a, b in zip(gy, gx)}

    ramp_only = dem.stack_tiles([z])
    plain = patches(key, ramp_only, 64, size=32, scales=(32, 64), augment=False)
    assert directions(plain) == {(0, 1)}  # all rise left to right
    augmented = patches(key, ramp_only, 64, size=32, scales=(32, 64))
    assert directions(augmented) == {(0, 1), (0, -1), (1, 0), (-1, 0)}  # all four orientations appear
    with pytest.raises(ValueError, match="smaller than the smallest crop"):
        dem.random_patches(key, tiles, 4, size=32, scales=(80,))


def test_matplotlib_dem_patches():
    dems = dem.load_dems()
    assert [a.shape for _, a in dems] == [(344, 403), (91, 120)]
    assert float(dems[1][1].min()) == 0.0  # topobathy: sea floor set to sea level
    tiles = dem.stack_tiles([a for _, a in dems])
    p = patches(jax.random.PRNGKey(1), tiles, 16, size=64)
    assert p.shape == (16, 64, 64)
    np.testing.assert_allclose(np.asarray(p.max(axis=(1, 2))), 1.0, atol=1e-6)
    np.testing.assert_allclose(np.asarray(p.min(axis=(1, 2))), 0.0, atol=1e-6)
    assert float(jnp.abs(p[0] - p[1]).mean()) > 0.01


# ---------------------------------------------------------------------------------------------------------------
# Training run (gan_train.train_gan; the train-gan command: tests/integration/test_stage_commands.py)
# ---------------------------------------------------------------------------------------------------------------
def tiny_run(steps: int):
    """A tiny architecture and batch, so the test compiles fast; a checkpoint, a log line and a grid every step."""
    from jaxterrain.generators import gan_train

    return gan_train.GanRun(G.GanConfig(size=32, channels=(16, 8, 4), disc_channels=(8, 16)), steps=steps,
                            batch_size=2, sample_every=1, ckpt_every=1, log_every=1, quality_samples=0)


@pytest.fixture(scope="module")
def sample_tiles():
    """matplotlib's sample DEMs, stacked for the device (train-gan's default data)."""
    return dem.stack_tiles([z for _, z in dem.load_dems(None, min(dem.DEFAULT_SCALES))])


@pytest.mark.slow  # 10-70 s on 2 CPU cores; the default suite keeps under 15 min (2026-11-29)
def test_train_checkpoint_resume_bit_equal(tmp_path, sample_tiles):
    """``train_gan`` stopped after 1 step and resumed (to 2, then 3 steps) ends with the generator bytes, the
    discriminator, optimiser states, step, key and metric history of an uninterrupted 3-step run."""
    from jaxterrain.runtime import driver
    from jaxterrain.generators import gan_train

    run = tiny_run(3)
    like = gan_train.init_state(jax.random.PRNGKey(0), run.config)
    whole = gan_train.train_gan(run, sample_tiles, tmp_path / "a", progress=False)
    assert whole.done == 3 and whole.variables is not None and whole.quality is None
    assert len(whole.history["d_loss"]) == 3 and whole.last_metrics["d_loss"] == whole.history["d_loss"][-1]
    part = gan_train.train_gan(run._replace(steps=1), sample_tiles, tmp_path / "b", progress=False)
    assert part.done == 1 and driver.restore(tmp_path / "b", like)[1] == 1
    assert gan_train.train_gan(run._replace(steps=2), sample_tiles, tmp_path / "b", resume=True,
                               progress=False).done == 2
    resumed = gan_train.train_gan(run, sample_tiles, tmp_path / "b", resume=True, progress=False)
    assert resumed.history == whole.history
    a = (tmp_path / "a" / "final" / "generator.msgpack").read_bytes()
    b = (tmp_path / "b" / "final" / "generator.msgpack").read_bytes()
    assert a == b  # bit-equal generator after resume
    (sa, da, ha, _), (sb, db, hb, meta) = (driver.restore(tmp_path / r, like) for r in ("a", "b"))
    leaves_a, leaves_b = jax.tree_util.tree_leaves(sa), jax.tree_util.tree_leaves(sb)
    assert len(leaves_a) == len(leaves_b) == len(jax.tree_util.tree_leaves(like))
    for x, y in zip(leaves_a, leaves_b):  # bit-equal discriminator, optimiser states, step and key
        assert np.asarray(x).dtype == np.asarray(y).dtype and np.array_equal(np.asarray(x), np.asarray(y))
    assert da == db == 3 and int(sa.step) == 3 and ha == hb and len(ha["d_loss"]) == 3
    assert meta["command"] == "train-gan" and meta["config"] == run.config.to_json()
    moved = [float(np.abs(np.asarray(x) - np.asarray(y)).max()) for x, y in zip(
        jax.tree_util.tree_leaves(sa.g_params), jax.tree_util.tree_leaves(like.g_params))]
    assert max(moved) > 0  # training changed the generator
    assert (tmp_path / "a" / "samples" / "step_00000003.png").is_file()
    assert (tmp_path / "a" / "samples" / "real.png").is_file()
    log = [json.loads(line) for line in (tmp_path / "a" / "log.jsonl").read_text().splitlines()]
    assert [r["step"] for r in log] == [1, 2, 3] and all(np.isfinite(r["d_loss"]) for r in log)
    np.testing.assert_allclose([r["d_loss"] for r in log], ha["d_loss"], rtol=1e-6)
    rows = (tmp_path / "b" / "metrics.csv").read_text().splitlines()
    assert rows[0].startswith("step,") and [r.split(",")[0] for r in rows[1:]] == ["1", "2", "3"]
    # the final folder loads as a generator
    gen = G.gan(size=32, weights=tmp_path / "a" / "final")
    assert gen.render(gen.sample(jax.random.PRNGKey(0), 2)).shape == (2, 32, 32)


def test_train_time_limit_stops_after_a_checkpoint(tmp_path, sample_tiles):
    """A limit of 10 us: the run stops after its first chunk, with a checkpoint, no final/ folder and no
    variables; resumed, it ends."""
    from jaxterrain.runtime import driver
    from jaxterrain.generators import gan_train

    run = tiny_run(3)
    like = gan_train.init_state(jax.random.PRNGKey(0), run.config)
    stopped = gan_train.train_gan(run, sample_tiles, tmp_path / "c", time_limit_s=1e-5, progress=False)
    assert stopped.done == 1 and stopped.variables is None and stopped.quality is None
    assert driver.restore(tmp_path / "c", like)[1] == 1
    assert not (tmp_path / "c" / "final").exists()
    assert gan_train.train_gan(run, sample_tiles, tmp_path / "c", resume=True, progress=False).done == 3
    assert (tmp_path / "c" / "final" / "generator.msgpack").is_file()


def test_wasserstein_and_quality_report(tiny_weights):
    from jaxterrain.generators import gan_train

    a = np.arange(100.0)[:, None]
    np.testing.assert_allclose(gan_train.wasserstein1(a, a + 2.0), [2.0], atol=1e-9)

    def fake_descriptors(maps, names, window, stride):  # a local stand-in with the same signature
        return jnp.stack([maps.std(axis=(1, 2)), maps.mean(axis=(1, 2)), maps.max(axis=(1, 2))], -1)

    cfg, variables = G.load_generator(tiny_weights)
    tiles = dem.stack_tiles([_ramp(100, 120) + np.random.default_rng(0).normal(size=(100, 120))])
    report = gan_train.quality_check(jax.random.PRNGKey(0), cfg, variables, tiles, n=16,
                                     descriptors=fake_descriptors)
    assert set(report["w1"]) >= {"gan", "real_b"}
    assert report["mean_w1"]["real_b"] < report["mean_w1"]["gan"]  # an untrained GAN is far from the data
