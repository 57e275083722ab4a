"""Shapes placed in world space: meshes (from files or primitives) and analytic spheres.

Both dialects end here, so the rules for normals live in one place: positions go through to_world,
shading normals through its inverse transpose (renormalised), and flip_normals reverses the winding
and negates the shading normals together, so geometric and shading normals keep agreeing. A shape
keeps what it was placed from (Shape.local, to_world), so `place` can move it again (volcl.traverse).
"""
from __future__ import annotations

import numpy as np

from .. import mesh as meshes
from . import transform as tf
from .checks import FLOAT32_MAX, CheckError
from .model import Bsdf, Shape, Source
from .xml import Element

PRIMITIVES = {
    "rectangle": meshes.rectangle,
    "cube": meshes.cube,
    "disk": meshes.disk,
}


def place(shape: Shape, to_world: np.ndarray) -> None:
    """Set the shape's world-space fields from its object-space data and `to_world`; CheckError
    (and the shape unchanged) when the transform is not allowed for it."""
    if shape.kind == "sphere":
        center, radius = shape.local
        s = tf.similarity_scale(to_world)
        if s is None:
            raise CheckError("a sphere's to_world must be a similarity transform (rotation, uniform "
                             "scale, translation); a non-uniform scale or shear would make it an "
                             "ellipsoid, which is not supported: use a mesh instead")
        center, radius = tf.apply_point(to_world, center), float(radius) * s
        if not ((np.abs(center) <= FLOAT32_MAX).all() and radius <= FLOAT32_MAX):
            raise CheckError("to_world moves the sphere beyond the floating-point range")
        shape.center, shape.radius = center, radius
    else:
        mesh = shape.local
        vertices = tf.apply_point(to_world, mesh.vertices)
        if not (np.abs(vertices) <= FLOAT32_MAX).all():     # the kernels hold them as float32
            raise CheckError("to_world moves vertices beyond the floating-point range")
        normals = None
        if mesh.normals is not None and not shape.face_normals:
            normals = tf.apply_normal(to_world, mesh.normals)
        faces = mesh.faces.copy()
        if shape.flip_normals:
            faces = faces[:, ::-1].copy()
            normals = None if normals is None else -normals
        shape.vertices, shape.faces, shape.normals = vertices, faces, normals
    shape.to_world = np.array(to_world, dtype=np.float64)


def mesh_shape(mesh: meshes.TriangleMesh, to_world: np.ndarray, *, bsdf: Bsdf, source: Source,
               where: Element, face_normals: bool = False, flip_normals: bool = False) -> Shape:
    shape = Shape(kind="mesh", bsdf=bsdf, flip_normals=flip_normals, source=source, local=mesh,
                  face_normals=face_normals)
    try:
        place(shape, to_world)
    except CheckError as exc:
        raise where.error(str(exc)) from None
    return shape


def sphere_shape(center, radius: float, to_world: np.ndarray, *, bsdf: Bsdf, source: Source,
                 where: Element, flip_normals: bool = False) -> Shape:
    """An analytic sphere; to_world must keep it a sphere (rotation, uniform scale, translation)."""
    shape = Shape(kind="sphere", bsdf=bsdf, flip_normals=flip_normals, source=source,
                  local=(np.asarray(center, dtype=np.float64), float(radius)))
    try:
        place(shape, to_world)
    except CheckError as exc:
        raise where.error(str(exc)) from None
    return shape


def bounds(shapes: list[Shape]) -> tuple[np.ndarray, np.ndarray] | None:
    """World-space bounding box (min, max) of all shapes, or None without shapes."""
    lo, hi = [], []
    for shape in shapes:
        if shape.kind == "sphere":
            lo.append(shape.center - shape.radius)
            hi.append(shape.center + shape.radius)
        else:
            lo.append(shape.vertices.min(axis=0))
            hi.append(shape.vertices.max(axis=0))
    if not lo:
        return None
    return np.min(lo, axis=0), np.max(hi, axis=0)
