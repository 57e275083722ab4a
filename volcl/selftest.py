"""A device's self-test: small renders with known answers, run before volcl trusts a device.

A driver can build volcl's kernels and still compute wrong images (Intel's CPU runtime once
returned another work item's float3 lanes from calls it did not inline). Two tiny scenes,
rendered with the feature sets real scenes specialize to, catch that kind of failure:

  wall     a diffuse wall lit by a point light through a purely absorbing, chromatic medium: every
           pixel's mean is exp(-sigma (d_cam + r)) (R / pi) I cos / r^2, integrated here over the
           pixel by quadrature; rendered twice with the same seed, which must give the same bits;
  furnace  an albedo-1, chromatic, anisotropic medium in a closed box whose walls emit 1 and
           reflect a: L = 1 / (1 - a) everywhere;
  bare     the wall without the medium, on CPUs, where "auto" renders such a scene with the packet
           renderer (volcl.packets): (R / pi) I cos / r^2.

Each image's mean per channel, and over 2x2 blocks, must lie within Z_LIMIT standard errors of
its answer (the renders' own variance estimates) with no invalid samples. Seeds are fixed, so
a device passes or fails the same way every time; the limit is wide enough that a correct
device fails by chance with a probability below 1e-7, far narrower than the errors a
miscompiled kernel makes.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from . import packets
from .scene.model import Bsdf, Camera, Emitter, Filter, Integrator, Medium, Phase, Scene, Shape, rgb

Z_LIMIT = 6.0
SIZE = 8
SPP = 64


@dataclass
class SelfTest:
    ok: bool
    message: str        # what failed, or a summary of what passed
    seconds: float


def _scene(shapes, emitters, medium, fov, max_depth, seed=3) -> Scene:
    cam = Camera(to_world=np.eye(4), fov=fov, width=SIZE, height=SIZE, rfilter=Filter("box", 0.5, 0.5),
                 medium=medium)
    sc = Scene(path="<self-test>", dialect="mitsuba", camera=cam, seed=seed, shapes=shapes,
               emitters=emitters, media=[medium] if medium is not None else [])
    sc.integrator = Integrator("volpathmis", max_depth=max_depth)
    return sc


# the wall scene: camera at the origin looking down +z at the wall z = WALL_Z
WALL_Z, WALL_R, LIGHT_I = 2.0, 0.8, 5.0
LIGHT_P = np.array([0.3, -0.2, 1.0])
SIGMA = np.array([0.2, 0.5, 1.2])
WALL_FOV = 20.0


def wall_scene(absorbing: bool = True) -> Scene:
    fog = Medium("homogeneous", sigma_t=SIGMA.copy(), albedo=rgb(0.0)) if absorbing else None
    s = 5.0
    verts = np.array([[-s, -s, WALL_Z], [s, -s, WALL_Z], [s, s, WALL_Z], [-s, s, WALL_Z]])
    wall = Shape("mesh", Bsdf("diffuse", reflectance=rgb(WALL_R), twosided=True), vertices=verts,
                 faces=np.array([[0, 1, 2], [0, 2, 3]]))
    light = Emitter("point", rgb(LIGHT_I), position=LIGHT_P.copy())
    return _scene([wall], [light], fog, WALL_FOV, max_depth=2)


def wall_expected(sc: Scene, sub: int = 8, sigma=SIGMA) -> np.ndarray:
    """Each pixel's mean radiance (box filter): the midpoint rule on sub x sub points per pixel."""
    cam = sc.camera
    t = math.tan(math.radians(cam.fov) / 2)
    u = (np.arange(SIZE * sub) + 0.5) / (SIZE * sub)
    sx, sy = np.meshgrid(u, u)
    # camera space: +x left, +y up, looking down +z; the ray through (sx, sy) at depth 1 is dc
    dc = np.stack([(1 - 2 * sx) * t, (1 - 2 * sy) * t, np.ones_like(sx)], -1)
    p = WALL_Z * dc                                         # the wall point seen
    cam_dist = (WALL_Z - cam.near_clip) * np.linalg.norm(dc, axis=-1)   # rays start at the near clip
    v = LIGHT_P - p
    r = np.linalg.norm(v, axis=-1)
    cos = np.abs(v[..., 2]) / r
    direct = (WALL_R / math.pi) * LIGHT_I * cos / r ** 2
    L = np.exp(-np.asarray(sigma) * (cam_dist + r)[..., None]) * direct[..., None]
    return L.reshape(SIZE, sub, SIZE, sub, 3).mean(axis=(1, 3))


