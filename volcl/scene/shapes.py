"""Shapes placed in world space: meshes (from files or primitives), analytic spheres and cylinders.

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


def place(shape: Shape, to_world: np.ndarray, normal_matrix=None) -> None:
    """Set the shape's world-space fields from its object-space data and `to_world`; CheckError
    (and the shape unchanged) when the transform is not allowed for it. normal_matrix: the 3x3
    matrix that takes a mesh file's normals to the world where it is not to_world's inverse
    transpose (Mitsuba's rotate with an axis not of unit length, volcl.scene.properties)."""
    if shape.kind == "sphere":
        center, radius = shape.local
        s = tf.similarity_scale(to_world)
        if s is None:
            raise CheckError("a sphere's to_world must be a similarity transform (rotation, uniform "
                             "scale, translation); a non-uniform scale or shear would make it an "
                             "ellipsoid, which is not supported for a shape placed directly: use a mesh, or put "
                             "the sphere in a shapegroup and place it by an instance with this to_world "
                             "(intersected exactly, as Mitsuba does)")
        center, radius = tf.apply_point(to_world, center), float(radius) * s
        if not ((np.abs(center) <= FLOAT32_MAX).all() and radius <= FLOAT32_MAX):
            raise CheckError("to_world moves the sphere beyond the floating-point range")
        shape.center, shape.radius = center, radius
    elif shape.kind == "cylinder":
        m = np.asarray(to_world, np.float64) @ shape.local
        if not (tf.is_invertible(m) and (np.abs(m) <= FLOAT32_MAX).all()):
            raise CheckError("the cylinder's transform is singular or beyond the floating-point range")
        shape.cylinder = m
    else:
        _place_mesh(shape, to_world, normal_matrix)
    shape.to_world = np.array(to_world, dtype=np.float64)
    shape.normal_matrix = normal_matrix


def _place_mesh(shape: Shape, to_world: np.ndarray, normal_matrix) -> None:
    mesh = shape.local
    vertices = tf.apply_point(to_world, mesh.vertices)
    if not (np.abs(vertices) <= FLOAT32_MAX).all():     # the kernels hold them as float32
        raise CheckError("to_world moves vertices beyond the floating-point range")
    normals = None
    if mesh.normals is not None and not shape.face_normals:
        if normal_matrix is None:
            normals = tf.apply_normal(to_world, mesh.normals)
        else:
            normals = np.asarray(mesh.normals, np.float64) @ np.asarray(normal_matrix).T
            normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    elif shape.smooth_normals and not shape.face_normals:
        normals = _smooth_normals(vertices, mesh.faces)
    faces = mesh.faces.copy()
    mirrored = shape.normal_by_transform and np.linalg.det(np.asarray(to_world, np.float64)[:3, :3]) < 0
    if shape.flip_normals != mirrored:
        faces = faces[:, ::-1].copy()
        normals = None if normals is None else -normals
    shape.vertices, shape.faces, shape.normals, shape.uvs = vertices, faces, normals, mesh.uvs


def _smooth_normals(vertices: np.ndarray, faces: np.ndarray):
    """Mitsuba's vertex normals for a mesh file without them, computed as it computes them: from the
    world-space vertices with the file's winding; None where they equal the face normals everywhere
    (a planar mesh), which renders the same without them."""
    normals = meshes.mitsuba_vertex_normals(vertices, faces)
    return None if meshes.normals_are_flat(vertices, faces, normals) else normals


def mesh_shape(mesh: meshes.TriangleMesh, to_world: np.ndarray, *, bsdf: Bsdf, source: Source,
               where: Element, face_normals: bool = False, flip_normals: bool = False,
               smooth_normals: bool = False, normal_matrix=None, normal_by_transform: bool = False) -> Shape:
    """smooth_normals: a mesh file without normals gets Mitsuba's computed vertex normals;
    normal_by_transform: Mitsuba's analytic rectangle and disk (see Shape.normal_by_transform)."""
    shape = Shape(kind="mesh", bsdf=bsdf, flip_normals=flip_normals, source=source, local=mesh,
                  face_normals=face_normals, smooth_normals=smooth_normals,
                  normal_by_transform=normal_by_transform)
    try:
        place(shape, to_world, normal_matrix)
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


def cylinder_shape(frame: np.ndarray, to_world: np.ndarray, *, bsdf: Bsdf, source: Source,
                   where: Element, flip_normals: bool = False) -> Shape:
    """Mitsuba's cylinder: the unit cylinder (radius 1, z in [0, 1]) placed by `frame` (from p0, p1
    and radius), then to_world."""
    shape = Shape(kind="cylinder", bsdf=bsdf, flip_normals=flip_normals, source=source,
                  local=np.asarray(frame, np.float64))
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
        elif shape.kind == "cylinder":
            box = cylinder_bounds(shape.cylinder)
            lo.append(box[0])
            hi.append(box[1])
        else:
            lo.append(shape.vertices.min(axis=0))
            hi.append(shape.vertices.max(axis=0))
    if not lo:
        return None
    return np.min(lo, axis=0), np.max(hi, axis=0)


def cylinder_bounds(m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Box around the unit cylinder (radius 1, z in [0, 1]) under the matrix `m`: the boxes of its two
    end circles (Mitsuba's bound)."""
    m = np.asarray(m, np.float64)
    half = np.sqrt(m[:3, 0] ** 2 + m[:3, 1] ** 2)      # extent of a transformed unit circle per axis
    p0, p1 = m[:3, 3], m[:3, 3] + m[:3, 2]
    return np.minimum(p0, p1) - half, np.maximum(p0, p1) + half
