"""Emission from temperature, with pbrt-v4's meaning (its BlackbodySpectrum and nanovdb medium):
a blackbody at T kelvin has Planck's spectral radiance B(lambda, T) divided by its value at the
peak wavelength lambda_max = b / T (Wien's displacement law, b = 2.8977721e-3 m K), so its
spectrum peaks at exactly 1 whatever the temperature; times `volcl_emission_scale`. Temperatures
come from the grid as T = (value - volcl_temperature_offset) * volcl_temperature_scale, and
T <= 100 K emits nothing (pbrt-v4's cut-off).

volcl renders linear sRGB, so the normalized spectrum is integrated against the CIE 1931 matching
functions exactly as volcl.scene.spectra converts any emission spectrum (Mitsuba's 1000-point sum,
a unit spectrum of luminance 1, no white-point weighting), and taken to linear sRGB, negative
components clamped to 0. The kernels interpolate a table of that colour over log T (table);
tests/test_temperature.py checks the table against the direct integral.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from .scene import spectra

WIEN_B = 2.8977721e-3          # m K
T_CUTOFF = 100.0               # kelvin: at or below it, no emission (pbrt-v4)
# The table spans log T from T_CUTOFF to T_MAX in TABLE_SIZE knots; hotter clamps to T_MAX, where
# the normalized colour has long stopped changing (it tends to the Rayleigh-Jeans limit's).
T_MAX = 1.0e6
TABLE_SIZE = 4096


def normalized_spectrum(wavelength_nm: np.ndarray, temperature: float) -> np.ndarray:
    """B(lambda, T) / B(lambda_max, T)."""
    peak_nm = WIEN_B / temperature * 1e9
    return spectra.blackbody_radiance(wavelength_nm, temperature) / spectra.blackbody_radiance(
        np.array([peak_nm]), temperature)[0]


def rgb(temperature: float) -> np.ndarray:
    """Linear sRGB of the normalized blackbody at `temperature` (0 at or below the cut-off)."""
    if not temperature > T_CUTOFF:
        return np.zeros(3)
    return _rgb_many(np.array([float(temperature)]))[0]


def _rgb_many(temperatures: np.ndarray) -> np.ndarray:
    """rgb() of many temperatures at once (the same sum, as one matrix product)."""
    grid, cmfs, _ = spectra._tables()
    w = spectra._sum_points()
    xyz_bar = np.stack([np.interp(w, grid, cmfs[:, i]) for i in range(3)], axis=1)
    with np.errstate(over="ignore"):
        v = np.stack([normalized_spectrum(w, t) for t in temperatures])
    xyz = v @ xyz_bar * (spectra.CIE_MAX - spectra.CIE_MIN) * spectra.Y_NORMALIZATION / spectra.STEPS
    return np.maximum(xyz @ spectra.XYZ_TO_SRGB.T, 0.0)


@lru_cache(maxsize=1)
def table() -> np.ndarray:
    """(TABLE_SIZE, 3) float32: the colour at T = T_CUTOFF * (T_MAX / T_CUTOFF) ** (i / (TABLE_SIZE - 1)).
    Linear interpolation of it is within 1e-3 of the colour (relative to its largest channel) above
    500 K, and within 4e-6 absolutely everywhere (tests/test_temperature.py)."""
    temps = T_CUTOFF * (T_MAX / T_CUTOFF) ** (np.arange(TABLE_SIZE) / (TABLE_SIZE - 1))
    out = _rgb_many(temps)
    out[0] = 0.0            # the cut-off itself emits nothing
    return out.astype(np.float32)


def table_lookup(temperature: np.ndarray) -> np.ndarray:
    """The kernel's interpolation of table() (numpy reference), for temperatures in kelvin."""
    t = np.asarray(temperature, np.float64)
    x = np.log(np.maximum(t, T_CUTOFF) / T_CUTOFF) / np.log(T_MAX / T_CUTOFF) * (TABLE_SIZE - 1)
    x = np.clip(x, 0, TABLE_SIZE - 1)
    i = np.minimum(np.floor(x).astype(int), TABLE_SIZE - 2)
    w = (x - i)[..., None]
    tab = table().astype(np.float64)
    out = (1 - w) * tab[i] + w * tab[i + 1]
    return np.where((t > T_CUTOFF)[..., None], out, 0.0)
