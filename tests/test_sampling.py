"""Warps of kernels/sampling.h and free-flight sampling of kernels/media.h against their densities
(chi-square, tests/stats.py), with the expectations of the medium estimator checked by z-tests."""
import math

import numpy as np
import pytest

import stats
from conftest import run_kernel
from volcl import layout
from volcl.features import all_features
from volcl.pack import filter_cdf_size, filter_table
from volcl.scene.model import Filter

pytestmark = pytest.mark.every_implementation

N = 1_000_000
F32 = float(np.finfo(np.float32).eps)
u32, i32, f32 = np.uint32, np.int32, np.float32


@pytest.fixture(scope="module")
def prog(test_program):
    return test_program("sampling_tests.cl")


@pytest.fixture(scope="module")
def prog_grey(test_program):
    """The same kernels without VOLCL_HAS_CHROMATIC_MEDIA: media.h's grey free-flight path."""
    return test_program("sampling_tests.cl", {**all_features(), "CHROMATIC_MEDIA": False})


def norms_ok(d, what):
    """Unit vectors: a float32 vector built from a few rounded operations is unit to a few eps."""
    err = np.abs(np.linalg.norm(d.astype(np.float64), axis=1) - 1.0)
    assert err.max() <= 8 * F32, f"{what}: |d| deviates from 1 by up to {err.max():.3g}"


# ---- directions -------------------------------------------------------------------------------


def test_cosine_hemisphere(cl_env, prog):
    d, pdf = run_kernel(cl_env, prog, "warp_cosine_hemisphere", N, [(f32, (3,)), (f32, ())], u32(11))
    norms_ok(d, "cosine hemisphere")
    assert (d[:, 2] >= 0).all()
    stats.chi2_directions(d, lambda v: np.maximum(v[..., 2], 0.0) / np.pi, what="sample_cosine_hemisphere")
    # the device pdf is the density of the warp, at the sampled point
    np.testing.assert_allclose(pdf, d[:, 2].astype(np.float64) / np.pi, rtol=4 * F32, atol=0)
    total = stats.integral_sphere(lambda v: np.maximum(v[..., 2], 0.0) / np.pi)
    stats.assert_integrates_to_one(total, 1e-7, "cos/pi over the hemisphere")


def test_uniform_sphere(cl_env, prog):
    d, pdf = run_kernel(cl_env, prog, "warp_uniform_sphere", N, [(f32, (3,)), (f32, ())], u32(12))
    norms_ok(d, "uniform sphere")
    stats.chi2_directions(d, lambda v: np.full(v.shape[:-1], 1 / (4 * np.pi)), what="sample_uniform_sphere")
    assert np.all(pdf == np.float32(1 / (4 * np.pi)))


@pytest.mark.parametrize("cos_max", [0.999, 0.9, 0.3, -0.6])
def test_uniform_cone(cl_env, prog, cos_max):
    c = float(np.float32(cos_max))     # the value the kernel receives
    d, pdf = run_kernel(cl_env, prog, "warp_uniform_cone", N, [(f32, (3,)), (f32, ())], u32(13), f32(cos_max))
    norms_ok(d, "uniform cone")
    density = 1.0 / (2 * np.pi * (1.0 - c))
    stats.chi2_directions(d, lambda v: np.where(v[..., 2] >= c, density, 0.0), cos_range=(c, 1.0),
                          what=f"sample_uniform_cone(cos_max={cos_max})")
    np.testing.assert_allclose(pdf, density, rtol=4 * F32 / (1 - c), atol=0)
    total = stats.integral_sphere(lambda v: np.where(v[..., 2] >= c, density, 0.0), cos_range=(c, 1.0))
    stats.assert_integrates_to_one(total, 1e-7, "cone pdf")


# ---- points -----------------------------------------------------------------------------------


def test_uniform_triangle(cl_env, prog):
    (b,) = run_kernel(cl_env, prog, "warp_uniform_triangle", N, [(f32, (2,))], u32(14))
    assert (b >= 0).all() and (b.astype(np.float64).sum(1) <= 1.0 + F32).all()
    # uniform on the triangle {b1, b2 >= 0, b1 + b2 <= 1} of the barycentric plane: density 2
    stats.chi2_2d(b, lambda x, y: np.where(x + y <= 1.0, 2.0, 0.0), (0.0, 1.0 + F32), (0.0, 1.0 + F32),
                  res=(31, 31), what="sample_uniform_triangle")


