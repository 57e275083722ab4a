"""Which effects a scene calls for, as the kernel's VOLCL_HAS_* flags.

A flag decides whether code exists in the compiled program, never a value: spp, depth, g and the
like are kernel data. The set is kept coarse (one flag per effect a user would name) so the
kernels stay readable.
"""
from __future__ import annotations

import numpy as np

from .pack_materials import chain, textures_of
from .phase import device_kind
from .scene.model import Scene, Volume

FLAGS = (
    "SPHERES",              # analytic sphere primitives
    "SHADING_NORMALS",      # interpolated vertex normals on some mesh
    "DIFFUSE", "DIELECTRIC", "CONDUCTOR", "NULL_BSDF",
    "AREA_LIGHTS", "POINT_LIGHTS", "DIRECTIONAL_LIGHTS",
    "ENV_LIGHTS",           # an environment at infinity: a constant or an envmap
    "ENVMAP",               # an image-based environment (Mitsuba's envmap): lookups and importance sampling
    "SPOT_LIGHTS",          # Mitsuba's spot light
    "MEDIA",                # any participating medium
    "MEDIUM_BOUNDARIES",    # shapes that name an interior or exterior medium
    "CHROMATIC_MEDIA",      # a medium whose extinction differs between colour channels
    "HG",                   # an anisotropic (Henyey-Greenstein) phase function
    "EMISSIVE_MEDIA",       # a medium that emits light
    "EMISSION_NEE",         # next-event estimation towards emissive media (kernels/emission_nee.h)
    "GRID_MEDIA",           # a heterogeneous medium: grid lookups, delta and ratio tracking
    "SPARSE_GRIDS",         # a grid in bricks (OpenVDB / NanoVDB files: kernels/grid.h)
    "EQUIANGULAR",          # equiangular sampling towards point lights in homogeneous media
    "CYLINDERS",            # analytic cylinder primitives (Mitsuba's cylinder)
    "THINLENS",             # a thin-lens camera (depth of field)
    "ORTHOGRAPHIC",         # an orthographic camera
    "DIRECT",               # Mitsuba's direct integrator instead of the volumetric path tracer
    "ROUGHCONDUCTOR", "ROUGHDIELECTRIC", "PLASTIC", "ROUGHPLASTIC", "THINDIELECTRIC",
    "MASK",                 # Mitsuba's mask (opacity) wrapper
    "TEXTURES",             # a bsdf parameter given by a bitmap or checkerboard texture
    "BUMP_MAPS",            # bump or normal maps
    "PHASE_FAMILIES",       # phase functions beyond HG: Rayleigh, Draine, Cornette-Shanks, Fournier-Forand,
                            # tabulated, blends, approximate Mie (one flag: volcl/phase.py, README)
    "INSTANCES",            # shape groups placed by instances: a two-level BVH (kernels/bvh.h)
)


def _media_of(scene: Scene):
    return list(scene.media)


def _chromatic(sigma_t) -> bool:
    """Whether an extinction (rgb array, or a Volume of a heterogeneous medium) differs between
    colour channels somewhere."""
    if isinstance(sigma_t, Volume):
        if sigma_t.kind == "const":
            return bool(np.ptp(sigma_t.value) > 0)
        data = sigma_t.values()
        return data.shape[-1] == 3 and bool(np.any(data.max(axis=-1) != data.min(axis=-1)))
    return bool(np.ptp(np.asarray(sigma_t, dtype=float)) > 0)


def _volumes_of(medium) -> list:
    return [medium.sigma_t, medium.albedo, medium.emission_volume]


