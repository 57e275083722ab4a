"""Editable scene parameters: what volcl.traverse returns.

Keys are "<object>.<parameter>", named as Mitsuba 3's traverse names them where the meaning is the
same: "fog.sigma_t.value", "white.reflectance.value", "light.intensity.value", "floor.to_world",
"sensor.to_world", "fog.phase_function.g". An object is named by its id; one without an id by the
object that holds it ("floor.bsdf", "box.interior_medium", "lamp.emitter", "sensor.medium"), and a
shape, emitter or sensor without one by its kind and place in the scene ("shape_3", "emitter_0",
"sensor").

Which parameters an object has follows the scene model (volcl.scene.model): PARAMETERS maps each
model class to a function listing the parameters of one object of it, so a new kind of object
brings its parameters along by adding an entry. Every parameter says which packed arrays
(volcl.pack.PARTS) its value goes into; `update()` repacks those parts only and uploads the arrays
whose bytes changed (volcl.prepared.Scene.apply). A value is checked when it is set, by the same
rules and with the same messages as in a scene file (volcl.scene.checks).
"""
from __future__ import annotations

import difflib
import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, Callable

import numpy as np

from . import features as feat
from .errors import VolclError
from .pack_materials import chain, texture_tree, textures_of
from .scene import checks
from .scene.checks import CheckError
from .scene.model import Bsdf, Camera, Emitter, Medium, Phase, Scene as ModelScene, Shape, Texture, Volume, rgb
from .scene.objects import IOR_NAMES
from .scene.shapes import place


class UnknownParameter(VolclError, KeyError):
    """A key the scene has no parameter for; the message lists those it has."""

    __str__ = Exception.__str__


class FeatureChange(UserWarning):
    """An update changed the kernel features the scene needs: a render builds another program."""


# What each kind of value must be, in the words the parser uses for file values (with the Python
# form beside them).
KINDS = {
    "float": "a <float> (a Python number)",
    "color": "a colour (<rgb>/<color>, <spectrum> or <float>: three numbers or one)",
    "point": "a <point> or <vector> (three numbers)",
    "transform": "a <transform> (a 4x4 matrix)",
    "ior": "a <float> or a <string> material name",
    "grid": "a grid of values (a numpy array of the grid's shape)",
    "image": "an image's texels (a numpy array of the image's shape: height, width, channels)",
    "uv_transform": "a 3x3 affine map of texture coordinates (last row 0 0 1)",
}


@dataclass
class Param:
    """One editable value: its key, kind, how to read and write it in the model, the packed
    parts it lands in, and the object it belongs to (for messages)."""
    key: str
    name: str                       # the parameter's own name, as a file writes it
    kind: str
    get: Callable[[], Any]
    set: Callable[[Any], None]      # takes the converted value; raises CheckError
    parts: tuple
    owner: tuple                    # ('<medium type="homogeneous">', "medium 'fog' at scenes/fog.xml:16")
    shape: tuple | None = None      # grid parameters: the array shape a value must have


# -- converting Python values ------------------------------------------------------------------

def _type_error(param: Param, value) -> CheckError:
    return CheckError(f"parameter '{param.name}' of {param.owner[0]} must be {KINDS[param.kind]}, not "
                      f"{type(value).__name__} {_short(value)}")


def _short(value) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _number(value) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def _floats(param: Param, value, counts) -> np.ndarray:
    if _number(value):
        value = [value]
    try:
        a = np.asarray(value)
    except Exception:
        raise _type_error(param, value) from None
    if a.dtype.kind not in "iuf" or a.ndim > 1 or a.size not in counts:
        raise _type_error(param, value)
    a = a.astype(np.float64).reshape(-1)
    for x in a:
        checks.finite(f"'{param.name}'", float(x), str(x))
    return a


