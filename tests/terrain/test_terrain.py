"""Physical scale, MuJoCo hfield geometry and exports (jaxterrain.terrain)."""

import numpy as np
import pytest

from jaxterrain import terrain as T


def test_terrain_scale_defaults_and_validation():
    s = T.TerrainScale()
    assert (s.cell_size, s.height) == (0.04, 1.0)
    assert T.TerrainScale(0.02, 2.0) == (0.02, 2.0)
    for bad in (0.0, -0.1, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="cell_size"):
            T.TerrainScale(cell_size=bad)
        with pytest.raises(ValueError, match="height"):
            T.TerrainScale(height=bad)
    with pytest.raises(ValueError, match="TerrainScale"):
        T.to_metres(np.zeros((2, 2)), scale=(0.04, 0.5))
    h = np.array([[0.0, 0.25], [0.5, 1.0]], np.float32)
    np.testing.assert_allclose(T.to_metres(h, T.TerrainScale(height=0.8)), [[0.0, 0.2], [0.4, 0.8]], rtol=1e-7)
    np.testing.assert_allclose(T.to_metres(np.stack([h, h])), 1.0 * np.stack([h, h]), rtol=1e-7)  # default 1.0 m


def test_terrain_scale_is_a_pytree():
    import jax

    s = T.TerrainScale(0.05, 0.7)
    leaves, tree = jax.tree_util.tree_flatten(s)
    assert leaves == [0.05, 0.7]
    assert jax.tree_util.tree_unflatten(tree, leaves) == s
    out = jax.jit(lambda sc, h: T.to_metres(h, sc))(s, np.ones((2, 2), np.float32))
    np.testing.assert_allclose(out, 0.7, rtol=1e-6)


def test_hfield_size():
    # 256 samples 0.04 m apart span 255 * 0.04 = 10.2 m -> radius 5.1; elevation = metres per heightmap unit.
    assert T.hfield_size((256, 256)) == pytest.approx((5.1, 5.1, 1.0, 0.1))
    # [B, H, W] shapes and non-square maps: radius_x follows the columns (W), radius_y the rows (H).
    assert T.hfield_size((8, 11, 21), T.TerrainScale(0.1, 2.0), base=0.3) == pytest.approx((1.0, 0.5, 2.0, 0.3))
    with pytest.raises(ValueError, match="shape"):
        T.hfield_size((1, 5))
    with pytest.raises(ValueError, match="base"):
        T.hfield_size((5, 5), base=0.0)


def test_png_round_trip_16bit(tmp_path):
    from PIL import Image

    h = np.random.default_rng(0).random((17, 23)).astype(np.float32)
    h[0, 0], h[0, 1] = 0.0, 1.0
    p = T.save_png(tmp_path / "t.png", h)
    with Image.open(p) as img:
        assert img.mode == "I;16" and img.size == (23, 17)
        raw = np.array(img)
    np.testing.assert_array_equal(raw, np.round(h.astype(np.float64) * 65535).astype(np.uint16))
    back = T.load_png(p)
    assert back.dtype == np.float32 and back.shape == h.shape
    assert np.abs(back - h).max() <= 0.5 / 65535 + 1e-7
    assert back[0, 0] == 0.0 and back[0, 1] == 1.0
    assert [f.name for f in tmp_path.iterdir()] == ["t.png"]  # no temporary files left behind
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        T.save_png(tmp_path / "bad.png", h + 0.5)
    with pytest.raises(ValueError, match=r"\[H, W\]"):
        T.save_png(tmp_path / "bad.png", np.stack([h, h]))


def test_npy_round_trip_exact(tmp_path):
    h = np.random.default_rng(1).normal(size=(3, 9, 7)).astype(np.float32)
    np.testing.assert_array_equal(T.load_npy(T.save_npy(tmp_path / "b.npy", h)), h)
    np.testing.assert_array_equal(T.load_npy(T.save_npy(tmp_path / "s.npy", h[0])), h[0])


@pytest.mark.parametrize("inline", [False, True])
def test_mjcf_loads_in_mujoco_with_matching_heights(tmp_path, inline):
    import mujoco  # a runtime dependency: fail, never skip, if it is missing
    rng = np.random.default_rng(2)
    h = (0.2 + 0.6 * rng.random((12, 15))).astype(np.float32)  # min > 0: exercises the re-normalisation offset
    scale = T.TerrainScale(cell_size=0.1, height=2.0)
    xml = T.save_mjcf(tmp_path / "terrain.xml", h, scale, inline=inline)
    m = mujoco.MjModel.from_xml_path(str(xml))
    assert (m.nhfield, int(m.hfield_nrow[0]), int(m.hfield_ncol[0])) == (1, 12, 15)
    rx, ry, ez, base = m.hfield_size[0]
    assert (rx, ry, base) == pytest.approx((0.7, 0.55, 0.1))  # (15-1)*0.1/2, (12-1)*0.1/2
    geom = m.geom("terrain")
    z0 = m.geom_pos[geom.id][2]
    # Loaded surface height = data * size_z + geom z = heightmap * scale.height.
    heights = m.hfield_data.reshape(12, 15) * ez + z0
    np.testing.assert_allclose(heights, h * 2.0, atol=1e-5)
    # Orientation: a ray cast down onto sample (i, j) at x = -rx + j * cell, y = -ry + i * cell hits h[i, j] * 2.
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    geomid = np.zeros(1, np.int32)
    for i, j in [(0, 0), (0, 14), (11, 0), (5, 7), (11, 14)]:
        x, y = -rx + j * 0.1, -ry + i * 0.1
        x, y = x - 1e-6 * np.sign(x), y - 1e-6 * np.sign(y)  # a ray exactly on the outer edge misses
        dist = mujoco.mj_ray(m, d, np.array([x, y, 10.0]), np.array([0.0, 0.0, -1.0]), None, 1, -1, geomid)
        assert 10.0 - dist == pytest.approx(2.0 * h[i, j], abs=1e-3), (i, j)
    files = sorted(f.name for f in tmp_path.iterdir())
    assert files == (["terrain.xml"] if inline else ["terrain.hfield.bin", "terrain.xml"])


