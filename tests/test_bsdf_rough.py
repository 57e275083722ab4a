"""Microfacet and layered bsdfs (kernels/bsdf_rough.h, bsdf.h, microfacet.h) against the float64
reference models of tests/microfacet_ref.py (Mitsuba 3.9's definitions):

- evaluation and pdf pointwise against the reference;
- sampling against the reference pdf by chi-square (every microfacet bsdf, Beckmann and GGX,
  visible-normal and all-normal sampling, isotropic and anisotropic, roughness 0.01 to 1, narrow
  lobes histogrammed in charts around their axes), the samples the sampler refuses counted against
  the mass the pdf leaves out;
- the sample's pdf and weight are those that evaluation gives for its direction (pdf = eval where
  sampling is exact);
- white furnace: the mean sample weight (the albedo, transmission counted with its eta^2) equals the
  reference's integral of f cos and never exceeds 1; an index-matched rough dielectric passes every
  direction straight on, losing only the exit's masking;
- thin dielectrics and plastics: their discrete choices are binomial with Mitsuba's probabilities.
"""
import numpy as np
import pytest

import microfacet_ref as ref
import stats
from conftest import run_kernel
from test_bsdf import GOLD_ETA, GOLD_K, fresnel_exact, sample, unit
from volcl import microfacet
from volcl.pack_materials import MaterialPacker
from volcl.scene.model import Bsdf, rgb

pytestmark = pytest.mark.every_implementation

F32 = float(np.finfo(np.float32).eps)
f32 = np.float32
N = 200_000


@pytest.fixture(scope="module")
def prog(test_program):
    return test_program("sampling_tests.cl")


def packed(bsdf: Bsdf):
    arrays = MaterialPacker([bsdf]).arrays()
    return arrays["bsdfs"], arrays["bsdf_tables"]


def eval_pairs(cl_env, prog, b, tables, wo, wi):
    wo, wi = np.ascontiguousarray(wo, np.float32), np.ascontiguousarray(wi, np.float32)
    return run_kernel(cl_env, prog, "bsdf_eval_pairs", len(wo), [(f32, (3,)), (f32, ())],
                      inputs=[b, np.asarray(tables, np.float32), wo, wi])


def direction(cos_theta, phi=0.7, side=1.0):
    s = np.sqrt(1 - cos_theta ** 2)
    return unit([s * np.cos(phi), s * np.sin(phi), side * cos_theta])


def conductor(kind="ggx", au=0.3, av=None, visible=True, mirror=False):
    b = Bsdf("roughconductor", distribution=kind, alpha_u=au, alpha_v=au if av is None else av,
             anisotropic=av is not None, sample_visible=visible)
    if not mirror:
        b.eta, b.k = np.array(GOLD_ETA), np.array(GOLD_K)
    return b


def dielectric(kind="ggx", au=0.3, av=None, visible=True, eta=1.5):
    return Bsdf("roughdielectric", distribution=kind, alpha_u=au, alpha_v=au if av is None else av,
                anisotropic=av is not None, sample_visible=visible, int_ior=eta, ext_ior=1.0)


def gold(cos):
    n = np.array(GOLD_ETA, np.float32).astype(np.float64) + 1j * np.array(GOLD_K, np.float32).astype(np.float64)
    return fresnel_exact(np.abs(cos)[..., None], n)


def ref_conductor(b, wo, wi):
    fres = (lambda c: np.ones(c.shape + (3,))) if b.eta is None else gold
    return ref.roughconductor(wo, wi, b.distribution, b.alpha_u, b.alpha_v, b.sample_visible, fres)


def ref_dielectric(b, wo, wi):
    value, pdf = ref.roughdielectric(wo, wi, b.distribution, b.alpha_u, b.alpha_v, b.sample_visible,
                                     float(f32(b.int_ior / b.ext_ior)))
    return np.repeat(value[..., None], 3, -1), pdf


