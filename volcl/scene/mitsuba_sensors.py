"""Mitsuba sensors, films, reconstruction filters and samplers (src/sensors, src/films, src/render/sensor.cpp).

- perspective: `fov` + `fov_axis` or `focal_length` ("50mm" on a 36 x 24 mm film, along the
  diagonal; Mitsuba's default), clip planes, `principal_point_offset_x/y` (the image plane shifted
  by that fraction of its width / height); `focus_distance` means nothing to a pinhole.
- thinlens: the same plus `aperture_radius` and `focus_distance` (default: the far clip distance).
- orthographic: looks along +z from the plane z = near_clip of its frame, over x in [-1, 1] and y in
  [-1/aspect, 1/aspect]; to_world may scale that frame.
- hdrfilm: `width`, `height`, its rfilter, `sample_border` (off, Mitsuba's default: no samples
  outside the film, so a pixel within the filter's radius of the edge averages only the filter's
  part inside it; on: every pixel's whole filter).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from . import objects
from .model import Filter, Sensor
from .objects import Sampler
from .parse_common import Node, Spec

_TO_WORLD = {"to_world": "transform"}
_SAMPLER_PARAMS = {"sample_count": "int", "seed": "int"}
_SENSOR_CHILDREN = frozenset({"film", "sampler", "medium"})
_SHUTTER = {"shutter_open": "volcl renders a still image (nothing in a Mitsuba XML file moves)",
            "shutter_close": "volcl renders a still image (nothing in a Mitsuba XML file moves)"}
_PROJECTIVE = {"fov": "float", "fov_axis": "string", "focal_length": "string", "near_clip": "float",
               "far_clip": "float", **_TO_WORLD}

_FILM_NOTES = {
    "pixel_format": "volcl writes RGB (EXR: float32 RGB plus a variance layer; PNG: sRGB)",
    "component_format": "volcl writes EXR channels as float32",
    "file_format": "the output's extension (.exr or .png) decides the format",
    "compensate": "volcl accumulates per-pixel sums in float32 on the device and adds them up in float64",
    "banner": "volcl writes no banner",
    **{name: "volcl renders the whole film (no crop window)" for name in
       ("crop_offset_x", "crop_offset_y", "crop_width", "crop_height")},
}

SPECS = {
    "sensor": {
        "perspective": Spec({**_PROJECTIVE, "principal_point_offset_x": "float",
                             "principal_point_offset_y": "float", "focus_distance": "float"},
                            children=_SENSOR_CHILDREN, ignored=_SHUTTER),
        "thinlens": Spec({**_PROJECTIVE, "aperture_radius": "float", "focus_distance": "float"},
                         children=_SENSOR_CHILDREN, ignored=_SHUTTER),
        "orthographic": Spec({"near_clip": "float", "far_clip": "float", **_TO_WORLD},
                             children=_SENSOR_CHILDREN, ignored=_SHUTTER),
    },
    "film": {"hdrfilm": Spec({"width": "int", "height": "int", "sample_border": "bool"},
                             children=frozenset({"rfilter"}),
                             ignored=_FILM_NOTES)},
    "rfilter": {"box": Spec(), "gaussian": Spec({"stddev": "float"}),
                "tent": Spec({"radius": "float"})},
    # Mitsuba's other samplers are accepted with a warning and replaced by independent sampling.
    "sampler": {"independent": Spec(_SAMPLER_PARAMS),
                "stratified": Spec({**_SAMPLER_PARAMS, "jitter": "bool"}),
                "multijitter": Spec({**_SAMPLER_PARAMS, "jitter": "bool"}),
                "orthogonal": Spec({**_SAMPLER_PARAMS, "jitter": "bool", "strength": "int"}),
                "ldsampler": Spec(_SAMPLER_PARAMS)},
}

# Mitsuba 3's perspective sensor without a fov uses a 50 mm lens on a 36 x 24 mm film, measured
# along the diagonal.
_DEFAULT_FOCAL_LENGTH = "50mm"
_FOV_AXES = ("x", "y", "diagonal", "smaller", "larger")


@dataclass
class Film:
    width: int = 768
    height: int = 576
    # Mitsuba's default reconstruction filter: gaussian, stddev 0.5, radius 4 * stddev.
    rfilter: Filter = field(default_factory=lambda: Filter("gaussian", radius=2.0, stddev=0.5))
    # off: no samples outside the film, so a pixel near its edge sees only its filter's inside part
    sample_border: bool = False


def _fov(node: Node) -> tuple[float, str]:
    """(fov in degrees, fov_axis) from fov / fov_axis or focal_length, as Mitsuba's parse_fov."""
    if node.has("fov") and node.has("focal_length"):
        raise node.fail("focal_length", "give either 'fov' or 'focal_length', not both")
    if node.has("fov"):
        axis = node.string("fov_axis", "x").lower()
        if axis not in _FOV_AXES:
            raise node.fail("fov_axis", f"'fov_axis' is {axis!r}; supported: " + ", ".join(_FOV_AXES))
        return node.float("fov"), axis
    if node.has("fov_axis"):
        raise node.fail("fov_axis", "'fov_axis' needs a 'fov' to apply to")
    text = node.string("focal_length", _DEFAULT_FOCAL_LENGTH).strip()
    number = text[:-2] if text.endswith("mm") else text
    try:
        focal = float(number)
    except ValueError:
        raise node.fail("focal_length", f"'focal_length' {text!r} is not a length in millimetres such as "
                                        f"\"50mm\"") from None
    if not (math.isfinite(focal) and focal > 0):
        raise node.fail("focal_length", f"'focal_length' must be > 0, got {text!r}")
    return math.degrees(2.0 * math.atan(math.hypot(36.0, 24.0) / (2.0 * focal))), "diagonal"


