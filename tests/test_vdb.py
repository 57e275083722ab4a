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


# --- in scenes -------------------------------------------------------------------------------------

def medium_scene(folder, medium_body, kind="heterogeneous"):
    path = folder / f"scene_{abs(hash(medium_body))}.xml"
    path.write_text(f'''<scene version="3.0.0">
    <medium type="{kind}" id="m">{medium_body}</medium>
    <sensor type="perspective"><ref id="m"/><film type="hdrfilm"><integer name="width" value="4"/>
        <integer name="height" value="4"/></film></sensor>
</scene>''')
    return path


def vdb_volume_xml(name, filename, grid):
    return (f'<volume type="volcl_vdb" name="{name}"><string name="filename" value="{filename}"/>'
            f'<string name="grid" value="{grid}"/></volume>')


def test_scene_reads_vdb_and_nvdb_volumes_alike(files):
    from volcl.scene import load
    d = files["d"]
    a = load(medium_scene(d, vdb_volume_xml("sigma_t", "grids.vdb", "density"))).camera.medium.sigma_t
    assert a.kind == "sparse" and a.grid_name == "density"
    check_density(a.sparse, files)
    if shutil.which("nanovdb_convert"):
        b = load(medium_scene(d, vdb_volume_xml("sigma_t", "grids.nvdb", "density"))).camera.medium.sigma_t
        np.testing.assert_array_equal(a.sparse.dense(), b.sparse.dense())
        np.testing.assert_allclose(a.to_world, b.to_world, rtol=1e-12, atol=1e-12)


def test_scene_errors_name_the_file_and_the_grids(files):
    from volcl.scene import load
    d = files["d"]
    with pytest.raises(VolclError) as exc:
        load(medium_scene(d, vdb_volume_xml("sigma_t", "grids.vdb", "smoke")))
    msg = str(exc.value)
    assert "no grid named 'smoke'" in msg and "'density' (float)" in msg and "'Cd' (vec3s)" in msg
    assert ".xml:2: <string>" in msg, "file, line and element"
    with pytest.raises(VolclError, match=r"'volcl_temperature' needs a float grid, but grid 'Cd' of .*grids.vdb "
                                         r"holds vec3s values"):
        load(medium_scene(d, vdb_volume_xml("sigma_t", "grids.vdb", "density")
                          + vdb_volume_xml("volcl_temperature", "grids.vdb", "Cd")))
    with pytest.raises(VolclError, match=r"'sigma_t' needs a float grid"):
        load(medium_scene(d, vdb_volume_xml("sigma_t", "grids.vdb", "Cd")))


def test_grid_too_large_to_read_is_refused(files, monkeypatch):
    monkeypatch.setattr(vdb, "MAX_REGION_VOXELS", 4096)
    vdb._read.cache_clear()
    try:
        with pytest.raises(VolclError, match=r"grid 'density' of .*grids.vdb spans \d+x\d+x\d+ voxels .*more "
                                             r"than volcl reads from one grid"):
            vdb.read(files["vdb"], "density")
    finally:
        vdb._read.cache_clear()


def test_constant_temperature_in_a_homogeneous_medium(tmp_path):
    from volcl import blackbody
    from volcl.scene import load
    body = ('<rgb name="sigma_t" value="1"/><rgb name="albedo" value="0.2"/>'
            '<float name="volcl_temperature" value="1900"/><float name="volcl_temperature_offset" value="100"/>'
            '<float name="volcl_temperature_scale" value="1.5"/><float name="volcl_emission_scale" value="4"/>')
    m = load(medium_scene(tmp_path, body, kind="homogeneous")).camera.medium
    np.testing.assert_allclose(m.radiance, 4 * blackbody.rgb(2700.0), rtol=1e-12)
