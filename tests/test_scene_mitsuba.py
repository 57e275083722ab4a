"""The Mitsuba 3 dialect: a scene using every contract feature, defaults, refs and -D overrides."""
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from volcl.scene import load
from volcl.scene import transform as tf
from volcl.scene.model import Scene
from volcl.scene.volfile import write_vol

DATA = Path(__file__).parent / "data" / "scene"
DENSITY = np.arange(24, dtype=np.float32).reshape(2, 3, 4) / 24.0


@pytest.fixture
def scene_dir(tmp_path):
    for name in ("mitsuba_full.xml", "tetra.obj"):
        shutil.copy(DATA / name, tmp_path / name)
    write_vol(tmp_path / "density.vol", DENSITY)
    return tmp_path


@pytest.fixture
def full(scene_dir) -> Scene:
    return load(scene_dir / "mitsuba_full.xml")


def scene(tmp_path, body: str, **defines) -> Scene:
    path = tmp_path / "scene.xml"
    path.write_text(f'<scene version="3.0.0">\n{body}\n</scene>\n')
    shutil.copy(DATA / "tetra.obj", tmp_path / "tetra.obj")
    return load(path, defines or None)


SENSOR = '<sensor type="perspective"><float name="fov" value="40"/></sensor>'


def test_full_scene_settings(full):
    assert full.dialect == "mitsuba"
    assert (full.integrator.kind, full.integrator.max_depth, full.integrator.rr_depth,
            full.integrator.hide_emitters) == ("volpath", 8, 3, True)
    cam = full.camera
    assert (cam.fov, cam.fov_axis, cam.near_clip, cam.far_clip) == (35.0, "y", 0.1, 100.0)
    assert (cam.width, cam.height) == (64, 48)
    assert (cam.rfilter.kind, cam.rfilter.radius) == ("tent", 1.5)
    assert np.allclose(cam.to_world, [[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1, 5], [0, 0, 0, 1]])
    assert (full.spp, full.seed) == (16, 7)          # sample_count="$spp" with default 16
    pixel_format, hidden, unbounded = full.warnings
    assert "pixel_format" in pixel_format and "mitsuba_full.xml:39" in pixel_format
    assert "hide_emitters" in hidden and "pass through area emitters" in hidden
    # the camera's fog reaches to infinity under a constant environment (Mitsuba's NEE differs there)
    assert "camera's medium is not enclosed" in unbounded and "twice the scene's bounding radius" in unbounded


def test_full_scene_media_are_shared_objects(full):
    fog = full.camera.medium
    assert fog.kind == "homogeneous" and fog.id == "fog"
    assert np.allclose(fog.sigma_t, [0.5, 1, 2])
    assert np.allclose(fog.albedo, 0.8)               # "$albedo"
    assert fog.scale == 2.0
    assert (fog.phase.kind, fog.phase.g) == ("hg", 0.3)
    assert np.allclose(fog.radiance, 0.1)
    cube = full.shapes[1]
    assert cube.interior is fog and cube.exterior is fog
    hetero = full.shapes[2].interior
    assert [id(m) for m in full.media] == [id(fog), id(hetero)]


def test_full_scene_heterogeneous_medium(full):
    medium = full.shapes[2].interior
    assert medium.kind == "heterogeneous"
    grid = medium.sigma_t
    assert grid.kind == "grid" and grid.filter == "nearest"
    assert grid.data.shape == (2, 3, 4, 1)
    assert np.array_equal(grid.data[..., 0], DENSITY)
    assert np.allclose(grid.to_world, tf.translate([-0.5] * 3))
    assert grid.filename.endswith("density.vol")
    assert medium.albedo.kind == "const" and np.allclose(medium.albedo.value, 0.9)
    assert medium.phase.kind == "isotropic"


