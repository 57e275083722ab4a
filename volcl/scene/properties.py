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


def _spectrum(el: Element, name: str) -> np.ndarray:
    text = el.attrs["value"]
    tokens = [t for t in _SEPARATORS.split(text.strip()) if t]
    if len(tokens) != 1 or ":" in text:
        raise el.error(f"'{name}': only a single constant spectrum value is supported "
                       f"(use <rgb> for colour), got {text!r}")
    return np.full(3, parse_float(tokens[0], el, f"'{name}'"))


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


def parse_property(el: Element) -> Prop:
    """Parse a property element whose tag is in PROPERTY_TAGS."""
    if el.tag != "transform":
        check_leaf(el)
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
    return Prop(el.attrs["name"], el.tag, parse_transform(el), el)


def parse_transform(el: Element) -> np.ndarray:
    m = np.eye(4)
    for op in el.children:
        reader = _TRANSFORM_OPS.get(op.tag)
        if reader is None:
            raise op.error(f"unknown transform operation <{op.tag}>; supported: "
                           + ", ".join(sorted(_TRANSFORM_OPS)))
        check_leaf(op)
        m = reader(op) @ m
    try:
        return invertible(el.attrs["name"], m)
    except CheckError as exc:
        raise el.error(str(exc)) from None


def _translate(op: Element) -> np.ndarray:
    check_attrs(op, (), ("value", "x", "y", "z"))
    return tf.translate(xyz(op, "translate", 0.0))


def _scale(op: Element) -> np.ndarray:
    check_attrs(op, (), ("value", "x", "y", "z"))
    return tf.scale(xyz(op, "scale", 1.0))


def _rotate(op: Element) -> np.ndarray:
    check_attrs(op, ("angle",), ("value", "x", "y", "z"))
    axis = xyz(op, "rotate axis", 0.0)
    if not np.any(axis):
        raise op.error("rotate: the axis is zero; give it as value=\"x, y, z\" or x=/y=/z=")
    return tf.rotate(axis, parse_float(op.attrs["angle"], op, "rotate angle"))


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
