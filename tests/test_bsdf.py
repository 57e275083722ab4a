"""kernels/bsdf.h: diffuse sampling against its pdf, weights equal value / pdf, one- and two-sided
behaviour; dielectric reflection probability equals the Fresnel reflectance (binomial tests),
refraction obeys Snell's law with weight 1 / eta^2, eta = 1 passes straight through; conductor
mirror direction and Fresnel reflectance against the exact complex-IOR formula in numpy.
Directions are in the local shading frame (normal +z) and point away from the surface."""
import numpy as np
import pytest

import stats
from conftest import run_kernel
from volcl import layout

pytestmark = pytest.mark.every_implementation

F32 = float(np.finfo(np.float32).eps)
u32, f32 = np.uint32, np.float32
GOLD_ETA = (0.143, 0.374, 1.442)    # gold-like complex IOR (eta + i k) at roughly R, G, B
GOLD_K = (3.983, 2.385, 1.603)


@pytest.fixture(scope="module")
def prog(test_program):
    return test_program("sampling_tests.cl")


def make_bsdf(kind, twosided=False, eta=1.5, color=(0.7, 0.5, 0.3), cond_eta=GOLD_ETA, cond_k=GOLD_K, mirror=False):
    b = np.zeros(1, layout.BSDF)
    b["type"] = layout.BSDF_TYPES[kind]
    b["twosided"] = int(twosided)
    b["eta"] = eta
    b["conductor_mirror"] = int(mirror)
    b["color"], b["cond_eta"], b["cond_k"] = color, cond_eta, cond_k
    b["spec_r"], b["spec_t"] = 1.0, 1.0
    for name in layout.BSDF_TEXTURE_FIELDS:
        b[name] = -1
    return b


NO_TABLES = np.zeros(1, np.float32)


def unit(v):
    v = np.asarray(v, np.float64)
    return (v / np.linalg.norm(v, axis=-1, keepdims=True)).astype(np.float32)


def sample(cl_env, prog, b, wo, seed=41, u1=None, tables=NO_TABLES):
    """bsdf_sample for each row of wo (n, 3). Returns a dict of the outputs."""
    wo = np.ascontiguousarray(wo, np.float32)
    n = len(wo)
    u1 = np.full(n, -1.0, np.float32) if u1 is None else np.ascontiguousarray(u1, np.float32)
    wi, w, pdf, eta, info, val, epdf = run_kernel(
        cl_env, prog, "bsdf_sample_dirs", n,
        [(f32, (3,)), (f32, (3,)), (f32, ()), (f32, ()), (np.int32, (3,)), (f32, (3,)), (f32, ())],
        u32(seed), inputs=[b, np.asarray(tables, np.float32), wo, u1])
    return dict(wi=wi, weight=w, pdf=pdf, eta=eta, ok=info[:, 0].astype(bool), delta=info[:, 1].astype(bool),
                null=info[:, 2].astype(bool), value=val, eval_pdf=epdf)


def eval_pairs(cl_env, prog, b, wo, wi, tables=NO_TABLES):
    wo, wi = np.ascontiguousarray(wo, np.float32), np.ascontiguousarray(wi, np.float32)
    val, pdf = run_kernel(cl_env, prog, "bsdf_eval_pairs", len(wo), [(f32, (3,)), (f32, ())],
                          inputs=[b, np.asarray(tables, np.float32), wo, wi])
    return val, pdf


def norms_ok(d, what):
    err = np.abs(np.linalg.norm(d.astype(np.float64), axis=1) - 1.0)
    assert err.max() <= 8 * F32, f"{what}: |wi| deviates from 1 by up to {err.max():.3g}"


# ---- diffuse ----------------------------------------------------------------------------------

N = 1_000_000
WO_UP = unit([0.3, -0.2, 0.8])
WO_DOWN = unit([0.3, -0.2, -0.8])
COLOR = np.array([0.7, 0.5, 0.3], np.float32)


