"""kernels/phase.h: Henyey-Greenstein and isotropic sampling against their densities, the sampler's
pdf against phase_eval, normalization, mean cosine = g, the sign convention (cos_theta =
dot(d_in, d_out) with d_in the travel direction, so g > 0 scatters forward), and the hard cases of
docs/volumetrics.md: g near 0 and |g| near 1."""
import math

import numpy as np
import pytest

import phasekit
import stats
from conftest import run_kernel
from volcl.scene.model import Phase

pytestmark = pytest.mark.every_implementation

N = 1_000_000
F32 = float(np.finfo(np.float32).eps)
u32, f32 = np.uint32, np.float32

G_CHI2 = [-0.99, -0.5, -1e-4, 0.0, 1e-4, 0.5, 0.99]
G_EXTREME = [-0.99999, -0.999, -1e-6, 1e-6, 0.999, 0.99999]
Z_UP = np.array([0.0, 0.0, 1.0], np.float32)
D_RANDOM = (np.array([0.48, -0.61, -0.63]) / np.linalg.norm([0.48, -0.61, -0.63])).astype(np.float32)


def unit64(v):
    """The direction a float32 vector stands for, exactly unit in float64. (Its own norm is off by
    ~3e-8, and at g = 0.99 a cos_theta off by 3e-8 moves the density by 1e-3 near the peak: the
    reference would not integrate to one.)"""
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v)


@pytest.fixture(scope="module")
def prog(test_program):
    return test_program("sampling_tests.cl")


def hg_phase(g=None):
    return Phase("isotropic") if g is None else Phase("hg", g)


def hg_u(g, u):
    """HG density as a function of u = 1 - |cos| measured from the lobe's peak (cos = +1 for g > 0,
    -1 for g < 0): the denominator is a sum of non-negative terms, exact for |g| near 1. g is taken
    as the float32 value the kernel receives (at g = 0.99999 its rounding alone moves 1 - |g| by 0.1%)."""
    ag = abs(float(np.float32(g)))
    return (1 - ag) * (1 + ag) / (4 * math.pi * ((1 - ag) ** 2 + 2 * ag * u) ** 1.5)


def peak_distance(g, c):
    return 1 - c if g >= 0 else 1 + c


def hg(g, c):
    """HG density in float64 for cos_theta = dot(d_in, d_out)."""
    return hg_u(g, peak_distance(g, c))


def dlog_hg(g, c):
    """|d ln p / d cos_theta| = 3 |g| / (1 + g^2 - 2 g cos): how a rounding of cos_theta moves p."""
    ag = abs(g)
    return 3 * ag / ((1 - ag) ** 2 + 2 * ag * peak_distance(g, c))


def sample(cl_env, prog, g, d_in, seed=31, n=N):
    s = phasekit.sample(cl_env, prog, hg_phase(g), d_in, seed, n)
    # exact sampling: weight 1, and the pdf phase_eval_pdf gives is the value
    assert np.all(s.weight == 1.0) and np.all(s.eval_pdf == s.value), f"g={g}: weight != 1 or pdf != value"
    return s.d, s.pdf, s.value


def device_eval(cl_env, prog, g, cos_theta):
    return phasekit.eval_cos(cl_env, prog, hg_phase(g), cos_theta)


def check_valid(d, pdf, ev, what):
    assert np.isfinite(d).all(), f"{what}: non-finite directions"
    assert np.isfinite(pdf).all() and (pdf > 0).all(), f"{what}: pdf not finite and positive: {pdf[~(pdf > 0)][:5]}"
    assert np.isfinite(ev).all() and (ev > 0).all(), f"{what}: phase_eval not finite and positive"
    err = np.abs(np.linalg.norm(d.astype(np.float64), axis=1) - 1.0)
    # normalize() in float32: unit to a few eps
    assert err.max() <= 8 * F32, f"{what}: |d_out| deviates from 1 by {err.max():.3g}"


@pytest.mark.parametrize("g", G_CHI2)
@pytest.mark.parametrize("d_in", [Z_UP, D_RANDOM], ids=["d_in=+z", "d_in=random"])
def test_hg_sampling_chi2(cl_env, prog, g, d_in):
    d, pdf, ev = sample(cl_env, prog, g, d_in)
    check_valid(d, pdf, ev, f"HG g={g}")
    din = unit64(d_in)
    stats.chi2_directions(d, lambda v: hg(g, v @ din), what=f"phase_sample HG g={g} d_in={d_in.tolist()}")


