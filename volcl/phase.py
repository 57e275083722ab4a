"""Phase functions on the host: what each kind means, and the records kernels/phase.h reads.

Convention: cos = dot(d_in, d_out) of the travel directions before and after scattering, so
cos = 1 is forward scattering and g > 0 scatters forward.

A medium's phase function reaches the device in one of three forms: isotropic and
Henyey-Greenstein live in the Medium record itself (the path every HG-only scene keeps), everything
else is a mixture of lobes (PhaseLobe records, compiled only with the PHASE_FAMILIES feature).
A blend flattens into a mixture, blend(w, A, B) = (1 - w) A + w B nested to any depth: that is
the distribution Mitsuba 3's blendphase samples (it picks a child with probability 1 - w or w and
returns the blended value and pdf), so a flat mixture means exactly what the nested blends mean.
Lobes that need a table (tabulated, Fournier-Forand) point into one float buffer of
piecewise-linear densities on explicit knots: knots, densities, CDF (three runs of `size` floats).

How each kind is sampled (kernels/phase.h):
  - isotropic, Henyey-Greenstein, Rayleigh: exact inversion of the CDF in closed form;
  - Draine and Cornette-Shanks (Draine with alpha = 1): rejection from the exact HG sampler with
    acceptance (1 + alpha cos^2) / (1 + alpha), exact in distribution, at most 3 proposals on
    average for any g and alpha >= 0;
  - tabulated (Mitsuba's tabphase): exact inversion of the piecewise-linear density;
  - Fournier-Forand: its CDF has a closed form but its inverse has none, so it is sampled from a
    tabulated inverse CDF (fournier_forand_table) whose own pdf the integrator uses, with the
    closed-form value over that pdf in the path throughput;
  - approximate Mie (Jendersie and d'Eon 2023): a mixture of an HG and a Draine lobe.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import layout
from .scene.model import Phase

INV_4PI = 1.0 / (4.0 * math.pi)

# Validity ranges, checked by the scene parser (volcl/scene/phases.py) and named in its errors.
DRAINE_ALPHA_MAX = 1e6
MIE_DIAMETER_RANGE = (0.0, 50.0)      # micrometres, exclusive below: the range of the fit
FF_MU_RANGE = (3.001, 5.0)            # Junge slope; below 3.001 (a < 5e-4) the lobe is a float32 delta
FF_N_RANGE = (1.0, 3.0)               # relative refractive index, exclusive below
FF_TABLE_MAX_KNOTS = 8193


# ---------------------------------------------------------------------------------------------
# Draine (2003), Cornette-Shanks, and the approximate Mie fit


def draine_normalization(g: float, alpha: float) -> float:
    """1 / (1 + alpha (1 + 2 g^2) / 3): HG(cos) (1 + alpha cos^2) times this integrates to one
    (E_HG[cos^2] = (1 + 2 g^2) / 3)."""
    return 1.0 / (1.0 + alpha * (1.0 + 2.0 * g * g) / 3.0)


def mie_parameters(d: float) -> tuple[float, float, float, float]:
    """(g_HG, g_Draine, alpha, w_Draine) of Jendersie and d'Eon's fit (2023, with its supplement)
    of the Mie phase function of water droplets of diameter d micrometres: (1 - w) HG(g_HG) +
    w Draine(g_Draine, alpha)."""
    if d <= 0.1:
        return 13.8 * d * d, 1.1456 * d * math.sin(9.29044 * d), 250.0, 0.252977 - 312.983 * d ** 4.3
    ld = math.log(d)
    if d < 1.5:
        a = (ld - 0.238604) * (ld + 1.00667)
        b = 0.507522 - 0.15677 * ld
        c = 1.19692 * math.cos(a / b) + 1.37932 * ld + 0.0625835
        return (0.862 - 0.143 * ld * ld, 0.379685 * math.cos(c) + 0.344213, 250.0,
                0.146209 * math.cos(3.38707 * ld + 2.11193) + 0.316072 + 0.0778917 * ld)
    if d < 5.0:
        lld = math.log(ld)
        return (0.0604931 * lld + 0.940256, 0.500411 - 0.081287 / (-2.0 * ld + math.tan(ld) + 1.27551),
                7.30354 * ld + 6.31675, 0.026914 * (ld - math.cos(5.68947 * (lld - 0.0292149))) + 0.3764)
    return (math.exp(-0.0990567 / (d - 1.67154)), math.exp(-2.20679 / (d + 3.91029) - 0.428934),
            math.exp(3.62489 - 8.29288 / (d + 5.52825)), math.exp(-0.599085 / (d - 0.641583) - 0.665888))


# ---------------------------------------------------------------------------------------------
# Fournier-Forand (Fournier and Jonasz 1999)


def _expm1_ratio(a: float, L):
    """expm1(a L) / expm1(L), which tends to a as L -> 0."""
    L = np.asarray(L, np.float64)
    small = np.abs(L) < 1e-12
    Ls = np.where(small, 1.0, L)
    return np.where(small, a, np.expm1(a * Ls) / np.expm1(Ls))


@dataclass(frozen=True)
class FournierForand:
    """The Fournier-Forand phase function of particles with relative refractive index n and a
    Junge size distribution of slope mu (3 < mu <= 5), in float64, as functions of
    s = sin^2(theta / 2) = (1 - cos) / 2.

    With a = (mu - 3) / 2 (= -nu of the literature), q = 4 / (3 (n - 1)^2) (delta at 180 degrees),
    delta = q s and L = ln delta, the textbook form rearranges to
        4 pi p = (q - 1) D(L) / expm1(L)^2 + a exp((a - 1) L) + (c3 / 4) (3 cos^2 - 1),
        D(L) = (1 - a) expm1(a L) + a expm1((a - 1) L) = a (1 - a) sum_{m >= 2} (a^(m-1) - (a-1)^(m-1)) L^m / m!,
        c3 = (q^a - 1) / (q - 1),
    whose terms are all positive (D >= 0 by convexity) and which has no 0/0 at delta = 1, where the
    textbook form divides a second-order zero by (1 - delta)^2. Near delta = 1 (|L| < 1/2) the
    series is used. The CDF, P(scattering angle <= theta), is
        F = 1 - (1 - s) expm1(a L) / expm1(L) + (c3 / 8) cos sin^2.
    The lobe is singular at the forward direction (p ~ s^(a - 1)) but F ~ (q s)^a is not: in
    x = s^a the density of x is bounded on [0, 1], which is the coordinate the sampling table
    uses."""
    n: float
    mu: float

    @property
    def a(self) -> float:
        return 0.5 * (self.mu - 3.0)

    @property
    def q(self) -> float:
        return 4.0 / (3.0 * (self.n - 1.0) ** 2)

    @property
    def c3(self) -> float:
        return float(_expm1_ratio(self.a, math.log(self.q)))

    def pdf(self, s) -> np.ndarray:
        """Value per unit solid angle at s = sin^2(theta / 2) in (0, 1]."""
        a, q = self.a, self.q
        s = np.asarray(s, np.float64)
        L = np.log(q * s)
        series = np.abs(L) < 0.5
        # the series: D / expm1(L)^2 = a (1 - a) S(L) / (expm1(L) / L)^2
        Ls = np.where(series, L, 0.0)
        S = np.zeros_like(Ls)
        pa, pb, fact, powL = 1.0, 1.0, 1.0, np.ones_like(Ls)
        for m in range(2, 16):
            pa, pb, fact = pa * a, pb * (a - 1.0), fact * m
            S = S + (pa - pb) / fact * powL
            powL = powL * Ls
        e1 = np.where(series & (Ls != 0), np.expm1(Ls) / np.where(Ls != 0, Ls, 1.0), 1.0)
        ratio_series = a * (1.0 - a) * S / (e1 * e1)
        Ld = np.where(series, 1.0, L)
        ratio_direct = ((1.0 - a) * np.expm1(a * Ld) + a * np.expm1((a - 1.0) * Ld)) / np.expm1(Ld) ** 2
        ratio = np.where(series, ratio_series, ratio_direct)
        T = (q - 1.0) * ratio + a * np.exp((a - 1.0) * L)
        c = 1.0 - 2.0 * s
        return T * INV_4PI + self.c3 * (3.0 * c * c - 1.0) / (16.0 * math.pi)

    def cdf(self, s) -> np.ndarray:
        """P(scattering angle <= theta) at s = sin^2(theta / 2) in [0, 1]."""
        s = np.asarray(s, np.float64)
        pos = s > 0
        L = np.log(self.q * np.where(pos, s, 1.0))
        r = np.where(pos, _expm1_ratio(self.a, L), 1.0)
        c = 1.0 - 2.0 * s
        return 1.0 - (1.0 - s) * r + 0.125 * self.c3 * c * 4.0 * s * (1.0 - s)

    def backscatter(self) -> float:
        """The backscatter fraction B = P(angle > 90 degrees) = expm1(a ln d90) / (2 expm1(ln d90))
        with d90 = q / 2 (the literature's closed form)."""
        return 0.5 * float(_expm1_ratio(self.a, math.log(self.q / 2.0)))

    def density_x(self, x) -> np.ndarray:
        """Density of x = s^a in [0, 1]: 4 pi p(s) s / (a x) = 4 pi p(s) s^(1 - a) / a; at x = 0 its
        limit, q^a for a < 1 (1 + c3 / 2 for a = 1, where the lobe is no longer singular)."""
        a = self.a
        x = np.asarray(x, np.float64)
        pos = x > 0
        s = np.where(pos, x, 1.0) ** (1.0 / a)
        # p(s) s^(1 - a) / a, with s^(1 - a) kept apart from p so that neither overflows
        d = 4.0 * math.pi * self.pdf(np.maximum(s, 1e-300)) * np.maximum(s, 1e-300) ** (1.0 - a) / a
        at0 = self.q ** a if a < 1.0 else 1.0 + 0.5 * self.c3
        return np.where(pos, d, at0)


def fournier_forand_from_backscatter(backscatter: float, n: float | None = None) -> FournierForand:
    """The Fournier-Forand phase function with backscatter fraction B: for a given n, the mu with
    that B (B rises monotonically from 0 to 1/2 as mu goes from 3 to 5); without n, n and mu tied by
    n = 1.01 + 0.1542 (mu - 3), the relation Mobley et al. (2002) fitted to oceanic particles (it
    reproduces the (n, mu, B) table of Mobley's Ocean Optics Web Book to its printed digits)."""
    def make(mu):
        return FournierForand(n if n is not None else 1.01 + 0.1542 * (mu - 3.0), mu)
    lo, hi = FF_MU_RANGE
    if not make(lo).backscatter() <= backscatter <= make(hi).backscatter():
        raise ValueError(f"backscatter {backscatter} outside [{make(lo).backscatter():.4g}, "
                         f"{make(hi).backscatter():.4g}]")
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if make(mid).backscatter() < backscatter:
            lo = mid
        else:
            hi = mid
    return make(0.5 * (lo + hi))


def backscatter_range(n: float | None = None) -> tuple[float, float]:
    """The backscatter fractions FF_MU_RANGE allows (for a given n, or on Mobley's n(mu))."""
    def b(mu):
        return FournierForand(n if n is not None else 1.01 + 0.1542 * (mu - 3.0), mu).backscatter()
    return b(FF_MU_RANGE[0]), b(FF_MU_RANGE[1])


def _equal_probability_x(ff: FournierForand, count: int) -> np.ndarray:
    """x = s^a at the CDF levels j / count, j = 1 .. count - 1 (bisection in float64)."""
    target = np.arange(1, count) / count
    lo, hi = np.zeros_like(target), np.ones_like(target)
    for _ in range(64):
        mid = 0.5 * (lo + hi)
        below = ff.cdf(mid ** (1.0 / ff.a)) < target
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    return 0.5 * (lo + hi)


# A bin whose probability is below this is not split further: near x = 0 the density of x is
# continuous but drops like x^((1 - a) / a) from its limit, which for a -> 1 no line follows; the
# ratio value / pdf stays bounded there by the density's range over the bin.
_FF_MIN_BIN_PROBABILITY = 1e-9
# kernels/phase_families.h PHASE_FF_S_MIN: the lobe is evaluated at s >= this (as float32)
FF_S_MIN = float(np.float32(1e-13))


def fournier_forand_table(ff: FournierForand, tolerance: float) -> dict:
    """The sampling table of `ff`: a piecewise-linear density of x = s^a on knots refined until the
    line through each bin's end values is within `tolerance` (relative) of the true density at the
    bin's quarter points (bins of probability below 1e-9 excepted), as float32 arrays the device
    reads ({'x', 'density', 'cdf'}), plus the measured bound on |value / pdf - 1| ('ratio_error')
    over 15 points in every bin that holds at least 1e-4 of the probability.

    The densities are the true ones at the knots; the CDF gives each bin its probability, and the
    device's pdf is the line times the bin's CDF share over the line's integral, which is what the
    sampler draws with (24-bit uniforms land on the float32 CDF's own grid above 1/2; in bins below
    1e-4 the share's float32 rounding moves value / pdf by up to 6e-8 / share).
    The first bin is [0, x_min], x_min = FF_S_MIN^a: its directions are d_in itself in float32 and
    the device evaluates them at s = FF_S_MIN, so it holds exactly the value's own probability
    there, the CDF at FF_S_MIN, and its line is set to integrate to that: value / pdf = 1 at x_min.
    (Near mu = 3 that bin is most of the lobe: 87% of it for mu = 3.01.)"""
    a = ff.a
    x_min = FF_S_MIN ** a
    # start from the ends alone, so that the tolerance alone decides the table (tests render with a
    # deliberately coarse one), and split bins where the line misses
    x = np.array([x_min, 1.0])
    if ff.q > 1.0:     # delta = 1 inside the lobe: the closed form changes branch there
        x = np.union1d(x, [(1.0 / ff.q) ** a])
    x = x[x >= x_min]
    for _ in range(64):
        y = ff.density_x(x)
        t = np.array([0.25, 0.5, 0.75])
        xt = x[:-1, None] + t[None] * np.diff(x)[:, None]
        lin = y[:-1, None] * (1 - t) + y[1:, None] * t
        err = np.abs(lin / ff.density_x(xt) - 1.0).max(1)
        prob = 0.5 * (y[:-1] + y[1:]) * np.diff(x)
        split = (err > tolerance) & (prob > _FF_MIN_BIN_PROBABILITY)
        if not split.any():
            break
        x = np.union1d(x, 0.5 * (x[:-1] + x[1:])[split])
        if len(x) > FF_TABLE_MAX_KNOTS:
            raise ValueError(f"Fournier-Forand n={ff.n}, mu={ff.mu}: its sampling table needs more than "
                             f"{FF_TABLE_MAX_KNOTS} knots for tolerance {tolerance}")
    # what the device reads: float32 knots and densities, the CDF from exactly those
    x32 = np.concatenate([[0.0], np.unique(x.astype(np.float32))]).astype(np.float32)
    xd = x32.astype(np.float64)
    y = ff.density_x(xd)
    floor_mass = float(ff.cdf(FF_S_MIN))
    y[0] = max(2.0 * floor_mass / xd[1] - y[1], 0.0)
    y32 = y.astype(np.float32)
    yd = y32.astype(np.float64)
    mass = 0.5 * (yd[:-1] + yd[1:]) * np.diff(xd)
    mass[1:] *= (1.0 - floor_mass) / mass[1:].sum()
    mass[0] = floor_mass
    cdf32 = np.concatenate([[0.0], np.cumsum(mass)]).astype(np.float32)
    cdf32[-1] = 1.0
    # value / pdf - 1 over 15 interior points of each bin, with the pdf as the device computes it
    t = np.linspace(0.0, 1.0, 17)[1:-1]
    xt = xd[:-1, None] + t[None] * np.diff(xd)[:, None]
    lin = yd[:-1, None] * (1 - t) + yd[1:, None] * t
    share = np.diff(cdf32.astype(np.float64))
    with np.errstate(divide="ignore", invalid="ignore"):     # bins of zero float32 share: never sampled
        err = np.abs(ff.density_x(xt) / (lin * (share / (0.5 * (yd[:-1] + yd[1:]) * np.diff(xd)))[:, None])
                     - 1.0).max(1)
    big = share >= 1e-4
    big[0] = False      # evaluated at x_min only, where value / pdf = 1
    return {"x": x32, "density": y32, "cdf": cdf32, "ratio_error": float(err[big].max())}


# ---------------------------------------------------------------------------------------------
# tabulated (Mitsuba 3's tabphase)


def tabulated_table(values) -> dict:
    """Mitsuba 3.9's tabphase: `values` at cosines evenly spaced over [-1, 1] (1 forward), a linear
    interpolant normalized by its trapezoid integral (ContinuousDistribution); value = pdf =
    interpolant / (2 pi)."""
    v = np.asarray(values, np.float64)
    x = np.linspace(-1.0, 1.0, len(v))
    total = np.sum(0.5 * (v[:-1] + v[1:]) * np.diff(x))
    y32 = (v / total).astype(np.float32)
    yd = y32.astype(np.float64)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (yd[:-1] + yd[1:]) * np.diff(x))])
    cdf32 = (cdf / cdf[-1]).astype(np.float32)
    cdf32[-1] = 1.0
    return {"x": x.astype(np.float32), "density": y32, "cdf": cdf32}