def test_concentric_disk(cl_env, prog):
    (p,) = run_kernel(cl_env, prog, "warp_concentric_disk", N, [(f32, (2,))], u32(15))
    r2 = (p.astype(np.float64) ** 2).sum(1)
    assert r2.max() <= 1.0 + 4 * F32
    lim = 1.0 + 4 * F32
    stats.chi2_2d(p, lambda x, y: np.where(x * x + y * y <= 1.0, 1 / np.pi, 0.0), (-lim, lim), (-lim, lim),
                  res=(31, 31), what="sample_concentric_disk")


# ---- discrete distributions -------------------------------------------------------------------


def host_cdf(weights):
    """The table the host builds: inclusive prefix sum in float32, normalized to end at exactly 1."""
    c = np.cumsum(np.asarray(weights, np.float64))
    c = (c / c[-1]).astype(np.float32)
    c[-1] = 1.0
    return c


def cdf_probabilities(cdf):
    """Exact probability of each index: u is a multiple of 2^-24 in [0, 1) and the routine returns
    the first entry with cdf > u, so P(index <= i) = ceil(cdf[i] * 2^24) / 2^24."""
    scale = 2.0 ** 24
    below = np.ceil(np.asarray(cdf, np.float64) * scale) / scale
    return np.diff(np.concatenate([[0.0], below]))


@pytest.mark.parametrize("weights", [
    [0.1, 0.0, 0.3, 0.05, 0.0, 0.25, 0.3],       # zero-probability entries must never be chosen
    [1.0],
    [1e-5, 1.0, 1e-5],                            # tiny entries at both ends
    np.random.default_rng(5).gamma(0.5, 1.0, 1000).tolist(),
], ids=["with-zeros", "single", "tiny-ends", "random-1000"])
def test_discrete_cdf(cl_env, prog, weights):
    cdf = host_cdf(weights)
    (k,) = run_kernel(cl_env, prog, "warp_discrete_cdf", N, [(np.int32, ())], u32(16), i32(len(cdf)), inputs=[cdf])
    p = cdf_probabilities(cdf)
    assert not np.isin(k, np.flatnonzero(p == 0)).any(), "an entry of probability zero was sampled"
    if len(cdf) == 1:
        assert (k == 0).all()
        return
    stats.chi2_discrete(k, p, what=f"sample_discrete_cdf over {len(cdf)} entries")


@pytest.mark.parametrize("n", [1, 2, 3, 7, 256, 511, 1000])
@pytest.mark.parametrize("start", ["guide", "zero", "last", "random"])
def test_discrete_cdf_index_is_the_first_entry_above_u(cl_env, prog, n, start):
    """The index itself, not only its distribution, for the binary search and the guided one
    (from volcl.guides.guide's starts, and from starts at 0, at n - 1 and at random, which must
    give the same index): the first entry greater than u, or n - 1, at u on, just below and just
    above every entry (ties included: the repeated entries of zero-weight bins), at 0 and at the
    largest u below 1."""
    from volcl.guides import guide
    rng = np.random.default_rng(n)
    w = rng.gamma(0.5, 1.0, n)
    w[::5] = 0.0
    w[-1] = max(w[-1], 1e-3)
    cdf = host_cdf(w.tolist())
    g = {"guide": guide(cdf), "zero": np.zeros(n, np.float32), "last": np.full(n, n - 1, np.float32),
         "random": rng.integers(0, n, n).astype(np.float32)}[start]
    u = np.concatenate([cdf, np.nextafter(cdf, np.float32(0)), np.nextafter(cdf, np.float32(2)),
                        np.float32([0.0, 0.99999994])]).astype(np.float32)
    u = u[u < 1.0]
    plain, guided = run_kernel(cl_env, prog, "discrete_cdf_at", len(u), [(np.int32, ())] * 2, i32(n),
                               inputs=[cdf, g, u])
    want = np.minimum(np.searchsorted(cdf, u, side="right"), n - 1)
    for name, k in (("binary", plain), ("guided", guided)):
        bad = np.flatnonzero(k != want)
        assert not bad.size, f"{name}: u={u[bad[:5]]}: index {k[bad[:5]]}, want {want[bad[:5]]}"


