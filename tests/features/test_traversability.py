"""jaxterrain.features.learned: patches, labels, the strided map, the shipped model, the descriptor, weight files."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxterrain import features
from jaxterrain.features import learned as trav

CELL = 0.04
TINY = trav.ModelConfig(channels=(4, 4, 4, 4), input_scale=10.0)


def world(row, col, shape):
    """World (x, y) metres of pixel (row, col) of an [H, W] heightfield centred at the origin."""
    h, w = shape
    return np.array([col * CELL - (w - 1) * CELL / 2, row * CELL - (h - 1) * CELL / 2], np.float32)


# ------------------------------------------------------------------------------------------------ patches
def test_pixel_of_inverts_world():
    shape = (64, 72)
    pts = np.stack([world(r, c, shape) for r, c in [(0, 0), (10, 40), (63, 71)]])
    np.testing.assert_array_equal(np.asarray(trav.pixel_of(pts, shape, CELL)), [[0, 0], [10, 40], [63, 71]])


def test_patches_of_a_step():
    t = np.zeros((64, 64), np.float32)
    t[:, 40:] = 0.5  # a 0.5 m step up along +x at column 40
    p = np.asarray(trav.extract_patches(t, world(30, 36, t.shape)[None], 32, CELL))[0]  # centre (30, 36)
    assert p.shape == (32, 32)
    np.testing.assert_array_equal(p[:, :20], 0.0)  # patch column j is map column 20 + j: below the step
    np.testing.assert_array_equal(p[:, 20:], 0.5)  # map columns 40.. are the step
    on_top = np.asarray(trav.extract_patches(t, world(30, 50, t.shape)[None], 32, CELL))[0]
    np.testing.assert_array_equal(on_top[:, :6], -0.5)  # centre on the step: the low ground is -0.5 relative
    np.testing.assert_array_equal(on_top[:, 6:], 0.0)


def test_patches_of_a_wall_and_the_edge():
    t = np.zeros((64, 64), np.float32)
    t[:, 30:33] = 1.0  # a 1 m wall across the path, 3 pixels thick
    p = np.asarray(trav.extract_patches(t, world(20, 20, t.shape)[None], 32, CELL))[0]
    expect = np.zeros((32, 32), np.float32)
    expect[:, 26:29] = 1.0  # patch column j is map column j + 4
    np.testing.assert_array_equal(p, expect)
    # near the edge the map is extended by its edge values: map rows < 0 repeat row 0
    ramp = np.repeat(0.01 * np.arange(64, dtype=np.float32)[:, None], 64, axis=1)
    q = np.asarray(trav.extract_patches(ramp, world(2, 30, ramp.shape)[None], 32, CELL))[0]
    rows = np.arange(32) - 14  # patch row i is map row i - 14
    np.testing.assert_allclose(q[:, 7], 0.01 * np.maximum(rows, 0) - 0.02, atol=1e-6)


def test_batched_patches_equal_single_terrain_patches():
    maps = np.asarray(jax.random.uniform(jax.random.key(7), (3, 40, 48)))
    xy = np.stack([world(5, 7, (40, 48)), world(20, 30, (40, 48)), world(39, 47, (40, 48))])
    index = np.array([2, 0, 2])
    batched = np.asarray(trav.extract_patches_batch(maps, index, xy, 32, CELL))
    for n in range(3):
        np.testing.assert_array_equal(batched[n], np.asarray(trav.extract_patches(maps[index[n]], xy[n:n + 1]))[0])


def test_patch_errors():
    with pytest.raises(ValueError, match="terrain must be"):
        trav.extract_patches(np.zeros((2, 8, 8)), np.zeros((1, 2)))
    with pytest.raises(ValueError, match="patch"):
        trav.extract_patches(np.zeros((8, 8)), np.zeros((1, 2)), patch=1)


# ------------------------------------------------------------------------------------------------- labels
def synthetic_walks(horizon=100):
    """Three walks along +x: steady 0.02 m/step to the horizon; the same but falling at step 50; a slow 0.005 m/step
    walk that reaches the goal (ends without a fall) at step 80."""
    t = np.arange(horizon + 1, dtype=np.float32)
    steady = 0.02 * t
    falls = 0.02 * np.minimum(t, 50)
    slow = 0.005 * np.minimum(t, 80)
    x = np.stack([steady, falls, slow])[None]  # [1, 3, T + 1]
    xy = np.stack([x, np.zeros_like(x)], -1)
    return trav.Walks(jnp.asarray(xy), jnp.asarray([[horizon, 50, 80]], jnp.int32), jnp.asarray([[False, True, False]]))


def test_labels_on_a_synthetic_run():
    cfg = trav.LabelConfig(window=30, threshold=0.3, every=10, warmup=0)
    starts, labels = trav.window_labels(synthetic_walks(), cfg)
    np.testing.assert_array_equal(np.asarray(starts), np.arange(0, 100, 10))
    lab = np.asarray(labels)[0]
    # steady: 0.6 m per window > 0.3 while the window fits in the horizon (start + 30 <= 100), then no label
    np.testing.assert_array_equal(lab[0], [1, 1, 1, 1, 1, 1, 1, 1, -1, -1])
    # falls at 50: windows ending at or after the fall (start 20, 30, 40) are negative, later ones have no label
    np.testing.assert_array_equal(lab[1], [1, 1, 0, 0, 0, -1, -1, -1, -1, -1])
    # slow: 0.15 m per window < 0.3 -> 0; windows past its (non-fall) end at 80 have no label
    np.testing.assert_array_equal(lab[2], [0, 0, 0, 0, 0, 0, -1, -1, -1, -1])


def test_labelled_centres_take_the_middle_of_the_window():
    cfg = trav.LabelConfig(window=30, threshold=0.3, every=10, warmup=0)
    walks = synthetic_walks()
    starts, labels = trav.window_labels(walks, cfg)
    terrain, xy, lab = trav.labelled_centres(walks, starts, labels, cfg)
    assert len(lab) == int((np.asarray(labels) >= 0).sum()) == 8 + 5 + 6
    np.testing.assert_array_equal(terrain, 0)
    np.testing.assert_allclose(xy[:8, 0], 0.02 * (np.arange(0, 80, 10) + 15), atol=1e-6)
    np.testing.assert_allclose(xy[8:13, 0], 0.02 * np.minimum(np.arange(0, 50, 10) + 15, 50), atol=1e-6)


def test_label_config_errors():
    with pytest.raises(ValueError, match="warmup"):
        trav.window_labels(synthetic_walks(), trav.LabelConfig(warmup=100))


def test_balanced_indices():
    labels = np.array([1] * 10 + [0] * 3)
    idx = trav.balanced_indices(jax.random.key(0), labels)
    assert len(idx) == 6 and labels[idx].sum() == 3 and len(set(idx.tolist())) == 6


# --------------------------------------------------------------------------------------------------- model
def test_strided_map_equals_model_patch_by_patch():
    params = trav.init_params(jax.random.key(1), TINY)
    t = np.asarray(jax.random.uniform(jax.random.key(2), (64, 72)))
    logit_map = jax.jit(trav.logit_map, static_argnums=2)
    m = np.asarray(logit_map(params, t, TINY))
    assert m.shape == ((64 - 32) // 8 + 1, (72 - 32) // 8 + 1) == (5, 6)
    rows, cols = np.meshgrid(np.arange(5), np.arange(6), indexing="ij")
    centres = np.stack([world(8 * i + 16, 8 * j + 16, t.shape) for i, j in zip(rows.ravel(), cols.ravel())])
    patches = trav.extract_patches(t, centres, 32, CELL)  # relative to their centres
    per_patch = np.asarray(jax.jit(trav.apply_patches, static_argnums=2)(params, patches, TINY)).reshape(5, 6)
    np.testing.assert_allclose(m, per_patch, rtol=1e-4, atol=1e-5)
    # a constant offset changes nothing (zero-sum first layer)
    np.testing.assert_allclose(np.asarray(logit_map(params, t + 0.3, TINY)), m, atol=1e-4)


def test_training_separates_walls_from_flat_ground():
    key = jax.random.key(3)
    noise = 0.01 * jax.random.normal(key, (64, 32, 32))
    wall = jnp.zeros((32, 32)).at[:, 20:23].set(0.8)
    x = jnp.concatenate([noise[:32], noise[32:] + wall])
    y = np.array([1] * 32 + [0] * 32)
    params = trav.train(jax.random.key(4), x, y, trav.TrainConfig(steps=60, batch=32, learning_rate=1e-2), TINY)
    scores = np.asarray(trav.apply_patches(params, x, TINY))
    assert trav.accuracy(scores, y) >= 0.95 and trav.roc_auc(scores, y) >= 0.99


def test_roc_auc_and_accuracy():
    assert trav.roc_auc([0.1, 0.4, 0.35, 0.8], [0, 0, 1, 1]) == pytest.approx(0.75)
    assert trav.roc_auc([0.5, 0.5], [0, 1]) == pytest.approx(0.5)
    assert np.isnan(trav.roc_auc([0.1, 0.2], [1, 1]))
    assert trav.accuracy([-1.0, 2.0, 0.5], [0, 1, 0]) == pytest.approx(2 / 3)


# -------------------------------------------------------------------------------------------- weight files
def test_save_load_roundtrip_and_bad_files(tmp_path):
    params = trav.init_params(jax.random.key(5), TINY)
    trav.save(tmp_path / "m", params, TINY, extra={"note": "test"})
    model = trav.load(tmp_path / "m")
    assert model.config == TINY and model.meta["note"] == "test"
    for a, b in zip(jax.tree.leaves(params), jax.tree.leaves(model.params)):
        np.testing.assert_array_equal(a, b)
    # weights of another shape: the config names a wider network than the weights hold
    other = tmp_path / "other"
    trav.save(other, params, TINY)
    meta = json.loads((other / "config.json").read_text())
    meta["model"]["channels"] = [8, 4, 4, 4]
    (other / "config.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match=r"weights\.msgpack.*conv0.*shape"):
        trav.load(other)
    # a corrupt weights file
    (other / "weights.msgpack").write_bytes(b"\xc1 not msgpack at all")
    with pytest.raises(ValueError, match=r"other/weights\.msgpack.*corrupt"):
        trav.load(other)
    # a corrupt config, a missing file
    (other / "config.json").write_text("{not json")
    with pytest.raises(ValueError, match=r"other/config\.json"):
        trav.load(other)
    with pytest.raises(FileNotFoundError, match="model file missing.*missing"):
        trav.load(tmp_path / "missing")


# ---------------------------------------------------------------------------------- shipped model, descriptor
def test_registered_by_name():
    assert "traversability" in features.descriptor_names()


def test_shipped_model_range_determinism_and_vmap():
    maps = jax.random.uniform(jax.random.key(6), (2, 3, 48, 48)) * 0.3
    flat = maps.reshape(6, 48, 48)
    d1 = np.asarray(trav.descriptor(flat))
    d2 = np.asarray(trav.descriptor(flat))
    assert d1.shape == (6,) and np.all((d1 > 0) & (d1 < 1))
    np.testing.assert_array_equal(d1, d2)
    tmap = np.asarray(trav.traversability_map(trav.shipped().params, flat, trav.shipped().config))
    assert tmap.shape == (6, 3, 3) and np.all((tmap > 0) & (tmap < 1))
    np.testing.assert_allclose(tmap.mean(axis=(1, 2)), d1, rtol=1e-5)
    vm = np.asarray(jax.vmap(trav.descriptor)(maps))
    np.testing.assert_allclose(vm.reshape(6), d1, rtol=1e-5, atol=1e-6)
    by_name = np.asarray(jax.jit(features.descriptors, static_argnames=("names", "window", "stride"))(
        flat, names=("tri", "traversability")))
    np.testing.assert_allclose(by_name[:, 1], d1, rtol=1e-5, atol=1e-6)


def test_shipped_model_ranks_a_wall_below_flat_ground():
    flat = np.zeros((64, 64), np.float32)
    wall = flat.copy()
    wall[:, 30:34] = 1.0  # a 1 m wall across the +x path
    d = np.asarray(trav.descriptor(np.stack([flat, wall])))
    assert d[1] < d[0] - 0.1, d
    tmap = np.asarray(trav.traversability_map(trav.shipped().params, wall, trav.shipped().config))
    assert tmap.min() < np.asarray(trav.traversability_map(trav.shipped().params, flat, trav.shipped().config)).min()


@pytest.mark.slow
def test_walks_advance_on_flat_ground():
    """The base policy's recorded walks on flat ground advance along +x (the command's smoke preset:
    tests/integration/test_stage_commands.py; MJX compiles: a minute or more on 2 CPU cores)."""
    walks = trav.walk(jax.random.key(0), np.zeros((1, 64, 256), np.float32), attempts=2, horizon=40)
    x = np.asarray(walks.xy)[..., 0]
    assert walks.xy.shape == (1, 2, 41, 2) and np.all(x[..., -1] > x[..., 0] + 0.3)