def tabulated_pdf(values, cos) -> np.ndarray:
    """Tabphase's value per unit solid angle at `cos`, in float64."""
    v = np.asarray(values, np.float64)
    x = np.linspace(-1.0, 1.0, len(v))
    total = np.sum(0.5 * (v[:-1] + v[1:]) * np.diff(x))
    return np.interp(cos, x, v) / total / (2.0 * math.pi)


# ---------------------------------------------------------------------------------------------
# flattening and packing


def lobes(phase: Phase, weight: float = 1.0) -> list[tuple[float, Phase]]:
    """The phase function as a mixture of leaf phases [(weight, leaf)], blends flattened; leaves of
    weight zero are dropped (at least one leaf always remains)."""
    if phase.kind == "blend":
        first, second = phase.phases
        out = lobes(first, weight * (1.0 - phase.weight)) + lobes(second, weight * phase.weight)
        kept = [lw for lw in out if lw[0] > 0.0]
        return kept or out[:1]
    if phase.kind == "mie":
        g_hg, g_d, alpha, w_d = mie_parameters(phase.diameter)
        parts = [(weight * (1.0 - w_d), Phase("hg", g_hg)), (weight * w_d, Phase("draine", g_d, alpha=alpha))]
        return [p for p in parts if p[0] > 0.0] or parts[:1]
    if phase.kind == "cornette_shanks":
        return [(weight, Phase("draine", phase.g, alpha=1.0))]
    if phase.kind == "hg" and phase.g == 0.0:
        return [(weight, Phase("isotropic"))]
    return [(weight, phase)]