def build_sensor(node: Node) -> Sensor:
    film = node.single("film")
    film = film.obj if film else Film()
    sampler = node.single("sampler")
    sampler = sampler.obj if sampler else Sampler(4)
    medium = node.single("medium")
    kind = node.type
    fov, fov_axis = (0.0, "x") if kind == "orthographic" else _fov(node)
    near, far = node.float("near_clip", 1e-2), node.float("far_clip", 1e4)
    camera = objects.camera(node, kind=kind, fov=fov, fov_axis=fov_axis, width=film.width,
                            height=film.height, near=near, far=far, to_world=node.transform("to_world"),
                            rfilter=film.rfilter,
                            names={"fov": "fov" if node.has("fov") else "focal_length", "width": None,
                                   "height": None, "near": "near_clip", "far": "far_clip",
                                   "to_world": "to_world"})
    if kind == "perspective":
        camera.principal_point = (node.float("principal_point_offset_x", 0.0),
                                  node.float("principal_point_offset_y", 0.0))
        if node.has("focus_distance"):
            node.ctx.warn(node.at("focus_distance"), "'focus_distance' has no effect on a perspective "
                                                     "(pinhole) camera, in Mitsuba as in volcl; use a "
                                                     "thinlens sensor for depth of field")
    elif kind == "thinlens":
        _thin_lens(node, camera, far)
    camera.medium = medium.obj if medium else None
    camera.sample_border = film.sample_border
    camera.id = node.element.attrs.get("id", "")
    return Sensor(camera, sampler.sample_count, sampler.seed, node.source())


def _thin_lens(node: Node, camera, far: float) -> None:
    radius = node.float("aperture_radius")
    if radius < 0:
        raise node.fail("aperture_radius", f"'aperture_radius' must be >= 0, got {radius}")
    focus = node.float("focus_distance", far)
    if not focus > 0:
        raise node.fail("focus_distance", f"'focus_distance' must be > 0, got {focus}")
    if radius == 0:
        # Mitsuba replaces a zero aperture by float epsilon, a pinhole to any precision
        node.ctx.warn(node.at("aperture_radius"), "a zero 'aperture_radius' makes a pinhole camera "
                                                  "(Mitsuba uses float epsilon instead): rendered as a "
                                                  "perspective camera")
        camera.kind = "perspective"
        return
    camera.aperture_radius, camera.focus_distance = radius, focus


def build_film(node: Node) -> Film:
    rfilter = node.single("rfilter")
    film = Film(node.int("width", 768), node.int("height", 576), sample_border=node.bool("sample_border", False))
    if rfilter is not None:
        film.rfilter = rfilter.obj
    for name in ("width", "height"):
        if getattr(film, name) < 1:
            raise node.fail(name, f"film {name} must be >= 1, got {getattr(film, name)}")
    return film


def build_rfilter(node: Node) -> Filter:
    if node.type == "gaussian":
        stddev = node.positive("stddev", 0.5)
        return Filter("gaussian", radius=4.0 * stddev, stddev=stddev)
    if node.type == "tent":
        return Filter("tent", radius=node.positive("radius", 1.0))
    return Filter("box", radius=0.5)


def build_sampler(node: Node) -> Sampler:
    if node.type != "independent":
        node.ctx.warn(node.element, f"sampler '{node.type}' is not supported; rendering with "
                                    f"independent sampling")
    return Sampler(objects.sample_count(node, "sample_count", 4), node.int("seed", 0))
