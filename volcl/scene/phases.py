"""<phase> elements of the Mitsuba dialect: Mitsuba 3's isotropic, hg, rayleigh, blendphase and
tabphase with Mitsuba 3.9's meaning, and volcl's extensions (volcl_ prefix, so that Mitsuba reports
them instead of misreading them). volcl/phase.py says what each one is and how it is sampled.

Defaults of the extensions follow Blender Cycles' Volume Scatter node, which has the same phase
functions: g 0, alpha 0.5, diameter 20 micrometres, backscatter 0.1.
"""
from __future__ import annotations

import numpy as np

from .. import phase as ph
from .model import Phase
from .objects import phase_hg
from .parse_common import Node, Spec

SPECS = {
    "isotropic": Spec(),
    "hg": Spec({"g": "float"}),
    "rayleigh": Spec(),
    # a <volume> weight is read only to refuse it with a clear message
    "blendphase": Spec({"weight": "float"}, children=frozenset({"phase", "volume"})),
    "tabphase": Spec({"values": "string"}),
    "volcl_draine": Spec({"g": "float", "alpha": "float"}),
    "volcl_cornetteshanks": Spec({"g": "float"}),
    "volcl_fournierforand": Spec({"backscatter": "float", "n": "float", "mu": "float"}),
    "volcl_mie": Spec({"diameter": "float"}),
}


def _g(node: Node, default: float) -> float:
    return phase_hg(node, "g", default).g


def _blend(node: Node) -> Phase:
    volumes = node.objects("volume")
    if volumes:
        raise volumes[0].element.error("a spatially varying blendphase 'weight' (a <volume>) is not "
                                       "supported; give the weight as a <float> in [0, 1]")
    children = node.objects("phase")
    if len(children) != 2:
        raise node.fail(None, f"blendphase blends exactly two nested <phase> elements, found {len(children)}")
    weight = node.float("weight", 0.5)
    if not 0.0 <= weight <= 1.0:
        raise node.fail("weight", f"blendphase 'weight' = {weight} is outside its range [0, 1] (0 selects "
                                  f"the first nested phase, 1 the second)")
    # Mitsuba 3.9 takes the children in the order they are written (its documentation's
    # alphabetical order of names is not what 3.9.1 does)
    return Phase("blend", weight=weight, phases=(children[0].obj, children[1].obj))


def _tabulated(node: Node) -> Phase:
    text = node.string("values")
    tokens = [t for t in text.replace(",", " ").split() if t]
    values = []
    for t in tokens:
        try:
            values.append(float(t))
        except ValueError:
            raise node.fail("values", f"tabphase 'values': {t!r} is not a number") from None
    v = np.array(values, np.float64)
    if len(v) < 2:
        raise node.fail("values", f"tabphase 'values' needs at least 2 entries (the phase function at "
                                  f"cosines evenly spaced from -1 to 1), found {len(v)}")
    if not np.all(np.isfinite(v)) or np.any(v < 0):
        bad = v[~(np.isfinite(v) & (v >= 0))][0]
        raise node.fail("values", f"tabphase 'values' must all be finite and >= 0, found {bad:g}")
    if not np.any(v > 0):
        raise node.fail("values", "tabphase 'values' are all zero: a phase function needs some positive value")
    return Phase("tabulated", values=v)


def _draine(node: Node) -> Phase:
    g = _g(node, 0.0)
    alpha = node.float("alpha", 0.5)
    if not 0.0 <= alpha <= ph.DRAINE_ALPHA_MAX:
        raise node.fail("alpha", f"'alpha' = {alpha} is outside the allowed range 0 <= alpha <= "
                                 f"{ph.DRAINE_ALPHA_MAX:g}")
    return Phase("draine", g, alpha=alpha)


def _fournier_forand(node: Node) -> Phase:
    has = {k for k in ("backscatter", "n", "mu") if node.has(k)}
    n_lo, n_hi = ph.FF_N_RANGE
    mu_lo, mu_hi = ph.FF_MU_RANGE
    if "n" in has:
        n = node.float("n")
        if not n_lo < n <= n_hi:
            raise node.fail("n", f"'n' = {n} is outside the allowed range {n_lo:g} < n <= {n_hi:g} (the "
                                 f"particles' refractive index relative to the medium)")
    if has == {"n", "mu"}:
        mu = node.float("mu")
        if not mu_lo <= mu <= mu_hi:
            raise node.fail("mu", f"'mu' = {mu} is outside the allowed range {mu_lo:g} <= mu <= {mu_hi:g} "
                                  f"(the slope of the particles' Junge size distribution)")
        return Phase("fournier_forand", n=n, mu=mu)
    if has in (set(), {"backscatter"}, {"backscatter", "n"}):
        b = node.float("backscatter", 0.1)
        n = node.float("n") if "n" in has else None
        lo, hi = ph.backscatter_range(n)
        if not lo <= b <= hi:
            tied = f"n = {n:g}" if n is not None else "n tied to mu as n = 1.01 + 0.1542 (mu - 3) (Mobley et al. 2002)"
            raise node.fail("backscatter", f"'backscatter' = {b} is outside the allowed range {lo:.4g} <= "
                                           f"backscatter <= {hi:.4g} (with {tied}: mu from {mu_lo:g} to {mu_hi:g})")
        ff = ph.fournier_forand_from_backscatter(b, n)
        return Phase("fournier_forand", n=ff.n, mu=ff.mu)
    raise node.fail(None, "volcl_fournierforand takes 'backscatter' (alone, or with 'n'), or 'n' and 'mu'; "
                          f"got {', '.join(sorted(has))}")


def _mie(node: Node) -> Phase:
    d = node.float("diameter", 20.0)
    lo, hi = ph.MIE_DIAMETER_RANGE
    if not lo < d <= hi:
        raise node.fail("diameter", f"'diameter' = {d} micrometres is outside the range of the approximate "
                                    f"Mie fit, {lo:g} < diameter <= {hi:g}")
    return Phase("mie", diameter=d)


_BUILDERS = {
    "isotropic": lambda node: Phase(),
    "hg": lambda node: phase_hg(node, "g", 0.8),
    "rayleigh": lambda node: Phase("rayleigh"),
    "blendphase": _blend,
    "tabphase": _tabulated,
    "volcl_draine": _draine,
    "volcl_cornetteshanks": lambda node: Phase("cornette_shanks", _g(node, 0.0)),
    "volcl_fournierforand": _fournier_forand,
    "volcl_mie": _mie,
}


def build_phase(node: Node) -> Phase:
    return _BUILDERS[node.type](node)
