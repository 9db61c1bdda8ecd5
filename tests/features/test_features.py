"""Terrain features (TRI, TPI, roughness), descriptors and Algorithm 1 (jaxterrain.features)."""

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxterrain import features as F
from jaxterrain.terrain import TerrainScale

DATA = Path(__file__).resolve().parents[1] / "data"

# A 5 x 5 map with a few bumps. With window 3, stride 1 the maps are 3 x 3; map pixel (i, j) is the window of
# rows i..i+2, columns j..j+2 with centre z = H[i+1, j+1].
H5 = np.array(
    [
        [0, 0, 0, 0, 5],
        [0, 1, 0, 2, 0],
        [0, 0, 0, 0, 0],
        [0, 3, 0, 0, 0],
        [0, 0, 0, 0, 0],
    ],
    np.float32,
)
# Derivation per window (others = the 8 non-centre pixels):
# (0,0) [[0,0,0],[0,1,0],[0,0,0]] z=1, others all 0: TRI 8/8=1, TPI 1-0=1, rough 1-0=1, Riley sqrt(8*1)
# (0,1) [[0,0,0],[1,0,2],[0,0,0]] z=0, others sum 3: TRI 3/8, TPI -3/8, rough 2, Riley sqrt(1+4)
# (0,2) [[0,0,5],[0,2,0],[0,0,0]] z=2, |d| = 7*2 + |5-2| = 17: TRI 17/8, TPI 2-5/8 = 11/8, rough 5,
#       Riley sqrt(7*4 + 9) = sqrt(37)
# (1,0) [[0,1,0],[0,0,0],[0,3,0]] z=0, others sum 4: TRI 4/8, TPI -4/8, rough 3, Riley sqrt(1+9)
# (1,1) [[1,0,2],[0,0,0],[3,0,0]] z=0, others sum 6: TRI 6/8, TPI -6/8, rough 3, Riley sqrt(1+4+9)
# (1,2) [[0,2,0],[0,0,0],[0,0,0]] z=0, others sum 2: TRI 2/8, TPI -2/8, rough 2, Riley sqrt(4)
# (2,0) [[0,0,0],[0,3,0],[0,0,0]] z=3, others all 0: TRI 24/8=3, TPI 3, rough 3, Riley sqrt(8*9)
# (2,1) [[0,0,0],[3,0,0],[0,0,0]] z=0, others sum 3: TRI 3/8, TPI -3/8, rough 3, Riley sqrt(9)
# (2,2) all zeros: 0, 0, 0, 0
TRI5 = np.array([[1, 3 / 8, 17 / 8], [4 / 8, 6 / 8, 2 / 8], [3, 3 / 8, 0]])
TPI5 = np.array([[1, -3 / 8, 11 / 8], [-4 / 8, -6 / 8, -2 / 8], [3, -3 / 8, 0]])
ROUGH5 = np.array([[1, 2, 5], [3, 3, 2], [3, 3, 0]])
RILEY5 = np.sqrt(np.array([[8, 5, 37], [10, 14, 4], [72, 9, 0]]))


