"""Mitsuba 3.9's rayleigh, blendphase and tabphase against volcl's, with Mitsuba itself as the
reference (optional: skipped without a Python that has Mitsuba 3, from $VOLCL_MITSUBA_PYTHON or
../mitsuba-venv beside the checkout; Mitsuba always runs in its own process).

  - the phase functions' values at a set of scattering angles, from Mitsuba's eval_pdf, against
    kernels/phase.h on the device (nested blends, the table's orientation and normalization);
  - whole images: benchmarks/scenes/phase_*.xml (a sphere of each medium in the Cornell box)
    rendered by both, two seeds each, judged by ../shared/tools/compare_renders.py."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import phasekit
from volcl.scene.model import Phase

ROOT = Path(__file__).resolve().parent.parent
BENCH = ROOT / "benchmarks"
TOOL = ROOT.parent / "shared" / "tools" / "compare_renders.py"


def _mitsuba_python():
    for candidate in (os.environ.get("VOLCL_MITSUBA_PYTHON"), str(ROOT.parent / "mitsuba-venv" / "bin" / "python")):
        if candidate and Path(candidate).is_file():
            probe = subprocess.run([candidate, "-c", "import mitsuba"], capture_output=True)
            if probe.returncode == 0:
                return candidate
    return None


MITSUBA = _mitsuba_python()
pytestmark = pytest.mark.skipif(MITSUBA is None, reason="Mitsuba 3 not found ($VOLCL_MITSUBA_PYTHON, ../mitsuba-venv)")

COSINES = [-1.0, -0.7, -0.2, 0.0, 0.3, 0.9, 0.99, 1.0]
TABLE = "4, 1, 0.3, 0.2, 0.3, 1, 6, 12"
CASES = {
    "rayleigh": ({"type": "rayleigh"}, Phase("rayleigh")),
    "tabphase": ({"type": "tabphase", "values": TABLE},
                 Phase("tabulated", values=np.array([float(v) for v in TABLE.split(",")]))),
    "tabphase two": ({"type": "tabphase", "values": "0, 1"}, Phase("tabulated", values=np.array([0.0, 1.0]))),
    "nested blendphase": (
        {"type": "blendphase", "weight": 0.3, "phase_0": {"type": "hg", "g": 0.8},
         "phase_1": {"type": "blendphase", "weight": 0.6, "phase_0": {"type": "rayleigh"},
                     "phase_1": {"type": "hg", "g": -0.6}}},
        Phase("blend", weight=0.3, phases=(Phase("hg", 0.8), Phase("blend", weight=0.6, phases=(
            Phase("rayleigh"), Phase("hg", -0.6)))))),
}

# Mitsuba's wi points back along the incoming ray: the travel direction d_in is -wi, and a travel
# cosine c = dot(d_in, wo) is the direction (sqrt(1 - c^2), 0, -c) for wi = +z.
EVAL_SCRIPT = """
import json, sys
import drjit as dr
import mitsuba as mi
mi.set_variant("scalar_rgb")
cases, cosines = json.loads(sys.argv[1]), json.loads(sys.argv[2])
out = {}
for name, d in cases.items():
    p = mi.load_dict(d)
    it = dr.zeros(mi.MediumInteraction3f)
    it.wi = mi.Vector3f(0, 0, 1)
    it.sh_frame = mi.Frame3f(it.wi)
    ctx = mi.PhaseFunctionContext()
    out[name] = [[float(dr.ravel(v)[0]), float(pdf)] for v, pdf in
                 (p.eval_pdf(ctx, it, mi.Vector3f((1 - c * c) ** 0.5, 0, -c)) for c in cosines)]
print(json.dumps(out))
"""


def test_phase_values_match_mitsuba(cl_env, test_program):
    proc = subprocess.run([MITSUBA, "-c", EVAL_SCRIPT, json.dumps({k: v[0] for k, v in CASES.items()}),
                           json.dumps(COSINES)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    ref = json.loads(proc.stdout.strip().splitlines()[-1])
    prog = test_program("sampling_tests.cl")
    c = np.array(COSINES)
    d_out = np.stack([np.sqrt(1 - c * c), np.zeros_like(c), c], 1)      # travel cosine c from d_in = +z
    for name, (_, phase) in CASES.items():
        value, pdf = phasekit.evaluate(cl_env, prog, phase, [0, 0, 1], d_out)
        mts = np.array(ref[name])
        assert np.allclose(mts[:, 0], mts[:, 1]), f"{name}: Mitsuba's value and pdf differ"
        assert np.allclose(value, mts[:, 0], rtol=2e-6, atol=0), f"{name}: volcl {value} vs Mitsuba {mts[:, 0]}"
        assert np.all(pdf == value)


@pytest.fixture(scope="module")
def compare():
    sys.path.insert(0, str(BENCH))
    import compare_mitsuba
    import mitsuba_ref
    if not TOOL.is_file():
        pytest.skip(f"comparison tool {TOOL} missing")
    return compare_mitsuba, mitsuba_ref


@pytest.mark.parametrize("name", ["phase_rayleigh", "phase_blend", "phase_tab"])
def test_image_matches_mitsuba(device, tmp_path, compare, name):
    compare_mitsuba, mitsuba_ref = compare
    scene = BENCH / "scenes" / f"{name}.xml"
    defines = {"width": "64", "height": "48"}
    refs, tests = [], []
    for seed in (0, 1):
        refs.append(tmp_path / f"mitsuba_s{seed}.exr")
        mitsuba_ref.render_mitsuba(str(scene), str(refs[-1]), MITSUBA, mitsuba_ref.DEFAULT_VARIANT, 256, seed,
                                   defines, repeat=1, warmup=False)
        tests.append(tmp_path / f"volcl_s{seed}.exr")
        res = compare_mitsuba.render_volcl(scene, tests[-1], 256, seed, defines, device)
        assert res.invalid == 0
    proc = subprocess.run([sys.executable, str(TOOL), *map(str, refs), *map(str, tests), "--name", name],
                          capture_output=True, text=True)
    assert proc.stdout.strip().splitlines()[-1].startswith("PASS"), proc.stdout + proc.stderr
