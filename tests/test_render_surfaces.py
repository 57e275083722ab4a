"""Surface rendering against analytic answers, with tolerances from the renders' own variance."""
import math

import numpy as np
import pytest

from imagestats import assert_mean_matches
from scenebuild import (box_mesh, camera, constant_env, diffuse, furnace, look_at, quad_mesh, scene,
                        sphere)
from volcl.renderer import render
from volcl.scene.model import Bsdf, Emitter, Shape, rgb

pytestmark = pytest.mark.every_implementation


@pytest.mark.parametrize("albedo", [0.5, 0.8])
def test_furnace_converges_to_geometric_series(device, albedo):
    """Nori's furnace: L = 1 / (1 - a) in every direction."""
    r = render(furnace(albedo), spp=512, device=device)
    assert_mean_matches(r, 1 / (1 - albedo), what=f"furnace a={albedo}")


@pytest.mark.parametrize("max_depth", [1, 2, 3, 5])
def test_max_depth_has_mitsubas_meaning(device, max_depth):
    """max_depth counts vertices: 1 = emitters only, 2 = one bounce, ... so L = sum_{k < max_depth} a^k."""
    a = 0.6
    r = render(furnace(a, max_depth=max_depth), spp=256, device=device)
    assert_mean_matches(r, sum(a ** k for k in range(max_depth)), what=f"max_depth={max_depth}")


def test_hide_emitters(device):
    sc = furnace(0.5)
    sc.integrator.hide_emitters = True
    r = render(sc, spp=512, device=device)
    assert_mean_matches(r, 1 / (1 - 0.5) - 1, what="hidden emitters")


def _plane_view(width=12, height=12):
    """Camera 2 units above the plane z = 0, looking straight down; (px, py) -> world point."""
    cam = camera(width, height, fov=40, to_world=look_at((0, 0, 2), (0, 0, 0), up=(0, 1, 0)))
    return cam


def _plane_points(cam, sub=8):
    """World points on z = 0 seen through each pixel, on a sub x sub grid per pixel (box filter)."""
    w, h = cam.width, cam.height
    tx = math.tan(math.radians(cam.fov) / 2)
    ty = tx * h / w
    off = (np.arange(sub) + 0.5) / sub
    px = (np.arange(w)[:, None] + off[None]).reshape(-1)
    py = (np.arange(h)[:, None] + off[None]).reshape(-1)
    sx, sy = np.meshgrid(px / w, py / h)
    dc = np.stack([(1 - 2 * sx) * tx, (1 - 2 * sy) * ty, np.ones_like(sx)], -1)
    m = cam.to_world
    dw = dc @ m[:3, :3].T
    o = m[:3, 3]
    t = -o[2] / dw[..., 2]
    p = o + t[..., None] * dw
    return p.reshape(h, sub, w, sub, 3)


def test_point_light_on_diffuse_plane(device):
    """Direct lighting from a point light: L = I cos / d^2 * R / pi, averaged over each pixel."""
    cam = _plane_view()
    verts, faces = quad_mesh((0, 0, 0), (5, 0, 0), (0, 5, 0))
    R, I = 0.7, 3.0
    light_pos = np.array([0.4, -0.3, 1.0])
    plane = Shape("mesh", diffuse(R), vertices=verts, faces=faces)
    sc = scene([plane], [Emitter("point", rgb(I), position=light_pos)], cam=cam, max_depth=2)
    r = render(sc, spp=64, device=device)
    p = _plane_points(cam)
    v = light_pos - p
    d2 = (v ** 2).sum(-1)
    expected = (I * (v[..., 2] / np.sqrt(d2)) / d2 * R / math.pi).mean(axis=(1, 3))
    # the only randomness is the position inside the pixel; compare to the pixel-footprint average
    assert_mean_matches(r, np.repeat(expected[..., None], 3, -1), what="point light")


def test_directional_light_on_diffuse_plane(device):
    cam = _plane_view()
    verts, faces = quad_mesh((0, 0, 0), (5, 0, 0), (0, 5, 0))
    R, E = 0.5, 2.0
    direction = np.array([0.3, 0.2, -1.0])
    cos = -direction[2] / np.linalg.norm(direction)
    plane = Shape("mesh", diffuse(R), vertices=verts, faces=faces)
    sc = scene([plane], [Emitter("directional", rgb(E), direction=direction)], cam=cam, max_depth=2)
    r = render(sc, spp=16, device=device)
    np.testing.assert_allclose(r.image, E * cos * R / math.pi, rtol=1e-5)


def _sphere_in_env(device, bsdf, spp=256, width=16):
    cam = camera(width, width, fov=30, to_world=look_at((0, 0, 5), (0, 0, 0)))
    sc = scene([sphere((0, 0, 0), 1.0, bsdf)], [constant_env(1.0)], cam=cam)
    return render(sc, spp=spp, device=device)