def test_full_scene_shapes(full):
    rect, cube, sphere, disk, tetra = full.shapes
    assert [s.kind for s in full.shapes] == ["mesh", "mesh", "sphere", "mesh", "mesh"]
    # scale 2 then translate y 1.
    assert np.allclose(rect.vertices, [[-2, -1, 0], [2, -1, 0], [2, 3, 0], [-2, 3, 0]])
    assert rect.bsdf.kind == "diffuse" and rect.bsdf.id == "grey"
    assert np.allclose(rect.bsdf.reflectance, [0.2, 0.4, 0.6])
    assert np.allclose(rect.emitter_radiance, 5)
    assert cube.bsdf.kind == "null" and len(cube.faces) == 12 and cube.normals is None
    # center (1,2,3): rotate y 90 -> (3,2,-1), scale 2 -> (6,4,-2), translate z 1.
    assert np.allclose(sphere.center, [6, 4, -1]) and sphere.radius == pytest.approx(1.0)
    assert sphere.bsdf.kind == "dielectric"
    assert (sphere.bsdf.int_ior, sphere.bsdf.ext_ior) == (1.3330, 1.0)
    assert disk.flip_normals and disk.bsdf.twosided and disk.bsdf.kind == "conductor"
    assert np.allclose(disk.bsdf.eta, [0.2, 0.9, 1.1]) and np.allclose(disk.bsdf.k, [3.9, 2.4, 2.2])
    assert tetra.bsdf.kind == "conductor" and tetra.bsdf.eta is None and tetra.bsdf.k is None
    assert tetra.normals is not None and tetra.normals.shape == tetra.vertices.shape


def test_full_scene_emitters(full):
    point, directional, constant = full.emitters
    assert point.kind == "point" and np.allclose(point.value, 10)
    assert np.allclose(point.position, [1, 2, 3])
    assert directional.kind == "directional" and np.allclose(directional.direction, [0, -1, 0])
    assert np.allclose(directional.value, 3)
    assert constant.kind == "constant" and np.allclose(constant.value, 0.05)


def test_define_overrides_default(scene_dir):
    s = load(scene_dir / "mitsuba_full.xml", {"spp": "64", "albedo": "0.25"})
    assert s.spp == 64
    assert np.allclose(s.camera.medium.albedo, 0.25)


def test_define_without_default(tmp_path):
    s = scene(tmp_path, f'{SENSOR}<shape type="sphere"><float name="radius" value="$r"/></shape>',
              r="3")
    assert s.shapes[0].radius == 3.0


def test_substitution_inside_a_value(tmp_path):
    body = ('<default name="c" value="0.5"/>'
            '<shape type="sphere"><bsdf type="diffuse">'
            '<rgb name="reflectance" value="$c, 0.25 $c"/></bsdf></shape>' + SENSOR)
    assert np.allclose(scene(tmp_path, body).shapes[0].bsdf.reflectance, [0.5, 0.25, 0.5])


def test_missing_integrator_warns_and_uses_volpathmis(tmp_path):
    s = scene(tmp_path, SENSOR)
    assert s.integrator.kind == "volpathmis" and s.integrator.max_depth == -1
    assert s.integrator.rr_depth == 5
    assert any("no <integrator>" in w for w in s.warnings)


@pytest.mark.parametrize("kind, kernel_rr_depth", [("path", 3), ("volpath", 4), ("volpathmis", 4)])
def test_roulette_starts_where_mitsubas_integrator_starts_it(tmp_path, kind, kernel_rr_depth):
    """The kernel plays roulette after a bounce that brings the depth to its rr_depth. Mitsuba's
    path does so at the file's rr_depth; volpath and volpathmis test depth > rr_depth at the top
    of their loop, one bounce later."""
    from volcl.pack import pack
    s = scene(tmp_path, f'<integrator type="{kind}"><integer name="rr_depth" value="3"/></integrator>' + SENSOR)
    assert s.integrator.rr_depth == 3
    assert int(pack(s).params["rr_depth"]) == kernel_rr_depth


def test_sensor_defaults(tmp_path):
    s = scene(tmp_path, '<integrator type="path"/><sensor type="perspective"/>')
    cam = s.camera
    assert (cam.width, cam.height) == (768, 576)
    assert (cam.rfilter.kind, cam.rfilter.radius, cam.rfilter.stddev) == ("gaussian", 2.0, 0.5)
    assert (cam.near_clip, cam.far_clip) == (0.01, 1e4)
    # Mitsuba's default 50 mm lens on 36 x 24 mm film, along the diagonal.
    assert cam.fov_axis == "diagonal"
    assert cam.fov == pytest.approx(2 * math.degrees(math.atan(math.hypot(36, 24) / 100)))
    assert (s.spp, s.seed) == (4, 0)
    assert s.warnings == []