def check_diffuse_lobe(s, side, what):
    """Samples of a cosine lobe on the hemisphere `side` (+1 or -1 in z)."""
    ok = s["ok"]
    # bsdf_sample gives up when the warp lands on the rim (pdf 0): u exactly 0 in one dimension, or
    # a radius that rounds to 1; a few chances in 2^24 per sample. More than that is a bug.
    refused = np.count_nonzero(~ok)
    if refused:
        stats.assert_probability(refused, len(ok), 4 * 2.0 ** -24, f"{what}: samples refused")
    wi = s["wi"][ok]
    norms_ok(wi, what)
    assert np.all(wi[:, 2] * side > 0), f"{what}: wi on the wrong side"
    stats.chi2_directions(wi, lambda v: np.maximum(side * v[..., 2], 0.0) / np.pi, what=what)
    # weight = value / pdf, from the sampler and from bsdf_eval of the sampled direction
    assert np.all(s["weight"][ok] == COLOR), f"{what}: weight is not the albedo"
    np.testing.assert_allclose(s["pdf"][ok], np.abs(wi[:, 2].astype(np.float64)) / np.pi, rtol=4 * F32, atol=0)
    np.testing.assert_allclose(s["eval_pdf"][ok], s["pdf"][ok], rtol=4 * F32, atol=0)
    np.testing.assert_allclose(s["value"][ok] / s["eval_pdf"][ok, None], s["weight"][ok], rtol=8 * F32, atol=0)
    assert not s["delta"].any()


def test_diffuse_sampling(cl_env, prog):
    b = make_bsdf("diffuse", color=COLOR)
    s = sample(cl_env, prog, b, np.tile(WO_UP, (N, 1)), seed=42)
    check_diffuse_lobe(s, +1, "diffuse, wo above")


def test_diffuse_one_sided_from_below(cl_env, prog):
    b = make_bsdf("diffuse", color=COLOR)
    s = sample(cl_env, prog, b, np.tile(WO_DOWN, (1000, 1)), seed=43)
    assert not s["ok"].any(), "a one-sided diffuse surface scattered light arriving from below"
    rng = np.random.default_rng(1)
    wi = unit(rng.normal(size=(1000, 3)))
    val, pdf = eval_pairs(cl_env, prog, b, np.tile(WO_DOWN, (1000, 1)), wi)
    assert np.all(val == 0) and np.all(pdf == 0)
    # and from above, directions below get nothing
    val, pdf = eval_pairs(cl_env, prog, b, np.tile(WO_UP, (1000, 1)), wi)
    below = wi[:, 2] <= 0
    assert np.all(val[below] == 0) and np.all(pdf[below] == 0)
    np.testing.assert_allclose(val[~below], COLOR * wi[~below, 2:3].astype(np.float64) / np.pi, rtol=4 * F32)


def test_diffuse_twosided_from_below(cl_env, prog):
    """A two-sided surface mirrors its lobe to the side wo is on."""
    b = make_bsdf("diffuse", twosided=True, color=COLOR)
    s = sample(cl_env, prog, b, np.tile(WO_DOWN, (N, 1)), seed=44)
    check_diffuse_lobe(s, -1, "two-sided diffuse, wo below")
    rng = np.random.default_rng(2)
    wi = unit(rng.normal(size=(1000, 3)))
    val, pdf = eval_pairs(cl_env, prog, b, np.tile(WO_DOWN, (1000, 1)), wi)
    below = wi[:, 2] < 0
    assert np.all(val[~below] == 0) and np.all(pdf[~below] == 0)
    np.testing.assert_allclose(pdf[below], -wi[below, 2].astype(np.float64) / np.pi, rtol=4 * F32)


# ---- Fresnel in numpy -------------------------------------------------------------------------


