"""Your own terrains (``jaxterrain.suite.folder``): a folder of PNG / GeoTIFF / .npy / .npz heightmaps read into the
walker's terrains, and the one-line refusals of bad folders. No physics: every test here is numpy."""

import numpy as np
import pytest
from PIL import Image
from terrain_tiles import write_tiles

from jaxterrain import suite
from jaxterrain.suite import folder as F
from jaxterrain.terrain import TerrainScale


def test_a_folder_reads_each_file_as_one_square_terrain_in_metres_with_flat_start_strips(tmp_path):
    d = write_tiles(tmp_path / "tiles")
    (d / "notes.txt").write_text("not a heightmap")
    f = suite.load_folder(d, height=0.5)
    assert f.names == ("a_ramp.npy", "b_grey8.png", "c_grey16.png", "d_dem.tif") and f.skipped == ("notes.txt",)
    assert f.heightmaps.shape == (4, 256, 256) and f.heightmaps.dtype == np.float32
    # images: grey 0..1 -> 0..0.5 m; metre files rescaled to span [0, 0.5] m with a height given
    np.testing.assert_allclose(f.relief, [0.5, 0.5, 0.5, 0.5], rtol=1e-5)
    strip = F.edge_distance(256, TerrainScale()) < F.START_STRIP
    assert np.all(f.heightmaps[:, strip] == 0.0) and np.all(f.heightmaps >= 0) and np.all(f.heightmaps <= 0.5 + 1e-6)
    # the centred square of a 40 x 50 ramp along x: the middle of the terrain is the middle of the ramp
    mid = f.heightmaps[1, 128, 128]
    assert abs(mid - 0.25) < 0.02, mid
    # without a height: the .npy keeps its metres (0.3 m), images take 1 m of full grey, the 20 m DEM is refused
    with pytest.raises(ValueError, match=r"terrain .*d_dem.tif: its relief is 39.97 m, more than the walker's 1 m"):
        suite.load_folder(d)
    (d / "d_dem.tif").unlink()
    g = suite.load_folder(d)
    np.testing.assert_allclose(g.relief, [0.3, 1.0, 1.0], rtol=1e-5)


def test_the_digest_names_the_files_and_how_they_were_read(tmp_path):
    d = write_tiles(tmp_path / "tiles")
    a, b = suite.load_folder(d, 0.5), suite.load_folder(d, 0.5)
    assert a.digest == b.digest and len(a.files_sha256) == 4
    assert suite.load_folder(d, 0.4).digest != a.digest
    np.save(d / "a_ramp.npy", np.zeros((40, 50), np.float32))
    assert suite.load_folder(d, 0.5).digest != a.digest


def test_a_folder_is_a_suite_of_one_family_per_file_and_a_bank_ranked_by_hardness(tmp_path):
    f = suite.load_folder(write_tiles(tmp_path / "tiles"), 0.5, side=64)
    s = suite.folder_suite(f)
    assert list(s.family) == list(f.names) and s.heightmaps.shape == (4, 64, 64) and set(s.level) == {0}
    np.testing.assert_array_equal(s.heightmaps, f.heightmaps)  # metres at the 1 m height scale: the same numbers
    bank = suite.folder_bank(f, suite.name_order(f))
    np.testing.assert_array_equal(np.asarray(bank.distance), [0, 1, 2, 3])
    np.testing.assert_array_equal(np.asarray(bank.source), [0, 1, 2, 3])
    # difficulty: the terrain the base policy walks farthest on first, ties in name order
    np.testing.assert_array_equal(suite.difficulty_order([0.2, 0.9, 0.2, 1.0]), [2, 1, 3, 0])


@pytest.mark.parametrize("make, needle", [
    (lambda d: None, "no heightmap files in it"),
    (lambda d: np.save(d / "x.npy", np.zeros((4, 4, 3))), "x.npy: a heightmap is a 2-D array"),
    (lambda d: np.save(d / "x.npy", np.zeros(9)), "x.npy: a heightmap is a 2-D array"),
    (lambda d: np.save(d / "x.npy", np.zeros((1, 9)) + np.arange(9)), "x.npy: 1 x 9 cells; each side must be >= 2"),
    (lambda d: np.save(d / "x.npy", np.where(np.eye(5) > 0, np.nan, 0.1)), "x.npy: 5 NaN / infinite / no-data"),
    (lambda d: (d / "x.png").write_bytes(b"not a png"), "x.png: unreadable .png file"),
    (lambda d: (d / "x.tif").write_bytes(b"not a tiff"), "x.tif: unreadable .tif file"),
    (lambda d: Image.new("RGB", (8, 8)).save(d / "x.png"), "x.png: a PNG heightmap must be 8- or 16-bit greyscale"),
])
def test_a_bad_folder_is_refused_in_one_line_naming_the_file(tmp_path, make, needle):
    d = tmp_path / "bad"
    d.mkdir()
    make(d)
    with pytest.raises(ValueError) as err:
        suite.load_folder(d)
    assert needle in str(err.value) and "\n" not in str(err.value)


def test_a_missing_folder_and_a_height_out_of_range_are_refused(tmp_path):
    with pytest.raises(ValueError, match="no such folder"):
        suite.load_folder(tmp_path / "missing")
    for height in (0.0, -1.0, 1.5, float("nan"), "1"):
        with pytest.raises(ValueError, match=r"terrain height must be a number of metres in \(0, 1\]"):
            suite.load_folder(write_tiles(tmp_path / "t"), height)