FURNACE_A = 0.5


def furnace_scene() -> Scene:
    fog = Medium("homogeneous", sigma_t=np.array([1.0, 2.0, 4.0]), albedo=rgb(1.0), phase=Phase("hg", 0.5))
    v = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)])
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    # wound so the geometric normals point into the box, the side that emits and reflects
    faces = np.array([f for q in quads for f in ((q[0], q[2], q[1]), (q[0], q[3], q[2]))])
    box = Shape("mesh", Bsdf("diffuse", reflectance=rgb(FURNACE_A)), vertices=v, faces=faces,
                emitter_radiance=rgb(1.0))
    return _scene([box], [], fog, 90.0, max_depth=-1)


def _z_failures(what, res, expected) -> list[str]:
    img, var = res.image.astype(np.float64), res.variance.astype(np.float64)
    exp = np.broadcast_to(expected, img.shape)
    half = SIZE // 2
    regions = [(slice(None), slice(None))] + [(slice(i, i + half), slice(j, j + half))
                                              for i in (0, half) for j in (0, half)]
    out = []
    if res.invalid:
        out.append(f"{what}: {res.invalid} invalid samples")
    for sy, sx in regions:
        n = img[sy, sx].shape[0] * img[sy, sx].shape[1]
        diff = (img[sy, sx] - exp[sy, sx]).sum((0, 1)) / n
        se = np.sqrt(var[sy, sx].sum((0, 1))) / n
        for c in range(3):
            if not abs(diff[c]) <= Z_LIMIT * se[c] + 1e-6 * abs(exp[sy, sx][..., c].mean()):
                # a black image has no variance: say so rather than divide by it
                z = f"{diff[c] / se[c]:+.1f} standard errors" if se[c] > 0 else "zero variance"
                out.append(f"{what}: mean {img[sy, sx][..., c].mean():.4g} expected "
                           f"{exp[sy, sx][..., c].mean():.4g} (channel {c}, {z})")
                return out
    return out


def _bare_wall_failures(info) -> list[str]:
    """The wall without its medium, through the packet renderer (its own program build: only on the
    devices where "auto" renders such scenes with it)."""
    from .renderer import Renderer
    bare = wall_scene(absorbing=False)
    try:
        res = Renderer(bare, device=info, engine="packet").render(SPP)
    except Exception as exc:
        text = str(exc).strip().splitlines()
        return [f"packet renderer failed: {text[-1] if text else type(exc).__name__}"]
    return _z_failures("point light on a bare wall (packet renderer)", res, wall_expected(bare, sigma=np.zeros(3)))


def run(info) -> SelfTest:
    """Render the self-test scenes on device `info` (a volcl.device.DeviceInfo)."""
    from .features import detect
    from .renderer import Renderer
    t0 = time.perf_counter()
    wall, furnace_sc = wall_scene(), furnace_scene()
    # one program for both scenes (one build): the union of what they use
    features = {k: a or b for (k, a), b in zip(detect(wall).items(), detect(furnace_sc).values())}
    try:
        r = Renderer(wall, device=info, features=features)
        first = r.render(SPP)
        r.reset()
        again = r.render(SPP)
        furnace = Renderer(furnace_sc, device=info, features=features).render(SPP)
    except Exception as exc:    # a driver that fails to run what it built is as broken as a wrong answer
        text = str(exc).strip().splitlines()
        return SelfTest(False, f"self-test render failed: {text[-1] if text else type(exc).__name__}",
                        time.perf_counter() - t0)
    failures = _z_failures("point light through an absorbing medium", first, wall_expected(wall))
    if not np.array_equal(first.image, again.image) or first.invalid != again.invalid:
        failures.append("the same seed gave different images (the kernel reads something undefined)")
    failures += _z_failures(f"medium furnace (1 / (1 - a) = {1 / (1 - FURNACE_A):g})", furnace,
                            1 / (1 - FURNACE_A))
    if not failures and packets.runs_on(info):
        failures += _bare_wall_failures(info)
    seconds = time.perf_counter() - t0
    if failures:
        return SelfTest(False, "; ".join(failures), seconds)
    return SelfTest(True, "ok", seconds)
