"""Mitsuba's textures (src/textures/bitmap.cpp, checkerboard.cpp) and the parameters that take them.

A bitmap is read once into linear float32 texels through volcl.scene.images.read_image (integer
formats sRGB-decoded unless `raw`), as Mitsuba stores it: alpha dropped, one channel for grey
(Y, YA) images and three for colour, an image smaller than 2x2 padded to 2x2 by repeating its last
column and row. `to_uv` is a <transform> whose 2D part Mitsuba uses (the upper-left 2x2 block and
the x, y translation). Lookup conventions are in kernels/textures.h.

A parameter that takes a texture gets either a colour (or float) property or a <texture> child (or
<ref>) with that name; `texture_param` reads whichever the element has.
"""
from __future__ import annotations

import numpy as np

from . import objects
from .images import read_image
from .model import Texture
from .parse_common import Node, Spec

_TO_UV = {"to_uv": "transform"}

SPECS = {
    "bitmap": Spec({"filename": "string", "filter_type": "string", "wrap_mode": "string", "raw": "bool",
                    "format": "string", **_TO_UV},
                   ignored={"accel": "volcl does its own lookups (the same values)"}),
    "checkerboard": Spec({"color0": "color", "color1": "color", **_TO_UV}, children=frozenset({"texture"})),
}


def uv_transform(node: Node) -> np.ndarray:
    """Mitsuba's 2D affine map from a 4x4 to_uv: the upper-left 2x2 block and the x, y translation."""
    m = node.transform("to_uv")
    out = np.eye(3)
    out[:2, :2] = m[:2, :2]
    out[:2, 2] = m[:2, 3]
    return out


def _bitmap(node: Node) -> Texture:
    filter_type = node.choice("filter_type", ("bilinear", "nearest"), "bilinear")
    wrap = node.choice("wrap_mode", ("repeat", "mirror", "clamp"), "repeat")
    if node.has("format"):
        fmt = node.choice("format", ("auto", "variant", "float16", "fp16", "uint8"))
        if fmt != "auto":
            node.ctx.warn(node.at("format"), f"format={fmt!r} sets Mitsuba's storage precision; volcl keeps "
                                             f"float32 texels (the image differs by that rounding only)")
    raw = node.bool("raw", False)
    path = objects.resolve_path(node, "filename", "image")
    data = read_image(path, raw=raw, where=lambda message: node.fail("filename", message))
    channels = data.shape[2]
    if channels in (1, 2):
        data = data[..., :1]
    elif channels in (3, 4):
        data = data[..., :3]
    else:
        raise node.fail("filename", f"image {path} has {channels} channels; a bitmap texture needs 1 (grey), "
                                    f"2 (grey and alpha), 3 (RGB) or 4 (RGBA)")
    h, w = data.shape[:2]
    if h < 2 or w < 2:
        # Mitsuba's Bitmap::pad_to: repeat the last column, then the last row
        data = np.pad(data, ((0, max(0, 2 - h)), (0, max(0, 2 - w)), (0, 0)), mode="edge")
    data = np.ascontiguousarray(data, np.float32)
    tex = Texture("bitmap", data=data, filter=filter_type, wrap=wrap, raw=raw, to_uv=uv_transform(node),
                  filename=path)
    if not raw:
        reduced = data[..., 0] if data.shape[2] == 1 else data.astype(np.float64) @ np.array([0.212671, 0.715160, 0.072169])
        if (reduced > 1).any():
            node.ctx.warn(node.element, f"the texture {node.string('filename')!r} has texels above 1 (Mitsuba "
                                        f"warns too); they are used as they are")
    return tex


def _checkerboard(node: Node) -> Texture:
    tex = Texture("checkerboard", to_uv=uv_transform(node),
                  color0=texture_param(node, "color0", 0.4), color1=texture_param(node, "color1", 0.2))
    check_texture_names(node, ("color0", "color1"))
    return tex


def build_texture(node: Node) -> Texture:
    tex = _bitmap(node) if node.type == "bitmap" else _checkerboard(node)
    tex.id = node.element.attrs.get("id", "")
    tex.source = node.source()
    return tex


def texture_child(node: Node, name: str):
    """The <texture> child (or <ref>) named `name`, or None."""
    found = [c for c in node.objects("texture") if c.name == name]
    if len(found) > 1:
        raise found[1].element.error(f"texture '{name}' given twice")
    if found and node.has(name):
        raise found[0].element.error(f"'{name}' is given both as a property (line {node.at(name).line}) "
                                     f"and as a texture")
    return found[0] if found else None


def texture_param(node: Node, name: str, default, kind: str = "reflectance", check: str = "nonneg"):
    """A colour parameter that may be a texture: the Texture, or the colour (rgb array). check:
    'nonneg' (>= 0) or 'unit' ([0, 1]) for a constant colour."""
    child = texture_child(node, name)
    if child is not None:
        return child.obj
    if check == "unit":
        return node.unit_color(name, default, kind)
    return node.nonneg_color(name, default, kind)


def float_texture_param(node: Node, name: str, default: float, textures: bool = True):
    """A float parameter that may be a texture (roughness, opacity): the Texture, or a float. A
    colour given for it reads as its channel mean, as Mitsuba's eval_1 reads a constant colour."""
    child = texture_child(node, name)
    if child is not None:
        if not textures:
            raise child.element.error(f"'{name}' of <{node.label}> must be a number: Mitsuba does not take a "
                                      f"texture for it")
        return child.obj
    if not node.has(name):
        return float(default)
    value = node.color(name, default, kind="unbounded")
    return float(value[0] if np.all(value == value[0]) else np.mean(value))


def check_texture_names(node: Node, names) -> None:
    """Every <texture> child must give one of `names`."""
    for child in node.objects("texture"):
        if child.name not in names:
            allowed = ", ".join(names) or "none"
            raise child.element.error(f"a texture named {child.name!r} is not a parameter of <{node.label}>; "
                                      f"the parameters that take textures here: {allowed}")

