"""Heterogeneous (grid) media rendered: invariances with known answers, with tolerances from the
renders' own variance. Two renders compared with each other use different seeds, so that their
noise is independent."""
import numpy as np
import pytest

from imagestats import assert_images_match, assert_mean_matches
from scenebuild import (camera, constant_env, cube_to_world, furnace, grid, hetero_medium, look_at, medium,
                        scene, sphere)
from volcl.renderer import render
from volcl.scene import transform as tf
from volcl.scene.model import Bsdf, Emitter, rgb

pytestmark = pytest.mark.every_implementation

SIGMA = np.array([1.0, 2.0, 0.5])
ALBEDO = np.array([0.9, 0.7, 0.5])


def random_grid(shape, channels, seed, sparse=0.0):
    rng = np.random.default_rng(seed)
    data = rng.random(shape + (channels,)).astype(np.float32)
    if sparse:
        data *= rng.random(shape + (1,)) >= sparse
    return data


def lit_sphere_of(med, seed):
    """A null sphere holding `med`, lit by a constant environment and a point light."""
    ball = sphere((0, 0, 0), 1.0, Bsdf("null"), interior=med)
    lights = [constant_env(0.4), Emitter("point", rgb(6.0), position=np.array([2.0, 2.5, 1.5]))]
    cam = camera(12, 12, fov=45, to_world=look_at((0, 0, 3), (0, 0, 0)))
    return scene([ball], lights, cam=cam, seed=seed)


@pytest.mark.parametrize("filter", ["trilinear", "nearest"])
def test_constant_grid_renders_like_the_homogeneous_medium(device, filter):
    """A grid holding sigma_t / 2 everywhere with scale 2 (rotated, covering the sphere) is the
    homogeneous medium sigma_t: chromatic extinction, hg phase, NEE through the medium."""
    data = np.broadcast_to((SIGMA / 2).astype(np.float32), (2, 3, 2, 3))
    to_world = tf.rotate([1, 1, 0], 25) @ cube_to_world(-1.3, 1.3)
    hetero = hetero_medium(grid(data, to_world, filter), ALBEDO, g=0.5, scale=2.0)
    homo = medium(SIGMA, ALBEDO, g=0.5)
    a = render(lit_sphere_of(hetero, seed=1), spp=384, device=device)
    b = render(lit_sphere_of(homo, seed=2), spp=384, device=device)
    assert a.tracking_cutoffs == 0
    assert_images_match(a, b, blocks=2, what=f"constant {filter} grid vs homogeneous")


def test_majorants_scaled_by_four_leave_the_image_unchanged(device):
    """Looser majorants mean more null collisions, never a different expected image; and a single
    global majorant gives the same image as the majorant grid."""
    data = random_grid((10, 9, 8), 3, seed=4, sparse=0.6) * 4.0
    to_world = tf.rotate([0, 1, 1], 40) @ cube_to_world(-0.9, 0.9)
    med = hetero_medium(grid(data, to_world), ALBEDO, g=0.3)
    tight = render(lit_sphere_of(med, seed=3), spp=384, device=device)
    loose = render(lit_sphere_of(med, seed=4), spp=384, device=device, majorant_scale=4.0)
    assert tight.tracking_cutoffs == 0 and loose.tracking_cutoffs == 0
    assert_images_match(loose, tight, blocks=2, what="majorants x4")
    single = render(lit_sphere_of(med, seed=5), spp=384, device=device, majorant_cells=1)
    assert_images_match(single, tight, blocks=2, what="one global majorant")


@pytest.mark.parametrize("channels, g", [(1, 0.0), (3, 0.6)])
def test_furnace_with_albedo_one_grid_medium(device, channels, g):
    """An albedo-1 heterogeneous medium in a closed furnace (walls of albedo a emitting 1) changes
    nothing: L = 1 / (1 - a). The grid is rotated and sticks out of the box on two sides."""
    a = 0.5
    data = random_grid((7, 6, 5), channels, seed=8, sparse=0.3) * 3.0
    to_world = tf.rotate([1, 0, 1], 20) @ cube_to_world(-0.7, 1.3)
    med = hetero_medium(grid(data, to_world), 1.0, g=g)
    r = render(furnace(a, medium=med), spp=512, device=device)
    assert r.tracking_cutoffs == 0
    assert_mean_matches(r, 1 / (1 - a), what=f"grid medium furnace ({channels} channels, g={g})")


def test_emissive_grid_medium_with_albedo_grid_in_black_emitting_box(device):
    """Black walls emitting Le around a medium emitting sigma_a(x) Le: L = Le everywhere, with both
    the extinction and the albedo varying (their grids have different resolutions and frames)."""
    Le = 0.7
    sigma = random_grid((6, 5, 7), 3, seed=2) * 3.0
    albedo = random_grid((3, 4, 2), 3, seed=6) * 0.9
    med = hetero_medium(grid(sigma, cube_to_world(-1.1, 1.1)),
                        grid(albedo, tf.rotate([0, 0, 1], 30) @ cube_to_world(-0.8, 0.8), "nearest"),
                        g=0.3, radiance=Le)
    r = render(furnace(0.0, radiance=Le, medium=med), spp=512, device=device)
    assert r.tracking_cutoffs == 0
    assert_mean_matches(r, Le, what="emissive grid medium")


def test_tracking_step_bound_is_counted(device):
    """Majorants a hundred thousand times too large need more steps than the bound allows: each cut
    segment is counted (and ends its path), never silently dropped."""
    med = hetero_medium(grid(np.full((2, 2, 2), 2.0, np.float32), cube_to_world(-1, 1)), 1.0)
    sc = furnace(0.5, medium=med)
    sc.camera.width = sc.camera.height = 4
    r = render(sc, spp=2, device=device, majorant_scale=1e5)
    assert r.tracking_cutoffs > 0
    assert r.invalid == 0