def ref_roughplastic(b, tables, wo, wi):
    eta = float(f32(b.int_ior / b.ext_ior))
    _, internal = microfacet.roughplastic_tables(b.distribution, float(b.alpha_u), eta)
    sw = 1.0 / (np.mean(b.reflectance) + 1.0)
    return ref.roughplastic(wo, wi, b.distribution, float(b.alpha_u), b.sample_visible, eta, b.reflectance,
                            tables[:64].astype(np.float64), internal, sw, b.nonlinear)


def lobe_charts(b, wo):
    """Charts for the chi-square test: around the mirror direction (and the refracted one), as wide
    as the lobe."""
    width = max(4.0 * max(b.alpha_u, b.alpha_v), 0.02)
    mirror = np.array([-wo[0], -wo[1], wo[2]], np.float64)
    if b.kind != "roughdielectric":
        return [(mirror, width, lambda d: np.ones(d.shape[:-1], bool))]
    eta = b.int_ior / b.ext_ior
    e = eta if wo[2] > 0 else 1 / eta
    sin_t = np.hypot(wo[0], wo[1]) / e
    if sin_t < 1:
        refr = unit([-wo[0] / e, -wo[1] / e, -np.sign(wo[2]) * np.sqrt(1 - sin_t ** 2)]).astype(np.float64)
    else:
        refr = np.array([0.0, 0.0, -np.sign(wo[2])])
    side = np.sign(wo[2])
    return [(mirror, width, lambda d: d[..., 2] * side >= 0),
            (refr, width * (1 + e), lambda d: d[..., 2] * side < 0)]


# ---- pointwise evaluation ---------------------------------------------------------------------

EVAL_CASES = [("beckmann", 0.1, None), ("ggx", 0.1, None), ("beckmann", 0.6, 0.2), ("ggx", 0.05, 0.5),
              ("ggx", 1.0, None), ("beckmann", 0.01, None)]


def random_pairs(n, seed, spread=1.0):
    rng = np.random.default_rng(seed)
    wo = unit(rng.normal(size=(n, 3)) * [1, 1, 2])
    wo[:, 2] = np.abs(wo[:, 2])
    wi = unit(rng.normal(size=(n, 3)))
    return wo.astype(np.float32), wi.astype(np.float32)


def assert_close_to_reference(got, want, what, rtol=2e-4, conditioned=None):
    """conditioned: the pairs whose half vector float32 determines well (|wo + wi| not tiny: near
    retro-reflection at grazing angles a rounding of wo or wi turns it, and D with it)."""
    got, want = np.asarray(got, np.float64), np.asarray(want, np.float64)
    assert np.isfinite(got).all(), f"{what}: non-finite values"
    if conditioned is not None:
        got, want = got[conditioned], want[conditioned]
    scale = np.abs(want).max()
    bad = np.abs(got - want) > rtol * np.abs(want) + 1e-5 * scale
    i = np.argmax(np.abs(got - want) - rtol * np.abs(want))
    assert not bad.any(), (f"{what}: {bad.sum()} of {bad.size} values off the reference, e.g. {got.flat[i]:.7g} vs "
                           f"{want.flat[i]:.7g}")


@pytest.mark.parametrize("kind,au,av", EVAL_CASES)
@pytest.mark.parametrize("visible", [True, False], ids=["visible", "all-normals"])
def test_roughconductor_eval_matches_reference(cl_env, prog, kind, au, av, visible):
    b = conductor(kind, au, av, visible)
    rec, tables = packed(b)
    wo, wi = random_pairs(20000, 5)
    # half the pairs near the specular lobe, where the values are large
    wi[::2] = unit(np.array([-wo[::2, 0], -wo[::2, 1], wo[::2, 2]]).T + 0.3 * au * np.random.default_rng(1).normal(size=(10000, 3)))
    value, pdf = eval_pairs(cl_env, prog, rec, tables, wo, wi)
    rv, rp = ref_conductor(b, wo.astype(np.float64), wi.astype(np.float64))
    good = np.linalg.norm(wo.astype(np.float64) + wi, axis=1) > 0.1
    assert_close_to_reference(value, rv, "roughconductor value", conditioned=good)
    assert_close_to_reference(pdf, rp, "roughconductor pdf", conditioned=good)