def test_mjcf_flat_map(tmp_path):
    import mujoco  # a runtime dependency: fail, never skip, if it is missing
    h = np.full((6, 6), 0.3, np.float32)
    m = mujoco.MjModel.from_xml_path(str(T.save_mjcf(tmp_path / "flat.xml", h)))
    heights = m.hfield_data.reshape(6, 6) * m.hfield_size[0][2] + m.geom_pos[m.geom("terrain").id][2]
    np.testing.assert_allclose(heights, 0.3 * T.TerrainScale().height, atol=1e-6)
    m = mujoco.MjModel.from_xml_path(str(T.save_mjcf(tmp_path / "flat2.xml", h, T.TerrainScale(height=0.5))))
    heights = m.hfield_data.reshape(6, 6) * m.hfield_size[0][2] + m.geom_pos[m.geom("terrain").id][2]
    np.testing.assert_allclose(heights, 0.15, atol=1e-6)
    with pytest.raises(ValueError, match="finite"):
        T.save_mjcf(tmp_path / "nan.xml", np.full((4, 4), np.nan))


@pytest.mark.parametrize("fmt", ["obj", "stl"])
def test_mesh_round_trip_through_trimesh(tmp_path, fmt):
    import trimesh

    rng = np.random.default_rng(3)
    h = rng.random((9, 13)).astype(np.float32)
    scale = T.TerrainScale(cell_size=0.05, height=2.0)
    path = (T.save_obj if fmt == "obj" else T.save_stl)(tmp_path / f"t.{fmt}", h, scale)
    mesh = trimesh.load(path, file_type=fmt, force="mesh")  # STL stores triangles: the loader merges shared corners
    assert len(mesh.vertices) == 9 * 13  # one vertex per pixel
    assert len(mesh.faces) == 2 * 8 * 12  # two triangles per cell
    rx, ry, _, _ = T.hfield_size(h.shape, scale)
    # Each vertex sits at its sample's (x, y) (the hfield's placement) with z = heightmap * height, in metres.
    j = np.round((mesh.vertices[:, 0] + rx) / 0.05).astype(int)
    i = np.round((mesh.vertices[:, 1] + ry) / 0.05).astype(int)
    assert sorted(zip(i.tolist(), j.tolist())) == [(a, b) for a in range(9) for b in range(13)]
    np.testing.assert_allclose(mesh.vertices[:, 2], 2.0 * h[i, j], atol=1e-5)
    np.testing.assert_allclose(mesh.vertices[:, 0], -rx + j * 0.05, atol=1e-6)
    assert mesh.bounds[0][:2] == pytest.approx((-rx, -ry)) and mesh.bounds[1][:2] == pytest.approx((rx, ry))
    assert np.all(mesh.face_normals[:, 2] > 0)  # facing up
    if fmt == "obj":  # OBJ keeps the vertex order: vertex i * W + j is sample (i, j)
        np.testing.assert_allclose(mesh.vertices[:, 2], 2.0 * h.ravel(), atol=1e-5)


def test_to_mesh_vertices_faces_and_area():
    h = np.zeros((4, 6), np.float32)
    mesh = T.to_mesh(h, T.TerrainScale(cell_size=0.5))
    assert mesh.vertices.shape == (24, 3) and mesh.faces.shape == (30, 3)
    assert mesh.area == pytest.approx(3 * 0.5 * 5 * 0.5)  # a flat 1.5 m x 2.5 m rectangle
    v, f = T.mesh_arrays(np.full((2, 2), 0.25), T.TerrainScale(1.0, 4.0))
    np.testing.assert_allclose(v, [[-0.5, -0.5, 1.0], [0.5, -0.5, 1.0], [-0.5, 0.5, 1.0], [0.5, 0.5, 1.0]])
    assert f.tolist() == [[0, 1, 3], [0, 3, 2]]
    with pytest.raises(ValueError, match="finite"):
        T.to_mesh(np.full((3, 3), np.nan))
    with pytest.raises(ValueError, match="shape"):
        T.to_mesh(np.zeros((1, 3)))