def convert(param: Param, value):
    """`value` as the model holds it, or CheckError."""
    kind = param.kind
    if kind == "float":
        if not _number(value) and not (isinstance(value, np.ndarray) and value.size == 1):
            raise _type_error(param, value)
        return checks.finite(f"'{param.name}'", float(value), str(value))
    if kind == "ior":
        if isinstance(value, str):
            key = value.strip().lower()
            if key not in IOR_NAMES:
                raise CheckError(f"unknown IOR name {value!r} for '{param.name}'; supported: "
                                 + ", ".join(IOR_NAMES) + ", or a number")
            return IOR_NAMES[key]
        return convert(replace(param, kind="float"), value)
    if kind == "color":
        a = _floats(param, value, (1, 3))
        return rgb(a[0]) if a.size == 1 else a
    if kind == "point":
        return _floats(param, value, (3,))
    if kind == "transform":
        try:
            m = np.asarray(value, dtype=np.float64)
        except Exception:
            raise _type_error(param, value) from None
        if m.shape != (4, 4):
            raise _type_error(param, value)
        for x in m.reshape(-1):
            checks.finite("matrix", float(x), str(x))
        if np.abs(m[3] - [0, 0, 0, 1]).max() > 0:
            raise CheckError(f"matrix: the last row must be 0 0 0 1 (affine), got {m[3].tolist()}")
        return checks.invertible(param.name, m)
    if kind == "image":
        # texture texels and environment maps alike: a shape kept, finite and non-negative texels
        if not isinstance(value, np.ndarray) or value.dtype.kind not in "iuf":
            raise _type_error(param, value)
        what = "texture" if "bsdfs" in param.parts else "image"
        if value.shape != param.shape:
            raise CheckError(f"'{param.name}' must keep the {what}'s shape {param.shape} (height, width, "
                             f"channels), got {value.shape}; load another image file to change it")
        a = np.array(value, dtype=np.float32)
        bad = ~np.isfinite(a) | (a < 0)
        if bad.any():
            y, x, c = (int(i) for i in np.argwhere(bad)[0])
            v = float(a[y, x, c])
            raise CheckError(f"'{param.name}' has a {'negative' if v < 0 else 'non-finite'} texel {v!r} at x={x} "
                             f"y={y} channel={c}; {what}s need finite, non-negative values")
        return a
    if kind == "uv_transform":
        try:
            m = np.asarray(value, dtype=np.float64)
        except Exception:
            raise _type_error(param, value) from None
        if m.shape != (3, 3):
            raise _type_error(param, value)
        for x in m.reshape(-1):
            checks.finite("to_uv", float(x), str(x))
        if np.abs(m[2] - [0, 0, 1]).max() > 0:
            raise CheckError(f"to_uv: the last row must be 0 0 1 (affine), got {m[2].tolist()}")
        return m
    if kind == "grid":
        if not isinstance(value, np.ndarray) or value.dtype.kind not in "iuf":
            raise _type_error(param, value)
        if value.shape != param.shape:
            raise CheckError(f"'{param.name}' must keep the grid's shape {param.shape} (z, y, x, channels), "
                             f"got {value.shape}; load another volume file to change it")
        a = np.array(value, dtype=np.float32)
        if not np.isfinite(a).all():
            raise CheckError(f"'{param.name}': the grid holds values that are not finite numbers")
        return a
    raise AssertionError(kind)


# -- the parameters of each kind of object -----------------------------------------------------

def _owner(label: str, obj, what: str) -> tuple:
    """(the element label messages name the parameter by, where the object was defined)."""
    ident = getattr(obj, "id", "")
    text = f"the {what} '{ident}'" if ident else f"the {what}"
    source = getattr(obj, "source", None)
    if source is None:
        return label, text
    return f"<{source.element}>", f"{text} at {source.file}:{source.line}"


# bsdf kind -> its colour parameters that may be textures: (name in files, model attribute)
_BSDF_COLOURS = {
    "diffuse": (("reflectance", "reflectance"),),
    "conductor": (("specular_reflectance", "specular_reflectance"), ("eta", "eta"), ("k", "k")),
    "dielectric": (("specular_reflectance", "specular_reflectance"),
                   ("specular_transmittance", "specular_transmittance")),
    "plastic": (("diffuse_reflectance", "reflectance"), ("specular_reflectance", "specular_reflectance")),
}
_BSDF_COLOURS.update(roughconductor=_BSDF_COLOURS["conductor"], roughdielectric=_BSDF_COLOURS["dielectric"],
                     thindielectric=_BSDF_COLOURS["dielectric"], roughplastic=_BSDF_COLOURS["plastic"])
