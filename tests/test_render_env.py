"""Rendering with environment maps and spot lights against analytic answers, with tolerances from
the renders' own variance: a constant envmap equals `constant`; albedo-1 media (homogeneous and
grid, behind null boundaries) under a uniform envmap render 1 everywhere whatever the estimator;
single scattering in a thin slab under a uniform environment (where pbrt-v4 once rendered env-lit
media too dark, its issues 221 and 277) against quadrature; a spot light on a plane against its
irradiance."""
import math

import numpy as np
import pytest
from scipy import integrate, special

from imagestats import assert_images_match, assert_mean_matches
from scenebuild import (box_mesh, camera, constant_env, cube_to_world, diffuse, grid, hetero_medium, look_at,
                        medium, quad_mesh, scene, sphere)
from test_render_surfaces import _plane_points, _plane_view, _silhouette_coverage
from volcl.estimator import Estimator
from volcl.renderer import render
from volcl.scene import transform as tf
from volcl.scene.model import Bsdf, Emitter, Shape, Texture, rgb

pytestmark = pytest.mark.every_implementation

OFF_AXIS = tf.rotate([1.0, 2.0, 3.0], 50.0)


def envmap(image, scale=1.0, to_world=OFF_AXIS):
    return Emitter("envmap", rgb(1.0), to_world=to_world, image=np.asarray(image, np.float32), scale=scale)


def uniform_map(value, h=8, w=16):
    return np.full((h, w, 3), value, np.float32)


