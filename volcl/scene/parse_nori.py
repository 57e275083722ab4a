"""The Nori dialect (<scene> without a version, or a <test type="ttest"> root): table and builders.

Defaults are Nori's own (camera 1280x720, fov 30, gaussian filter of radius 2, one sample per
pixel). Nori's integrators differ only in how they estimate the same light transport, so each maps
to a volcl Integrator by what it computes: full path tracing, direct lighting, or Whitted.
"""
from __future__ import annotations

import math

import numpy as np

from . import objects
from .model import Bsdf, Emitter, Filter, Integrator, Medium, Phase, Scene, TTest
from .objects import AreaLight, Sampler
from .parse_common import Dialect, Node, Spec, medium_list
from .properties import PROPERTY_TAGS, parse_float
from .shapes import mesh_shape

# Nori integrator -> (max_depth in Mitsuba's meaning, specular chains only).
INTEGRATORS = {
    **{kind: (-1, False) for kind in ("path_mis", "path_mats", "path_ems", "vol_path")},
    **{kind: (2, False) for kind in ("direct", "direct_ems", "direct_mats", "direct_mis")},
    "whitted": (-1, True),
}

_SCENE_CHILDREN = frozenset({"integrator", "camera", "sampler", "mesh", "emitter", "medium",
                             "bsdf"})

SPECS = {
    "test": {"ttest": Spec({"references": "string", "significanceLevel": "float"},
                           children=frozenset({"scene"}), attrs=("type",))},
    "scene": {None: Spec(children=_SCENE_CHILDREN, attrs=())},
    "integrator": {kind: Spec() for kind in INTEGRATORS},
    "camera": {"perspective": Spec({"fov": "float", "width": "int", "height": "int",
                                    "nearClip": "float", "farClip": "float",
                                    "toWorld": "transform"},
                                   children=frozenset({"rfilter"}))},
    "rfilter": {"gaussian": Spec({"radius": "float", "stddev": "float"}), "box": Spec(),
                "tent": Spec()},
    "sampler": {"independent": Spec({"sampleCount": "int"})},
    "mesh": {"obj": Spec({"filename": "string", "toWorld": "transform"},
                         children=frozenset({"bsdf", "emitter"}))},
    "bsdf": {"diffuse": Spec({"albedo": "color"}), "mirror": Spec(),
             "dielectric": Spec({"intIOR": "float", "extIOR": "float"})},
    "emitter": {"area": Spec({"radiance": "color"}),
                "point": Spec({"position": "point", "power": "color"})},
    "medium": {"homogeneous": Spec({"sigma_s": "color", "sigma_t": "color", "sigma_a": "color",
                                    "g": "float", "radiance": "color"})},
}


def build_test(node: Node) -> TTest:
    text = node.string("references")
    references = [parse_float(t, node.at("references"), "references")
                  for t in text.replace(",", " ").split()]
    scenes = [c.obj for c in node.objects("scene")]
    if not scenes or len(references) != len(scenes):
        raise node.fail("references", f"a ttest needs one reference per <scene>: {len(references)} "
                                      f"references for {len(scenes)} scenes")
    significance = node.float("significanceLevel", 0.01)
    if not 0 < significance < 1:
        raise node.fail("significanceLevel", f"'significanceLevel' must lie in (0, 1), got "
                                             f"{significance}")
    return TTest(path=node.ctx.path, scenes=scenes, references=references,
                 significance=significance)


def build_scene(node: Node) -> Scene:
    for child in node.children:
        if child.element.tag == "ref":
            raise child.element.error("a <ref> directly inside <scene> has no effect; refer to "
                                      "objects from inside the mesh that uses them")
    integrator = _required(node, "integrator")
    camera = _required(node, "camera").obj
    sampler = node.single("sampler")
    sampler = sampler.obj if sampler else Sampler(1)
    shapes = [c.obj for c in node.objects("mesh")]
    emitters = []
    for child in node.objects("emitter"):
        if isinstance(child.obj, AreaLight):
            raise child.element.error("an area emitter must be placed inside the <mesh> that "
                                      "emits")
        emitters.append(child.obj)
    medium = node.single("medium")
    if medium is not None:
        # A scene-level Nori medium fills the whole scene, the inside of closed meshes included
        # (the seed report's glass sphere sits in fog and holds fog): the camera starts in it and
        # no surface changes the medium, so no shape names one.
        camera.medium = medium.obj
    return Scene(path=node.ctx.path, dialect="nori", integrator=integrator.obj, camera=camera,
                 spp=sampler.sample_count, seed=sampler.seed, shapes=shapes, emitters=emitters,
                 media=medium_list(camera.medium, shapes),
                 warnings=node.ctx.warnings[node.first_warning:])


def _required(node: Node, tag: str):
    child = node.single(tag)
    if child is None:
        options = ", ".join(sorted(SPECS[tag]))
        article = "an" if tag[0] in "aeiou" else "a"
        raise node.fail(None, f"a Nori scene needs {article} <{tag}> (supported types: {options})")
    return child


