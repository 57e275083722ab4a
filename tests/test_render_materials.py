"""Rough and layered bsdfs in whole renders with known answers: a sphere in a uniform environment
of radiance 1 (a white furnace) never renders brighter than 1, and renders exactly 1 where the
material loses nothing (a thin dielectric; a rough dielectric of index 1 with little roughness,
which disappears). Media inside rough glass are entered and left through it."""
import numpy as np
import pytest

from imagestats import assert_mean_matches, z_limit
from scenebuild import camera, look_at, scene
from test_render_surfaces import _silhouette_coverage
from volcl import render
from volcl.scene.model import Bsdf, Emitter, Medium, Shape, rgb

pytestmark = pytest.mark.every_implementation


def sphere_scene(bsdf, medium=None):
    cam = camera(16, 16, fov=30, to_world=look_at((0, 0, 5), (0, 0, 0)))
    ball = Shape("sphere", bsdf, center=np.zeros(3), radius=1.0, local=(np.zeros(3), 1.0), interior=medium)
    return scene([ball], [Emitter("constant", rgb(1.0))], cam=cam, media=[medium] if medium else [])


def furnace_render(bsdf, spp=256, medium=None):
    return render(sphere_scene(bsdf, medium), spp=spp)


def assert_not_above(result, bound, what, blocks=4):
    """No block of the image is brighter than `bound` beyond its standard error."""
    img, var = result.image.astype(np.float64), result.variance.astype(np.float64)
    h, w = img.shape[:2]
    limit = z_limit(3 * blocks * blocks)
    for i in range(blocks):
        for j in range(blocks):
            sl = (slice(i * h // blocks, (i + 1) * h // blocks), slice(j * w // blocks, (j + 1) * w // blocks))
            n = img[sl].shape[0] * img[sl].shape[1]
            mean = img[sl].reshape(-1, 3).mean(0)
            se = np.sqrt(var[sl].reshape(-1, 3).sum(0)) / n
            assert np.all(mean <= bound + limit * se + 1e-6), f"{what}: block ({i},{j}) mean {mean} above {bound}"
    assert result.invalid == 0


def rough(kind, **kw):
    defaults = dict(distribution="ggx", alpha_u=0.3, alpha_v=0.3)
    defaults.update(kw)
    return Bsdf(kind, **defaults)


@pytest.mark.parametrize("bsdf", [
    rough("roughconductor", alpha_u=0.5, alpha_v=0.5),
    rough("roughconductor", distribution="beckmann", alpha_u=0.1, alpha_v=0.6, anisotropic=True),
    rough("roughdielectric", int_ior=1.5, ext_ior=1.0),
    rough("roughdielectric", distribution="beckmann", alpha_u=1.0, alpha_v=1.0, int_ior=1.33, ext_ior=1.0),
    rough("roughplastic", reflectance=rgb(0.8), int_ior=1.49, ext_ior=1.0),
    Bsdf("plastic", reflectance=rgb(0.8), int_ior=1.49, ext_ior=1.0),
    Bsdf("mask", opacity=0.4, nested=Bsdf("diffuse", reflectance=rgb(0.8), twosided=True)),
], ids=["roughconductor", "roughconductor-anisotropic", "roughdielectric", "roughdielectric-beckmann-1",
        "roughplastic", "plastic", "mask"])
def test_white_furnace_never_above_one(device, bsdf):
    assert_not_above(furnace_render(bsdf), 1.0, bsdf.kind)


def test_lossless_thin_dielectric_is_invisible(device):
    r = furnace_render(Bsdf("thindielectric", int_ior=1.5, ext_ior=1.0), spp=128)
    assert_mean_matches(r, 1.0, what="thin dielectric")


def test_index_matched_rough_dielectric_disappears(device):
    """Index 1, roughness 1e-3: every path passes straight on, with no reflection, so the image has
    (next to) no noise; what it loses is the masking term G1 = 2 / (1 + sqrt(1 + alpha^2 tan^2)) of
    each crossing, below 1e-4 except within a degree of grazing, i.e. on the silhouette."""
    bsdf = rough("roughdielectric", alpha_u=1e-3, alpha_v=1e-3, int_ior=1.0, ext_ior=1.0)
    r = furnace_render(bsdf, spp=128)
    cam = camera(16, 16, fov=30, to_world=look_at((0, 0, 5), (0, 0, 0)))
    c = _silhouette_coverage(cam)
    inner = (c == 1.0) | (c == 0.0)
    img = r.image[inner].astype(np.float64)
    assert inner.sum() > 100 and r.invalid == 0
    assert np.all(img <= 1.0 + 1e-6) and np.all(img >= 1.0 - 1e-4), (img.min(), img.max())
    assert np.all(r.image <= 1.0 + 1e-6) and r.image.min() > 0.99


def test_rough_glass_holds_its_medium(device):
    """A scattering medium in rough glass (albedo 1, so the furnace still holds): light gets in and
    out through the rough surface and nothing exceeds the environment."""
    fog = Medium("homogeneous", sigma_t=rgb(2.0), albedo=rgb(1.0))
    r = furnace_render(rough("roughdielectric", alpha_u=0.2, alpha_v=0.2, int_ior=1.5, ext_ior=1.0), medium=fog)
    assert_not_above(r, 1.0, "rough glass with medium")
    assert r.image.mean() > 0.5
