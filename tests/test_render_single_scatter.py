"""Single scattering in a fog cube bounded by a null mesh, lit by an area light just above it:
volcl (max_depth = 2) against numerical quadrature of the single-scattering integral.

This is where media bounded by surfaces go wrong in practice: next-event estimation from points
just under the boundary must leave the medium at the boundary (the light sits in vacuum), and
phase-sampled rays that cross the boundary and hit the light must be weighted consistently.
"""
import math

import numpy as np
import pytest

from imagestats import assert_mean_matches
from scenebuild import box_mesh, camera, diffuse, look_at, medium, quad_mesh, scene
from volcl.renderer import render
from volcl.scene.model import Bsdf, Shape, rgb

pytestmark = pytest.mark.every_implementation

SIGMA, ALBEDO, G, LE = 1.0, 0.95, 0.6, 30.0
LIGHT_Y, LIGHT_HALF = 1.175, 0.3


def _scene(width, height):
    fog = medium(SIGMA, ALBEDO, g=G)
    cv, cf = box_mesh(half=1.0, inward=False)
    cube = Shape("mesh", Bsdf("null"), vertices=cv, faces=cf, interior=fog)
    lv, lf = quad_mesh((0, LIGHT_Y, 0), (LIGHT_HALF, 0, 0), (0, 0, LIGHT_HALF))     # faces -y
    light = Shape("mesh", diffuse(0.0), vertices=lv, faces=lf, emitter_radiance=rgb(LE))
    cam = camera(width, height, fov=4, to_world=look_at((0, 0.85, 3.0), (0, 0.85, 0)))
    return scene([cube, light], cam=cam, max_depth=2), cam


def _box_span(o, d):
    """Entry and exit distances of rays o + t d through [-1, 1]^3 (rows of d)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t0, t1 = (-1 - o) / d, (1 - o) / d
    lo = np.nanmax(np.minimum(t0, t1), axis=-1)
    hi = np.nanmin(np.maximum(t0, t1), axis=-1)
    return np.maximum(lo, 0.0), hi


def _single_scattering(o, d, n_t, n_light):
    """Midpoint quadrature over distance along the ray and over the light's area."""
    t0, t1 = _box_span(o[None], d[None])
    t0, t1 = float(t0[0]), float(t1[0])
    if not t1 > t0:
        return 0.0
    ts = t0 + (np.arange(n_t) + 0.5) / n_t * (t1 - t0)
    x = o + ts[:, None] * d
    g = ((np.arange(n_light) + 0.5) / n_light * 2 - 1) * LIGHT_HALF
    lx, lz = np.meshgrid(g, g)
    lp = np.stack([lx, np.full_like(lx, LIGHT_Y), lz], -1).reshape(-1, 3)
    v = lp[None] - x[:, None]
    dist = np.linalg.norm(v, axis=-1)
    w = v / dist[..., None]
    cos_light = np.maximum(w[..., 1], 0.0)       # the light's normal is -y
    _, exit_t = _box_span(np.repeat(x[:, None], len(lp), 1), w)
    transmittance = np.exp(-SIGMA * np.minimum(exit_t, dist))
    cos_theta = (w * d).sum(-1)
    phase = (1 - G * G) / (4 * math.pi * (1 + G * G - 2 * G * cos_theta) ** 1.5)
    d_area = (2 * LIGHT_HALF / n_light) ** 2
    inner = (LE * phase * transmittance * cos_light / dist ** 2 * d_area).sum(-1)
    dt = (t1 - t0) / n_t
    return float((np.exp(-SIGMA * (ts - t0)) * SIGMA * ALBEDO * inner * dt).sum())


def _expected_image(cam, n_t, n_light, sub):
    """Per-pixel single scattering, averaged over sub x sub points of each pixel (box filter)."""
    w, h = cam.width, cam.height
    tx = math.tan(math.radians(cam.fov) / 2)
    ty = tx * h / w
    m = cam.to_world
    offsets = (np.arange(sub) + 0.5) / sub
    out = np.zeros((h, w))
    for py in range(h):
        for px in range(w):
            for ox in offsets:
                for oy in offsets:
                    sx, sy = (px + ox) / w, (py + oy) / h
                    dc = np.array([(1 - 2 * sx) * tx, (1 - 2 * sy) * ty, 1.0])
                    d = m[:3, :3] @ dc
                    out[py, px] += _single_scattering(m[:3, 3], d / np.linalg.norm(d), n_t, n_light)
    return out / sub ** 2


def test_single_scattering_through_null_mesh_boundary_matches_quadrature(device):
    sc, cam = _scene(5, 5)
    result = render(sc, spp=4096, device=device)
    coarse = _expected_image(cam, 100, 24, 1)
    fine = _expected_image(cam, 200, 40, 2)
    # quadrature and pixel footprint must be resolved far below the render's noise for the
    # comparison to mean anything
    se = np.sqrt(result.variance.mean(-1))
    assert np.all(np.abs(fine - coarse) < 0.2 * np.maximum(se, 1e-4)), "quadrature not converged"
    assert fine.max() > 0.5, "the view should show lit fog"
    assert_mean_matches(result, np.repeat(fine[..., None], 3, -1), blocks=1, what="single scattering")
