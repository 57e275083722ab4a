"""The Mitsuba dialect (<scene version="...">, versions 2.x and 3.x; volcl.scene.mitsuba_files has
what happens to the file before this): its plugin table and the builders behind it.

Defaults and rules follow Mitsuba 3.9 (its documentation, and its source where that is silent), so
a file renders to the same expected image in both renderers, bugs included. volcl's own extensions
carry a `volcl_` prefix here so that Mitsuba reports them instead of misreading them. Sensors live
in mitsuba_sensors, shapes in mitsuba_shapes.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from . import checks, mitsuba_bsdfs, mitsuba_instances, mitsuba_sensors, mitsuba_shapes, objects, textures, transform as tf
from .model import (Camera, Emitter, Integrator, Medium, Phase, Scene, Sensor, Volume, rgb,
                    select_sensor)
from .objects import AreaLight
from .images import read_image
from .parse_common import Dialect, Node, Spec, medium_list
from .phases import SPECS as PHASE_SPECS, build_phase
from .properties import PROPERTY_TAGS
from .shapes import bounds

_TO_WORLD = {"to_world": "transform"}
_MEDIUM_PARAMS = {"sigma_t": "color", "albedo": "color", "scale": "float",
                  "has_spectral_extinction": "bool", "volcl_radiance": "color",
                  "volcl_temperature": "float", "volcl_temperature_scale": "float",
                  "volcl_temperature_offset": "float", "volcl_emission_scale": "float"}
# the volumes a heterogeneous medium may hold, and whether each must be a one-channel (float) grid
_MEDIUM_VOLUMES = {"sigma_t": False, "albedo": False, "volcl_radiance": False, "volcl_temperature": True}
_MEDIUM_NOTES = {"sample_emitters": "volcl always samples emitters from medium vertices; the expected "
                                    "image is the same, only the noise differs"}
_PATH_PARAMS = {"max_depth": "int", "rr_depth": "int", "hide_emitters": "bool"}
_INTEGRATOR_NOTES = {
    "timeout": "volcl renders the scene's sample count; use --time-limit to stop after a time",
    "samples_per_pass": "volcl chooses its own passes (the image does not depend on them)",
    "block_size": "volcl chooses its own launch sizes (the image does not depend on them)",
}

SPECS = {
    # films, filters and samplers at the top level do nothing until a sensor refers to them by id
    "scene": {None: Spec(attrs=("version", "id"), children=frozenset(
        {"integrator", "sensor", "shape", "bsdf", "emitter", "medium", "volume", "phase", "film",
         "rfilter", "sampler", "texture"}))},
    "integrator": {
        "path": Spec(_PATH_PARAMS, ignored=_INTEGRATOR_NOTES),
        "volpath": Spec(_PATH_PARAMS, ignored=_INTEGRATOR_NOTES),
        "volpathmis": Spec(_PATH_PARAMS, ignored={
            **_INTEGRATOR_NOTES, "use_spectral_mis": "volcl renders RGB with its own channel mixture "
                                                     "for distance sampling (same expected image)"}),
        "direct": Spec({"emitter_samples": "int", "bsdf_samples": "int", "shading_samples": "int",
                        "hide_emitters": "bool"}, ignored=_INTEGRATOR_NOTES),
        "moment": Spec(children=frozenset({"integrator"})),
    },
    **mitsuba_sensors.SPECS,
    "shape": mitsuba_shapes.SPECS,
    "bsdf": mitsuba_bsdfs.SPECS,
    "texture": textures.SPECS,
    "emitter": {
        "area": Spec({"radiance": "color"}),
        "point": Spec({"intensity": "color", "position": "point", **_TO_WORLD}),
        "directional": Spec({"irradiance": "color", "direction": "point", **_TO_WORLD}),
        "constant": Spec({"radiance": "color"}),
        "spot": Spec({"intensity": "color", "cutoff_angle": "float", "beam_width": "float", **_TO_WORLD},
                     children=frozenset({"texture"})),
        "envmap": Spec({"filename": "string", "scale": "float", **_TO_WORLD}, ignored={
            "mis_compensation": "volcl samples the map by its luminance as given (the expected image is the "
                                "same, only the noise differs)"}),
    },
    "medium": {
        "homogeneous": Spec(_MEDIUM_PARAMS, children=frozenset({"phase"}), ignored=_MEDIUM_NOTES),
        "heterogeneous": Spec(_MEDIUM_PARAMS, children=frozenset({"phase", "volume"}),
                              ignored=_MEDIUM_NOTES),
    },
    "volume": {
        "gridvolume": Spec({"filename": "string", "filter_type": "string", "wrap_mode": "string",
                            "use_grid_bbox": "bool", "max_value": "float", **_TO_WORLD},
                           ignored={"raw": "in RGB rendering the grid's values are used as they are either way",
                                    "accel": "volcl uses its own lookups (same values)"}),
        "constvolume": Spec({"value": "color", **_TO_WORLD}),
        "volcl_vdb": Spec({"filename": "string", "grid": "string", "filter_type": "string", **_TO_WORLD}),
    },
    "phase": PHASE_SPECS,
}


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
    shapes, instances = mitsuba_instances.scene_shapes([c.obj for c in node.objects("shape")])
    sensors = [c.obj for c in node.objects("sensor")] or [_default_sensor(node, shapes, instances)]
    if len(sensors) > 1:
        ctx.warn(node.objects("sensor")[1].element,
                 f"the scene has {len(sensors)} sensors; volcl renders the first (line "
                 f"{sensors[0].source.line}) unless --sensor N picks another (0 to {len(sensors) - 1})")
    emitters = []
    for child in node.objects("emitter"):
        if isinstance(child.obj, AreaLight):
            # as in Mitsuba: a surface emitter emits from the shapes that refer to it (by id)
            if not child.obj.attached:
                ctx.warn(child.element, "an area emitter at the top level emits only from the shapes "
                                        "that refer to it (<ref id=...> inside a <shape>), and no shape "
                                        "does: it emits nothing, as in Mitsuba")
            continue
        emitters.append(child.obj)
    _one_environment(node)
    scene = Scene(path=ctx.path, dialect="mitsuba",
                  integrator=integrator.obj if integrator else Integrator(),
                  shapes=shapes, emitters=emitters, sensors=sensors, instances=instances,
                  warnings=ctx.warnings[node.first_warning:])
    select_sensor(scene, 0)
    _check_integrator(node, scene)
    _environment_through_unbounded_medium(node, scene)
    scene.warnings = ctx.warnings[node.first_warning:]
    return scene


def _one_environment(node: Node) -> None:
    """Mitsuba allows one environment emitter per scene. volcl adds up several constants (its older
    rule, which renders what their sum would), but an envmap stands alone, as in Mitsuba."""
    env = [c for c in node.objects("emitter") if getattr(c.obj, "kind", "") in ("constant", "envmap")]
    if len(env) > 1 and any(c.obj.kind == "envmap" for c in env):
        first = env[0].element
        raise env[1].element.error(f"only one environment emitter (envmap or constant) can be specified per "
                                   f"scene, as in Mitsuba; the first is at line {first.line}")


def _environment_through_unbounded_medium(node: Node, scene: Scene) -> None:
    """A camera medium that no shape bounds in some direction fills space out to infinity: no light
    of an environment emitter gets through it (volcl's answer). Mitsuba 3.9 stops its shadow rays
    towards the environment at twice the scene's bounding radius, so its next-event estimate sees
    the environment dimmed over that distance only (while its phase-sampled rays never escape): a
    different image, which depends on the scene's size."""
    medium = scene.camera.medium
    if medium is None or not any(e.kind in ("constant", "envmap") for e in scene.emitters):
        return
    from ..features import escapes_unbounded
    if escapes_unbounded(scene, scene.camera.to_world[:3, 3]):
        node.ctx.warn(node.element, "the camera's medium is not enclosed by a shape (it reaches to infinity in "
                                    "some direction), so no light of the environment arrives through it; Mitsuba "
                                    "3.9 counts the environment's direct light through such a medium as if it "
                                    "ended at twice the scene's bounding radius (a brighter image, which depends "
                                    "on the scene's size). Bound the medium with a shape (e.g. a null sphere) to "
                                    "render the same image in both")


def _default_sensor(node: Node, shapes, instances) -> Sensor:
    """What Mitsuba 3 does without a sensor: 45 degrees, looking along +z at the whole scene."""
    node.ctx.warn(node.element, "no <sensor>: using Mitsuba's default perspective camera "
                                "(fov 45, looking along +z at the scene's bounding box)")
    camera = Camera(fov=45.0, fov_axis="x", rfilter=mitsuba_sensors.Film().rfilter)
    boxes = [b for b in [bounds([s for s in shapes if s.group is None])] if b is not None]
    boxes += mitsuba_instances.instance_bounds(instances, bounds)
    box = (np.min([b[0] for b in boxes], 0), np.max([b[1] for b in boxes], 0)) if boxes else None
    if box is not None and np.max(box[1] - box[0]) > 0:
        center, extents = (box[0] + box[1]) / 2, box[1] - box[0]
        distance = extents.max() / (2.0 * math.tan(math.radians(45.0) / 2))
        camera.far_clip = extents.max() * 5 + distance
        camera.near_clip = distance / 100
        camera.to_world = tf.translate([center[0], center[1], box[0][2] - distance])
    return Sensor(camera, 4, 0, node.source())


def _check_integrator(node: Node, scene: Scene) -> None:
    integ = scene.integrator
    if integ.kind == "path":
        _path_integrator(node, scene)
    if integ.kind == "volpath" and integ.hide_emitters and scene.media:
        node.ctx.warn(node.element, "hide_emitters with volpath and media: camera rays pass through area "
                                    "emitters as in Mitsuba, but volcl samples the medium beyond them, "
                                    "which Mitsuba's volpath skips")
    if integ.kind != "direct":
        return
    delta = [e for e in scene.emitters if e.kind in ("point", "spot", "directional")]
    if integ.emitter_samples > 1 and delta:
        node.ctx.warn(node.element, f"direct with emitter_samples={integ.emitter_samples}: Mitsuba 3.9 counts "
                                    f"each sample of a point, spot or directional light at full weight, so these "
                                    f"lights come out {integ.emitter_samples}x as bright as with one sample; "
                                    f"volcl renders what Mitsuba renders")
    # Mitsuba's direct integrator traces surfaces only: media are not sampled and a null boundary
    # is shaded like a surface; volcl refuses rather than render something else
    culprit = next((s for s in scene.shapes if s.bsdf.kind == "null" or s.interior or s.exterior), None)
    if scene.media or culprit is not None:
        where = culprit.source if culprit is not None else None
        raise node.fail(None, "the 'direct' integrator with participating media or null boundaries"
                        + (f" (first: {where})" if where else "")
                        + ": Mitsuba's direct integrator ignores media and treats null boundaries as "
                          "surfaces; use volpath (max_depth 2 for direct lighting)")


def _path_integrator(node: Node, scene: Scene) -> None:
    """Mitsuba's path integrator is a surface integrator: it ignores participating media, and counts
    a crossing of a null surface as a bounce."""
    if scene.media or any(s.camera.medium for s in scene.sensors):
        node.ctx.warn(node.element, "Mitsuba's path integrator ignores participating media (volpath "
                                    "renders them); volcl renders what Mitsuba renders, without them")
        for shape in scene.shapes:
            shape.interior = shape.exterior = None
        for sensor in scene.sensors:
            sensor.camera.medium = None
        scene.media = []
    if scene.integrator.max_depth >= 0 and any(s.bsdf.kind in ("null", "mask", "thindielectric")
                                               for s in scene.shapes):
        node.ctx.warn(node.element, "Mitsuba's path integrator counts each crossing of a null surface as a "
                                    "bounce towards max_depth (and each pass through a mask or thin "
                                    "dielectric), volcl does not: such paths can be longer in volcl than in "
                                    "Mitsuba (use volpath, which counts as volcl does)")


def _positive_count(node: Node, name: str, default: int) -> int:
    value = node.int(name, default)
    if value < 0:
        raise node.fail(name, f"'{name}' must be >= 0, got {value}")
    return value


def build_integrator(node: Node) -> Integrator:
    if node.type == "moment":
        return _moment(node)
    if node.type == "direct":
        return _direct(node)
    max_depth = node.int("max_depth", -1)
    if max_depth < -1:
        raise node.fail("max_depth", f"'max_depth' must be -1 (unlimited) or >= 0, got {max_depth}")
    rr_depth = node.int("rr_depth", 5)
    if rr_depth < 1:
        raise node.fail("rr_depth", f"'rr_depth' must be >= 1, got {rr_depth}")
    return Integrator(kind=node.type, max_depth=max_depth, rr_depth=rr_depth,
                      hide_emitters=node.bool("hide_emitters", False))


def _direct(node: Node) -> Integrator:
    if node.has("shading_samples") and (node.has("emitter_samples") or node.has("bsdf_samples")):
        raise node.fail("shading_samples", "give either 'shading_samples' or 'emitter_samples' / "
                                           "'bsdf_samples', not both")
    shading = _positive_count(node, "shading_samples", 1)
    emitter_samples = _positive_count(node, "emitter_samples", shading)
    bsdf_samples = _positive_count(node, "bsdf_samples", shading)
    if emitter_samples + bsdf_samples == 0:
        raise node.fail(None, "the direct integrator needs at least one emitter or bsdf sample")
    # direct lighting: depth 2 in Mitsuba's counting, no Russian roulette within it
    return Integrator(kind="direct", max_depth=2, rr_depth=1 << 30,
                      hide_emitters=node.bool("hide_emitters", False),
                      emitter_samples=emitter_samples, bsdf_samples=bsdf_samples)


def _moment(node: Node) -> Integrator:
    inner = node.objects("integrator")
    if not inner:
        raise node.fail(None, "the moment integrator wraps an integrator, found none")
    if inner[0].obj.moment:
        raise inner[0].element.error("a moment integrator inside a moment integrator is not supported")
    for extra in inner[1:]:
        node.ctx.warn(extra.element, "the moment integrator wraps several integrators; volcl renders the "
                                     "first one only (its image is Mitsuba's image too)")
    node.ctx.warn(node.element, "moment: volcl renders the wrapped integrator and writes the second "
                                "moment of each pixel's samples as the EXR layer m2.R/G/B (linear RGB; "
                                "Mitsuba writes its moments as XYZ layers)")
    return replace(inner[0].obj, moment=True)


# ---------------------------------------------------------------------------------------------

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
    return Emitter("point", node.nonneg_color("intensity", 1.0, kind="emission"), position=position,
                   source=node.source())


def _directional(node: Node) -> Emitter:
    _exclusive(node, "direction", "to_world")
    if node.has("direction"):
        direction = node.point("direction")
    else:
        direction = tf.apply_vector(node.transform("to_world"), [0.0, 0.0, 1.0])
    direction = node.checked("direction", checks.direction, direction)
    return Emitter("directional", node.nonneg_color("irradiance", 1.0, kind="emission"), direction=direction,
                   source=node.source())


def _spot(node: Node) -> Emitter:
    """Mitsuba's spot: at to_world's origin, along its +z; full intensity within beam_width (default
    3/4 of cutoff_angle), falling linearly in angle to zero at cutoff_angle (degrees)."""
    to_world = node.transform("to_world")
    cutoff = node.checked("cutoff_angle", checks.spot_cutoff, node.float("cutoff_angle", 20.0))
    beam = node.checked("beam_width", checks.spot_beam, node.float("beam_width", cutoff * 0.75))
    if beam > cutoff:
        node.ctx.warn(node.at("beam_width"), f"'beam_width' {beam:g} exceeds 'cutoff_angle' {cutoff:g}: the spot "
                                             f"is a hard-edged cone of the cutoff angle, as in Mitsuba")
    # Mitsuba's projection texture: the spot's intensity times the texture at the direction's place
    # in the cone's square (kernels/lights.h spot_texture_uv); only a texture element, as Mitsuba
    # refuses a constant one
    textures.check_texture_names(node, ("texture",))
    child = textures.texture_child(node, "texture")
    return Emitter("spot", node.nonneg_color("intensity", 1.0, kind="emission"),
                   position=tf.apply_point(to_world, np.zeros(3)), to_world=to_world, cutoff_angle=cutoff,
                   beam_width=beam, source=node.source(), texture=child.obj if child is not None else None)


def _envmap(node: Node) -> Emitter:
    """Mitsuba's envmap: a latitude-longitude image (any aspect ratio, as Mitsuba reads it) times
    `scale`, turned by to_world (volcl.envmap, kernels/envmap.h)."""
    path = objects.resolve_path(node, "filename", "environment map")
    image = read_image(path, where=lambda message: node.fail("filename", message))
    scale = node.float("scale", 1.0)
    if not scale >= 0:
        raise node.fail("scale", f"'scale' must be >= 0, got {scale}")
    peak = float(image.max()) * scale if image.size else 0.0
    if not peak <= checks.FLOAT32_MAX:
        raise node.fail("scale", f"the environment map's brightest texel times 'scale' is {peak:.4g}, beyond the "
                                 f"single-precision range volcl renders in (<= {checks.FLOAT32_MAX:.7g})")
    to_world = node.checked("to_world", checks.envmap_transform, node.transform("to_world"))
    height, width = image.shape[:2]
    if width != 2 * height:
        node.ctx.warn(node.at("filename"), f"the environment map {path} is {width}x{height} texels, not 2:1: it is "
                                           f"read as a latitude-longitude map all the same (columns over 360 "
                                           f"degrees of longitude, rows over 180 of latitude), as Mitsuba reads it")
    return Emitter("envmap", rgb(1.0), to_world=to_world, image=image, scale=scale, filename=path,
                   source=node.source())


_EMITTERS = {
    "area": lambda node: AreaLight(node.nonneg_color("radiance", 1.0, kind="emission")),
    "point": _point,
    "spot": _spot,
    "envmap": _envmap,
    "directional": _directional,
    "constant": lambda node: Emitter("constant", node.nonneg_color("radiance", 1.0, kind="emission"),
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
    volumes = {}
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
                    radiance=node.nonneg_color("volcl_radiance", kind="emission")
                    if node.has("volcl_radiance") else None,
                    id=node.element.attrs.get("id", ""), source=node.source())
    _emission(node, medium, volumes)
    objects.check_medium(node, medium)
    _spectral_extinction(node, medium)
    return medium


def _spectral_extinction(node: Node, medium: Medium) -> None:
    """Mitsuba's has_spectral_extinction=false skips the per-channel weighting of distance sampling:
    right for a grey extinction (where the flag only saves work), a different image otherwise."""
    if not node.has("has_spectral_extinction"):
        return
    from ..features import _chromatic
    where = node.at("has_spectral_extinction")
    if node.bool("has_spectral_extinction") or not _chromatic(medium.sigma_t):
        node.ctx.warn(where, "'has_spectral_extinction' is ignored: volcl compiles the chromatic-extinction "
                             "code only where the extinction differs between channels (same image)")
    else:
        node.ctx.warn(where, "has_spectral_extinction=false with an extinction that differs between colour "
                             "channels: Mitsuba then samples distances as if every channel had the sampled "
                             "channel's extinction (a different image); volcl renders the chromatic "
                             "extinction as given")


def _named_volumes(node: Node) -> dict:
    volumes = {}
    for child in node.objects("volume"):
        if child.name not in _MEDIUM_VOLUMES:
            raise child.element.error("a volume inside a medium needs name=" + ", ".join(
                f'"{n}"' for n in _MEDIUM_VOLUMES) + f", got name={child.name!r}")
        if child.name in volumes or node.has(child.name):
            raise child.element.error(f"'{child.name}' is given twice")
        if _MEDIUM_VOLUMES[child.name] or child.name == "sigma_t" and child.obj.kind == "sparse":
            _one_channel(child)
        volumes[child.name] = child
    return volumes


def _one_channel(child) -> None:
    v = child.obj
    if v.kind != "const" and v.channels != 1:
        what = (f"grid '{v.grid_name}' of {v.filename} holds {v.sparse.value_type} values"
                if v.kind == "sparse" else f"{v.filename} holds {v.channels} channels")
        raise child.element.error(f"'{child.name}' needs a float grid, but {what}; choose a float grid "
                                  f"(density, temperature, ...)")


def _emission(node: Node, medium: Medium, volumes: dict) -> None:
    """volcl_radiance (a colour, or a volume in a heterogeneous medium) or volcl_temperature (a float,
    or a volume in a heterogeneous medium, with pbrt-v4's blackbody meaning: volcl.blackbody), each
    times volcl_emission_scale. A constant temperature becomes the radiance of its blackbody."""
    from .. import blackbody
    temp_params = ("volcl_temperature_scale", "volcl_temperature_offset")
    has_temp = node.has("volcl_temperature") or "volcl_temperature" in volumes
    has_radiance = node.has("volcl_radiance") or "volcl_radiance" in volumes
    if has_temp and has_radiance:
        where = volumes["volcl_temperature"].element if "volcl_temperature" in volumes else node.at("volcl_temperature")
        raise where.error("a medium emits from 'volcl_radiance' or from 'volcl_temperature', not both")
    for name in temp_params:
        if node.has(name) and not has_temp:
            node.ctx.warn(node.at(name), f"'{name}' is ignored: the medium has no 'volcl_temperature'")
    medium.emission_scale = node.checked("volcl_emission_scale", checks.nonneg, "volcl_emission_scale",
                                         node.float("volcl_emission_scale", 1.0))
    medium.temperature_scale = node.checked("volcl_temperature_scale", checks.nonneg, "volcl_temperature_scale",
                                            node.float("volcl_temperature_scale", 1.0))
    medium.temperature_offset = node.float("volcl_temperature_offset", 0.0)
    if not np.isfinite(medium.temperature_offset):
        raise node.fail("volcl_temperature_offset", "'volcl_temperature_offset' must be finite")
    if node.has("volcl_emission_scale") and not (has_temp or has_radiance):
        node.ctx.warn(node.at("volcl_emission_scale"), "'volcl_emission_scale' is ignored: the medium "
                                                       "has no 'volcl_radiance' or 'volcl_temperature'")
    for name in ("volcl_radiance", "volcl_temperature"):
        if name in volumes and volumes[name].obj.kind != "const":
            medium.emission_kind = name[len("volcl_"):]
            medium.emission_volume = volumes[name].obj
            objects.check_volume_range(volumes[name].element, name, medium.emission_volume, None)
            return
    if has_temp:
        value = (float(volumes["volcl_temperature"].obj.value[0]) if "volcl_temperature" in volumes
                 else node.float("volcl_temperature"))
        t = (value - medium.temperature_offset) * medium.temperature_scale
        medium.radiance = medium.emission_scale * blackbody.rgb(t)
    elif "volcl_radiance" in volumes:
        medium.radiance = medium.emission_scale * np.asarray(volumes["volcl_radiance"].obj.value, np.float64)
    elif medium.radiance is not None:
        medium.radiance = medium.emission_scale * medium.radiance


def _volume_param(node: Node, volumes: dict, name: str, default: float, upper) -> Volume:
    if name in volumes:
        volume, where = volumes[name].obj, volumes[name].element
    else:
        volume, where = Volume("const", value=node.color(name, default)), node.at(name)
    objects.check_volume_range(where, name, volume, upper)
    return volume


def build_volume(node: Node) -> Volume:
    if node.type == "constvolume":
        return Volume("const", value=node.color("value", 1.0, kind="unbounded"),
                      to_world=node.transform("to_world"))
    if node.type == "volcl_vdb":
        return objects.vdb_volume(node)
    node.choice("wrap_mode", ("clamp",), "clamp")
    data, path, bbox = objects.grid_from_file(node, "filename")
    to_world = node.transform("to_world")
    if node.bool("use_grid_bbox", False):
        # the grid fills the box stored in its file instead of the unit cube, before to_world
        lo, hi = bbox
        if not np.all(hi > lo):
            raise node.fail("use_grid_bbox", f"use_grid_bbox: the bounding box in {path} is empty "
                                             f"({lo.tolist()} to {hi.tolist()})")
        to_world = to_world @ tf.translate(lo) @ tf.scale(hi - lo)
    if node.has("max_value"):
        node.ctx.warn(node.at("max_value"), "'max_value' is ignored: volcl bounds the grid by its own "
                                            "majorants (Mitsuba's image is biased if max_value is below the "
                                            "grid's largest value)")
    return Volume("grid", value=rgb(0.0), data=data, to_world=to_world,
                  filter=node.choice("filter_type", ("trilinear", "nearest"), "trilinear"),
                  filename=path)


DIALECT = Dialect(
    name="mitsuba",
    property_tags=PROPERTY_TAGS - {"color"},
    specs=SPECS,
    builders={
        "scene": build_scene, "integrator": build_integrator,
        "sensor": mitsuba_sensors.build_sensor, "film": mitsuba_sensors.build_film,
        "rfilter": mitsuba_sensors.build_rfilter, "sampler": mitsuba_sensors.build_sampler,
        "shape": mitsuba_shapes.build_shape, "bsdf": mitsuba_bsdfs.build_bsdf, "emitter": build_emitter,
        "texture": textures.build_texture,
        "medium": build_medium, "volume": build_volume, "phase": build_phase,
    },
    rotate_axis_as_given=True,
)
