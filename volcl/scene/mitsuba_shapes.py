"""Mitsuba shapes (src/shapes): mesh files, the primitive meshes, analytic spheres and cylinders;
shape groups and their instances in mitsuba_instances.

Mesh files without vertex normals get smooth ones computed as Mitsuba computes them, unless
`face_normals` is set (Mitsuba's obj, ply and serialized plugins all do this); normals that come out
equal to the face normals everywhere (a planar mesh) are dropped, which renders the same image.
A shape with an emitter and no bsdf is black, as in Mitsuba 3 (src/render/shape.cpp).
"""
from __future__ import annotations

import numpy as np

from .. import mesh as meshes
from . import mitsuba_instances, objects, transform as tf
from .objects import AreaLight
from .parse_common import Node, Spec
from .shapes import PRIMITIVES, cylinder_shape, mesh_shape, sphere_shape

_TO_WORLD = {"to_world": "transform"}
_CHILDREN = frozenset({"bsdf", "emitter", "medium"})
_COMMON_NOTES = {"silhouette_sampling_weight": "it steers Mitsuba's differentiable rendering only"}
_FILE_PARAMS = {"filename": "string", "face_normals": "bool", "flip_normals": "bool", **_TO_WORLD}

SPECS = {
    "obj": Spec({**_FILE_PARAMS, "flip_tex_coords": "bool"}, children=_CHILDREN, ignored=_COMMON_NOTES),
    "ply": Spec({**_FILE_PARAMS, "flip_tex_coords": "bool"}, children=_CHILDREN, ignored=_COMMON_NOTES),
    "serialized": Spec({**_FILE_PARAMS, "shape_index": "int"}, children=_CHILDREN, ignored=_COMMON_NOTES),
    **{kind: Spec({"flip_normals": "bool", **_TO_WORLD}, children=_CHILDREN, ignored=_COMMON_NOTES)
       for kind in PRIMITIVES},
    "sphere": Spec({"center": "point", "radius": "float", "flip_normals": "bool", **_TO_WORLD},
                   children=_CHILDREN, ignored=_COMMON_NOTES),
    "cylinder": Spec({"p0": "point", "p1": "point", "radius": "float", "flip_normals": "bool",
                      **_TO_WORLD}, children=_CHILDREN, ignored=_COMMON_NOTES),
    **mitsuba_instances.SPECS,
}


def build_shape(node: Node):
    if node.type == "shapegroup":
        return mitsuba_instances.build_shapegroup(node)
    if node.type == "instance":
        return mitsuba_instances.build_instance(node)
    emitter = node.single("emitter")
    bsdf = node.single("bsdf")
    bsdf = bsdf.obj if bsdf else objects.default_bsdf(emitter=emitter is not None)
    to_world = node.transform("to_world")
    flip = node.bool("flip_normals", False)
    if node.type == "sphere":
        shape = sphere_shape(node.point("center", np.zeros(3)), node.positive("radius", 1.0), to_world,
                             bsdf=bsdf, source=node.source(), where=node.at("to_world"), flip_normals=flip)
    elif node.type == "cylinder":
        shape = _cylinder(node, to_world, bsdf, flip)
    else:
        mesh = _mesh(node)
        normal_matrix = node.normal_matrix("to_world")
        if normal_matrix is not None and mesh.normals is not None and node.type not in PRIMITIVES:
            node.ctx.warn(node.at("to_world"), "a rotate axis that is not of unit length also scales and shears "
                                               "(Mitsuba uses it as given), and Mitsuba turns the mesh's vertex "
                                               "normals with the rotate matrix itself rather than its inverse "
                                               "transpose; volcl does the same")
        shape = mesh_shape(mesh, to_world, bsdf=bsdf, source=node.source(), where=node.at("to_world"),
                           face_normals=node.bool("face_normals", False), flip_normals=flip,
                           smooth_normals=mesh.normals is None and node.type not in PRIMITIVES,
                           normal_matrix=normal_matrix, normal_by_transform=node.type in ("rectangle", "disk"))
    if node.type == "disk":
        shape.uv_map = "disk"
    _attach_emitter_and_media(node, shape, emitter)
    objects.check_shape(node, shape)
    shape.id = node.element.attrs.get("id", "")
    return shape


