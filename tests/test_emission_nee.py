"""Next-event estimation towards emissive media (kernels/emission_nee.h, volcl/emission_sampler.py):
the point sampler against its target density (chi-square over cells and within them, and the
density it reports against the one looked up at the point), and renders of a small emitting medium in
a dark room (dense grid, sparse grid, homogeneous) with it on and off: the same image, and less
per-pixel variance with it on at the same sample count."""
import math

import numpy as np
import pytest

from conftest import run_kernel
from imagestats import assert_same_image, z_limit
from scenebuild import box_mesh, camera, diffuse, grid, hetero_medium, medium, scene
from stats import assert_chi_square
from volcl import vdb
from volcl.estimator import Estimator
from volcl.pack import pack
from volcl.renderer import Renderer, render
from volcl.scene import transform as tf
from volcl.scene.model import Bsdf, Shape

pytestmark = pytest.mark.every_implementation

N = 12          # the flame's voxels per axis
HALF = 0.3      # the flame's box: [-HALF, HALF]^3 around FLAME_AT
FLAME_AT = np.array([0.0, -0.4, 0.3])


def flame_fields():
    """Density and temperature of a small ball of fire, hot at its centre, smoke around it."""
    x = (np.arange(N) + 0.5) / N * 2 - 1
    r = np.sqrt(x[:, None, None] ** 2 + x[None, :, None] ** 2 + x[None, None, :] ** 2)
    density = np.clip(1.2 - r, 0, None).astype(np.float32) * 6
    temperature = np.clip(5000 * (1 - 1.4 * r), 0, None).astype(np.float32)
    return density, temperature


def flame_medium(layout):
    to_world = tf.translate(FLAME_AT - HALF) @ tf.scale([2 * HALF] * 3)
    if layout == "homogeneous":
        return medium(3.0, 0.4, radiance=[4.0, 1.5, 0.3])
    density, temperature = flame_fields()
    if layout == "dense":
        sigma_t, temp = grid(density, to_world), grid(temperature, to_world)
    else:
        from volcl.scene.model import Volume, rgb
        vols = []
        for name, values in (("density", density), ("temperature", temperature)):
            sg = vdb.from_dense(values, ijk=(0, 0, 0))
            m = to_world @ np.diag([1.0 / N, 1.0 / N, 1.0 / N, 1.0])
            vols.append(Volume("sparse", value=rgb(0.0), to_world=m @ sg.unit_to_world(), sparse=sg,
                               grid_name=name))
        sigma_t, temp = vols
    med = hetero_medium(sigma_t, 0.4)
    med.emission_kind, med.emission_volume = "temperature", temp
    med.emission_scale = 4.0
    return med


def flame_room(layout, width=16, seed=3):
    """A closed grey room (half-size 1) lit only by the flame, a null box around it."""
    v, f = box_mesh(inward=True)
    room = Shape("mesh", diffuse(0.6), vertices=v, faces=f)
    bv, bf = box_mesh(HALF, inward=False)
    holder = Shape("mesh", Bsdf("null"), vertices=bv + FLAME_AT, faces=bf, interior=flame_medium(layout))
    cam = camera(width, width, fov=70, to_world=tf.translate([0.0, 0.2, -0.9]))
    return scene([room, holder], cam=cam, seed=seed)


LAYOUTS = ["dense", "sparse", "homogeneous"]


def _needs(layout):
    if layout == "sparse" and not vdb.available()[0]:
        pytest.skip(f"OpenVDB's Python module is not available: {vdb.available()[1]}")


@pytest.mark.parametrize("layout", LAYOUTS)
def test_point_sampler_follows_its_target_density(cl_env, test_program, layout):
    """Cells drawn as often as their bound says (the target computed here from the majorants and
    the fields, not from the sampler's own tables), points uniform within each cell (octants), and
    the density returned with a point equal to the one looked up at it."""
    _needs(layout)
    sc = flame_room(layout)
    packed = pack(sc)
    assert packed.params["emission_table"] >= 0
    buffers = [packed.arrays[name] for name in Renderer.ARG_ORDER]
    n = 200_000
    out, ids = run_kernel(cl_env, test_program("grid_tests.cl"), "emission_points", n,
                          [(np.float32, (5,)), (np.int32, (2,))], np.uint32(17), inputs=buffers)
    assert (ids[:, 0] >= 0).all(), "a draw landed on no emission"
    med = packed.arrays["media"][ids[0, 0]]
    block = packed.arrays["grid_data"][med["emission_sampler"]:]
    res = block[4:7].view(np.int32)
    cells = int(np.prod(res))
    target = _target_weights(sc, packed, layout)
    assert target.size == cells
    p = target / target.sum()
    drawn = np.bincount(ids[:, 1], minlength=cells)
    assert drawn[p == 0].sum() == 0, "a cell without emission was drawn"
    keep = p > 0
    assert_chi_square(drawn[keep], n * p[keep], f"cells ({layout})")
    # within the cells: the octant of each point in its cell's local frame
    to_local = np.r_[block[19:31].reshape(3, 4), [[0, 0, 0, 1]]]
    pl = (to_local @ np.c_[out[:, :3], np.ones(n)].T).T[:, :3] * res
    frac = pl - np.floor(pl)
    octant = ((frac >= 0.5) * [1, 2, 4]).sum(1)
    assert_chi_square(np.bincount(octant, minlength=8), np.full(8, n / 8), f"points in cells ({layout})")
    volume = abs(np.linalg.det(np.linalg.inv(to_local)[:3, :3])) / cells
    # the sampler's probabilities are the widths of its float32 CDF's intervals: within an ulp of 1
    np.testing.assert_allclose(out[:, 3], p[ids[:, 1]] / volume, rtol=1e-5, atol=2 * 2.0 ** -24 / volume)
    np.testing.assert_allclose(out[:, 4], out[:, 3], rtol=1e-5)


