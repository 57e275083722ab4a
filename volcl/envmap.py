"""Environment maps (Mitsuba's `envmap`) as the kernels read them: the image's texels and the tables
that importance sample it. kernels/envmap.h states the conventions (frame, texel placement, density)
and the layout written here.

The density follows Mitsuba 3.9 (src/emitters/envmap.cpp): over the image's (u, v) square it is the
bilinear interpolant of luminance x sin(theta) at the texels (columns texel-centred and periodic, rows
on the poles), so its pdf is Mitsuba's own. Mitsuba draws from it by hierarchical warping; volcl picks
a bilinear patch from a marginal and a conditional CDF, then a point inside the patch, which gives the
same density.
"""
from __future__ import annotations

import math

import numpy as np

from .guides import guide

# Mitsuba's luminance of linear sRGB (src/render/srgb.h, the kernels' luminance())
LUMINANCE = np.array([0.212671, 0.715160, 0.072169])
# Mitsuba pads smaller images to this (width, height) by repeating the last column and row
MIN_SIZE = (2, 3)


def rgb_texels(image: np.ndarray) -> np.ndarray:
    """(h, w, 3) float64 colours of an image as read by volcl.scene.images.read_image, as Mitsuba's
    Bitmap.convert(RGB) makes them: a grey image (with or without alpha) repeats its grey, an RGB(A)
    image keeps its first three channels (alpha is dropped, not divided out)."""
    a = np.asarray(image, np.float64)
    if a.ndim == 2:
        a = a[..., None]
    if a.shape[2] <= 2:
        return np.repeat(a[..., :1], 3, axis=2)
    return a[..., :3].copy()


def pad_to_minimum(texels: np.ndarray) -> np.ndarray:
    """Mitsuba's Bitmap::pad_to(2, 3): columns, then rows, repeated at the end up to the minimum."""
    h, w = texels.shape[:2]
    if w < MIN_SIZE[0]:
        texels = np.concatenate([texels] + [texels[:, -1:]] * (MIN_SIZE[0] - w), axis=1)
    if h < MIN_SIZE[1]:
        texels = np.concatenate([texels] + [texels[-1:]] * (MIN_SIZE[1] - h), axis=0)
    return texels


