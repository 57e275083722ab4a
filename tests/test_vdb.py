"""Reading OpenVDB and NanoVDB grids (volcl/vdb.py): files written here by OpenVDB (and converted with
NanoVDB's nanovdb_convert) read back as the numpy arrays they were made from, including tiles,
inactive tiles with values of their own and negative index bounds; and the errors for bad files."""
import shutil

import numpy as np
import pytest

from volcl import vdb
from volcl.errors import VolclError

ok, why = vdb.available()
pytestmark = pytest.mark.skipif(not ok, reason=f"OpenVDB's Python module is not available: {why}")
needs_nanovdb = pytest.mark.skipif(shutil.which("nanovdb_convert") is None, reason="no nanovdb_convert")


def expected_dense(sg, pieces, background):
    """The padded box of `sg` (z, y, x, c) filled from pieces [(ijk, array [x][y][z][c])] and tiles."""
    lo, hi = sg.index_box()
    n = hi - lo + 1
    out = np.empty((n[2], n[1], n[0], sg.channels), np.float32)
    out[...] = background
    for ijk, a in pieces:
        a = a.reshape(a.shape[:3] + (-1,))
        big = np.full((n[0] + 2 * a.shape[0], n[1] + 2 * a.shape[1], n[2] + 2 * a.shape[2], a.shape[3]),
                      background, np.float32)
        o = np.asarray(ijk) - lo + a.shape[:3]
        big[o[0]:o[0] + a.shape[0], o[1]:o[1] + a.shape[1], o[2]:o[2] + a.shape[2]] = a
        inside = big[a.shape[0]:a.shape[0] + n[0], a.shape[1]:a.shape[1] + n[1], a.shape[2]:a.shape[2] + n[2]]
        # whatever of the array lies outside the box is background
        assert np.sum(big != background) == np.sum(inside != background)
        mask = inside.transpose(2, 1, 0, 3) != background
        out[mask] = inside.transpose(2, 1, 0, 3)[mask]
    return out


def cloud():
    rng = np.random.default_rng(1)
    a = np.zeros((30, 21, 26), np.float32)
    a[3:20, 2:15, 5:22] = rng.random((17, 13, 17)).astype(np.float32) + 0.1
    return a


HAZE = np.random.default_rng(3).random((12, 12, 12)).astype(np.float32)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """One .vdb with a float cloud at negative index bounds, tiles active and inactive (with values
    of their own), a vec3 grid and a grid with a non-zero background; and its .nvdb conversion."""
    d = tmp_path_factory.mktemp("vdb")
    density = cloud()
    colour = np.random.default_rng(2).random((9, 10, 11, 3)).astype(np.float32)
    m = np.diag([0.1, 0.2, 0.05, 1.0])
    m[:3, 3] = (1.0, -2.0, 0.5)
    grids = [
        dict(name="density", array=density, ijk=(-37, -5, 3), index_to_world=m,
             tiles=[((-64, 16, 16), (-49, 31, 31), 0.5, False),     # inactive tile, its own value
                    ((-80, -8, 0), (-73, -1, 7), 0.25, True)]),     # active tile (8^3)
        dict(name="Cd", array=colour, ijk=(-4, -3, -2), background=[0.0, 0.0, 0.0]),
        dict(name="haze", array=HAZE, ijk=(100, 200, 300), background=0.125),
    ]
    path = d / "grids.vdb"
    vdb.write(str(path), grids)
    nvdb = d / "grids.nvdb"
    if shutil.which("nanovdb_convert"):
        vdb.write(str(nvdb), grids)
    return dict(vdb=str(path), nvdb=str(nvdb), density=density, colour=colour, m=m, d=d)


def check_density(sg, files):
    assert sg.channels == 1 and sg.value_type == "float"
    tile_inactive = np.full((16, 16, 16), 0.5, np.float32)
    tile_active = np.full((8, 8, 8), 0.25, np.float32)
    want = expected_dense(sg, [((-37, -5, 3), files["density"]), ((-64, 16, 16), tile_inactive),
                               ((-80, -8, 0), tile_active)], 0.0)
    assert sg.dense().shape == want.shape
    np.testing.assert_array_equal(sg.dense(), want)
    # the brick index reaches below zero on every axis and the padding is background
    assert np.all(sg.index_box()[0] < 0)
    np.testing.assert_allclose(sg.index_to_world, files["m"], rtol=1e-12, atol=1e-12)


def test_float_grid_with_tiles_and_negative_bounds(files):
    check_density(vdb.read(files["vdb"], "density"), files)


@needs_nanovdb
def test_nanovdb_grid_reads_the_same_values(files):
    check_density(vdb.read(files["nvdb"], "density"), files)
    sg = vdb.read(files["nvdb"], "Cd")
    np.testing.assert_array_equal(sg.dense(), expected_dense(sg, [((-4, -3, -2), files["colour"])], 0.0))


def test_vector_grid_and_background(files):
    sg = vdb.read(files["vdb"], "Cd")
    assert sg.channels == 3
    np.testing.assert_array_equal(sg.dense(), expected_dense(sg, [((-4, -3, -2), files["colour"])], 0.0))
    haze = vdb.read(files["vdb"], "haze")
    assert haze.background[0] == np.float32(0.125)
    np.testing.assert_array_equal(haze.dense(), expected_dense(haze, [((100, 200, 300), HAZE)],
                                                               0.125))


def test_bricks_are_sparse(files):
    """Only bricks with more than one value are stored whole; tiles are one value each."""
    sg = vdb.read(files["vdb"], "density")
    assert len(sg.tile_coords) == 8 + 1             # the 16^3 inactive tile, the 8^3 active one
    nb = sg.padded_counts()
    assert len(sg.coords) < 0.1 * np.prod(nb)
    assert sg.stored_bytes() < 0.2 * np.prod(nb) * 512 * 4


def test_unit_cube_maps_voxel_centres_to_the_grid_transform(files):
    """Voxel i of the padded box is centred at (i + 0.5) / n of the unit cube, and there the grid's
    own transform places index lo + i."""
    sg = vdb.read(files["vdb"], "density")
    lo, hi = sg.index_box()
    n = hi - lo + 1
    i = np.array([3, 7, 11])
    u = np.append((i + 0.5) / n, 1.0)
    want = files["m"] @ np.append(lo + i, 1.0)
    np.testing.assert_allclose(sg.unit_to_world() @ u, want, rtol=1e-12, atol=1e-12)


def test_missing_grid_lists_the_grids(files):
    with pytest.raises(VolclError) as exc:
        vdb.read(files["vdb"], "temperature")
    msg = str(exc.value)
    assert "no grid named 'temperature'" in msg
    for name in ("'density' (float)", "'Cd' (vec3s)", "'haze' (float)"):
        assert name in msg


def test_not_a_vdb_file(tmp_path):
    bad = tmp_path / "smoke.vdb"
    bad.write_bytes(b"VOL\x03" + bytes(64))
    with pytest.raises(VolclError, match="is not an OpenVDB file"):
        vdb.read(str(bad), "density")
    nbad = tmp_path / "smoke.nvdb"
    nbad.write_bytes(b" BDV" + bytes(64))
    with pytest.raises(VolclError, match="is not a NanoVDB file"):
        vdb.read(str(nbad), "density")
    truncated = tmp_path / "cut.vdb"
    truncated.write_bytes(b"\x20\x42\x44\x56" + bytes(20))
    with pytest.raises(VolclError, match="holds no grids"):
        vdb.read(str(truncated), "density")