def _target_weights(sc, packed, layout):
    """The sampler's target, from the scene: homogeneous, one cell; grids, per voxel cell its
    centre's sigma_a Le plus BOUND_SHARE of its bound: the largest density a lookup in it reads
    times max(1 - albedo) times the largest blackbody colour any temperature up to the cell's
    largest one can give."""
    from volcl import blackbody, grids as g
    if layout == "homogeneous":
        return np.ones(1)
    med = sc.shapes[1].interior
    density, temperature = flame_fields()
    # the flame's two grids share a frame and a resolution, so their majorant cells coincide
    # grids are sampled by voxel (a sparse one this small over its padded box)
    if layout == "sparse":
        density, temperature = med.sigma_t.sparse.dense()[..., 0], med.emission_volume.sparse.dense()[..., 0]
    res = density.shape[::-1]
    maj = g.majorant_grid(density[..., None], "trilinear", res).reshape(-1).astype(np.float64)
    t_max = g.majorant_grid(temperature[..., None], "trilinear", res).reshape(-1)
    # the cells are the voxels: each centre's own emission plus a share of the bound
    centre = (density.reshape(-1).astype(np.float64) * 0.6 * med.emission_scale
              * blackbody.table_lookup(temperature.reshape(-1).astype(np.float64)).max(-1))
    t = np.geomspace(blackbody.T_CUTOFF, blackbody.T_MAX, blackbody.TABLE_SIZE)
    prefix = np.maximum.accumulate(blackbody.table().max(1))
    le = np.array([prefix[min(np.searchsorted(t, x * (1 - 1e-6)), len(t) - 1)] if x > blackbody.T_CUTOFF else 0.0
                   for x in t_max])
    from volcl.emission_sampler import BOUND_SHARE
    return centre + BOUND_SHARE * maj * 0.6 * le * med.emission_scale


def _pair(layout, device, spp, seed_on, seed_off):
    sc_on, sc_off = flame_room(layout, seed=seed_on), flame_room(layout, seed=seed_off)
    on = render(sc_on, spp=spp, device=device)
    off = render(sc_off, spp=spp, device=device, estimator=Estimator(emission_nee=False))
    assert on.features["EMISSION_NEE"] and not off.features["EMISSION_NEE"]
    return on, off


@pytest.mark.parametrize("layout", LAYOUTS)
def test_emission_nee_leaves_the_image_unchanged(device, layout):
    _needs(layout)
    on, off = _pair(layout, device, 128, 3, 4)
    assert on.tracking_cutoffs == 0 and off.tracking_cutoffs == 0
    assert on.image.mean() > 1e-3, "the room is lit"
    assert_same_image(on, off, blocks=2, what=f"emission NEE on vs off ({layout})")


@pytest.mark.parametrize("layout", LAYOUTS)
def test_emission_nee_lowers_the_variance(device, layout):
    """Summed per-pixel sample variance over the walls (the flame's own pixels excluded), from the
    same number of samples, in B independent pairs of renders: the mean of log(V_off / V_on) over
    the pairs is above log(2) by more than z standard errors of that mean (a one-sided test at the
    suite's per-test level)."""
    _needs(layout)
    batches = 4
    ratios = []
    for b in range(batches):
        on, off = _pair(layout, device, 256, 10 + 2 * b, 11 + 2 * b)
        walls = off.image.mean(-1) < np.quantile(off.image.mean(-1), 0.9)
        ratios.append(math.log(off.variance[walls].sum() / on.variance[walls].sum()))
    ratios = np.array(ratios)
    se = ratios.std(ddof=1) / math.sqrt(batches)
    lower = ratios.mean() - z_limit(1) * se
    assert lower > math.log(2.0), (f"{layout}: variance ratio off/on {math.exp(ratios.mean()):.2f} "
                                   f"(lower bound {math.exp(lower):.2f}; pairs {np.exp(ratios).round(2)})")