def device_kind(phase: Phase) -> str:
    """How the kernels see the phase function: 'isotropic', 'hg' (the Medium record's own fields),
    or 'lobes' (a mixture; the PHASE_FAMILIES feature)."""
    parts = lobes(phase)
    if len(parts) == 1 and parts[0][1].kind in ("isotropic", "hg"):
        return parts[0][1].kind
    return "lobes"


def _pdf_leaf(leaf: Phase, cos: np.ndarray) -> np.ndarray:
    c = np.asarray(cos, np.float64)
    if leaf.kind == "isotropic":
        return np.full_like(c, INV_4PI)
    if leaf.kind in ("hg", "draine"):
        g = leaf.g
        hg = (1 - g * g) * INV_4PI / (1 + g * g - 2 * g * c) ** 1.5
        return hg if leaf.kind == "hg" else hg * (1 + leaf.alpha * c * c) * draine_normalization(g, leaf.alpha)
    if leaf.kind == "rayleigh":
        return 3.0 / (16.0 * math.pi) * (1 + c * c)
    if leaf.kind == "tabulated":
        return tabulated_pdf(leaf.values, c)
    if leaf.kind == "fournier_forand":
        return FournierForand(leaf.n, leaf.mu).pdf(np.maximum((1 - c) / 2, 1e-300))
    raise ValueError(f"unknown phase kind {leaf.kind!r}")


