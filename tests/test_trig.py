"""kernels/trig.h: the short polynomials the samplers use for azimuths and free flights, against float64."""
import numpy as np
import pytest

from conftest import run_kernel


@pytest.fixture(scope="module")
def prog(test_program):
    return test_program("trig_tests.cl")


def test_sin_and_cos_of_turns_are_within_two_ulps(cl_env, prog):
    """sincos_turn(u) for every u the random number generator makes in [0, 1) near the quarter
    turns (where the reduction switches quadrant) and a random sample of the rest. The error is
    measured against the exact sin and cos of the float32 argument 2 pi u would round to, in units
    of the result's last place, or of pi's near a zero of the result (one ulp of the angle)."""
    rng = np.random.default_rng(3)
    k = np.concatenate([np.arange(0, 64), 2 ** 24 - np.arange(1, 64),
                        *[q * 2 ** 22 + np.arange(-64, 64) for q in (1, 2, 3)],
                        rng.integers(0, 2 ** 24, 200_000)])
    u = (k * 2.0 ** -24).astype(np.float32)
    s, c = run_kernel(cl_env, prog, "trig_turn", len(u), [(np.float32, ())] * 2, inputs=[u])
    a = 2.0 * np.pi * u.astype(np.float64)
    floor = np.spacing(np.float32(np.pi)).astype(np.float64)
    for got, want in ((s, np.sin(a)), (c, np.cos(a))):
        ulp = np.maximum(np.spacing(np.abs(want).astype(np.float32)).astype(np.float64), floor)
        err = np.abs(got.astype(np.float64) - want) / ulp
        assert err.max() <= 2.0, (err.max(), u[np.argmax(err)])
    assert np.all(np.abs(s) <= 1.0) and np.all(np.abs(c) <= 1.0)


def test_sin_and_cos_of_turns_past_one_turn(cl_env, prog):
    """The environment map's azimuths reach 1 + 1/(2 W) turns: from 1 to 1.125 (every float32 there
    near 1, a random sample of the rest) the reduction is still exact and the error within 2 ulps."""
    rng = np.random.default_rng(4)
    u = np.concatenate([np.float32(1.0) + np.arange(0, 4096, dtype=np.float32) * np.spacing(np.float32(1.0)),
                        rng.uniform(1.0, 1.125, 100_000).astype(np.float32)]).astype(np.float32)
    s, c = run_kernel(cl_env, prog, "trig_turn", len(u), [(np.float32, ())] * 2, inputs=[u])
    a = 2.0 * np.pi * u.astype(np.float64)
    floor = np.spacing(np.float32(np.pi)).astype(np.float64)
    for got, want in ((s, np.sin(a)), (c, np.cos(a))):
        ulp = np.maximum(np.spacing(np.abs(want).astype(np.float32)).astype(np.float64), floor)
        assert (np.abs(got.astype(np.float64) - want) / ulp).max() <= 2.0


def test_atan2_on_the_whole_plane_is_within_three_ulps(cl_env, prog):
    """atan2_full (the environment map's azimuth) in all four quadrants, ratios from 1e-6 to 1e6,
    on the axes (signed zeros: the library's answers but for (+-0, -x), which gives +pi for both)
    and at the origin (0, as the library gives for (+0, +0)). Three ulps of the result, half what
    OpenCL allows its atan2: the polynomial's worst seen over 2^20 such points is 2.05, just below
    the result's binade at 1/2 (numpy's float32 arctan2 reaches 2.99 on the same points)."""
    rng = np.random.default_rng(6)
    n = 1 << 16
    r = 10.0 ** rng.uniform(-6, 6, n)
    x = (np.where(rng.random(n) < 0.5, -1.0, 1.0) * rng.uniform(0.1, 10.0, n))
    y = np.where(rng.random(n) < 0.5, -1.0, 1.0) * np.abs(x) * r
    axes = np.array([(0.0, 1.0), (0.0, -1.0), (1.0, 0.0), (-1.0, 0.0), (-0.0, 1.0), (2.0, -0.0)])
    y = np.concatenate([axes[:, 0], y]).astype(np.float32)
    x = np.concatenate([axes[:, 1], x]).astype(np.float32)
    (got,) = run_kernel(cl_env, prog, "trig_atan2_full", len(x), [(np.float32, ())], inputs=[y, x])
    want = np.arctan2(y.astype(np.float64), x.astype(np.float64))
    ulp = np.spacing(np.maximum(np.abs(want).astype(np.float32), np.finfo(np.float32).tiny)).astype(np.float64)
    assert (np.abs(got - want) / ulp).max() <= 3.0
    (origin,) = run_kernel(cl_env, prog, "trig_atan2_full", 1, [(np.float32, ())],
                           inputs=[np.float32([0.0]), np.float32([0.0])])
    assert origin[0] == 0.0


def test_log_of_one_minus_a_variate_is_within_one_ulp(cl_env, prog):
    """log_pos(1 - u), the free flights' optical depth, for every u = k 2^-24 the random number
    generator makes (all 2^24 of them: 1 - u is exact), and for normal numbers across the whole
    float range, against float64 in units of the result's last place; log_pos(1) is exactly 0."""
    x = (1.0 - np.arange(0, 2 ** 24) * 2.0 ** -24).astype(np.float32)
    rng = np.random.default_rng(5)
    wide = (2.0 ** rng.uniform(-125, 127, 100_000)).astype(np.float32)
    for inputs in (x, wide):
        (got,) = run_kernel(cl_env, prog, "trig_log", len(inputs), [(np.float32, ())], inputs=[inputs])
        want = np.log(inputs.astype(np.float64))
        ulp = np.spacing(np.maximum(np.abs(want), np.finfo(np.float32).tiny).astype(np.float32)).astype(np.float64)
        err = np.abs(got.astype(np.float64) - want) / ulp
        assert err.max() <= 1.0, (err.max(), inputs[np.argmax(err)])
    (one,) = run_kernel(cl_env, prog, "trig_log", 1, [(np.float32, ())], inputs=[np.float32([1.0])])
    assert one[0] == 0.0
