"""kernels/phase_families.h: Rayleigh, Draine, Cornette-Shanks, tabulated (Mitsuba's tabphase),
blends (nested), Fournier-Forand and the approximate Mie phase function, on the device.

For each: samples against the density their sampler claims by chi-square (at several parameters,
the extremes among them: |g| near 1 and near 0, alpha 0 and 250, the smallest and largest
diameters, Fournier-Forand's slope mu at both ends), the pdf integrates to one, pdf = value and
weight = 1 where sampling is exact, the mean cosine against its closed form (for Fournier-Forand
the weighted mean, E[weight cos]), the value against float64 references written here from the
papers' formulas. Fournier-Forand is sampled from a table: its samples are tested against the
table's own pdf, and the table's pdf against the value."""
import math

import numpy as np
import pytest

import phasekit
import stats
from conftest import run_kernel
from volcl import phase as ph
from volcl.scene.model import Phase

pytestmark = pytest.mark.every_implementation

N = 1_000_000
F32 = float(np.finfo(np.float32).eps)
f32 = np.float32
INV4PI = 1 / (4 * math.pi)
D_IN = (np.array([0.48, -0.61, -0.63]) / np.linalg.norm([0.48, -0.61, -0.63])).astype(np.float32)
DIN64 = D_IN.astype(np.float64) / np.linalg.norm(D_IN.astype(np.float64))
Z_UP = np.array([0.0, 0.0, 1.0], np.float32)


@pytest.fixture(scope="module")
def prog(test_program):
    return test_program("sampling_tests.cl")


# ---------------------------------------------------------------------------------------------
# float64 references, from the formulas in the literature (not from volcl/phase.py)


def hg_w(g, w):
    """HG at distance w = 1 - |cos| from its peak."""
    ag = abs(g)
    return (1 - ag) * (1 + ag) * INV4PI / ((1 - ag) ** 2 + 2 * ag * w) ** 1.5


# Densities below take the angle as (c, wf, wb): cos, 1 - cos and 1 + cos, each computed where it
# keeps its digits (wf from |d_out - d_in|^2 / 2 near the forward peak, wb near the backward one).


def hg(g, c, wf, wb):
    return hg_w(g, wf if g >= 0 else wb)


def draine(g, alpha, c, wf, wb):
    """Draine (2003), eq. 4: HG (1 + alpha cos^2) / (1 + alpha (1 + 2 g^2) / 3)."""
    return hg(g, c, wf, wb) * (1 + alpha * c * c) / (1 + alpha * (1 + 2 * g * g) / 3)


def draine_mean_cos(g, alpha):
    """Draine (2003), eq. 6."""
    return g * (1 + alpha * (3 + 2 * g * g) / 5) / (1 + alpha * (1 + 2 * g * g) / 3)


def trapezoid(v, x):
    return float(np.sum(0.5 * (v[1:] + v[:-1]) * np.diff(x)))


def rayleigh(c):
    return 3 / (16 * math.pi) * (1 + c * c)


def tabulated(values, c):
    """Mitsuba's tabphase: the linear interpolant of `values` at cosines evenly spaced on [-1, 1],
    over its trapezoid integral, per 2 pi."""
    v = np.asarray(values, np.float64)
    x = np.linspace(-1, 1, len(v))
    return np.interp(c, x, v) / trapezoid(v, x) / (2 * math.pi)


def tabulated_mean_cos(values):
    """int c f(c) dc / int f dc for the linear interpolant, interval by interval, exactly."""
    v = np.asarray(values, np.float64)
    x = np.linspace(-1, 1, len(v))
    a, b, fa, fb = x[:-1], x[1:], v[:-1], v[1:]
    h = b - a
    # integral of c * (fa + (fb - fa)(c - a)/h) over [a, b]
    first = h * (fa * (a + b) / 2 + (fb - fa) * (a / 2 + h / 3))
    return first.sum() / trapezoid(v, x)


def r32(x):
    return float(np.float32(x))


def mie_density(d, c, wf, wb):
    """Jendersie and d'Eon's mixture for diameter d: (1 - w) HG(g_HG) + w Draine(g_D, alpha)."""
    g_hg, g_d, alpha, w = (r32(p) for p in ph.mie_parameters(d))
    return (1 - w) * hg(g_hg, c, wf, wb) + w * draine(g_d, alpha, c, wf, wb)


