"""Sparse (brick) grids on the device: lookups equal the dense grid of the same padded box, majorant
bricks bound every lookup, and the layout's size is what it claims."""
import numpy as np
import pytest

from conftest import run_kernel
from scenebuild import grid
from volcl import grids, vdb
from volcl.scene.model import Volume, rgb

PROGRAM = "grid_tests.cl"


def cloud(channels, seed=5, background=0.0):
    """A blob in a larger box, with a constant 8^3-aligned block (a tile) and empty space."""
    rng = np.random.default_rng(seed)
    a = np.full((29, 23, 37, channels), background, np.float32)
    z, y, x = np.mgrid[0:29, 0:23, 0:37]
    inside = (x - 15) ** 2 / 120 + (y - 11) ** 2 / 60 + (z - 14) ** 2 / 80 < 1
    a[inside] = rng.random((inside.sum(), channels)).astype(np.float32) * 3
    a[16:24, 0:8, 24:32] = 1.5          # aligned to bricks once placed at ijk below
    return a


def sparse_volume(sg, filter="trilinear"):
    return Volume("sparse", value=rgb(0.0), to_world=sg.unit_to_world(), filter=filter, sparse=sg,
                  grid_name=sg.name)


@pytest.mark.parametrize("filter", ["trilinear", "nearest"])
@pytest.mark.parametrize("channels", [1, 3])
def test_sparse_lookups_equal_the_dense_box(cl_env, test_program, filter, channels):
    sg = vdb.from_dense(cloud(channels), ijk=(-24, 8, -16))
    assert len(sg.tile_coords) >= 1 and len(sg.coords) > 0
    packer = grids.GridPacker()
    packer.add(sparse_volume(sg, filter))
    desc, flat = packer.arrays()
    dense = sg.dense()
    rng = np.random.default_rng(9)
    res = np.array(dense.shape[2::-1])
    pts = np.concatenate([
        rng.uniform(-0.2, 1.2, (6000, 3)),
        (rng.integers(0, 1000, (1000, 3)) % res + 0.5) / res,          # voxel centres
        rng.integers(0, 2 * res.max() + 1, (1000, 3)) / (2 * res),     # voxel faces and brick edges
    ]).astype(np.float32)
    (out,) = run_kernel(cl_env, test_program(PROGRAM), "lookups", len(pts), [(np.float32, (3,))], np.int32(0),
                        inputs=[desc, flat, pts])
    ref = grids.lookup(dense, filter, pts)
    ref = np.repeat(ref, 3, axis=1) if channels == 1 else ref
    assert np.allclose(out, ref, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("filter", ["trilinear", "nearest"])
def test_brick_majorants_bound_every_lookup(filter):
    sg = vdb.from_dense(cloud(3), ijk=(5, -3, 0), background=0.0)
    scale = np.float32(1.7)
    dense = sg.dense() * scale          # the values the device holds: scaled in float32
    maj = grids.sparse_majorants(sg, scale)
    nb = sg.padded_counts()
    assert maj.shape == tuple(nb[::-1])
    rng = np.random.default_rng(2)
    pts = np.concatenate([rng.random((60000, 3)),
                          rng.integers(0, 16 * nb.max() + 1, (20000, 3)) / (16 * nb)]).clip(0, 1)
    value = grids.lookup(dense, filter, pts).max(axis=1)
    g = pts * nb
    for shift in (0.0, -1e-6, 1e-6):
        c = np.clip(np.floor(g + shift), 0, nb - 1).astype(int)
        assert (value <= maj[c[:, 2], c[:, 1], c[:, 0]]).all()
    # tight: the dense majorant of the same cells, which reads the same supports, to the bit (so a
    # sparse grid and its dense box render the same image: tests/test_render_vdb.py)
    dense_maj = grids.majorant_grid(dense, filter, tuple(nb))
    np.testing.assert_array_equal(maj, dense_maj)
    assert (maj == 0).mean() > 0.3, "empty bricks away from the cloud must be free"


def test_from_dense_cuts_bricks_as_the_file_reader(tmp_path):
    """vdb.from_dense (tests, benchmarks) and a file written by OpenVDB and read back agree brick for brick."""
    ok, why = vdb.available()
    if not ok:
        pytest.skip(f"OpenVDB's Python module is not available: {why}")
    a = cloud(1)[..., 0]
    path = tmp_path / "c.vdb"
    vdb.write(str(path), [dict(name="density", array=a.transpose(2, 1, 0), ijk=(-24, 8, -16))])
    read = vdb.read(str(path), "density")
    made = vdb.from_dense(a, ijk=(-24, 8, -16))
    np.testing.assert_array_equal(read.origin, made.origin)
    np.testing.assert_array_equal(read.counts, made.counts)
    np.testing.assert_array_equal(read.dense(), made.dense())
    assert len(read.coords) == len(made.coords) and len(read.tile_coords) == len(made.tile_coords)


def test_device_bytes_per_active_voxel():
    """A ball filling 4% of its box keeps under 30% of the dense box's bytes."""
    rng = np.random.default_rng(4)
    n = 96
    z, y, x = np.mgrid[0:n, 0:n, 0:n]
    ball = (x - 48) ** 2 + (y - 48) ** 2 + (z - 48) ** 2 < 20 ** 2
    a = np.where(ball, rng.random((n, n, n)), 0).astype(np.float32)
    sg = vdb.from_dense(a)
    dense_bytes = a.size * 4
    assert sg.active_voxels == ball.sum()
    assert sg.stored_bytes() < 0.3 * dense_bytes
    packer = grids.GridPacker()
    packer.add(sparse_volume(sg), tracked=True)
    cost = packer.sparse[0]
    assert cost["bytes"] == sg.stored_bytes() + 4 * np.prod(sg.padded_counts())
    # every stored voxel costs 4 bytes; the rest is one index and one majorant word a brick
    assert cost["bytes"] == 4 * (512 * len(sg.coords) + len(sg.tile_coords) + 1 + 2 * np.prod(sg.padded_counts()))