def test_missing_sensor_frames_the_scene_like_mitsuba(tmp_path):
    s = scene(tmp_path, '<integrator type="path"/><shape type="cube"/>')
    cam = s.camera
    distance = 2 / (2 * math.tan(math.radians(22.5)))
    assert cam.fov == 45
    assert np.allclose(cam.to_world, tf.translate([0, 0, -1 - distance]))
    assert cam.far_clip == pytest.approx(10 + distance)
    assert cam.near_clip == pytest.approx(distance / 100)
    assert any("no <sensor>" in w for w in s.warnings)


@pytest.mark.parametrize("xml, kind, radius, stddev", [
    ('<rfilter type="gaussian"><float name="stddev" value="1"/></rfilter>', "gaussian", 4.0, 1.0),
    ('<rfilter type="box"/>', "box", 0.5, 0.5),
    ('<rfilter type="tent"/>', "tent", 1.0, 0.5),
])
def test_rfilters(tmp_path, xml, kind, radius, stddev):
    s = scene(tmp_path, f'<sensor type="perspective"><film type="hdrfilm">{xml}</film></sensor>')
    f = s.camera.rfilter
    assert (f.kind, f.radius, f.stddev) == (kind, radius, stddev)


def test_other_sampler_warns(tmp_path):
    body = ('<sensor type="perspective"><sampler type="stratified">'
            '<integer name="sample_count" value="9"/></sampler></sensor>')
    s = scene(tmp_path, body)
    assert s.spp == 9
    assert any("stratified" in w and "scene.xml:2" in w for w in s.warnings)


def test_shape_without_bsdf_is_diffuse_half(tmp_path):
    s = scene(tmp_path, SENSOR + '<shape type="cube"/><shape type="cube"/>')
    a, b = s.shapes
    assert a.bsdf.kind == "diffuse" and np.allclose(a.bsdf.reflectance, 0.5)
    assert a.bsdf is not b.bsdf


def test_ref_shares_bsdf_and_twosided_copies_it(tmp_path):
    body = ('<bsdf type="diffuse" id="white"/>' + SENSOR +
            '<shape type="cube"><ref id="white"/></shape>'
            '<shape type="cube"><bsdf type="twosided"><ref id="white"/></bsdf></shape>'
            '<shape type="cube"><ref id="white"/></shape>')
    a, b, c = scene(tmp_path, body).shapes
    assert a.bsdf is c.bsdf and not a.bsdf.twosided
    assert b.bsdf.twosided and b.bsdf.kind == "diffuse"


def test_conductor_defaults(tmp_path):
    body = SENSOR + ('<shape type="cube"><bsdf type="conductor"><rgb name="eta" value="0.5"/>'
                     '</bsdf></shape>')
    bsdf = scene(tmp_path, body).shapes[0].bsdf
    assert np.allclose(bsdf.eta, 0.5) and np.allclose(bsdf.k, 1.0)
    assert np.allclose(bsdf.specular_reflectance, 1.0)


def test_reflectance_above_one_warns(tmp_path):
    body = SENSOR + ('<shape type="cube"><bsdf type="diffuse">\n<float name="reflectance" '
                     'value="1.5"/></bsdf></shape>')
    s = scene(tmp_path, body)
    assert np.allclose(s.shapes[0].bsdf.reflectance, 1.5)
    (warning,) = [w for w in s.warnings if "exceeds 1" in w]
    assert "scene.xml:3" in warning


def test_dielectric_defaults_and_names(tmp_path):
    body = SENSOR + ('<shape type="cube"><bsdf type="dielectric"/></shape>'
                     '<shape type="cube"><bsdf type="dielectric">'
                     '<string name="int_ior" value="fused silica"/>'
                     '<string name="ext_ior" value="vacuum"/></bsdf></shape>')
    a, b = (s.bsdf for s in scene(tmp_path, body).shapes)
    assert (a.int_ior, a.ext_ior) == (1.5046, 1.000277)
    assert (b.int_ior, b.ext_ior) == (1.4585, 1.0)