_WITH_IORS = ("dielectric", "roughdielectric", "thindielectric", "plastic", "roughplastic")
_DISTINCT_IORS = ("roughdielectric", "roughplastic")   # Mitsuba refuses int_ior == ext_ior for these


def _bsdf_params(scene: ModelScene, bsdf: Bsdf, prefix: str, named=None):
    """A two-sided bsdf is a copy of the one it wraps (parse_mitsuba): an edit reaches both, as an
    edit of the file would. Textures give their own parameters under the parameter's name (or
    their id); a wrapped bsdf (mask, bump and normal maps) under `nested_bsdf` (or its id)."""
    root = bsdf.twosided_of or bsdf
    group = [root] + [s.bsdf for s in scene.shapes if s.bsdf.twosided_of is root and s.bsdf is not root]
    group = list({id(b): b for b in group}.values())
    owner = _owner(f"<bsdf type=\"{bsdf.kind}\">", bsdf, "bsdf")
    named = {} if named is None else named

    def field_param(key, name, attr, kind, rule=None):
        def get():
            value = getattr(bsdf, attr)
            return value.copy() if isinstance(value, np.ndarray) else float(value)

        def put(value):
            if rule is not None:
                rule(name, value)
            if name == "reflectance" and (value > 1).any():
                warnings.warn(f"{prefix}.{key}: '{name}' {value.tolist()} exceeds 1: the surface reflects "
                              f"more light than it receives", stacklevel=4)
            if attr in ("int_ior", "ext_ior") and bsdf.kind in _DISTINCT_IORS:
                other = bsdf.ext_ior if attr == "int_ior" else bsdf.int_ior
                if value == other:
                    raise CheckError(f"the interior and exterior indices of refraction must differ (both "
                                     f"{value:g}), as Mitsuba requires for {bsdf.kind}")
            for b in group:
                setattr(b, attr, value.copy() if isinstance(value, np.ndarray) else value)
        return Param(f"{prefix}.{key}", name, kind, get, put, ("bsdfs",), owner)

    def textured(name, attr, kind, rule):
        value = getattr(bsdf, attr)
        if isinstance(value, Texture):
            yield from _texture_params(value, named.get(id(value)) or f"{prefix}.{name}", named)
        elif value is not None:
            yield field_param(f"{name}.value", name, attr, kind, rule)

    for name, attr in _BSDF_COLOURS.get(bsdf.kind, ()):
        value = getattr(bsdf, attr)
        if (name.startswith("specular_") and bsdf.kind not in ("conductor", "roughconductor")
                and not isinstance(value, Texture) and np.all(np.asarray(value) == 1.0)):
            continue        # Mitsuba lists these factors only where a file gives them
        yield from textured(name, attr, "color", checks.nonneg_color)
    if bsdf.kind in _WITH_IORS:
        yield field_param("int_ior", "int_ior", "int_ior", "ior", checks.positive)
        yield field_param("ext_ior", "ext_ior", "ext_ior", "ior", checks.positive)
    if bsdf.kind in ("roughconductor", "roughdielectric", "roughplastic"):
        names = (("alpha_u", "alpha_u"), ("alpha_v", "alpha_v")) if bsdf.anisotropic else (("alpha", "alpha_u"),)
        for name, attr in names:
            if bsdf.kind == "roughplastic":
                yield _alpha_param(bsdf, group, prefix, owner)
            else:
                yield from textured(name, attr, "float", None) if isinstance(getattr(bsdf, attr), Texture) \
                    else [_alpha_param(bsdf, group, prefix, owner, name, attr, f"{name}.value")]
    if bsdf.kind == "mask":
        if isinstance(bsdf.opacity, Texture):
            yield from _texture_params(bsdf.opacity, named.get(id(bsdf.opacity)) or f"{prefix}.opacity", named)
        else:
            yield field_param("opacity.value", "opacity", "opacity", "float")
    if bsdf.kind == "bumpmap":
        yield field_param("scale", "scale", "scale", "float")
    if bsdf.kind in ("bumpmap", "normalmap"):
        sub = "nested_texture" if bsdf.kind == "bumpmap" else "normalmap"
        yield from _texture_params(bsdf.map_texture, named.get(id(bsdf.map_texture)) or f"{prefix}.{sub}", named)