@pytest.mark.parametrize("kind,au,av", EVAL_CASES)
@pytest.mark.parametrize("visible", [True, False], ids=["visible", "all-normals"])
def test_roughdielectric_eval_matches_reference(cl_env, prog, kind, au, av, visible):
    b = dielectric(kind, au, av, visible)
    rec, tables = packed(b)
    wo, wi = random_pairs(20000, 6)
    wo[1::2, 2] *= -1          # half from inside
    value, pdf = eval_pairs(cl_env, prog, rec, tables, wo, wi)
    rv, rp = ref_dielectric(b, wo.astype(np.float64), wi.astype(np.float64))
    e = np.where(wo[:, 2] > 0, 1.5, 1 / 1.5)[:, None]
    h = wo.astype(np.float64) + np.where(wo[:, 2:] * wi[:, 2:] > 0, 1.0, e) * wi
    good = np.linalg.norm(h, axis=1) > 0.1
    assert_close_to_reference(value, rv, "roughdielectric value", rtol=1e-3, conditioned=good)
    assert_close_to_reference(pdf, rp, "roughdielectric pdf", rtol=1e-3, conditioned=good)


@pytest.mark.parametrize("kind,alpha", [("beckmann", 0.1), ("ggx", 0.3), ("ggx", 1.0)])
def test_roughplastic_eval_matches_reference(cl_env, prog, kind, alpha):
    b = Bsdf("roughplastic", distribution=kind, alpha_u=alpha, alpha_v=alpha, reflectance=rgb([0.7, 0.4, 0.1]),
             int_ior=1.49, ext_ior=1.000277)
    rec, tables = packed(b)
    wo, wi = random_pairs(20000, 7)
    value, pdf = eval_pairs(cl_env, prog, rec, tables, wo, wi)
    rv, rp = ref_roughplastic(b, tables, wo.astype(np.float64), wi.astype(np.float64))
    good = np.linalg.norm(wo.astype(np.float64) + wi, axis=1) > 0.1
    assert_close_to_reference(value, rv, "roughplastic value", rtol=1e-3, conditioned=good)
    assert_close_to_reference(pdf, rp, "roughplastic pdf", rtol=1e-3, conditioned=good)


def test_beckmann_masking_fit_is_within_mitsubas_bound():
    """Mitsuba's rational Beckmann G1 is within 0.35% of the exact Smith function."""
    a = np.linspace(1e-3, 1.6, 20001)
    m = np.array([0.0, 0.0, 1.0])
    v = np.stack([np.ones_like(a), np.zeros_like(a), a], -1)       # tan theta = 1 / a at alpha 1
    fit = ref.G1("beckmann", 1.0, 1.0, v, m)
    exact = ref.beckmann_g1_exact(a)
    assert np.max(np.abs(fit / exact - 1)) < 0.0035


# ---- sampling ---------------------------------------------------------------------------------

ALPHAS = [0.01, 0.1, 0.5, 1.0]
CONDUCTOR_CASES = ([(k, v, a, None, 0.6) for k in ("beckmann", "ggx") for v in (True, False) for a in ALPHAS]
                   + [(k, True, 0.05, 0.4, 0.6) for k in ("beckmann", "ggx")]
                   + [(k, False, 0.3, 0.08, 0.6) for k in ("beckmann", "ggx")]
                   + [("ggx", True, 0.3, None, 0.1), ("beckmann", True, 0.3, None, 0.1)])


