"""Model objects that both dialects build the same way, from a checked Node.

Cameras, reconstruction filters, meshes read from files, grid volumes, phase functions, dielectric
IORs and the checks on media: the dialects differ in names and defaults, not in these rules.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Optional

import numpy as np

from .. import mesh as meshes
from ..errors import VolclError
from . import checks
from .model import Bsdf, Camera, Filter, Phase, Volume
from .parse_common import Node
from .volfile import read_vol
from .xml import Element

# Mitsuba 3's named IORs (its dielectric documentation lists these values).
IOR_NAMES = {
    "vacuum": 1.0,
    "air": 1.000277,
    "water": 1.3330,
    "bk7": 1.5046,
    "fused silica": 1.4585,
    "diamond": 2.419,
}


@dataclass
class AreaLight:
    """An area emitter waiting to be attached to the shape it sits in."""
    radiance: np.ndarray


@dataclass
class Sampler:
    sample_count: int
    seed: int = 0


def resolve_path(node: Node, name: str) -> str:
    """A filename parameter, relative ones taken from the scene file's folder."""
    filename = node.string(name)
    if not filename:
        raise node.fail(name, f"'{name}' is empty")
    return os.path.join(os.path.dirname(os.path.abspath(node.ctx.path)), filename)


def mesh_from_file(node: Node, name: str, fmt: str) -> meshes.TriangleMesh:
    path = resolve_path(node, name)
    try:
        return meshes.load_mesh(path, fmt)
    except VolclError as exc:
        raise node.fail(name, f"cannot load mesh '{node.string(name)}': {exc}") from None


def grid_from_file(node: Node, name: str) -> tuple[np.ndarray, str]:
    path = resolve_path(node, name)
    try:
        data, _bbox = read_vol(path)     # the bbox is ignored: the grid fills [0,1]^3 (contract)
    except VolclError as exc:
        raise node.fail(name, f"cannot load volume '{node.string(name)}': {exc}") from None
    return data, path


def default_bsdf() -> Bsdf:
    """Both Mitsuba and Nori give a shape without a bsdf a diffuse reflectance of 0.5."""
    return Bsdf(kind="diffuse")


def ior(node: Node, name: str, default: str | float) -> float:
    value = node.value(name, default)
    if isinstance(value, str):
        key = value.strip().lower()
        if key not in IOR_NAMES:
            raise node.fail(name, f"unknown IOR name {value!r} for '{name}'; supported: "
                            + ", ".join(IOR_NAMES) + ", or a number")
        return IOR_NAMES[key]
    return float(node.checked(name, checks.positive, name, value))


def phase_hg(node: Node, name: str, default: float) -> Phase:
    return Phase("hg", node.checked(name, checks.hg_g, name, node.float(name, default)))


def check_volume_range(where: Element, name: str, volume: Volume, upper: Optional[float]) -> None:
    """sigma_t values must be >= 0; albedo values must also be <= 1."""
    try:
        checks.volume_range(name, volume, upper)
    except checks.CheckError as exc:
        raise where.error(str(exc)) from None


def _shape_name(node: Node) -> str:
    """How a shape is named in messages: its id and mesh file, where it has them."""
    parts = [f"id '{node.element.attrs['id']}'"] if "id" in node.element.attrs else []
    if node.has("filename"):
        parts.append(f"mesh '{node.string('filename')}'")
    return "the shape" + (f" ({', '.join(parts)})" if parts else "")


def check_shape(node: Node, shape) -> None:
    """Rules for a finished shape that no single parameter decides (volcl.scene.checks.shape_rules)."""
    node.checked(None, checks.shape_rules, shape, _shape_name(node))


def check_medium(node: Node, medium) -> None:
    """Coefficients valid one by one can still overflow float32 once combined (volcl.scene.checks)."""
    node.checked(None, checks.medium_limits, medium)


def camera(node: Node, *, fov: float, fov_axis: str, width: int, height: int, near: float,
           far: float, to_world: np.ndarray, rfilter: Filter, names: dict) -> Camera:
    """Check and assemble a perspective camera; `names` maps field -> the dialect's parameter name."""
    if not 0 < fov < 180:
        raise node.fail(names["fov"], f"field of view {fov} must lie strictly between 0 and 180 "
                                      f"degrees")
    for field_name, value in (("width", width), ("height", height)):
        if value < 1:
            raise node.fail(names[field_name], f"film {field_name} must be >= 1, got {value}")
    if not near > 0:
        raise node.fail(names["near"], f"near clip must be > 0, got {near}")
    if not far > near:
        raise node.fail(names["far"], f"far clip ({far}) must exceed near clip ({near})")
    node.checked(names["to_world"], checks.camera_transform, to_world)
    return Camera(to_world=to_world, fov=fov, fov_axis=fov_axis, width=width, height=height,
                  near_clip=near, far_clip=far, rfilter=rfilter)


def sample_count(node: Node, name: str, default: int) -> int:
    count = node.int(name, default)
    if count < 1:
        raise node.fail(name, f"'{name}' must be >= 1, got {count}")
    return count


def warn_if_above_one(node: Node, name: str, value: np.ndarray) -> None:
    if (value > 1).any():
        node.ctx.warn(node.at(name), f"'{name}' {value.tolist()} exceeds 1: the surface "
                                     f"reflects more light than it receives")