def _alpha_param(bsdf: Bsdf, group, prefix, owner, name="alpha", attr="alpha_u", key="alpha"):
    """Isotropic roughness sets alpha_u and alpha_v together."""
    def put(value):
        for b in group:
            if bsdf.anisotropic:
                setattr(b, attr, value)
            else:
                b.alpha_u = b.alpha_v = value
    return Param(f"{prefix}.{key}", name, "float", lambda: float(getattr(bsdf, attr)), put, ("bsdfs",), owner)


def _texture_params(tex: Texture, prefix: str, named: dict):
    """A bitmap's texels and uv map, a checkerboard's colours (or their textures) and uv map."""
    named.setdefault(id(tex), prefix)
    owner = _owner(f"<texture type=\"{tex.kind}\">", tex, "texture")

    def param(key, name, kind, get, put, shape=None):
        return Param(f"{prefix}.{key}", name, kind, get, put, ("bsdfs",), owner, shape)

    if tex.kind == "bitmap":
        def put_data(a):
            tex.data = a
        yield param("data", "data", "image", lambda: tex.data.copy(), put_data, tex.data.shape)
    else:
        for k in ("color0", "color1"):
            value = getattr(tex, k)
            if isinstance(value, Texture):
                yield from _texture_params(value, named.get(id(value)) or f"{prefix}.{k}", named)
                continue

            def put_colour(a, k=k):
                checks.nonneg_color(k, a)
                setattr(tex, k, a)
            yield param(f"{k}.value", k, "color", lambda k=k: np.array(getattr(tex, k), np.float64), put_colour)

    def put_uv(m):
        tex.to_uv = m
    yield param("to_uv", "to_uv", "uv_transform", lambda: np.array(tex.to_uv, np.float64), put_uv)


def _medium_params(scene: ModelScene, m: Medium, prefix: str):
    owner = _owner(f"<medium type=\"{m.kind}\">", m, "medium")

    def param(key, name, kind, get, put, shape=None):
        return Param(f"{prefix}.{key}", name, kind, get, put, ("media",), owner, shape)

    def assign(**changes):
        """Set fields of the medium once the medium as a whole passes the combined checks."""
        checks.medium_limits(replace(m, **changes))
        for k, v in changes.items():
            setattr(m, k, v)

    def coefficient(name, upper):
        value = getattr(m, name)
        if isinstance(value, Volume):
            vol = value
            if vol.kind == "grid":
                def put_grid(a, vol=vol):
                    checks.volume_range(name, replace(vol, data=a), upper)
                    assign(**{name: replace(vol, data=a)})
                yield param(f"{name}.data", name, "grid", lambda: getattr(m, name).data.copy(), put_grid,
                            vol.data.shape)
                return

            def put_const(a, vol=vol):
                checks.volume_range(name, replace(vol, value=a), upper)
                assign(**{name: replace(vol, value=a)})
            yield param(f"{name}.value", name, "color", lambda: getattr(m, name).value.copy(), put_const)
            return
        rule = checks.nonneg_color if upper is None else checks.unit_color

        def put_rgb(a):
            rule(name, a)
            assign(**{name: a})
        yield param(f"{name}.value", name, "color", lambda: np.array(getattr(m, name), np.float64), put_rgb)

    yield from coefficient("sigma_t", None)
    yield from coefficient("albedo", 1.0)

    def put_scale(v):
        assign(scale=checks.positive("scale", v))
    yield param("scale", "scale", "float", lambda: float(m.scale), put_scale)

    def put_g(g):
        checks.hg_g("g", g)
        # an isotropic medium given g != 0 becomes Henyey-Greenstein; Nori reads g = 0 as isotropic
        if g == 0 and (m.phase.kind == "isotropic" or scene.dialect == "nori"):
            m.phase = Phase()
        else:
            m.phase = Phase("hg", g)
    # only isotropic and HG media have this g: setting it would replace any other phase function with HG
    if m.phase.kind in ("isotropic", "hg"):
        yield param("phase_function.g", "g", "float", lambda: float(m.phase.g if m.phase.kind == "hg" else 0.0),
                    put_g)

    def put_radiance(a):
        checks.nonneg_color("volcl_radiance", a)
        assign(radiance=a)
    yield param("volcl_radiance.value", "volcl_radiance", "color",
                lambda: np.zeros(3) if m.radiance is None else np.array(m.radiance, np.float64), put_radiance)