def mie_mean_cos(d):
    g_hg, g_d, alpha, w = ph.mie_parameters(d)
    return (1 - w) * g_hg + w * draine_mean_cos(g_d, alpha)


def ff_textbook(n, mu, theta):
    """Fournier and Jonasz (1999) as printed (Mobley's Ocean Optics Web Book, eq. 1): fine away
    from delta = 1 and from theta -> 0, where it cancels."""
    nu = (3 - mu) / 2
    d = 4 / (3 * (n - 1) ** 2) * np.sin(theta / 2) ** 2
    d180 = 4 / (3 * (n - 1) ** 2)
    s2 = np.sin(theta / 2) ** 2
    return (1 / (4 * math.pi * (1 - d) ** 2 * d ** nu) * (nu * (1 - d) - (1 - d ** nu) + (d * (1 - d ** nu) - nu * (1 - d)) / s2)
            + (1 - d180 ** nu) / (16 * math.pi * (d180 - 1) * d180 ** nu) * (3 * np.cos(theta) ** 2 - 1))


# ---------------------------------------------------------------------------------------------
# the cases


DRAINE = [(0.0, 0.5), (0.5, 1.0), (-0.5, 37.0), (1e-4, 250.0), (-1e-4, 0.5), (0.7, 0.0), (0.3, 1e4)]
DRAINE_PEAKED = [(0.99, 1.0), (-0.99, 37.0), (0.999, 250.0), (-0.9999, 0.5)]
CS = [-0.9, 0.0, 0.7]
TABLES = {
    "ramp": [1.0, 2.0, 5.0],
    "two": [1.0, 0.0],
    "zeros inside": [0.0, 0.0, 1.0, 5.0, 0.0, 2.0, 0.0],
    "hg 0.6 at 201": list(hg_w(0.6, 1 - np.linspace(-1, 1, 201))),
}
NESTED = Phase("blend", weight=0.3, phases=(
    Phase("hg", 0.8),
    Phase("blend", weight=0.6, phases=(Phase("rayleigh"), Phase("hg", -0.5)))))
MIE_SPREAD = [0.01, 0.3, 1.0, 2.0]     # lobes broad enough for the sphere grid
MIE_PEAKED = [5.0, 20.0, 50.0]
FF = [(1.1, 3.5835), (1.04, 3.2), (1.2, 4.9), (1.01, 3.01), (1.3, 5.0), (1.001, 3.001)]


def exact_cases():
    """(id, phase, density(c, wf, wb), mean cosine) for the exactly sampled phase functions."""
    cases = [("rayleigh", Phase("rayleigh"), lambda c, wf, wb: rayleigh(c), 0.0)]
    # the references take parameters as the float32 values the kernel receives (at g = 0.99 the
    # rounding of g alone moves 1 - |g| by 1e-6)
    for g, alpha in DRAINE + DRAINE_PEAKED:
        cases.append((f"draine g={g} alpha={alpha}", Phase("draine", g, alpha=alpha),
                      lambda *a, g=r32(g), alpha=r32(alpha): draine(g, alpha, *a), draine_mean_cos(g, alpha)))
    for g in CS:
        cases.append((f"cornette-shanks g={g}", Phase("cornette_shanks", g),
                      lambda *a, g=r32(g): draine(g, 1.0, *a), draine_mean_cos(g, 1.0)))
    for name, v in TABLES.items():
        cases.append((f"tabphase {name}", Phase("tabulated", values=np.array(v)),
                      lambda c, wf, wb, v=v: tabulated(v, c), tabulated_mean_cos(v)))
    nested_density = lambda c, wf, wb: (0.7 * hg(r32(0.8), c, wf, wb)                   # noqa: E731
                                        + 0.3 * (0.4 * rayleigh(c) + 0.6 * hg(r32(-0.5), c, wf, wb)))
    cases.append(("nested blend", NESTED, nested_density, 0.7 * 0.8 + 0.3 * 0.6 * -0.5))
    cases.append(("blend weight 1", Phase("blend", weight=1.0, phases=(Phase("hg", 0.9), Phase("rayleigh"))),
                  lambda c, wf, wb: rayleigh(c), 0.0))
    for d in MIE_SPREAD + MIE_PEAKED:
        cases.append((f"mie d={d}", Phase("mie", diameter=d), lambda *a, d=d: mie_density(d, *a), mie_mean_cos(d)))
    return cases


