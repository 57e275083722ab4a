"""<spectrum> values turned into the linear sRGB colours volcl renders with, as Mitsuba 3.9's RGB
variants turn them (src/core/properties.cpp get_texture_impl, src/core/spectrum.cpp
spectrum_list_to_srgb):

- a uniform spectrum is that grey, except on an emitter, where it is the value times
  xyz_to_srgb(1, 1, 1): a flat spectrum seen through the CIE curves is not white in sRGB (D65 white),
  and Mitsuba's RGB variants give it the same purple tint its spectral variants render;
- a tabulated spectrum (wavelength:value pairs, a file of such lines, or <spectrum type="regular"> /
  "irregular">) is interpolated linearly and integrated against the CIE 1931 2-degree matching
  functions by Mitsuba's 1000-point sum over 360-830 nm (zero outside the table's range), normalized
  so that a unit spectrum has luminance 1, then taken from XYZ to linear sRGB. Reflectances and other
  bounded values are weighted by the D65 illuminant (so that a unit reflectance is white) and clamped
  to [0, 1]; emission and unbounded values (conductor eta and k) are not weighted and only clamped
  at 0. Mitsuba warns when it clamps, and so does volcl;
- a blackbody (<spectrum type="blackbody">, `temperature` in kelvin, radiance per nm as Mitsuba
  defines it) is an emission spectrum: Mitsuba's RGB variants cannot render it (its blackbody throws
  outside spectral variants), so volcl integrates Planck's law the same way as a tabulated emission
  spectrum, which is the colour Mitsuba's spectral variants render, and warns.

The CIE 1931 matching functions and the D65 illuminant come from colour-science, sampled every 5 nm
and interpolated linearly as Mitsuba samples them (its tables are the same numbers: checked in
tests/test_spectra.py); the XYZ-to-sRGB matrix is Mitsuba's.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Callable, Optional

import numpy as np

CIE_MIN, CIE_MAX = 360.0, 830.0
STEPS = 1000
# Mitsuba's normalizations: 1 / the integral of y-bar, and of y-bar times D65 (relative to 560 nm)
Y_NORMALIZATION = 1.0 / 106.7502593994140625
D65_NORMALIZATION = 1.0 / 98.99741751876255
XYZ_TO_SRGB = np.array([[3.240479, -1.537150, -0.498535],
                        [-0.969256, 1.875991, 0.041556],
                        [0.055648, -0.204043, 1.057311]])

# Planck's law with the constants Mitsuba's blackbody uses (CODATA 2014)
_C = 2.99792458e8
_H = 6.62607004e-34
_K = 1.38064852e-23

KINDS = ("reflectance", "unbounded", "emission")


@dataclass(frozen=True)
class Spectrum:
    """A <spectrum>: uniform (one value), tabulated (wavelengths in nm, values), or a blackbody
    (temperature in kelvin, over wavelengths [wavelength_min, wavelength_max])."""
    values: tuple = ()
    wavelengths: Optional[tuple] = None
    temperature: Optional[float] = None
    wavelength_range: tuple = (CIE_MIN, CIE_MAX)

    @property
    def uniform(self) -> bool:
        return self.wavelengths is None and self.temperature is None

    def describe(self) -> str:
        if self.temperature is not None:
            return f"blackbody {self.temperature:g} K"
        if self.uniform:
            return f"uniform {self.values[0]:g}"
        return f"{len(self.values)} samples from {self.wavelengths[0]:g} to {self.wavelengths[-1]:g} nm"


@lru_cache(maxsize=1)
def _tables() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(wavelengths every 5 nm over 360-830, CIE 1931 x/y/z-bar (95, 3), D65 (95,))."""
    import colour      # imported here: it takes a second or two, and only spectra need it
    grid = np.arange(CIE_MIN, CIE_MAX + 1, 5.0)
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    # D65 from the CIE daylight series at its nominal 6504 K (the CIE D65 table, also past 780 nm,
    # where colour's tabulated D65 ends)
    xy = colour.temperature.CCT_to_xy_CIE_D(6500.0 * 1.4388 / 1.4380)
    d65 = colour.sd_CIE_illuminant_D_series(xy)
    return grid, np.asarray(cmfs[grid], np.float64), np.asarray(d65[grid], np.float64)


