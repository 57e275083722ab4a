"""Equiangular sampling (kernels/equiangular.h) against its pdf, and its use in the path loop: a point
light in fog renders the same image with and without it, and the analytic single-scattering answer."""
import math

import numpy as np
import pytest

from conftest import run_kernel
from imagestats import assert_mean_matches, assert_same_image
from scenebuild import camera, look_at, medium, scene
from stats import assert_integrates_to_one, chi2_1d, line_rule
from volcl.estimator import Estimator
from volcl.features import detect
from volcl.phase import pdf as phase_pdf
from volcl.renderer import render
from volcl.scene.model import Emitter, rgb

pytestmark = pytest.mark.every_implementation

SPAN = 1000.0   # EQUIANGULAR_SPAN in kernels/equiangular.h

# (what, origin, direction, light, t_max)
CASES = [
    ("light beside the middle", (0, 0, 0), (1, 0, 0), (2.0, 0.5, 0.0), 5.0),
    ("light behind the origin", (0.5, -1, 2), (0, 1, 0), (0.3, -2.0, 2.2), 3.0),
    ("light beyond the end", (0, 0, 0), (0, 0, -1), (1.0, 0.0, -6.0), 4.0),
    ("oblique ray, light close to it", (1, 2, 3), (0.48, 0.6, 0.64), (1.9, 3.25, 4.25), 4.0),
    ("infinite segment", (0, 0, 0), (0, 1, 0), (0.2, 1.0, 0.0), math.inf),
]


def reference_pdf(o, d, light, t_max):
    """The equiangular pdf in float64, clipped to |t - delta| <= SPAN h like the kernel."""
    o, d, light = (np.asarray(a, np.float64) for a in (o, d, light))
    d = d / np.linalg.norm(d)
    delta = (light - o) @ d
    h = np.linalg.norm(light - o - delta * d)
    t0, t1 = max(0.0, delta - SPAN * h), min(t_max, delta + SPAN * h)
    theta = math.atan((t1 - delta) / h) - math.atan((t0 - delta) / h)

    def pdf(t):
        t = np.asarray(t, np.float64)
        inside = (t >= t0) & (t <= t1)
        return np.where(inside, h / (theta * (h * h + (t - delta) ** 2)), 0.0)
    return pdf, t0, t1


def _cfg(o, d, light, t_max):
    d = np.asarray(d, np.float64) / np.linalg.norm(d)
    return np.array([*o, *d, *light, t_max], np.float32)


def _sample(cl_env, prog, case, n, seed=1):
    _, o, d, light, t_max = case
    u = np.random.default_rng(seed).random(n, dtype=np.float32)
    t, pdf, again, ok = run_kernel(cl_env, prog, "equiangular_sample", n,
                                   [(np.float32, ()), (np.float32, ()), (np.float32, ()), (np.int32, ())],
                                   inputs=[_cfg(o, d, light, t_max), u])
    return t.astype(np.float64), pdf.astype(np.float64), again.astype(np.float64), ok


@pytest.fixture(scope="module")
def prog(test_program):
    return test_program("equiangular_tests.cl")


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_samples_follow_the_pdf(cl_env, prog, case):
    what, o, d, light, t_max = case
    t, pdf, again, ok = _sample(cl_env, prog, case, 200_000)
    assert ok.all(), f"{what}: {np.count_nonzero(ok == 0)} samples failed"
    ref, t0, t1 = reference_pdf(o, d, light, t_max)
    # the pdf the sampler reports, and the one sample_equiangular_pdf evaluates, are the density
    np.testing.assert_allclose(pdf, ref(t), rtol=2e-4, err_msg=f"{what}: reported pdf")
    np.testing.assert_array_equal(pdf, again, err_msg=f"{what}: sampler and pdf routine disagree")
    if math.isfinite(t_max):
        chi2_1d(t, ref, t0, t1 * (1 + 1e-7), what=f"equiangular, {what}")
    else:
        # a tail out to delta + SPAN h: test in y = log(1 + t), where the cells resolve the peak
        y = np.log1p(t)
        chi2_1d(y, lambda y: ref(np.expm1(y)) * np.exp(y), 0.0, math.log1p(t1) * (1 + 1e-7),
                what=f"equiangular, {what}")