def pdf(phase: Phase, cos) -> np.ndarray:
    """The phase function's value per unit solid angle at cos = dot(d_in, d_out), in float64."""
    return sum(w * _pdf_leaf(leaf, cos) for w, leaf in lobes(phase))


def _mean_cosine_leaf(leaf: Phase) -> float:
    if leaf.kind in ("isotropic", "rayleigh"):
        return 0.0
    if leaf.kind == "hg":
        return leaf.g
    if leaf.kind == "draine":      # Draine (2003), eq. 6
        g, a = leaf.g, leaf.alpha
        return g * (1 + a * (3 + 2 * g * g) / 5) * draine_normalization(g, a)
    if leaf.kind == "tabulated":
        c = np.linspace(-1.0, 1.0, 200_001)
        f = 2 * math.pi * tabulated_pdf(leaf.values, c)
        return float(np.sum(0.5 * ((f * c)[1:] + (f * c)[:-1]) * np.diff(c)))
    # Fournier-Forand: over x = s^a, where the density is bounded (cells graded towards x = 0)
    ff = FournierForand(leaf.n, leaf.mu)
    edges = np.concatenate([[0.0], np.logspace(-30, 0, 301)])
    nodes, weights = np.polynomial.legendre.leggauss(16)
    half = 0.5 * np.diff(edges)
    x = (0.5 * (edges[1:] + edges[:-1]))[:, None] + half[:, None] * nodes[None]
    return float(np.sum(half[:, None] * weights[None] * ff.density_x(x) * (1 - 2 * x ** (1 / ff.a))))