EXACT = exact_cases()
EXACT_IDS = [c[0] for c in EXACT]
PEAKED_IDS = {f"draine g={g} alpha={a}" for g, a in DRAINE_PEAKED} | {f"mie d={d}" for d in MIE_PEAKED}
SPREAD = [c for c in EXACT if c[0] not in PEAKED_IDS]
PEAKED = [c for c in EXACT if c[0] in PEAKED_IDS]


def directions64(d):
    v = d.astype(np.float64)
    return v / np.linalg.norm(v, axis=1)[:, None]


def w_fwd_of(v, din):
    """1 - cos from the directions, keeping its digits for tiny angles."""
    return 0.5 * np.sum((v - din) ** 2, axis=-1)


def geometry(v, din):
    """(cos, 1 - cos, 1 + cos) of unit directions v (..., 3) from din."""
    return np.clip(v @ din, -1, 1), w_fwd_of(v, din), w_fwd_of(v, -din)


# ---------------------------------------------------------------------------------------------
# exactly sampled phase functions


@pytest.mark.parametrize("case", SPREAD, ids=[c[0] for c in SPREAD])
def test_sampling_chi2(cl_env, prog, case):
    name, phase, density, _ = case
    s = phasekit.sample(cl_env, prog, phase, D_IN, seed=41)
    assert np.isfinite(s.d).all() and (s.pdf > 0).all(), f"{name}: non-finite directions or pdf <= 0"
    stats.chi2_directions(s.d, lambda v: density(*geometry(v, DIN64)), what=f"phase_sample {name}")


@pytest.mark.parametrize("case", PEAKED, ids=[c[0] for c in PEAKED])
def test_peaked_sampling_chi2(cl_env, prog, case):
    """Lobes too narrow for a sphere grid: the distance from the peak u = 1 - |cos| on [0, 30 w)
    with w the HG lobe's width (1 - |g|)^2 / 2|g| of the narrowest lobe, plus one tail cell."""
    name, phase, density, _ = case
    s = phasekit.sample(cl_env, prog, phase, D_IN, seed=42)
    v = directions64(s.d)
    parts = ph.lobes(phase)
    g = max((p.g for _, p in parts), key=abs)
    peak = DIN64 if g >= 0 else -DIN64
    u = w_fwd_of(v, peak)
    width = max((1 - abs(g)) ** 2 / (2 * abs(g)), 1e-7)
    U = min(30 * width, 1.0)

    def dens_u(x):      # density of u, from the peak's side
        if g >= 0:
            return 2 * math.pi * density(1 - x, x, 2 - x)
        return 2 * math.pi * density(x - 1, 2 - x, x)
    tail = stats.integral_1d(dens_u, U, 2.0, tol=1e-10)
    stats.chi2_1d(u[u < U], dens_u, 0.0, U, bins=51, extra_observed=[np.sum(u >= U)], extra_probability=[tail],
                  extra_labels=[f"[{U:.3g}, 2]"], what=f"phase_sample {name}: 1 - |cos| from the peak")


@pytest.mark.parametrize("case", EXACT, ids=EXACT_IDS)
def test_exact_sampling_pdf_is_value(cl_env, prog, case):
    """Exact samplers: weight 1, the pdf returned equals phase_eval_pdf's pdf and value of the same
    direction, and that value is the float64 density (to float32 rounding)."""
    name, phase, density, _ = case
    for d_in in (D_IN, Z_UP):
        s = phasekit.sample(cl_env, prog, phase, d_in, seed=43, n=200_000)
        assert np.all(s.weight == 1.0), f"{name}: weights {np.unique(s.weight)[:5]}"
        assert np.all(s.pdf == s.eval_pdf), f"{name}: phase_sample's pdf differs from phase_eval_pdf's"
        assert np.all(s.eval_pdf == s.value), f"{name}: pdf != value"
    # the value against float64 at the directions sampled around +z, taken as their float32
    # components are (normalizing them would move 1 - cos by their 1e-7 deviation from unit length)
    wf, wb = w_fwd_of(s.d.astype(np.float64), Z_UP), w_fwd_of(s.d.astype(np.float64), -Z_UP)
    c = np.where(wf <= 1, 1 - wf, wb - 1)
    ref = density(c, wf, wb)
    # float32 arithmetic: a few eps of each operation, and the device's 1 - cos carries a few eps of
    # itself, which moves the density by |d ln p / d ln w| times that (derivative taken numerically)
    h = 1e-4
    fwd = wf <= wb          # perturb the smaller of the two distances, relative to itself
    wf2 = np.where(fwd, wf * (1 + h), 2 - wb * (1 + h))
    wb2 = np.where(fwd, 2 - wf * (1 + h), wb * (1 + h))
    dlog = np.abs(np.log(density(np.where(fwd, 1 - wf2, wb2 - 1), wf2, wb2) / ref)) / h
    tol = 16 * F32 * (1 + dlog)
    rel = np.abs(s.value / ref - 1)
    i = np.argmax(rel / tol)
    assert np.all(rel <= tol), f"{name}: value {s.value[i]:.8g} vs float64 {ref[i]:.8g} at cos {c[i]:.8f}"


