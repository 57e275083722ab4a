#!/usr/bin/env python3
"""Writes scenes/textures/sky.exr, the environment map of scenes/cloud_sky.xml: an analytic clear sky
(Preetham, Shirley and Smits 1999: the Perez distribution of luminance and chromaticity for a
turbidity and a sun position), a sun disc, and a dim ground below the horizon; numpy only, nothing
downloaded, the same file on every run.

The map is laid out as Mitsuba's envmap reads it (kernels/envmap.h): +y up, the top row on the
zenith and the bottom row on the nadir, texel column i at longitude 2 pi (i + 0.5) / W, direction
(sin phi sin theta, cos theta, -cos phi sin theta). The sky is scaled to a zenith radiance of 1; the
sun (2 degrees across, larger than the real one so that the map resolves it) adds about three
times the sky's irradiance on the ground. Half-float EXR, zip-compressed.

Run it again to regenerate: python scenes/make_sky.py [--width 512] [--elevation 35] [--azimuth 120]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
OUT = HERE / "textures" / "sky.exr"

# linear sRGB from CIE XYZ (D65 white)
XYZ_TO_SRGB = np.array([[3.2404542, -1.5371385, -0.4985314],
                        [-0.9692660, 1.8760108, 0.0415560],
                        [0.0556434, -0.2040259, 1.0572252]])


def perez_coefficients(turbidity: float) -> np.ndarray:
    """(3, 5): Perez's A..E for luminance Y and chromaticities x, y (Preetham et al., appendix)."""
    t = turbidity
    return np.array([
        [0.1787 * t - 1.4630, -0.3554 * t + 0.4275, -0.0227 * t + 5.3251, 0.1206 * t - 2.5771, -0.0670 * t + 0.3703],
        [-0.0193 * t - 0.2592, -0.0665 * t + 0.0008, -0.0004 * t + 0.2125, -0.0641 * t - 0.8989, -0.0033 * t + 0.0452],
        [-0.0167 * t - 0.2608, -0.0950 * t + 0.0092, -0.0079 * t + 0.2102, -0.0441 * t - 1.6537, -0.0109 * t + 0.0529],
    ])


def zenith_Yxy(turbidity: float, theta_sun: float) -> np.ndarray:
    """Zenith luminance (kcd/m^2) and chromaticity for the sun at zenith angle theta_sun."""
    t = turbidity
    chi = (4.0 / 9.0 - t / 120.0) * (np.pi - 2.0 * theta_sun)
    luminance = (4.0453 * t - 4.9710) * np.tan(chi) - 0.2155 * t + 2.4192
    s = np.array([theta_sun ** 3, theta_sun ** 2, theta_sun, 1.0])
    tt = np.array([t * t, t, 1.0])
    x = tt @ np.array([[0.00166, -0.00375, 0.00209, 0.0],
                       [-0.02903, 0.06377, -0.03202, 0.00394],
                       [0.11693, -0.21196, 0.06052, 0.25886]]) @ s
    y = tt @ np.array([[0.00275, -0.00610, 0.00317, 0.0],
                       [-0.04214, 0.08970, -0.04153, 0.00516],
                       [0.15346, -0.26756, 0.06670, 0.26688]]) @ s
    return np.array([luminance, x, y])


def perez(theta, gamma, c):
    """Perez's F(theta, gamma) = (1 + A exp(B / cos theta)) (1 + C exp(D gamma) + E cos^2 gamma)."""
    a, b, cc, d, e = c
    cos_t = np.maximum(np.cos(theta), 0.01)      # the horizon: the fit's exp(B / cos) limit
    return (1 + a * np.exp(b / cos_t)) * (1 + cc * np.exp(d * gamma) + e * np.cos(gamma) ** 2)