@pytest.mark.parametrize("g", G_CHI2 + G_EXTREME)
def test_hg_pdf_equals_eval(cl_env, prog, g):
    """The pdf phase_sample returns is phase_eval of the direction it returns. Both are float32 and
    the sampler evaluates its own cosine while the check re-derives it from the direction (float32
    frame, normalize and dot: a few eps of error in cos_theta, 8 eps allowed), so the tolerance is
    1e-4 plus what that error in cos_theta does to p: |d ln p / d cos| * 8 eps."""
    d, pdf, ev = sample(cl_env, prog, g, D_RANDOM, seed=32, n=200_000)
    check_valid(d, pdf, ev, f"HG g={g}")
    c = np.clip(d.astype(np.float64) @ unit64(D_RANDOM), -1, 1)
    tol = 1e-4 + dlog_hg(g, c) * 8 * F32
    rel = np.abs(pdf.astype(np.float64) / ev - 1.0)
    i = np.argmax(rel / tol)
    assert np.all(rel <= tol), (f"g={g}: pdf {pdf[i]:.8g} vs phase_eval {ev[i]:.8g} (relative {rel[i]:.3g}, "
                                f"tolerance {tol[i]:.3g}) at cos {c[i]:.9f}")


@pytest.mark.parametrize("g", G_CHI2 + G_EXTREME)
def test_hg_eval_matches_density_at_sampled_direction(cl_env, prog, g):
    """phase_eval(dot(d_in, d_out)) is the float64 HG density of the sampled direction (d_out
    normalized in float64, 1 - cos taken as |d_out x d_in|^2 / (1 + |cos|) to keep its digits), to the
    same tolerance as above."""
    d, pdf, ev = sample(cl_env, prog, g, Z_UP, seed=37, n=200_000)
    v = d.astype(np.float64)
    v /= np.linalg.norm(v, axis=1)[:, None]
    u = (v[:, 0] ** 2 + v[:, 1] ** 2) / (1 + np.abs(v[:, 2]))      # distance from the peak, 1 - |cos|
    same_side = np.sign(v[:, 2]) == (1 if g >= 0 else -1)
    u = np.where(same_side, u, 2 - u)
    ref = hg_u(g, u)
    c = np.where(g >= 0, 1 - u, u - 1)
    tol = 1e-4 + dlog_hg(g, c) * 8 * F32
    rel = np.abs(ev / ref - 1.0)
    j = np.argmax(rel / tol)
    assert np.all(rel <= tol), (f"g={g}: phase_eval {ev[j]:.8g} vs float64 HG {ref[j]:.8g} at 1 - |cos| = "
                                f"{u[j]:.3g} (relative {rel[j]:.3g}, tolerance {tol[j]:.3g}); "
                                f"{np.sum(rel > tol)} of {len(u)} samples")


@pytest.mark.parametrize("g", [0.9, 0.99, -0.99, 0.999, -0.999, 0.99999, -0.99999])
def test_hg_lobe_resolved(cl_env, prog, g):
    """Chi-square of the sampled lobe in its own scale: u = 1 - |cos| from the peak on [0, 30 w)
    with w = (1 - |g|)^2 / 2|g| its width (a sphere grid puts all of a narrow lobe in one cell)."""
    d, pdf, ev = sample(cl_env, prog, g, Z_UP, seed=38)
    v = d.astype(np.float64)
    v /= np.linalg.norm(v, axis=1)[:, None]
    peak = 1.0 if g >= 0 else -1.0
    u = (v[:, 0] ** 2 + v[:, 1] ** 2) / (1 + np.abs(v[:, 2]))
    u = np.where(np.sign(v[:, 2]) == peak, u, 2 - u)
    w = (1 - abs(g)) ** 2 / (2 * abs(g))
    U = 30 * w
    tail = stats.integral_1d(lambda x: 2 * math.pi * hg_u(g, x), U, 2.0, tol=1e-10)
    stats.chi2_1d(u[u < U], lambda x: 2 * math.pi * hg_u(g, x), 0.0, U, bins=51,
                  extra_observed=[np.sum(u >= U)], extra_probability=[tail], extra_labels=["[30 w, 2]"],
                  what=f"HG g={g}: 1 - |cos| around the peak")


@pytest.mark.parametrize("g", G_CHI2 + G_EXTREME)
def test_hg_mean_cosine(cl_env, prog, g):
    d, pdf, ev = sample(cl_env, prog, g, D_RANDOM, seed=33)
    c = d.astype(np.float64) @ unit64(D_RANDOM)
    # under HG, E[P2(cos)] = g^2, so Var(cos) = (1 - g^2) / 3; for |g| near 1 that variance comes from
    # a few dozen back-scattered samples, which a sample variance estimates poorly
    stats.assert_mean(c, g, f"HG g={g}: mean cos_theta = g", sd=math.sqrt((1 - g * g) / 3))