def _emitter_params(scene: ModelScene, e: Emitter, prefix: str, named=None):
    owner = _owner(f"<emitter type=\"{e.kind}\">", e, "emitter")
    if e.kind == "envmap":
        yield from _envmap_params(e, prefix, owner)
        return
    name = {"point": "intensity", "spot": "intensity", "directional": "irradiance", "constant": "radiance"}[e.kind]

    def put_value(a):
        checks.nonneg_color(name, a)
        e.value = a
    yield Param(f"{prefix}.{name}.value", name, "color", lambda: np.array(e.value, np.float64), put_value,
                ("lights",), owner)
    if e.kind == "spot":
        yield from _spot_params(e, prefix, owner)
        if e.texture is not None:       # packed with the bsdfs' textures (volcl.pack.Packer)
            named = {} if named is None else named
            yield from _texture_params(e.texture, named.get(id(e.texture)) or f"{prefix}.texture", named)
    elif e.kind == "point":
        def put_position(p):
            e.position = p
        yield Param(f"{prefix}.position", "position", "point", lambda: np.array(e.position, np.float64),
                    put_position, ("lights",), owner)
    elif e.kind == "directional":
        def put_direction(d):
            e.direction = checks.direction(d)
        yield Param(f"{prefix}.direction", "direction", "point", lambda: np.array(e.direction, np.float64),
                    put_direction, ("lights",), owner)


def _spot_params(e: Emitter, prefix: str, owner):
    def put_cutoff(v):
        e.cutoff_angle = checks.spot_cutoff(v)

    def put_beam(v):
        e.beam_width = checks.spot_beam(v)

    def put_to_world(m):
        e.to_world = m
        e.position = m[:3, 3].copy()
    yield Param(f"{prefix}.cutoff_angle", "cutoff_angle", "float", lambda: float(e.cutoff_angle), put_cutoff,
                ("lights",), owner)
    yield Param(f"{prefix}.beam_width", "beam_width", "float", lambda: float(e.beam_width), put_beam,
                ("lights",), owner)
    yield Param(f"{prefix}.to_world", "to_world", "transform", lambda: e.to_world.copy(), put_to_world,
                ("lights",), owner)


def _envmap_params(e: Emitter, prefix: str, owner):
    """Mitsuba's keys: scale, data (here the image as read, (height, width, channels); Mitsuba's
    tensor has two more columns, copies of the seam), to_world."""
    def put_scale(v):
        if not v >= 0:
            raise CheckError(f"'scale' must be >= 0, got {v}")
        if float(np.max(e.image)) * v > checks.FLOAT32_MAX:
            raise CheckError(f"the brightest texel times 'scale' {v:g} is beyond the single-precision range")
        e.scale = v

    def put_data(a):
        bad = a < 0
        if bad.any():
            y, x, c = (int(i) for i in np.argwhere(bad)[0])
            raise CheckError(f"'data' has a negative texel {float(a[y, x, c])!r} at x={x} y={y} channel={c}")
        if float(np.max(a)) * e.scale > checks.FLOAT32_MAX:
            raise CheckError("'data' times 'scale' reaches beyond the single-precision range")
        e.image = a

    def put_to_world(m):
        e.to_world = checks.envmap_transform(m)
    yield Param(f"{prefix}.scale", "scale", "float", lambda: float(e.scale), put_scale, ("lights",), owner)
    yield Param(f"{prefix}.data", "data", "image", lambda: e.image.copy(), put_data, ("lights",), owner,
                e.image.shape)
    yield Param(f"{prefix}.to_world", "to_world", "transform", lambda: e.to_world.copy(), put_to_world,
                ("lights",), owner)


