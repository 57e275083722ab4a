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