def _sum_points() -> np.ndarray:
    return CIE_MIN + np.arange(STEPS) / (STEPS - 1) * (CIE_MAX - CIE_MIN)


def to_srgb(w: np.ndarray, v: np.ndarray, *, d65: bool) -> np.ndarray:
    """Linear sRGB of the spectrum with values v at the sum points w (nm), before any clamping."""
    grid, cmfs, d65_table = _tables()
    xyz_bar = np.stack([np.interp(w, grid, cmfs[:, i]) for i in range(3)], axis=1)
    weight = v * (np.interp(w, grid, d65_table) * D65_NORMALIZATION if d65 else 1.0)
    xyz = (xyz_bar * weight[:, None]).sum(axis=0) * (CIE_MAX - CIE_MIN) * Y_NORMALIZATION / STEPS
    return XYZ_TO_SRGB @ xyz


def tabulated_srgb(wavelengths, values, *, d65: bool) -> np.ndarray:
    """Linear sRGB of a tabulated spectrum (not clamped)."""
    w = _sum_points()
    wl, vals = np.asarray(wavelengths, np.float64), np.asarray(values, np.float64)
    inside = (w >= wl[0]) & (w <= wl[-1])
    v = np.where(inside, np.interp(w, wl, vals), 0.0)
    return to_srgb(w, v, d65=d65)


def blackbody_radiance(wavelength_nm: np.ndarray, temperature: float) -> np.ndarray:
    """Planck's spectral radiance in W / (m^2 sr nm), as Mitsuba's blackbody evaluates it."""
    lam = np.asarray(wavelength_nm, np.float64) * 1e-9
    return 1e-9 * 2 * _H * _C * _C / (lam ** 5 * np.expm1(_H * _C / (_K * lam * temperature)))


def blackbody_srgb(temperature: float, wavelength_range=(CIE_MIN, CIE_MAX)) -> np.ndarray:
    """Linear sRGB of Planck's radiance at `temperature` over `wavelength_range` (nm)."""
    w = _sum_points()
    inside = (w >= wavelength_range[0]) & (w <= wavelength_range[1])
    v = np.where(inside, blackbody_radiance(w, temperature), 0.0)
    return np.maximum(to_srgb(w, v, d65=False), 0.0)


def to_rgb(spectrum: Spectrum, kind: str, warn: Callable[[str], None], fail: Callable[[str], Exception]
           ) -> np.ndarray:
    """The linear sRGB colour Mitsuba's RGB variants use for `spectrum` as a parameter of `kind`:
    'reflectance' (bounded: reflectances, albedo, sigma_t), 'unbounded' (conductor eta and k,
    constant volumes) or 'emission' (radiance, intensity, irradiance)."""
    assert kind in KINDS, kind
    if spectrum.temperature is not None:
        if kind != "emission":
            raise fail("a blackbody spectrum is only meaningful as emission (radiance, intensity, "
                       "irradiance), as in Mitsuba")
        rgb = blackbody_srgb(spectrum.temperature, spectrum.wavelength_range)
        warn(f"blackbody {spectrum.temperature:g} K: Mitsuba 3's RGB variants cannot render a "
             f"blackbody (only its spectral variants can); volcl uses the linear sRGB colour of the "
             f"spectrum integrated against the CIE curves, {np.round(rgb, 6).tolist()}, what the "
             f"spectral variants render")
        return rgb
    if spectrum.uniform:
        value = float(spectrum.values[0])
        if kind == "emission":
            return value * (XYZ_TO_SRGB @ np.ones(3))
        return np.full(3, value)
    raw = tabulated_srgb(spectrum.wavelengths, spectrum.values, d65=kind != "emission")
    rgb = np.clip(raw, 0.0, 1.0 if kind == "reflectance" else np.inf)
    if np.any(rgb != raw):
        warn(f"the spectrum ({spectrum.describe()}) converts to linear sRGB "
             f"{np.round(raw, 6).tolist()}, outside the gamut; clamped to "
             f"{np.round(rgb, 6).tolist()} as Mitsuba clamps it")
    return rgb