@pytest.mark.parametrize("case", EXACT, ids=EXACT_IDS)
def test_mean_cosine(cl_env, prog, case):
    name, phase, _, mean = case
    s = phasekit.sample(cl_env, prog, phase, D_IN, seed=44)
    c = directions64(s.d) @ DIN64
    stats.assert_mean(c, mean, f"{name}: mean cosine")


@pytest.mark.parametrize("case", EXACT, ids=EXACT_IDS)
def test_value_integrates_to_one(cl_env, prog, case):
    """The device value on a rule over u = 1 - cos (d_in = +z, directions built in float64 from u)
    that integrates the float64 density to 1e-9; the float32 values carry a few eps of error."""
    name, phase, density, _ = case
    # peaked lobes: the rule refines near the peak by itself; backward peaks are at u = 2
    x, w = stats.line_rule(lambda u: 2 * math.pi * density(1 - u, u, 2 - u), 0.0, 2.0, tol=1e-9)
    d_out = np.stack([np.sqrt(np.maximum(x * (2 - x), 0)), np.zeros_like(x), 1 - x], axis=1)
    value, _ = phasekit.evaluate(cl_env, prog, phase, [0, 0, 1], d_out)
    total = float(np.sum(w * 2 * math.pi * value))
    exact_total = float(np.sum(w * 2 * math.pi * density(1 - x, x, 2 - x)))
    stats.assert_integrates_to_one(exact_total, 1e-7, f"{name} (float64 reference)")
    stats.assert_integrates_to_one(total, 1e-7 + 32 * F32, f"{name} (device)")


def test_rayleigh_cardano_root(cl_env, prog):
    """The sampled cosine solves c^3 + 3c + 4 = 8u (the CDF) to float32 rounding, lies in [-1, 1]
    and increases with u, from -1 at u = 0."""
    u = np.linspace(0, 1, 100_001, dtype=np.float32)[:-1]
    (c,) = run_kernel(cl_env, prog, "phase_rayleigh_cos", len(u), [(f32, ())], inputs=[u])
    cd = c.astype(np.float64)
    assert np.all(np.abs(cd) <= 1) and np.all(np.diff(cd) >= 0) and cd[0] == -1.0
    assert np.abs((cd ** 3 + 3 * cd + 4) / 8 - u).max() < 8 * F32