def test_guide_starts_at_the_answer_for_its_bin():
    """guide[g] is the index the search returns at u = g / n (in float32), row by row of a 2-d table."""
    from volcl.guides import guide
    rng = np.random.default_rng(2)
    cdf = np.stack([host_cdf(rng.gamma(0.3, 1.0, 64).tolist()) for _ in range(5)])
    g = guide(cdf)
    assert g.shape == cdf.shape and g.dtype == np.float32
    at = np.arange(64, dtype=np.float32) / np.float32(64)
    for row, gr in zip(cdf, g):
        assert np.array_equal(gr, np.minimum(np.searchsorted(row, at, side="right"), 63))


# ---- reconstruction filter --------------------------------------------------------------------

FILTERS = [Filter("box", 0.5, 0.5), Filter("tent", 1.0, 0.5), Filter("gaussian", 2.0, 0.5),
           Filter("gaussian", 1.5, 0.3)]
FILTER_IDS = ["box", "tent", "gaussian-r2-s0.5", "gaussian-r1.5-s0.3"]


def filter_profile(f):
    """The filter's normalized 1D profile on [-radius, radius], as volcl.pack.filter_table defines it."""
    r, s = f.radius, f.stddev
    if f.kind == "box":
        return lambda x: np.where(np.abs(x) <= r, 1.0 / (2 * r), 0.0)
    if f.kind == "tent":
        return lambda x: np.maximum(0.0, 1.0 - np.abs(x) / r) / r
    floor = math.exp(-r * r / (2 * s * s))
    norm = s * math.sqrt(2 * math.pi) * math.erf(r / (s * math.sqrt(2))) - 2 * r * floor
    return lambda x: np.maximum(0.0, np.exp(-x * x / (2 * s * s)) - floor) * (np.abs(x) <= r) / norm


def table_density(table, radius):
    """Density sample_filter_offset draws from a CDF table: each interval of the equally spaced grid
    on [-radius, radius] holds cdf[k + 1] - cdf[k] of the mass, spread evenly."""
    t = table[:filter_cdf_size(table)].astype(np.float64)
    edges = np.linspace(-radius, radius, len(t))
    dens = np.diff(t) / np.diff(edges)

    def pdf(x):
        i = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(dens) - 1)
        return np.where((x >= edges[0]) & (x < edges[-1]), dens[i], 0.0)
    return pdf


def sample_filter(cl_env, prog, f, seed):
    table = filter_table(f)
    (x,) = run_kernel(cl_env, prog, "warp_filter_offset", N, [(f32, ())], u32(seed), i32(filter_cdf_size(table)),
                      f32(f.radius), inputs=[table])
    return table, x


@pytest.mark.parametrize("f", FILTERS, ids=FILTER_IDS)
def test_filter_offset_follows_its_table(cl_env, prog, f):
    """sample_filter_offset reproduces the distribution its CDF table describes."""
    table, x = sample_filter(cl_env, prog, f, 17)
    r = f.radius
    assert np.abs(x).max() <= r
    hi = float(np.nextafter(np.float32(r), np.float32(np.inf)))
    stats.chi2_1d(x, table_density(table, r), -r, hi, bins=51, what=f"sample_filter_offset ({f.kind} table)")


@pytest.mark.parametrize("f", FILTERS, ids=FILTER_IDS)
def test_filter_offset_follows_filter_profile(cl_env, prog, f):
    """End to end: table (volcl.pack.filter_table) plus kernel sample the normalized filter profile."""
    total = stats.integral_1d(filter_profile(f), -f.radius, f.radius)
    stats.assert_integrates_to_one(total, 1e-7, f"{f.kind} profile")
    table, x = sample_filter(cl_env, prog, f, 18)
    hi = float(np.nextafter(np.float32(f.radius), np.float32(np.inf)))
    stats.chi2_1d(x, filter_profile(f), -f.radius, hi, bins=51, what=f"filter offsets vs the {f.kind} profile")


# A pixel within the filter's radius of the image's edge (Mitsuba's film without sample_border):
# its centre 0.5 or 1.5 pixels from one edge, or an image one pixel wide (both sides cut).
CUTS = [(-0.5, None), (-1.5, None), (None, 0.5), (-0.5, 0.5), (-0.3, 0.2)]


