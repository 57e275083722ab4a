"""Grid volumes on the device: lookups with Mitsuba 3's voxel-centre convention, majorants that bound
every lookup, and the tracking routines (ratio-tracking transmittance on shadow rays, delta-tracking
free flights) against optical depths integrated exactly for a density ramp."""
import math

import numpy as np
import pytest

from conftest import run_kernel
from imagestats import z_limit
from scenebuild import camera, grid, hetero_medium, scene
from volcl import grids
from volcl.pack import pack
from volcl.renderer import Renderer
from volcl.scene import transform as tf

pytestmark = pytest.mark.every_implementation

PROGRAM = "grid_tests.cl"


def upload_lookup(volume):
    packer = grids.GridPacker()
    packer.add(volume)
    return packer.arrays()


@pytest.mark.parametrize("filter", ["trilinear", "nearest"])
@pytest.mark.parametrize("channels", [1, 3])
def test_lookup_matches_reference(cl_env, test_program, filter, channels):
    rng = np.random.default_rng(3)
    data = rng.random((5, 4, 6, channels), dtype=np.float32)
    desc, flat = upload_lookup(grid(data, filter=filter))
    res = np.array([6, 4, 5])
    pts = np.concatenate([
        rng.uniform(-0.3, 1.3, (4000, 3)),                                  # inside and outside
        (rng.integers(0, 6, (500, 3)) % res + 0.5) / res,                  # voxel centres
        rng.integers(0, 13, (500, 3)) / 12.0,                               # faces and cell edges
    ]).astype(np.float32)
    (out,) = run_kernel(cl_env, test_program(PROGRAM), "lookups", len(pts), [(np.float32, (3,))], np.int32(0),
                        inputs=[desc, flat, pts])
    ref = grids.lookup(data, filter, pts)
    ref = np.repeat(ref, 3, axis=1) if channels == 1 else ref
    assert np.allclose(out, ref, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("filter, expected", [
    ("trilinear", [1.0, 1.0, 1.0, 1.0, 1.3, 2.0, 2.5, 3.0, 4.0, 4.0, 4.0, 4.0]),
    ("nearest", [1.0, 1.0, 1.0, 1.0, 1.0, 2.0, 3.0, 3.0, 4.0, 4.0, 4.0, 4.0]),
])
def test_lookup_convention_is_mitsubas(cl_env, test_program, filter, expected):
    """A row of 4 voxels [1 2 3 4] evaluated where Mitsuba 3.9.1's gridvolume was evaluated (its
    printed values): centres at (i + 0.5) / 4, clamp to the edge voxels outside them."""
    xs = [-0.1, 0.0, 0.05, 0.125, 0.2, 0.375, 0.5, 0.625, 0.875, 0.95, 1.0, 1.1]
    desc, flat = upload_lookup(grid(np.array([1, 2, 3, 4], np.float32).reshape(1, 1, 4), filter=filter))
    pts = np.array([[x, 0.5, 0.5] for x in xs], np.float32)
    (out,) = run_kernel(cl_env, test_program(PROGRAM), "lookups", len(pts), [(np.float32, (3,))], np.int32(0),
                        inputs=[desc, flat, pts])
    assert np.allclose(out[:, 0], expected, atol=1e-6)


@pytest.mark.parametrize("filter", ["trilinear", "nearest"])
@pytest.mark.parametrize("cells", [None, 3])
def test_majorants_bound_every_lookup(filter, cells):
    rng = np.random.default_rng(11)
    data = (rng.random((9, 7, 11, 3)) * (rng.random((9, 7, 11, 1)) < 0.3)).astype(np.float32)
    data[:, :, :5] = 0.0                                  # an empty slab: its cells must be free
    res = data.shape[2::-1]
    mres = np.array(grids.majorant_resolution(res, cells))
    maj = grids.majorant_grid(data, filter, mres)
    assert maj.shape == tuple(mres[::-1])
    # random points, and points on cell boundaries, which the walk may put in either neighbour
    pts = np.concatenate([rng.random((50000, 3)),
                          rng.integers(0, 2 * mres.max() + 1, (20000, 3)) / (2 * mres)]).clip(0, 1)
    value = grids.lookup(data, filter, pts).max(axis=1)
    g = pts * mres
    for shift in (0.0, -1e-6, 1e-6):
        c = np.clip(np.floor(g + shift), 0, mres - 1).astype(int)
        assert (value <= maj[c[:, 2], c[:, 1], c[:, 0]]).all()
    if cells is None:
        assert (maj[:, :, 0] == 0).all(), "cells whose support is empty must have majorant 0"
    # and it is tight: no cell's majorant exceeds the largest voxel value in the grid
    assert maj.max() <= data.max() * (1 + 2 * grids.MAJORANT_MARGIN)


# --- tracking against a density ramp -------------------------------------------------------------

RAMP_RES = 8
SCALE = 1.5
# to_world of the grid: a 2 x 1.5 x 1 box, rotated and moved; along local x one world unit is 1/2
TO_WORLD = tf.translate([0.3, -0.2, 0.5]) @ tf.rotate([0, 0, 1], 30) @ np.diag([2.0, 1.5, 1.0, 1.0])
X_PER_WORLD = 0.5
# (local x at the start, direction along local x, world length): outside to outside, outside to
# inside, inside to inside, an unbounded ray, backwards, and inside the clamped edge region
RAYS = [(-0.5, 1, 4.0), (-0.2, 1, 1.0), (0.3, 1, 0.8), (1.3, -1, math.inf), (0.9, -1, 1.2), (0.02, 1, 0.1)]


def ramp_data(channels):
    """Values depending on x only: channel 0 rises from 0.2 to 3.0; with 3 channels, channel 1 is
    zero and channel 2 falls."""
    i = np.arange(RAMP_RES, dtype=np.float64)
    cols = [0.2 + 0.4 * i] if channels == 1 else [0.2 + 0.4 * i, 0 * i, 1.6 - 0.2 * i]
    row = np.stack(cols, axis=-1)                                       # (x, c)
    return np.broadcast_to(row, (3, 2, RAMP_RES, channels)).astype(np.float32)


def optical_depth(data, filter, x0, x1):
    """Exact integral of scale * sigma over local x in [x0, x1] (zero outside the unit cube), per
    channel, in world length: the lookup is piecewise linear (trilinear) or piecewise constant
    (nearest) between known breakpoints, so the trapezoid or midpoint rule per piece is exact."""
    lo, hi = max(min(x0, x1), 0.0), min(max(x0, x1), 1.0)
    if hi <= lo:
        return np.zeros(data.shape[-1])
    n = data.shape[2]
    breaks = np.arange(n + 1) / n if filter == "nearest" else (np.arange(n) + 0.5) / n
    xs = np.unique(np.r_[lo, hi, breaks[(breaks > lo) & (breaks < hi)]])
    a, b = xs[:-1], xs[1:]

    def f(x):
        return grids.lookup(data, filter, np.stack([x, np.full_like(x, 0.5), np.full_like(x, 0.5)], 1))
    if filter == "nearest":
        integral = (f(0.5 * (a + b)) * (b - a)[:, None]).sum(0)
    else:
        integral = (0.5 * (f(a) + f(b)) * (b - a)[:, None]).sum(0)
    return SCALE * integral / X_PER_WORLD


def ray_arrays():
    out = []
    for x0, sign, length in RAYS:
        o = tf.apply_point(TO_WORLD, [x0, 0.3, 0.6])
        d = tf.apply_vector(TO_WORLD, [sign, 0.0, 0.0])
        out.append(np.r_[o, d / np.linalg.norm(d), length])
    return np.array(out, np.float32)


def local_end(x0, sign, length):
    return x0 + sign * min(length, 10.0) * X_PER_WORLD


def tracking_setup(channels, filter, majorant_scale, albedo=1.0):
    data = ramp_data(channels)
    med = hetero_medium(grid(data, TO_WORLD, filter), albedo, scale=SCALE)
    packed = pack(scene(cam=camera(medium=med)), majorant_scale=majorant_scale)
    buffers = [packed.arrays[name] for name in Renderer.ARG_ORDER]
    return data, buffers


def sample_count(n_per_ray):
    return len(RAYS) * n_per_ray


@pytest.mark.parametrize("majorant_scale", [1.0, 4.0])
@pytest.mark.parametrize("filter", ["trilinear", "nearest"])
@pytest.mark.parametrize("channels", [1, 3])
def test_ratio_tracking_transmittance_is_exp_of_optical_depth(cl_env, test_program, channels, filter,
                                                              majorant_scale):
    data, buffers = tracking_setup(channels, filter, majorant_scale)
    per_ray = 20000
    n = sample_count(per_ray)
    tr, cut = run_kernel(cl_env, test_program(PROGRAM), "shadow_rays", n, [(np.float32, (3,)), (np.uint32, ())],
                         np.int32(len(RAYS)), np.int32(0), np.uint32(5), inputs=buffers + [ray_arrays()])
    assert cut.sum() == 0
    tr = tr.reshape(per_ray, len(RAYS), 3).astype(np.float64)
    limit = z_limit(len(RAYS) * 3)
    for k, (x0, sign, length) in enumerate(RAYS):
        tau = optical_depth(data, filter, x0, local_end(x0, sign, length))
        expected = np.exp(-np.broadcast_to(tau, 3) if channels == 1 else -tau)
        mean = tr[:, k].mean(0)
        se = tr[:, k].std(0, ddof=1) / math.sqrt(per_ray)
        for c in range(3):
            if se[c] == 0:      # a channel the ray never sees any density in: exactly 1
                assert mean[c] == pytest.approx(expected[c], abs=1e-6), (k, c)
            else:
                z = (mean[c] - expected[c]) / se[c]
                assert abs(z) < limit, f"ray {k} channel {c}: T {mean[c]:.5f}, exp(-tau) {expected[c]:.5f}, z {z:.2f}"


@pytest.mark.parametrize("majorant_scale", [1.0, 4.0])
@pytest.mark.parametrize("channels", [1, 3])
def test_delta_tracking_free_flights_follow_the_optical_depth(cl_env, test_program, channels, majorant_scale):
    """With albedo 1, the weighted probability of a collision before distance s is 1 - exp(-tau(s))
    in every channel, and of none on the whole segment exp(-tau)."""
    filter = "trilinear"
    data, buffers = tracking_setup(channels, filter, majorant_scale)
    per_ray = 20000
    n = sample_count(per_ray)
    out, cut = run_kernel(cl_env, test_program(PROGRAM), "free_flights", n, [(np.float32, (5,)), (np.uint32, ())],
                          np.int32(len(RAYS)), np.int32(0), np.uint32(9), inputs=buffers + [ray_arrays()])
    assert cut.sum() == 0
    out = out.reshape(per_ray, len(RAYS), 5).astype(np.float64)
    fractions = (0.25, 0.5, 0.75)
    limit = z_limit(len(RAYS) * 3 * (len(fractions) + 1))
    failures = []
    for k, (x0, sign, length) in enumerate(RAYS):
        t, scattered, w = out[:, k, 0], out[:, k, 1] > 0, out[:, k, 2:]
        span = min(length, 10.0)
        checks = [(np.where((scattered & (t <= f * span))[:, None], w, 0.0),
                   1 - np.exp(-optical_depth(data, filter, x0, x0 + sign * f * span * X_PER_WORLD)))
                  for f in fractions]
        checks.append((np.where(~scattered[:, None], w, 0.0),
                       np.exp(-optical_depth(data, filter, x0, local_end(x0, sign, length)))))
        for j, (samples, expected) in enumerate(checks):
            expected = np.broadcast_to(expected, 3)
            mean = samples.mean(0)
            se = samples.std(0, ddof=1) / math.sqrt(per_ray)
            for c in range(3):
                ok = (abs(mean[c] - expected[c]) < 1e-6 if se[c] == 0
                      else abs(mean[c] - expected[c]) < limit * se[c])
                if not ok:
                    failures.append(f"ray {k} check {j} channel {c}: {mean[c]:.5f} vs {expected[c]:.5f} "
                                    f"(se {se[c]:.5f})")
    assert not failures, "; ".join(failures[:6])
