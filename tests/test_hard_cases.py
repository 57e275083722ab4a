"""The numerical hard cases of ../shared/docs/volumetrics.md, rendered on the device: each image is
compared with an analytic answer within its own standard error, and none may hold an invalid
(NaN, infinite or negative) sample (imagestats.assert_mean_matches checks both).

The kernel code that keeps each case stable carries a comment naming the hazard at the place it
is handled (kernels/common.h offset_origin / offset_back, kernels/media.h, kernels/phase.h,
kernels/integrator.h camera_start_medium, kernels/surface.h, kernels/lights.h).
"""
import math
import time
from pathlib import Path

import numpy as np
import pytest

from imagestats import assert_mean_matches, assert_same_image
from scenebuild import (box_mesh, camera, constant_env, diffuse, furnace, look_at, medium, quad_mesh, scene,
                        sphere)
from volcl.pack import camera_tangents
from volcl.renderer import render
from volcl.scene import load
from volcl.scene.model import Bsdf, Emitter, Shape, rgb

pytestmark = pytest.mark.every_implementation

SCENES = sorted((Path(__file__).resolve().parent.parent / "scenes").glob("*.xml"))


# -- helpers: the camera's rays in numpy, and analytic answers ----------------------------------

def pixel_directions(cam, sub_x=8, sub_y=8):
    """Unit directions (h, sub_y, w, sub_x, 3) through a grid of points in every pixel: the box
    filter's footprint, for averaging an analytic answer over each pixel."""
    tx, ty = camera_tangents(cam)
    px = ((np.arange(cam.width)[:, None] + (np.arange(sub_x) + 0.5)[None] / sub_x) / cam.width).reshape(-1)
    py = ((np.arange(cam.height)[:, None] + (np.arange(sub_y) + 0.5)[None] / sub_y) / cam.height).reshape(-1)
    x, y = np.meshgrid((1 - 2 * px) * tx, (1 - 2 * py) * ty)
    d = np.stack([x, y, np.ones_like(x)], -1) @ cam.to_world[:3, :3].T
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    return d.reshape(cam.height, sub_y, cam.width, sub_x, 3)


def pixel_mean(values):
    """Average of per-subsample values (h, sub_y, w, sub_x) per pixel, as rgb (h, w, 3)."""
    return np.repeat(values.mean(axis=(1, 3))[..., None], 3, -1)


