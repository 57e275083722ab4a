"""Feature detection (which effects a scene calls for) and what it buys: the specialized kernel
builds for every shipped scene, and renders the same image as the kernel with every feature on."""
from pathlib import Path

import numpy as np
import pytest

from imagestats import assert_same_image
from scenebuild import box_mesh, camera, constant_env, diffuse, furnace, medium, quad_mesh, scene, sphere
from volcl.device import cl
from volcl.features import FLAGS, all_features, defines, detect
from volcl.program import build_program
from volcl.renderer import render
from volcl.scene import load
from volcl.scene.model import Bsdf, Emitter, Shape, rgb

SCENES = sorted((Path(__file__).resolve().parent.parent / "scenes").glob("*.xml"))


def on(features):
    return {k for k, v in features.items() if v}


def test_surface_only_scene_compiles_no_media_code():
    f = detect(furnace(0.5))
    assert on(f) == {"DIFFUSE", "AREA_LIGHTS"}


def test_grey_isotropic_medium():
    f = detect(furnace(0.5, medium=medium(1.0, 0.9)))
    assert on(f) == {"DIFFUSE", "AREA_LIGHTS", "MEDIA"}


@pytest.mark.parametrize("kw,flag", [
    (dict(sigma_t=[1.0, 2.0, 3.0], albedo=0.9), "CHROMATIC_MEDIA"),
    (dict(sigma_t=1.0, albedo=0.9, g=0.3), "HG"),
    (dict(sigma_t=1.0, albedo=0.5, radiance=1.0), "EMISSIVE_MEDIA"),
])
def test_each_medium_effect_has_its_flag(kw, flag):
    f = detect(furnace(0.5, medium=medium(**kw)))
    # an emissive medium also calls for next-event estimation towards it (the default estimator's)
    extra = {"EMISSION_NEE"} if flag == "EMISSIVE_MEDIA" else set()
    assert on(f) == {"DIFFUSE", "AREA_LIGHTS", "MEDIA", flag} | extra


def test_chromatic_albedo_alone_is_not_chromatic_extinction():
    """Only a channel-dependent sigma_t needs spectral MIS; an rgb albedo is free."""
    f = detect(furnace(0.5, medium=medium(1.0, [0.2, 0.5, 0.9])))
    assert not f["CHROMATIC_MEDIA"]


def test_bsdfs_lights_shapes_and_boundaries():
    fog = medium(1.0, 0.9)
    glass = sphere((0, 0, 0), 1.0, Bsdf("dielectric"), interior=fog)
    mirror = sphere((2, 0, 0), 0.5, Bsdf("conductor"))
    v, faces = quad_mesh((0, -1, 0), (3, 0, 0), (0, 0, 3))
    plane = Shape("mesh", diffuse(0.5), vertices=v, faces=faces, normals=np.tile([0, 1.0, 0], (4, 1)))
    hole = sphere((-2, 0, 0), 0.5, Bsdf("null"))
    sc = scene([glass, mirror, plane, hole],
               [Emitter("point", rgb(1.0), position=np.zeros(3)), Emitter("directional", rgb(1.0), direction=np.array([0, -1.0, 0])),
                constant_env(0.1)])
    # the point light at the origin sits inside the glass sphere's fog: equiangular sampling applies
    assert on(detect(sc)) == {"SPHERES", "SHADING_NORMALS", "DIFFUSE", "DIELECTRIC", "CONDUCTOR", "NULL_BSDF",
                              "POINT_LIGHTS", "DIRECTIONAL_LIGHTS", "ENV_LIGHTS", "MEDIA", "MEDIUM_BOUNDARIES",
                              "EQUIANGULAR"}


def test_defines_cover_every_flag_with_zero_or_one():
    d = defines(detect(furnace(0.5)))
    assert len(d) == len(FLAGS)
    assert all(x.endswith("=0") or x.endswith("=1") for x in d)


def test_kernel_builds_for_every_shipped_feature_set_and_all_on(device):
    ctx = cl.Context([device.device])
    sets = {tuple(sorted(detect(load(p)).items())) for p in SCENES}
    sets.add(tuple(sorted(all_features().items())))
    for s in sets:
        prog = build_program(ctx, dict(s))
        cl.Kernel(prog, "render_pass")      # creating the kernel forces the driver's final compile


@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
def test_specialized_and_all_features_kernels_agree(device, path):
    sc = load(path)
    sc.camera.width, sc.camera.height = 24, 18
    specialized = render(sc, spp=96, device=device, seed=1)
    everything = render(sc, spp=96, device=device, features=all_features(), seed=2)
    assert specialized.features != everything.features or on(specialized.features) == set(FLAGS)
    assert_same_image(specialized, everything, blocks=3, what=path.name)