@pytest.mark.parametrize("cut", CUTS, ids=lambda c: f"{c[0]}..{c[1]}")
@pytest.mark.parametrize("f", FILTERS, ids=FILTER_IDS)
def test_filter_offset_within_follows_the_cut_profile(cl_env, prog, f, cut):
    """sample_filter_offset_within draws from the filter's part inside [lo, hi], renormalized."""
    r = f.radius
    lo, hi = (-r if cut[0] is None else cut[0]), (r if cut[1] is None else cut[1])
    lo, hi = max(lo, -r), min(hi, r)
    table = filter_table(f)
    (x,) = run_kernel(cl_env, prog, "warp_filter_offset_within", N, [(f32, ())], u32(19), i32(filter_cdf_size(table)),
                      f32(r), f32(lo), f32(hi), inputs=[table])
    assert x.min() >= np.float32(lo) and x.max() <= np.float32(hi)
    profile = filter_profile(f)
    mass = stats.integral_1d(profile, lo, hi)
    top = float(np.nextafter(np.float32(hi), np.float32(np.inf)))
    stats.chi2_1d(x, lambda t: profile(t) / mass, lo, top, bins=41,
                  what=f"filter offsets within [{lo}, {hi}] vs the cut {f.kind} profile")


def test_filter_offset_within_the_whole_filter_is_the_plain_offset(cl_env, prog):
    """Bounds at or beyond the radius cut nothing: the same offsets, bit for bit."""
    f = FILTERS[2]
    table, plain = sample_filter(cl_env, prog, f, 20)
    (x,) = run_kernel(cl_env, prog, "warp_filter_offset_within", N, [(f32, ())], u32(20), i32(filter_cdf_size(table)),
                      f32(f.radius), f32(-f.radius), f32(f.radius), inputs=[table])
    assert np.array_equal(x, plain)


# ---- free-flight distances --------------------------------------------------------------------


def make_medium(sigma_t, albedo=(0.8, 0.6, 0.4), emission=(0.0, 0.0, 0.0)):
    m = np.zeros(1, layout.MEDIUM)
    m["type"] = layout.MEDIUM_TYPES["homogeneous"]
    m["phase"] = layout.PHASE_TYPES["isotropic"]
    m["sigma_t"], m["albedo"], m["emission"] = sigma_t, albedo, emission
    return m


