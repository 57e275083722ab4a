"""Faces of the scene's convex hull, which shadow rays from surfaces never need to test.

Every point a path can scatter from at a surface lies on the scene's geometry, so inside H, the
convex hull of all primitives. A light sample at a finite distance (a point on an emitting shape, or
a point or spot light inside H) lies in H too. A segment between two points of H cannot cross a
plane that supports H: both ends lie on the same side of it. So a triangle lying in such a plane
(a wall, floor or ceiling of a room, the outer faces of a box) can never block, tint or change the
medium of such a shadow ray, and the kernels trace those rays through a second tree without these
faces (RenderParams.shadow_root). Shadow rays from points in media (which may lie outside H, in a
medium that fills space) and towards lights at infinity keep the whole scene.

Rounding: a hit point computed in float32 may lie a few ulps outside H, near an edge; the whole
scene's tree can then report the hull face beside it as a blocker a hair from the ray's start, which
the offset origin (kernels/common.h, 1e-5 of the coordinates' magnitude) is there to avoid anyway.
Such samples are the only ones whose bits the second tree can change.
"""
from __future__ import annotations

import numpy as np

from .bvh_instanced import box_corners

# Scenes with more primitives get no second tree: the test is an all-pairs one (triangles against
# points), and a big mesh gains little from skipping a few walls its rays rarely reach.
MAX_PRIMITIVES = 1024
# How far outside a face's plane (relative to the scene's largest coordinate) a point may lie and
# still count as on it: float32 corners of a flat quad are coplanar to about 1e-7 of their magnitude.
TOLERANCE = 1e-6
_CHUNK = 256


def hull_faces(tri_v, centers=(), radii=(), box_lo=(), box_hi=()):
    """Which triangles lie in a plane that supports the convex hull of everything: the triangles'
    corners `tri_v` (n, 3, 3), balls (centers, radii) and boxes (box_lo, box_hi: bounds of other
    primitives). Returns (mask over the triangles, their planes as (normals (k, 3) pointing out of
    the hull, offsets (k,)) for the k triangles of the mask, and the tolerance of inside())."""
    tri = np.asarray(tri_v, np.float64).reshape(-1, 3, 3)
    centers = np.asarray(centers, np.float64).reshape(-1, 3)
    radii = np.asarray(radii, np.float64).reshape(-1)
    lo, hi = np.asarray(box_lo, np.float64).reshape(-1, 3), np.asarray(box_hi, np.float64).reshape(-1, 3)
    corners = [box_corners(l, h) for l, h in zip(lo, hi)]
    # (repeated corners change no maximum; np.unique would import numpy.ma, 8 ms of every start-up)
    points = np.concatenate([tri.reshape(-1, 3), *corners])
    reach = max(float(np.abs(points).max(initial=0.0)),
                float((np.abs(centers).max(axis=1) + radii).max(initial=0.0)) if len(radii) else 0.0)
    tol = TOLERANCE * reach
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(n, axis=1)
    mask = np.zeros(len(tri), bool)
    normals = np.zeros((len(tri), 3))
    for a in range(0, len(tri), _CHUNK):
        b = min(a + _CHUNK, len(tri))
        ok = length[a:b] > 0
        u = n[a:b] / np.where(ok, length[a:b], 1.0)[:, None]
        c = np.einsum("ij,ij->i", u, tri[a:b, 0])
        d = points @ u.T - c                                    # (points, triangles)
        s = centers @ u.T - c
        top = np.maximum(d.max(axis=0, initial=-np.inf), (s + radii[:, None]).max(axis=0, initial=-np.inf))
        bottom = np.minimum(d.min(axis=0, initial=np.inf), (s - radii[:, None]).min(axis=0, initial=np.inf))
        below, above = top <= tol, bottom >= -tol
        # a flat scene (everything in one plane) has no inside to keep rays in: no face of it counts
        mask[a:b] = ok & (below != above)
        normals[a:b] = np.where(below[:, None], u, -u)
    offsets = np.einsum("ij,ij->i", normals[mask], tri[mask, 0])
    return mask, (normals[mask], offsets), tol


def inside(points, planes, tol) -> bool:
    """Whether every point lies inside (or within tol of) every plane of `planes` (hull_faces')."""
    normals, offsets = planes
    points = np.asarray(points, np.float64).reshape(-1, 3)
    if len(points) == 0 or len(offsets) == 0:
        return True
    return bool(np.all(points @ normals.T - offsets <= tol))
