"""The Nori dialect: the real cbox and furnace scenes, integrators, media and point lights."""
import math
from pathlib import Path

import numpy as np
import pytest

from volcl.scene import load
from volcl.scene.model import Scene, TTest

_HERE = Path(__file__).resolve()
NORI = next((p for p in (_HERE.parents[2] / "shared" / "nori", Path("/work/shared/nori"))
             if p.is_dir()), None)
needs_nori = pytest.mark.skipif(NORI is None, reason="shared/nori scenes not found")
DATA = Path(__file__).parent / "data" / "scene"


def nori(tmp_path, body: str, camera: str = '<camera type="perspective"/>') -> Scene:
    (tmp_path / "tetra.obj").write_bytes((DATA / "tetra.obj").read_bytes())
    path = tmp_path / "nori.xml"
    path.write_text(f'<scene>\n<integrator type="path_mis"/>{camera}\n{body}\n</scene>\n')
    return load(path)


@needs_nori
def test_cbox():
    s = load(NORI / "cbox" / "cbox_path_mis.xml")
    assert isinstance(s, Scene) and s.dialect == "nori"
    assert s.integrator.kind == "path_mis" and s.integrator.max_depth == -1
    assert not s.integrator.specular_chains_only
    assert s.spp == 256
    cam = s.camera
    assert (cam.width, cam.height, cam.fov, cam.fov_axis) == (800, 600, 27.7856, "x")
    assert (cam.rfilter.kind, cam.rfilter.radius, cam.rfilter.stddev) == ("gaussian", 2.0, 0.5)
    assert (cam.near_clip, cam.far_clip) == (1e-4, 1e4)
    # lookat from (0, .919769, 5.41159) to (0, .893051, 4.41198), up +y: dir = (0, dy, dz),
    # left = cross(up, dir) = (dz, 0, 0) = -x, up' = cross(dir, left) = (0, -dz, dy); the
    # scale -1,1,1 applied first negates the left column.
    d = np.array([0, 0.893051 - 0.919769, 4.41198 - 5.41159])
    dy, dz = d[1:] / np.linalg.norm(d)
    expected = [[1, 0, 0, 0], [0, -dz, dy, 0.919769], [0, dy, dz, 5.41159], [0, 0, 0, 1]]
    assert np.allclose(cam.to_world, expected)
    assert np.allclose(cam.to_world[1:3, 1:3], [[0.999643, -0.0267189], [-0.0267189, -0.999643]],
                       atol=1e-5)
    assert cam.medium is None and s.media == [] and s.emitters == []

    walls, right, left, mirror, glass, light = s.shapes
    assert len(s.shapes) == 6
    assert np.allclose(walls.bsdf.reflectance, [0.725, 0.71, 0.68])
    assert np.allclose(left.bsdf.reflectance, [0.630, 0.065, 0.05])
    assert mirror.bsdf.kind == "conductor" and mirror.bsdf.eta is None
    assert glass.bsdf.kind == "dielectric"
    assert (glass.bsdf.int_ior, glass.bsdf.ext_ior) == (1.5046, 1.000277)
    assert np.allclose(light.emitter_radiance, 40)
    assert [sh.emitter_radiance is not None for sh in s.shapes] == [False] * 5 + [True]
    # The spheres carry vn normals in their OBJ files; the walls do not.
    assert mirror.normals is not None and glass.normals is not None
    assert walls.normals is None and light.normals is None
    assert light.bsdf.kind == "diffuse" and np.allclose(light.bsdf.reflectance, 0.5)


@needs_nori
def test_furnace_ttest():
    t = load(NORI / "furnace" / "test-furnace.xml")
    assert isinstance(t, TTest)
    assert t.references == [2, 5, 2, 5, 2, 5] and t.significance == 0.01
    assert len(t.scenes) == 6
    assert [sc.integrator.kind for sc in t.scenes] == ["path_ems"] * 2 + ["path_mats"] * 2 + \
        ["path_mis"] * 2
    for scene, albedo in zip(t.scenes, [0.5, 0.8] * 3):
        assert (scene.camera.width, scene.camera.height, scene.camera.fov) == (1, 1, 10)
        (box,) = scene.shapes
        assert np.allclose(box.bsdf.reflectance, albedo) and np.allclose(box.emitter_radiance, 1)
        assert box.normals is not None and len(box.faces) == 12
        assert scene.spp == 1 and scene.path.endswith("test-furnace.xml")


