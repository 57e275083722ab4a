"""The rules for parameter values, shared by the parsers and by volcl.traverse, so that a bad value
gets the same message whether it comes from a file or from Python.

Each function returns the checked value or raises CheckError with the message; the parsers add the
file, line and element (Node.fail), volcl.params adds the parameter's key and where the object was
defined.
"""
from __future__ import annotations

import math

import numpy as np

from . import transform as tf

# The kernels compute in float32: a value beyond its range would reach them as infinity.
FLOAT32_MAX = float(np.finfo(np.float32).max)


class CheckError(ValueError):
    """A value that breaks a parameter's rule; the message says which rule and what was found."""


def finite(what: str, value: float, text: str | None = None) -> float:
    """A finite number within the float32 range ('what: text is not a finite number')."""
    text = repr(value) if text is None else repr(text)
    if not math.isfinite(value):
        raise CheckError(f"{what}: {text} is not a finite number")
    if abs(value) > FLOAT32_MAX:
        raise CheckError(f"{what}: {text} is beyond the single-precision floating-point range volcl "
                         f"renders in (|x| <= {FLOAT32_MAX:.7g})")
    return value


def positive(name: str, value: float) -> float:
    if not value > 0:
        raise CheckError(f"'{name}' must be > 0, got {value}")
    return value


def nonneg(name: str, value: float) -> float:
    if not value >= 0:
        raise CheckError(f"'{name}' must be >= 0, got {value}")
    return value


def nonneg_color(name: str, value: np.ndarray) -> np.ndarray:
    if (value < 0).any():
        raise CheckError(f"'{name}' must be >= 0, got {value.tolist()}")
    return value


def unit_color(name: str, value: np.ndarray) -> np.ndarray:
    if (value < 0).any() or (value > 1).any():
        raise CheckError(f"'{name}' must lie in [0, 1], got {value.tolist()}")
    return value


def hg_g(name: str, g: float) -> float:
    if not -1 < g < 1:
        raise CheckError(f"'{name}' = {g} is outside the allowed range -1 < g < 1")
    return g


def volume_range(name: str, volume, upper: float | None) -> None:
    """sigma_t values must be >= 0; albedo values must also be <= 1 (a Volume, const or grid)."""
    values = volume.values()
    low, high = float(np.min(values)), float(np.max(values))
    if low < 0 or (upper is not None and high > upper):
        allowed = ">= 0" if upper is None else f"in [0, {upper:g}]"
        found = f" in {volume.filename}" if volume.kind != "const" else ""
        if volume.kind == "sparse":
            found += f" (grid '{volume.grid_name}')"
        raise CheckError(f"'{name}' values must be {allowed}; found values from {low:g} to "
                         f"{high:g}{found}")


def medium_limits(medium) -> None:
    """Coefficients valid one by one can still overflow float32 once combined: sigma_t times
    scale, and the emission sigma_a * radiance the kernels are given."""
    from .model import Volume

    def biggest(value):
        return float(np.max(value.values())) if isinstance(value, Volume) else float(np.max(value))
    sigma_t = biggest(medium.sigma_t) * medium.scale
    limits = [("sigma_t (times scale)", sigma_t)]
    if medium.radiance is not None:
        limits.append(("the emission sigma_t * radiance", sigma_t * float(np.max(medium.radiance))))
    for what, value in limits:
        if not value <= FLOAT32_MAX:
            raise CheckError(f"{what} reaches {value:.4g}, beyond the single-precision range "
                             f"volcl renders in (<= {FLOAT32_MAX:.7g})")


def invertible(name: str, m: np.ndarray) -> np.ndarray:
    if not tf.is_invertible(m):
        raise CheckError(f"transform '{name}' is singular or not finite (a scale of zero, or huge "
                         f"values?)")
    return m


def camera_transform(to_world: np.ndarray, kind: str = "perspective") -> np.ndarray:
    """An orthographic camera's transform may scale and shear (it sets the extent of the view, as in
    Mitsuba); the others only rotate, translate and mirror."""
    if not (np.abs(to_world) <= FLOAT32_MAX).all():
        raise CheckError("the camera's transform places it beyond the single-precision floating-point "
                         "range volcl renders in")
    if kind == "orthographic":
        return to_world
    scale = tf.similarity_scale(to_world)
    if scale is None or abs(scale - 1) > 1e-3:
        # As in Mitsuba 3: ray directions and the field of view assume an unscaled frame.
        raise CheckError("the camera's transform may rotate, translate and mirror, but not scale or shear")
    return to_world


def envmap_transform(to_world: np.ndarray) -> np.ndarray:
    """An envmap's to_world may rotate and mirror only: Mitsuba 3.9 turns directions with it without
    normalizing them, so a scale or shear distorts its image and its sampling; a translation does
    nothing to a map at infinity."""
    scale = tf.similarity_scale(to_world)
    if scale is None or abs(scale - 1) > 1e-4:
        raise CheckError("an envmap's to_world may rotate and mirror, but not scale or shear (Mitsuba 3.9 "
                         "turns directions with it without normalizing them, which distorts the map and its "
                         "sampling)")
    return to_world


def spot_cutoff(value: float) -> float:
    """A spot light's cutoff angle: (0, 180] degrees."""
    if not 0 < value <= 180:
        raise CheckError(f"'cutoff_angle' must lie in (0, 180] degrees, got {value}")
    return value


def spot_beam(value: float) -> float:
    """A spot light's beam width: [0, 180] degrees."""
    if not 0 <= value <= 180:
        raise CheckError(f"'beam_width' must lie in [0, 180] degrees, got {value}")
    return value


def direction(value: np.ndarray) -> np.ndarray:
    """A unit direction from a non-zero vector."""
    d = tf.normalize(value)
    if not np.any(d):
        raise CheckError("the direction is the zero vector")
    return d


def shape_rules(shape, name: str) -> None:
    """Rules for a finished shape (`name`: how messages call it) that no single parameter decides:
    an area emitter needs a mesh with some area (in the float32 the kernels compute in; its
    triangles are sampled by area)."""
    from .. import mesh as meshes
    if shape.kind != "mesh" or shape.emitter_radiance is None:
        return
    areas = meshes.triangle_areas32(shape.vertices, shape.faces)
    if not areas.sum() > 0:
        raise CheckError(f"{name} carries an area emitter but its mesh has zero total area (all "
                         f"{len(areas)} triangles are degenerate in single precision): an emitter "
                         f"needs triangles of positive area")


def interior_gap(shape, name: str) -> str | None:
    """Why a shape with an interior medium does not enclose it (a warning, not an error: Mitsuba
    accepts such shapes too), or None. The kernels tell inside from outside by the side each surface
    is crossed from, as Mitsuba does, so a gap lets paths in or out unseen."""
    from .. import mesh as meshes
    if shape.interior is None:
        return None
    if shape.kind == "cylinder":
        problem = "a cylinder is an open tube (no end caps)"
    elif shape.kind == "mesh":
        problem = meshes.closure_problem(shape.vertices, shape.faces)
    else:
        return None
    if problem is None:
        return None
    return (f"{name} has an interior medium, but {problem}: as in Mitsuba, inside and outside are decided "
            f"at each crossing by the side the ray crosses from, so paths can enter or leave the medium "
            f"through the gaps without crossing a surface")
