"""Sparse grids rendered end to end: a grid in bricks renders the very bits of the same values as a
dense grid of its padded box (same seed, same majorant cells), both built in Python and read from
an OpenVDB file against a .vol file of the same densities in Mitsuba's format; Mitsuba 3 renders
that .vol file like volcl renders the .vdb (optional); and the pre-upload memory check counts the
bricks and names what each sparse grid costs."""
from types import SimpleNamespace

import numpy as np
import pytest

from imagestats import assert_mean_matches
from scenebuild import camera, constant_env, hetero_medium, grid, look_at, scene, sphere
from volcl import device as devmod
from volcl import vdb
from volcl.errors import VolclError
from volcl.prepared import Scene as PreparedScene
from volcl.renderer import Renderer, render
from volcl.scene import load
from volcl.scene import transform as tf
from volcl.scene.model import Bsdf, Emitter, Volume, rgb
from volcl.scene.volfile import write_vol

IJK = (-13, 3, -5)          # negative index bounds, not aligned to bricks


def puff(n=21, seed=5):
    """(z, y, x) densities: a noisy ball in an n^3 box, background 0."""
    rng = np.random.default_rng(seed)
    z, y, x = np.mgrid[0:n, 0:n, 0:n]
    c = (n - 1) / 2
    ball = (x - c) ** 2 + (y - c) ** 2 + (z - c) ** 2 < (0.4 * n) ** 2
    return np.where(ball, rng.random((n, n, n)) * 4, 0).astype(np.float32)


def sparse_volume(sg, to_world):
    return Volume("sparse", value=rgb(0.0), to_world=to_world @ sg.unit_to_world(), sparse=sg,
                  grid_name=sg.name)


def lit_ball(volume, seed):
    med = hetero_medium(volume, 0.8, g=0.3)
    ball = sphere((0, 0, 0), 2.0, Bsdf("null"), interior=med)
    lights = [constant_env(0.4), Emitter("point", rgb(6.0), position=np.array([2.0, 2.5, 1.5]))]
    return scene([ball], lights, cam=camera(12, 12, fov=45, to_world=look_at((0, 0, 5), (0, 0, 0))), seed=seed)


def test_sparse_grid_renders_the_bits_of_its_dense_box(device):
    """Lookups, majorants and the tracking walk all agree, so the images are identical, not just close."""
    sg = vdb.from_dense(puff(), ijk=IJK)
    nb = sg.padded_counts()
    assert len(set(nb)) == 1, "a cubic brick box, so the dense grid can get the same majorant cells"
    to_world = tf.rotate([1, 1, 0], 25) @ np.diag([0.1, 0.1, 0.1, 1.0])
    a = render(lit_ball(sparse_volume(sg, to_world), seed=1), spp=32, device=device)
    b = render(lit_ball(grid(sg.dense(), to_world @ sg.unit_to_world()), seed=1), spp=32, device=device,
               majorant_cells=int(nb[0]))
    assert a.tracking_cutoffs == 0 and a.image.mean() > 0.05
    np.testing.assert_array_equal(a.image, b.image)


# --- from files --------------------------------------------------------------------------------------

needs_openvdb = pytest.mark.skipif(not vdb.available()[0],
                                   reason=f"OpenVDB's Python module is not available: {vdb.available()[1]}")

# index -> world of the written grid: voxels 0.12 apart, shifted; then the scene's own to_world
INDEX_TO_WORLD = np.array([[0.12, 0, 0, 0.3], [0, 0.12, 0, -0.2], [0, 0, 0.12, 0.1], [0, 0, 0, 1]])


def _matrix(m):
    return '<matrix value="' + " ".join(f"{v:.17g}" for v in np.asarray(m).reshape(-1)) + '"/>'


def cloud_xml(volume_xml, spp=32, width=16):
    return f'''<scene version="3.0.0">
    <integrator type="volpath"><integer name="max_depth" value="-1"/></integrator>
    <sensor type="perspective"><float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 0.5, 4.5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="{width}"/><integer name="height" value="{width}"/>
            <rfilter type="box"/></film>
        <sampler type="independent"><integer name="sample_count" value="{spp}"/></sampler>
    </sensor>
    <emitter type="constant"><rgb name="radiance" value="0.5"/></emitter>
    <emitter type="point"><point name="position" x="2" y="3" z="2"/><rgb name="intensity" value="8"/></emitter>
    <shape type="cube"><transform name="to_world"><scale value="1.6"/></transform>
        <bsdf type="null"/>
        <medium type="heterogeneous" name="interior">
            {volume_xml}
            <rgb name="albedo" value="0.9, 0.8, 0.6"/>
            <float name="scale" value="1.5"/>
            <phase type="hg"><float name="g" value="0.4"/></phase>
        </medium>
    </shape>
</scene>
'''


