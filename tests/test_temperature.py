"""Emission from temperature (volcl/blackbody.py): the normalized blackbody's colour against an
independent integration through colour-science, its table against the direct integral, and renders
with known answers: an absorbing slab whose columns hold different temperatures gives
Le(T) (1 - exp(-sigma d)) per pixel, and a temperature grid read from an OpenVDB file in a black box
whose walls emit the same radiance is in equilibrium (L = Le everywhere)."""
import numpy as np
import pytest

from imagestats import assert_mean_matches
from scenebuild import box_mesh, camera, grid, hetero_medium, scene
from volcl import blackbody, vdb
from volcl.renderer import render
from volcl.scene import load
from volcl.scene import transform as tf
from volcl.scene.model import Bsdf, Shape, Volume, rgb

TEMPERATURES = [600.0, 1000.0, 1500.0, 2500.0, 4000.0, 6500.0, 10000.0, 30000.0]


def colour_science_rgb(t):
    """pbrt-v4's normalized blackbody through colour-science alone: Planck's law at 0.1 nm steps
    over 360-830 nm divided by its value at Wien's peak, integrated against the CIE 1931 2-degree
    functions, luminance 1 for a unit spectrum, then colour's own XYZ -> linear sRGB (no adaptation)."""
    import colour
    w = np.arange(360.0, 830.0 + 1e-9, 0.1)
    table = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    cmfs = np.stack([np.interp(w, table.wavelengths, table.values[:, k]) for k in range(3)], axis=1)
    planck = colour.colorimetry.planck_law(w * 1e-9, t)
    peak = float(np.ravel(colour.colorimetry.planck_law(np.array([2.8977721e-3 / t, 1.0]), t))[0])
    xyz = (cmfs * (planck / peak)[:, None]).sum(0) / cmfs[:, 1].sum()
    srgb = colour.RGB_COLOURSPACES["sRGB"]
    return np.maximum(srgb.matrix_XYZ_to_RGB @ xyz, 0.0)


@pytest.mark.parametrize("t", TEMPERATURES)
def test_blackbody_colour_matches_colour_science(t):
    # the sums differ in step (1000 points vs 0.1 nm) and the matrices in their last digits
    np.testing.assert_allclose(blackbody.rgb(t), colour_science_rgb(t), rtol=2e-3, atol=1e-6)


def test_normalized_spectrum_peaks_at_one():
    w = np.linspace(50.0, 1e5, 2_000_000)
    for t in (800.0, 5000.0, 20000.0):
        s = blackbody.normalized_spectrum(w, t)
        assert abs(s.max() - 1.0) < 1e-6
        assert abs(w[np.argmax(s)] - blackbody.WIEN_B / t * 1e9) < 0.1


def test_table_interpolation_is_close_to_the_integral():
    t = np.geomspace(150.0, 1e5, 300)
    exact = np.array([blackbody.rgb(x) for x in t])
    table = blackbody.table_lookup(t)
    scale = exact.max(axis=1, keepdims=True)
    assert np.abs(table - exact).max() < 4e-6, "against a peak of 1"
    visible = t > 500
    assert (np.abs(table - exact)[visible] <= 1e-3 * scale[visible]).all()
    assert (blackbody.table_lookup(np.array([0.0, 50.0, 100.0])) == 0).all(), "cut-off: nothing at or below 100 K"


def test_colour_runs_from_red_to_blue():
    low, mid, high = blackbody.rgb(1500.0), blackbody.rgb(6500.0), blackbody.rgb(30000.0)
    assert low[0] > low[1] > low[2]
    assert high[2] > high[0]
    assert 0.8 < mid[0] / mid[2] < 1.25


# --- renders ---------------------------------------------------------------------------------------

W = 8


def slab_scene(temperature_volume, sigma, depth, scale, offset, t_scale, seed):
    """An absorbing slab z in [0, depth] (x, y in [-1.5, 1.5]) seen along +z by an orthographic
    camera over x, y in [-1, 1] at W x W pixels; no other light."""
    sigma_t = Volume("const", value=rgb(sigma), to_world=tf.translate([-1.5, -1.5, 0]) @ tf.scale([3, 3, depth]))
    med = hetero_medium(sigma_t, 0.0)
    med.emission_kind, med.emission_volume = "temperature", temperature_volume
    med.emission_scale, med.temperature_offset, med.temperature_scale = scale, offset, t_scale
    v, f = box_mesh(inward=False)
    v = v * [1.5, 1.5, depth / 2] + [0, 0, depth / 2]
    slab = Shape("mesh", Bsdf("null"), vertices=v, faces=f, interior=med)
    cam = camera(W, W, to_world=tf.translate([0, 0, -1.0]))
    cam.kind = "orthographic"
    return scene([slab], [], cam=cam, seed=seed)