def mitsuba_widened_weight(b, wo, wi):
    """The weight Mitsuba's roughdielectric gives a sample drawn without visible normals: it draws
    from the widened distribution but weights as if from the actual one, G (wo.m) / (cos_o m.z),
    leaving out D(m) / D_widened(m); its estimator is biased there (volcl renders what it renders)."""
    ci = wo[..., 2]
    reflect = ci * wi[..., 2] > 0
    eta = b.int_ior / b.ext_ior
    e = np.where(ci > 0, eta, 1 / eta)
    m = ref.normalize(wo + wi * np.where(reflect, 1.0, e)[..., None])
    m = m * np.sign(m[..., 2])[..., None]
    g = ref.G1(b.distribution, b.alpha_u, b.alpha_v, wo, m) * ref.G1(b.distribution, b.alpha_u, b.alpha_v, wi, m)
    return g * ref.dot(wo, m) / (ci * m[..., 2]) * np.where(reflect, 1.0, 1 / e ** 2)


def check_sampling(cl_env, prog, b, wo, reference, what, seed):
    rec, tables = packed(b)
    s = sample(cl_env, prog, rec, np.tile(wo, (N, 1)), seed=seed, tables=tables)
    ok = s["ok"]
    assert not s["delta"][ok].any() and not s["null"].any()
    wi = s["wi"][ok].astype(np.float64)
    # pdf = eval where sampling is exact: the sample's own pdf and weight are evaluation's
    np.testing.assert_allclose(s["pdf"][ok], s["eval_pdf"][ok], rtol=2e-3, atol=0, err_msg=f"{what}: pdf")
    if b.kind == "roughdielectric" and not b.sample_visible:
        expected = mitsuba_widened_weight(b, np.broadcast_to(wo.astype(np.float64), wi.shape), wi)
        np.testing.assert_allclose(s["weight"][ok, 0], expected, rtol=2e-3, err_msg=f"{what}: Mitsuba's weight")
    else:
        np.testing.assert_allclose(s["weight"][ok] * s["pdf"][ok, None], s["value"][ok], rtol=2e-3,
                                   atol=1e-6 * float(np.abs(s["value"][ok]).max()), err_msg=f"{what}: weight")
    pdf = lambda d: reference(np.broadcast_to(wo.astype(np.float64), d.shape), d)[1]   # noqa: E731
    if max(b.alpha_u, b.alpha_v) < 0.2 and abs(wo[2]) > 0.3:
        # narrow lobes, far from the horizon: cells around their axes
        stats.chi2_directions_charts(wi, pdf, lobe_charts(b, wo), refused=int((~ok).sum()), what=what)
    else:
        # wide lobes: the hemispheres, with a cell edge at the horizon where the pdfs may jump
        zones = [(0.0, 1.0), (-1.0, 0.0)] if b.kind == "roughdielectric" else [(0.0, 1.0)]
        stats.chi2_directions_zones(wi, pdf, zones, refused=int((~ok).sum()), what=what)
    return s


@pytest.mark.parametrize("kind,visible,au,av,cos_o", CONDUCTOR_CASES)
def test_roughconductor_sampling(cl_env, prog, kind, visible, au, av, cos_o):
    b = conductor(kind, au, av, visible)
    wo = direction(cos_o)
    check_sampling(cl_env, prog, b, wo, lambda o, d: ref_conductor(b, o, d),
                   f"roughconductor {kind} {'visible' if visible else 'all'} alpha {au}/{av}, cos {cos_o}", seed=61)


DIELECTRIC_CASES = ([(k, v, a, None, 0.6, 1) for k in ("beckmann", "ggx") for v in (True, False) for a in ALPHAS]
                    + [(k, v, 0.3, None, 0.6, -1) for k in ("beckmann", "ggx") for v in (True, False)]
                    + [(k, True, 0.05, 0.3, 0.7, s) for k in ("beckmann", "ggx") for s in (1, -1)])


@pytest.mark.parametrize("kind,visible,au,av,cos_o,side", DIELECTRIC_CASES)
def test_roughdielectric_sampling(cl_env, prog, kind, visible, au, av, cos_o, side):
    b = dielectric(kind, au, av, visible)
    wo = direction(cos_o, side=side)
    check_sampling(cl_env, prog, b, wo, lambda o, d: ref_dielectric(b, o, d),
                   f"roughdielectric {kind} {'visible' if visible else 'all'} alpha {au}/{av}, cos {cos_o} "
                   f"{'outside' if side > 0 else 'inside'}", seed=62)


