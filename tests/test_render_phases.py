"""Every phase function in the path tracer: albedo-1 furnaces stay at 1 / (1 - a) (homogeneous and
grid media), single scattering from a point light matches quadrature of the phase function's
float64 value (next-event estimation and equiangular sampling use the value), and Fournier-Forand
rendered from a deliberately coarse sampling table (4 knots: value / pdf from 0.3 to 1.4) gives the same
image as from the fine one: the throughput carries value / pdf and every MIS weight the sampler's
pdf, or the two would differ."""
import numpy as np
import pytest

from imagestats import assert_mean_matches, assert_same_image
from scenebuild import camera, constant_env, furnace, hetero_medium, look_at, medium, quad_mesh, scene, sphere
from test_equiangular import _fog_scene, _light_pixel_mask, _single_scattering
from volcl import phase as ph
from volcl.estimator import Estimator
from volcl.features import detect
from volcl.renderer import render
from volcl.scene.model import Bsdf, Phase, Shape, rgb

PETZOLD = ph.fournier_forand_from_backscatter(0.0183)      # n = 1.10, mu = 3.5835
NESTED = Phase("blend", weight=0.3, phases=(
    Phase("hg", 0.8), Phase("blend", weight=0.6, phases=(Phase("rayleigh"), Phase("hg", -0.5)))))
PHASES = {
    "rayleigh": Phase("rayleigh"),
    "draine": Phase("draine", 0.6, alpha=37.0),
    "cornette-shanks": Phase("cornette_shanks", -0.7),
    "tabphase": Phase("tabulated", values=np.array([3.0, 1.0, 0.5, 0.2, 1.0, 6.0])),
    "nested blend": NESTED,
    "fournier-forand": Phase("fournier_forand", n=PETZOLD.n, mu=PETZOLD.mu),
    "fournier-forand mu 3.01": Phase("fournier_forand", n=1.01, mu=3.01),
    "fournier-forand coarse table": Phase("fournier_forand", n=PETZOLD.n, mu=PETZOLD.mu, tolerance=10.0),
    "mie 0.05 um": Phase("mie", diameter=0.05),
    "mie 20 um": Phase("mie", diameter=20.0),
}


def with_phase(med, phase):
    med.phase = phase
    return med


@pytest.mark.parametrize("name", list(PHASES))
def test_furnace_with_albedo_one_medium(device, name):
    a = 0.5
    r = render(furnace(a, medium=with_phase(medium(2.0, 1.0), PHASES[name])), spp=512, device=device)
    assert r.features["PHASE_FAMILIES"]
    assert_mean_matches(r, 1 / (1 - a), what=f"medium furnace, {name}")


@pytest.mark.parametrize("name", ["fournier-forand coarse table", "mie 20 um", "nested blend"])
def test_furnace_with_albedo_one_grid_medium(device, name):
    a = 0.5
    data = np.random.default_rng(7).random((6, 5, 4, 1)).astype(np.float32) * 4
    from scenebuild import cube_to_world, grid
    med = with_phase(hetero_medium(grid(data, cube_to_world(-1.5, 1.5)), 1.0), PHASES[name])
    r = render(furnace(a, medium=med), spp=512, device=device)
    assert r.features["GRID_MEDIA"] and r.features["PHASE_FAMILIES"]
    assert_mean_matches(r, 1 / (1 - a), what=f"grid medium furnace, {name}")


@pytest.mark.parametrize("name", ["rayleigh", "draine", "tabphase", "nested blend", "fournier-forand",
                                  "fournier-forand coarse table", "mie 20 um"])
def test_single_scattering_from_a_point_light_matches_quadrature(device, name):
    """Camera and point light in an infinite medium, max_depth 2 (test_equiangular.py): the light
    scattered once, by quadrature of the float64 phase function along each ray."""
    sc = _fog_scene(phase=PHASES[name])
    assert detect(sc)["EQUIANGULAR"]
    expected = _single_scattering(sc)
    r = render(sc, spp=256, device=device, seed=3)
    assert_mean_matches(r, np.repeat(expected[..., None], 3, -1), mask=_light_pixel_mask(sc),
                        what=f"single scattering, {name}")


def _lamp_behind_fog(phase, seed, half):
    """A null sphere of medium before a square area lamp of half-size `half` (hidden from the camera),
    single scattering only (max_depth 2): the lamp's light scattered towards the camera at small
    angles."""
    v, f = quad_mesh((0, 0.8, -2.6), (half, 0, 0), (0, half, 0))        # faces the camera (+z)
    lamp = Shape("mesh", Bsdf("diffuse", reflectance=rgb(0.0)), vertices=v, faces=f,
                 emitter_radiance=rgb(1.5 / (half * half)))
    fog = with_phase(medium([1.5, 1.0, 0.6], [0.95, 0.9, 0.8]), phase)
    ball = sphere((0, 0, 0), 1.0, Bsdf("null"), interior=fog)
    cam = camera(12, 12, fov=50, to_world=look_at((0, 0, 2.6), (0, 0, 0)))
    return scene([ball, lamp], cam=cam, seed=seed, max_depth=2, hide_emitters=True)


COARSE = PHASES["fournier-forand coarse table"]


def test_the_coarse_table_is_coarse():
    t = ph.fournier_forand_table(PETZOLD, COARSE.tolerance)
    assert t["ratio_error"] > 0.5 and len(t["x"]) <= 5


def test_fournier_forand_coarse_table_weighted_by_value_over_pdf(device):
    """The coarse table's pdf is 0.7 to 3 times the value. With light sampling off the image comes
    from phase-sampled hits of the lamp alone, weighted by value / pdf: it must be the image the
    fine table gives with light sampling and MIS."""
    fine = render(_lamp_behind_fog(PHASES["fournier-forand"], 1, half=0.6), spp=512, device=device)
    no_nee = render(_lamp_behind_fog(COARSE, 2, half=0.6), spp=2048, device=device,
                    estimator=Estimator(nee=False))
    assert fine.image.mean() > 0.02
    assert_same_image(fine, no_nee, blocks=3, what="FF, fine table with NEE and coarse table without")


def test_fournier_forand_coarse_table_in_mis_weights(device):
    """Light sampling and MIS on, a lamp where its pdf and the phase pdf at 10 to 30 degrees are of
    the same order: the weights of both techniques must use the same pdf, the sampler's. (With the
    value in the light-sampling weight instead, this image comes out 3% dark: 7 standard errors.)"""
    fine = render(_lamp_behind_fog(PHASES["fournier-forand"], 3, half=0.8), spp=16384, device=device)
    coarse = render(_lamp_behind_fog(COARSE, 4, half=0.8), spp=16384, device=device)
    assert fine.image.mean() > 0.02
    assert_same_image(fine, coarse, blocks=1, what="FF, fine and coarse tables, NEE and MIS")


def test_equiangular_with_a_tabulated_sampler(device):
    """A point light in a Fournier-Forand medium (coarse table), multiple scattering: the same
    image with equiangular sampling and without."""
    sc = _fog_scene(phase=PHASES["fournier-forand coarse table"], max_depth=4, width=12, height=12)
    on = render(sc, spp=512, device=device, seed=8)
    off = render(sc, spp=1024, device=device, seed=9, estimator=Estimator(equiangular="off"))
    assert on.features["EQUIANGULAR"] and not off.features["EQUIANGULAR"]
    assert_same_image(on, off, blocks=3, what="FF point light, equiangular on / off")
