"""Shapes placed in world space: meshes (from files or primitives) and analytic spheres.

Both dialects end here, so the rules for normals live in one place: positions go through to_world,
shading normals through its inverse transpose (renormalised), and flip_normals reverses the winding
and negates the shading normals together, so geometric and shading normals keep agreeing.
"""
from __future__ import annotations

import numpy as np

from .. import mesh as meshes
from . import transform as tf
from .model import Bsdf, Shape, Source
from .properties import FLOAT32_MAX
from .xml import Element

PRIMITIVES = {
    "rectangle": meshes.rectangle,
    "cube": meshes.cube,
    "disk": meshes.disk,
}


def mesh_shape(mesh: meshes.TriangleMesh, to_world: np.ndarray, *, bsdf: Bsdf, source: Source,
               where: Element, face_normals: bool = False, flip_normals: bool = False,
               normal_matrix=None) -> Shape:
    """normal_matrix: the 3x3 matrix that takes the file's normals to the world, where it is not
    to_world's inverse transpose (Mitsuba's rotate with an axis not of unit length)."""
    vertices = tf.apply_point(to_world, mesh.vertices)
    if not (np.abs(vertices) <= FLOAT32_MAX).all():     # the kernels hold them as float32
        raise where.error("to_world moves vertices beyond the floating-point range")
    normals = None
    if mesh.normals is not None and not face_normals:
        if normal_matrix is None:
            normals = tf.apply_normal(to_world, mesh.normals)
        else:
            normals = np.asarray(mesh.normals, np.float64) @ np.asarray(normal_matrix).T
            normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    faces = mesh.faces.copy()
    if flip_normals:
        faces = faces[:, ::-1].copy()
        normals = None if normals is None else -normals
    return Shape(kind="mesh", bsdf=bsdf, vertices=vertices, faces=faces, normals=normals,
                 uvs=mesh.uvs, flip_normals=flip_normals, source=source)


def sphere_shape(center, radius: float, to_world: np.ndarray, *, bsdf: Bsdf, source: Source,
                 where: Element, flip_normals: bool = False) -> Shape:
    """An analytic sphere; to_world must keep it a sphere (rotation, uniform scale, translation)."""
    s = tf.similarity_scale(to_world)
    if s is None:
        raise where.error("a sphere's to_world must be a similarity transform (rotation, uniform "
                          "scale, translation); a non-uniform scale or shear would make it an "
                          "ellipsoid, which is not supported: use a mesh instead")
    center, radius = tf.apply_point(to_world, center), float(radius) * s
    if not ((np.abs(center) <= FLOAT32_MAX).all() and radius <= FLOAT32_MAX):
        raise where.error("to_world moves the sphere beyond the floating-point range")
    return Shape(kind="sphere", bsdf=bsdf, center=center, radius=radius,
                 flip_normals=flip_normals, source=source)


def bounds(shapes: list[Shape]) -> tuple[np.ndarray, np.ndarray] | None:
    """World-space bounding box (min, max) of all shapes, or None without shapes."""
    lo, hi = [], []
    for shape in shapes:
        if shape.kind == "sphere":
            lo.append(shape.center - shape.radius)
            hi.append(shape.center + shape.radius)
        elif shape.kind == "cylinder":
            box = cylinder_bounds(shape.to_world)
            lo.append(box[0])
            hi.append(box[1])
        else:
            lo.append(shape.vertices.min(axis=0))
            hi.append(shape.vertices.max(axis=0))
    if not lo:
        return None
    return np.min(lo, axis=0), np.max(hi, axis=0)


def cylinder_bounds(to_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Box around the unit cylinder (radius 1, z in [0, 1]) under `to_world`: the boxes of its two end
    circles (Mitsuba's bound)."""
    m = np.asarray(to_world, np.float64)
    half = np.sqrt(m[:3, 0] ** 2 + m[:3, 1] ** 2)      # extent of a transformed unit circle per axis
    p0, p1 = m[:3, 3], m[:3, 3] + m[:3, 2]
    return np.minimum(p0, p1) - half, np.maximum(p0, p1) + half