def detect(scene: Scene) -> dict[str, bool]:
    """The features `scene` needs: every flag in FLAGS, True where some element uses it."""
    bsdfs = [b for s in scene.shapes for b in chain(s.bsdf)]
    bsdf_kinds = {b.kind for b in bsdfs}
    light_kinds = {e.kind for e in scene.emitters}
    media = _media_of(scene)
    f = dict.fromkeys(FLAGS, False)
    f["SPHERES"] = any(s.kind == "sphere" for s in scene.shapes)
    f["CYLINDERS"] = any(s.kind == "cylinder" for s in scene.shapes)
    f["INSTANCES"] = bool(getattr(scene, "instances", None))
    f["THINLENS"] = scene.camera.kind == "thinlens"
    f["ORTHOGRAPHIC"] = scene.camera.kind == "orthographic"
    f["DIRECT"] = scene.integrator.kind == "direct"
    f["SHADING_NORMALS"] = any(s.kind == "mesh" and s.normals is not None for s in scene.shapes)
    f["DIFFUSE"] = "diffuse" in bsdf_kinds
    f["DIELECTRIC"] = "dielectric" in bsdf_kinds
    f["CONDUCTOR"] = "conductor" in bsdf_kinds
    f["NULL_BSDF"] = "null" in bsdf_kinds
    for kind in ("roughconductor", "roughdielectric", "plastic", "roughplastic", "thindielectric", "mask"):
        f[kind.upper()] = kind in bsdf_kinds
    # normal maps read theirs as colours; a spot may project one
    f["TEXTURES"] = any(textures_of(b) for b in bsdfs) or any(e.texture is not None for e in scene.emitters)
    f["BUMP_MAPS"] = bool(bsdf_kinds & {"bumpmap", "normalmap"})
    f["AREA_LIGHTS"] = any(s.emitter_radiance is not None for s in scene.shapes)
    f["POINT_LIGHTS"] = "point" in light_kinds
    f["DIRECTIONAL_LIGHTS"] = "directional" in light_kinds
    f["ENV_LIGHTS"] = bool(light_kinds & {"constant", "envmap"})
    f["ENVMAP"] = "envmap" in light_kinds
    f["SPOT_LIGHTS"] = "spot" in light_kinds
    f["MEDIA"] = bool(media)
    f["MEDIUM_BOUNDARIES"] = any(s.interior is not None or s.exterior is not None for s in scene.shapes)
    f["CHROMATIC_MEDIA"] = any(_chromatic(m.sigma_t) for m in media)
    phase_kinds = {device_kind(m.phase) for m in media}
    f["HG"] = "hg" in phase_kinds
    f["PHASE_FAMILIES"] = "lobes" in phase_kinds
    f["EMISSIVE_MEDIA"] = any(m.emissive for m in media)
    # the estimator's default (volcl.estimator: on unless switched off); not in the direct integrator
    f["EMISSION_NEE"] = f["EMISSIVE_MEDIA"] and scene.integrator.kind != "direct"
    f["GRID_MEDIA"] = any(m.kind == "heterogeneous" for m in media)
    f["SPARSE_GRIDS"] = any(isinstance(v, Volume) and v.kind == "sparse" for m in media for v in _volumes_of(m))
    # the estimator's default ('auto'): worth compiling where a point light sits inside a medium
    f["EQUIANGULAR"] = any(m is not None for m in point_light_media(scene))
    return f


# Directions of the probe rays that find the medium around a point: the axes and the diagonals,
# turned slightly so that no probe runs exactly along an axis-aligned wall or through its edges.
_PROBES = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]
                   + [[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], np.float64)
_PROBES = _PROBES + np.array([0.0123, -0.0217, 0.0311])
_PROBES /= np.linalg.norm(_PROBES, axis=1, keepdims=True)


def _first_transition(scene: Scene, o: np.ndarray, d: np.ndarray):
    """(shape, dot(d, ng)) of the nearest shape naming a medium that the ray o + t d (t > 0) meets,
    or None. Shapes that name no medium are passed through: crossing them changes no medium. Shapes
    of a shape group are met where its instances place them: the ray is taken into the group's space
    (the kernels' normal convention, the inverse transpose, keeps the sign of dot(d, ng) there)."""
    def names_medium(s):
        return s.interior is not None or s.exterior is not None
    best_t, best = _nearest_transition([s for s in scene.shapes if s.group is None and names_medium(s)],
                                       o, d, np.inf, None)
    for inst in getattr(scene, "instances", ()):
        members = [s for s in inst.group.shapes if names_medium(s)]
        if not members:
            continue
        inv = np.linalg.inv(inst.to_world)
        lo, ld = inv[:3, :3] @ o + inv[:3, 3], inv[:3, :3] @ d
        length = float(np.linalg.norm(ld))
        t, found = _nearest_transition(members, lo, ld / length, best_t * length, None)
        if found is not None:
            best_t, best = t / length, found
    return best