def build_integrator(node: Node) -> Integrator:
    max_depth, specular_only = INTEGRATORS[node.type]
    return Integrator(kind=node.type, max_depth=max_depth, specular_chains_only=specular_only)


def build_camera(node: Node):
    rfilter = node.single("rfilter")
    camera = objects.camera(
        node, fov=node.float("fov", 30.0), fov_axis="x", width=node.int("width", 1280),
        height=node.int("height", 720), near=node.float("nearClip", 1e-4),
        far=node.float("farClip", 1e4), to_world=node.transform("toWorld"),
        rfilter=rfilter.obj if rfilter else Filter("gaussian", radius=2.0, stddev=0.5),
        names={"fov": "fov", "width": "width", "height": "height", "near": "nearClip",
               "far": "farClip", "to_world": "toWorld"})
    camera.id = node.element.attrs.get("id", "")
    return camera


def build_rfilter(node: Node) -> Filter:
    if node.type == "gaussian":
        return Filter("gaussian", radius=node.positive("radius", 2.0),
                      stddev=node.positive("stddev", 0.5))
    return Filter(node.type, radius=0.5 if node.type == "box" else 1.0)


def build_sampler(node: Node) -> Sampler:
    return Sampler(objects.sample_count(node, "sampleCount", 1))


def build_mesh(node: Node):
    bsdf = node.single("bsdf")
    shape = mesh_shape(objects.mesh_from_file(node, "filename", "obj"), node.transform("toWorld"),
                       bsdf=bsdf.obj if bsdf else objects.default_bsdf(), source=node.source(),
                       where=node.at("toWorld"))
    emitter = node.single("emitter")
    if emitter is not None:
        if not isinstance(emitter.obj, AreaLight):
            raise emitter.element.error("only an area emitter can be attached to a mesh; point "
                                        "lights go directly inside <scene>")
        shape.emitter_radiance = emitter.obj.radiance
    objects.check_shape(node, shape)
    shape.id = node.element.attrs.get("id", "")
    return shape


def build_bsdf(node: Node) -> Bsdf:
    if node.type == "diffuse":
        albedo = node.nonneg_color("albedo", 0.5)
        objects.warn_if_above_one(node, "albedo", albedo)
        bsdf = Bsdf("diffuse", reflectance=albedo)
    elif node.type == "mirror":
        bsdf = Bsdf("conductor")       # eta None: a perfect mirror
    else:
        bsdf = Bsdf("dielectric", int_ior=objects.ior(node, "intIOR", 1.5046),
                    ext_ior=objects.ior(node, "extIOR", 1.000277))
    bsdf.id = node.element.attrs.get("id", "")
    bsdf.source = node.source()
    return bsdf


def build_emitter(node: Node):
    if node.type == "area":
        return AreaLight(node.nonneg_color("radiance"))
    power = node.nonneg_color("power")
    return Emitter("point", power / (4.0 * math.pi),
                   position=node.point("position", np.zeros(3)), source=node.source(),
                   id=node.element.attrs.get("id", ""))


def build_medium(node: Node) -> Medium:
    sigma_s = node.nonneg_color("sigma_s")
    if node.has("sigma_t") == node.has("sigma_a"):
        raise node.fail(None, "a Nori medium needs exactly one of 'sigma_t' or 'sigma_a' "
                              "(besides 'sigma_s')")
    if node.has("sigma_a"):
        sigma_t = sigma_s + node.nonneg_color("sigma_a")
    else:
        sigma_t = node.nonneg_color("sigma_t")
        if (sigma_s > sigma_t * (1 + 1e-6)).any():
            raise node.fail("sigma_t", f"sigma_s {sigma_s.tolist()} exceeds sigma_t "
                                       f"{sigma_t.tolist()}: the albedo would be above 1")
    positive = sigma_t > 0
    albedo = np.where(positive, np.minimum(sigma_s / np.where(positive, sigma_t, 1.0), 1.0), 0.0)
    phase = objects.phase_hg(node, "g", 0.0)
    medium = Medium(kind="homogeneous", sigma_t=sigma_t, albedo=albedo,
                    phase=phase if phase.g != 0 else Phase(),
                    radiance=node.nonneg_color("radiance") if node.has("radiance") else None,
                    id=node.element.attrs.get("id", ""), source=node.source())
    objects.check_medium(node, medium)
    return medium


DIALECT = Dialect(
    name="nori",
    property_tags=PROPERTY_TAGS - {"rgb"},
    specs=SPECS,
    builders={
        "test": build_test, "scene": build_scene, "integrator": build_integrator,
        "camera": build_camera, "rfilter": build_rfilter, "sampler": build_sampler,
        "mesh": build_mesh, "bsdf": build_bsdf, "emitter": build_emitter,
        "medium": build_medium,
    },
)