def _shape_params(scene: ModelScene, s: Shape, prefix: str):
    owner = _owner(f"<shape type=\"{s.kind}\">", s, "shape")
    if s.local is not None:
        def put_to_world(m):
            moved = replace(s)
            place(moved, m)
            checks.shape_rules(moved, f"the shape '{prefix}'")
            s.vertices, s.faces, s.normals, s.uvs = moved.vertices, moved.faces, moved.normals, moved.uvs
            s.center, s.radius, s.to_world = moved.center, moved.radius, moved.to_world
            s.cylinder, s.normal_matrix = moved.cylinder, moved.normal_matrix
        yield Param(f"{prefix}.to_world", "to_world", "transform", lambda: s.to_world.copy(), put_to_world,
                    ("geometry", "lights"), owner)


def _area_emitter_params(scene: ModelScene, s: Shape, prefix: str):
    owner = _owner("<emitter type=\"area\">", s, "shape")

    def put(a):
        checks.nonneg_color("radiance", a)
        s.emitter_radiance = a
    yield Param(f"{prefix}.radiance.value", "radiance", "color", lambda: np.array(s.emitter_radiance, np.float64),
                put, ("lights",), owner)


def _camera_params(scene: ModelScene, cam: Camera, prefix: str):
    def put(m):
        cam.to_world = checks.camera_transform(m, cam.kind)
    yield Param(f"{prefix}.to_world", "to_world", "transform", lambda: np.array(cam.to_world, np.float64), put,
                (), _owner("<sensor>", cam, "sensor"))


# model class -> fn(scene, object, key prefix) yielding its Params
PARAMETERS = {
    Camera: _camera_params,
    Shape: _shape_params,
    Bsdf: _bsdf_params,
    Medium: _medium_params,
    Emitter: _emitter_params,
}


def collect(scene: ModelScene) -> dict:
    """Every editable parameter of `scene`, by key, in the order the scene holds its objects."""
    taken = {o.id for o in _objects(scene) if getattr(o, "id", "")}
    taken.update(s.emitter_id for s in scene.shapes if s.emitter_id)
    named: dict[int, str] = {}
    out: dict[str, Param] = {}
    # textures with an id are named by it; others by the parameter that holds them
    textures = {id(t): t.id for t in _all_textures(scene) if t.id}
    taken.update(textures.values())

    def name(obj, fallback: str) -> str | None:
        """The key prefix of obj (None: already listed under another name)."""
        if id(obj) in named:
            return None
        ident = getattr(obj, "id", "")
        if not ident:
            ident = fallback
            while ident in taken:
                ident += "_"
            taken.add(ident)
        named[id(obj)] = ident
        return ident

    def add(params):
        for p in params:
            out[p.key] = p

    cam = scene.camera
    cam_key = name(cam, "sensor")
    add(_camera_params(scene, cam, cam_key))
    if cam.medium is not None:
        prefix = name(cam.medium, f"{cam_key}.medium")
        if prefix:
            add(PARAMETERS[Medium](scene, cam.medium, prefix))
    for i, s in enumerate(scene.shapes):
        key = name(s, f"shape_{i}")
        add(PARAMETERS[Shape](scene, s, key))
        holder = f"{key}.bsdf"
        for b in chain(s.bsdf):
            prefix = name(b, holder)
            if prefix:
                add(PARAMETERS[Bsdf](scene, b, prefix, textures))
            holder = f"{named[id(b)]}.nested_bsdf"
        if s.emitter_radiance is not None:
            prefix = s.emitter_id if s.emitter_id and s.emitter_id not in named.values() else f"{key}.emitter"
            named[id(s.emitter_radiance)] = prefix
            add(_area_emitter_params(scene, s, prefix))
        for side in ("interior", "exterior"):
            m = getattr(s, side)
            if m is not None:
                prefix = name(m, f"{key}.{side}_medium")
                if prefix:
                    add(PARAMETERS[Medium](scene, m, prefix))
    for i, e in enumerate(scene.emitters):
        add(PARAMETERS[Emitter](scene, e, name(e, f"emitter_{i}"), textures))
    for i, m in enumerate(scene.media):
        prefix = name(m, f"medium_{i}")
        if prefix:
            add(PARAMETERS[Medium](scene, m, prefix))
    return out


def _all_textures(scene: ModelScene):
    for s in scene.shapes:
        for b in chain(s.bsdf):
            for t in textures_of(b):
                yield from texture_tree(t)
    for e in scene.emitters:
        if e.texture is not None:
            yield from texture_tree(e.texture)