@pytest.mark.parametrize("case", CASES[:4], ids=[c[0] for c in CASES[:4]])
def test_device_pdf_integrates_to_one(cl_env, prog, case):
    what, o, d, light, t_max = case
    ref, t0, t1 = reference_pdf(o, d, light, t_max)
    x, w = line_rule(ref, t0, t1, tol=1e-9)
    (p,) = run_kernel(cl_env, prog, "equiangular_pdf", len(x), [(np.float32, ())],
                      inputs=[_cfg(o, d, light, t_max), x.astype(np.float32)])
    assert_integrates_to_one(float(np.sum(w * p)), 1e-4, f"equiangular pdf, {what}")


def test_no_sample_for_a_light_on_the_rays_line(cl_env, prog):
    """The integrand is singular there (a measure-zero set of rays); the sampler declines and the pdf
    is zero, which leaves those distances to distance sampling with MIS weight one."""
    case = ("on the line", (0, 0, 0), (1, 0, 0), (2.0, 0.0, 0.0), 5.0)
    t, pdf, again, ok = _sample(cl_env, prog, case, 64)
    assert not ok.any() and (pdf == 0).all()


def test_pdf_is_zero_outside_the_segment(cl_env, prog):
    _, o, d, light, t_max = CASES[0]
    ts = np.array([-0.5, -1e-6, 5.0 + 1e-3, 7.0, 1e30], np.float32)
    (p,) = run_kernel(cl_env, prog, "equiangular_pdf", len(ts), [(np.float32, ())],
                      inputs=[_cfg(o, d, light, t_max), ts])
    assert (p == 0).all()


# ---- in the path loop ------------------------------------------------------------------------


def _fog_scene(sigma_t=0.5, albedo=0.8, g=0.3, width=16, height=16, max_depth=2, phase=None):
    """Camera and point light inside an infinite homogeneous medium (no surfaces); `phase`, a model
    Phase, replaces the HG phase function of asymmetry g."""
    fog = medium(sigma_t, albedo, g=g)
    if phase is not None:
        fog.phase = phase
    cam = camera(width, height, fov=40, to_world=look_at((0, 0, 0), (0, 0, -1)), medium=fog)
    light = Emitter("point", rgb(5.0), position=np.array([0.37, -0.21, -2.0]))
    return scene([], [light], cam=cam, max_depth=max_depth, media=[fog])