def mean_cosine(phase: Phase) -> float:
    """E[cos] of the phase function (its asymmetry), closed forms where they exist."""
    return sum(w * _mean_cosine_leaf(leaf) for w, leaf in lobes(phase))


def check(phase: Phase) -> None:
    """ValueError naming the valid range for a phase function outside its domain (the scene parser
    reports the same with the file and line; this guards phase functions built in Python)."""
    def bad(what):
        raise ValueError(f"{phase.kind} phase function: {what}")
    if phase.kind == "blend":
        if not 0.0 <= phase.weight <= 1.0 or len(phase.phases) != 2:
            bad(f"weight {phase.weight} outside [0, 1], or {len(phase.phases)} nested phases instead of 2")
        for p in phase.phases:
            check(p)
    elif phase.kind in ("hg", "draine", "cornette_shanks") and not -1.0 < phase.g < 1.0:
        bad(f"g = {phase.g} outside -1 < g < 1")
    elif phase.kind == "draine" and not 0.0 <= phase.alpha <= DRAINE_ALPHA_MAX:
        bad(f"alpha = {phase.alpha} outside 0 <= alpha <= {DRAINE_ALPHA_MAX:g}")
    elif phase.kind == "tabulated":
        v = np.asarray(phase.values, np.float64)
        if v.ndim != 1 or len(v) < 2 or not np.all(np.isfinite(v)) or np.any(v < 0) or not np.any(v > 0):
            bad("values must be at least 2 finite numbers >= 0, not all 0")
    elif phase.kind == "fournier_forand" and not (FF_N_RANGE[0] < phase.n <= FF_N_RANGE[1]
                                                  and FF_MU_RANGE[0] <= phase.mu <= FF_MU_RANGE[1]):
        bad(f"n = {phase.n}, mu = {phase.mu} outside {FF_N_RANGE[0]:g} < n <= {FF_N_RANGE[1]:g}, "
            f"{FF_MU_RANGE[0]:g} <= mu <= {FF_MU_RANGE[1]:g}")
    elif phase.kind == "mie" and not MIE_DIAMETER_RANGE[0] < phase.diameter <= MIE_DIAMETER_RANGE[1]:
        bad(f"diameter {phase.diameter} outside {MIE_DIAMETER_RANGE[0]:g} < d <= {MIE_DIAMETER_RANGE[1]:g} micrometres")
    elif phase.kind not in ("isotropic", "hg", "rayleigh", "draine", "cornette_shanks", "tabulated",
                            "fournier_forand", "mie", "blend"):
        bad("unknown kind")