def test_hand_computed_5x5_window3():
    np.testing.assert_allclose(F.tri(H5), TRI5, atol=1e-6)
    np.testing.assert_allclose(F.tri(H5, algorithm="riley"), RILEY5, atol=1e-5)
    np.testing.assert_allclose(F.tpi(H5), TPI5, atol=1e-6)
    np.testing.assert_allclose(F.roughness(H5), ROUGH5, atol=1e-6)
    # Stride 2 keeps windows (0,0), (0,2), (2,0), (2,2) of the stride-1 maps.
    np.testing.assert_allclose(F.tri(H5, 3, 2), TRI5[::2, ::2], atol=1e-6)
    np.testing.assert_allclose(F.tpi(H5, 3, 2), TPI5[::2, ::2], atol=1e-6)
    np.testing.assert_allclose(F.roughness(H5, 3, 2), ROUGH5[::2, ::2], atol=1e-6)
    # Descriptors are the map means: TRI (1 + 3/8 + 17/8 + 1/2 + 3/4 + 1/4 + 3 + 3/8 + 0) / 9 = 8.375 / 9,
    # TPI (the mean of |TPI|) (1 + 3/8 + 11/8 + 1/2 + 3/4 + 1/4 + 3 + 3/8 + 0) / 9 = 7.625 / 9,
    # signed TPI (1 - 3/8 + 11/8 - 1/2 - 3/4 - 1/4 + 3 - 3/8 + 0) / 9 = 3.125 / 9, roughness 22 / 9.
    # Descriptors take heights in [0, 1]: H5 / 5, whose features are those of H5 / 5 (all are linear in h).
    d = F.descriptors(H5 / 5, ("tri", "tpi", "tpi_signed", "roughness"), window=3, stride=1)
    np.testing.assert_allclose(d, np.array([8.375 / 9, 7.625 / 9, 3.125 / 9, 22 / 9]) / 5, rtol=1e-6)


def test_even_window_centre_is_k_over_2():
    # A single 1 at (2, 2); window 4 (centre = pixel (2, 2) of the window), stride 1 -> 2 x 2 maps.
    # Window (0,0): centre H[2,2] = 1, 15 zeros -> TRI 15/15 = 1, TPI 1 - 0 = 1.
    # Windows (0,1), (1,0), (1,1): centres H[2,3], H[3,2], H[3,3] = 0, the 1 is among the others
    # -> TRI 1/15, TPI -1/15. Roughness is 1 everywhere (every window contains the 1).
    h = np.zeros((5, 5), np.float32)
    h[2, 2] = 1.0
    assert F.window_centre(4) == 2 and F.window_centre(30) == 15 and F.window_centre(3) == 1
    np.testing.assert_allclose(F.tri(h, 4), [[1, 1 / 15], [1 / 15, 1 / 15]], atol=1e-6)
    np.testing.assert_allclose(F.tpi(h, 4), [[1, -1 / 15], [-1 / 15, -1 / 15]], atol=1e-6)
    np.testing.assert_allclose(F.roughness(h, 4), np.ones((2, 2)), atol=1e-6)


def test_gdaldem_equivalence_window3():
    fx = np.load(DATA / "gdaldem_k3.npz")
    dem = fx["dem"]
    ours = {
        "tri_wilson": F.tri(dem, 3, 1),
        "tri_riley": F.tri(dem, 3, 1, algorithm="riley"),
        "tpi": F.tpi(dem, 3, 1),
        "roughness": F.roughness(dem, 3, 1),
    }
    for name, got in ours.items():
        ref = fx[name]
        assert np.all(ref[0] == fx[name + "_nodata"])  # the border is GDAL's nodata
        interior = ref[1:-1, 1:-1]
        assert got.shape == interior.shape == (10, 10)
        np.testing.assert_allclose(np.asarray(got), interior, atol=2e-6, rtol=0, err_msg=name)
    # Wilson and Riley differ, so the fixture really tells them apart.
    assert np.abs(fx["tri_wilson"][1:-1, 1:-1] - fx["tri_riley"][1:-1, 1:-1]).min() > 0.1


@pytest.mark.parametrize("window,stride", [(3, 1), (4, 1), (5, 3), (7, 2)])
def test_maps_equal_numpy_reference(window, stride):
    h = np.random.default_rng(window * 10 + stride).random((2, 17, 19)).astype(np.float32)
    ref = F.reference_maps(h, window, stride)
    np.testing.assert_allclose(F.tri(h, window, stride), ref["tri"], atol=1e-6)
    np.testing.assert_allclose(F.tri(h, window, stride, "riley"), ref["tri_riley"], atol=2e-6)
    np.testing.assert_allclose(F.tpi(h, window, stride), ref["tpi"], atol=1e-6)
    np.testing.assert_allclose(F.roughness(h, window, stride), ref["roughness"], atol=1e-6)


