"""Statistical checks for sampling routines: chi-square goodness of fit against a pdf, "the pdf
integrates to one", z-tests of means and binomial tests of probabilities.

The chi-square test follows the habits of Mitsuba 3's harness, written anew for numpy:
  - samples are histogrammed on a grid of odd resolution (no cell edge on a symmetry plane, where
    float rounding decides the side); directions use (cos theta, phi) cells, which have equal area;
  - expected counts are n times the pdf integrated over each cell, in float64, by adaptive
    Gauss-Legendre quadrature on sub-cells (refined until the error is far below the cell's own
    Poisson noise, so quadrature never decides a test; peaked lobes and support edges just refine);
  - cells expected to hold fewer than 5 samples are pooled into one cell;
  - a sample in a cell whose expected count is zero fails the test outright;
  - the p-value (scipy.stats.chi2.sf) must exceed the per-test significance: ALPHA over the whole
    suite, Sidak-corrected for the number of hypothesis tests the suite makes (SUITE_TESTS).
Every failure message names the statistic, the p-value, the threshold and the worst cells.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.polynomial.legendre import leggauss
from scipy.stats import binomtest, chi2, norm

# Family-wise chance that a correct implementation fails any statistical test of the sampling suite
# (tests/test_rng.py, test_sampling.py, test_phase.py, test_bsdf.py, test_bsdf_rough.py,
# test_equiangular.py, test_envmap.py, test_phase_families.py) on a given seed.
ALPHA = 0.01
# Upper bound on the number of hypothesis tests those files make (each chi-square test, each column
# of a z-test of means, each binomial test counts once). Every check below counts itself and fails
# when a run makes more tests than this, so the correction cannot silently fall behind the suite.
# With 600: per-test significance 1.7e-5, |z| limit 4.30 on one implementation.
# The files run once per OpenCL implementation tested (tests/conftest.py), and the family-wise
# ALPHA covers them all: conftest sets SUITE_TESTS to the bound times the implementations in the run.
SUITE_TESTS_PER_IMPLEMENTATION = 600
SUITE_TESTS = SUITE_TESTS_PER_IMPLEMENTATION
_tests_made = 0


def _count(k: int = 1):
    global _tests_made
    _tests_made += k
    assert _tests_made <= SUITE_TESTS, (f"the suite now makes more than SUITE_TESTS = {SUITE_TESTS} hypothesis "
                                        "tests: raise SUITE_TESTS_PER_IMPLEMENTATION in tests/stats.py")


def tests_made() -> int:
    return _tests_made


MIN_EXPECTED = 5.0
# Quadrature budget per cell, as a fraction of the cell's Poisson standard deviation sqrt(E): the
# chi-square statistic moves by at most QUAD_FRACTION^2 per cell (0.0025) through quadrature error.
QUAD_FRACTION = 0.05


def test_alpha(tests: int | None = None, alpha: float = ALPHA) -> float:
    """Sidak-corrected significance of one test so that `tests` tests (default SUITE_TESTS) fail
    together with chance alpha."""
    return 1.0 - (1.0 - alpha) ** (1.0 / (SUITE_TESTS if tests is None else tests))


test_alpha.__test__ = False     # a helper, not a pytest test


def z_limit(tests: int | None = None, alpha: float = ALPHA) -> float:
    """Two-sided bound on |z| at the per-test significance."""
    return float(norm.isf(test_alpha(tests, alpha) / 2))


# ----------------------------------------------------------------------------------------------
# adaptive Gauss-Legendre quadrature over the cells of a grid


_ORDER = 5
_GX, _GW = leggauss(_ORDER)


def _gauss_1d(f, a, b):
    half = 0.5 * (b - a)
    x = 0.5 * (a + b)[:, None] + half[:, None] * _GX[None]
    return half * (np.asarray(f(x), np.float64) @ _GW)


def _gauss_2d(f, x0, x1, y0, y1):
    hx, hy = 0.5 * (x1 - x0), 0.5 * (y1 - y0)
    x = (0.5 * (x0 + x1))[:, None, None] + hx[:, None, None] * _GX[None, :, None]
    y = (0.5 * (y0 + y1))[:, None, None] + hy[:, None, None] * _GX[None, None, :]
    x, y = np.broadcast_arrays(x, y)
    v = np.asarray(f(x, y), np.float64)
    return hx * hy * np.einsum("mij,i,j->m", v, _GW, _GW)


# relative accuracy below which a sub-cell counts as converged whatever its budget: float64 rounding
# of the Gauss sums would otherwise keep a tall narrow peak refining forever
REL_FLOOR = 1e-12
MAX_ACTIVE = 100_000    # sub-cells refined at once; more means the budget is unreachable (memory, time)


class QuadratureError(AssertionError):
    pass


def _give_up(active: int, depth: int, err: float):
    raise QuadratureError(f"adaptive quadrature did not converge: {active} sub-cells still above their budget "
                          f"at depth {depth} (largest error {err:.3g}); widen the budget or align the grid with "
                          "the pdf's discontinuities")


def integrate_cells_1d(f, edges, cell_tol, max_depth: int = 60, rule: bool = False, min_depth: int = 6):
    """Integral of f over each interval [edges[i], edges[i+1]]. cell_tol(estimates) gives each
    cell's absolute error budget; a sub-interval holding a fraction w of its cell gets
    budget * sqrt(w), which lets refinement converge around discontinuities and kinks. Raises
    QuadratureError rather than return an integral that missed its budget. Every cell is halved
    min_depth times before any estimate is trusted (cheap in 1D), so that features a fraction of a
    cell wide (jumps of a tabulated density) cannot hide between the Gauss nodes. rule=True also
    returns the rule it converged to, (nodes, weights), as integrate_cells_2d does."""
    edges = np.asarray(edges, np.float64)
    ncell = len(edges) - 1
    a, b, owner = edges[:-1].copy(), edges[1:].copy(), np.arange(ncell)
    coarse = _gauss_1d(f, a, b)
    budget = np.asarray(cell_tol(coarse), np.float64) * np.ones(ncell)
    width0 = b - a
    out = np.zeros(ncell)
    final = []
    for depth in range(max_depth):
        m = 0.5 * (a + b)
        ca, cb = np.concatenate([a, m]), np.concatenate([m, b])
        child = _gauss_1d(f, ca, cb)
        fine = child[:len(a)] + child[len(a):]
        err = np.abs(fine - coarse)
        tol = budget[owner] * np.sqrt((b - a) / width0[owner])
        done = (err <= tol + REL_FLOOR * np.abs(fine)) & (depth >= min_depth)
        if not done.all() and (depth == max_depth - 1 or 2 * np.count_nonzero(~done) > MAX_ACTIVE):
            _give_up(2 * np.count_nonzero(~done), depth, float(err[~done].max()))
        np.add.at(out, owner[done], fine[done])
        if rule:
            d2 = np.concatenate([done, done])
            final.append((ca[d2], cb[d2]))
        keep = np.concatenate([~done, ~done])
        a, b, owner, coarse = ca[keep], cb[keep], np.concatenate([owner, owner])[keep], child[keep]
        if len(a) == 0:
            break
    if rule:
        a, b = (np.concatenate(r) for r in zip(*final))
        half = 0.5 * (b - a)
        x = (0.5 * (a + b))[:, None] + half[:, None] * _GX[None]
        return out, (x.ravel(), (half[:, None] * _GW[None]).ravel())
    return out


def _gauss_nodes_2d(x0, x1, y0, y1):
    """Nodes and weights of the tensor Gauss rule on each rectangle, flattened."""
    hx, hy = 0.5 * (x1 - x0), 0.5 * (y1 - y0)
    x = (0.5 * (x0 + x1))[:, None, None] + hx[:, None, None] * _GX[None, :, None]
    y = (0.5 * (y0 + y1))[:, None, None] + hy[:, None, None] * _GX[None, None, :]
    w = (hx * hy)[:, None, None] * (_GW[:, None] * _GW[None, :])[None]
    x, y, w = np.broadcast_arrays(x, y, w)
    return x.ravel(), y.ravel(), w.ravel()


def integrate_cells_2d(f, x_edges, y_edges, cell_tol, max_depth: int = 60, rule: bool = False, min_depth: int = 0):
    """Integral of f(x, y) over each cell of the grid x_edges x y_edges, shape (nx, ny); adaptive
    like integrate_cells_1d (a sub-cell holding a fraction w of its cell gets budget * sqrt(w)).
    A sub-cell is halved along x and along y for the error estimate, and split along the axis where
    halving changed the estimate more, so a lobe or edge varying along one axis costs refinement
    along that axis only.
    Note the usual limit of adaptive quadrature: a feature narrower than a cell that no Gauss node
    of the cell touches is missed (restrict the grid to the pdf's support instead).
    rule=True also returns the quadrature rule it converged to, (x, y, weights), so that another
    function (a float32 device routine, whose rounding noise would stall refinement) can be
    integrated on the partition chosen for an accurate float64 one. min_depth: splits every cell
    gets before any estimate is trusted, as in 1D (a pdf that is zero at all Gauss nodes of a cell,
    such as one that starts at a horizon crossing the cell, would otherwise count as zero there)."""
    xe, ye = np.asarray(x_edges, np.float64), np.asarray(y_edges, np.float64)
    nx, ny = len(xe) - 1, len(ye) - 1
    ix, iy = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    x0, x1, y0, y1 = xe[ix].ravel(), xe[ix + 1].ravel(), ye[iy].ravel(), ye[iy + 1].ravel()
    owner = np.arange(nx * ny)
    area0 = (x1 - x0) * (y1 - y0)
    coarse = _gauss_2d(f, x0, x1, y0, y1)
    budget = np.asarray(cell_tol(coarse), np.float64) * np.ones(nx * ny)
    out = np.zeros(nx * ny)
    final = []
    for depth in range(max_depth):
        m = len(x0)
        xm, ym = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
        # children: x-halves (left, right), then y-halves (bottom, top)
        cx0 = np.concatenate([x0, xm, x0, x0])
        cx1 = np.concatenate([xm, x1, x1, x1])
        cy0 = np.concatenate([y0, y0, y0, ym])
        cy1 = np.concatenate([y1, y1, ym, y1])
        child = _gauss_2d(f, cx0, cx1, cy0, cy1).reshape(4, m)
        fx, fy = child[0] + child[1], child[2] + child[3]
        ex, ey = np.abs(fx - coarse), np.abs(fy - coarse)
        along_x = ex >= ey
        fine = np.where(along_x, fx, fy)
        err = np.maximum(ex, ey)
        tol = budget[owner] * np.sqrt((x1 - x0) * (y1 - y0) / area0[owner])
        done = (err <= tol + REL_FLOOR * np.abs(fine)) & (depth >= min_depth)
        if not done.all() and (depth == max_depth - 1 or 2 * np.count_nonzero(~done) > MAX_ACTIVE):
            _give_up(2 * np.count_nonzero(~done), depth, float(err[~done].max()))
        np.add.at(out, owner[done], fine[done])
        # the two children along the chosen axis, for every sub-cell
        pick = np.where(along_x, 0, 2)
        idx = np.concatenate([pick * m + np.arange(m), (pick + 1) * m + np.arange(m)])
        sel_done, sel_keep = np.tile(done, 2), np.tile(~done, 2)
        if rule:
            k = idx[sel_done]
            final.append((cx0[k], cx1[k], cy0[k], cy1[k]))
        k = idx[sel_keep]
        x0, x1, y0, y1 = cx0[k], cx1[k], cy0[k], cy1[k]
        owner, coarse = np.tile(owner, 2)[sel_keep], child.ravel()[k]
        if len(x0) == 0:
            break
    if rule:
        return out.reshape(nx, ny), _gauss_nodes_2d(*(np.concatenate(r) for r in zip(*final)))
    return out.reshape(nx, ny)


def _check_total(probabilities, n: int, what: str):
    """The pdf integrates to one over the histogram's domain: the expected counts add up to n within
    QUAD_FRACTION of the Poisson noise of the whole count. Catches a pdf that is not normalized, a
    domain that misses part of the support, and a lobe that the quadrature stepped over."""
    total = float(np.sum(probabilities))
    if abs(total - 1.0) * n > QUAD_FRACTION * math.sqrt(n):
        raise QuadratureError(f"{what}: the pdf integrates to {total:.9g} over the histogram's domain, not 1 "
                              f"(tolerance {QUAD_FRACTION / math.sqrt(n):.2g}): not normalized, a domain smaller "
                              "than its support, or a lobe narrower than the grid that the quadrature missed")


def _poisson_budget(n: int):
    """Per-cell quadrature budget (in probability) that is QUAD_FRACTION of the Poisson noise."""
    return lambda p: QUAD_FRACTION * np.sqrt(np.maximum(n * np.abs(p), 1.0)) / n


# ----------------------------------------------------------------------------------------------
# the chi-square test itself


@dataclass
class ChiSquareResult:
    statistic: float
    dof: int
    p_value: float
    threshold: float
    worst: list          # (label, observed, expected, contribution), largest contribution first
    pooled: int          # cells pooled together because their expected count was below MIN_EXPECTED
    error: str = ""      # a failure that is not a matter of statistics (samples where the pdf is 0)

    @property
    def passed(self) -> bool:
        return not self.error and self.p_value > self.threshold

    def report(self, what: str) -> str:
        lines = [f"{what}: chi-square {self.statistic:.2f} with {self.dof} dof, p-value {self.p_value:.3g} "
                 f"(threshold {self.threshold:.3g}); {self.pooled} low-count cells pooled"]
        if self.error:
            lines.append(self.error)
        lines.append("worst cells (cell: observed, expected, contribution):")
        lines += [f"  {lab}: {o:.0f}, {e:.2f}, {c:.2f}" for lab, o, e, c in self.worst]
        return "\n".join(lines)


def chi_square(observed, expected, labels=None, threshold: float | None = None) -> ChiSquareResult:
    """Pearson's chi-square of observed counts against expected counts (same shape, any number of
    cells), with low-expected cells pooled."""
    obs = np.asarray(observed, np.float64).ravel()
    exp = np.asarray(expected, np.float64).ravel()
    if labels is None:
        shape = np.shape(observed)
        labels = [str(np.unravel_index(i, shape)) if len(shape) > 1 else str(i) for i in range(obs.size)]
    threshold = test_alpha() if threshold is None else threshold
    error = ""
    # a cell whose pdf integral is zero (to rounding) must stay empty
    zero = exp <= 1e-12 * max(exp.sum(), 1.0)
    bad = np.flatnonzero(zero & (obs > 0))
    if bad.size:
        error = (f"{int(obs[bad].sum())} samples fell in {bad.size} cells where the pdf is zero, e.g. "
                 + ", ".join(f"{labels[i]} ({obs[i]:.0f})" for i in bad[:5]))
    order = np.argsort(exp, kind="stable")
    low = order[exp[order] < MIN_EXPECTED]
    pool_e, pool_o = exp[low].sum(), obs[low].sum()
    rest = order[exp[order] >= MIN_EXPECTED]
    k = 0
    while pool_e > 0 and pool_e < MIN_EXPECTED and k < rest.size:   # pool until the pool is big enough
        pool_e += exp[rest[k]]
        pool_o += obs[rest[k]]
        k += 1
    pooled = low.size + k
    rest = rest[k:]
    cells_o, cells_e = obs[rest], exp[rest]
    lab = [labels[i] for i in rest]
    if pooled:
        cells_o = np.append(cells_o, pool_o)
        cells_e = np.append(cells_e, pool_e)
        lab.append(f"pool of {pooled} cells")
    contrib = (cells_o - cells_e) ** 2 / np.where(cells_e > 0, cells_e, np.inf)
    stat = float(contrib.sum())
    dof = max(cells_o.size - 1, 1)
    p = float(chi2.sf(stat, dof))
    worst_idx = np.argsort(contrib)[::-1][:8]
    worst = [(lab[i], cells_o[i], cells_e[i], contrib[i]) for i in worst_idx]
    return ChiSquareResult(stat, dof, p, threshold, worst, pooled, error)


def assert_chi_square(observed, expected, what: str, labels=None) -> ChiSquareResult:
    _count()
    res = chi_square(observed, expected, labels)
    assert res.passed, res.report(what)
    return res


def _finish(observed, expected, what, labels, check: bool) -> ChiSquareResult:
    """check=False returns the result without asserting or counting (tests of the harness itself)."""
    if check:
        return assert_chi_square(observed, expected, what, labels)
    return chi_square(observed, expected, labels)


# ----------------------------------------------------------------------------------------------
# domains


def _check_finite(samples, what):
    s = np.asarray(samples)
    bad = ~np.isfinite(s.reshape(len(s), -1)).all(1)
    assert not bad.any(), f"{what}: {bad.sum()} non-finite samples, e.g. {s[bad][:3].tolist()}"


def chi2_1d(samples, pdf, lo: float, hi: float, bins: int = 51, extra_observed=(), extra_probability=(),
            extra_labels=(), what: str = "1D samples", check: bool = True) -> ChiSquareResult:
    """Samples in [lo, hi) against pdf (float64 callable) on `bins` equal cells. A sample outside
    [lo, hi) fails the test. extra_*: further cells (e.g. a discrete 'no event' outcome) with their
    observed counts and exact probabilities, part of the same test."""
    assert bins % 2 == 1, "use an odd resolution"
    x = np.asarray(samples, np.float64)
    _check_finite(x, what)
    n = x.size + int(np.sum(extra_observed))
    outside = (x < lo) | (x >= hi)
    assert not outside.any(), (f"{what}: {outside.sum()} samples outside [{lo}, {hi}), e.g. "
                               f"{x[outside][:5].tolist()}")
    edges = np.linspace(lo, hi, bins + 1)
    idx = np.minimum(((x - lo) / (hi - lo) * bins).astype(np.int64), bins - 1)
    counts = np.bincount(idx, minlength=bins).astype(np.float64)
    probs = integrate_cells_1d(pdf, edges, _poisson_budget(n))
    extra_labels = list(extra_labels) + [f"extra cell {k}" for k in range(len(extra_labels), len(extra_observed))]
    labels = [f"[{edges[i]:.4g}, {edges[i + 1]:.4g})" for i in range(bins)] + extra_labels
    allp = np.concatenate([probs, np.asarray(extra_probability, np.float64)])
    _check_total(allp, n, what)
    obs = np.concatenate([counts, np.asarray(extra_observed, np.float64)])
    exp = n * allp
    return _finish(obs, exp, what, labels, check)


def chi2_2d(samples, pdf, x_range, y_range, res=(31, 31), what: str = "2D samples",
            check: bool = True) -> ChiSquareResult:
    """Points (n, 2) in the rectangle x_range x y_range against pdf(x, y) (float64 callable)."""
    assert res[0] % 2 == 1 and res[1] % 2 == 1, "use an odd resolution"
    s = np.asarray(samples, np.float64)
    _check_finite(s, what)
    (x0, x1), (y0, y1) = x_range, y_range
    outside = (s[:, 0] < x0) | (s[:, 0] >= x1) | (s[:, 1] < y0) | (s[:, 1] >= y1)
    assert not outside.any(), f"{what}: {outside.sum()} samples outside the domain, e.g. {s[outside][:3].tolist()}"
    n = len(s)
    i = np.minimum(((s[:, 0] - x0) / (x1 - x0) * res[0]).astype(np.int64), res[0] - 1)
    j = np.minimum(((s[:, 1] - y0) / (y1 - y0) * res[1]).astype(np.int64), res[1] - 1)
    counts = np.bincount(i * res[1] + j, minlength=res[0] * res[1]).reshape(res).astype(np.float64)
    xe, ye = np.linspace(x0, x1, res[0] + 1), np.linspace(y0, y1, res[1] + 1)
    probs = integrate_cells_2d(pdf, xe, ye, _poisson_budget(n))
    _check_total(probs, n, what)
    labels = [f"x [{xe[a]:.3g}, {xe[a + 1]:.3g}) y [{ye[b]:.3g}, {ye[b + 1]:.3g})"
              for a in range(res[0]) for b in range(res[1])]
    return _finish(counts, n * probs, what, labels, check)


def _sphere_pdf_in_cos_phi(pdf):
    def f(c, phi):
        s = np.sqrt(np.maximum(0.0, 1.0 - c * c))
        d = np.stack([s * np.cos(phi), s * np.sin(phi), c], axis=-1)
        return pdf(d)
    return f


def chi2_directions(dirs, pdf, res=(51, 101), cos_range=(-1.0, 1.0), what: str = "directions",
                    check: bool = True) -> ChiSquareResult:
    """Unit vectors (n, 3) against a solid-angle pdf(d) (float64 callable on (..., 3) arrays), on
    equal-area (cos theta, phi) cells over the sphere, or over the zone cos_range of it (for a pdf
    that vanishes outside: a sample outside the zone fails the test)."""
    assert res[0] % 2 == 1 and res[1] % 2 == 1, "use an odd resolution"
    d = np.asarray(dirs, np.float64)
    _check_finite(d, what)
    n = len(d)
    c0, c1 = cos_range
    cos = np.clip(d[:, 2] / np.linalg.norm(d, axis=1), -1.0, 1.0)
    # float32 unit vectors are unit to a few eps: a direction on the zone's edge may land that far out
    slack = 8 * float(np.finfo(np.float32).eps)
    outside = (cos < c0 - slack) | (cos > c1 + slack)
    cos = np.clip(cos, c0, c1)
    assert not outside.any(), (f"{what}: {outside.sum()} directions outside the zone cos theta in [{c0}, {c1}], "
                               f"e.g. {d[outside][:3].tolist()}")
    phi = np.mod(np.arctan2(d[:, 1], d[:, 0]), 2 * np.pi)
    i = np.minimum(((cos - c0) / (c1 - c0) * res[0]).astype(np.int64), res[0] - 1)
    j = np.minimum((phi / (2 * np.pi) * res[1]).astype(np.int64), res[1] - 1)
    counts = np.bincount(i * res[1] + j, minlength=res[0] * res[1]).reshape(res).astype(np.float64)
    ce, pe = np.linspace(c0, c1, res[0] + 1), np.linspace(0.0, 2 * np.pi, res[1] + 1)
    probs = integrate_cells_2d(_sphere_pdf_in_cos_phi(pdf), ce, pe, _poisson_budget(n))
    _check_total(probs, n, what)
    labels = [f"cos [{ce[a]:.3f}, {ce[a + 1]:.3f}) phi [{pe[b]:.3f}, {pe[b + 1]:.3f})"
              for a in range(res[0]) for b in range(res[1])]
    return _finish(counts, n * probs, what, labels, check)


def _chart_frame(axis):
    a = np.asarray(axis, np.float64)
    a = a / np.linalg.norm(a)
    helper = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(helper, a)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(a, e1), a


def chi2_directions_charts(dirs, pdf, charts, refused: int | None = None, res=(31, 61),
                           what: str = "directions", check: bool = True) -> ChiSquareResult:
    """Unit vectors (n, 3) against a solid-angle pdf(d) (float64 callable on (..., 3)) whose mass may
    lie in lobes far narrower than a (cos theta, phi) cell. The sphere is split into regions, each
    histogrammed in coordinates (t, phi) around its own axis: theta the angle from the axis,
    t = theta / (theta + width), which spreads a lobe `width` wide over half the cells and still
    covers the whole sphere. charts: (axis, width, region) with region(d) -> bool mask; the regions
    must partition the sphere (e.g. the two hemispheres of a reflection and a transmission lobe).
    refused: the number of samples the sampler gave up on, which form one more cell with expectation
    n (1 - integral of the pdf); None when the sampler never gives up (then the pdf must integrate
    to one)."""
    d = np.asarray(dirs, np.float64)
    _check_finite(d, what)
    n = len(d) + (refused or 0)
    counts_all, probs_all, labels = [], [], []
    owned = np.zeros(len(d), np.int64)
    for k, (axis, width, region) in enumerate(charts):
        e1, e2, a = _chart_frame(axis)
        t_max = np.pi / (np.pi + width)
        mine = np.asarray(region(d), bool)
        owned += mine
        v = d[mine]
        theta = np.arccos(np.clip(v @ a / np.linalg.norm(v, axis=1), -1.0, 1.0))
        phi = np.mod(np.arctan2(v @ e2, v @ e1), 2 * np.pi)
        t = theta / (theta + width)
        i = np.minimum((t / t_max * res[0]).astype(np.int64), res[0] - 1)
        j = np.minimum((phi / (2 * np.pi) * res[1]).astype(np.int64), res[1] - 1)
        counts_all.append(np.bincount(i * res[1] + j, minlength=res[0] * res[1]).astype(np.float64))

        def f(tt, pp, e1=e1, e2=e2, a=a, region=region):
            th = width * tt / (1.0 - tt)
            st = np.sin(th)
            dd = (st * np.cos(pp))[..., None] * e1 + (st * np.sin(pp))[..., None] * e2 + np.cos(th)[..., None] * a
            return pdf(dd) * np.where(region(dd), 1.0, 0.0) * st * width / (1.0 - tt) ** 2

        te, pe = np.linspace(0.0, t_max, res[0] + 1), np.linspace(0.0, 2 * np.pi, res[1] + 1)
        probs_all.append(integrate_cells_2d(f, te, pe, _poisson_budget(n), min_depth=2).ravel())
        labels += [f"chart {k} theta [{width * te[p] / (1 - te[p]):.4g}, {width * te[p + 1] / (1 - te[p + 1]):.4g}) "
                   f"phi [{pe[q]:.3f}, {pe[q + 1]:.3f})" for p in range(res[0]) for q in range(res[1])]
    assert np.all(owned == 1), f"{what}: the chart regions do not partition the sphere"
    return _finish_cells(counts_all, probs_all, labels, n, refused, what, check)


def _finish_cells(counts_all, probs_all, labels, n, refused, what, check) -> ChiSquareResult:
    """The test over cells from several parts of the sphere; with `refused` samples, the probability
    the cells leave over is one more cell, the refused ones."""
    counts, probs = np.concatenate(counts_all), np.concatenate(probs_all)
    if refused is None:
        _check_total(probs, n, what)
    else:
        rest = 1.0 - float(probs.sum())
        if rest * n < -QUAD_FRACTION * math.sqrt(n):
            raise QuadratureError(f"{what}: the pdf integrates to {probs.sum():.9g} > 1")
        counts = np.append(counts, refused)
        probs = np.append(probs, max(rest, 0.0))
        labels.append("refused samples")
    return _finish(counts, n * probs, what, labels, check)


def chi2_directions_zones(dirs, pdf, zones, refused: int | None = None, res=(31, 61),
                          what: str = "directions", check: bool = True) -> ChiSquareResult:
    """Unit vectors (n, 3) against a solid-angle pdf(d) on equal-area (cos theta, phi) cells over
    zones [c0, c1] of cos theta (e.g. the two hemispheres, so that a pdf that jumps at the horizon
    has a cell edge there); a sample outside every zone fails the test. refused: as in
    chi2_directions_charts."""
    d = np.asarray(dirs, np.float64)
    _check_finite(d, what)
    n = len(d) + (refused or 0)
    cos = np.clip(d[:, 2] / np.linalg.norm(d, axis=1), -1.0, 1.0)
    phi = np.mod(np.arctan2(d[:, 1], d[:, 0]), 2 * np.pi)
    counts_all, probs_all, labels = [], [], []
    placed = np.zeros(len(d), bool)
    for c0, c1 in zones:
        inside = (cos >= c0) & (cos <= c1) & ~placed
        placed |= inside
        i = np.minimum(((cos[inside] - c0) / (c1 - c0) * res[0]).astype(np.int64), res[0] - 1)
        j = np.minimum((phi[inside] / (2 * np.pi) * res[1]).astype(np.int64), res[1] - 1)
        counts_all.append(np.bincount(i * res[1] + j, minlength=res[0] * res[1]).astype(np.float64))
        ce, pe = np.linspace(c0, c1, res[0] + 1), np.linspace(0.0, 2 * np.pi, res[1] + 1)
        probs_all.append(integrate_cells_2d(_sphere_pdf_in_cos_phi(pdf), ce, pe, _poisson_budget(n)).ravel())
        labels += [f"cos [{ce[a]:.3f}, {ce[a + 1]:.3f}) phi [{pe[b]:.3f}, {pe[b + 1]:.3f})"
                   for a in range(res[0]) for b in range(res[1])]
    assert placed.all(), f"{what}: {(~placed).sum()} directions outside the zones, e.g. {d[~placed][:3].tolist()}"
    return _finish_cells(counts_all, probs_all, labels, n, refused, what, check)


def chi2_discrete(indices, probabilities, what: str = "discrete samples", check: bool = True) -> ChiSquareResult:
    """Sampled indices against their probabilities; an index out of range fails the test."""
    k = np.asarray(indices)
    p = np.asarray(probabilities, np.float64)
    bad = (k < 0) | (k >= p.size)
    assert not bad.any(), f"{what}: {bad.sum()} indices outside [0, {p.size}), e.g. {k[bad][:5].tolist()}"
    counts = np.bincount(k, minlength=p.size).astype(np.float64)
    return _finish(counts, k.size * p, what, [f"index {i}" for i in range(p.size)], check)


# ----------------------------------------------------------------------------------------------
# "the pdf integrates to one"


def line_rule(pdf, lo: float, hi: float, tol: float = 1e-9, cells: int = 65):
    """A quadrature rule (nodes, weights) on [lo, hi] that integrates pdf (float64 callable) to
    within tol: integrate a float32 device routine on it, or the same pdf."""
    _, rule = integrate_cells_1d(pdf, np.linspace(lo, hi, cells + 1), lambda p: tol / cells, rule=True)
    return rule


def integral_1d(pdf, lo: float, hi: float, tol: float = 1e-9, cells: int = 65) -> float:
    x, w = line_rule(pdf, lo, hi, tol, cells)
    return float(np.sum(w * pdf(x)))


def sphere_rule(pdf, tol: float = 1e-9, res=(51, 101), cos_range=(-1.0, 1.0)):
    """A quadrature rule (directions (k, 3), weights (k,)) over the sphere, or the zone cos_range
    of it, that integrates the solid-angle density pdf (float64 callable on (..., 3)) to within tol."""
    _, (c, phi, w) = integrate_cells_2d(_sphere_pdf_in_cos_phi(pdf), np.linspace(*cos_range, res[0] + 1),
                                        np.linspace(0, 2 * np.pi, res[1] + 1), lambda p: tol / (res[0] * res[1]),
                                        rule=True)
    s = np.sqrt(np.maximum(0.0, 1.0 - c * c))
    return np.stack([s * np.cos(phi), s * np.sin(phi), c], axis=-1), w


def integral_sphere(pdf, tol: float = 1e-9, res=(51, 101), cos_range=(-1.0, 1.0)) -> float:
    """Integral over the sphere (or the zone cos_range of it, for a pdf that vanishes outside) of a
    solid-angle density pdf(d) (float64 callable on (..., 3))."""
    d, w = sphere_rule(pdf, tol, res, cos_range)
    return float(np.sum(w * pdf(d)))


def assert_integrates_to_one(total: float, tol: float, what: str):
    """`tol` is a numerical bound (quadrature plus the float precision the pdf is evaluated in)."""
    assert abs(total - 1.0) <= tol, f"{what}: the pdf integrates to {total:.9g}, not 1 (tolerance {tol:.2g})"


# ----------------------------------------------------------------------------------------------
# means and probabilities


def assert_mean(values, expected, what: str, names=None, sd=None):
    """The sample mean of each column of `values` equals `expected` within z_limit() standard errors.
    The standard error is estimated from the samples, or comes from `sd`, the standard deviation the
    null hypothesis implies, where it is known: prefer that for skewed distributions, whose rare
    large values make the sample estimate unreliable. A column whose samples are all equal has no
    standard error: its mean must then equal the expectation to float32 rounding. Counts as one
    test per column."""
    v = np.asarray(values, np.float64)
    v = v.reshape(len(v), -1)
    _check_finite(v, what)
    exp = np.broadcast_to(np.asarray(expected, np.float64), (v.shape[1],))
    mean = v.mean(0)
    spread = v.std(0, ddof=1) if sd is None else np.broadcast_to(np.asarray(sd, np.float64), (v.shape[1],))
    se = spread / math.sqrt(len(v))
    _count(v.shape[1])
    limit = z_limit()
    fails = []
    for c in range(v.shape[1]):
        name = names[c] if names else f"column {c}"
        if se[c] == 0.0:
            ok = abs(mean[c] - exp[c]) <= 4 * np.finfo(np.float32).eps * max(1.0, abs(exp[c]))
            z = 0.0 if ok else math.inf
        else:
            z = (mean[c] - exp[c]) / se[c]
        if not abs(z) < limit:
            fails.append(f"{name}: mean {mean[c]:.7g} expected {exp[c]:.7g}, standard error {se[c]:.3g}, "
                         f"z = {z:.2f} (limit {limit:.2f})")
    assert not fails, f"{what}: " + "; ".join(fails)


def assert_probability(k: int, n: int, p: float, what: str):
    """k successes in n trials are consistent with probability p (exact two-sided binomial test).
    p = 0 or 1 is a certainty, checked exactly."""
    k, n = int(k), int(n)
    _count()
    if p <= 0.0 or p >= 1.0:
        want = 0 if p <= 0.0 else n
        assert k == want, f"{what}: {k} of {n} where the probability is {p} (expected {want})"
        return
    pv = binomtest(k, n, p).pvalue
    assert pv > test_alpha(), (f"{what}: {k} of {n} = {k / n:.6f}, expected probability {p:.6f} "
                               f"(binomial p-value {pv:.3g}, threshold {test_alpha():.3g})")