@pytest.mark.parametrize("kind,alpha,visible", [("beckmann", 0.01, True), ("ggx", 0.01, True), ("beckmann", 0.3, True),
                                                ("ggx", 0.3, False), ("ggx", 1.0, True), ("beckmann", 1.0, False)])
def test_roughplastic_sampling(cl_env, prog, kind, alpha, visible):
    b = Bsdf("roughplastic", distribution=kind, alpha_u=alpha, alpha_v=alpha, sample_visible=visible,
             reflectance=rgb([0.5, 0.3, 0.2]), int_ior=1.49, ext_ior=1.000277)
    rec, tables = packed(b)
    wo = direction(0.5)
    # the specular lobe gets its chart; the diffuse lobe lies wide over the rest
    check_sampling(cl_env, prog, b, wo, lambda o, d: ref_roughplastic(b, tables, o, d),
                   f"roughplastic {kind} alpha {alpha} {'visible' if visible else 'all'}", seed=63)


# ---- furnace ----------------------------------------------------------------------------------

FURNACE_CASES = [(conductor("ggx", a, mirror=True), a) for a in (0.01, 0.3, 1.0)] + \
                [(conductor("beckmann", 0.5, 0.1, mirror=True), 0.5)] + \
                [(dielectric("ggx", a), a) for a in (0.01, 0.3, 1.0)] + [(dielectric("beckmann", 0.6, visible=False), 0.6)]


@pytest.mark.parametrize("bsdf,alpha", FURNACE_CASES, ids=[f"{b.kind}-{b.distribution}-{a}-{i}"
                                                            for i, (b, a) in enumerate(FURNACE_CASES)])
def test_white_furnace(cl_env, prog, bsdf, alpha):
    """The albedo, estimated by the mean sample weight (eta^2 undoing radiance's compression on
    transmission), equals the reference's integral of f cos over the sphere and stays below 1."""
    rec, tables = packed(bsdf)
    for cos_o in (0.9, 0.3):
        wo = direction(cos_o)
        s = sample(cl_env, prog, rec, np.tile(wo, (N, 1)), seed=64, tables=tables)
        w = np.where(s["ok"][:, None], s["weight"], 0.0).astype(np.float64)
        w = w * np.where(s["eta"] != 1.0, s["eta"] ** 2, 1.0)[:, None]
        reference = ref_conductor if bsdf.kind == "roughconductor" else ref_dielectric

        eta = bsdf.int_ior / bsdf.ext_ior

        def energy(d, wo=wo):
            v, _ = reference(bsdf, np.broadcast_to(wo.astype(np.float64), d.shape), d)
            return v[..., 0] * np.where(d[..., 2] * wo[2] < 0, eta ** 2, 1.0)

        def mitsubas_estimate(d, wo=wo):
            o = np.broadcast_to(wo.astype(np.float64), d.shape)
            _, p = reference(bsdf, o, d)
            return p * mitsuba_widened_weight(bsdf, o, d) * np.where(d[..., 2] * wo[2] < 0, eta ** 2, 1.0)

        def integral(f):
            return sum(float(np.sum(stats.integrate_cells_2d(
                _chart_integrand(f, axis, width, region), np.linspace(0, np.pi / (np.pi + width), 32),
                np.linspace(0, 2 * np.pi, 62), lambda p: 1e-7))) for axis, width, region in lobe_charts(bsdf, wo))
        albedo = integral(energy)
        assert albedo <= 1 + 1e-6, f"{bsdf.kind}: the reference albedo {albedo} exceeds 1"
        what = f"{bsdf.kind} {bsdf.distribution} alpha {alpha}, cos {cos_o}: albedo"
        if bsdf.kind == "roughdielectric" and not bsdf.sample_visible:
            # Mitsuba's estimator here is biased (mitsuba_widened_weight): its own expectation
            stats.assert_mean(w[:, :1], integral(mitsubas_estimate), what + " (Mitsuba's estimator)")
        else:
            stats.assert_mean(w[:, :1], albedo, what)