def check_free_flight(cl_env, program, sigma_t, t_max, beta, albedo=(0.8, 0.6, 0.4),
                      emission=(0.0, 0.0, 0.0), grey=False, seed=21, what="free flight"):
    """medium_sample_distance against the mixture density sum_k p_k sigma_k exp(-sigma_k t) on
    [0, t_max) plus the mass of 'no scattering' sum_k p_k exp(-sigma_k t_max), p proportional to
    beta (grey: one channel), and its weights against the expectations they estimate."""
    m = make_medium(sigma_t, albedo, emission)
    sig = m["sigma_t"][0].astype(np.float64)
    alb = m["albedo"][0].astype(np.float64)
    emi = m["emission"][0].astype(np.float64)
    tm = float(np.float32(t_max))
    t, sc, w, e = run_kernel(cl_env, program, "medium_distance", N,
                             [(f32, ()), (np.int32, ()), (f32, (3,)), (f32, (3,))],
                             u32(seed), f32(t_max), *[f32(b) for b in beta], inputs=[m])
    scat = sc.astype(bool)
    assert np.isfinite(w).all() and np.isfinite(e).all(), \
        f"{what}: non-finite weights, e.g. {w[~np.isfinite(w).all(1)][:3].tolist()}"
    assert (w >= 0).all() and (e >= 0).all()
    assert np.all(t[~scat] == np.float32(t_max)), f"{what}: a sample without scattering does not end at t_max"
    assert np.all(t[scat] < np.float32(t_max)) and np.all(t[scat] >= 0)

    # the distance distribution
    if grey:
        p, rates = np.array([1.0]), sig[:1]
    else:
        b = np.maximum(np.asarray(beta, np.float64), 0)
        p, rates = b / b.sum(), sig
    pos = (rates > 0) & (p > 0)
    with np.errstate(invalid="ignore"):
        survive = np.where(rates > 0, np.exp(-rates * tm), 1.0)     # exp(-sigma t_max), 1 for sigma = 0

    def pdf(x):
        x = np.asarray(x)[..., None]
        return np.sum(p * rates * np.exp(-rates * x), axis=-1)
    if pos.any():
        # histogram where the density lives; the rest of [0, t_max) is one tail cell
        T = min(tm, 12.0 / rates[pos].min())
        tail = float(np.sum(p[pos] * (np.exp(-rates[pos] * T) - np.exp(-rates[pos] * tm))))
        no_scatter = float(np.sum(p * survive))
        ts = t[scat].astype(np.float64)
        stats.chi2_1d(ts[ts < T], pdf, 0.0, T, bins=51,
                      extra_observed=[np.sum(ts >= T), np.sum(~scat)], extra_probability=[tail, no_scatter],
                      extra_labels=[f"[{T:.4g}, t_max)", "no scattering"], what=f"{what}: distances")
    else:
        assert not scat.any(), f"{what}: scattering in a medium without extinction"

    # expectations of the weights, per channel (beta_k = 0 channels carry no contribution: compare
    # the weights the integrator multiplies into beta, where they are used)
    chan = np.asarray(beta) > 0 if not grey else np.ones(3, bool)
    with np.errstate(over="ignore", invalid="ignore"):
        tr = np.where(sig > 0, np.exp(-sig * tm), 1.0)
        emitted = np.where(sig > 0, emi * -np.expm1(-sig * tm) / np.where(sig > 0, sig, 1.0), emi * tm)
    names = ["r", "g", "b"]
    ws = np.where(scat[:, None], w, 0.0)[:, chan]
    wn = np.where(~scat[:, None], w, 0.0)[:, chan]
    cn = [names[k] for k in range(3) if chan[k]]
    stats.assert_mean(ws, (alb * (1.0 - tr))[chan], f"{what}: E[weight * 1{{scattered}}]", cn)
    stats.assert_mean(wn, tr[chan], f"{what}: E[weight * 1{{not scattered}}]", cn)
    if np.any(emi > 0) and np.isfinite(emitted[chan]).all():
        stats.assert_mean(np.where(scat[:, None], e, 0.0)[:, chan], emitted[chan],
                          f"{what}: E[emission] = emission * integral of Tr", cn)


FREE_FLIGHT = {
    "grey": dict(sigma_t=(1.3, 1.3, 1.3), t_max=2.0, beta=(1.0, 1.0, 1.0), emission=(0.5, 0.5, 0.5)),
    "grey-unbounded": dict(sigma_t=(0.7, 0.7, 0.7), t_max=math.inf, beta=(1.0, 1.0, 1.0)),
    "grey-thick": dict(sigma_t=(90.0, 90.0, 90.0), t_max=3.0, beta=(1.0, 1.0, 1.0)),
    "grey-vacuum-unbounded": dict(sigma_t=(0.0, 0.0, 0.0), t_max=math.inf, beta=(1.0, 1.0, 1.0)),
    "chromatic": dict(sigma_t=(0.5, 1.0, 2.0), t_max=1.5, beta=(1.0, 0.5, 0.25), albedo=(0.9, 0.5, 0.2),
                      emission=(1.0, 2.0, 3.0)),
    "chromatic-zero-channel-unbounded": dict(sigma_t=(0.0, 1.0, 3.0), t_max=math.inf, beta=(1.0, 1.0, 1.0)),
    "chromatic-zero-channel": dict(sigma_t=(0.0, 1.0, 3.0), t_max=2.5, beta=(0.2, 1.0, 0.5),
                                   emission=(0.3, 0.2, 0.1)),
    "chromatic-zero-beta": dict(sigma_t=(0.0, 1.0, 3.0), t_max=math.inf, beta=(0.0, 1.0, 1.0)),
    "chromatic-only-zero-channel": dict(sigma_t=(0.0, 1.0, 3.0), t_max=math.inf, beta=(1.0, 0.0, 0.0)),
    "chromatic-thick": dict(sigma_t=(40.0, 80.0, 160.0), t_max=5.0, beta=(1.0, 1.0, 1.0)),
}