def _nearest_transition(shapes, o, d, best_t, best):
    """(t, (shape, dot(d, ng))) of the nearest crossing closer than best_t of `shapes` by the ray
    o + t d (|d| = 1), else (best_t, best)."""
    for s in shapes:
        if s.kind == "cylinder":
            hit = _cylinder_hit(s, o, d, best_t)
            if hit is not None:
                best_t, best = hit
            continue
        if s.kind == "sphere":
            oc = o - s.center
            b = oc @ d
            disc = b * b - (oc @ oc - s.radius ** 2)
            if disc < 0:
                continue
            for t in sorted((-b - np.sqrt(disc), -b + np.sqrt(disc))):
                if 1e-9 < t < best_t:
                    n = (o + t * d - s.center) / s.radius
                    best_t, best = t, (s, float(d @ (-n if s.flip_normals else n)))
                    break
            continue
        tri = s.vertices[s.faces]
        for chunk in range(0, len(tri), 1 << 18):
            p0, p1, p2 = (tri[chunk:chunk + (1 << 18), k] for k in range(3))
            e1, e2 = p1 - p0, p2 - p0
            pv = np.cross(d, e2)
            det = (e1 * pv).sum(1)
            ok = np.abs(det) > 1e-300
            inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
            tv = o - p0
            u = (tv * pv).sum(1) * inv
            qv = np.cross(tv, e1)
            v = (qv @ d) * inv
            t = (e2 * qv).sum(1) * inv
            hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-9) & (t < best_t)
            if hit.any():
                k = np.flatnonzero(hit)[np.argmin(t[hit])]
                best_t, best = t[k], (s, float(np.cross(e1[k], e2[k]) @ d))
    return best_t, best


def _cylinder_hit(s, o: np.ndarray, d: np.ndarray, best_t: float):
    """(t, (shape, dot(d, ng))) of the nearest crossing of the open cylinder `s` closer than best_t,
    or None; as kernels/cylinder.h, in the cylinder's own frame."""
    inv = np.linalg.inv(s.cylinder)
    lo, ld = inv[:3, :3] @ o + inv[:3, 3], inv[:3, :3] @ d
    a = ld[0] ** 2 + ld[1] ** 2
    if not a > 0:
        return None
    tc = -(lo[0] * ld[0] + lo[1] * ld[1]) / a
    closest = lo[:2] + tc * ld[:2]
    disc = 1.0 - closest @ closest
    if disc < 0:
        return None
    h = np.sqrt(disc / a)
    for t in (tc - h, tc + h):
        z = lo[2] + t * ld[2]
        if 1e-9 < t < best_t and 0 <= z <= 1:
            p = lo + t * ld
            n = inv[:3, :3].T @ np.array([p[0], p[1], 0.0])
            n = -n if s.flip_normals else n
            return t, (s, float(d @ n))
    return None


def medium_at(scene: Scene, point) -> object:
    """The medium around `point` by the renderer's rules (a shape's geometric normal points to its
    exterior), voted over probe rays; the camera's medium when no probe meets a shape that names one
    (an open scene filled with the camera's medium)."""
    o = np.asarray(point, np.float64)
    votes = {}
    for d in _PROBES:
        found = _first_transition(scene, o, d)
        if found is None:
            continue
        shape, cos = found
        m = shape.interior if cos > 0 else shape.exterior
        votes.setdefault(id(m), [m, 0])[1] += 1
    if not votes:
        return scene.camera.medium
    return max(votes.values(), key=lambda mv: mv[1])[0]


POINT_LIKE = ("point", "spot")


def escapes_unbounded(scene: Scene, point) -> bool:
    """Whether some probe ray from `point` leaves the scene without meeting a shape that names a
    medium: the medium around the point then reaches to infinity that way."""
    o = np.asarray(point, np.float64)
    return any(_first_transition(scene, o, d) is None for d in _PROBES)


def point_light_media(scene: Scene) -> list:
    """The medium around each point or spot light (None: vacuum), in the order of scene.emitters."""
    return [medium_at(scene, e.position) for e in scene.emitters if e.kind in POINT_LIKE]


def all_features() -> dict[str, bool]:
    return dict.fromkeys(FLAGS, True)


def parse_override(text: str) -> dict[str, bool]:
    """`--features all`: every flag on, for comparing against the specialized kernel."""
    if text == "all":
        return all_features()
    raise ValueError(f"unknown feature set {text!r}; supported: 'all'")


def defines(features: dict[str, bool]) -> list[str]:
    return [f"-DVOLCL_HAS_{name}={int(bool(features[name]))}" for name in FLAGS]


def describe(features: dict[str, bool]) -> str:
    on = [name.lower() for name in FLAGS if features[name]]
    return ",".join(on) if on else "none"