def _single_scattering(sc, sub=6, panels=64, order=8):
    """Pixel means of the single-scattered light of the point light seen by the camera (box
    filter), by Gauss-Legendre quadrature: per ray, over the angle theta seen from the light (the
    substitution s - delta = h tan(theta) turns ds / r^2 into d(theta) / h, smooth everywhere)."""
    cam, fog = sc.camera, sc.media[0]
    w, h = cam.width, cam.height
    tx = math.tan(math.radians(cam.fov) / 2)
    ty = tx * h / w
    gx, gw = np.polynomial.legendre.leggauss(sub)
    off = 0.5 * (gx + 1)
    px = (np.arange(w)[:, None] + off[None]).ravel() / w
    py = (np.arange(h)[:, None] + off[None]).ravel() / h
    sx, sy = np.meshgrid(px, py)                                 # (h*sub, w*sub)
    dc = np.stack([(1 - 2 * sx) * tx, (1 - 2 * sy) * ty, np.ones_like(sx)], -1)
    along = np.linalg.norm(dc, axis=-1)
    m = cam.to_world
    dw = dc @ m[:3, :3].T
    dw /= np.linalg.norm(dw, axis=-1, keepdims=True)
    o = m[:3, 3]
    lp = sc.emitters[0].position
    intensity = sc.emitters[0].value[0]
    sigma_t = fog.sigma_t[0]
    sigma_s = sigma_t * fog.albedo[0]
    s0, s1 = cam.near_clip * along, cam.far_clip * along
    delta = (lp - o) @ dw.reshape(-1, 3).T
    delta = delta.reshape(along.shape)
    hh = np.linalg.norm(lp - o - delta[..., None] * dw, axis=-1)
    th0, th1 = np.arctan((s0 - delta) / hh), np.arctan((s1 - delta) / hh)
    nx, nw = np.polynomial.legendre.leggauss(order)
    edges = np.linspace(0, 1, panels + 1)
    a = edges[:-1, None] + (edges[1:, None] - edges[:-1, None]) * 0.5 * (nx[None] + 1)   # (panels, order)
    wts = ((edges[1:] - edges[:-1])[:, None] * 0.5 * nw[None]).ravel()
    frac = a.ravel()
    theta = th0[..., None] + (th1 - th0)[..., None] * frac          # (..., k)
    s = delta[..., None] + hh[..., None] * np.tan(theta)
    r = hh[..., None] / np.cos(theta)
    p = o + s[..., None] * dw[..., None, :]
    wi = (lp - p) / np.linalg.norm(lp - p, axis=-1, keepdims=True)
    cos = (wi * dw[..., None, :]).sum(-1)
    phase = phase_pdf(fog.phase, cos)      # float64 (HG: (1 - g^2) / (4 pi (1 + g^2 - 2 g cos)^1.5))
    f = np.exp(-sigma_t * (s - s0[..., None] + r)) * sigma_s * phase * intensity / hh[..., None]
    L = (f * wts).sum(-1) * (th1 - th0)
    # the kernel's ray starts at the near clip plane; transmittance counts from there (s - s0)
    L = L.reshape(h, sub, w, sub)
    pix = np.einsum("yaxb,a,b->yx", L, gw / 2, gw / 2)
    return pix


def _light_pixel_mask(sc):
    """Every pixel but the one the light projects into (its mean has an integrable 1/h singularity
    that the quadrature does not resolve)."""
    cam = sc.camera
    m = cam.to_world
    c = m[:3, :3].T @ (sc.emitters[0].position - m[:3, 3])      # camera space: x left, y up, z forward
    tx = math.tan(math.radians(cam.fov) / 2)
    ty = tx * cam.height / cam.width
    sx, sy = (1 - c[0] / c[2] / tx) / 2, (1 - c[1] / c[2] / ty) / 2
    mask = np.ones((cam.height, cam.width), bool)
    mask[int(sy * cam.height), int(sx * cam.width)] = False
    return mask


def test_single_scattering_from_a_point_light_matches_quadrature(device):
    """Camera and point light in an infinite medium, max_depth 2: the image is the light scattered
    once, an integral along each ray computed independently by quadrature."""
    sc = _fog_scene()
    expected = _single_scattering(sc)
    assert detect(sc)["EQUIANGULAR"]
    r = render(sc, spp=256, device=device, seed=3)
    assert_mean_matches(r, np.repeat(expected[..., None], 3, -1), mask=_light_pixel_mask(sc),
                        what="single scattering, equiangular + MIS")


@pytest.mark.parametrize("est", [Estimator(equiangular="on", equiangular_mis="one"),
                                 Estimator(equiangular="on", mis=False),
                                 Estimator(equiangular="off")], ids=["one-sample", "no-mis", "distance"])
def test_every_variant_matches_single_scattering(device, est):
    sc = _fog_scene()
    expected = _single_scattering(sc)
    r = render(sc, spp=512, device=device, seed=5, estimator=est)
    assert_mean_matches(r, np.repeat(expected[..., None], 3, -1), mask=_light_pixel_mask(sc),
                        what=f"single scattering, {est.describe()}")