def test_emitters_from_to_world(tmp_path):
    body = SENSOR + ('<emitter type="point"><transform name="to_world">'
                     '<translate value="1, 2, 3"/></transform></emitter>'
                     '<emitter type="directional"><transform name="to_world">'
                     '<rotate x="1" angle="90"/></transform></emitter>')
    point, directional = scene(tmp_path, body).emitters
    assert np.allclose(point.position, [1, 2, 3]) and np.allclose(point.value, 1)
    assert np.allclose(directional.direction, [0, -1, 0])   # +z rotated 90 about x


def test_spectrum_and_float_colours(tmp_path):
    body = SENSOR + ('<shape type="cube"><bsdf type="diffuse"><spectrum name="reflectance" '
                     'value="0.3"/></bsdf></shape><shape type="cube"><bsdf type="diffuse">'
                     '<float name="reflectance" value="0.7"/></bsdf></shape>')
    a, b = scene(tmp_path, body).shapes
    assert np.allclose(a.bsdf.reflectance, 0.3) and np.allclose(b.bsdf.reflectance, 0.7)


def test_homogeneous_defaults(tmp_path):
    body = SENSOR + '<shape type="cube"><medium type="homogeneous" name="interior"/></shape>'
    m = scene(tmp_path, body).shapes[0].interior
    assert np.allclose(m.sigma_t, 1) and np.allclose(m.albedo, 0.75) and m.scale == 1
    assert m.phase.kind == "isotropic" and m.radiance is None


def test_hg_default_g_is_mitsubas(tmp_path):
    body = SENSOR + ('<shape type="cube"><medium type="homogeneous" name="interior">'
                     '<phase type="hg"/></medium></shape>')
    assert scene(tmp_path, body).shapes[0].interior.phase.g == 0.8


def test_sensor_medium_child(tmp_path):
    body = ('<sensor type="perspective"><medium type="homogeneous">'
            '<float name="sigma_t" value="0.1"/></medium></sensor>')
    s = scene(tmp_path, body)
    assert np.allclose(s.camera.medium.sigma_t, 0.1) and s.media == [s.camera.medium]


def test_unused_top_level_medium_is_not_listed(tmp_path):
    s = scene(tmp_path, SENSOR + '<medium type="homogeneous" id="unused"/>')
    assert s.media == []


def test_sphere_defaults_and_uniform_scale(tmp_path):
    body = SENSOR + ('<shape type="sphere"/><shape type="sphere"><transform name="to_world">'
                     '<scale value="3"/><rotate x="1" angle="30"/><translate x="1"/></transform>'
                     '<float name="radius" value="2"/></shape>')
    a, b = scene(tmp_path, body).shapes
    assert np.allclose(a.center, 0) and a.radius == 1.0
    assert np.allclose(b.center, [1, 0, 0]) and b.radius == pytest.approx(6.0)



def test_heterogeneous_medium_with_constant_sigma_t_warns_and_keeps_to_world(tmp_path):
    """Mitsuba 3 bounds such a medium by the constant volume's unit cube (after its to_world); volcl
    renders the same and says so."""
    body = SENSOR + ('<shape type="sphere"><medium type="heterogeneous" name="interior">\n'
                     '<volume type="constvolume" name="sigma_t"><float name="value" value="2"/>'
                     '<transform name="to_world"><scale value="3"/></transform></volume>'
                     '</medium></shape>')
    s = scene(tmp_path, body)
    sigma_t = s.shapes[0].interior.sigma_t
    assert sigma_t.kind == "const" and np.allclose(sigma_t.value, 2)
    assert np.allclose(sigma_t.to_world, tf.scale([3, 3, 3]))
    (warning,) = [w for w in s.warnings if "constant 'sigma_t'" in w]
    assert "scene.xml:2" in warning and "unit cube" in warning


def test_shipped_smoke_scene_loads_its_grid():
    s = load(Path(__file__).resolve().parent.parent / "scenes" / "smoke_grid.xml")
    (smoke,) = s.media
    assert smoke.kind == "heterogeneous" and smoke.sigma_t.kind == "grid"
    assert smoke.sigma_t.data.shape == (48, 48, 48, 1) and smoke.sigma_t.filter == "trilinear"
    assert s.warnings == []