@pytest.mark.parametrize("kind, depth, whitted", [
    ("path_mis", -1, False), ("path_mats", -1, False), ("path_ems", -1, False),
    ("vol_path", -1, False), ("direct", 2, False), ("direct_ems", 2, False),
    ("direct_mats", 2, False), ("direct_mis", 2, False), ("whitted", -1, True),
])
def test_integrators(tmp_path, kind, depth, whitted):
    path = tmp_path / "i.xml"
    path.write_text(f'<scene><integrator type="{kind}"/><camera type="perspective"/></scene>')
    integrator = load(path).integrator
    assert (integrator.kind, integrator.max_depth, integrator.specular_chains_only) == \
        (kind, depth, whitted)


def test_camera_defaults(tmp_path):
    cam = nori(tmp_path, "").camera
    assert (cam.width, cam.height, cam.fov, cam.fov_axis) == (1280, 720, 30.0, "x")
    assert (cam.rfilter.kind, cam.rfilter.radius) == ("gaussian", 2.0)


@pytest.mark.parametrize("xml, kind, radius", [
    ('<rfilter type="box"/>', "box", 0.5),
    ('<rfilter type="tent"/>', "tent", 1.0),
    ('<rfilter type="gaussian"><float name="radius" value="3"/>'
     '<float name="stddev" value="0.7"/></rfilter>', "gaussian", 3.0),
])
def test_rfilters(tmp_path, xml, kind, radius):
    f = nori(tmp_path, "", f'<camera type="perspective">{xml}</camera>').camera.rfilter
    assert (f.kind, f.radius) == (kind, radius)


def test_medium_fills_the_scene(tmp_path):
    body = ('<medium type="homogeneous"><color name="sigma_s" value="0.5, 1, 0"/>'
            '<color name="sigma_a" value="0.5"/><float name="g" value="0.4"/>'
            '<color name="radiance" value="2"/></medium>'
            '<mesh type="obj"><string name="filename" value="tetra.obj"/></mesh>'
            '<mesh type="obj"><string name="filename" value="tetra.obj"/></mesh>')
    s = nori(tmp_path, body)
    m = s.camera.medium
    assert np.allclose(m.sigma_t, [1, 1.5, 0.5])
    assert np.allclose(m.albedo, [0.5, 1 / 1.5, 0])
    assert (m.phase.kind, m.phase.g) == ("hg", 0.4)
    assert np.allclose(m.radiance, 2)
    assert all(sh.exterior is None and sh.interior is None for sh in s.shapes)
    assert s.media == [m]


def test_medium_with_sigma_t_and_zero_extinction(tmp_path):
    body = ('<medium type="homogeneous"><float name="sigma_s" value="0"/>'
            '<color name="sigma_t" value="0, 1, 2"/></medium>')
    m = nori(tmp_path, body).camera.medium
    assert np.allclose(m.sigma_t, [0, 1, 2]) and np.allclose(m.albedo, 0)
    assert m.phase.kind == "isotropic"


def test_point_light_power_to_intensity(tmp_path):
    body = ('<emitter type="point"><point name="position" value="1, 2, 3"/>'
            '<color name="power" value="100"/></emitter>')
    (light,) = nori(tmp_path, body).emitters
    assert np.allclose(light.value, 100 / (4 * math.pi))
    assert np.allclose(light.position, [1, 2, 3])


def test_sampler_and_mesh_transform(tmp_path):
    body = ('<sampler type="independent"><integer name="sampleCount" value="32"/></sampler>'
            '<mesh type="obj"><string name="filename" value="tetra.obj"/>'
            '<transform name="toWorld"><translate value="0, 0, 1"/></transform></mesh>')
    s = nori(tmp_path, body)
    assert s.spp == 32
    assert np.allclose(s.shapes[0].vertices.min(axis=0), [0, 0, 1])


def test_defaults_work_in_nori_files(tmp_path):
    path = tmp_path / "d.xml"
    path.write_text('<scene><default name="w" value="7"/><integrator type="direct"/>'
                    '<camera type="perspective"><integer name="width" value="$w"/></camera>'
                    '</scene>')
    assert load(path).camera.width == 7
    assert load(path, {"w": "9"}).camera.width == 9