@pytest.mark.parametrize("case", list(FREE_FLIGHT), ids=list(FREE_FLIGHT))
def test_free_flight(cl_env, prog, case):
    check_free_flight(cl_env, prog, what=f"medium_sample_distance [{case}]", **FREE_FLIGHT[case])


@pytest.mark.parametrize("case", [c for c in FREE_FLIGHT if c.startswith("grey")])
def test_free_flight_grey_build(cl_env, prog_grey, case):
    """The path compiled when no medium is chromatic: exponential with rate sigma_t."""
    check_free_flight(cl_env, prog_grey, grey=True, what=f"medium_sample_distance, grey build [{case}]",
                      **FREE_FLIGHT[case])


def test_transmittance_never_nan(cl_env, prog):
    m = make_medium((0.0, 1.0, 1e30))
    t = np.array([0.0, 1.0, 1e30, np.inf], np.float32)
    (tr,) = run_kernel(cl_env, prog, "medium_tr", len(t), [(f32, (3,))], inputs=[m, t])
    expected = np.array([[1, 1, 1], [1, math.exp(-1), 0], [1, 0, 0], [1, 0, 0]], np.float64)
    assert np.isfinite(tr).all()
    np.testing.assert_allclose(tr, expected, rtol=4 * F32, atol=0)


# ---- the harness itself (tests/stats.py) ------------------------------------------------------
# numpy samplers with known answers: the harness must accept the right density and reject a
# slightly wrong one at the sample counts used above. These are not hypothesis tests of volcl, so
# they use check=False and do not count towards the Sidak correction.


def numpy_hg(rng, g, n):
    """Exact HG sampling in float64 around +z (textbook inversion, fine for |g| >= 0.1)."""
    u = rng.random(n)
    k = (1 - g * g) / (1 - g + 2 * g * u)
    c = (1 + g * g - k * k) / (2 * g)
    phi = 2 * np.pi * rng.random(n)
    s = np.sqrt(np.maximum(0, 1 - c * c))
    return np.stack([s * np.cos(phi), s * np.sin(phi), c], 1)


def hg_pdf(g):
    return lambda v: (1 - g * g) / (4 * np.pi * (1 + g * g - 2 * g * v[..., 2]) ** 1.5)


def test_harness_accepts_and_rejects():
    rng = np.random.default_rng(7)
    d = numpy_hg(rng, 0.5, N)
    assert stats.chi2_directions(d, hg_pdf(0.5), check=False).passed
    wrong = stats.chi2_directions(d, hg_pdf(0.48), check=False)
    assert not wrong.passed and wrong.p_value < 1e-12, wrong.report("HG 0.5 vs pdf of 0.48")
    assert "worst cells" in wrong.report("x") and "p-value" in wrong.report("x")
    # 1D: exponential with rate 1 against rate 1.01
    t = rng.exponential(1.0, N)
    t = t[t < 5]
    assert stats.chi2_1d(t, lambda x: np.exp(-x), 0, 5, extra_observed=[N - len(t)],
                         extra_probability=[math.exp(-5)], check=False).passed
    assert not stats.chi2_1d(t, lambda x: 1.01 * np.exp(-1.01 * x), 0, 5, extra_observed=[N - len(t)],
                             extra_probability=[math.exp(-5.05)], check=False).passed
    # samples where the pdf is zero fail however few they are
    p = np.array([0.5, 0.5, 0.0])
    k = np.concatenate([rng.integers(0, 2, N), [2]])
    res = stats.chi2_discrete(k, p, check=False)
    assert not res.passed and "pdf is zero" in res.error


def test_harness_catches_unnormalized_pdf():
    rng = np.random.default_rng(8)
    d = numpy_hg(rng, 0.5, 1000)
    with pytest.raises(stats.QuadratureError):
        stats.chi2_directions(d, lambda v: 1.01 * hg_pdf(0.5)(v), check=False)


def test_sidak_threshold():
    assert stats.test_alpha(1, 0.01) == pytest.approx(0.01)
    assert stats.test_alpha(100, 0.01) == pytest.approx(1 - 0.99 ** 0.01)
    assert 1 - (1 - stats.test_alpha()) ** stats.SUITE_TESTS == pytest.approx(stats.ALPHA)
