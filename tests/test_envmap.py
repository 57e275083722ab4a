"""Environment maps and spot lights on the device (kernels/envmap.h, kernels/lights.h, volcl/envmap.py):
envmap direction sampling by chi-square against its solid-angle pdf, the pdf integrating to one, the
device's lookups and pdf against a float64 reference of Mitsuba's definitions, and (optional, with
Mitsuba 3) against Mitsuba's own envmap and spot emitters."""
import json
import math
import subprocess
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

import stats
from conftest import run_kernel
from scenebuild import camera, scene
from test_mitsuba_agreement import mitsuba_python
from volcl import envmap
from volcl.pack import pack
from volcl.scene import transform as tf
from volcl.scene.model import Emitter, rgb

pytestmark = pytest.mark.every_implementation

N = 1_000_000
f32, i32, u32 = np.float32, np.int32, np.uint32
HERE = Path(__file__).resolve().parent


@pytest.fixture(scope="module")
def prog(test_program):
    return test_program("light_tests.cl")


def map_image(h=6, w=10):
    """A small map with what makes sampling hard: a sun, a black strip, a bright seam column."""
    rng = np.random.default_rng(3)
    img = (rng.random((h, w, 3)) * 0.5 + 0.05).astype(np.float32)
    img[h // 2 - 1, (3 * w) // 10] = [40.0, 30.0, 20.0]
    img[h - 2, (6 * w) // 10:max((9 * w) // 10, (6 * w) // 10 + 1)] = 0.0
    img[:, 0] *= 3.0
    return img

# a rotation about an oblique axis: no image axis lines up with the chi-square grid's
ROTATION = tf.rotate(np.array([1.0, 2.0, 3.0]) / math.sqrt(14.0), 50.0)


def env_emitter(img, to_world=ROTATION, scale=2.0):
    return Emitter("envmap", rgb(1.0), to_world=to_world, image=img, scale=scale)


def buffers(emitters):
    p = pack(scene([], list(emitters), cam=camera()))
    return [p.arrays["lights"], p.arrays["env_data"], p.arrays["params"]]


def reference(img, to_world=ROTATION, scale=2.0):
    """float64 radiance and pdf of world directions, from Mitsuba's definitions (volcl.envmap)."""
    texels = envmap.texels_for(img, scale)
    to_local = np.linalg.inv(to_world[:3, :3])

    def local(d):
        return np.asarray(d, np.float64) @ to_local.T
    return (lambda d: envmap.radiance(texels, local(d))), (lambda d: envmap.pdf(texels, local(d)))


def pdf_rtol(img, dirs, to_world=ROTATION):
    """Per direction, how far the device's pdf may lie from the float64 reference: float32 arithmetic,
    and the rounding of the two float32 CDF steps that pick the patch (each entry within an ulp of 1,
    relative to the step's own probability; the device's pdf is the density of those steps)."""
    local = np.asarray(dirs, np.float64) @ np.linalg.inv(to_world[:3, :3]).T
    texels = envmap.texels_for(img)
    row, patch = envmap.patch_choice(texels, local)
    # float32 angles put the point up to ~1e-6 rad off: the bilinear density moves by its slope
    h, w = texels.shape[:2]
    f = envmap.nodes(texels).astype(np.float64)
    i, j, s, t = envmap._patches(envmap.direction_to_uv(local), w, h)
    a, b, c, d = f[j, i], f[j, i + 1], f[j + 1, i], f[j + 1, i + 1]
    bil = (1 - t) * ((1 - s) * a + s * b) + t * ((1 - s) * c + s * d)
    slope = np.abs((1 - t) * (b - a) + t * (d - c)) * w / (2 * np.pi) + np.abs((1 - s) * (c - a) + s * (d - b)) * (h - 1) / np.pi
    ulp = float(np.finfo(np.float32).eps)
    with np.errstate(divide="ignore", invalid="ignore"):
        return 1e-4 + 2 * ulp / row + 2 * ulp / patch + 1e-6 * slope / bil


def assert_pdf_close(device, expected, rtol, what):
    """The device pdf within rtol (per element) of the reference; zero only where the reference is."""
    device, expected = np.asarray(device, np.float64), np.asarray(expected, np.float64)
    err = np.abs(device - expected)
    bad = np.where(expected > 0, ~(err <= rtol * expected), device != 0)
    assert not bad.any(), (f"{what}: {bad.sum()} of {len(device)} pdfs off, e.g. device {device[bad][:4]} "
                           f"reference {expected[bad][:4]} (allowed relative error {rtol[bad][:4]})")


def unit_dirs(n, seed):
    d = np.random.default_rng(seed).normal(size=(n, 3))
    return (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)


@pytest.mark.parametrize("shape", [(6, 10), (5, 3)], ids=["6x10", "5x3 (not 2:1)"])
def test_envmap_sampling_matches_its_pdf(cl_env, prog, shape):
    img = map_image(*shape)
    radiance, pdf = reference(img)
    dirs, values, pdfs = run_kernel(cl_env, prog, "envmap_samples", N, [(f32, (3,)), (f32, (3,)), (f32, ())],
                                    i32(0), u32(21), inputs=buffers([env_emitter(img)]))
    assert (pdfs > 0).all(), f"{(pdfs <= 0).sum()} samples failed"
    np.testing.assert_allclose(np.linalg.norm(dirs.astype(np.float64), axis=1), 1.0, atol=1e-6)
    stats.chi2_directions(dirs, pdf, what=f"envmap_sample on a {shape[1]}x{shape[0]} map")
    # the density the sampler reports, and the value it carries, are the map's at that direction
    # (within the float32 rounding of the direction: a position error of ~1e-6 texels, times the
    # steepest step between texels, which is at most the brightest texel)
    sub = slice(0, 20000)
    peak = 2.0 * float(img.max())
    assert_pdf_close(pdfs[sub], pdf(dirs[sub]), pdf_rtol(img, dirs[sub]), "sampled pdfs")
    np.testing.assert_allclose(values[sub], radiance(dirs[sub]), rtol=2e-5, atol=1e-5 * peak)


def test_envmap_lookups_and_pdf_match_the_reference(cl_env, prog):
    img = map_image()
    radiance, pdf = reference(img)
    dirs = unit_dirs(50000, 4)
    values, pdfs = run_kernel(cl_env, prog, "env_emission", len(dirs), [(f32, (3,)), (f32, ())],
                              inputs=buffers([env_emitter(img)]) + [dirs])
    np.testing.assert_allclose(values, radiance(dirs), rtol=2e-5, atol=1e-5 * 2.0 * float(img.max()))
    assert_pdf_close(pdfs, pdf(dirs), pdf_rtol(img, dirs), "pdfs")


def test_envmap_pdf_integrates_to_one(cl_env, prog):
    img = map_image()
    _, pdf = reference(img)
    assert stats.integral_sphere(pdf, tol=1e-7) == pytest.approx(1.0, abs=1e-6)
    # the device's pdf on the quadrature rule of the reference
    dirs, weights = stats.sphere_rule(pdf, tol=1e-7)
    (_, pdfs) = run_kernel(cl_env, prog, "env_emission", len(dirs), [(f32, (3,)), (f32, ())],
                           inputs=buffers([env_emitter(img)]) + [dirs.astype(np.float32)])
    stats.assert_integrates_to_one(float(np.sum(weights * pdfs)), 1e-4, "envmap pdf on the device")


def test_light_sampling_includes_the_choice_of_the_envmap(cl_env, prog):
    """With a point light beside it, the map is picked half the time and its pdf halves; the point
    light's samples are delta (pdf = the choice probability)."""
    img = map_image()
    _, pdf = reference(img)
    point = Emitter("point", rgb(5.0), position=np.array([0.0, 3.0, 0.0]))
    dirs, values, pdfs, picked = run_kernel(cl_env, prog, "light_samples", 200000,
                                            [(f32, (3,)), (f32, (3,)), (f32, ()), (i32, ())],
                                            f32(0), f32(0), f32(0), u32(5),
                                            inputs=buffers([point, env_emitter(img)]))
    env = picked == 1
    stats.assert_probability(int(env.sum()), len(picked), 0.5, "envmap picked among two lights")
    assert_pdf_close(pdfs[env], 0.5 * pdf(dirs[env]), pdf_rtol(img, dirs[env]), "pdfs with two lights")
    assert np.all(pdfs[picked == 0] == np.float32(0.5))
    np.testing.assert_allclose(values[picked == 0], 5.0 / 9.0, rtol=1e-6)


def test_constant_envmap_is_constant_everywhere(cl_env, prog):
    """A map of one colour has exactly that radiance in every direction (and a density that varies
    only through the sin(theta) weights of its rows)."""
    img = np.full((4, 8, 3), [0.3, 0.5, 0.7], np.float32)
    dirs = unit_dirs(20000, 6)
    values, pdfs = run_kernel(cl_env, prog, "env_emission", len(dirs), [(f32, (3,)), (f32, ())],
                              inputs=buffers([env_emitter(img, scale=1.0)]) + [dirs])
    assert np.all(values == np.float32([0.3, 0.5, 0.7]))
    assert (pdfs > 0).all()


@pytest.mark.parametrize("a, b", [(0.2, 3.0), (0.0, 1.0), (5.0, 0.0), (1.0, 1.0), (1e30, 3e30)])
def test_sample_linear(cl_env, prog, a, b):
    (x,) = run_kernel(cl_env, prog, "linear_samples", 200000, [(f32, ())], f32(a), f32(b), u32(9))
    assert (x >= 0).all() and (x < 1).all()
    stats.chi2_1d(x, lambda t: 2 * ((1 - t) * a + t * b) / (a + b), 0.0, 1.0, what=f"sample_linear({a}, {b})")


def _spot(cutoff=30.0, beam=20.0, to_world=None):
    to_world = tf.translate([0.5, -0.2, 1.0]) @ ROTATION if to_world is None else to_world
    return Emitter("spot", rgb([2.0, 1.0, 0.5]), position=to_world[:3, 3], to_world=to_world, cutoff_angle=cutoff,
                   beam_width=beam)


def spot_falloff(e, w_world):
    """Mitsuba's falloff in float64: 1 within the beam, linear in angle to 0 at the cutoff."""
    local = np.asarray(w_world, np.float64) @ np.linalg.inv(e.to_world[:3, :3]).T
    cos_t = local[:, 2] / np.linalg.norm(local, axis=1)
    angle = np.degrees(np.arccos(np.clip(cos_t, -1, 1)))
    ramp = (e.cutoff_angle - angle) / (e.cutoff_angle - e.beam_width) if e.cutoff_angle != e.beam_width else 0
    return np.where(angle < e.cutoff_angle, np.where(angle <= e.beam_width, 1.0, ramp), 0.0)


@pytest.mark.parametrize("cutoff, beam", [(30.0, 20.0), (45.0, 45.0), (10.0, 25.0), (120.0, 60.0)])
def test_spot_falloff(cl_env, prog, cutoff, beam):
    e = _spot(cutoff, beam)
    axis = e.to_world[:3, 2] / np.linalg.norm(e.to_world[:3, 2])
    # directions around the axis, a good share of them inside the cone
    dirs = unit_dirs(20000, 8) + 1.5 * axis
    dirs = (dirs / np.linalg.norm(dirs, axis=1, keepdims=True)).astype(np.float32)
    (values,) = run_kernel(cl_env, prog, "point_intensity", len(dirs), [(f32, (3,))], i32(0),
                           inputs=[buffers([e])[0], dirs])
    expected = spot_falloff(e, dirs)[:, None] * np.array([2.0, 1.0, 0.5])
    # near the cutoff's edge float32 angles decide the side: keep a margin of 1e-4 degrees
    local = dirs.astype(np.float64) @ np.linalg.inv(e.to_world[:3, :3]).T
    angle = np.degrees(np.arccos(np.clip(local[:, 2] / np.linalg.norm(local, axis=1), -1, 1)))
    clear = np.abs(angle - cutoff) > 1e-4
    assert clear.sum() > 0.95 * len(dirs)
    np.testing.assert_allclose(values[clear], expected[clear], rtol=1e-4, atol=2e-5)
    assert (expected[:, 0] > 0).mean() > 0.02


# ---- against Mitsuba 3 itself (optional) ---------------------------------------------------------

def _write_exr(path, pixels):
    h, w, c = pixels.shape
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(w, h, c, oiio.FLOAT))
    out.write_image(np.ascontiguousarray(pixels, np.float32))
    out.close()


@pytest.fixture(scope="module")
def mitsuba_answers(tmp_path_factory):
    python = mitsuba_python()
    if python is None or subprocess.run([python, "-c", "import mitsuba"], capture_output=True).returncode != 0:
        pytest.skip("Mitsuba 3 not found (set VOLCL_MITSUBA_PYTHON to a Python that has it)")
    folder = tmp_path_factory.mktemp("mitsuba_queries")
    img = map_image(7, 12)
    _write_exr(folder / "map.exr", img)
    dirs = unit_dirs(4000, 11)
    spot = _spot()
    # receivers in front of the spot, inside and outside its cone and in the falloff between
    axis = spot.to_world[:3, 2] / np.linalg.norm(spot.to_world[:3, 2])
    points = spot.position + 2.0 * axis + np.random.default_rng(12).normal(size=(4000, 3)) * 0.8
    queries = {"variant": "llvm_ad_rgb",
               "envmap": {"filename": str(folder / "map.exr"), "scale": 2.0, "to_world": ROTATION.tolist(),
                          "dirs": dirs.tolist()},
               "spot": {"intensity": [2.0, 1.0, 0.5], "cutoff_angle": spot.cutoff_angle,
                        "beam_width": spot.beam_width, "to_world": spot.to_world.tolist(), "points": points.tolist()}}
    (folder / "queries.json").write_text(json.dumps(queries))
    proc = subprocess.run([python, str(HERE / "mitsuba_queries.py"), str(folder / "queries.json"),
                           str(folder / "answers.json")], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return img, dirs, spot, points, json.loads((folder / "answers.json").read_text())


def test_envmap_agrees_with_mitsuba(cl_env, prog, mitsuba_answers):
    """Orientation, texel placement, filtering, scale and pdf: Mitsuba's eval() and pdf_direction()."""
    img, dirs, _, _, answers = mitsuba_answers
    values, pdfs = run_kernel(cl_env, prog, "env_emission", len(dirs), [(f32, (3,)), (f32, ())],
                              inputs=buffers([env_emitter(img)]) + [dirs])
    mi_value = np.array(answers["envmap"]["value"]).T
    np.testing.assert_allclose(values, mi_value, rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(pdfs, np.array(answers["envmap"]["pdf"]), rtol=1e-3, atol=1e-6)


def test_spot_agrees_with_mitsuba(cl_env, prog, mitsuba_answers):
    _, _, spot, points, answers = mitsuba_answers
    v = spot.position - points
    d2 = (v ** 2).sum(1)
    w = (-v / np.sqrt(d2)[:, None]).astype(np.float32)
    (intensity,) = run_kernel(cl_env, prog, "point_intensity", len(w), [(f32, (3,))], i32(0),
                              inputs=[buffers([spot])[0], w])
    mi_value = np.array(answers["spot"]["value"]).T
    lit = mi_value[:, 0] > 0
    assert 0.05 < lit.mean() < 0.95
    # in the falloff's ramp a float32 angle (off by ~1e-7 rad in either renderer) moves the falloff
    # by that much times the ramp's slope, 1 / (cutoff - beam width) per radian
    slope = 1.0 / math.radians(spot.cutoff_angle - spot.beam_width)
    tol = 1e-4 * np.abs(mi_value) + 1e-6 * slope * np.array([2.0, 1.0, 0.5]) / d2[:, None]
    err = np.abs(intensity / d2[:, None] - mi_value)
    assert (err <= tol).all(), f"{(err > tol).sum()} values off, worst {err.max():.3g}"