# Mitsuba flips the v of OBJ texture coordinates by default (OBJ's v runs up the image, Mitsuba's
# down its rows), of PLY ones only when asked; serialized files are read as stored
_FLIP_V_DEFAULT = {"obj": True, "ply": False}


def _mesh(node: Node) -> meshes.TriangleMesh:
    if node.type in PRIMITIVES:
        return PRIMITIVES[node.type]()
    shape_index = node.int("shape_index", 0)
    if shape_index < 0:
        raise node.fail("shape_index", f"'shape_index' must be >= 0, got {shape_index}")
    mesh = objects.mesh_from_file(node, "filename", node.type, shape_index)
    if mesh.uvs is not None and node.bool("flip_tex_coords", _FLIP_V_DEFAULT.get(node.type, False)):
        mesh = mesh._replace(uvs=np.column_stack([mesh.uvs[:, 0], 1.0 - mesh.uvs[:, 1]]))
    return mesh


def _cylinder(node: Node, to_world: np.ndarray, bsdf, flip: bool):
    """Mitsuba's cylinder: the unit cylinder (radius 1, z from 0 to 1, open at both ends) placed by
    translate(p0) * frame(p1 - p0) * scale(radius, radius, |p1 - p0|), then to_world."""
    p0 = node.point("p0", np.zeros(3))
    p1 = node.point("p1", np.array([0.0, 0.0, 1.0]))
    radius = node.positive("radius", 1.0)
    axis = p1 - p0
    length = float(np.linalg.norm(axis))
    if not length > 0:
        raise node.fail("p1", "the cylinder's 'p0' and 'p1' coincide")
    d = axis / length
    s, t = tf.coordinate_system(d)
    frame = np.eye(4)
    frame[:3, 0], frame[:3, 1], frame[:3, 2] = s, t, d
    frame = tf.translate(p0) @ frame @ tf.scale([radius, radius, length])
    shape = cylinder_shape(frame, to_world, bsdf=bsdf, source=node.source(), where=node.at("to_world"),
                           flip_normals=flip)
    lin = shape.cylinder[:3, :3]
    gram = lin.T @ lin
    if abs(gram[0, 1]) > 1e-6 * gram[0, 0] or abs(gram[0, 0] - gram[1, 1]) > 1e-6 * gram[0, 0]:
        # Mitsuba intersects the same (elliptic) surface in its own frame, warns alike, and samples
        # it by area as if it were circular
        node.ctx.warn(node.at("to_world"), "the cylinder's transform scales or shears its cross-section "
                                           "unevenly (Mitsuba warns too): it is intersected exactly, but as "
                                           "an emitter it is sampled as if circular, as in Mitsuba")
    return shape


def _attach_emitter_and_media(node: Node, shape, emitter) -> None:
    if emitter is not None:
        if not isinstance(emitter.obj, AreaLight):
            raise emitter.element.error("only an area emitter can be attached to a shape; "
                                        "point, directional and constant emitters go directly "
                                        "inside <scene>")
        shape.emitter_radiance = emitter.obj.radiance
        shape.emitter_id = emitter.element.attrs.get("id", "")
        emitter.obj.attached = True
    for child in node.objects("medium"):
        if child.name not in ("interior", "exterior"):
            raise child.element.error(f"a medium inside a shape needs name=\"interior\" or "
                                      f"name=\"exterior\", got name={child.name!r}")
        if getattr(shape, child.name) is not None:
            raise child.element.error(f"the shape already has an {child.name} medium")
        setattr(shape, child.name, child.obj)
