"""Small scenes built directly from volcl's data model, for tests with analytic answers."""
import numpy as np

from volcl.scene.model import Bsdf, Camera, Emitter, Filter, Integrator, Medium, Phase, Scene, Shape, Volume, rgb

CUBE_QUADS = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]


def box_mesh(half=1.0, inward=True):
    """A closed cube's vertices and faces; `inward`: geometric normals point into the box."""
    v = np.array([[x, y, z] for x in (-half, half) for y in (-half, half) for z in (-half, half)], float)
    faces = []
    for q in CUBE_QUADS:
        faces += [(q[0], q[1], q[2]), (q[0], q[2], q[3])]
    f = np.array(faces)
    return v, (f[:, ::-1].copy() if inward else f)


def quad_mesh(center, u, v):
    """A rectangle center +- u +- v, normal along cross(u, v)."""
    c, u, v = (np.asarray(a, float) for a in (center, u, v))
    verts = np.array([c - u - v, c + u - v, c + u + v, c - u + v])
    return verts, np.array([[0, 1, 2], [0, 2, 3]])


def look_at(origin, target, up=(0, 1, 0)):
    o, t, up = (np.asarray(a, float) for a in (origin, target, up))
    d = (t - o) / np.linalg.norm(t - o)
    left = np.cross(up, d)
    left /= np.linalg.norm(left)
    new_up = np.cross(d, left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, new_up, d, o
    return m


def camera(width=16, height=16, fov=40.0, to_world=None, rfilter="box", medium=None):
    radius = {"box": 0.5, "tent": 1.0, "gaussian": 2.0}[rfilter]
    return Camera(to_world=np.eye(4) if to_world is None else to_world, fov=fov, width=width, height=height,
                  rfilter=Filter(rfilter, radius, 0.5), medium=medium)


def diffuse(a, twosided=False):
    return Bsdf("diffuse", reflectance=rgb(a), twosided=twosided)


def scene(shapes=(), emitters=(), cam=None, max_depth=-1, rr_depth=5, hide_emitters=False, media=(), seed=7):
    sc = Scene(path="<test>", dialect="mitsuba", shapes=list(shapes), emitters=list(emitters),
               camera=cam or camera(), seed=seed, media=list(media))
    sc.integrator = Integrator("volpathmis", max_depth=max_depth, rr_depth=rr_depth, hide_emitters=hide_emitters)
    seen = {id(m): m for m in sc.media}
    for m in [sc.camera.medium] + [x for s in sc.shapes for x in (s.interior, s.exterior)]:
        if m is not None and id(m) not in seen:
            seen[id(m)] = m
    sc.media = list(seen.values())
    return sc


def furnace(albedo, radiance=1.0, max_depth=-1, medium=None):
    """Camera inside a closed box that emits `radiance` inwards and reflects diffusely."""
    v, f = box_mesh(inward=True)
    box = Shape("mesh", diffuse(albedo), vertices=v, faces=f, emitter_radiance=rgb(radiance))
    return scene([box], cam=camera(8, 8, fov=90, medium=medium), max_depth=max_depth)


def medium(sigma_t, albedo, g=0.0, radiance=None):
    phase = Phase("hg", g) if g != 0 else Phase("isotropic")
    return Medium("homogeneous", sigma_t=rgb(sigma_t), albedo=rgb(albedo), phase=phase,
                  radiance=None if radiance is None else rgb(radiance))


def grid(data, to_world=None, filter="trilinear"):
    """A grid volume; data (z, y, x) or (z, y, x, c), filling to_world's image of the unit cube."""
    a = np.asarray(data, np.float32)
    a = a[..., None] if a.ndim == 3 else a
    return Volume("grid", value=rgb(0.0), data=a, to_world=np.eye(4) if to_world is None else to_world,
                  filter=filter)


def cube_to_world(lo, hi):
    """to_world mapping the unit cube onto the box [lo, hi]."""
    lo, hi = np.asarray(lo, float) * np.ones(3), np.asarray(hi, float) * np.ones(3)
    m = np.diag(np.r_[hi - lo, 1.0])
    m[:3, 3] = lo
    return m


def hetero_medium(sigma_t, albedo, g=0.0, scale=1.0, radiance=None):
    """A heterogeneous medium; sigma_t and albedo: Volume objects, or colours (constant volumes)."""
    def vol(v):
        return v if isinstance(v, Volume) else Volume("const", value=rgb(v))
    phase = Phase("hg", g) if g != 0 else Phase("isotropic")
    return Medium("heterogeneous", sigma_t=vol(sigma_t), albedo=vol(albedo), scale=scale, phase=phase,
                  radiance=None if radiance is None else rgb(radiance))


def sphere(center, radius, bsdf, **kw):
    return Shape("sphere", bsdf, center=np.asarray(center, float), radius=radius, **kw)


def constant_env(radiance=1.0):
    return Emitter("constant", rgb(radiance))
