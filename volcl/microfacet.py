"""Host-side microfacet quantities that bsdfs precompute, as Mitsuba 3.9 computes them:

- roughplastic's table of the rough coating's transmittance at 64 cosines, and its internal
  reflectance (src/bsdfs/roughplastic.cpp parameters_changed, include/mitsuba/render/microfacet.h
  eval_transmittance / eval_reflectance): Gauss-Legendre quadrature over the unit square of visible
  normal sampling, 32 x 32 nodes for eta > 1 and 128 x 128 below;
- plastic's internal diffuse Fresnel reflectance (include/mitsuba/render/fresnel.h
  fresnel_diffuse_reflectance: Egan and Hilgeman's fit below eta = 1, d'Eon and Irving's above).

Written in float64 numpy; the visible-normal sampling here is the same construction the kernels
use (kernels/microfacet.h), so the quadrature integrates what Mitsuba integrates. A roughplastic
table takes about a second (the 128 x 128 quadrature at 64 cosines), so each is kept in volcl's
cache folder under a key of its parameters and this file's text, and read back bit for bit by
later processes.
"""
from __future__ import annotations

import hashlib
import os
from functools import lru_cache
from pathlib import Path

import numpy as np
from numpy.polynomial.legendre import leggauss

TABLE_SIZE = 64     # Mitsuba's MI_ROUGH_TRANSMITTANCE_RES


def fresnel(cos_i, eta):
    """Mitsuba's fresnel(): (reflectance, cos_t signed, eta_it, eta_ti) for signed cos_i."""
    cos_i = np.asarray(cos_i, np.float64)
    outside = cos_i >= 0
    eta_it = np.where(outside, eta, 1.0 / eta)
    eta_ti = 1.0 / eta_it
    ct2 = 1.0 - (1.0 - cos_i ** 2) * eta_ti ** 2
    ci, ct = np.abs(cos_i), np.sqrt(np.maximum(ct2, 0.0))
    a_s = (ci - eta_it * ct) / (ci + eta_it * ct)
    a_p = (ct - eta_it * ci) / (ct + eta_it * ci)
    r = 0.5 * (a_s ** 2 + a_p ** 2)
    if eta == 1.0:
        r = np.zeros_like(r)
    r = np.where(ci == 0, 1.0, r)
    return r, np.where(outside, -ct, ct), eta_it, eta_ti


def fresnel_diffuse_reflectance(eta: float) -> float:
    """Hemispherically averaged Fresnel reflectance for light from inside a medium of relative IOR eta."""
    if eta < 1.0:
        return 0.0636 / eta + eta * (eta * -1.4399 + 0.7099) + 0.6681
    x = 1.0 / eta
    return ((((-1.36881 * x + 4.98554) * x - 7.80989) * x + 6.75335) * x - 3.4793) * x + 0.919317


def smith_g1(kind: str, alpha: float, v, m):
    xy = (alpha * v[..., 0]) ** 2 + (alpha * v[..., 1]) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        tan2 = xy / v[..., 2] ** 2
        if kind == "beckmann":
            a = 1.0 / np.sqrt(tan2)
            r = np.where(a >= 1.6, 1.0, (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a))
        else:
            r = 2.0 / (1.0 + np.sqrt(1.0 + tan2))
    r = np.where(xy == 0, 1.0, r)
    return np.where(np.einsum("...i,...i", v, m) * v[..., 2] <= 0, 0.0, r)


def _concentric(u):
    x, y = 2 * u[..., 0] - 1, 2 * u[..., 1] - 1
    first = np.abs(x) > np.abs(y)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(first, x, y)
        theta = np.where(first, np.pi / 4 * (y / x), np.pi / 2 - np.pi / 4 * (x / y))
    zero = (x == 0) & (y == 0)
    r, theta = np.where(zero, 0.0, r), np.where(zero, 0.0, theta)
    return r * np.cos(theta), r * np.sin(theta)


def _visible_slope_11(kind: str, cos_i, u):
    if kind == "beckmann":
        from scipy.special import erf, erfinv
        tan_i = np.sqrt(np.maximum(1 - cos_i ** 2, 0)) / cos_i
        with np.errstate(divide="ignore"):
            cot_i = 1 / tan_i       # inf at normal incidence, where erf gives 1
        maxval = erf(cot_i)
        u = np.clip(u, 1e-6, 1 - 1e-6)
        x = maxval - (maxval + 1) * erf(np.sqrt(-np.log(u[..., 0])))
        ux = u[..., 0] * (1 + maxval + tan_i * np.exp(-cot_i ** 2) / np.sqrt(np.pi))
        for _ in range(3):
            slope = erfinv(x)
            value = 1 + x + tan_i * np.exp(-slope ** 2) / np.sqrt(np.pi) - ux
            x = x - value / (1 - slope * tan_i)
        return erfinv(x), erfinv(2 * u[..., 1] - 1)
    px, py = _concentric(u)
    s = 0.5 * (1 + cos_i)
    py = (1 - s) * np.sqrt(np.maximum(1 - px ** 2, 0)) + s * py
    z = np.sqrt(np.maximum(1 - px ** 2 - py ** 2, 0))
    sin_i = np.sqrt(np.maximum(1 - cos_i ** 2, 0))
    norm = 1 / (sin_i * py + cos_i * z)
    return (cos_i * py - sin_i * z) * norm, px * norm