def test_fast_window30_descriptors_equal_reference():
    # The paper's setting (k = 30, s = 2) on small maps, odd and even sizes (the polyphase split pads odd ones).
    rng = np.random.default_rng(3)
    names = ("tri", "tpi", "roughness", "tri_riley", "tpi_signed")
    f = jax.jit(F.descriptors, static_argnames=("names", "window", "stride"))
    fmap = jax.jit(F.tri, static_argnames=("window", "stride", "algorithm"))
    for shape in [(3, 36, 41), (2, 40, 34)]:
        h = rng.random(shape).astype(np.float32) ** 2
        ref = F.reference_maps(h, 30, 2)
        got = np.asarray(f(h, names=names, window=30, stride=2))
        assert got.shape == (shape[0], 5)
        maps = {**ref, "tpi": np.abs(ref["tpi"]), "tpi_signed": ref["tpi"]}  # the "tpi" descriptor is mean |TPI|
        want = np.stack([maps[n].mean(axis=(1, 2)) for n in names], axis=-1)
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)
    # The per-pixel TRI map (same offset sum) also matches.
    np.testing.assert_allclose(fmap(h, window=30, stride=2), ref["tri"], atol=1e-6)


@pytest.mark.parametrize("unroll", [True, False])
def test_offset_sum_strategies_equal_reference(monkeypatch, unroll):
    # The fully unrolled offset sum (used on GPU/TPU) and the row loop (used on CPU) give the same maps.
    monkeypatch.setattr(F.kernels, "_UNROLL", unroll)
    h = np.random.default_rng(4).random((2, 23, 20)).astype(np.float32)
    ref = F.reference_maps(h, 8, 2)
    f = jax.jit(F.descriptors, static_argnames=("names", "window", "stride"))
    got = f(h, names=("tri", "tri_riley"), window=8, stride=2)
    np.testing.assert_allclose(got, np.stack([ref["tri"].mean((1, 2)), ref["tri_riley"].mean((1, 2))], -1), rtol=1e-6)
    np.testing.assert_allclose(jax.jit(lambda x: F.tri(x, 8, 2))(h), ref["tri"], atol=1e-6)


def test_batch_and_single_agree():
    h = np.random.default_rng(1).random((3, 12, 10)).astype(np.float32)
    for fn in (F.tri, F.tpi, F.roughness):
        fn = jax.jit(fn, static_argnums=(1, 2))
        batch = np.asarray(fn(h, 4, 2))
        assert batch.shape == (3, 5, 4)
        for b in range(3):
            np.testing.assert_allclose(fn(h[b], 4, 2), batch[b], atol=1e-7)
    desc = jax.jit(F.descriptors, static_argnames=("names", "window", "stride"))
    d = np.asarray(desc(h, window=4, stride=2))
    assert d.shape == (3, 3)
    np.testing.assert_allclose(desc(h[1], window=4, stride=2), d[1], atol=1e-7)
    # Descriptors are the means of the maps, in the order of names.
    maps = {"tri": F.reference_maps(h, 4, 2)["tri"], "roughness": np.asarray(batch)}  # batch: roughness maps
    np.testing.assert_allclose(d[:, 0], maps["tri"].mean(axis=(1, 2)), atol=1e-6)
    np.testing.assert_allclose(d[:, 2], maps["roughness"].mean(axis=(1, 2)), atol=1e-6)
    d2 = desc(h, ("roughness", "tri"), window=4, stride=2)
    np.testing.assert_allclose(d2, d[:, [2, 0]], atol=1e-7)