def texels_for(image: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """The (H, W, 3) float32 texels the kernel reads: RGB, padded, times scale."""
    return (pad_to_minimum(rgb_texels(image)) * scale).astype(np.float32)


def nodes(texels: np.ndarray) -> np.ndarray:
    """(H, W + 1) float32 nodes of the density: each texel's luminance times sin(theta) of its row
    (theta = pi j / (H - 1)), the first column repeated at the end (the periodic seam)."""
    h = texels.shape[0]
    lum = np.asarray(texels, np.float64) @ LUMINANCE
    lum = np.concatenate([lum, lum[:, :1]], axis=1)
    sin_theta = np.sin(np.pi * np.arange(h) / (h - 1))
    # the pole rows are exactly zero (sin(pi) is 1.2e-16 in float64)
    sin_theta[[0, -1]] = 0.0
    return (lum * sin_theta[:, None]).astype(np.float32)


def patch_masses(node_values: np.ndarray) -> np.ndarray:
    """(H - 1, W) integral of the bilinear interpolant over each patch: the mean of its four nodes."""
    f = np.asarray(node_values, np.float64)
    return 0.25 * (f[:-1, :-1] + f[:-1, 1:] + f[1:, :-1] + f[1:, 1:])


def _normalized_cdf(weights: np.ndarray) -> np.ndarray:
    """Inclusive prefix sums along the last axis, normalized to end at exactly 1; a row without
    weight gets a uniform CDF (never picked: its marginal probability is zero)."""
    c = np.cumsum(weights, axis=-1)
    total = c[..., -1:]
    n = weights.shape[-1]
    uniform = np.arange(1, n + 1) / n
    out = np.where(total > 0, c / np.where(total > 0, total, 1.0), uniform)
    out[..., -1] = 1.0
    return out


def tables(texels: np.ndarray) -> tuple[np.ndarray, float]:
    """(the float32 tables kernels/envmap.h reads: texels, nodes, conditional and marginal CDFs,
    concatenated; env_norm). env_norm is 0 for an image without light (nothing to sample)."""
    h, w = texels.shape[:2]
    f = nodes(texels)
    masses = patch_masses(f)
    rows = masses.sum(axis=1)
    cond = _normalized_cdf(masses)
    marg = _normalized_cdf(rows)
    total = float(rows.sum())
    norm = w * (h - 1) / (2 * math.pi ** 2) if total > 0 else 0.0
    cond, marg = cond.astype(np.float32), marg.astype(np.float32)
    data = np.concatenate([np.asarray(texels, np.float32).reshape(-1), f.reshape(-1), cond.reshape(-1), marg,
                           guide(cond).reshape(-1), guide(marg)])
    return data, norm


def table_size(width: int, height: int) -> int:
    """Floats tables() writes for an image of this size (after padding)."""
    return 3 * width * height + (width + 1) * height + 2 * (width * (height - 1) + (height - 1))


# -- the same functions in float64, for tests and checks: directions in the envmap's own frame ------

def direction_to_uv(d: np.ndarray) -> np.ndarray:
    """(..., 2) image coordinates (u in [0, 1), v in [0, 1]) of local directions (..., 3)."""
    d = np.asarray(d, np.float64)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    u = np.arctan2(d[..., 0], -d[..., 2]) / (2 * np.pi)
    v = np.arccos(np.clip(d[..., 1], -1.0, 1.0)) / np.pi
    return np.stack([u - np.floor(u), v], axis=-1)


def uv_to_direction(uv: np.ndarray) -> np.ndarray:
    uv = np.asarray(uv, np.float64)
    theta, phi = np.pi * uv[..., 1], 2 * np.pi * uv[..., 0]
    return np.stack([np.sin(phi) * np.sin(theta), np.cos(theta), -np.cos(phi) * np.sin(theta)], axis=-1)


def _patches(uv: np.ndarray, w: int, h: int):
    """(i, j, s, t): the patch of image coordinates and the place in it (kernels/envmap.h)."""
    x = np.mod(uv[..., 0] * w - 0.5, w)
    y = uv[..., 1] * (h - 1)
    i = np.minimum(np.floor(x).astype(np.int64), w - 1)
    j = np.minimum(np.floor(y).astype(np.int64), h - 2)
    return i, j, x - i, y - j


def patch_choice(texels: np.ndarray, d_local: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(probability of the row of patches, probability of the patch within its row) that the
    sampler picks for local directions d: the float64 values of the CDF steps the kernel reads in
    float32 (whose rounding, up to an ulp of 1 per entry, is relative to these)."""
    h, w = texels.shape[:2]
    masses = patch_masses(nodes(texels))
    rows = masses.sum(axis=1)
    i, j, _, _ = _patches(direction_to_uv(d_local), w, h)
    with np.errstate(divide="ignore", invalid="ignore"):
        return rows[j] / rows.sum(), masses[j, i] / rows[j]


def _bilinear(grid: np.ndarray, uv: np.ndarray, periodic_width: int) -> np.ndarray:
    """Bilinear interpolation of grid (H, W + 1, ...) with columns i at x = i, x = u W - 0.5 wrapped
    into [0, W), rows j at y = v (H - 1)."""
    i, j, s, t = _patches(uv, periodic_width, grid.shape[0])
    if grid.ndim == 3:
        s, t = s[..., None], t[..., None]
    a, b, c, e = grid[j, i], grid[j, i + 1], grid[j + 1, i], grid[j + 1, i + 1]
    return (1 - t) * ((1 - s) * a + s * b) + t * ((1 - s) * c + s * e)


def radiance(texels: np.ndarray, d_local: np.ndarray) -> np.ndarray:
    """(..., 3) radiance arriving from local directions d (Mitsuba's envmap eval, float64)."""
    t = np.asarray(texels, np.float64)
    periodic = np.concatenate([t, t[:, :1]], axis=1)
    return _bilinear(periodic, direction_to_uv(d_local), t.shape[1])


def pdf(texels: np.ndarray, d_local: np.ndarray) -> np.ndarray:
    """The solid-angle density of the envmap's direction sampling at local directions d (float64,
    from the float32 nodes; the float32 CDF steps the kernel uses differ from it by their rounding)."""
    h, w = texels.shape[:2]
    f = nodes(texels).astype(np.float64)
    total = patch_masses(f).sum()
    d = np.asarray(d_local, np.float64)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    uv = direction_to_uv(d)
    sin_theta = np.sqrt(d[..., 0] ** 2 + d[..., 2] ** 2)
    density_uv = _bilinear(f, uv, w) / total * w * (h - 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = density_uv / (2 * np.pi ** 2 * sin_theta)
    return np.where(sin_theta > 0, out, 0.0)
