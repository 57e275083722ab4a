"""Which effects a scene calls for, as the kernel's VOLCL_HAS_* flags.

A flag decides whether code exists in the compiled program, never a value: spp, depth, g and the
like are kernel data. The set is kept coarse (one flag per effect a user would name) so the
kernels stay readable.
"""
from __future__ import annotations

import numpy as np

from .scene.model import Scene, Volume

FLAGS = (
    "SPHERES",              # analytic sphere primitives
    "SHADING_NORMALS",      # interpolated vertex normals on some mesh
    "DIFFUSE", "DIELECTRIC", "CONDUCTOR", "NULL_BSDF",
    "AREA_LIGHTS", "POINT_LIGHTS", "DIRECTIONAL_LIGHTS", "ENV_LIGHTS",
    "MEDIA",                # any participating medium
    "MEDIUM_BOUNDARIES",    # shapes that name an interior or exterior medium
    "CHROMATIC_MEDIA",      # a medium whose extinction differs between colour channels
    "HG",                   # an anisotropic (Henyey-Greenstein) phase function
    "EMISSIVE_MEDIA",       # a medium that emits light
    "GRID_MEDIA",           # a heterogeneous medium: grid lookups, delta and ratio tracking
)


def _media_of(scene: Scene):
    return list(scene.media)


def _chromatic(sigma_t) -> bool:
    """Whether an extinction (rgb array, or a Volume of a heterogeneous medium) differs between
    colour channels somewhere."""
    if isinstance(sigma_t, Volume):
        if sigma_t.kind == "const":
            return bool(np.ptp(sigma_t.value) > 0)
        data = sigma_t.data
        return data.shape[-1] == 3 and bool(np.any(data.max(axis=-1) != data.min(axis=-1)))
    return bool(np.ptp(np.asarray(sigma_t, dtype=float)) > 0)


def detect(scene: Scene) -> dict[str, bool]:
    """The features `scene` needs: every flag in FLAGS, True where some element uses it."""
    bsdf_kinds = {s.bsdf.kind for s in scene.shapes}
    light_kinds = {e.kind for e in scene.emitters}
    media = _media_of(scene)
    f = dict.fromkeys(FLAGS, False)
    f["SPHERES"] = any(s.kind == "sphere" for s in scene.shapes)
    f["SHADING_NORMALS"] = any(s.kind == "mesh" and s.normals is not None for s in scene.shapes)
    f["DIFFUSE"] = "diffuse" in bsdf_kinds
    f["DIELECTRIC"] = "dielectric" in bsdf_kinds
    f["CONDUCTOR"] = "conductor" in bsdf_kinds
    f["NULL_BSDF"] = "null" in bsdf_kinds
    f["AREA_LIGHTS"] = any(s.emitter_radiance is not None for s in scene.shapes)
    f["POINT_LIGHTS"] = "point" in light_kinds
    f["DIRECTIONAL_LIGHTS"] = "directional" in light_kinds
    f["ENV_LIGHTS"] = "constant" in light_kinds
    f["MEDIA"] = bool(media)
    f["MEDIUM_BOUNDARIES"] = any(s.interior is not None or s.exterior is not None for s in scene.shapes)
    f["CHROMATIC_MEDIA"] = any(_chromatic(m.sigma_t) for m in media)
    f["HG"] = any(m.phase.kind == "hg" for m in media)
    f["EMISSIVE_MEDIA"] = any(m.radiance is not None and np.any(np.asarray(m.radiance) > 0) for m in media)
    f["GRID_MEDIA"] = any(m.kind == "heterogeneous" for m in media)
    return f


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