def box_chord(o, d, lo, hi):
    """Length of the rays o + t d (t > 0) inside the box [lo, hi]."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        t0, t1 = (lo - o) / d, (hi - o) / d
    near = np.nan_to_num(np.minimum(t0, t1), nan=-np.inf).max(-1)
    far = np.nan_to_num(np.maximum(t0, t1), nan=np.inf).min(-1)
    return np.maximum(far - np.maximum(near, 0.0), 0.0)


def chandrasekhar_h(c, mu, n=64, iterations=2000):
    """Chandrasekhar's H-function for isotropic scattering with albedo c < 1, at the cosines mu:
    H(mu) = 1 / (1 - c/2 mu int_0^1 H(mu') / (mu + mu') dmu'), iterated on Gauss-Legendre nodes."""
    x, w = np.polynomial.legendre.leggauss(n)
    nodes, weights = 0.5 * (x + 1), 0.5 * w
    h = np.ones(n)
    for _ in range(iterations):
        h = 1 / (1 - 0.5 * c * nodes * (weights * h / (nodes[:, None] + nodes[None, :])).sum(1))
    # the known moment int_0^1 H = 2 (1 - sqrt(1 - c)) / c checks the solution
    assert abs((weights * h).sum() - 2 * (1 - math.sqrt(1 - c)) / c) < 1e-9
    mu = np.asarray(mu, float)
    return 1 / (1 - 0.5 * c * mu * (weights * h / (mu[..., None] + nodes)).sum(-1))


def null_box(lo, hi, interior=None, exterior=None, bsdf=None):
    """A closed box [lo, hi] with outward normals."""
    v, f = box_mesh(1.0, inward=False)
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    v = lo + (v + 1) / 2 * (hi - lo)
    return Shape("mesh", bsdf or Bsdf("null"), vertices=v, faces=f, interior=interior, exterior=exterior)


def emitter_quad(center, u, v, radiance):
    qv, qf = quad_mesh(center, u, v)
    return Shape("mesh", diffuse(0.0), vertices=qv, faces=qf, emitter_radiance=rgb(radiance))


# -- Henyey-Greenstein near |g| = 1 and g = 0 ----------------------------------------------------

@pytest.mark.parametrize("g", [0.999, -0.999, 1e-6, -1e-6])
def test_hg_extreme_g_leaves_albedo_one_furnace_unchanged(device, g):
    """phase.h: no clamp of g; the pdf stays finite as |g| -> 1 and sampling is exact at g -> 0.
    A medium of albedo 1 in a furnace of wall albedo a: L = 1 / (1 - a) whatever g is."""
    a = 0.5
    r = render(furnace(a, medium=medium(2.0, 1.0, g=g)), spp=256, device=device)
    assert_mean_matches(r, 1 / (1 - a), what=f"furnace with HG g={g}")


# -- sigma_t = 0 on some or all channels --------------------------------------------------------

WALL_DISTANCE = 1.5


def _camera_in_medium(fog, forward):
    """A narrow camera inside `fog` at the origin looking along -z (at the wall) or +z (at the sky)."""
    target = (0, 0, -1) if forward else (0, 0, 1)
    return camera(4, 4, fov=2, to_world=look_at((0, 0, 0), target), medium=fog)


@pytest.mark.parametrize("sigma", [[0.0, 1.0, 2.0], [0.0, 0.0, 0.0]], ids=["one-channel", "all-channels"])
def test_zero_extinction_camera_in_absorbing_medium(device, sigma):
    """media.h: exp(-sigma t) is 1 for sigma = 0 even on infinite segments (0 * INF = NaN guarded).
    Looking at an emitter at distance d: Le exp(-sigma d); looking at the sky through an unbounded
    medium: the environment where sigma = 0, nothing elsewhere."""
    sigma = np.array(sigma)
    fog = medium(sigma, 0.0)
    wall = emitter_quad((0, 0, -WALL_DISTANCE), (10, 0, 0), (0, 10, 0), 2.0)    # faces the camera
    cam = _camera_in_medium(fog, forward=True)
    d = pixel_directions(cam)
    dist = WALL_DISTANCE / -d[..., 2]
    expected = 2.0 * np.exp(-sigma * dist.mean(axis=(1, 3))[..., None])
    r = render(scene([wall], [constant_env(1.0)], cam=cam), spp=512, device=device)
    assert_mean_matches(r, expected, blocks=2, what="emitter through absorbing medium")
    r = render(scene([wall], [constant_env(1.0)], cam=_camera_in_medium(fog, forward=False)), spp=64,
               device=device)
    assert_mean_matches(r, np.where(sigma == 0, 1.0, 0.0), blocks=2, what="sky through unbounded medium")


def test_zero_extinction_channel_in_scattering_sphere(device):
    """Chromatic one-sample MIS with a channel that never scatters: an albedo-1 sphere in a constant
    environment of radiance 1 renders 1 in every channel (the sigma = 0 channel passes straight)."""
    fog = medium([0.0, 2.0, 6.0], 1.0, g=0.5)
    shapes = [sphere((0, 0, 0), 1.0, Bsdf("null"), interior=fog)]
    cam = camera(8, 8, fov=45, to_world=look_at((0, 0, 2.5), (0, 0, 0)))
    r = render(scene(shapes, [constant_env(1.0)], cam=cam), spp=256, device=device)
    assert_mean_matches(r, 1.0, what="sphere with a zero-extinction channel")


# -- very large optical depth ------------------------------------------------------------------

@pytest.mark.parametrize("sigma", [1e6, [1e6, 2e6, 4e6]], ids=["grey", "chromatic"])
def test_thick_absorbing_slab_hides_an_emitter(device, sigma):
    """exp(-tau) underflows to exactly 0 past tau ~ 104: the slab between camera and emitter
    renders exactly 0, with no 0/0 from transmittance over pdf."""
    slab = null_box((-5, -5, -0.5), (5, 5, 0.5), interior=medium(sigma, 0.0))
    wall = emitter_quad((0, 0, -2), (10, 0, 0), (0, 10, 0), 2.0)
    cam = camera(8, 8, fov=30, to_world=look_at((0, 0, 3), (0, 0, -1)))
    r = render(scene([wall, slab], cam=cam), spp=128, device=device)
    assert_mean_matches(r, 0.0, what="thick absorbing slab")
    assert np.all(r.image == 0)


@pytest.mark.parametrize("sigma, size", [(1.0, 400.0), (1e6, 0.02)], ids=["sigma1", "sigma1e6"])
def test_thick_half_space_reflects_chandrasekhar_albedo(device, sigma, size):
    """An optically thick slab of isotropic albedo c under a sky of radiance 1 (index-matched null
    boundary) seen at cosine mu: L = R(mu) = 1 - sqrt(1 - c) H(mu), Chandrasekhar's half-space
    albedo. The slab's optical depth is 2e4 in both cases. At sigma_t = 1e6 the ray offset at the
    boundary once skipped ten mean free paths (kernels/common.h offset_back)."""
    c = 0.9
    slab = null_box((-size, -size / 2, -size), (size, 0, size), interior=medium(sigma, c))
    cam = camera(4, 4, fov=2, to_world=look_at((0, 0.01 * size, 0.01 * size), (0, 0, 0)))
    cam.near_clip = 1e-4 * size
    r = render(scene([slab], [constant_env(1.0)], cam=cam), spp=2048, device=device)
    mu = -pixel_directions(cam, 4, 4)[..., 1]
    expected = pixel_mean(1 - math.sqrt(1 - c) * chandrasekhar_h(c, mu))
    assert_mean_matches(r, expected, blocks=1, what=f"half-space albedo, sigma_t={sigma}")


def test_albedo_one_medium_of_sigma_1e6_in_a_micro_furnace(device):
    """sigma_t = 1e6 and albedo 1 in a furnace 2e-6 across (optical size 2, so light gets out):
    L = 1 / (1 - a), as in the unit furnace; offsets and tiny distances keep to the scale."""
    a = 0.5
    v, f = box_mesh(1e-6, inward=True)
    walls = Shape("mesh", diffuse(a), vertices=v, faces=f, emitter_radiance=rgb(1.0))
    cam = camera(8, 8, fov=90, medium=medium(1e6, 1.0, g=0.5))
    cam.near_clip = 1e-9
    r = render(scene([walls], cam=cam), spp=512, device=device)
    assert_mean_matches(r, 1 / (1 - a), what="micro furnace")


def test_thick_albedo_one_medium_ends_in_bounded_time(device):
    """A furnace filled with an albedo-1 medium of sigma_t = 1e6: paths never reach a wall (that
    takes ~1e12 scattering events), so only Russian roulette (survival capped at 0.95) and the step
    bound end them. The render must stay fast and valid. (The furnace's 1 / (1 - a) is out of reach
    for any unbiased path tracer here; the sigma_t = 2 furnace in test_render_media.py checks it.)"""
    fog = medium(1e6, 1.0, g=0.5)
    start = time.perf_counter()
    r = render(furnace(0.5, medium=fog), spp=256, device=device)
    seconds = time.perf_counter() - start
    assert r.invalid == 0 and np.isfinite(r.image).all()
    assert seconds < 20, f"albedo-1 thick furnace took {seconds:.1f} s for {8 * 8 * 256} paths"


# -- very thin media -----------------------------------------------------------------------------

def test_thin_slab_transmittance(device):
    """sigma_t = 1e-8 over unit thickness: T = exp(-1e-8 / mu), which is 1 in float32."""
    slab = null_box((-5, -5, -0.5), (5, 5, 0.5), interior=medium(1e-8, 0.5))
    wall = emitter_quad((0, 0, -2), (10, 0, 0), (0, 10, 0), 2.0)
    cam = camera(4, 4, fov=20, to_world=look_at((0, 0, 3), (0, 0, -1)))
    r = render(scene([wall, slab], cam=cam), spp=64, device=device)
    assert_mean_matches(r, 2.0, what="thin slab transmittance")


def test_thin_medium_single_scattering_matches_slab_formula(device):
    """sigma_t = 1e-8 over a slab 2e6 thick (tau = 0.02), lit by a directional light of irradiance
    E at cosine mu0 and seen at mu from the lit side, single scattering only (max_depth 2):
    L = E albedo p(theta) mu0 / (mu0 + mu) (1 - exp(-tau (1/mu0 + 1/mu)))."""
    sigma, thickness, albedo, g, E = 1e-8, 2e6, 0.8, 0.4, 3.0
    slab = null_box((-1e9, -thickness, -1e9), (1e9, 0, 1e9), interior=medium(sigma, albedo, g=g))
    light_dir = np.array([0.0, -1.0, 1.0]) / math.sqrt(2)       # the direction light travels
    sun = Emitter("directional", rgb(E), direction=light_dir)
    cam = camera(4, 4, fov=10, to_world=look_at((0, 1e6, 2e6), (0, 0, 0)))
    cam.far_clip = 1e8
    r = render(scene([slab], [sun], cam=cam, max_depth=2), spp=4096, device=device)
    d = pixel_directions(cam)
    mu0, mu = -light_dir[1], -d[..., 1]
    cos_theta = (light_dir * -d).sum(-1)       # light's travel direction before and after (towards the camera)
    phase = (1 - g * g) / (4 * math.pi * (1 + g * g - 2 * g * cos_theta) ** 1.5)
    tau = sigma * thickness
    L = E * albedo * phase * mu0 / (mu0 + mu) * -np.expm1(-tau * (1 / mu0 + 1 / mu))
    assert_mean_matches(r, pixel_mean(L), blocks=2, what="thin slab single scattering")


# -- albedo exactly 0 and exactly 1 --------------------------------------------------------------

def test_albedo_zero_emissive_medium_is_in_equilibrium(device):
    """Albedo 0: every collision ends the path (its weight is exactly 0). A medium emitting
    sigma_a Le between black walls emitting Le: L = Le everywhere."""
    Le = 0.7
    fog = medium([1.0, 3.0, 0.5], 0.0, radiance=Le)
    r = render(furnace(0.0, radiance=Le, medium=fog), spp=256, device=device)
    assert_mean_matches(r, Le, what="albedo-0 emissive medium")


def test_albedo_one_ends_in_bounded_time(device):
    """Albedo 1: the throughput never drops, so Russian roulette ends paths only through its capped
    survival (0.95). A camera inside an unbounded albedo-1 medium under a sky: no path ever leaves,
    the image is exactly 0 (the sky is behind infinite optical depth), and every path ends soon."""
    cam = camera(8, 8, fov=60, medium=medium([0.5, 1.0, 2.0], 1.0, g=0.7))
    start = time.perf_counter()
    r = render(scene([], [constant_env(1.0)], cam=cam), spp=1024, device=device)
    seconds = time.perf_counter() - start
    assert_mean_matches(r, 0.0, what="unbounded albedo-1 medium")
    assert seconds < 20, f"{8 * 8 * 1024} paths in an albedo-1 medium took {seconds:.1f} s"


# -- scale invariance ----------------------------------------------------------------------------

def _scaled_scene(s, seed):
    """Fog in a null box, a glass sphere of chromatic medium in it, an area light and a sky; every
    length times s and every coefficient divided by s."""
    fog = medium(2.0 / s, 0.8, g=0.5)
    core = medium(np.array([3.0, 1.0, 0.5]) / s, [0.9, 0.5, 1.0], g=-0.3)
    box = null_box((-s, -s, -s), (s, s, s), interior=fog)
    ball = sphere((0.3 * s, 0, 0), 0.5 * s, Bsdf("dielectric", int_ior=1.33, ext_ior=1.0), interior=core,
                  exterior=fog)
    light = emitter_quad((0, 1.5 * s, 0), (0.5 * s, 0, 0), (0, 0, -0.5 * s), 5.0)   # faces -y
    cam = camera(12, 12, fov=45, to_world=look_at((0, 0.5 * s, 3.5 * s), (0, 0, 0)))
    cam.near_clip, cam.far_clip = 1e-2 * s, 1e4 * s
    return scene([box, ball, light], [constant_env(0.3)], cam=cam, seed=seed)


@pytest.fixture(scope="module")
def unit_scale_render(device):
    return render(_scaled_scene(1.0, seed=1), spp=512, device=device)


@pytest.mark.parametrize("s", [1e-4, 1e4])
def test_scaled_scene_renders_the_same_image(device, unit_scale_render, s):
    """kernels/common.h offset_origin: ray offsets relative to the geometry's own coordinates. With
    an absolute floor, at 1e-4 scale every boundary crossing skipped a tenth of the medium."""
    r = render(_scaled_scene(s, seed=2), spp=512, device=device)
    assert_same_image(unit_scale_render, r, what=f"scene scaled by {s:g}")


@pytest.mark.parametrize("s", [1e-6, 1e-4, 1.0, 1e4])
def test_scaled_absorbing_box_transmittance(device, s):
    """An absorbing box of optical thickness 2 seen face-on at any scale: T = exp(-2)."""
    box = null_box((-s, -s, -s), (s, s, s), interior=medium(1.0 / s, 0.0))
    cam = camera(4, 4, fov=1, to_world=look_at((0, 0, 3 * s), (0, 0, 0)))
    cam.near_clip, cam.far_clip = 1e-2 * s, 1e4 * s
    r = render(scene([box], [constant_env(1.0)], cam=cam), spp=1024, device=device)
    d = pixel_directions(cam)
    chord = box_chord(np.array([0, 0, 3.0]), d, (-1, -1, -1), (1, 1, 1))
    assert_mean_matches(r, pixel_mean(np.exp(-chord)), blocks=1, what=f"absorbing box at scale {s:g}")


# -- geometry at its edges -----------------------------------------------------------------------

@pytest.mark.parametrize("height", [0.0, 0.02], ids=["in-plane", "above"])
def test_grazing_camera_rays_on_a_medium_boundary(device, height):
    """A camera level with (or just above) the top face of an absorbing slab looks along it: rays
    graze the boundary, enter at glancing angles or pass just above it. Per pixel, the transmittance
    along each ray's chord through the slab, averaged over the pixel."""
    lo, hi = np.array([-2.0, -1.0, -2.0]), np.array([2.0, 0.0, 2.0])
    slab = null_box(lo, hi, interior=medium(1.0, 0.0))
    origin = np.array([0.0, height, 3.0])
    cam = camera(8, 8, fov=8, to_world=look_at(origin, origin + (0, 0, -1)))
    r = render(scene([slab], [constant_env(1.0)], cam=cam), spp=1024, device=device)
    d = pixel_directions(cam, 16, 64)
    expected = pixel_mean(np.exp(-box_chord(origin, d, lo, hi)))
    assert_mean_matches(r, expected, blocks=2, what=f"grazing rays, camera at height {height}")


def test_camera_on_a_null_sphere_surface(device):
    """A pinhole exactly on a boundary (kernels/integrator.h camera_start_medium): rays into the
    sphere cross it at t = 0, which no intersection test reports; they must still enter. An
    absorbing sphere in a sky of radiance 1, camera on its surface looking along the tangent plane:
    inward rays see exp(-sigma chord) with chord = -2 (o - c) . d, outward rays see the sky."""
    sigma = 1.5
    ball = sphere((0, 0, 0), 1.0, Bsdf("null"), interior=medium(sigma, 0.0))
    origin = np.array([0.0, 0.0, 1.0])
    for target in [(1, 0.5, 0.5), (0, 0, 0)]:
        cam = camera(8, 8, fov=90, to_world=look_at(origin, target))
        r = render(scene([ball], [constant_env(1.0)], cam=cam), spp=256, device=device)
        d = pixel_directions(cam)
        chord = np.maximum(-2 * d[..., 2], 0.0)
        assert_mean_matches(r, pixel_mean(np.exp(-sigma * chord)), blocks=2, what=f"camera on sphere, facing {target}")


def test_camera_just_outside_a_medium_within_the_near_clip(device):
    """The near clip plane lies inside the medium while the pinhole is outside it: rays start in the
    medium they crossed into before the clip plane."""
    sigma = 1.0
    box = null_box((-1, -1, -1), (1, 1, 1), interior=medium(sigma, 0.0))
    origin = np.array([0.0, 0.0, 1.005])
    cam = camera(4, 4, fov=20, to_world=look_at(origin, (0, 0, 0)))
    cam.near_clip = 0.01
    r = render(scene([box], [constant_env(1.0)], cam=cam), spp=256, device=device)
    d = pixel_directions(cam)
    chord = box_chord(origin, d, (-1, -1, -1), (1, 1, 1))
    assert_mean_matches(r, pixel_mean(np.exp(-sigma * chord)), blocks=1, what="near clip inside the medium")


@pytest.mark.parametrize("kind", ["perspective", "thinlens"])
def test_the_camera_walk_is_skipped_only_where_it_would_find_nothing(device, monkeypatch, kind):
    """camera_start_medium's walk to the near clip plane (a BVH query per camera ray) is skipped
    where no surface's bounds reach the stretch of the camera rays it covers (RenderParams.camera_walk):
    a camera at a distance gets the bits of the walked render; one whose near clip reaches a boundary
    (as in the tests above) keeps the walk."""
    import volcl.pack as vpack
    box = null_box((-1, -1, -1), (1, 1, 1), interior=medium([0.5, 1.0, 2.0], 0.7, g=0.3))

    def render_from(z, walk=None):
        cam = camera(12, 8, fov=40, to_world=look_at((0.3, 0.2, z), (0, 0, 0)))
        cam.near_clip = 0.05
        if kind == "thinlens":
            cam.kind, cam.aperture_radius, cam.focus_distance = "thinlens", 0.2, 2.5
        with monkeypatch.context() as m:
            if walk is not None:
                m.setattr(vpack.Packer, "_camera_walk", lambda self, radius: walk)
            sc = scene([box], [constant_env(1.0)], cam=cam)
            return vpack.Packer(sc).pack().params["camera_walk"], render(sc, spp=16, seed=5, device=device)

    for z in (4.0, 0.5):                # at a distance; inside the box, far from its faces
        flag, skipped = render_from(z)
        assert flag == 0, z
        _, walked = render_from(z, walk=True)
        assert skipped.image.tobytes() == walked.image.tobytes(), z
    assert render_from(1.03)[0] == 1 and render_from(0.97)[0] == 1      # the near clip reaches the face


def test_the_camera_walk_near_a_sphere(device, monkeypatch):
    """Inside a null sphere of fog, away from its surface: skipped, the walked bits; with the near
    clip reaching the surface from inside or outside: kept."""
    import volcl.pack as vpack
    ball = sphere((0, 0, 0), 1.0, Bsdf("null"), interior=medium([0.5, 1.0, 2.0], 0.7, g=0.3))

    def render_from(z, walk=None):
        cam = camera(12, 8, fov=60, to_world=look_at((0.1, 0.0, z), (0, 0, -2)))
        cam.near_clip = 0.05
        with monkeypatch.context() as m:
            if walk is not None:
                m.setattr(vpack.Packer, "_camera_walk", lambda self, radius: walk)
            sc = scene([ball], [constant_env(1.0)], cam=cam)
            return vpack.Packer(sc).pack().params["camera_walk"], render(sc, spp=16, seed=5, device=device)

    flag, skipped = render_from(0.3)
    assert flag == 0
    assert skipped.image.tobytes() == render_from(0.3, walk=True)[1].image.tobytes()
    assert render_from(0.97)[0] == 1 and render_from(1.02)[0] == 1


def test_coincident_faces_between_two_media(device):
    """Two closed boxes sharing a face, each filled with its own albedo-1 medium, inside a furnace
    of wall albedo a: which of the two coincident faces a ray finds first is up to rounding, but
    the image stays finite and at 1 / (1 - a)."""
    a = 0.5
    left = null_box((-0.8, -0.5, -0.5), (0, 0.5, 0.5), interior=medium(2.0, 1.0, g=0.6))
    right = null_box((0, -0.5, -0.5), (0.8, 0.5, 0.5), interior=medium([1.0, 4.0, 8.0], 1.0, g=-0.4))
    fv, ff = box_mesh(2.0, inward=True)
    walls = Shape("mesh", diffuse(a), vertices=fv, faces=ff, emitter_radiance=rgb(1.0))
    cam = camera(8, 8, fov=70, to_world=look_at((0, 0.3, 1.8), (0, 0, 0)))
    r = render(scene([walls, left, right], cam=cam), spp=512, device=device)
    assert_mean_matches(r, 1 / (1 - a), what="coincident faces")


def _with_degenerate_triangles(v, f):
    """The mesh plus triangles with a repeated index, collinear corners, a triangle of one point
    and a sliver whose corners collapse to one point in float32."""
    n = len(v)
    extra = np.array([[0.3, 0.2, 2.0], [-0.5, -2.0, 0.1], [0.0, -2.0, 0.1], [0.5, -2.0, 0.1],
                      [2.0, 0.1, 0.1], [2.0, 0.1 + 1e-9, 0.1 + 1e-9], [2.0, 0.1 + 2e-9, 0.1]])
    faces = np.array([[0, 0, 1], [n, n, 2], [n + 1, n + 2, n + 3], [n, n, n], [n + 4, n + 5, n + 6]])
    return np.vstack([v, extra]), np.vstack([f[:5], faces, f[5:]])


@pytest.mark.parametrize("with_medium", [False, True], ids=["vacuum", "medium"])
def test_degenerate_triangles_in_an_emitting_furnace(device, with_medium):
    """Zero-area triangles in an emitter and its walls are never hit and never sampled: the furnace
    still renders 1 / (1 - a)."""
    a = 0.5
    v, f = _with_degenerate_triangles(*box_mesh(2.0, inward=True))
    walls = Shape("mesh", diffuse(a), vertices=v, faces=f, emitter_radiance=rgb(1.0))
    fog = medium(1.0, 1.0, g=0.3) if with_medium else None
    r = render(scene([walls], cam=camera(8, 8, fov=90, medium=fog)), spp=256, device=device)
    assert_mean_matches(r, 1 / (1 - a), what="furnace with degenerate triangles")


def test_degenerate_triangles_in_a_medium_boundary(device):
    """A closed null box with degenerate triangles holding an albedo-1 medium in a sky: 1."""
    v, f = _with_degenerate_triangles(*box_mesh(2.0, inward=False))
    box = Shape("mesh", Bsdf("null"), vertices=v * 0.5, faces=f, interior=medium(2.0, 1.0, g=0.5))
    cam = camera(8, 8, fov=45, to_world=look_at((0, 0.5, 3), (0, 0, 0)))
    r = render(scene([box], [constant_env(1.0)], cam=cam), spp=256, device=device)
    assert_mean_matches(r, 1.0, what="degenerate boundary")


def test_light_inside_a_medium_object_in_equilibrium(device):
    """A black sphere emitting 1 inside a null box of albedo-1 medium, under a sky of radiance 1:
    everything is in equilibrium at radiance 1 (light sampled inside the medium, through its
    boundary, and hit by phase sampling)."""
    box = null_box((-1, -1, -1), (1, 1, 1), interior=medium([1.0, 2.0, 0.5], 1.0, g=0.4))
    lamp = sphere((0.2, 0, 0), 0.3, diffuse(0.0), emitter_radiance=rgb(1.0))
    cam = camera(8, 8, fov=50, to_world=look_at((0, 0.5, 3), (0, 0, 0)))
    r = render(scene([box, lamp], [constant_env(1.0)], cam=cam), spp=256, device=device)
    assert_mean_matches(r, 1.0, what="light inside a medium")


def test_emitter_inside_an_absorbing_medium_object(device):
    """An emitting quad inside an absorbing box, seen face-on from outside: L = Le exp(-sigma d),
    d the distance from the box's face to the quad."""
    sigma, Le = 0.8, 3.0
    box = null_box((-1, -1, -1), (1, 1, 1), interior=medium(sigma, 0.0))
    lamp = emitter_quad((0, 0, -0.25), (2, 0, 0), (0, 2, 0), Le)   # faces +z, 1.25 behind the front face
    origin = np.array([0.0, 0.0, 3.0])
    cam = camera(4, 4, fov=10, to_world=look_at(origin, (0, 0, 0)))
    r = render(scene([box, lamp], cam=cam), spp=256, device=device)
    d = pixel_directions(cam)
    inside = (1.0 + 0.25) / -d[..., 2]
    assert_mean_matches(r, pixel_mean(Le * np.exp(-sigma * inside)), blocks=1, what="emitter in absorbing box")


# -- every shipped scene -------------------------------------------------------------------------

@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
def test_shipped_scene_has_no_invalid_samples(device, path):
    sc = load(path)
    sc.camera.width, sc.camera.height = 32, 24
    r = render(sc, spp=32, device=device)
    assert r.invalid == 0, f"{path.name}: {r.invalid} invalid samples"
    assert np.isfinite(r.image).all() and np.isfinite(r.variance).all()
    assert r.image.mean() > 0, f"{path.name} rendered black"


def test_invalid_samples_are_counted_and_left_out(device):
    """Walls emitting near the float32 maximum: path sums overflow to infinity. Such samples are
    counted per pixel on the device (RenderResult.invalid) and kept out of the image's sums."""
    r = render(furnace(0.9, radiance=3e38), spp=16, device=device)
    assert 0 < r.invalid <= 8 * 8 * 16
    assert np.isfinite(r.image).all() and np.isfinite(r.variance).all()