def _chart_integrand(f, axis, width, region):
    e1, e2, a = stats._chart_frame(axis)

    def g(tt, pp):
        th = width * tt / (1.0 - tt)
        st = np.sin(th)
        d = (st * np.cos(pp))[..., None] * e1 + (st * np.sin(pp))[..., None] * e2 + np.cos(th)[..., None] * a
        return f(d) * np.where(region(d), 1.0, 0.0) * st * width / (1.0 - tt) ** 2
    return g


@pytest.mark.parametrize("kind,alpha", [("ggx", 0.01), ("ggx", 0.5), ("beckmann", 0.2)])
def test_index_matched_roughdielectric_passes_straight_on(cl_env, prog, kind, alpha):
    """eta = 1: no reflection, every direction continues unchanged, weighted by the masking of the
    exit direction, G1(-wo) (the loss of a single-scattering microfacet model)."""
    b = dielectric(kind, alpha, eta=1.0)
    rec, tables = packed(b)
    for cos_o in (0.95, 0.4):
        wo = direction(cos_o)
        s = sample(cl_env, prog, rec, np.tile(wo, (N // 4, 1)), seed=65, tables=tables)
        ok = s["ok"]
        assert ok.mean() > 0.99
        np.testing.assert_allclose(s["wi"][ok], np.broadcast_to(-wo, s["wi"][ok].shape), atol=16 * F32)
        assert np.all(s["eta"][ok] == 1.0)
        # Smith's G1 depends on m only through the side it faces, which visible normals always pass
        o = wo.astype(np.float64)
        expected = float(ref.G1(kind, alpha, alpha, -o, np.array([0.0, 0.0, 1.0])))
        assert expected <= 1.0
        np.testing.assert_allclose(s["weight"][ok], expected, rtol=1e-5, err_msg=f"{kind} alpha {alpha}, cos {cos_o}")


# ---- thin dielectric, plastic, mask -----------------------------------------------------------


def test_thindielectric(cl_env, prog):
    b = Bsdf("thindielectric", int_ior=1.5, ext_ior=1.0, specular_reflectance=rgb([0.9, 0.8, 0.7]),
             specular_transmittance=rgb([0.5, 0.6, 0.7]))
    rec, tables = packed(b)
    for cos_o, side in ((0.9, 1), (0.3, 1), (0.6, -1)):
        wo = direction(cos_o, side=side)
        s = sample(cl_env, prog, rec, np.tile(wo, (N // 4, 1)), seed=66, tables=tables)
        assert s["ok"].all() and s["delta"].all()
        r = float(ref.fresnel_dielectric(cos_o, 1.5))
        r = 2 * r / (1 + r)
        refl = ~s["null"]
        stats.assert_probability(refl.sum(), len(refl), r, f"thindielectric cos {cos_o}: reflections")
        assert np.all(s["wi"][refl] == wo * np.array([-1, -1, 1], np.float32))
        assert np.all(s["wi"][~refl] == -wo)
        assert np.all(s["weight"][refl] == np.array([0.9, 0.8, 0.7], np.float32))
        assert np.all(s["weight"][~refl] == np.array([0.5, 0.6, 0.7], np.float32))
        assert np.all(s["value"] == 0)


@pytest.mark.parametrize("nonlinear", [False, True])
def test_plastic(cl_env, prog, nonlinear):
    """The specular lobe is picked with Mitsuba's probability (Fresnel times the specular weight,
    normalized), the diffuse samples follow the diffuse lobe's pdf, and weights are value / pdf."""
    diffuse = np.array([0.6, 0.3, 0.1])
    b = Bsdf("plastic", reflectance=rgb(diffuse), int_ior=1.49, ext_ior=1.000277, nonlinear=nonlinear)
    rec, tables = packed(b)
    eta = float(f32(1.49 / 1.000277))
    sw = 1.0 / (diffuse.mean() + 1.0)
    fdr = microfacet.fresnel_diffuse_reflectance(1 / eta)
    wo = direction(0.4)
    s = sample(cl_env, prog, rec, np.tile(wo, (N, 1)), seed=67, tables=tables)
    fi = float(ref.fresnel_dielectric(0.4, eta))
    p_spec = fi * sw / (fi * sw + (1 - fi) * (1 - sw))
    spec = s["delta"]
    stats.assert_probability(spec.sum(), len(spec), p_spec, "plastic: specular samples")
    np.testing.assert_allclose(s["weight"][spec], np.full((spec.sum(), 3), fi / p_spec), rtol=1e-5)
    d = s["ok"] & ~spec
    pdf = lambda v: ref.plastic_diffuse(np.broadcast_to(wo.astype(np.float64), v.shape), v, eta, diffuse, fdr, sw,  # noqa: E731
                                        nonlinear)[1] / (1 - p_spec)
    stats.chi2_directions(s["wi"][d], pdf, cos_range=(0.0, 1.0), what="plastic: diffuse samples")
    rv, rp = ref.plastic_diffuse(np.broadcast_to(wo.astype(np.float64), s["wi"][d].shape),
                                 s["wi"][d].astype(np.float64), eta, diffuse, fdr, sw, nonlinear)
    np.testing.assert_allclose(s["value"][d], rv, rtol=1e-4)
    np.testing.assert_allclose(s["eval_pdf"][d], rp, rtol=1e-4)
    np.testing.assert_allclose(s["weight"][d] * s["pdf"][d, None], s["value"][d], rtol=1e-4)


def test_mask_passes_with_one_minus_opacity(cl_env, prog):
    """A mask around a diffuse bsdf: a null event (straight on, weight 1) with probability
    1 - opacity, else the wrapped bsdf, whose value and pdf scale by the opacity."""
    inner = Bsdf("diffuse", reflectance=rgb(0.5))
    b = Bsdf("mask", opacity=0.3, nested=inner)
    rec, tables = packed(b)
    wo = direction(0.7)
    s = sample(cl_env, prog, rec, np.tile(wo, (N // 4, 1)), seed=68, tables=tables)
    stats.assert_probability(s["null"].sum(), len(s["null"]), 0.7, "mask: passes")
    assert np.all(s["wi"][s["null"]] == -wo) and np.all(s["weight"][s["null"]] == 1)
    d = s["ok"] & ~s["null"]
    np.testing.assert_allclose(s["eval_pdf"][d], 0.3 * s["wi"][d, 2] / np.pi, rtol=1e-5)
    np.testing.assert_allclose(s["value"][d], np.repeat(0.3 * 0.5 * s["wi"][d, 2:] / np.pi, 3, 1), rtol=1e-5)
    np.testing.assert_allclose(s["weight"][d], 0.5, rtol=1e-5)


def test_roughplastic_tables_are_kept_between_processes(tmp_path, monkeypatch):
    """The tables come back from the cache folder bit for bit; a damaged file is computed again."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    args = ("ggx", 0.3, 1.5)
    fresh = microfacet._computed_tables(*args)
    microfacet.roughplastic_tables.cache_clear()
    first = microfacet.roughplastic_tables(*args)
    path = microfacet._table_file(*args)
    assert path.is_file()
    microfacet.roughplastic_tables.cache_clear()
    compute = microfacet._computed_tables
    monkeypatch.setattr(microfacet, "_computed_tables", lambda *a: pytest.fail("the stored tables were not read"))
    again = microfacet.roughplastic_tables(*args)
    monkeypatch.setattr(microfacet, "_computed_tables", compute)
    for got in (first, again):
        np.testing.assert_array_equal(got[0], fresh[0])
        assert got[1] == fresh[1]
    path.write_bytes(b"not a table")
    microfacet.roughplastic_tables.cache_clear()
    damaged = microfacet.roughplastic_tables(*args)
    np.testing.assert_array_equal(damaged[0], fresh[0])
    assert damaged[1] == fresh[1]
    microfacet.roughplastic_tables.cache_clear()
