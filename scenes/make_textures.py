#!/usr/bin/env python3
"""Writes the textures the shipped scenes use (scenes/textures/), from seeded procedural patterns,
so no image is downloaded. Run it again to regenerate: python scenes/make_textures.py

- tiles.png: ceramic floor tiles, each its own shade, with grout lines (sRGB colour);
- wood.png: wood grain, growth rings bent by noise (sRGB colour);
- roughness.png: microfacet roughness 0.05 to 0.45 in blotches (raw grey: read with raw=true);
- plaster_normals.png: a tangent-space normal map of rough plaster (raw RGB, 2 rgb - 1);
- bumps.exr: a height field of round dimples for a bump map (float, 0 to 0.02).
"""
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parent / "textures"


def value_noise(shape, cells, rng):
    """Smoothly interpolated random values on a grid of `cells` per axis, tiling the image."""
    h, w = shape
    grid = rng.random((cells, cells))
    y, x = np.mgrid[0:h, 0:w]
    fy, fx = y / h * cells, x / w * cells
    y0, x0 = np.floor(fy).astype(int), np.floor(fx).astype(int)
    ty, tx = fy - y0, fx - x0
    ty, tx = ty * ty * (3 - 2 * ty), tx * tx * (3 - 2 * tx)
    y1, x1 = (y0 + 1) % cells, (x0 + 1) % cells
    top = grid[y0, x0] * (1 - tx) + grid[y0, x1] * tx
    bottom = grid[y1, x0] * (1 - tx) + grid[y1, x1] * tx
    return top * (1 - ty) + bottom * ty


def fractal(shape, rng, octaves=4, cells=4):
    total, amp = np.zeros(shape), 1.0
    for k in range(octaves):
        total += amp * value_noise(shape, cells * 2 ** k, rng)
        amp *= 0.5
    return total / (2 - 2 ** (1 - octaves))


def write(name, pixels, fmt):
    import OpenImageIO as oiio
    h, w, c = pixels.shape
    out = oiio.ImageOutput.create(str(OUT / name))
    out.open(str(OUT / name), oiio.ImageSpec(w, h, c, fmt))
    out.write_image(pixels)
    out.close()


def to_srgb8(linear):
    x = np.clip(linear, 0, 1)
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    return np.round(s * 255).astype(np.uint8)


def tiles(rng, n=256, per_side=4):
    y, x = np.mgrid[0:n, 0:n] / n * per_side
    ty, tx = np.floor(y).astype(int), np.floor(x).astype(int)
    shade = rng.uniform(0.75, 1.0, (per_side, per_side))[ty, tx]
    base = np.array([0.62, 0.52, 0.40])
    colour = base * shade[..., None] * (0.92 + 0.08 * fractal((n, n), rng)[..., None])
    fy, fx = y - ty, x - tx
    grout = (np.minimum(fy, 1 - fy) < 0.03) | (np.minimum(fx, 1 - fx) < 0.03)
    colour[grout] = [0.18, 0.17, 0.16]
    return to_srgb8(colour)


def wood(rng, n=256):
    y, x = np.mgrid[0:n, 0:n] / n
    warp = fractal((n, n), rng, cells=3)
    rings = np.sin(2 * np.pi * (9 * np.hypot(x - 0.3, 0.4 * (y - 1.4)) + 1.5 * warp)) * 0.5 + 0.5
    grain = 0.85 + 0.15 * value_noise((n, n), 64, rng)
    light, dark = np.array([0.55, 0.33, 0.15]), np.array([0.30, 0.15, 0.06])
    colour = (dark + (light - dark) * rings[..., None] ** 0.7) * grain[..., None]
    return to_srgb8(colour)


def roughness(rng, n=128):
    blotches = fractal((n, n), rng, cells=3)
    alpha = 0.05 + 0.4 * np.clip((blotches - 0.3) / 0.4, 0, 1)
    return np.round(alpha * 255).astype(np.uint8)[..., None]


def plaster_normals(rng, n=128, strength=2.0):
    height = fractal((n, n), rng, octaves=5, cells=8)
    gy, gx = np.gradient(height * strength * n / 32)
    normal = np.stack([-gx, -gy, np.ones_like(gx)], -1)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    return np.round((normal * 0.5 + 0.5) * 255).astype(np.uint8)


def bumps(n=64, per_side=4):
    y, x = np.mgrid[0:n, 0:n] / n * per_side
    fy, fx = y - np.floor(y) - 0.5, x - np.floor(x) - 0.5
    r2 = (fx * fx + fy * fy) / 0.16
    # heights in [0, 0.02] (textures hold no negative texels): the rim at 0.02, the dimples' floors at 0
    return ((1 - np.where(r2 < 1, (1 - r2) ** 2, 0.0)) * 0.02).astype(np.float32)[..., None]


def main():
    OUT.mkdir(exist_ok=True)
    rng = np.random.default_rng(2024)
    write("tiles.png", tiles(rng), "uint8")
    write("wood.png", wood(rng), "uint8")
    write("roughness.png", roughness(rng), "uint8")
    write("plaster_normals.png", plaster_normals(rng), "uint8")
    write("bumps.exr", bumps(), "float")


if __name__ == "__main__":
    main()