def sample_visible(kind: str, alpha: float, wi, u):
    """Isotropic visible-normal sample m for directions wi (..., 3) in the upper hemisphere."""
    wp = np.stack([alpha * wi[..., 0], alpha * wi[..., 1], wi[..., 2]], -1)
    wp /= np.linalg.norm(wp, axis=-1, keepdims=True)
    st = np.hypot(wp[..., 0], wp[..., 1])
    small = st ** 2 <= 4 * np.finfo(np.float32).eps
    with np.errstate(divide="ignore", invalid="ignore"):
        cos_phi = np.where(small, 1.0, np.clip(wp[..., 0] / st, -1, 1))
        sin_phi = np.where(small, 0.0, np.clip(wp[..., 1] / st, -1, 1))
    sx, sy = _visible_slope_11(kind, wp[..., 2], u)
    slope_x = (cos_phi * sx - sin_phi * sy) * alpha
    slope_y = (sin_phi * sx + cos_phi * sy) * alpha
    m = np.stack([-slope_x, -slope_y, np.ones_like(slope_x)], -1)
    return m / np.linalg.norm(m, axis=-1, keepdims=True)


def _quadrature(res: int):
    nodes, weights = leggauss(res)
    u = np.stack(np.meshgrid(0.5 * nodes + 0.5, 0.5 * nodes + 0.5, indexing="ij"), -1).reshape(-1, 2)
    w = np.outer(weights, weights).reshape(-1) * 0.25
    return u, w


def _directions():
    mu = np.maximum(1e-6, np.linspace(0, 1, TABLE_SIZE))
    return mu, np.stack([np.sqrt(1 - mu * mu), np.zeros_like(mu), mu], -1)


def _masked_lobe(kind: str, alpha: float, eta: float, transmit: bool) -> np.ndarray:
    """Mitsuba's eval_transmittance (transmit) or eval_reflectance at the table's directions."""
    u, w = _quadrature(32 if eta > 1 else 128)
    mu, wi = _directions()
    wi_b = np.broadcast_to(wi[:, None, :], (len(mu), len(u), 3))
    u_b = np.broadcast_to(u[None], (len(mu), len(u), 2))
    m = sample_visible(kind, max(alpha, 1e-4), wi_b, u_b)
    cos_im = np.einsum("...i,...i", wi_b, m)
    r, cos_t, eta_it, eta_ti = fresnel(cos_im, eta)
    if transmit:
        wo = m * (cos_im * eta_ti + cos_t)[..., None] - wi_b * eta_ti[..., None]
        value = smith_g1(kind, max(alpha, 1e-4), wo, m) * (1 - r)
        value = np.where(wo[..., 2] * wi_b[..., 2] >= 0, 0.0, value)
    else:
        wo = 2 * cos_im[..., None] * m - wi_b
        value = smith_g1(kind, max(alpha, 1e-4), wo, m) * r
        value = np.where((wo[..., 2] <= 0) | (wi_b[..., 2] <= 0), 0.0, value)
    return np.nan_to_num(value) @ w


def _computed_tables(kind: str, alpha: float, eta: float) -> tuple[np.ndarray, float]:
    table = _masked_lobe(kind, alpha, eta, transmit=True)
    mu, _ = _directions()
    internal = 2.0 * float(np.mean(_masked_lobe(kind, alpha, 1.0 / eta, transmit=False) * mu))
    return table, internal


@lru_cache(maxsize=None)
def _source_hash() -> str:
    return hashlib.sha256(Path(__file__).read_bytes()).hexdigest()


def _table_file(kind: str, alpha: float, eta: float) -> Path:
    base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "volcl" / "roughplastic"
    name = hashlib.sha256(f"{_source_hash()} {kind} {float(alpha)!r} {float(eta)!r}".encode()).hexdigest()[:32]
    return base / f"{name}.npy"


@lru_cache(maxsize=64)
def roughplastic_tables(kind: str, alpha: float, eta: float) -> tuple[np.ndarray, float]:
    """(external transmittance at cos = linspace(0, 1, 64) (Mitsuba floors the first at 1e-6),
    internal reflectance: 2 * mean(R(mu) mu) over the same cosines, with R the reflectance from
    inside, relative IOR 1 / eta). From the cache folder where an earlier process computed them;
    a missing, unreadable or malformed file is computed again."""
    path = _table_file(kind, alpha, eta)
    try:
        stored = np.load(path, allow_pickle=False)
        if stored.shape == (TABLE_SIZE + 1,) and stored.dtype == np.float64 and np.isfinite(stored).all():
            return stored[:-1].copy(), float(stored[-1])
    except (OSError, ValueError):
        pass
    table, internal = _computed_tables(kind, alpha, eta)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp.npy")
        np.save(tmp, np.append(np.asarray(table, np.float64), internal))
        os.replace(tmp, path)
    except OSError:
        pass            # a read-only cache only costs the next process the computation
    return table, internal