@pytest.mark.parametrize("layout", ["dense", "sparse"])
def test_emitting_slab_gives_its_analytic_radiance(device, layout):
    """Column i of the image sees temperature T_i all along its rays (a nearest-filtered grid whose
    voxels are the pixel columns), so L = scale * B(T_i) (1 - exp(-sigma d)) exactly, with B the
    kernel's table (within 2e-3 of the integral: test above)."""
    sigma, depth, scale = np.array([0.7, 1.1, 2.0]), 1.3, 3.0
    offset, t_scale = 250.0, 2.0
    temps = np.geomspace(900.0, 12000.0, W)
    raw = (temps / t_scale + offset).astype(np.float32)
    if layout == "dense":
        values = np.broadcast_to(raw, (1, 1, W))
        vol = grid(values, tf.translate([-1, -2, -1]) @ tf.scale([2, 4, depth + 2]), "nearest")
    else:
        values = np.broadcast_to(raw, (9, 8, W)).copy()
        sg = vdb.from_dense(values, ijk=(0, 0, 0))
        # index i of x covers [-1 + 2 i / W, -1 + 2 (i + 1) / W]; y and z cover the rays with margin
        sy, sz = 2.4 / 8, (depth + 0.2) / 9
        m = np.array([[2.0 / W, 0, 0, -1 + 1.0 / W], [0, sy, 0, -1.2 + sy / 2], [0, 0, sz, -0.1 + sz / 2],
                      [0, 0, 0, 1]])
        vol = Volume("sparse", value=rgb(0.0), to_world=m @ sg.unit_to_world(), filter="nearest", sparse=sg,
                     grid_name="temperature")
    r = render(slab_scene(vol, sigma, depth, scale, offset, t_scale, seed=3), spp=256, device=device)
    # per column; the image's x runs along the camera frame's -x (Mitsuba's camera convention)
    le = scale * blackbody.table_lookup(temps)[::-1]
    expected = np.broadcast_to(le[None, :, :] * (1 - np.exp(-sigma * depth)), (W, W, 3))
    assert r.tracking_cutoffs == 0
    assert_mean_matches(r, expected, blocks=2, what=f"emitting slab ({layout})")
    # columns differ in colour as their temperatures do: the test is not of a grey image
    hot, cool = r.image[:, 0].mean(axis=0), r.image[:, -1].mean(axis=0)
    assert hot[2] / hot[0] > 3 * cool[2] / cool[0]


needs_openvdb = pytest.mark.skipif(not vdb.available()[0],
                                   reason=f"OpenVDB's Python module is not available: {vdb.available()[1]}")


@needs_openvdb
def test_temperature_grid_from_vdb_in_equilibrium(device, tmp_path):
    """Density and temperature grids of one .vdb file (the temperature uniform over the density's
    support, with offset and scale), scattering albedo 0.5, inside black walls emitting the same
    blackbody radiance: L = Le everywhere, whatever the density does."""
    rng = np.random.default_rng(11)
    n = 14
    density = np.where(rng.random((n, n, n)) < 0.7, rng.random((n, n, n)) * 6, 0).astype(np.float32)
    temperature = np.full((n + 4, n + 4, n + 4), 1700.0, np.float32)      # covers the trilinear halo
    m = np.diag([2.4 / n, 2.4 / n, 2.4 / n, 1.0])
    m[:3, 3] = -1.2
    vdb.write(str(tmp_path / "fire.vdb"), [dict(name="density", array=density, ijk=(0, 0, 0), index_to_world=m),
                                           dict(name="temperature", array=temperature, ijk=(-2, -2, -2),
                                                index_to_world=m)])
    offset, t_scale, scale = 200.0, 2.0, 1.5
    le = scale * blackbody.table_lookup(np.array([(1700.0 - offset) * t_scale]))[0]
    xml = f'''<scene version="3.0.0">
    <integrator type="volpath"/>
        <medium type="heterogeneous" id="fire">
            <volume type="volcl_vdb" name="sigma_t"><string name="filename" value="fire.vdb"/>
                <string name="grid" value="density"/></volume>
            <volume type="volcl_vdb" name="volcl_temperature"><string name="filename" value="fire.vdb"/>
                <string name="grid" value="temperature"/></volume>
            <float name="albedo" value="0.5"/>
            <float name="volcl_temperature_offset" value="{offset}"/>
            <float name="volcl_temperature_scale" value="{t_scale}"/>
            <float name="volcl_emission_scale" value="{scale}"/>
        </medium>
    <sensor type="perspective"><float name="fov" value="90"/><ref id="fire"/>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/>
            <rfilter type="box"/></film>
        <sampler type="independent"><integer name="sample_count" value="256"/></sampler>
    </sensor>
    <shape type="cube"><bsdf type="diffuse"><rgb name="reflectance" value="0"/></bsdf><boolean name="flip_normals" value="true"/>
        <transform name="to_world"><scale value="1.5"/></transform>
        <emitter type="area"><rgb name="radiance" value="{le[0]:.9g}, {le[1]:.9g}, {le[2]:.9g}"/></emitter>
        <ref id="fire" name="interior"/></shape>
</scene>'''
    (tmp_path / "fire.xml").write_text(xml)
    r = render(load(tmp_path / "fire.xml"), spp=256, device=device)
    assert r.tracking_cutoffs == 0
    assert_mean_matches(r, le, what="temperature grid in equilibrium")


def test_radiance_grid_with_emission_scale_in_equilibrium(device):
    """volcl_radiance as an rgb grid (uniform Le / 2, times volcl_emission_scale 2) in a scattering
    medium whose density varies, inside black walls emitting Le: L = Le."""
    from scenebuild import furnace
    le = np.array([0.6, 0.9, 0.3])
    rng = np.random.default_rng(4)
    density = vdb.from_dense((rng.random((9, 10, 11)) * 4).astype(np.float32), ijk=(-3, 2, -7))
    sigma_t = Volume("sparse", value=rgb(0.0), to_world=tf.translate([-1.2] * 3) @ tf.scale([2.4] * 3),
                     sparse=density, grid_name="density")
    med = hetero_medium(sigma_t, 0.6, g=0.4)
    med.emission_kind = "radiance"
    med.emission_volume = grid(np.broadcast_to((le / 2).astype(np.float32), (3, 2, 4, 3)),
                               tf.rotate([1, 0, 0], 20) @ tf.translate([-1] * 3) @ tf.scale([2] * 3))
    med.emission_scale = 2.0
    r = render(furnace(0.0, radiance=le, medium=med), spp=256, device=device)
    assert r.tracking_cutoffs == 0
    assert_mean_matches(r, le, what="radiance grid in equilibrium")
