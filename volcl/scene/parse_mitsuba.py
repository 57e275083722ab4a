"""The Mitsuba 3 dialect (<scene version="3...">): its plugin table and the builders behind it.

Defaults and rules follow Mitsuba 3's plugin documentation wherever the volcl contract is silent,
so a file renders to the same expected image in both renderers. volcl's own extensions carry a
`volcl_` prefix here so that Mitsuba reports them instead of misreading them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from . import checks, objects, transform as tf
from .model import (Bsdf, Camera, Emitter, Filter, Integrator, Medium, Phase, Scene, Volume, rgb)
from .objects import AreaLight, Sampler
from .parse_common import Dialect, Node, Spec, medium_list
from .properties import PROPERTY_TAGS
from .shapes import PRIMITIVES, bounds, mesh_shape, sphere_shape

_TO_WORLD = {"to_world": "transform"}
_MEDIUM_PARAMS = {"sigma_t": "color", "albedo": "color", "scale": "float",
                  "volcl_radiance": "color"}
_SAMPLER_PARAMS = {"sample_count": "int", "seed": "int"}
_SHAPE_CHILDREN = frozenset({"bsdf", "emitter", "medium"})

SPECS = {
    "scene": {None: Spec(attrs=("version",), children=frozenset(
        {"integrator", "sensor", "shape", "bsdf", "emitter", "medium", "volume", "phase"}))},
    "integrator": {kind: Spec({"max_depth": "int", "rr_depth": "int", "hide_emitters": "bool"})
                   for kind in ("path", "volpath", "volpathmis")},
    "sensor": {"perspective": Spec({"fov": "float", "fov_axis": "string", "near_clip": "float",
                                    "far_clip": "float", **_TO_WORLD},
                                   children=frozenset({"film", "sampler", "medium"}))},
    "film": {"hdrfilm": Spec({"width": "int", "height": "int"}, children=frozenset({"rfilter"}),
                             other_params="warn")},
    "rfilter": {"box": Spec(), "gaussian": Spec({"stddev": "float"}),
                "tent": Spec({"radius": "float"})},
    # Mitsuba's other samplers are accepted with a warning and replaced by independent sampling.
    "sampler": {"independent": Spec(_SAMPLER_PARAMS),
                "stratified": Spec({**_SAMPLER_PARAMS, "jitter": "bool"}),
                "multijitter": Spec({**_SAMPLER_PARAMS, "jitter": "bool"}),
                "orthogonal": Spec({**_SAMPLER_PARAMS, "jitter": "bool", "strength": "int"}),
                "ldsampler": Spec(_SAMPLER_PARAMS)},
    "shape": {
        **{kind: Spec({"filename": "string", "face_normals": "bool", "flip_normals": "bool",
                       **_TO_WORLD}, children=_SHAPE_CHILDREN) for kind in ("obj", "ply")},
        **{kind: Spec({"flip_normals": "bool", **_TO_WORLD}, children=_SHAPE_CHILDREN)
           for kind in PRIMITIVES},
        "sphere": Spec({"center": "point", "radius": "float", "flip_normals": "bool",
                        **_TO_WORLD}, children=_SHAPE_CHILDREN),
    },
    "bsdf": {
        "diffuse": Spec({"reflectance": "color"}),
        "twosided": Spec(children=frozenset({"bsdf"})),
        "dielectric": Spec({"int_ior": "ior", "ext_ior": "ior"}),
        "conductor": Spec({"material": "string", "eta": "color", "k": "color",
                           "specular_reflectance": "color"}),
        "null": Spec(),
    },
    "emitter": {
        "area": Spec({"radiance": "color"}),
        "point": Spec({"intensity": "color", "position": "point", **_TO_WORLD}),
        "directional": Spec({"irradiance": "color", "direction": "point", **_TO_WORLD}),
        "constant": Spec({"radiance": "color"}),
    },
    "medium": {
        "homogeneous": Spec(_MEDIUM_PARAMS, children=frozenset({"phase"})),
        "heterogeneous": Spec(_MEDIUM_PARAMS, children=frozenset({"phase", "volume"})),
    },
    "volume": {
        "gridvolume": Spec({"filename": "string", "filter_type": "string", **_TO_WORLD}),
        "constvolume": Spec({"value": "color", **_TO_WORLD}),
    },
    "phase": {"isotropic": Spec(), "hg": Spec({"g": "float"})},
}

# Mitsuba 3's perspective sensor without a fov uses a 50 mm lens on a 36 x 24 mm film, measured
# along the diagonal.
_DEFAULT_FOV = math.degrees(2.0 * math.atan(math.hypot(36.0, 24.0) / (2.0 * 50.0)))
_FOV_AXES = ("x", "y", "diagonal", "smaller", "larger")


@dataclass
class Film:
    width: int = 768
    height: int = 576
    # Mitsuba's default reconstruction filter: gaussian, stddev 0.5, radius 4 * stddev.
    rfilter: Filter = field(default_factory=lambda: Filter("gaussian", radius=2.0, stddev=0.5))


@dataclass
class Sensor:
    camera: Camera
    sampler: Sampler


# ---------------------------------------------------------------------------------------------

def build_scene(node: Node) -> Scene:
    ctx = node.ctx
    for child in node.children:
        if child.element.tag == "ref":
            raise child.element.error("a <ref> directly inside <scene> has no effect; refer to "
                                      "objects from inside the shape or sensor that uses them")
    integrator = node.single("integrator")
    if integrator is None:
        ctx.warn(node.element, "no <integrator>: using volpathmis (max_depth -1, rr_depth 5)")
    shapes = [c.obj for c in node.objects("shape")]
    sensor = node.single("sensor")
    sensor = sensor.obj if sensor else _default_sensor(node, shapes)
    emitters = []
    for child in node.objects("emitter"):
        if isinstance(child.obj, AreaLight):
            raise child.element.error("an area emitter must be placed inside the <shape> that "
                                      "emits")
        emitters.append(child.obj)
    camera, sampler = sensor.camera, sensor.sampler
    return Scene(path=ctx.path, dialect="mitsuba",
                 integrator=integrator.obj if integrator else Integrator(),
                 camera=camera, spp=sampler.sample_count, seed=sampler.seed,
                 shapes=shapes, emitters=emitters, media=medium_list(camera.medium, shapes),
                 warnings=ctx.warnings[node.first_warning:])


def _default_sensor(node: Node, shapes) -> Sensor:
    """What Mitsuba 3 does without a sensor: 45 degrees, looking along +z at the whole scene."""
    node.ctx.warn(node.element, "no <sensor>: using Mitsuba's default perspective camera "
                                "(fov 45, looking along +z at the scene's bounding box)")
    camera = Camera(fov=45.0, fov_axis="x", rfilter=Film().rfilter)
    box = bounds(shapes)
    if box is not None and np.max(box[1] - box[0]) > 0:
        center, extents = (box[0] + box[1]) / 2, box[1] - box[0]
        distance = extents.max() / (2.0 * math.tan(math.radians(45.0) / 2))
        camera.far_clip = extents.max() * 5 + distance
        camera.near_clip = distance / 100
        camera.to_world = tf.translate([center[0], center[1], box[0][2] - distance])
    return Sensor(camera, Sampler(4))


def build_integrator(node: Node) -> Integrator:
    max_depth = node.int("max_depth", -1)
    if max_depth < -1:
        raise node.fail("max_depth", f"'max_depth' must be -1 (unlimited) or >= 0, got {max_depth}")
    rr_depth = node.int("rr_depth", 5)
    if rr_depth < 1:
        raise node.fail("rr_depth", f"'rr_depth' must be >= 1, got {rr_depth}")
    return Integrator(kind=node.type, max_depth=max_depth, rr_depth=rr_depth,
                      hide_emitters=node.bool("hide_emitters", False))


def build_sensor(node: Node) -> Sensor:
    film = node.single("film")
    film = film.obj if film else Film()
    sampler = node.single("sampler")
    medium = node.single("medium")
    if node.has("fov"):
        fov = node.float("fov")
        fov_axis = node.string("fov_axis", "x").lower()
        if fov_axis not in _FOV_AXES:
            raise node.fail("fov_axis", f"'fov_axis' is {fov_axis!r}; supported: "
                            + ", ".join(_FOV_AXES))
    elif node.has("fov_axis"):
        raise node.fail("fov_axis", "'fov_axis' needs a 'fov' to apply to")
    else:
        fov, fov_axis = _DEFAULT_FOV, "diagonal"
    camera = objects.camera(node, fov=fov, fov_axis=fov_axis, width=film.width,
                            height=film.height, near=node.float("near_clip", 1e-2),
                            far=node.float("far_clip", 1e4), to_world=node.transform("to_world"),
                            rfilter=film.rfilter,
                            names={"fov": "fov", "width": None, "height": None,
                                   "near": "near_clip", "far": "far_clip",
                                   "to_world": "to_world"})
    camera.medium = medium.obj if medium else None
    camera.id = node.element.attrs.get("id", "")
    return Sensor(camera, sampler.obj if sampler else Sampler(4))


def build_film(node: Node) -> Film:
    rfilter = node.single("rfilter")
    film = Film(node.int("width", 768), node.int("height", 576))
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


# ---------------------------------------------------------------------------------------------

def build_shape(node: Node):
    bsdf = node.single("bsdf")
    bsdf = bsdf.obj if bsdf else objects.default_bsdf()
    to_world = node.transform("to_world")
    flip = node.bool("flip_normals", False)
    if node.type == "sphere":
        radius = node.positive("radius", 1.0)
        shape = sphere_shape(node.point("center", np.zeros(3)), radius, to_world, bsdf=bsdf,
                             source=node.source(), where=node.at("to_world"), flip_normals=flip)
    else:
        if node.type in PRIMITIVES:
            mesh = PRIMITIVES[node.type]()
        else:
            mesh = objects.mesh_from_file(node, "filename", node.type)
        shape = mesh_shape(mesh, to_world, bsdf=bsdf, source=node.source(),
                           where=node.at("to_world"), face_normals=node.bool("face_normals", False), flip_normals=flip)
    _attach_emitter_and_media(node, shape)
    objects.check_shape(node, shape)
    shape.id = node.element.attrs.get("id", "")
    return shape


def _attach_emitter_and_media(node: Node, shape) -> None:
    emitter = node.single("emitter")
    if emitter is not None:
        if not isinstance(emitter.obj, AreaLight):
            raise emitter.element.error("only an area emitter can be attached to a shape; "
                                        "point, directional and constant emitters go directly "
                                        "inside <scene>")
        shape.emitter_radiance = emitter.obj.radiance
        shape.emitter_id = emitter.element.attrs.get("id", "")
    for child in node.objects("medium"):
        if child.name not in ("interior", "exterior"):
            raise child.element.error(f"a medium inside a shape needs name=\"interior\" or "
                                      f"name=\"exterior\", got name={child.name!r}")
        if getattr(shape, child.name) is not None:
            raise child.element.error(f"the shape already has an {child.name} medium")
        setattr(shape, child.name, child.obj)


# ---------------------------------------------------------------------------------------------

def _diffuse(node: Node) -> Bsdf:
    reflectance = node.nonneg_color("reflectance", 0.5)
    objects.warn_if_above_one(node, "reflectance", reflectance)
    return Bsdf("diffuse", reflectance=reflectance)


def _twosided(node: Node) -> Bsdf:
    inner = node.objects("bsdf")
    if len(inner) != 1:
        raise node.fail(None, f"twosided wraps exactly one bsdf, found {len(inner)}")
    if inner[0].obj.kind in ("dielectric", "null"):
        raise inner[0].element.error(f"twosided cannot wrap a {inner[0].obj.kind} bsdf: only "
                                     f"materials without transmission can be two-sided")
    # A copy, so that a shared bsdf referenced elsewhere stays one-sided there.
    wrapped = inner[0].obj
    return replace(wrapped, twosided=True, twosided_of=wrapped.twosided_of or wrapped)


def _dielectric(node: Node) -> Bsdf:
    return Bsdf("dielectric", int_ior=objects.ior(node, "int_ior", "bk7"),
                ext_ior=objects.ior(node, "ext_ior", "air"))


def _conductor(node: Node) -> Bsdf:
    material = node.string("material", "none")
    if material != "none":
        raise node.fail("material", f"conductor material {material!r} is not supported; "
                        f"supported: \"none\" (a perfect mirror, or give eta and k as rgb)")
    bsdf = Bsdf("conductor", specular_reflectance=node.nonneg_color("specular_reflectance", 1.0))
    if node.has("eta") or node.has("k"):
        # Mitsuba's defaults when either is given: eta 0, k 1 (which is itself a perfect mirror).
        bsdf.eta = node.nonneg_color("eta", 0.0)
        bsdf.k = node.nonneg_color("k", 1.0)
    return bsdf


_BSDFS = {"diffuse": _diffuse, "twosided": _twosided, "dielectric": _dielectric,
          "conductor": _conductor, "null": lambda node: Bsdf("null")}


def build_bsdf(node: Node) -> Bsdf:
    bsdf = _BSDFS[node.type](node)
    bsdf.id = node.element.attrs.get("id", "")
    bsdf.source = node.source()
    return bsdf


# ---------------------------------------------------------------------------------------------

def _exclusive(node: Node, a: str, b: str) -> None:
    if node.has(a) and node.has(b):
        raise node.fail(b, f"give either '{a}' or '{b}', not both")


def _point(node: Node) -> Emitter:
    _exclusive(node, "position", "to_world")
    if node.has("position"):
        position = node.point("position")
    else:
        position = tf.apply_point(node.transform("to_world"), np.zeros(3))
    return Emitter("point", node.nonneg_color("intensity", 1.0), position=position,
                   source=node.source())


def _directional(node: Node) -> Emitter:
    _exclusive(node, "direction", "to_world")
    if node.has("direction"):
        direction = node.point("direction")
    else:
        direction = tf.apply_vector(node.transform("to_world"), [0.0, 0.0, 1.0])
    direction = node.checked("direction", checks.direction, direction)
    return Emitter("directional", node.nonneg_color("irradiance", 1.0), direction=direction,
                   source=node.source())


_EMITTERS = {
    "area": lambda node: AreaLight(node.nonneg_color("radiance", 1.0)),
    "point": _point,
    "directional": _directional,
    "constant": lambda node: Emitter("constant", node.nonneg_color("radiance", 1.0),
                                     source=node.source()),
}


def build_emitter(node: Node):
    emitter = _EMITTERS[node.type](node)
    if isinstance(emitter, Emitter):
        emitter.id = node.element.attrs.get("id", "")
    return emitter


# ---------------------------------------------------------------------------------------------

def build_medium(node: Node) -> Medium:
    phase = node.single("phase")
    if node.type == "homogeneous":
        sigma_t = node.nonneg_color("sigma_t", 1.0)
        albedo = node.unit_color("albedo", 0.75)
    else:
        volumes = _named_volumes(node)
        sigma_t = _volume_param(node, volumes, "sigma_t", 1.0, upper=None)
        albedo = _volume_param(node, volumes, "albedo", 0.75, upper=1.0)
        if sigma_t.kind == "const":
            # Mitsuba 3 bounds a heterogeneous medium by its sigma_t volume's box, the unit cube
            # before to_world, even for a constant; volcl renders the same image
            node.ctx.warn(node.element, "a heterogeneous medium with a constant 'sigma_t' has that "
                                        "density only inside the volume's unit cube [0,1]^3 (after its "
                                        "to_world), as in Mitsuba 3; a homogeneous medium fills its shape")
    medium = Medium(kind=node.type, sigma_t=sigma_t, albedo=albedo,
                    scale=node.positive("scale", 1.0), phase=phase.obj if phase else Phase(),
                    radiance=node.nonneg_color("volcl_radiance") if node.has("volcl_radiance")
                    else None,
                    id=node.element.attrs.get("id", ""), source=node.source())
    objects.check_medium(node, medium)
    return medium


def _named_volumes(node: Node) -> dict:
    volumes = {}
    for child in node.objects("volume"):
        if child.name not in ("sigma_t", "albedo"):
            raise child.element.error(f"a volume inside a medium needs name=\"sigma_t\" or "
                                      f"name=\"albedo\", got name={child.name!r}")
        if child.name in volumes or node.has(child.name):
            raise child.element.error(f"'{child.name}' is given twice")
        volumes[child.name] = child
    return volumes


def _volume_param(node: Node, volumes: dict, name: str, default: float, upper) -> Volume:
    if name in volumes:
        volume, where = volumes[name].obj, volumes[name].element
    else:
        volume, where = Volume("const", value=node.color(name, default)), node.at(name)
    objects.check_volume_range(where, name, volume, upper)
    return volume


def build_volume(node: Node) -> Volume:
    if node.type == "constvolume":
        return Volume("const", value=node.color("value", 1.0), to_world=node.transform("to_world"))
    data, path = objects.grid_from_file(node, "filename")
    return Volume("grid", value=rgb(0.0), data=data, to_world=node.transform("to_world"),
                  filter=node.choice("filter_type", ("trilinear", "nearest"), "trilinear"),
                  filename=path)


def build_phase(node: Node) -> Phase:
    return objects.phase_hg(node, "g", 0.8) if node.type == "hg" else Phase()


DIALECT = Dialect(
    name="mitsuba",
    property_tags=PROPERTY_TAGS - {"color"},
    specs=SPECS,
    builders={
        "scene": build_scene, "integrator": build_integrator, "sensor": build_sensor,
        "film": build_film, "rfilter": build_rfilter, "sampler": build_sampler,
        "shape": build_shape, "bsdf": build_bsdf, "emitter": build_emitter,
        "medium": build_medium, "volume": build_volume, "phase": build_phase,
    },
)