@pytest.mark.parametrize("g", [0.5, 0.99, -0.5, -0.99])
def test_hg_sign_convention(cl_env, prog, g):
    """g > 0 scatters forward: d_out tends to continue along the travel direction d_in."""
    d, _, _ = sample(cl_env, prog, g, Z_UP, seed=34, n=100_000)
    c = d[:, 2].astype(np.float64)
    z = c.mean() / (c.std(ddof=1) / math.sqrt(len(c)))
    assert np.sign(z) == np.sign(g) and abs(z) > stats.z_limit(), \
        f"g={g}: mean dot(d_in, d_out) = {c.mean():.4f} ({z:.1f} standard errors from 0)"
    fwd, back = device_eval(cl_env, prog, g, [1.0, -1.0])
    assert (fwd > back) == (g > 0), f"g={g}: phase_eval(cos=+1) = {fwd}, phase_eval(cos=-1) = {back}"


@pytest.mark.parametrize("g", G_EXTREME + [-0.99, 0.99, -1e-4, 1e-4, 0.0])
def test_hg_sample_cos_in_range(cl_env, prog, g):
    (c,) = run_kernel(cl_env, prog, "hg_sample_cos", N, [(f32, ())], u32(35), f32(g))
    assert np.isfinite(c).all(), f"g={g}: NaN or infinite cosines"
    assert np.abs(c).max() <= 1.0, f"g={g}: {np.sum(np.abs(c) > 1)} cosines with |cos| > 1"


QUAD_TOL = 1e-7     # the quadratures' own budget is 1e-9 or less; float64 sums add far less


@pytest.mark.parametrize("g", G_CHI2 + G_EXTREME)
def test_hg_integrates_to_one_numpy(g):
    """The float64 density used as the reference everywhere here integrates to one: over the distance
    u = 1 - |cos| from the peak (the coordinate that keeps a narrow lobe's digits), and for the
    chi-square g over the sphere around the random d_in, with the grid the chi-square tests use."""
    total = stats.integral_1d(lambda u: 2 * math.pi * hg_u(g, u), 0.0, 2.0, tol=1e-10)
    stats.assert_integrates_to_one(total, QUAD_TOL, f"HG g={g} (float64, 1D)")
    if g in G_CHI2:
        din = unit64(D_RANDOM)
        total = stats.integral_sphere(lambda v: hg(g, v @ din), tol=1e-9)
        stats.assert_integrates_to_one(total, QUAD_TOL, f"HG g={g} (float64, sphere)")


@pytest.mark.parametrize("g", G_CHI2 + G_EXTREME)
def test_hg_device_eval_integrates_to_one(cl_env, prog, g):
    """phase_hg_eval_w on the device, on the nodes of a rule that integrates the float64 density
    over the distance from the peak u = 1 - |cos| to 1e-10. Its float32 values carry a relative error
    of a few eps from the arithmetic (8 eps allowed) plus |d ln p / d u| times the rounding of each
    node to float32: that budget, integrated against the density, bounds the deviation from one."""
    u, w = stats.line_rule(lambda x: 2 * math.pi * hg_u(g, x), 0.0, 2.0, tol=1e-10)
    u32_ = np.ascontiguousarray(u.astype(np.float32))
    (dev,) = run_kernel(cl_env, prog, "phase_hg_eval_at_w", u.size, [(f32, ())], f32(g), inputs=[u32_])
    dens = 2 * math.pi * hg_u(g, u)
    c = np.where(g >= 0, 1 - u, u - 1)
    budget = float(np.sum(w * dens * (8 * F32 + dlog_hg(g, c) * np.abs(u32_.astype(np.float64) - u))))
    total = float(np.sum(w * 2 * math.pi * dev))
    stats.assert_integrates_to_one(total, QUAD_TOL + budget, f"HG g={g} (device phase_hg_eval_w)")


def test_isotropic(cl_env, prog):
    d, pdf, ev = sample(cl_env, prog, None, D_RANDOM, seed=36)
    check_valid(d, pdf, ev, "isotropic")
    stats.chi2_directions(d, lambda v: np.full(v.shape[:-1], 1 / (4 * np.pi)), what="phase_sample isotropic")
    inv4pi = np.float32(1 / (4 * np.pi))
    assert np.all(pdf == inv4pi) and np.all(ev == inv4pi)
    stats.assert_mean(d.astype(np.float64) @ unit64(D_RANDOM), 0.0, "isotropic mean cosine", sd=math.sqrt(1 / 3))
    vals = device_eval(cl_env, prog, None, np.linspace(-1, 1, 101))
    assert np.all(vals == inv4pi)
