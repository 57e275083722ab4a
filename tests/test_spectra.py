"""Spectra to linear sRGB as Mitsuba 3.9's RGB variants convert them: colour-science's CIE 1931 and
D65 tables checked against Mitsuba's, and whole conversions against values read off Mitsuba 3.9.1
(mi.cie1931_xyz, mi.cie_d65, mi.spectrum_list_to_srgb), and live against Mitsuba where it is
installed."""
import json
import subprocess

import numpy as np
import pytest

from test_mitsuba_agreement import mitsuba_python
from volcl.scene import spectra


def interp_cmf(w):
    grid, cmfs, _ = spectra._tables()
    return np.array([np.interp(w, grid, cmfs[:, i]) for i in range(3)])


def interp_d65(w):
    grid, _, d65 = spectra._tables()
    return np.interp(w, grid, d65) * spectra.D65_NORMALIZATION


def test_tables_are_mitsubas():
    # mi.cie1931_xyz(555.5), mi.cie1931_xyz(432.0), mi.cie_d65(783.0) in Mitsuba 3.9.1 (float32)
    assert np.allclose(interp_cmf(555.5), [0.520295, 0.9995, 0.005565], atol=2e-6)
    assert np.allclose(interp_cmf(360.0), [0.0001299, 3.917e-6, 0.0006061], rtol=1e-4)
    assert interp_d65(783.0) == pytest.approx(0.6430386, rel=1e-5)
    grid, cmfs, d65 = spectra._tables()
    assert len(grid) == 95 and grid[0] == 360 and grid[-1] == 830
    assert d65[np.searchsorted(grid, 560)] == pytest.approx(100.0, abs=1e-3)     # D65 is relative to 560 nm


@pytest.mark.parametrize("wavelengths, values, d65, expected", [
    ([400, 500, 600, 700], [0.1, 0.8, 0.3, 0.5], True, [0.200403, 0.620177, 0.469339]),
    ([400, 500, 600, 700], [0.1, 0.8, 0.3, 0.5], False, [0.286496, 0.585734, 0.416193]),
    ([360, 830], [1, 1], False, [1.20488, 0.948229, 0.909267]),
    ([360, 830], [1, 1], True, [0.998983, 0.998872, 0.998802]),
])
def test_conversions_match_values_read_off_mitsuba(wavelengths, values, d65, expected):
    assert np.allclose(spectra.tabulated_srgb(wavelengths, values, d65=d65), expected, atol=2e-6)


def test_uniform_emission_is_mitsubas_purple():
    s = spectra.Spectrum(values=(1.0,))
    out = spectra.to_rgb(s, "emission", warn=lambda m: None, fail=ValueError)
    assert np.allclose(out, [1.204794, 0.948292, 0.908916], atol=1e-6)
    assert np.allclose(spectra.to_rgb(s, "reflectance", warn=lambda m: None, fail=ValueError), 1.0)


def test_blackbody_follows_planck():
    """Planck's law in W / (m^2 sr nm): the peak sits at Wien's 2.8978e6 nm K / T, and the colour
    warms as the temperature falls."""
    w = np.linspace(300, 3000, 5000)
    for temperature in (3000.0, 6000.0):
        peak = w[np.argmax(spectra.blackbody_radiance(w, temperature))]
        assert peak == pytest.approx(2.8978e6 / temperature, rel=2e-3)
    cool, hot = spectra.blackbody_srgb(3000), spectra.blackbody_srgb(9000)
    assert cool[0] / cool[2] > 1 > hot[0] / hot[2]


def test_against_mitsuba_itself():
    python = mitsuba_python()
    if python is None:
        pytest.skip("Mitsuba 3 not found")
    rng = np.random.default_rng(4)
    cases = []
    for _ in range(6):
        n = int(rng.integers(2, 12))
        w = np.sort(rng.uniform(350, 850, n)).round(2)
        if len(set(w)) < n:
            continue
        cases.append((w.tolist(), rng.uniform(0, 3, n).round(3).tolist()))
    code = ("import json, sys, mitsuba as mi; mi.set_variant('scalar_rgb'); cases = json.loads(sys.argv[1]); "
            "print(json.dumps([[list(mi.spectrum_list_to_srgb(w, v, b, d)) for b, d in ((False, True), (False, False))] "
            "for w, v in cases]))")
    proc = subprocess.run([python, "-c", code, json.dumps(cases)], capture_output=True, text=True, timeout=300)
    if proc.returncode != 0:
        pytest.skip(f"Mitsuba 3 did not run: {proc.stderr[-300:]}")
    # Mitsuba logs its clamping warnings to stdout too
    last = proc.stdout.strip().splitlines()[-1]
    expected = json.loads(last[last.index("[["):])
    for (w, v), (with_d65, without) in zip(cases, expected):
        assert np.allclose(np.maximum(spectra.tabulated_srgb(w, v, d65=True), 0), with_d65, atol=1e-5)
        assert np.allclose(np.maximum(spectra.tabulated_srgb(w, v, d65=False), 0), without, atol=1e-5)
