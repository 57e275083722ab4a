"""Participating media against analytic answers (see ../shared/docs/volumetrics.md, "Checks with
known answers"), with tolerances from the renders' own variance."""
import math
from pathlib import Path

import numpy as np
import pytest

from imagestats import assert_mean_matches
from scenebuild import (box_mesh, camera, constant_env, diffuse, furnace, look_at, medium, quad_mesh, scene,
                        sphere)
from volcl.renderer import render
from volcl.scene import load
from volcl.scene.model import Bsdf, Shape, rgb

pytestmark = pytest.mark.every_implementation


def test_absorbing_medium_attenuates_emitter(device):
    """Camera in a purely absorbing medium facing an emitter at distance d: L = Le exp(-sigma_t d)."""
    sigma = np.array([0.5, 1.0, 2.0])
    fog = medium(sigma, 0.0)
    d = 1.5
    lv, lf = quad_mesh((0, 0, -d), (10, 0, 0), (0, 10, 0))      # faces +z, towards the camera
    wall = Shape("mesh", diffuse(0.0), vertices=lv, faces=lf, emitter_radiance=rgb(2.0))
    # a narrow field of view: every pixel sees the wall at nearly the same distance, and the exact
    # per-pixel distance is used for the expectation
    cam = camera(4, 4, fov=2, to_world=look_at((0, 0, 0), (0, 0, -1)), medium=fog)
    r = render(scene([wall], cam=cam), spp=2048, device=device)
    tx = math.tan(math.radians(1))
    px = (np.arange(4) + 0.5) / 4
    x, y = np.meshgrid((1 - 2 * px) * tx, (1 - 2 * px) * tx)
    dist = d * np.sqrt(1 + x * x + y * y)
    expected = 2.0 * np.exp(-sigma[None, None, :] * dist[..., None])
    assert_mean_matches(r, expected, blocks=2, what="absorbing medium")


@pytest.mark.parametrize("g", [-0.9, 0.0, 0.9])
def test_furnace_filled_with_albedo_one_medium(device, g):
    """An albedo-1 medium inside a closed emitting furnace changes nothing: L = 1 / (1 - a)."""
    a = 0.5
    fog = medium(2.0, 1.0, g=g)
    r = render(furnace(a, medium=fog), spp=512, device=device)
    assert_mean_matches(r, 1 / (1 - a), what=f"medium furnace g={g}")


def test_furnace_with_chromatic_medium_and_a_zero_channel(device):
    a = 0.5
    fog = medium([0.0, 1.0, 4.0], 1.0, g=0.5)
    r = render(furnace(a, medium=fog), spp=512, device=device)
    assert_mean_matches(r, 1 / (1 - a), what="chromatic medium furnace")


def test_emissive_medium_in_black_emitting_box(device):
    """Black walls emitting Le around a medium emitting sigma_a * Le: L = Le everywhere, whatever
    the albedo or phase function (the medium is in equilibrium with the walls)."""
    Le = 0.7
    fog = medium([1.0, 2.0, 0.5], [0.3, 0.6, 0.0], g=0.3, radiance=Le)
    r = render(furnace(0.0, radiance=Le, medium=fog), spp=512, device=device)
    assert_mean_matches(r, Le, what="emissive medium")


def _sphere_of_medium(device, bsdf, med, cam_medium=None, outer=None, spp=256):
    """Albedo-1 sphere(s) in a constant environment of radiance 1, seen by the camera."""
    shapes = []
    if outer is not None:
        shapes.append(sphere((0, 0, 0), 3.0, Bsdf("null"), interior=outer))
    shapes.append(sphere((0, 0, 0), 1.0, bsdf, interior=med, exterior=outer))
    cam = camera(12, 12, fov=45, to_world=look_at((0, 0, 2.5), (0, 0, 0)), medium=cam_medium)
    return render(scene(shapes, [constant_env(1.0)], cam=cam), spp=spp, device=device)


@pytest.mark.parametrize("g", [-0.9, 0.0, 0.9])
def test_albedo_one_sphere_behind_null_boundary_renders_one(device, g):
    r = _sphere_of_medium(device, Bsdf("null"), medium(3.0, 1.0, g=g))
    assert_mean_matches(r, 1.0, what=f"null-bounded sphere g={g}")


def test_albedo_one_chromatic_sphere_renders_one(device):
    r = _sphere_of_medium(device, Bsdf("null"), medium([0.5, 3.0, 8.0], 1.0, g=0.6))
    assert_mean_matches(r, 1.0, what="chromatic sphere")


def test_albedo_one_sphere_behind_index_matched_dielectric_renders_one(device):
    r = _sphere_of_medium(device, Bsdf("dielectric", int_ior=1.33, ext_ior=1.33), medium(3.0, 1.0, g=0.5))
    assert_mean_matches(r, 1.0, what="index-matched dielectric sphere")


def test_albedo_one_sphere_behind_glass_renders_one(device):
    """A refracting boundary loses no energy either: a white furnace stays white."""
    r = _sphere_of_medium(device, Bsdf("dielectric", int_ior=1.5, ext_ior=1.0), medium(2.0, 1.0, g=0.0))
    assert_mean_matches(r, 1.0, what="glass sphere of albedo-1 medium")


def test_nested_media_with_camera_inside_the_outer_one(device):
    """An albedo-1 sphere inside a larger albedo-1 fog sphere, camera inside the fog: 1 everywhere."""
    fog = medium(0.4, 1.0, g=-0.3)
    core = medium([2.0, 4.0, 1.0], 1.0, g=0.8)
    r = _sphere_of_medium(device, Bsdf("null"), core, cam_medium=fog, outer=fog)
    assert_mean_matches(r, 1.0, what="nested media")


NORI_FURNACE = Path(__file__).resolve().parent.parent.parent / "shared" / "nori" / "furnace" / "furnace.obj"


@pytest.mark.skipif(not NORI_FURNACE.is_file(), reason="../shared/nori is not beside the checkout")
@pytest.mark.parametrize("g", [-0.9, 0.0, 0.9])
def test_nori_furnace_filled_with_albedo_one_medium(device, tmp_path, g):
    """Nori's own furnace box (camera inside, emitting 1, diffuse albedo 0.5) filled with an
    albedo-1 medium through the Nori dialect's scene-level <medium>: L = 1 / (1 - a) = 2."""
    xml = tmp_path / "furnace_medium.xml"
    xml.write_text(f"""<scene>
    <integrator type="vol_path"/>
    <camera type="perspective"><float name="fov" value="10"/>
        <integer name="width" value="2"/><integer name="height" value="2"/></camera>
    <sampler type="independent"><integer name="sampleCount" value="4096"/></sampler>
    <medium type="homogeneous">
        <color name="sigma_s" value="3, 3, 3"/><color name="sigma_a" value="0, 0, 0"/>
        <float name="g" value="{g}"/>
    </medium>
    <mesh type="obj"><string name="filename" value="{NORI_FURNACE}"/>
        <bsdf type="diffuse"><color name="albedo" value="0.5, 0.5, 0.5"/></bsdf>
        <emitter type="area"><color name="radiance" value="1, 1, 1"/></emitter>
    </mesh>
</scene>""")
    r = render(load(xml), device=device)
    assert_mean_matches(r, 2.0, blocks=1, what=f"Nori furnace with medium g={g}")