def test_diffuse_sphere_in_constant_environment(device):
    """A convex object sees only the environment: L = a * Le on the sphere, Le around it."""
    a = 0.6
    r = _sphere_in_env(device, diffuse(a))
    cam = camera(16, 16, fov=30, to_world=look_at((0, 0, 5), (0, 0, 0)))
    # pixels entirely on or off the sphere (the silhouette pixels mix both)
    c = _silhouette_coverage(cam)
    on, off = c == 1.0, c == 0.0
    assert on.sum() > 10 and off.sum() > 10
    assert_mean_matches(r, a, mask=on, blocks=1, what="diffuse sphere")
    assert_mean_matches(r, 1.0, mask=off, blocks=1, what="environment")


def _silhouette_coverage(cam, sub=8):
    w, h = cam.width, cam.height
    tx = math.tan(math.radians(cam.fov) / 2)
    ty = tx * h / w
    off = (np.arange(sub) + 0.5) / sub
    sx, sy = np.meshgrid((np.arange(w)[:, None] + off).reshape(-1) / w, (np.arange(h)[:, None] + off).reshape(-1) / h)
    dc = np.stack([(1 - 2 * sx) * tx, (1 - 2 * sy) * ty, np.ones_like(sx)], -1)
    d = dc @ cam.to_world[:3, :3].T
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    o = cam.to_world[:3, 3]
    b = d @ o
    hit = (b * b - (o @ o - 1.0)) > 0
    # pessimistic: a pixel counts as covered/uncovered only if all its sub-samples and a margin agree
    return hit.reshape(h, sub, w, sub).mean(axis=(1, 3))


@pytest.mark.parametrize("bsdf", [
    Bsdf("dielectric", int_ior=1.5, ext_ior=1.0),
    Bsdf("dielectric", int_ior=1.0, ext_ior=1.0),
    Bsdf("conductor", eta=None),
], ids=["glass", "index-matched", "mirror"])
def test_lossless_sphere_in_constant_environment_is_invisible(device, bsdf):
    """Glass and perfect mirrors lose no energy: in a uniform environment they render as Le."""
    r = _sphere_in_env(device, bsdf, spp=128)
    assert_mean_matches(r, 1.0, what=bsdf.kind)


def test_area_light_mis_matches_without_nee_limit(device):
    """A small one-sided area light over a diffuse floor, direct lighting only: the MIS estimate
    equals the analytic irradiance integral, computed by numerical quadrature over the light."""
    cam = _plane_view(8, 8)
    floor_v, floor_f = quad_mesh((0, 0, 0), (5, 0, 0), (0, 5, 0))
    lv, lf = quad_mesh((0.2, 0.1, 1.0), (0.15, 0, 0), (0, -0.15, 0))   # faces down (-z)
    R, Le = 0.8, 10.0
    floor = Shape("mesh", diffuse(R), vertices=floor_v, faces=floor_f)
    light = Shape("mesh", diffuse(0.0), vertices=lv, faces=lf, emitter_radiance=rgb(Le))
    sc = scene([floor, light], cam=cam, max_depth=2)
    r = render(sc, spp=1024, device=device)
    p = _plane_points(cam, sub=4)
    # irradiance from the light by midpoint quadrature over a 40x40 grid on it
    g = (np.arange(40) + 0.5) / 40 * 2 - 1
    lx, ly = np.meshgrid(0.2 + 0.15 * g, 0.1 + 0.15 * g)
    q = np.stack([lx, ly, np.ones_like(lx)], -1).reshape(-1, 3)
    dA = (0.3 / 40) ** 2
    v = q[None, None, None, None] - p[..., None, :]
    d2 = (v ** 2).sum(-1)
    cos_r = v[..., 2] / np.sqrt(d2)
    E = (Le * cos_r * cos_r / d2 * dA).sum(-1)
    expected = (E * R / math.pi).mean(axis=(1, 3))
    # the camera also sees the light's back (one-sided: black) where it covers the floor
    lit_view = np.ones_like(expected, bool)
    assert_mean_matches(r, np.repeat(expected[..., None], 3, -1), mask=_not_behind_light(cam, p), blocks=2,
                        what="area light")


def _not_behind_light(cam, p):
    """Pixels whose footprint on the floor is not hidden behind the light quad (seen from above)."""
    o = cam.to_world[:3, 3]
    d = p - o
    t = (1.0 - o[2]) / d[..., 2]
    q = o + t[..., None] * d
    inside = (np.abs(q[..., 0] - 0.2) <= 0.16) & (np.abs(q[..., 1] - 0.1) <= 0.16)
    return ~inside.any(axis=(1, 3))