def test_point_in_fog_same_image_with_and_without_equiangular(device):
    """The shipped scene (surfaces, multiple scattering): the same image either way."""
    from pathlib import Path

    from volcl.scene import load
    sc = load(Path(__file__).resolve().parent.parent / "scenes" / "point_in_fog.xml")
    sc.camera.width, sc.camera.height = 16, 12
    on = render(sc, spp=1024, device=device, seed=11)
    off = render(sc, spp=2048, device=device, seed=12, estimator=Estimator(equiangular="off"))
    assert on.features["EQUIANGULAR"] and not off.features["EQUIANGULAR"]
    assert_same_image(on, off, blocks=3, what="point_in_fog, equiangular on / off")


def test_feature_flag_follows_the_choice_and_the_scene():
    sc = _fog_scene()
    assert Estimator().resolve(sc)[0]["EQUIANGULAR"]
    feats, params = Estimator(equiangular="off").resolve(sc)
    assert not feats["EQUIANGULAR"] and params["equiangular"] == 0
    feats, params = Estimator(nee=False).resolve(sc)
    assert not feats["EQUIANGULAR"]
    assert Estimator(equiangular="on", equiangular_mis="one").resolve(sc)[1]["equiangular"] == 2
    # a point light outside the only medium (a fog sphere): 'auto' leaves it off, 'on' compiles it
    from scenebuild import sphere
    from volcl.scene.model import Bsdf
    fog = medium(1.0, 0.9)
    ball = sphere((0, 0, -3), 1.0, Bsdf("null"), interior=fog)
    outside = scene([ball], [Emitter("point", rgb(1.0), position=np.array([0.0, 3.0, -3.0]))])
    assert not detect(outside)["EQUIANGULAR"]
    assert Estimator(equiangular="on").resolve(outside)[0]["EQUIANGULAR"]
    inside = scene([ball], [Emitter("point", rgb(1.0), position=np.array([0.2, 0.1, -3.0]))])
    assert detect(inside)["EQUIANGULAR"]


def _ulps(got, want):
    """Error of float32 results in units of the last place of the float64 answer."""
    want32 = np.abs(want).astype(np.float32)
    ulp = np.spacing(np.maximum(want32, np.finfo(np.float32).tiny)).astype(np.float64)
    return np.abs(got.astype(np.float64) - want) / ulp


def test_short_range_math_is_within_two_ulps(cl_env, prog):
    """The sampler's own atan2 (angles in (0, pi)) and sincos (on [0, pi]) against float64, over
    ratios from 1e-6 to 1e6 on both sides of the y axis and angles across the whole range: the
    density they give stays the one the pdf states to float32 precision."""
    rng = np.random.default_rng(7)
    n = 1 << 16
    ratio = 10.0 ** rng.uniform(-6, 6, n)
    x = (np.where(rng.random(n) < 0.5, -1.0, 1.0) * rng.uniform(0.1, 10.0, n)).astype(np.float32)
    y = (np.abs(x.astype(np.float64)) * ratio).astype(np.float32)
    x[:4], y[:4] = 0.0, 1.0          # on the y axis: pi/2
    phi = np.concatenate([np.float32([0.0, np.pi / 4, np.pi / 2, np.pi]),
                          rng.uniform(0, np.pi, n - 4).astype(np.float32)])
    a, s, c = run_kernel(cl_env, prog, "equiangular_math", n, [(np.float32, ())] * 3, inputs=[y, x, phi])
    y64, x64, phi64 = y.astype(np.float64), x.astype(np.float64), phi.astype(np.float64)
    assert _ulps(a, np.arctan2(y64, x64)).max() <= 2.0
    # near a zero of sin or cos, an error of one ulp of the argument is the honest scale
    floor = np.spacing(np.float32(np.pi)).astype(np.float64)
    sin_err = np.abs(s - np.sin(phi64)) / np.maximum(np.spacing(np.abs(np.sin(phi64)).astype(np.float32)), floor)
    cos_err = np.abs(c - np.cos(phi64)) / np.maximum(np.spacing(np.abs(np.cos(phi64)).astype(np.float32)), floor)
    assert sin_err.max() <= 2.0 and cos_err.max() <= 2.0, (sin_err.max(), cos_err.max())