def test_blend_is_the_weighted_sum_of_its_parts(cl_env, prog):
    """A nested blend evaluates to (1 - w) A + w B at every direction, as Mitsuba's blendphase."""
    rng = np.random.default_rng(3)
    d = rng.normal(size=(1000, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    whole, pdf = phasekit.evaluate(cl_env, prog, NESTED, D_IN, d)
    inner = NESTED.phases[1]
    a, _ = phasekit.evaluate(cl_env, prog, NESTED.phases[0], D_IN, d)
    b1, _ = phasekit.evaluate(cl_env, prog, inner.phases[0], D_IN, d)
    b2, _ = phasekit.evaluate(cl_env, prog, inner.phases[1], D_IN, d)
    parts = 0.7 * a.astype(np.float64) + 0.3 * (0.4 * b1.astype(np.float64) + 0.6 * b2.astype(np.float64))
    assert np.allclose(whole, parts, rtol=8 * F32, atol=0) and np.all(pdf == whole)


def test_tabphase_forward_is_cos_plus_one(cl_env, prog):
    """Mitsuba's tabphase lists values from cos = -1 (backward) to +1 (forward)."""
    fwd, back = phasekit.eval_cos(cl_env, prog, Phase("tabulated", values=np.array([1.0, 3.0])), [1.0, -1.0])
    # normalized by the trapezoid integral 4: 3/4 and 1/4 per unit cosine, per 2 pi
    assert fwd == pytest.approx(3 / (8 * math.pi), rel=4 * F32) and back == pytest.approx(1 / (8 * math.pi), rel=4 * F32)


def test_mie_fit_stays_in_every_domain():
    """The fitted parameters over the whole diameter range: |g| < 1, alpha >= 0, 0 <= w <= 1."""
    for d in np.concatenate([np.logspace(-6, math.log10(50), 2000), [0.1, 1.5, 5.0, 50.0]]):
        g_hg, g_d, alpha, w = ph.mie_parameters(float(d))
        assert abs(g_hg) < 1 and abs(g_d) < 1 and alpha >= 0 and 0 <= w <= 1, (d, g_hg, g_d, alpha, w)


# ---------------------------------------------------------------------------------------------
# Fournier-Forand: a closed-form value, a tabulated sampler


def ff_phase(n, mu, tolerance=1e-3):
    return Phase("fournier_forand", n=n, mu=mu, tolerance=tolerance)


def table_of(phase):
    """The packed table as float64 arrays (x, density scaled to the sampler's bins, cdf)."""
    _, lobes, tables = phasekit.phase_buffers(phase)
    k, off = int(lobes[0]["table_size"]), int(lobes[0]["table"])
    x, y, c = (tables[off + i * k: off + (i + 1) * k].astype(np.float64) for i in range(3))
    return x, y, c


def table_density(phase, xs):
    """The device's sampling density of x = s^a: the line times the bin's CDF share over its integral."""
    x, y, c = table_of(phase)
    j = np.clip(np.searchsorted(x, xs, side="right") - 1, 0, len(x) - 2)
    f = np.clip((xs - x[j]) / (x[j + 1] - x[j]), 0, 1)
    line = 0.5 * (y[j] + y[j + 1]) * (x[j + 1] - x[j])
    return (y[j] + f * (y[j + 1] - y[j])) * (c[j + 1] - c[j]) / line


@pytest.mark.parametrize("n,mu", [(1.1, 0.3), (1.05, 1.2), (1.3, 2.5), (2.5, 0.7)])
def test_ff_stable_form_matches_textbook(n, mu):
    """volcl's rearranged closed form (volcl/phase.py) against the printed formula, at angles where
    the printed one is well conditioned (mu here is given as mu - 3)."""
    ff = ph.FournierForand(n, 3 + mu)
    theta = np.linspace(0.05, math.pi, 400)
    delta = ff.q * np.sin(theta / 2) ** 2
    theta = theta[np.abs(delta - 1) > 0.05]
    ours = ff.pdf(np.sin(theta / 2) ** 2)
    assert np.allclose(ours, ff_textbook(n, 3 + mu, theta), rtol=1e-9)


def ff_rule(ff, hi=1.0, tol=1e-11):
    """A rule over x = s^a in [0, hi] integrating the density of x to tol: cells graded towards
    x = 0, where for a -> 1 the density drops like x^((1 - a) / a) from its limit."""
    edges = np.concatenate([[0.0], np.logspace(-30, 0, 241) * hi])
    _, rule = stats.integrate_cells_1d(ff.density_x, edges, lambda p: tol / len(edges), rule=True)
    return rule


@pytest.mark.parametrize("n,mu", FF)
def test_ff_normalization_cdf_and_backscatter(n, mu):
    """The float64 value integrates to one (in x = s^a, where it is bounded), its integral from 0 to
    each s is the closed-form CDF, and 1 - CDF(90 degrees) is the closed-form backscatter fraction."""
    ff = ph.FournierForand(n, mu)
    x, w = ff_rule(ff)
    stats.assert_integrates_to_one(float(np.sum(w * ff.density_x(x))), 1e-9, f"FF n={n} mu={mu}")
    for s in (1e-6, 0.01, 0.3, 0.5, 0.9):
        x, w = ff_rule(ff, s ** ff.a)
        part = float(np.sum(w * ff.density_x(x)))
        assert abs(part - ff.cdf(s)) < 1e-9, (s, part, ff.cdf(s))
    assert abs(ff.backscatter() - (1 - ff.cdf(0.5))) < 1e-12


def test_ff_backscatter_matches_mobleys_table():
    """Mobley's Ocean Optics Web Book lists (n, mu, B) for FF phase functions; the closed form and
    volcl's parametrization by B (n tied to mu as n = 1.01 + 0.1542 (mu - 3)) reproduce them to
    the printed digits."""
    for n, mu, b in [(1.021, 3.0742, 1e-4), (1.040, 3.2010, 1e-3), (1.08, 3.483, 0.01), (1.175, 4.065, 0.1)]:
        assert ph.FournierForand(n, mu).backscatter() == pytest.approx(b, rel=0.04)
        fit = ph.fournier_forand_from_backscatter(b)
        assert fit.backscatter() == pytest.approx(b, rel=1e-9)
        assert fit.mu == pytest.approx(mu, abs=0.015) and fit.n == pytest.approx(n, abs=0.005)
    # Petzold's average particle phase function: B = 0.0183 is n = 1.10, mu = 3.5835
    petzold = ph.fournier_forand_from_backscatter(0.0183)
    assert petzold.n == pytest.approx(1.10, abs=1e-3) and petzold.mu == pytest.approx(3.5835, abs=1e-3)


@pytest.mark.parametrize("n,mu", FF)
def test_ff_device_value(cl_env, prog, n, mu):
    """phase_ff_eval_pdf in float32 against the float64 closed form over s from its floor 1e-13 to 1,
    densely around delta = 1 (where the printed form divides by (1 - delta)^2)."""
    ff = ph.FournierForand(n, mu)
    s = np.concatenate([np.logspace(-13, 0, 3000), np.linspace(0.9, 1.1, 1001) / ff.q])
    s = np.unique(s[s <= 1].astype(np.float32))
    s = s[s > ph.FF_S_MIN]      # at the floor itself the lobe counts value = pdf
    _, lobes, tables = phasekit.phase_buffers(ff_phase(n, mu))
    v, _ = run_kernel(cl_env, prog, "phase_ff_at_s", len(s), [(f32, ()), (f32, ())], inputs=[lobes, tables, s])
    rel = np.abs(v / ff.pdf(s.astype(np.float64)) - 1)
    # float32 logs, exps and powers of numbers up to |ln delta| ~ 70: a few eps of each, times |L|
    tol = 64 * F32 * (1 + np.abs(np.log(ff.q * s.astype(np.float64))))
    i = np.argmax(rel / tol)
    assert np.all(rel <= tol), f"n={n} mu={mu}: relative error {rel[i]:.3g} at s = {s[i]:.4g}"


@pytest.mark.parametrize("n,mu", FF)
def test_ff_table_pdf_follows_the_value(n, mu):
    """The sampling table's pdf is within its tolerance of the value in every bin holding >= 1e-4 of
    the probability (where float32 CDF rounding is far below it), as pack reports it."""
    ff = ph.FournierForand(n, mu)
    t = ph.fournier_forand_table(ff, 1e-3)
    assert t["ratio_error"] <= 1.5e-3, t["ratio_error"]
    x = np.linspace(0, 1, 200_001)[1:-1]
    dens = table_density(ff_phase(n, mu), x)
    c = table_of(ff_phase(n, mu))[2]
    j = np.clip(np.searchsorted(table_of(ff_phase(n, mu))[0], x, side="right") - 1, 0, len(c) - 2)
    big = np.diff(c)[j] >= 1e-4
    with np.errstate(divide="ignore"):      # bins of zero float32 share (never sampled) have pdf 0
        r = ff.density_x(x) / dens
    assert np.abs(r[big] - 1).max() <= 1.5e-3


@pytest.mark.parametrize("n,mu", FF)
def test_ff_sampling_chi2_against_its_table(cl_env, prog, n, mu):
    """Samples of x = s^a against the table's density, which is what the sampler claims, on
    [x_min, 1) with one more cell for [0, x_min) (s < 1e-13, directions d_in itself: the table's
    first bin); d_in = +z, where float32 directions keep s down to 1e-38. And the azimuth: uniform."""
    phase = ff_phase(n, mu)
    s = phasekit.sample(cl_env, prog, phase, [0, 0, 1], seed=45)
    v = directions64(s.d)
    sin2 = 0.5 * w_fwd_of(v, np.array([0.0, 0.0, 1.0]))
    x = np.minimum(np.maximum(sin2, 0.0) ** ph.FournierForand(n, mu).a, np.nextafter(1.0, 0))
    knots, _, cdf = table_of(phase)
    x_min = knots[1]
    stats.chi2_1d(x[x >= x_min], lambda xx: table_density(phase, xx), x_min, 1.0, bins=51,
                  extra_observed=[np.sum(x < x_min)], extra_probability=[cdf[1]], extra_labels=["[0, x_min)"],
                  what=f"FF n={n} mu={mu}: x = s^a against its table")
    tilted = sin2 > 1e-12
    phi = np.mod(np.arctan2(v[tilted, 1], v[tilted, 0]), 2 * math.pi)
    stats.chi2_1d(phi, lambda p: np.full_like(p, 1 / (2 * math.pi)), 0.0, 2 * math.pi, bins=31,
                  what=f"FF n={n} mu={mu}: azimuth")


@pytest.mark.parametrize("n,mu", FF)
def test_ff_sample_pdf_weight_and_mean_cosine(cl_env, prog, n, mu):
    """phase_sample's pdf is phase_eval_pdf's (the table's), weight is value / pdf and within the
    table's tolerance of 1 for all but a few samples, and the weighted mean cosine is FF's."""
    ff = ph.FournierForand(n, mu)
    s = phasekit.sample(cl_env, prog, ff_phase(n, mu), D_IN, seed=46)
    assert np.all(s.pdf == s.eval_pdf)
    assert np.allclose(s.weight, s.value / s.pdf, rtol=2 * F32, atol=0)
    off = np.abs(s.weight - 1) > 2e-3
    # bins of < 1e-4 probability (float32 CDF rounding, the log-singular first bin when mu -> 5)
    assert off.mean() < 1e-3, f"{off.mean():.2e} of the weights differ from 1 by more than 2e-3"
    xq, wq = ff_rule(ff)
    mean = float(np.sum(wq * ff.density_x(xq) * (1 - 2 * xq ** (1 / ff.a))))
    c = directions64(s.d) @ DIN64
    stats.assert_mean(s.weight * c, mean, f"FF n={n} mu={mu}: E[weight cos]")


@pytest.mark.parametrize("n,mu", FF)
def test_ff_pdf_integrates_to_one_on_the_device(cl_env, prog, n, mu):
    """The table pdf and the value, both on the device, over a rule in x = s^a: the pdf is exactly
    linear between knots (a rule with the knots as cell edges integrates it), the value is the
    float64 density to float32 rounding."""
    ff = ph.FournierForand(n, mu)
    phase = ff_phase(n, mu)
    knots = table_of(phase)[0]
    edges = np.unique(np.concatenate([knots, np.logspace(-30, 0, 121)]))
    _, (x, w) = stats.integrate_cells_1d(ff.density_x, edges, lambda p: 1e-11 / len(edges), rule=True)
    s64 = x ** (1 / ff.a)
    # nodes below the lobe's floor (s = 1e-13: directions equal d_in) count at their float64 values:
    # both the value and the table's density there
    keep = s64 >= ph.FF_S_MIN * (1 + 1e-6)
    s = s64[keep].astype(np.float32)
    _, lobes, tables = phasekit.phase_buffers(phase)
    v, p = run_kernel(cl_env, prog, "phase_ff_at_s", len(s), [(f32, ()), (f32, ())], inputs=[lobes, tables, s])
    jac = 4 * math.pi * s.astype(np.float64) ** (1 - ff.a) / ff.a     # dOmega / dx
    for what, f, ref in (("value", v, ff.density_x), ("table pdf", p, lambda xx: table_density(phase, xx))):
        total = float(np.sum(w[keep] * f * jac) + np.sum(w[~keep] * ref(x[~keep])))
        # float32 values (64 eps), and the float32 rounding of s moving x = s^a by a eps
        stats.assert_integrates_to_one(total, 1e-9 + 64 * F32, f"FF n={n} mu={mu} device {what}")