def test_descriptor_registry_takes_any_callable():
    def mean_height(h):  # heightmaps [B, H, W] -> [B]
        return jnp.mean(h, axis=(1, 2))

    F.register_descriptor("test_mean_height", mean_height)
    try:
        assert "test_mean_height" in F.descriptor_names()
        h = np.random.default_rng(2).random((4, 9, 9)).astype(np.float32)
        d = jax.jit(F.descriptors, static_argnames=("names", "window", "stride"))(
            h, names=("tpi", "test_mean_height"), window=3, stride=1
        )
        np.testing.assert_allclose(d[:, 1], h.mean(axis=(1, 2)), rtol=1e-6)
        np.testing.assert_allclose(d[:, 0], np.abs(np.asarray(F.tpi(h))).mean(axis=(1, 2)), atol=1e-6)
        with pytest.raises(ValueError, match="already registered"):
            F.register_descriptor("test_mean_height", mean_height)
        F.register_descriptor("test_bad_shape", lambda h: h[:, 0, :], overwrite=True)
        with pytest.raises(ValueError, match="must return"):
            F.descriptors(h, ("test_bad_shape",))
    finally:
        F.unregister_descriptor("test_mean_height")
        F.unregister_descriptor("test_bad_shape")
    with pytest.raises(ValueError, match="built-in"):
        F.register_descriptor("tri", mean_height)
    # built-ins first, then registered ones (jaxterrain registers "traversability" at import)
    with pytest.raises(ValueError, match=r"valid names: \('tri', 'tri_riley', 'tpi', 'tpi_signed', 'roughness'"):
        F.descriptors(H5, ("tri", "slope"), window=3)


def test_bad_parameters_raise():
    h = np.zeros((2, 8, 10), np.float32)
    with pytest.raises(ValueError, match=r"window must be an integer in \[2, 8\]"):
        F.tri(h, window=1)
    with pytest.raises(ValueError, match=r"window must be an integer in \[2, 8\]"):
        F.tpi(h, window=9)
    with pytest.raises(ValueError, match=r"stride must be an integer in >= 1"):
        F.roughness(h, window=3, stride=0)
    with pytest.raises(ValueError, match="window must be an integer"):
        F.tri(h, window=3.5)
    with pytest.raises(ValueError, match=r"window must be an integer in \[2, 8\]"):
        F.descriptors(h)  # default window 30 > 8
    with pytest.raises(ValueError, match="algorithm must be one of"):
        F.tri(h, algorithm="mean")
    with pytest.raises(ValueError, match=r"heightmaps must have shape \[B, H, W\] or \[H, W\]"):
        F.tri(np.zeros(5))
    with pytest.raises(ValueError, match="robot_height"):
        F.is_traversable(h, robot_height=0.0)
    with pytest.raises(ValueError, match="cell_size"):
        F.is_traversable(h, window=3, scale=TerrainScale(cell_size=-1.0))


def test_no_retrace_when_content_changes():
    traces = []

    def f(h):
        traces.append(1)
        return F.descriptors(h, window=3, stride=1)

    jf = jax.jit(f)
    rng = np.random.default_rng(0)
    a = jf(rng.random((2, 6, 6)).astype(np.float32))
    b = jf(rng.random((2, 6, 6)).astype(np.float32))
    assert len(traces) == 1 and not np.allclose(a, b)