def sky_rgb(dirs: np.ndarray, sun: np.ndarray, turbidity: float) -> np.ndarray:
    """Linear sRGB of the clear sky along unit directions (..., 3), y up, relative units."""
    theta = np.arccos(np.clip(dirs[..., 1], -1, 1))
    theta_sun = float(np.arccos(np.clip(sun[1], -1, 1)))
    gamma = np.arccos(np.clip(dirs @ sun, -1, 1))
    coeffs = perez_coefficients(turbidity)
    zenith = zenith_Yxy(turbidity, theta_sun)
    Yxy = np.stack([zenith[k] * perez(theta, gamma, coeffs[k]) / perez(0.0, theta_sun, coeffs[k])
                    for k in range(3)], axis=-1)
    Y, x, y = Yxy[..., 0], Yxy[..., 1], Yxy[..., 2]
    xyz = np.stack([x * Y / y, Y, (1 - x - y) * Y / y], axis=-1)
    return np.maximum(xyz @ XYZ_TO_SRGB.T, 0.0)


def texel_directions(width: int, height: int) -> np.ndarray:
    """(H, W, 3) directions of the texel centres as Mitsuba's envmap places them."""
    theta = np.pi * np.arange(height) / (height - 1)
    phi = 2 * np.pi * (np.arange(width) + 0.5) / width
    t, p = np.meshgrid(theta, phi, indexing="ij")
    return np.stack([np.sin(p) * np.sin(t), np.cos(t), -np.cos(p) * np.sin(t)], axis=-1)


def make_sky(width: int = 512, elevation: float = 35.0, azimuth: float = 120.0, turbidity: float = 3.0,
             sun_radius: float = 1.0, ground=(0.12, 0.10, 0.08)) -> np.ndarray:
    height = width // 2
    el, az = np.radians(elevation), np.radians(azimuth)
    sun = np.array([np.sin(az) * np.cos(el), np.sin(el), -np.cos(az) * np.cos(el)])
    dirs = texel_directions(width, height)
    sky = sky_rgb(dirs, sun, turbidity)
    sky /= sky_rgb(np.array([0.0, 1.0, 0.0]), sun, turbidity).mean()     # zenith radiance 1
    below = dirs[..., 1] < 0
    # the ground under the horizon: a soft transition over a degree, then a dim brown
    fade = np.clip(-dirs[..., 1] / np.sin(np.radians(1.0)), 0, 1)[..., None]
    sky = np.where(below[..., None], (1 - fade) * sky + fade * np.asarray(ground), sky)
    # the sun: a disc of uniform radiance, sized to the map, with a faint aureole
    gamma = np.degrees(np.arccos(np.clip(dirs @ sun, -1, 1)))
    disc_sr = 2 * np.pi * (1 - np.cos(np.radians(sun_radius)))
    sky_irradiance = np.pi * sky[~below].mean()
    disc = 3.0 * sky_irradiance / (disc_sr * np.sin(el)) * np.array([1.0, 0.93, 0.82])
    sky = np.where((gamma <= sun_radius)[..., None], disc, sky)
    sky += (4.0 * np.exp(-gamma / 3.0))[..., None] * np.array([1.0, 0.9, 0.75]) * (gamma > sun_radius)[..., None]
    return sky.astype(np.float32)


def write_exr(path: Path, pixels: np.ndarray) -> None:
    import OpenImageIO as oiio
    h, w, c = pixels.shape
    spec = oiio.ImageSpec(w, h, c, oiio.HALF)
    spec.attribute("compression", "zip")
    path.parent.mkdir(parents=True, exist_ok=True)
    out = oiio.ImageOutput.create(str(path))
    if out is None or not out.open(str(path), spec):
        raise SystemExit(f"cannot write {path}: {oiio.geterror()}")
    out.write_image(pixels)
    out.close()


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--width", type=int, default=512)
    p.add_argument("--elevation", type=float, default=35.0, help="sun elevation, degrees")
    p.add_argument("--azimuth", type=float, default=120.0, help="sun longitude, degrees from -z towards +x")
    p.add_argument("--turbidity", type=float, default=3.0)
    p.add_argument("--out", type=Path, default=OUT)
    args = p.parse_args(argv)
    sky = make_sky(args.width, args.elevation, args.azimuth, args.turbidity)
    write_exr(args.out, sky)
    print(f"wrote {args.out} ({sky.shape[1]}x{sky.shape[0]}, max {sky.max():.4g})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