def fresnel_exact(cos_i, n):
    """Unpolarized reflectance of a plane interface from the incident side, for the relative complex
    index n = n_t / n_i (k >= 0 absorbs), by the Fresnel equations with complex arithmetic: a
    dielectric past the critical angle gets an imaginary cos_t and |r| = 1 (total internal
    reflection) without a special case."""
    cos_i = np.asarray(cos_i, np.float64)
    n = np.asarray(n, np.complex128)
    sin2 = 1.0 - cos_i ** 2
    n2 = n * n
    root = np.sqrt(n2 - sin2 + 0j)              # n cos_t, principal branch (Im >= 0: a decaying wave)
    rs = (cos_i - root) / (cos_i + root)
    rp = (n2 * cos_i - root) / (n2 * cos_i + root)
    return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)


def test_fresnel_reference_sanity():
    """The numpy reference itself: normal incidence ((n-1)/(n+1))^2, total internal reflection, and
    energy conservation R + T = 1 for a dielectric (T from the transmitted flux)."""
    assert np.isclose(fresnel_exact(1.0, 1.5), 0.04)
    assert np.isclose(fresnel_exact(1.0, 1 / 1.5), 0.04)
    assert np.all(fresnel_exact(np.array([0.5, 0.2, 0.0]), 1 / 1.5) == pytest.approx(1.0))
    c = np.linspace(0.05, 1, 20)
    ct = np.sqrt(1 - (1 - c ** 2) / 1.5 ** 2)
    ts = 2 * c / (c + 1.5 * ct)
    tp = 2 * c / (1.5 * c + ct)
    T = 0.5 * (ts ** 2 + tp ** 2) * 1.5 * ct / c
    np.testing.assert_allclose(fresnel_exact(c, 1.5) + T, 1.0, rtol=1e-12)


# ---- dielectric -------------------------------------------------------------------------------

COS_ANGLES = [1.0, 0.8, 0.5, 0.2, 0.05]
PER_CASE = 100_000


def dielectric_cases(eta_bsdf):
    wos, labels = [], []
    for side in (+1, -1):
        for c in COS_ANGLES:
            s = np.sqrt(1 - c * c)
            wos.append(unit([0.6 * s, -0.8 * s, side * c]))
            labels.append((side, c))
    return wos, labels