def test_algorithm1_step_of_known_height():
    # A step along the columns: left half 0, right half `v` (heightmap units). Every 26-pixel window straddling the
    # step has max - min = v; in metres v * scale.height. Threshold robot_height / 3.
    scale = TerrainScale(cell_size=0.04, height=0.5)
    robot_height = 1.2  # threshold 0.4 m -> v * 0.5 <= 0.4 <=> v <= 0.8

    def step(v, size=60):
        h = np.zeros((size, size), np.float32)
        h[:, size // 2 :] = v
        return h

    hm = np.stack([step(0.79), step(0.81), step(0.8 - 1e-3), step(0.8 + 1e-3), np.zeros((60, 60), np.float32)])
    ok = np.asarray(F.is_traversable(hm, robot_height=robot_height, window=26, scale=scale))
    assert ok.dtype == bool and ok.tolist() == [True, False, True, False, True]
    # A taller metre scale makes the same map impassable: 0.79 * 1.0 m > 0.4 m.
    assert not bool(F.is_traversable(step(0.79), robot_height=robot_height, scale=TerrainScale(height=1.0)))
    # At the default scale (1.0 m): a 0.5 step (0.5 m) passes the default humanoid (1.57 / 3 = 0.523 m), 0.55 fails.
    assert F.HUMANOID_HEIGHT == pytest.approx(1.57) and bool(F.is_traversable(step(0.5)))
    assert not bool(F.is_traversable(step(0.55)))
    # Every valid window is checked, including the last row of windows (the paper's loop stops one short).
    h = np.zeros((60, 60), np.float32)
    h[-1, 3] = 0.9
    assert not bool(F.is_traversable(h, robot_height=robot_height, scale=scale))
    np.testing.assert_allclose(F.max_window_range(h), 0.9)
    # A gentle ramp rising 0.01 per pixel: any 26 window spans 25 * 0.01 = 0.25 -> 0.125 m, well under 0.4 m,
    # although the whole map rises 0.59 (0.295 m) ... and more than the threshold on a longer map.
    ramp = np.tile(np.arange(60, dtype=np.float32) * 0.01, (60, 1))
    np.testing.assert_allclose(F.max_window_range(ramp), 0.25, atol=1e-6)
    assert bool(F.is_traversable(ramp, robot_height=robot_height, scale=scale))
    # jit-able with the terrain as data.
    j = jax.jit(lambda x: F.is_traversable(x, robot_height=robot_height, scale=scale))
    assert np.asarray(j(hm)).tolist() == [True, False, True, False, True]


def test_large_batches_are_chunked_without_changing_values(monkeypatch):
    h = np.random.default_rng(5).random((7, 8, 9)).astype(np.float32)
    names = ("tri", "tpi", "roughness")
    f = jax.jit(F.descriptors, static_argnums=(1, 2, 3))
    whole = np.asarray(f(h, names, 4, 2))
    monkeypatch.setattr(F.kernels, "_MAX_CHUNK_ELEMENTS", 3 * 8 * 9)  # chunks of 3 maps: 3 + 3 + remainder 1
    chunked = np.asarray(jax.jit(F.descriptors, static_argnums=(1, 2, 3))(h, names, 4, 2))
    assert chunked.shape == (7, 3)
    np.testing.assert_allclose(chunked, whole, atol=1e-6)


# ---------------------------------------------------------------------------------------------------------------
# Vertical faces: step_heights, faces, max_step (issue 64)
# ---------------------------------------------------------------------------------------------------------------


def _step_map(value: float, n: int = 20, column: int = 10) -> np.ndarray:
    """``n x n``: 0 left of ``column``, ``value`` from it on (a riser between columns column - 1 and column)."""
    h = np.zeros((n, n), np.float32)
    h[:, column:] = value
    return h


def test_vertical_faces_of_a_single_step_of_known_height():
    # A 0.3 step between columns 9 and 10 of a 20 x 20 map: both columns have step 0.3, every other pixel 0.
    h = _step_map(0.3)
    s = np.asarray(F.step_heights(h))
    want = np.zeros((20, 20))
    want[:, 9:11] = 0.3
    np.testing.assert_allclose(s, want, atol=1e-7)
    # Window 4, stride 2: 9 x 9 windows, window (i, j) covers columns 2j .. 2j + 3; column 9 lies in j = 3, 4,
    # column 10 in j = 4, 5. faces = face pixels / 16: 4 / 16 at j = 3 and 5, 8 / 16 at j = 4; max_step 0.3 there.
    faces_row = np.array([0, 0, 0, 0.25, 0.5, 0.25, 0, 0, 0])
    np.testing.assert_allclose(F.faces(h, 4, 2), np.tile(faces_row, (9, 1)), atol=1e-7)
    np.testing.assert_allclose(F.max_step(h, 4, 2), np.tile([0, 0, 0, 0.3, 0.3, 0.3, 0, 0, 0], (9, 1)), atol=1e-7)
    # The descriptors are the means over the windows: 1 / 9 and 0.3 * 3 / 9; the same for the step turned by 90
    # degrees (a face along the rows).
    d = np.asarray(F.descriptors(np.stack([h, h.T]), names=("faces", "max_step"), window=4, stride=2))
    np.testing.assert_allclose(d, [[1 / 9, 0.1], [1 / 9, 0.1]], atol=1e-7)
    # A step under FACE_THRESHOLD (0.05) is no face, and max_step still reads its height.
    low = np.asarray(F.descriptors(_step_map(0.04), names=("faces", "max_step"), window=4, stride=2))
    np.testing.assert_allclose(low, [0.0, 0.04 * 3 / 9], atol=1e-7)
    # just above / below the threshold; a custom threshold
    assert float(F.faces(_step_map(0.051), 4, 2).max()) == 0.5 and float(F.faces(_step_map(0.049), 4, 2).max()) == 0
    assert float(F.faces(_step_map(0.3), 4, 2, threshold=0.31).max()) == 0.0
    # Down or up, the same.
    np.testing.assert_allclose(F.max_step(0.3 - h, 4, 2), F.max_step(h, 4, 2), atol=1e-7)


def test_vertical_faces_of_flat_and_ramp_maps():
    # Flat at any height: no face, no step.
    flat = np.full((2, 24, 24), 0.7, np.float32)
    np.testing.assert_array_equal(F.descriptors(flat, names=("faces", "max_step"), window=6, stride=3), 0.0)
    # A smooth ramp rising 0.02 per pixel along x (grade 0.5 at 4 cm pixels and 1 m per unit, the suite's steepest
    # slope): no face anywhere, and the largest step of every window is exactly the rise per pixel.
    ramp = np.tile(np.arange(24, dtype=np.float32) * 0.02, (24, 1))
    np.testing.assert_allclose(F.step_heights(ramp), 0.02, atol=1e-6)
    d = np.asarray(F.descriptors(ramp, names=("faces", "max_step"), window=6, stride=3))
    np.testing.assert_allclose(d, [0.0, 0.02], atol=1e-6)
    # A cliff at the end of the same ramp (0.2 extra between columns 19 and 20) shows up in both.
    cliff = ramp.copy()
    cliff[:, 20:] += 0.2
    assert float(F.faces(cliff, 6, 3).max()) > 0 and float(F.max_step(cliff, 6, 3).max()) == pytest.approx(0.22)


@pytest.mark.parametrize("window,stride", [(3, 1), (5, 3), (8, 2), (30, 2)])
def test_vertical_faces_equal_numpy_reference(window, stride):
    # Random maps (steps of all sizes around the threshold) against the NumPy loops of reference_maps; jitted
    # descriptors against the means of the reference maps.
    rng = np.random.default_rng(window + stride)
    h = (rng.random((2, 33, 37)) * 0.15).astype(np.float32)
    h[:, :, 20:] += 0.3
    ref = F.reference_maps(h, window, stride)
    np.testing.assert_allclose(F.faces(h, window, stride), ref["faces"], atol=1e-6)
    np.testing.assert_allclose(F.max_step(h, window, stride), ref["max_step"], atol=1e-6)
    f = jax.jit(F.descriptors, static_argnames=("names", "window", "stride"))
    got = np.asarray(f(h, names=("faces", "max_step", "tpi"), window=window, stride=stride))
    np.testing.assert_allclose(got[:, :2], np.stack([ref["faces"].mean((1, 2)), ref["max_step"].mean((1, 2))], -1),
                               rtol=1e-5, atol=1e-6)
    assert 0 < got[:, 0].min() and got[:, 0].max() < 1