class PhasePacker:
    """Collects the lobes and tables of every medium's phase function for the kernels."""

    def __init__(self):
        self.records: list = []
        self.tables: list = []
        self.table_floats = 0
        self.ratio_errors: list = []    # Fournier-Forand tables: measured |true / table - 1|
        self._done: dict = {}

    def _table(self, t: dict) -> tuple[int, int]:
        offset = self.table_floats
        data = np.concatenate([t["x"], t["density"], t["cdf"]]).astype(np.float32)
        self.tables.append(data)
        self.table_floats += data.size
        return offset, len(t["x"])

    def _lobe(self, weight: float, leaf: Phase) -> np.ndarray:
        r = np.zeros((), layout.PHASE_LOBE)
        r["type"] = layout.LOBE_TYPES[leaf.kind]
        r["weight"] = weight
        r["table"], r["table_size"] = -1, 0
        if leaf.kind == "hg":
            r["p"][0] = leaf.g
        elif leaf.kind == "draine":
            r["p"][:3] = leaf.g, leaf.alpha, draine_normalization(leaf.g, leaf.alpha)
        elif leaf.kind == "tabulated":
            r["table"], r["table_size"] = self._table(tabulated_table(leaf.values))
        elif leaf.kind == "fournier_forand":
            ff = FournierForand(leaf.n, leaf.mu)
            t = fournier_forand_table(ff, leaf.tolerance)
            self.ratio_errors.append(t["ratio_error"])
            r["table"], r["table_size"] = self._table(t)
            r["p"] = ff.a, ff.q, ff.c3 / (16.0 * math.pi), ff.q ** -ff.a
        return r

    def add(self, phase: Phase) -> tuple[int, float, int, int]:
        """(Medium.phase, Medium.g, Medium.phase_lobe, Medium.phase_lobe_count) for `phase`."""
        check(phase)
        kind = device_kind(phase)
        if kind != "lobes":
            return layout.PHASE_TYPES[kind], (lobes(phase)[0][1].g if kind == "hg" else 0.0), 0, 0
        key = id(phase)
        if key not in self._done:
            parts = lobes(phase)
            total = sum(w for w, _ in parts)
            first = len(self.records)
            self.records += [self._lobe(w / total, leaf) for w, leaf in parts]
            self._done[key] = (first, len(parts))
        first, count = self._done[key]
        return layout.PHASE_TYPES["lobes"], 0.0, first, count

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        lobes_arr = np.zeros(max(len(self.records), 1), layout.PHASE_LOBE)
        for i, r in enumerate(self.records):
            lobes_arr[i] = r
        data = np.concatenate(self.tables) if self.tables else np.zeros(1, np.float32)
        return lobes_arr, data.astype(np.float32)