def sky_map(h=16, w=32):
    """A bright band above a dark ground, with a sun: a map whose sampling matters."""
    theta = (np.arange(h) + 0.5) / h * np.pi
    sky = np.where(theta < np.pi / 2, 1.0 + 2.0 * np.cos(theta), 0.1)[:, None, None] * np.ones((h, w, 3))
    sky = sky * np.array([0.6, 0.8, 1.0])
    sky[h // 4, w // 3] = [200.0, 180.0, 150.0]
    return sky.astype(np.float32)


def test_constant_envmap_renders_like_constant(device):
    """A map of one colour and the constant emitter of that radiance: the same image (a diffuse
    sphere, a glass sphere and a medium behind a null boundary, lit only by them)."""
    shapes = [sphere((-0.9, 0, 0), 0.6, diffuse(0.6)),
              sphere((0.7, 0.4, 0), 0.5, Bsdf("dielectric", int_ior=1.5, ext_ior=1.0)),
              sphere((0.3, -0.7, 0.3), 0.5, Bsdf("null"), interior=medium([1.0, 2.0, 4.0], 0.8, g=0.4))]
    cam = camera(16, 16, fov=50, to_world=look_at((0, 0, 4), (0, 0, 0)))
    colour = [0.5, 1.0, 2.0]
    a = render(scene(shapes, [envmap(uniform_map(colour), scale=1.0)], cam=cam, seed=1), spp=256, device=device)
    b = render(scene(shapes, [constant_env(colour)], cam=cam, seed=2), spp=256, device=device)
    assert_images_match(a, b, blocks=4, what="constant envmap vs constant")


def test_diffuse_sphere_under_uniform_envmap(device):
    """A convex object sees only the map: L = a * Le on the sphere, Le around it (with the map's
    scale); with hide_emitters the background is black and the sphere unchanged."""
    a, le = 0.6, 1.5
    cam = camera(16, 16, fov=30, to_world=look_at((0, 0, 5), (0, 0, 0)))
    c = _silhouette_coverage(cam)
    on, off = c == 1.0, c == 0.0
    for hide in (False, True):
        sc = scene([sphere((0, 0, 0), 1.0, diffuse(a))], [envmap(uniform_map(0.5), scale=3.0)], cam=cam,
                   hide_emitters=hide)
        r = render(sc, spp=256, device=device)
        assert_mean_matches(r, a * le, mask=on, blocks=1, what=f"diffuse sphere (hide_emitters={hide})")
        if hide:
            # pixels clear of the silhouette (their neighbours are off the sphere too) see only the map
            clear = off.copy()
            clear[1:-1, 1:-1] &= off[:-2, 1:-1] & off[2:, 1:-1] & off[1:-1, :-2] & off[1:-1, 2:]
            assert clear.sum() > 10 and np.all(r.image[clear] == 0.0)
        else:
            assert_mean_matches(r, le, mask=off, blocks=1, what="the map around it")


def _albedo_one_ball(med, env, estimator=None, spp=256, seed=7):
    ball = sphere((0, 0, 0), 1.0, Bsdf("null"), interior=med)
    cam = camera(12, 12, fov=45, to_world=look_at((0, 0, 2.5), (0, 0, 0)))
    return render(scene([ball], [env], cam=cam, seed=seed), spp=spp, estimator=estimator)


@pytest.mark.parametrize("g", [0.0, 0.8])
@pytest.mark.parametrize("estimator", [Estimator(), Estimator(mis=False), Estimator(nee=False)],
                         ids=["mis", "nee-only", "phase-only"])
def test_albedo_one_medium_under_uniform_envmap_renders_one(device, g, estimator):
    """The environment's white furnace: light scattered without loss inside a null sphere under a
    uniform map comes out as the map's radiance, whichever technique finds the light."""
    r = _albedo_one_ball(medium(3.0, 1.0, g=g), envmap(uniform_map(0.25), scale=4.0), estimator)
    assert_mean_matches(r, 1.0, what=f"albedo-1 ball under a uniform envmap (g={g}, {estimator.describe()})")


def test_albedo_one_chromatic_grid_medium_under_uniform_envmap_renders_one(device):
    rng = np.random.default_rng(5)
    data = (rng.random((6, 7, 5, 3)) * np.array([1.0, 3.0, 8.0])).astype(np.float32)
    med = hetero_medium(grid(data, tf.rotate([0, 1, 1], 30) @ cube_to_world(-0.8, 0.8)), 1.0, g=0.5)
    r = _albedo_one_ball(med, envmap(uniform_map(1.0)))
    assert r.tracking_cutoffs == 0
    assert_mean_matches(r, 1.0, what="albedo-1 grid medium under a uniform envmap")


def test_estimators_agree_under_a_sky(device):
    """Under a map with a sun, light sampling, phase sampling and their MIS estimate one image."""
    med = medium([0.8, 1.2, 2.0], [0.9, 0.8, 0.7], g=0.6)
    env = envmap(sky_map(), to_world=tf.rotate([1, 0, 0], 20))
    mis = _albedo_one_ball(med, env, Estimator(), spp=512, seed=1)
    nee = _albedo_one_ball(med, env, Estimator(mis=False), spp=512, seed=2)
    phase = _albedo_one_ball(med, env, Estimator(nee=False), spp=2048, seed=3)
    assert_images_match(mis, nee, blocks=3, what="MIS vs NEE alone")
    assert_images_match(mis, phase, blocks=3, what="MIS vs phase sampling alone")


def slab_single_scattering(tau, albedo):
    """Radiance leaving an infinite slab of optical depth tau, isotropic scattering, along its normal,
    under a uniform environment of radiance 1, counting light scattered at most once: the light that
    crosses, exp(-tau), plus a/2 * integral over optical depth t of exp(-t) (E2(t) + E2(tau - t)),
    E2 being the transmittance averaged over the directions of a hemisphere (weighted by solid angle,
    1/(2 pi) integral of exp(-t / mu) dmu dphi)."""
    inner, _ = integrate.quad(lambda t: math.exp(-t) * (special.expn(2, t) + special.expn(2, tau - t)), 0.0, tau,
                              epsabs=1e-12, epsrel=1e-12, limit=200)
    return math.exp(-tau) + 0.5 * albedo * inner


@pytest.mark.parametrize("tau", [0.3, 2.0])
def test_thin_slab_single_scattering_under_uniform_envmap(device, tau):
    """A slab between null faces, seen head on through a narrow field of view, direct light only
    (max_depth 2): the transmitted map plus single scattering, against quadrature. NEE reaches the
    map through the slab's null faces with the medium's transmittance."""
    a, thickness = 0.8, 0.5
    sigma_t = tau / thickness
    v, f = box_mesh(1.0, inward=False)
    # 400 x 400 x 0.5: rays leaving through the sides have crossed >= 400 / 0.5 = 800 slab
    # thicknesses sideways... only at mu < 1e-3 of the normal, a solid-angle share of 1e-3
    # weighted by a transmittance exp(-tau * 800): nothing
    slab_v = v * np.array([200.0, 200.0, thickness / 2])
    slab = Shape("mesh", Bsdf("null"), vertices=slab_v, faces=f, interior=medium(sigma_t, a))
    cam = camera(4, 4, fov=2, to_world=look_at((0, 0, 3), (0, 0, 0)))
    r = render(scene([slab], [envmap(uniform_map(1.0))], cam=cam, max_depth=2), spp=8192, device=device)
    assert_mean_matches(r, slab_single_scattering(tau, a), blocks=1, what=f"single scattering, tau={tau}")


def test_spot_light_on_a_plane(device):
    """Direct light from a tilted spot: L = I falloff(angle) cos / d^2 * R / pi, averaged over each
    pixel's footprint; the falloff is Mitsuba's (full within the beam, linear in angle to the
    cutoff)."""
    cam = _plane_view(12, 12)
    verts, faces = quad_mesh((0, 0, 0), (5, 0, 0), (0, 5, 0))
    R, I = 0.7, np.array([3.0, 2.0, 1.0])
    cutoff, beam = 25.0, 15.0
    origin = np.array([0.3, -0.2, 1.2])
    to_world = tf.lookat(origin, [0.0, 0.1, 0.0], [0.0, 1.0, 0.0])
    spot = Emitter("spot", rgb(I), position=origin, to_world=to_world, cutoff_angle=cutoff, beam_width=beam)
    plane = Shape("mesh", diffuse(R), vertices=verts, faces=faces)
    r = render(scene([plane], [spot], cam=cam, max_depth=2), spp=256, device=device)
    p = _plane_points(cam, sub=48)
    v = origin - p
    d2 = (v ** 2).sum(-1)
    axis = to_world[:3, 2] / np.linalg.norm(to_world[:3, 2])
    angle = np.degrees(np.arccos(np.clip((-v @ axis) / np.sqrt(d2), -1, 1)))
    falloff = np.where(angle < cutoff, np.clip((cutoff - angle) / (cutoff - beam), 0, 1), 0.0)
    irradiance = falloff * (v[..., 2] / np.sqrt(d2)) / d2
    expected = irradiance.mean(axis=(1, 3))[..., None] * I * R / math.pi
    lit = expected[..., 0] > 0
    assert 10 < lit.sum() < 144 - 10
    assert_mean_matches(r, expected, what="spot light on a plane")


def test_spot_in_fog_with_and_without_equiangular_sampling(device):
    """A spot inside a fog box: equiangular sampling (two- and one-sample MIS, and alone) estimates
    the image distance sampling alone does; the falloff is part of what the equiangular vertex sees."""
    fog = medium(0.4, 0.8, g=0.3)
    v, f = box_mesh(1.5, inward=False)
    box = Shape("mesh", Bsdf("null"), vertices=v, faces=f, interior=fog)
    fv, ff = quad_mesh((0, -1.4, 0), (1.4, 0, 0), (0, 0, -1.4))
    floor = Shape("mesh", diffuse(0.5), vertices=fv, faces=ff, exterior=fog)
    to_world = tf.lookat([0.2, 1.0, 0.1], [-0.3, -1.4, 0.2], [0.0, 0.0, 1.0])
    spot = Emitter("spot", rgb(6.0), position=to_world[:3, 3], to_world=to_world, cutoff_angle=30.0, beam_width=20.0)
    cam = camera(16, 16, fov=60, to_world=look_at((0, 0, 4), (0, -0.2, 0)))
    images = {}
    for seed, (name, est) in enumerate([("distance", Estimator(equiangular="off")),
                                        ("two-sample", Estimator(equiangular="on")),
                                        ("one-sample", Estimator(equiangular="on", equiangular_mis="one")),
                                        ("equiangular alone", Estimator(equiangular="on", mis=False))]):
        sc = scene([box, floor], [spot], cam=cam, seed=seed, max_depth=6)
        images[name] = render(sc, spp=512, device=device, estimator=est)
    for name in ("two-sample", "one-sample", "equiangular alone"):
        assert_images_match(images[name], images["distance"], blocks=4, what=f"spot in fog: {name} vs distance")


def test_textured_spot_on_a_plane(device):
    """A spot projecting a checkerboard (Mitsuba's `texture`): the light's frame direction w maps to
    uv = 1/2 + w.xy / (2 w.z tan(cutoff)), and the plane receives I falloff tex(uv) cos / d^2."""
    cam = _plane_view(12, 12)
    verts, faces = quad_mesh((0, 0, 0), (5, 0, 0), (0, 5, 0))
    R, I = 0.7, np.array([3.0, 2.0, 1.0])
    cutoff, beam = 30.0, 20.0
    c0, c1 = np.array([1.0, 0.8, 0.6]), np.array([0.1, 0.2, 0.3])
    origin = np.array([0.2, -0.1, 1.3])
    to_world = tf.lookat(origin, [0.0, 0.05, 0.0], [0.0, 1.0, 0.0])
    checker = Texture("checkerboard", color0=rgb(c0), color1=rgb(c1), to_uv=np.diag([3.0, 3.0, 1.0]))
    spot = Emitter("spot", rgb(I), position=origin, to_world=to_world, cutoff_angle=cutoff, beam_width=beam,
                   texture=checker)
    plane = Shape("mesh", diffuse(R), vertices=verts, faces=faces)
    r = render(scene([plane], [spot], cam=cam, max_depth=2), spp=256, device=device)
    p = _plane_points(cam, sub=48)
    v = origin - p
    d2 = (v ** 2).sum(-1)
    local = (-v) @ np.linalg.inv(to_world[:3, :3]).T
    angle = np.degrees(np.arccos(np.clip(local[..., 2] / np.linalg.norm(local, axis=-1), -1, 1)))
    falloff = np.where(angle < cutoff, np.clip((cutoff - angle) / (cutoff - beam), 0, 1), 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = 0.5 + local[..., :2] / (2 * local[..., 2:3] * math.tan(math.radians(cutoff)))
    f = np.mod(np.nan_to_num(uv) * 3.0, 1.0)      # outside the cone the falloff is 0
    first = (f[..., 0] > 0.5) == (f[..., 1] > 0.5)
    tex = np.where(first[..., None], c0, c1)
    irradiance = (falloff * (v[..., 2] / np.sqrt(d2)) / d2)[..., None] * tex
    expected = irradiance.mean(axis=(1, 3)) * I * R / math.pi
    lit = expected[..., 0] > 0
    assert 10 < lit.sum() < 144 - 10
    assert_mean_matches(r, expected, what="textured spot light on a plane")