@pytest.mark.parametrize("eta_bsdf", [1.5, 1 / 1.5], ids=["eta=1.5", "eta=1/1.5"])
def test_dielectric(cl_env, prog, eta_bsdf):
    b = make_bsdf("dielectric", eta=eta_bsdf)
    wos, labels = dielectric_cases(eta_bsdf)
    s = sample(cl_env, prog, b, np.repeat(np.array(wos), PER_CASE, axis=0), seed=45)
    assert s["ok"].all() and s["delta"].all()
    eta_b = float(np.float32(eta_bsdf))
    for k, (wo, (side, c)) in enumerate(zip(wos, labels)):
        sl = slice(k * PER_CASE, (k + 1) * PER_CASE)
        wi, w, pdf, eta = s["wi"][sl], s["weight"][sl], s["pdf"][sl], s["eta"][sl]
        what = f"dielectric eta={eta_bsdf:.4g}, wo {'above' if side > 0 else 'below'}, cos {c}"
        eta_eff = eta_b if side > 0 else 1.0 / eta_b          # n_transmitted / n_incident
        cos_i = abs(float(wo[2]))
        F = float(fresnel_exact(cos_i, eta_eff))
        refl = np.sign(wi[:, 2]) == side
        stats.assert_probability(np.count_nonzero(refl), PER_CASE, F, f"{what}: reflections")
        # reflection: the mirror direction, weight 1, probability F as the pdf
        assert np.all(wi[refl] == np.array([-wo[0], -wo[1], wo[2]], np.float32)), f"{what}: not the mirror direction"
        assert np.all(w[refl] == 1.0) and np.all(eta[refl] == 1.0)
        # F in float32: a few operations on numbers of size 1, 16 eps; near grazing incidence the
        # float32 cos_i itself is the larger error (|dF/dcos| * eps/2 * cos), estimated numerically
        dF = abs(float(fresnel_exact(cos_i * (1 + 1e-6), eta_eff)) - F) / (cos_i * 1e-6)
        tol = 16 * F32 + dF * cos_i * F32
        assert np.all(np.abs(pdf[refl] - F) <= tol), f"{what}: reflection pdf {pdf[refl][:1]} vs Fresnel {F}"
        t = ~refl
        if not t.any():
            continue
        wt = wi[t].astype(np.float64)
        norms_ok(wi[t], what)
        assert np.all(np.abs(pdf[t] - (1 - F)) <= tol), f"{what}: transmission pdf {pdf[t][:1]} vs 1 - Fresnel {1 - F}"
        # Snell: sin_t = sin_i / eta, in the plane of incidence on the far side of the normal
        sin_i = np.hypot(wo[0], wo[1])
        sin_t = np.hypot(wt[:, 0], wt[:, 1])
        np.testing.assert_allclose(sin_t * eta_eff, sin_i, rtol=16 * F32, atol=4 * F32, err_msg=f"{what}: Snell")
        if sin_i > 0:
            cross = wt[:, 0] * wo[1] - wt[:, 1] * wo[0]
            assert np.all(np.abs(cross) <= 8 * F32) and np.all(wt[:, 0] * wo[0] + wt[:, 1] * wo[1] < 0), \
                f"{what}: refracted direction leaves the plane of incidence"
        # radiance transport: the refracted weight is 1 / eta^2 (eta = n_t / n_i), reported as eta
        np.testing.assert_allclose(w[t], 1.0 / eta_eff ** 2, rtol=4 * F32, err_msg=f"{what}: refraction weight")
        np.testing.assert_allclose(eta[t], eta_eff, rtol=2 * F32)
    # delta lobes evaluate to zero
    assert np.all(s["value"] == 0) and np.all(s["eval_pdf"] == 0)


def test_dielectric_total_internal_reflection(cl_env, prog):
    """Inside glass (eta 1.5) beyond the critical angle asin(1/1.5): reflection with probability 1,
    whatever u1 is (u1 just below 1 included)."""
    b = make_bsdf("dielectric", eta=1.5)
    crit = np.sqrt(1 - 1 / 1.5 ** 2)     # cos of the critical angle, 0.745
    cosines = np.array([0.74, 0.5, 0.1, 1e-3])
    wos = np.array([unit([np.sqrt(1 - c * c), 0.0, -c]) for c in cosines])
    n = 20_000
    u1 = np.tile(np.array([0.0, 0.5, np.float32(1 - 2 ** -24)], np.float32), n)[:n]
    for k, wo in enumerate(wos):
        assert abs(wo[2]) < crit
        s = sample(cl_env, prog, b, np.tile(wo, (n, 1)), seed=46, u1=u1)
        assert np.all(s["wi"][:, 2] < 0), f"cos {cosines[k]}: light escaped under total internal reflection"
        assert np.all(s["wi"] == np.array([-wo[0], -wo[1], wo[2]], np.float32))
        assert np.all(s["pdf"] == 1.0) and np.all(s["weight"] == 1.0)


INDEX_MATCHED_COS = [1.0, 0.7, 0.2, 0.01]


def index_matched_wo(cos_i, side):
    s_ = np.sqrt(1 - cos_i ** 2)
    return unit([0.6 * s_, -0.8 * s_, side * cos_i])