@pytest.fixture(scope="module")
def cloud_files(tmp_path_factory):
    """The same densities as cloud.vdb (written by OpenVDB) and as cloud.vol (the padded box, dense),
    and the two scenes; the .vol scene's to_world is the .vdb grid's placement made explicit."""
    folder = tmp_path_factory.mktemp("vdb_render")
    a = puff()
    vdb.write(str(folder / "cloud.vdb"), [dict(name="density", array=a.transpose(2, 1, 0), ijk=IJK,
                                               index_to_world=INDEX_TO_WORLD)])
    sg = vdb.read(str(folder / "cloud.vdb"), "density")
    write_vol(str(folder / "cloud.vol"), sg.dense())
    # the scene's own to_world, as a matrix so that both files' transforms are the same float64 numbers
    scene_m = tf.translate([-0.3, 0.2, -0.1]) @ tf.rotate([0, 1, 0], 30)
    vdb_xml = (f'<volume type="volcl_vdb" name="sigma_t"><string name="filename" value="cloud.vdb"/>'
               f'<string name="grid" value="density"/><transform name="to_world">{_matrix(scene_m)}</transform>'
               f'</volume>')
    vol_xml = (f'<volume type="gridvolume" name="sigma_t"><string name="filename" value="cloud.vol"/>'
               f'<transform name="to_world">{_matrix(scene_m @ sg.unit_to_world())}</transform></volume>')
    (folder / "cloud_vdb.xml").write_text(cloud_xml(vdb_xml))
    (folder / "cloud_vol.xml").write_text(cloud_xml(vol_xml, spp=16, width=24))
    (folder / "cloud_vol_small.xml").write_text(cloud_xml(vol_xml))
    return folder, sg


@needs_openvdb
def test_vdb_file_renders_the_bits_of_the_vol_file(device, cloud_files):
    folder, sg = cloud_files
    nb = int(sg.padded_counts()[0])
    a = Renderer(load(folder / "cloud_vdb.xml"), device=device, seed=4).render(16)
    b = Renderer(load(folder / "cloud_vol_small.xml"), device=device, seed=4, majorant_cells=nb).render(16)
    assert a.tracking_cutoffs == 0 and a.image.mean() > 0.05
    np.testing.assert_array_equal(a.image, b.image)


@needs_openvdb
def test_vdb_cloud_matches_mitsuba_on_the_vol_file(device, cloud_files):
    """Mitsuba 3 cannot read .vdb files; it renders the .vol holding the same densities, and volcl's
    render of the .vdb must match within both renders' noise."""
    from test_mitsuba_agreement import SEEDS, VARIANT, mitsuba_references, reference_image
    folder, _ = cloud_files
    out = str(folder / "mitsuba_cloud")
    jobs = [{"scene": str(folder / "cloud_vol.xml"), "out": out, "spp": 64, "seeds": SEEDS[:8], "variant": VARIANT}]
    mean, var = reference_image(mitsuba_references(folder, jobs, timeout=900), out)
    sc = load(folder / "cloud_vdb.xml")
    sc.camera.width = sc.camera.height = 24
    result = Renderer(sc, device=device, seed=3).render(512)
    assert_mean_matches(result, mean, blocks=4, what="vdb cloud vs Mitsuba's .vol", expected_variance=var)


# --- memory --------------------------------------------------------------------------------------------

def _small_device(global_mem):
    dev = SimpleNamespace(name="Small Test Device", global_mem_size=global_mem, max_mem_alloc_size=global_mem)
    return devmod.DeviceInfo(7, 3, dev, "test platform")


def test_memory_check_counts_the_bricks_and_names_their_cost():
    """A 24^3 ball in a 504^3 box: its bricks fit a device far too small for the dense box; a device
    too small for the bricks refuses before uploading, with each grid's bytes per active voxel."""
    n = 24
    a = puff(n)
    sg = vdb.from_dense(a, ijk=(0, 0, 0))
    far = vdb.from_dense(a[:8, :8, :8] + 0.5, ijk=(480, 480, 480))      # a second puff far away
    sg = vdb.merge_bricks([sg, far])
    nb = sg.padded_counts()
    dense_bytes = 4 * int(np.prod(nb)) * 512
    sc = lit_ball(sparse_volume(sg, np.diag([0.004, 0.004, 0.004, 1.0]) @ tf.translate([-250, -250, -250])), 1)
    total = sum(PreparedScene(sc).buffer_sizes().values())
    assert total < dense_bytes / 20
    with pytest.raises(VolclError) as info:
        Renderer(sc, device=_small_device(global_mem=total // 2))
    message = str(info.value)
    assert "too large for device" in message
    assert f"grid 'density' of (array): {sg.active_voxels} active voxels in {len(sg.coords)} bricks" in message
    assert f"dense would take {dense_bytes} bytes" in message


@needs_openvdb
def test_fire_scene_reports_its_grids():
    """scenes/vdb_fire.xml loads, and `volcl info` names both sparse grids and what each costs (the
    renders are in test_temperature.py; a kernel build of this scene's features would only add time)."""
    from test_cli import volcl
    r = volcl("info", "scenes/vdb_fire.xml", "--no-build")
    assert r.returncode == 0, r.stderr
    assert "sparse grid 'density'" in r.stdout and "VOLCL_HAS_SPARSE_GRIDS=1" in r.stdout
    for name in ("density", "temperature"):
        assert f"sparse     grid '{name}' of " in r.stdout and "bytes per active voxel" in r.stdout
