"""Reference microfacet bsdfs in float64 numpy, written from the definitions in Mitsuba 3.9's
microfacet.h and src/bsdfs/rough*.cpp, plastic.cpp (what volcl promises to match), for tests:
value = f |cos wi| and the sampling density of every model, for directions wo (towards the viewer)
and wi (..., 3) in the local frame (normal +z).

Conductor Fresnel comes from the complex Fresnel equations (test_bsdf.fresnel_exact), dielectric
Fresnel from the textbook equations with Mitsuba's two special cases (an index-matched interface
reflects nothing, grazing incidence everything). Beckmann masking is Mitsuba's rational fit, and
`beckmann_g1_exact` is the exact function the fit approximates.
"""
import numpy as np
from scipy.special import erf


def dot(a, b):
    return np.sum(a * b, axis=-1)


def normalize(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def D(kind, au, av, m):
    au, av = np.maximum(au, 1e-4), np.maximum(av, 1e-4)
    ct2 = m[..., 2] ** 2
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        if kind == "beckmann":
            r = np.exp(-((m[..., 0] / au) ** 2 + (m[..., 1] / av) ** 2) / ct2) / (np.pi * au * av * ct2 ** 2)
        else:
            r = 1.0 / (np.pi * au * av * ((m[..., 0] / au) ** 2 + (m[..., 1] / av) ** 2 + ct2) ** 2)
    return np.where(m[..., 2] > 0, np.nan_to_num(r), 0.0)


def G1(kind, au, av, v, m):
    au, av = np.maximum(au, 1e-4), np.maximum(av, 1e-4)
    xy = (au * v[..., 0]) ** 2 + (av * v[..., 1]) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        tan2 = xy / v[..., 2] ** 2
        if kind == "beckmann":
            a = 1.0 / np.sqrt(tan2)
            r = np.where(a >= 1.6, 1.0, (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a))
        else:
            r = 2.0 / (1.0 + np.sqrt(1.0 + tan2))
    r = np.where(xy == 0, 1.0, np.nan_to_num(r))
    return np.where(dot(v, m) * v[..., 2] <= 0, 0.0, r)


def beckmann_g1_exact(a):
    """Smith's G1 = 1 / (1 + Lambda) of the Beckmann distribution, a = 1 / (alpha tan theta)."""
    lam = (erf(a) - 1.0) / 2.0 + np.exp(-a * a) / (2.0 * a * np.sqrt(np.pi))
    return 1.0 / (1.0 + lam)


def pdf_m(kind, au, av, visible, wo, m):
    """Density of the sampled microfacet normal, per solid angle of m."""
    d = D(kind, au, av, m)
    if visible:
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.nan_to_num(d * G1(kind, au, av, wo, m) * np.abs(dot(wo, m)) / wo[..., 2])
    return d * m[..., 2]


def fresnel_dielectric(cos_i, eta):
    """Reflectance for signed cos_i (< 0: from inside, relative IOR 1 / eta)."""
    cos_i = np.asarray(cos_i, np.float64)
    e = np.where(cos_i >= 0, eta, 1.0 / eta)
    ci = np.abs(cos_i)
    st2 = (1 - ci ** 2) / e ** 2
    ct = np.sqrt(np.maximum(1 - st2, 0))
    with np.errstate(divide="ignore", invalid="ignore"):
        rs = (ci - e * ct) / (ci + e * ct)
        rp = (e * ci - ct) / (e * ci + ct)
    r = np.where(st2 >= 1, 1.0, 0.5 * (rs ** 2 + rp ** 2))
    if eta == 1.0:
        return np.zeros_like(r)
    return np.where(ci == 0, 1.0, r)


def roughconductor(wo, wi, kind, au, av, visible, fresnel):
    """(value (..., channels), pdf); fresnel(cos) -> reflectance per channel."""
    h = normalize(wo + wi)
    ok = (wo[..., 2] > 0) & (wi[..., 2] > 0) & (dot(wo, h) > 0) & (dot(wi, h) > 0)
    d = D(kind, au, av, h)
    g = G1(kind, au, av, wo, h) * G1(kind, au, av, wi, h)
    with np.errstate(divide="ignore", invalid="ignore"):
        value = (d * g / (4 * wo[..., 2]))[..., None] * fresnel(dot(wo, h))
        pdf = pdf_m(kind, au, av, visible, wo, h) / (4 * dot(wi, h))
    return np.where(ok[..., None], np.nan_to_num(value), 0.0), np.where(ok, np.nan_to_num(pdf), 0.0)


def roughdielectric(wo, wi, kind, au, av, visible, eta):
    """(value, pdf) of both lobes (radiance transport: transmission compressed by 1 / eta^2)."""
    ci, co = wo[..., 2], wi[..., 2]
    reflect = ci * co > 0
    e = np.where(ci > 0, eta, 1.0 / eta)
    h = normalize(wo + wi * np.where(reflect, 1.0, e)[..., None])
    h = h * np.sign(h[..., 2])[..., None]
    doo, dii = dot(wo, h), dot(wi, h)
    ok = (ci != 0) & (doo * ci > 0) & (dii * co > 0)
    d = D(kind, au, av, h)
    F = fresnel_dielectric(doo, eta)
    g = G1(kind, au, av, wo, h) * G1(kind, au, av, wi, h)
    scale = 1.0 if visible else 1.2 - 0.2 * np.sqrt(np.abs(ci))
    wo_up = wo * np.sign(ci)[..., None]
    with np.errstate(divide="ignore", invalid="ignore"):
        if visible:
            p = pdf_m(kind, au, av, True, wo_up, h)
        else:
            p = pdf_m(kind, au * scale, av * scale, False, wo_up, h)
        den = doo + e * dii
        value = np.where(reflect, F * d * g / (4 * np.abs(ci)),
                         np.abs((1 - F) * d * g * doo * dii / (ci * den ** 2)))
        jac = np.where(reflect, 1 / (4 * dii), e * e * dii / den ** 2)
        pdf = np.abs(p * np.where(reflect, F, 1 - F) * jac)
    return np.where(ok, np.nan_to_num(value), 0.0), np.where(ok, np.nan_to_num(pdf), 0.0)


def lerp_table(table, c):
    x = c * 63.0
    i = np.minimum(x.astype(np.int64), 62)
    return table[i] + (table[i + 1] - table[i]) * (x - i)


def roughplastic(wo, wi, kind, alpha, visible, eta, diffuse, table, internal, spec_weight, nonlinear=False):
    ci, co = wo[..., 2], wi[..., 2]
    ok = (ci > 0) & (co > 0)
    h = normalize(wo + wi)
    d = D(kind, alpha, alpha, h)
    F = fresnel_dielectric(dot(wo, h), eta)
    g = G1(kind, alpha, alpha, wo, h) * G1(kind, alpha, alpha, wi, h)
    ci_c, co_c = np.clip(ci, 0, 1), np.clip(co, 0, 1)
    t_i, t_o = lerp_table(table, ci_c), lerp_table(table, co_c)
    r = np.asarray(diffuse, np.float64)
    diff = r / (1 - (r * internal if nonlinear else internal))
    with np.errstate(divide="ignore", invalid="ignore"):
        value = (F * d * g / (4 * ci))[..., None] + diff * (co / np.pi / eta ** 2 * t_i * t_o)[..., None]
        ps = (1 - t_i) * spec_weight
        pd = t_i * (1 - spec_weight)
        p_spec = ps / (ps + pd)
        spec_pdf = pdf_m(kind, alpha, alpha, visible, wo, h) / (4 * dot(wi, h)) if not visible else \
            d * G1(kind, alpha, alpha, wo, h) / (4 * ci)
        pdf = p_spec * spec_pdf + (1 - p_spec) * co / np.pi
    return np.where(ok[..., None], np.nan_to_num(value), 0.0), np.where(ok, np.nan_to_num(pdf), 0.0)


def plastic_diffuse(wo, wi, eta, diffuse, fdr_int, spec_weight, nonlinear=False):
    """The smooth plastic's diffuse lobe (value, pdf); its specular lobe is a delta."""
    ci, co = wo[..., 2], wi[..., 2]
    ok = (ci > 0) & (co > 0)
    fi, fo = fresnel_dielectric(ci, eta), fresnel_dielectric(co, eta)
    r = np.asarray(diffuse, np.float64)
    diff = r / (1 - (r * fdr_int if nonlinear else fdr_int))
    value = diff * (co / np.pi / eta ** 2 * (1 - fi) * (1 - fo))[..., None]
    ps = fi * spec_weight
    pd = (1 - fi) * (1 - spec_weight)
    pdf = pd / (ps + pd) * co / np.pi
    return np.where(ok[..., None], value, 0.0), np.where(ok, pdf, 0.0)