@pytest.mark.parametrize("cos_i", INDEX_MATCHED_COS)
def test_dielectric_index_matched(cl_env, prog, cos_i):
    """eta = 1: every sample passes straight through, with weight 1, from either side."""
    b = make_bsdf("dielectric", eta=1.0)
    n = 100_000
    for side in (+1, -1):
        wo = index_matched_wo(cos_i, side)
        s = sample(cl_env, prog, b, np.tile(wo, (n, 1)), seed=47)
        wi = s["wi"].astype(np.float64)
        refl = np.sign(wi[:, 2]) == side
        assert not refl.any(), f"eta = 1, cos {cos_i}, side {side}: {refl.sum()} of {n} samples reflected"
        np.testing.assert_allclose(wi, np.broadcast_to(-wo.astype(np.float64), wi.shape), rtol=0, atol=8 * F32)
        assert np.all(s["weight"] == 1.0) and np.all(s["eta"] == 1.0)


def test_dielectric_index_matched_grazing(cl_env, prog):
    b = make_bsdf("dielectric", eta=1.0)
    wos = np.array([index_matched_wo(c, side) for c in (1e-4, 2e-4) for side in (1, -1)])
    s = sample(cl_env, prog, b, np.repeat(wos, 1000, axis=0), seed=51)
    refl = np.sign(s["wi"][:, 2]) == np.sign(np.repeat(wos, 1000, axis=0)[:, 2])
    assert not refl.any(), f"eta = 1, grazing incidence: {refl.sum()} of {len(refl)} samples reflected"


def test_dielectric_index_matched_u1_zero(cl_env, prog):
    b = make_bsdf("dielectric", eta=1.0)
    wos = np.array([index_matched_wo(c, side) for c in INDEX_MATCHED_COS for side in (1, -1)])
    s = sample(cl_env, prog, b, wos, seed=50, u1=np.zeros(len(wos), np.float32))
    refl = np.sign(s["wi"][:, 2]) == np.sign(wos[:, 2])
    assert not refl.any(), (f"eta = 1, u1 = 0: reflected at cos {np.abs(wos[refl, 2]).tolist()} with Fresnel "
                            f"pdf {s['pdf'][refl].tolist()}")


def test_fresnel_dielectric_function(cl_env, prog):
    """fresnel_dielectric on a dense grid against the complex Fresnel equations, with a tolerance
    from first-order error propagation: 16 eps of arithmetic on numbers of size 1, plus |dF/dcos_i|
    times the rounding of cos_i (eps cos_i) and of sin2_t = (1 - cos_i^2) / eta^2 (4 eps, i.e.
    2 eta^2 eps / cos_i in cos_i); the last dominates next to the critical angle."""
    check_fresnel_dielectric(cl_env, prog, (1.5, 1 / 1.5, 2.4, 1.01, 1 / 1.01))


def test_fresnel_dielectric_index_matched(cl_env, prog):
    """No interface, no reflection: F = 0 at every angle."""
    check_fresnel_dielectric(cl_env, prog, (1.0,))


def check_fresnel_dielectric(cl_env, prog, etas):
    cos_i = np.linspace(1e-4, 1.0, 20001).astype(np.float32)
    for eta in etas:
        f, ct = run_kernel(cl_env, prog, "fresnel_dielectric_grid", len(cos_i), [(f32, ()), (f32, ())], f32(eta),
                           inputs=[cos_i])
        e = float(np.float32(eta))
        c = cos_i.astype(np.float64)
        ref = fresnel_exact(c, e)
        h = 1e-7
        dF = np.abs(fresnel_exact(np.minimum(c + h, 1), e) - fresnel_exact(np.maximum(c - h, 0), e)) / (2 * h)
        sin2_t = (1 - c * c) / (e * e)
        # at the critical angle F jumps from its limit to 1 within one float32 step of sin2_t: a
        # step in the reference, where the tolerance must allow the whole jump
        near_crit = np.abs(sin2_t - 1) <= 8 * F32
        tol = 16 * F32 + dF * (c * F32 + 2 * e * e * F32 / c) + np.where(near_crit, 1.0, 0.0)
        bad = np.abs(f - ref) > tol
        i = np.argmax(np.abs(f - ref) - tol)
        assert not bad.any(), f"eta {eta}: F({c[i]:.7f}) = {f[i]:.8g}, reference {ref[i]:.8g} ({bad.sum()} points)"
        tir = sin2_t >= 1
        assert np.all(f[tir & ~near_crit] == 1.0) and np.all(ct[tir & ~near_crit] == 0.0)
        # cos_t = sqrt(1 - sin2_t): sin2_t carries ~4 eps of rounding, which moves cos_t by 2 eps / cos_t
        ok = ~tir & ~near_crit
        ct_ref = np.sqrt(1 - sin2_t[ok])
        assert np.all(np.abs(ct[ok] - ct_ref) <= 8 * F32 + 2 * F32 / ct_ref), f"eta {eta}: cos_t"


