"""Model objects that both dialects build the same way, from a checked Node.

Cameras, reconstruction filters, meshes read from files, grid volumes, phase functions, dielectric
IORs and the checks on media: the dialects differ in names and defaults, not in these rules.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from .. import mesh as meshes
from ..errors import VolclError
from . import checks
from .model import Bsdf, Camera, Filter, Phase, Volume, rgb
from .parse_common import Node
from .volfile import read_vol
from .xml import Element

# Mitsuba 3.9's named IORs (include/mitsuba/render/ior.h: Hecht, Optics, at about 589 nm, as
# float32 values), looked up case-insensitively.
IOR_NAMES = {
    "vacuum": 1.0, "helium": 1.000036, "hydrogen": 1.000132, "air": 1.000277,
    "carbon dioxide": 1.00045,
    "water": 1.3330, "acetone": 1.36, "ethanol": 1.361, "carbon tetrachloride": 1.461,
    "glycerol": 1.4729, "benzene": 1.501, "silicone oil": 1.52045, "bromine": 1.661,
    "water ice": 1.31, "fused quartz": 1.458, "pyrex": 1.470, "acrylic glass": 1.49,
    "polypropylene": 1.49, "bk7": 1.5046, "sodium chloride": 1.544, "amber": 1.55, "pet": 1.5750,
    "diamond": 2.419,
}
# Names volcl accepted before it had Mitsuba's whole table; Mitsuba 3 rejects them.
_VOLCL_IOR_NAMES = {"fused silica": 1.4585}


@dataclass
class AreaLight:
    """An area emitter waiting to be attached to the shape it sits in (or refers to)."""
    radiance: np.ndarray
    attached: bool = False


@dataclass
class Sampler:
    sample_count: int
    seed: int = 0


def resolve_path(node: Node, name: str, what: str = "file") -> str:
    """A filename parameter: absolute, or found in the scene's search folders (its own folder, and in
    the Mitsuba dialect the <path> folders before it)."""
    filename = node.string(name)
    if not filename:
        raise node.fail(name, f"'{name}' is empty")
    resolver = node.ctx.resolver
    found = resolver.resolve(filename)
    if found is None:
        raise node.fail(name, f"cannot load {what} '{filename}': file not found (looked in "
                              f"{resolver.describe()})")
    return found


def mesh_from_file(node: Node, name: str, fmt: str, shape_index: int = 0) -> meshes.TriangleMesh:
    path = resolve_path(node, name, "mesh")
    try:
        return meshes.load_mesh(path, fmt, shape_index)
    except VolclError as exc:
        raise node.fail(name, f"cannot load mesh '{node.string(name)}': {exc}") from None


def grid_from_file(node: Node, name: str) -> tuple[np.ndarray, str, tuple]:
    """(data, path, the file's bounding box (min, max)); the grid fills [0,1]^3 unless the Mitsuba
    dialect's use_grid_bbox asks for that box."""
    path = resolve_path(node, name, "volume")
    try:
        data, bbox = read_vol(path)
    except VolclError as exc:
        raise node.fail(name, f"cannot load volume '{node.string(name)}': {exc}") from None
    return data, path, bbox


def vdb_volume(node: Node) -> Volume:
    """<volume type="volcl_vdb">: grid `grid` of an OpenVDB (.vdb) or NanoVDB (.nvdb) file, placed by
    the grid's own index-to-world transform, then `to_world` (volcl/vdb.py)."""
    from .. import vdb
    path = resolve_path(node, "filename", "volume")
    if not path.lower().endswith((".vdb", ".nvdb")):
        raise node.fail("filename", f"volcl_vdb reads .vdb (OpenVDB) and .nvdb (NanoVDB) files, not "
                                    f"'{node.string('filename')}'")
    if not node.has("grid"):
        try:
            found = vdb.describe_grids(vdb.grids(path))
        except VolclError as exc:
            found = f"(the file cannot be read: {exc})"
        raise node.fail(None, f"volcl_vdb needs the name of a grid ('grid'); {path} holds {found}")
    try:
        sg = vdb.read(path, node.string("grid"))
    except VolclError as exc:
        raise node.fail("grid", f"cannot load volume '{node.string('filename')}': {exc}") from None
    if sg.empty:
        node.ctx.warn(node.at("grid"), f"grid '{sg.name}' of {path} holds no values but its background "
                                       f"{sg.background.tolist()}")
    return Volume("sparse", value=rgb(0.0), to_world=node.transform("to_world") @ sg.unit_to_world(),
                  filter=node.choice("filter_type", ("trilinear", "nearest"), "trilinear"),
                  filename=path, sparse=sg, grid_name=sg.name)


def default_bsdf(emitter: bool = False) -> Bsdf:
    """A shape without a bsdf is diffuse with reflectance 0.5 in both dialects, except that
    Mitsuba 3 makes it black on a shape that carries an emitter (src/render/shape.cpp)."""
    return Bsdf(kind="diffuse", reflectance=rgb(0.0 if emitter else 0.5))


def ior(node: Node, name: str, default: str | float) -> float:
    value = node.value(name, default)
    if isinstance(value, str):
        key = value.strip().lower()
        if key in _VOLCL_IOR_NAMES:
            node.ctx.warn(node.at(name), f"IOR name {value!r} is not in Mitsuba 3's table (Mitsuba 3 "
                                         f"rejects it); volcl uses {_VOLCL_IOR_NAMES[key]}")
            return _VOLCL_IOR_NAMES[key]
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
    """Rules for a finished shape that no single parameter decides (volcl.scene.checks.shape_rules);
    an interior medium that the shape does not enclose is a warning (checks.interior_gap)."""
    node.checked(None, checks.shape_rules, shape, _shape_name(node))
    gap = checks.interior_gap(shape, _shape_name(node))
    if gap is not None:
        node.ctx.warn(node.element, gap)


def check_medium(node: Node, medium) -> None:
    """Coefficients valid one by one can still overflow float32 once combined (volcl.scene.checks)."""
    node.checked(None, checks.medium_limits, medium)


def camera(node: Node, *, fov: float, fov_axis: str, width: int, height: int, near: float,
           far: float, to_world: np.ndarray, rfilter: Filter, names: dict, kind: str = "perspective"
           ) -> Camera:
    """Check and assemble a camera; `names` maps field -> the dialect's parameter name. An
    orthographic camera has no field of view, and its to_world may scale (the scale sets the
    extent of the view, as in Mitsuba)."""
    if kind != "orthographic" and not 0 < fov < 180:
        raise node.fail(names["fov"], f"field of view {fov} must lie strictly between 0 and 180 "
                                      f"degrees")
    for field_name, value in (("width", width), ("height", height)):
        if value < 1:
            raise node.fail(names[field_name], f"film {field_name} must be >= 1, got {value}")
    if not near > 0:
        raise node.fail(names["near"], f"near clip must be > 0, got {near}")
    if not far > near:
        raise node.fail(names["far"], f"far clip ({far}) must exceed near clip ({near})")
    node.checked(names["to_world"], checks.camera_transform, to_world, kind)
    return Camera(kind=kind, to_world=to_world, fov=fov, fov_axis=fov_axis, width=width, height=height,
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