def _objects(scene: ModelScene):
    yield scene.camera
    yield from scene.shapes
    yield from (b for s in scene.shapes for b in chain(s.bsdf))
    yield from scene.emitters
    yield from scene.media


class SceneParameters(Mapping):
    """The editable parameters of a volcl.Scene: read with params[key], set with params[key] = value
    (checked at once), and apply with update() before rendering (volcl.render applies what is
    pending on its own)."""

    def __init__(self, scene):
        from .prepared import Scene as PreparedScene
        if not isinstance(scene, PreparedScene):
            raise TypeError("traverse takes a scene from volcl.load_file or volcl.load_string (or volcl.Scene(model)), "
                            f"not {type(scene).__name__}")
        self.scene = scene
        self._params = collect(scene.model)

    def __getitem__(self, key):
        return self._param(key).get()

    def __setitem__(self, key, value):
        param = self._param(key)
        try:
            param.set(convert(param, value))
        except CheckError as exc:
            raise VolclError(f"{key}: {exc} ({param.owner[1]})") from None
        self.scene.pending.add(param.key, param.parts)

    def __iter__(self):
        return iter(self._params)

    def __len__(self):
        return len(self._params)

    def __contains__(self, key):
        return key in self._params

    def kind(self, key) -> str:
        """'float', 'color', 'point', 'transform', 'ior', 'grid' or 'image'."""
        return self._param(key).kind

    def _param(self, key) -> Param:
        param = self._params.get(key)
        if param is None:
            keys = list(self._params)
            close = difflib.get_close_matches(str(key), keys, n=3)
            hint = f"; did you mean {' or '.join(repr(k) for k in close)}?" if close else ""
            raise UnknownParameter(f"the scene has no parameter {key!r}{hint} Its parameters: {', '.join(keys)}")
        return param

    @property
    def pending(self) -> list:
        """Keys set since the last update()."""
        return list(self.scene.pending.keys)

    def update(self):
        """Apply the values set since the last update: repack the parts they live in, upload the
        arrays that changed to every device the scene is on, and say (a FeatureChange warning)
        when the kernel features change, so that the next render builds another program. Returns
        a volcl.prepared.Update."""
        return apply_pending(self.scene, stacklevel=3)

    def __repr__(self) -> str:
        lines = [f"SceneParameters ({len(self)} parameters)"]
        width = max((len(k) for k in self._params), default=0)
        for k, p in self._params.items():
            lines.append(f"  {k:<{width}}  {p.kind:<9}  {_value_text(p.get())}")
        return "\n".join(lines)


def _value_text(value) -> str:
    if isinstance(value, np.ndarray):
        if value.size <= 3:
            return "[" + ", ".join(f"{float(x):.6g}" for x in value.reshape(-1)) + "]"
        return f"array{value.shape}"
    return f"{value:.6g}" if isinstance(value, float) and math.isfinite(value) else repr(value)


class Pending:
    """Keys set and packed parts touched since the scene's last update."""

    def __init__(self):
        self.keys: list = []
        self.parts: set = set()

    def add(self, key: str, parts) -> None:
        if key not in self.keys:
            self.keys.append(key)
        self.parts.update(parts)

    def __bool__(self) -> bool:
        return bool(self.keys)

    def clear(self) -> None:
        self.keys, self.parts = [], set()


def apply_pending(scene, stacklevel: int = 2):
    """Scene.apply for what `scene.pending` holds; warns FeatureChange when the features change."""
    pending = scene.pending
    keys, parts = list(pending.keys), set(pending.parts)
    pending.clear()
    update = scene.apply(parts, keys)
    if update.features_changed:
        built = [d.label for d in update.devices if d.has_program(update.features_after)]
        todo = [d.label for d in update.devices if not d.has_program(update.features_after)]
        if update.devices and not todo:
            then = f"the program for them is built already on {', '.join(built)}"
        else:
            then = (f"the next render on {', '.join(todo) or 'a device'} builds a program for them (once per "
                    f"device; later renders reuse it)")
        warnings.warn(FeatureChange(
            f"{', '.join(keys)}: the scene's kernel features change ({update.feature_change()}; now "
            f"{feat.describe(update.features_after)}): {then}"), stacklevel=stacklevel + 1)
    return update