# ---- conductor --------------------------------------------------------------------------------


def test_fresnel_conductor_function(cl_env, prog):
    """fresnel_conductor (pbrt-v3's closed form) against the complex Fresnel equations for a gold-like
    eta + i k. The closed form works with terms up to |n|^2 ~ 16 and two differences of them: 64 eps
    absolute on a reflectance in [0, 1] covers that chain of about 20 float32 operations."""
    cos_i = np.concatenate([np.linspace(1e-3, 1.0, 4001), [1e-6, 1e-5]]).astype(np.float32)
    eta_k = np.array([GOLD_ETA, GOLD_K], np.float32)
    (f,) = run_kernel(cl_env, prog, "fresnel_conductor_grid", len(cos_i), [(f32, (3,))], inputs=[cos_i, eta_k])
    n = eta_k[0].astype(np.float64) + 1j * eta_k[1].astype(np.float64)
    ref = fresnel_exact(cos_i.astype(np.float64)[:, None], n[None])
    err = np.abs(f - ref)
    i = np.unravel_index(np.argmax(err), err.shape)
    assert err.max() <= 64 * F32, f"cos {cos_i[i[0]]}, channel {i[1]}: {f[i]:.8g} vs {ref[i]:.8g}"


@pytest.mark.parametrize("twosided", [False, True])
def test_conductor(cl_env, prog, twosided):
    color = np.array([0.9, 0.8, 0.7], np.float32)
    b = make_bsdf("conductor", twosided=twosided, color=color)
    cosines = np.array([1.0, 0.8, 0.5, 0.2, 0.05])
    wos = [unit([0.6 * np.sqrt(1 - c * c), -0.8 * np.sqrt(1 - c * c), side * c]) for side in (1, -1) for c in cosines]
    wos = np.array(wos)
    s = sample(cl_env, prog, b, np.repeat(wos, 10, axis=0), seed=48)
    wo = np.repeat(wos, 10, axis=0)
    above = wo[:, 2] > 0
    sampled = above | twosided
    assert np.array_equal(s["ok"], sampled), "conductor: sampled where it should not, or refused"
    ok = s["ok"]
    assert np.all(s["wi"][ok] == wo[ok] * np.array([-1, -1, 1], np.float32)), "conductor: not the mirror direction"
    assert np.all(s["delta"][ok]) and np.all(s["pdf"][ok] == 1.0)
    n = np.array(GOLD_ETA, np.float32).astype(np.float64) + 1j * np.array(GOLD_K, np.float32).astype(np.float64)
    F = fresnel_exact(np.abs(wo[ok, 2]).astype(np.float64)[:, None], n[None])
    np.testing.assert_allclose(s["weight"][ok], color * F, rtol=0, atol=64 * F32)
    assert np.all(s["value"] == 0) and np.all(s["eval_pdf"] == 0)
    # without eta/k: a mirror that reflects `color`
    m = make_bsdf("conductor", twosided=twosided, color=color, mirror=True)
    s = sample(cl_env, prog, m, wo, seed=49)
    assert np.array_equal(s["ok"], sampled)
    assert np.all(s["weight"][s["ok"]] == color)
