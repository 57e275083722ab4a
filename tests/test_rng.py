"""kernels/rng.h: rng_next_float is uniform on [0, 1) with 24-bit resolution, streams of neighbouring
pixels, sample indices and seeds are independent, and a stream depends only on (seed, pixel, sample)."""
import numpy as np
import pytest

import stats
from conftest import run_kernel

pytestmark = pytest.mark.every_implementation

u32, i32, f32 = np.uint32, np.int32, np.float32
SEED = 20240611


@pytest.fixture(scope="module")
def prog(test_program):
    return test_program("sampling_tests.cl")


def draws(cl_env, prog, items, count, seed=SEED, pixel0=0, sample0=0, npix=None):
    """(items, count): `count` consecutive floats of stream (seed, pixel0 + i % npix, sample0 + i / npix)."""
    npix = items if npix is None else npix
    (x,) = run_kernel(cl_env, prog, "rng_floats", items, [(f32, (count,))],
                      u32(seed), u32(pixel0), u32(sample0), i32(npix), i32(count))
    return x


def test_range_and_resolution(cl_env, prog):
    x = draws(cl_env, prog, 100_000, 10)
    assert x.min() >= 0.0 and x.max() < 1.0, f"outside [0, 1): min {x.min()}, max {x.max()}"
    k = x.astype(np.float64) * 2.0 ** 24
    assert np.all(k == np.floor(k)), "not a multiple of 2^-24"


def test_uniform_1d(cl_env, prog):
    x = draws(cl_env, prog, 100_000, 10).ravel()
    stats.chi2_1d(x, lambda t: np.ones_like(t), 0.0, 1.0, bins=101, what="rng_next_float")


def test_uniform_consecutive_pairs(cl_env, prog):
    """Pairs of consecutive draws of one stream are uniform on the unit square."""
    x = draws(cl_env, prog, 250_000, 4).reshape(-1, 2)
    stats.chi2_2d(x, lambda a, b: np.ones_like(a), (0.0, 1.0), (0.0, 1.0), res=(31, 31),
                  what="consecutive pairs of rng_next_float")


def standardized_products(a, b):
    """12 (a - 1/2)(b - 1/2): mean 0 and variance 1 for independent uniforms, so its mean is the
    correlation coefficient of a and b and its standard error is about 1/sqrt(n)."""
    return 12.0 * (a.astype(np.float64) - 0.5) * (b.astype(np.float64) - 0.5)


def test_adjacent_pixels_uncorrelated(cl_env, prog):
    n = 400_000
    x = draws(cl_env, prog, n, 4)                       # stream (seed, pixel i, sample 0)
    prods = np.stack([standardized_products(x[:-1, k], x[1:, k]) for k in range(4)]
                     + [standardized_products(x[:-1, 0], x[1:, 1])], axis=1)   # also across draw index
    stats.assert_mean(prods, 0.0, "correlation between streams of adjacent pixels",
                      ["draw 0", "draw 1", "draw 2", "draw 3", "draw 0 vs draw 1"])
    stats.chi2_2d(np.stack([x[:-1, 0], x[1:, 0]], 1), lambda a, b: np.ones_like(a), (0.0, 1.0), (0.0, 1.0),
                  res=(31, 31), what="first draws of adjacent pixels")


def test_adjacent_samples_uncorrelated(cl_env, prog):
    n = 400_000
    x = draws(cl_env, prog, n, 4, pixel0=12345, npix=1)    # stream (seed, pixel 12345, sample i)
    prods = np.stack([standardized_products(x[:-1, k], x[1:, k]) for k in range(4)], axis=1)
    stats.assert_mean(prods, 0.0, "correlation between streams of adjacent sample indices",
                      ["draw 0", "draw 1", "draw 2", "draw 3"])
    stats.chi2_2d(np.stack([x[:-1, 0], x[1:, 0]], 1), lambda a, b: np.ones_like(a), (0.0, 1.0), (0.0, 1.0),
                  res=(31, 31), what="first draws of adjacent sample indices")


def test_pixel_and_sample_index_do_not_alias(cl_env, prog):
    """(pixel p, sample s) and (pixel s, sample p) are different streams, and so are neighbouring seeds."""
    n = 400_000
    a = draws(cl_env, prog, n, 2, pixel0=0, sample0=7, npix=n)      # (p, 7)
    b = draws(cl_env, prog, n, 2, pixel0=7, sample0=0, npix=1)      # (7, p)
    c = draws(cl_env, prog, n, 2, seed=SEED + 1)                    # next seed, (p, 0)
    d = draws(cl_env, prog, n, 2)                                   # (p, 0)
    prods = np.stack([standardized_products(a[:, 0], b[:, 0]), standardized_products(c[:, 0], d[:, 0])], 1)
    stats.assert_mean(prods, 0.0, "correlation between swapped (pixel, sample) and adjacent seeds",
                      ["(p, 7) vs (7, p)", "seed vs seed + 1"])


def test_deterministic(cl_env, prog):
    x1 = draws(cl_env, prog, 50_000, 8)
    x2 = draws(cl_env, prog, 50_000, 8)
    assert np.array_equal(x1, x2), "the same launch gave different numbers"
    # a stream does not depend on the launch it is computed in
    part = draws(cl_env, prog, 1000, 8, pixel0=20_000, npix=1000)
    assert np.array_equal(part, x1[20_000:21_000])
    grid = draws(cl_env, prog, 300, 8, pixel0=5, sample0=3, npix=100)     # pixels 5..104, samples 3..5
    again = draws(cl_env, prog, 1, 8, pixel0=5 + 42, sample0=3 + 2, npix=1)
    assert np.array_equal(grid[2 * 100 + 42], again[0])
    other = draws(cl_env, prog, 50_000, 8, seed=SEED + 1)
    # another seed: equal values only by chance, 2^-24 per draw
    stats.assert_probability(np.count_nonzero(other == x1), x1.size, 2.0 ** -24, "equal draws under different seeds")
