"""Typed property elements (<float>, <rgb>, <point>, <transform>, ...) parsed into Python values.

A property element has a `name` and a value; this module turns its text into a float, int, bool, str,
float64 colour/point (3,) or 4x4 matrix, and rejects malformed text with the offending value in the
message. Which parameter names a plugin accepts is decided elsewhere (parse_common).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from .checks import FLOAT32_MAX, CheckError, finite, invertible
from . import transform as tf
from .spectra import Spectrum
from .xml import Element

# ASCII only: Python's float() and int() would also take digits of other scripts.
_FLOAT = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?\Z", re.ASCII)
_INT = re.compile(r"[+-]?\d+\Z", re.ASCII)
_SEPARATORS = re.compile(r"[\s,]+")


@dataclass
class Prop:
    """A parsed property: its name, the tag it was written with, its value, and its element."""
    name: str
    tag: str
    value: object
    element: Element
    # a transform's matrix for normals as Mitsuba 3 composes it (see parse_transform)
    normal_matrix: object = None


__all__ = ["FLOAT32_MAX", "Prop", "parse_property"]


def parse_float(text: str, el: Element, what: str) -> float:
    text = text.strip()
    value = float(text) if _FLOAT.match(text) else math.nan
    try:
        return finite(what, value, text)
    except CheckError as exc:
        raise el.error(str(exc)) from None


def parse_floats(text: str, el: Element, what: str, counts: tuple[int, ...]) -> list[float]:
    tokens = [t for t in _SEPARATORS.split(text.strip()) if t]
    if len(tokens) not in counts:
        allowed = " or ".join(str(c) for c in counts)
        raise el.error(f"{what}: expected {allowed} numbers separated by commas or spaces, "
                       f"got {text!r}")
    return [parse_float(t, el, what) for t in tokens]


def parse_int(text: str, el: Element, what: str) -> int:
    text = text.strip()
    if not _INT.match(text):
        raise el.error(f"{what}: {text!r} is not an integer")
    # Checking the length first also keeps int() away from its limit on very long digit strings.
    value = int(text) if len(text) <= 12 else None
    if value is None or not -2**31 <= value < 2**31:
        raise el.error(f"{what}: {text} is outside the 32-bit integer range")
    return value


def parse_bool(text: str, el: Element, what: str) -> bool:
    lowered = text.strip().lower()
    if lowered not in ("true", "false"):
        raise el.error(f"{what}: {text!r} is not a boolean; use true or false")
    return lowered == "true"


def check_attrs(el: Element, required: tuple[str, ...], optional: tuple[str, ...] = ()) -> None:
    for name in required:
        if name not in el.attrs:
            raise el.error(f"missing attribute '{name}'")
    for name in el.attrs:
        if name not in required and name not in optional:
            allowed = ", ".join(required + optional) or "none"
            raise el.error(f"unknown attribute '{name}'; supported: {allowed}")


def check_leaf(el: Element) -> None:
    if el.children:
        raise el.error(f"<{el.tag}> takes no child elements, found <{el.children[0].tag}>")


def xyz(el: Element, what: str, default: float) -> np.ndarray:
    """A 3-vector from value="x, y, z" (or one number for all three, as Mitsuba expands it)
    or from x=, y=, z= attributes, each defaulting to `default`."""
    if "value" in el.attrs:
        if any(k in el.attrs for k in "xyz"):
            raise el.error(f"{what}: give either value= or x=/y=/z=, not both")
        values = parse_floats(el.attrs["value"], el, what, (1, 3))
        return np.array(values * 3 if len(values) == 1 else values, dtype=np.float64)
    return np.array([parse_float(el.attrs[k], el, f"{what} {k}") if k in el.attrs else default
                     for k in "xyz"], dtype=np.float64)


def _colour(el: Element, name: str) -> np.ndarray:
    values = parse_floats(el.attrs["value"], el, f"'{name}'", (1, 3))
    return np.array(values * 3 if len(values) == 1 else values, dtype=np.float64)


def _spectrum(el: Element, name: str) -> Spectrum:
    """<spectrum name= value=/>: one value (uniform) or wavelength:value pairs; or filename= (a file of
    'wavelength value' lines, '#' comments); or <spectrum type=...> with its own parameters."""
    if "type" in el.attrs:
        return _spectrum_plugin(el, name)
    check_leaf(el)
    check_attrs(el, ("name",), ("value", "filename"))
    if ("value" in el.attrs) == ("filename" in el.attrs):
        raise el.error(f"'{name}': a <spectrum> needs either value= or filename= (not both)")
    if "filename" in el.attrs:
        return _spectrum_file(el, name)
    text = el.attrs["value"]
    tokens = [t for t in _SEPARATORS.split(text.strip()) if t]
    if len(tokens) == 1 and ":" not in tokens[0]:
        return Spectrum(values=(parse_float(tokens[0], el, f"'{name}'"),))
    pairs = []
    for token in tokens:
        parts = token.split(":")
        if len(parts) != 2:
            raise el.error(f"'{name}': {token!r} is not a wavelength:value pair (a spectrum is one "
                           f"value or pairs such as \"400:0.1, 500:0.3\")")
        pairs.append((parse_float(parts[0], el, f"'{name}' wavelength"),
                      parse_float(parts[1], el, f"'{name}' value")))
    return _tabulated(el, name, [w for w, _ in pairs], [v for _, v in pairs])


def _tabulated(el: Element, name: str, wavelengths, values) -> Spectrum:
    if len(wavelengths) < 2:
        raise el.error(f"'{name}': a tabulated spectrum needs at least two wavelength:value pairs")
    if len(wavelengths) != len(values):
        raise el.error(f"'{name}': {len(wavelengths)} wavelengths but {len(values)} values")
    if any(b <= a for a, b in zip(wavelengths, wavelengths[1:])):
        raise el.error(f"'{name}': wavelengths must increase, got {list(wavelengths)}")
    return Spectrum(values=tuple(values), wavelengths=tuple(wavelengths))


def _spectrum_file(el: Element, name: str) -> Spectrum:
    import os
    path = el.extra.get("path") or os.path.join(os.path.dirname(os.path.abspath(el.file)),
                                                el.attrs["filename"])
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            lines = fh.read().splitlines()
    except OSError as exc:
        raise el.error(f"'{name}': cannot read spectrum file {el.attrs['filename']!r}: "
                       f"{exc.strerror or exc}") from None
    wavelengths, values = [], []
    for number, line in enumerate(lines, 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        tokens = _SEPARATORS.split(line.strip())
        if len(tokens) < 2 or not (_FLOAT.match(tokens[0]) and _FLOAT.match(tokens[1])):
            raise el.error(f"'{name}': line {number} of spectrum file {path} is not 'wavelength "
                           f"value': {line.strip()[:60]!r}")
        wavelengths.append(parse_float(tokens[0], el, f"'{name}' (file line {number})"))
        values.append(parse_float(tokens[1], el, f"'{name}' (file line {number})"))
    return _tabulated(el, f"{name}' (file {path})'", wavelengths, values)


_SPECTRUM_TYPES = ("blackbody", "irregular", "regular", "uniform")


def _spectrum_plugin(el: Element, name: str) -> Spectrum:
    kind = el.attrs["type"]
    check_attrs(el, ("type", "name"), ("id",))
    if kind not in _SPECTRUM_TYPES:
        raise el.error(f"unknown spectrum type {kind!r}; supported: " + ", ".join(_SPECTRUM_TYPES)
                       + " (or <spectrum value=...>, or <rgb>)")
    params = {}
    for child in el.children:
        if child.tag not in ("float", "integer", "string"):
            raise child.error(f"<{child.tag}> is not allowed inside <spectrum type=\"{kind}\">")
        check_leaf(child)
        check_attrs(child, ("name", "value"))
        if child.attrs["name"] in params:
            raise child.error(f"parameter '{child.attrs['name']}' given twice")
        params[child.attrs["name"]] = child
    allowed = {"blackbody": {"temperature", "wavelength_min", "wavelength_max"},
               "regular": {"values", "wavelength_min", "wavelength_max"},
               "irregular": {"values", "wavelengths"}, "uniform": {"value"}}[kind]
    for pname, child in params.items():
        if pname not in allowed:
            raise child.error(f"unknown parameter '{pname}' for <spectrum type=\"{kind}\">; supported: "
                              + ", ".join(sorted(allowed)))

    def number(pname, default=None):
        child = params.get(pname)
        if child is None:
            if default is None:
                raise el.error(f"<spectrum type=\"{kind}\"> needs '{pname}'")
            return default
        return parse_float(child.attrs["value"], child, f"'{pname}'")

    def numbers(pname):
        child = params.get(pname)
        if child is None:
            raise el.error(f"<spectrum type=\"{kind}\"> needs '{pname}'")
        return [parse_float(t, child, f"'{pname}'") for t in _SEPARATORS.split(child.attrs["value"].strip()) if t]

    if kind == "uniform":
        return Spectrum(values=(number("value"),))
    if kind == "blackbody":
        temperature = number("temperature")
        if not temperature > 0:
            raise params["temperature"].error(f"'temperature' must be > 0 kelvin, got {temperature}")
        return Spectrum(temperature=temperature,
                        wavelength_range=(number("wavelength_min", 360.0), number("wavelength_max", 830.0)))
    values = numbers("values")
    if kind == "regular":
        lo, hi = number("wavelength_min", 360.0), number("wavelength_max", 830.0)
        if len(values) < 2:
            raise el.error("a regular spectrum needs at least two values")
        wavelengths = [lo + (hi - lo) * i / (len(values) - 1) for i in range(len(values))]
    else:
        wavelengths = numbers("wavelengths")
    return _tabulated(el, name, wavelengths, values)


_SCALAR_PARSERS = {
    "float": lambda el, name: parse_float(el.attrs["value"], el, f"'{name}'"),
    "integer": lambda el, name: parse_int(el.attrs["value"], el, f"'{name}'"),
    "boolean": lambda el, name: parse_bool(el.attrs["value"], el, f"'{name}'"),
    "string": lambda el, name: el.attrs["value"],
    "rgb": _colour,
    "color": _colour,
    "spectrum": _spectrum,
}

PROPERTY_TAGS = frozenset(_SCALAR_PARSERS) | {"point", "vector", "transform"}


def parse_property(el: Element, rotate_axis_as_given: bool = False) -> Prop:
    """Parse a property element whose tag is in PROPERTY_TAGS. `rotate_axis_as_given`: Mitsuba's
    rotate, which does not normalize its axis (Nori's does)."""
    if el.tag not in ("transform", "spectrum"):
        check_leaf(el)
    if el.tag == "spectrum":
        if "name" not in el.attrs:
            raise el.error("missing attribute 'name'")
        name = el.attrs["name"]
        return Prop(name, el.tag, _spectrum(el, name), el)
    if el.tag in _SCALAR_PARSERS:
        check_attrs(el, ("name", "value"))
        name = el.attrs["name"]
        return Prop(name, el.tag, _SCALAR_PARSERS[el.tag](el, name), el)
    if el.tag in ("point", "vector"):
        check_attrs(el, ("name",), ("value", "x", "y", "z"))
        name = el.attrs["name"]
        return Prop(name, el.tag, xyz(el, f"'{name}'", 0.0), el)
    assert el.tag == "transform", el.tag
    check_attrs(el, ("name",))
    matrix, normal_matrix = parse_transform(el, rotate_axis_as_given, with_normal_matrix=True)
    return Prop(el.attrs["name"], el.tag, matrix, el, normal_matrix)


def parse_transform(el: Element, rotate_axis_as_given: bool = False, with_normal_matrix: bool = False):
    """The 4x4 matrix of a <transform>, its ops applied in document order.

    with_normal_matrix: also the matrix that takes normals to the world, as Mitsuba 3 composes it.
    Mitsuba keeps each op's inverse transpose beside its matrix and multiplies both, taking a
    rotation's inverse transpose to be the rotation itself (src/core/transform.h). With the
    rotate axis used as given, a rotate whose axis is not of unit length is no rotation, and its
    normals then turn with the rotate matrix, not with its inverse transpose; elsewhere the two
    agree with the exact inverse transpose of the whole matrix."""
    m = np.eye(4)
    normal_m = np.eye(3)
    skewed = False
    for op in el.children:
        reader = _TRANSFORM_OPS.get(op.tag)
        if reader is None:
            raise op.error(f"unknown transform operation <{op.tag}>; supported: "
                           + ", ".join(sorted(_TRANSFORM_OPS)))
        check_leaf(op)
        step = (_rotate(op, normalize_axis=False) if op.tag == "rotate" and rotate_axis_as_given
                else reader(op))
        m = step @ m
        if op.tag == "rotate" and rotate_axis_as_given:
            normal_step = step[:3, :3]
            skewed |= not np.allclose(step[:3, :3] @ step[:3, :3].T, np.eye(3), atol=1e-9)
        else:
            normal_step = np.linalg.inv(step[:3, :3]).T if np.linalg.det(step[:3, :3]) != 0 else np.eye(3)
        normal_m = normal_step @ normal_m
    try:
        invertible(el.attrs["name"], m)
    except CheckError as exc:
        raise el.error(str(exc)) from None
    if with_normal_matrix:
        return m, (normal_m if skewed else None)
    return m


def _translate(op: Element) -> np.ndarray:
    check_attrs(op, (), ("value", "x", "y", "z"))
    return tf.translate(xyz(op, "translate", 0.0))


def _scale(op: Element) -> np.ndarray:
    check_attrs(op, (), ("value", "x", "y", "z"))
    return tf.scale(xyz(op, "scale", 1.0))


def _rotate(op: Element, normalize_axis: bool = True) -> np.ndarray:
    check_attrs(op, ("angle",), ("value", "x", "y", "z"))
    axis = xyz(op, "rotate axis", 0.0)
    if not np.any(axis):
        raise op.error("rotate: the axis is zero; give it as value=\"x, y, z\" or x=/y=/z=")
    return tf.rotate(axis, parse_float(op.attrs["angle"], op, "rotate angle"), normalize_axis)


def _matrix(op: Element) -> np.ndarray:
    check_attrs(op, ("value",))
    values = parse_floats(op.attrs["value"], op, "matrix", (16, 9))
    if len(values) == 9:
        m = np.eye(4)
        m[:3, :3] = np.reshape(values, (3, 3))
        return m
    m = np.reshape(values, (4, 4))
    if np.abs(m[3] - [0, 0, 0, 1]).max() > 0:
        raise op.error(f"matrix: the last row must be 0 0 0 1 (affine), got {m[3].tolist()}")
    return m


def _lookat(op: Element) -> np.ndarray:
    check_attrs(op, ("origin", "target"), ("up",))
    origin = parse_floats(op.attrs["origin"], op, "lookat origin", (3,))
    target = parse_floats(op.attrs["target"], op, "lookat target", (3,))
    up = parse_floats(op.attrs["up"], op, "lookat up", (3,)) if "up" in op.attrs else None
    try:
        return tf.lookat(origin, target, up)
    except ValueError as exc:
        raise op.error(f"invalid lookat: {exc}") from None


_TRANSFORM_OPS = {
    "translate": _translate,
    "scale": _scale,
    "rotate": _rotate,
    "matrix": _matrix,
    "lookat": _lookat,
}
