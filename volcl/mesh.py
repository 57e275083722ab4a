"""Triangle meshes: OBJ files (read here), PLY files (read through trimesh), Mitsuba's .serialized
files (volcl.serialized), and the primitive shapes scenes name.

Everything here is in object space; volcl.scene places meshes in the world. A mesh is a
`TriangleMesh` of float64 vertices (n, 3), int64 faces (m, 3), optional per-vertex shading
normals (n, 3), present only when the file itself stores them, and optional texture coordinates
(n, 2) where the file has them, as the file stores them (the Mitsuba dialect flips OBJ's v).
"""
from __future__ import annotations

import logging
import os
import warnings
import weakref
from contextlib import contextmanager
from typing import NamedTuple, Optional

import numpy as np

from .errors import VolclError


class TriangleMesh(NamedTuple):
    vertices: np.ndarray
    faces: np.ndarray
    normals: Optional[np.ndarray] = None
    uvs: Optional[np.ndarray] = None


_FORMATS = ("obj", "ply", "serialized")


def load_mesh(path: str, fmt: Optional[str] = None, shape_index: int = 0) -> TriangleMesh:
    """Read a mesh file as `fmt` ('obj', 'ply' or 'serialized', shape number `shape_index`; default:
    from the extension).

    Every problem with the file is a VolclError naming it.
    """
    ext = fmt or os.path.splitext(path)[1].lower().lstrip(".")
    if ext not in _FORMATS:
        raise VolclError(f"unsupported mesh format '{ext}'; supported: obj, ply, serialized", file=path)
    if ext == "serialized":
        from .serialized import load_serialized
        return load_serialized(path, shape_index)
    if not os.path.isfile(path):
        # Also refuses devices such as /dev/zero, which would never finish reading.
        raise VolclError("mesh file not found (or not a regular file)", file=path)
    try:
        with open(path, "rb") as fh:
            if ext == "obj":
                mesh = _read_obj(fh.read())
            else:
                with _quiet_trimesh():
                    mesh = _concatenate(_read_parts(fh, ext))
    except OSError as exc:
        raise VolclError(f"cannot read mesh file: {exc.strerror or exc}", file=path) from None
    except Exception as exc:  # the parsers raise many unrelated types on bad input
        raise VolclError(f"cannot parse {ext.upper()} mesh: {type(exc).__name__}: {exc}",
                         file=path) from None
    return _validated(mesh, path)


def _read_obj(data: bytes) -> TriangleMesh:
    """An OBJ file's faces as one mesh (groups and objects joined, as Mitsuba does; materials
    skipped: volcl takes materials from the scene file, and the Nori meshes name .mtl files that
    do not exist).

    Read here rather than through trimesh, whose import (it pulls in scipy where that is
    installed) took longer than a whole small render. The result matches trimesh's OBJ loader
    corner for corner: faces in file order, a quad split into (0, 1, 2) and (2, 3, 0), larger
    polygons into a fan around their first corner, negative indices counted back from the
    vertices defined so far, and one vertex per distinct (position, texture coordinate, normal)
    triple, with shading normals (texture coordinates) exactly when every corner of the file
    names one.
    """
    positions, normal_rows, uv_rows = [], [], []
    corner_v, corner_t, corner_n, sizes = [], [], [], []
    for line in data.decode("utf-8", "replace").splitlines():
        tokens = line.split()
        if not tokens:
            continue
        key = tokens[0]
        if key == "v":
            positions.append(tokens[1:4])
        elif key == "vn":
            normal_rows.append(tokens[1:4])
        elif key == "vt":
            uv_rows.append((tokens[1:3] + ["0"])[:2])
        elif key == "f":
            nv, nt, nn = len(positions), len(uv_rows), len(normal_rows)
            for corner in tokens[1:]:
                idx = corner.split("/")
                v = int(idx[0])
                corner_v.append(v - 1 if v > 0 else nv + v)
                vt = int(idx[1]) if len(idx) > 1 and idx[1] else 0
                corner_t.append(vt - 1 if vt > 0 else (nt + vt if vt < 0 else -1))
                n = int(idx[2]) if len(idx) > 2 and idx[2] else 0
                corner_n.append(n - 1 if n > 0 else (nn + n if n < 0 else -1))
            sizes.append(len(tokens) - 1)
    if any(len(row) != 3 for row in positions) or any(len(row) != 3 for row in normal_rows):
        raise ValueError("a v or vn line has fewer than three coordinates")
    pos = np.array(positions, dtype=np.float64).reshape(-1, 3)
    nrm = np.array(normal_rows, dtype=np.float64).reshape(-1, 3)
    tex = np.array(uv_rows, dtype=np.float64).reshape(-1, 2)
    corners = _triangulate_polygons(np.array(sizes, dtype=np.int64))
    cv = np.array(corner_v, dtype=np.int64)[corners]
    ct = np.array(corner_t, dtype=np.int64)[corners]
    cn = np.array(corner_n, dtype=np.int64)[corners]
    if len(cv) == 0:
        return TriangleMesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))
    bad = (cv < 0) | (cv >= len(pos))
    with_normals = bool(len(cn)) and bool(np.all((cn >= 0) & (cn < len(nrm))))
    with_uvs = bool(len(ct)) and bool(np.all((ct >= 0) & (ct < len(tex))))
    keys = np.stack([cv, ct if with_uvs else np.zeros_like(ct), cn if with_normals else np.zeros_like(cn)],
                    axis=-1).reshape(-1, 3)
    unique, inverse = np.unique(keys, axis=0, return_inverse=True)
    faces = inverse.reshape(-1, 3)
    if bad.any():
        faces[bad] = -1         # refused by _validated: faces that index missing vertices
    verts = pos[np.clip(unique[:, 0], 0, max(len(pos) - 1, 0))] if len(pos) else np.zeros((len(unique), 3))
    return TriangleMesh(verts, faces.astype(np.int64), nrm[unique[:, 2]] if with_normals else None,
                        tex[unique[:, 1]] if with_uvs else None)


def _triangulate_polygons(sizes: np.ndarray) -> np.ndarray:
    """Corner indices (m, 3) into the concatenated polygons of the given sizes: triangles as they
    are, quads as (0, 1, 2), (2, 3, 0), larger polygons as fans (0, i, i + 1), in polygon order."""
    if len(sizes) and sizes.min() < 3:
        raise ValueError(f"a face has {int(sizes.min())} corners")
    start = np.cumsum(sizes) - sizes
    per = np.maximum(sizes - 2, 0)
    poly = np.repeat(np.arange(len(sizes)), per)
    i = np.arange(per.sum()) - np.repeat(np.cumsum(per) - per, per)
    tri = np.stack([np.zeros_like(i), i + 1, i + 2], axis=1)
    quad = sizes[poly] == 4
    tri[quad & (i == 1)] = [2, 3, 0]
    return start[poly][:, None] + tri


def _read_parts(fh, ext: str) -> list[dict]:
    """A PLY file's geometry as a trimesh keyword dict, in a list.

    The loader is called directly rather than through trimesh.load so that 'vertex_normals'
    appears exactly when the file stores normals, instead of being computed."""
    from trimesh.exchange.ply import load_ply
    return [load_ply(fh, skip_materials=True)]


@contextmanager
def _quiet_trimesh():
    logger = logging.getLogger("trimesh")
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        # trimesh's texture-coordinate merging warns on NaN medians for meshes with one shared vt.
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            yield
    finally:
        logger.setLevel(level)


def _concatenate(parts: list[dict]) -> TriangleMesh:
    vertices, faces, normals, uvs = [], [], [], []
    offset = 0
    for part in parts:
        v = np.asarray(part.get("vertices", np.zeros((0, 3))), dtype=np.float64).reshape(-1, 3)
        f = _triangulate(part.get("faces"))
        n = part.get("vertex_normals")
        uv = getattr(part.get("visual"), "uv", None)
        vertices.append(v)
        faces.append(f + offset)
        normals.append(None if n is None else np.asarray(n, dtype=np.float64).reshape(-1, 3))
        uvs.append(None if uv is None else np.asarray(uv, dtype=np.float64).reshape(-1, 2))
        offset += len(v)
    if not vertices:
        return TriangleMesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))
    # Shading normals (and uvs) only when every part has them; a partial set cannot be used consistently.
    has_normals = all(n is not None and len(n) == len(v) for n, v in zip(normals, vertices))
    has_uvs = all(uv is not None and len(uv) == len(v) for uv, v in zip(uvs, vertices))
    return TriangleMesh(np.concatenate(vertices), np.concatenate(faces),
                        np.concatenate(normals) if has_normals else None,
                        np.concatenate(uvs) if has_uvs else None)


def _triangulate(faces) -> np.ndarray:
    """Triangles from polygons as fans around their first corner; the PLY loader keeps quads and
    n-gons as they are in the file (a rectangular array, or a list when sizes are mixed)."""
    if faces is None or len(faces) == 0:
        return np.zeros((0, 3), dtype=np.int64)
    try:
        polygons = [np.asarray(faces, dtype=np.int64)]
    except ValueError:       # ragged: polygons of several sizes, grouped by size
        by_size: dict[int, list] = {}
        for polygon in faces:
            by_size.setdefault(len(polygon), []).append(polygon)
        polygons = [np.asarray(group, dtype=np.int64) for group in by_size.values()]
    triangles = []
    for group in polygons:
        group = group.reshape(len(group), -1)
        corners = group.shape[1]
        if corners < 3:
            raise ValueError(f"a face has {corners} corners")
        for i in range(1, corners - 1):
            triangles.append(group[:, [0, i, i + 1]])
    return np.concatenate(triangles)


def _validated(mesh: TriangleMesh, path: str) -> TriangleMesh:
    v, f, n, uv = mesh
    if len(v) == 0 or len(f) == 0:
        raise VolclError("the mesh is empty (no triangles)", file=path)
    if not np.isfinite(v).all():
        raise VolclError("the mesh has non-finite vertex positions", file=path)
    if f.min() < 0 or f.max() >= len(v):
        raise VolclError("the mesh has faces that index missing vertices", file=path)
    if n is not None:
        length = np.linalg.norm(n, axis=1)
        if not (np.isfinite(length).all() and (length > 0).all()):
            raise VolclError("the mesh has zero-length or non-finite vertex normals; "
                             "fix the file or set face_normals=true", file=path)
        n = n / length[:, None]
    if uv is not None and not np.isfinite(uv).all():
        uv = None       # unusable texture coordinates are dropped: textures then read barycentric ones
    return TriangleMesh(v, f, n, uv)


def validated(mesh: TriangleMesh, path: str) -> TriangleMesh:
    """The checks every mesh file gets (volcl.serialized uses them too)."""
    return _validated(mesh, path)


def mitsuba_vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Smooth vertex normals as Mitsuba 3 computes them for a mesh file without normals
    (Mesh::recompute_vertex_normals, after Thurmer and Wuthrich 1998): each vertex sums the unit
    normals of its triangles, each weighted by the triangle's angle at that vertex, and normalizes.
    Degenerate triangles add nothing; a vertex left with a zero sum gets Mitsuba's placeholder
    (1, 0, 0), which only degenerate triangles use. Computed in float32 like Mitsuba."""
    p = np.asarray(vertices, np.float32)[faces]                       # (m, 3 corners, 3)
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]).astype(np.float64)
    length = np.linalg.norm(n, axis=1)
    valid = length > 0
    n = n[valid] / length[valid, None]
    p = p[valid].astype(np.float64)
    sums = np.zeros((len(vertices), 3))
    for corner in range(3):
        a = p[:, (corner + 1) % 3] - p[:, corner]
        b = p[:, (corner + 2) % 3] - p[:, corner]
        a /= np.maximum(np.linalg.norm(a, axis=1, keepdims=True), 1e-300)
        b /= np.maximum(np.linalg.norm(b, axis=1, keepdims=True), 1e-300)
        angle = _unit_angle(a, b)
        np.add.at(sums, faces[valid, corner], n * angle[:, None])
    norm = np.linalg.norm(sums, axis=1)
    out = np.tile([1.0, 0.0, 0.0], (len(vertices), 1))
    ok = norm > 0
    out[ok] = sums[ok] / norm[ok, None]
    return out


def _unit_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The angle between unit vectors, accurate also near 0 and pi (Mitsuba's unit_angle)."""
    dot = (a * b).sum(axis=1)
    near = 2.0 * np.arcsin(np.clip(0.5 * np.linalg.norm(a - b, axis=1), 0.0, 1.0))
    far = np.pi - 2.0 * np.arcsin(np.clip(0.5 * np.linalg.norm(a + b, axis=1), 0.0, 1.0))
    return np.where(dot >= 0, near, far)


def normals_are_flat(vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray, tol: float = 1e-6) -> bool:
    """Whether every triangle's interpolated shading normal is its own face normal (a planar mesh
    with recomputed normals, say): such normals change nothing, and the kernels need not read them."""
    p = np.asarray(vertices, np.float64)[faces]
    ng = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    length = np.linalg.norm(ng, axis=1)
    keep = length > 0
    ng = ng[keep] / length[keep, None]
    corner_normals = np.asarray(normals, np.float64)[faces[keep]]          # (m, 3, 3)
    return bool(np.all(np.abs(corner_normals - ng[:, None, :]).max(axis=(1, 2)) <= tol))


def triangle_areas32(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Triangle areas of the mesh as the kernels see it: corners rounded to float32 (where slivers
    can collapse to nothing), the area itself computed in float64."""
    v = np.asarray(vertices, dtype=np.float32).astype(np.float64)[faces]
    return 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)


# answers about a mesh's two arrays while they live: the scene checks ask closure_problem at load,
# volcl.sealed asks it and encloses_outward at every pack (seconds each on a million triangles)
_answers: dict = {}


def _remembered(vertices, faces, question, compute):
    """compute(vertices, faces), remembered under `question` for these two arrays while they live
    (they must not be edited in place meanwhile)."""
    key = (id(vertices), id(faces))
    kept = _answers.get(key)
    if kept is None or kept[0]() is not vertices or kept[1]() is not faces:
        if not (isinstance(vertices, np.ndarray) and isinstance(faces, np.ndarray)):
            return compute(vertices, faces)
        forget = lambda _, key=key: _answers.pop(key, None)     # noqa: E731
        kept = _answers[key] = (weakref.ref(vertices, forget), weakref.ref(faces, forget), {})
    if question not in kept[2]:
        kept[2][question] = compute(vertices, faces)
    return kept[2][question]


def closure_problem(vertices: np.ndarray, faces: np.ndarray) -> Optional[str]:
    """Why the mesh does not enclose a volume the way a medium boundary must, or None if it does
    (remembered for the same two arrays).

    The kernels decide inside and outside by the side a ray crosses each triangle from, so a medium
    needs a closed (watertight: every edge shared by exactly two triangles), consistently wound
    surface around it; a gap lets paths out of the medium, or into it without a crossing. Corners
    count as shared only when their float32 coordinates are equal, as they must be for the
    watertight intersection test; zero-area triangles are left out (rays never hit them).
    """
    return _remembered(vertices, faces, "closure", _closure)


def encloses_outward(vertices: np.ndarray, faces: np.ndarray) -> bool:
    """Closed and consistently wound (closure_problem) and wound outwards: the signed volume its
    triangles enclose is positive (remembered for the same two arrays)."""
    return _remembered(vertices, faces, "outward", _encloses_outward)


def _encloses_outward(vertices, faces) -> bool:
    if closure_problem(vertices, faces) is not None:
        return False
    p = np.asarray(vertices, np.float64)[np.asarray(faces)]
    return float(np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum()) > 0.0


def _closure(vertices, faces) -> Optional[str]:
    # corners merged by their float32 bits (-0 made +0 first: equal floats, equal bits), as one
    # 12-byte key each: a 1-D unique, many times faster than unique over rows
    v32 = np.ascontiguousarray(np.asarray(vertices, dtype=np.float32) + np.float32(0.0))
    _, keep, inverse = np.unique(v32.view(np.dtype((np.void, 12))).reshape(-1), return_index=True,
                                 return_inverse=True)
    unique = v32[keep]
    f = inverse.reshape(-1)[np.asarray(faces)].reshape(-1, 3)
    f = f[triangle_areas32(unique, f) > 0]
    if len(f) == 0:
        return "all of its triangles have zero area"
    directed = f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2).astype(np.int64)
    edges = np.stack([directed.min(axis=1), directed.max(axis=1)], axis=1)
    n = np.int64(len(unique))
    _, first, counts = np.unique(edges[:, 0] * n + edges[:, 1], return_index=True, return_counts=True)
    if np.any(counts != 2):
        open_edges, shared = int((counts == 1).sum()), int((counts > 2).sum())
        parts = []
        if open_edges:
            a, b = edges[first[np.argmax(counts == 1)]]
            parts.append(f"{open_edges} edges border only one triangle (a hole or an open rim, e.g. "
                         f"the edge from {_point(unique[a])} to {_point(unique[b])})")
        if shared:
            a, b = edges[first[np.argmax(counts > 2)]]
            parts.append(f"{shared} edges are shared by more than two triangles (non-manifold, e.g. "
                         f"the edge from {_point(unique[a])} to {_point(unique[b])})")
        return "it is not closed: " + "; ".join(parts)
    # closed: consistently wound exactly when the two triangles at each edge run it in opposite
    # directions, i.e. no directed edge occurs twice
    runs = np.sort(directed[:, 0] * n + directed[:, 1])
    if np.any(runs[1:] == runs[:-1]):
        return ("its triangles are not wound consistently (some face normals point inwards, some "
                "outwards), so inside and outside are undefined")
    return None


def _point(p) -> str:
    return "(" + ", ".join(f"{float(x):.6g}" for x in p) + ")"


def rectangle() -> TriangleMesh:
    """[-1, 1]^2 at z = 0; the winding makes the geometric normal +z. Mitsuba's uvs: ((x + 1) / 2,
    (y + 1) / 2)."""
    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], dtype=np.float64)
    f = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64)
    return TriangleMesh(v, f, None, (v[:, :2] + 1.0) / 2.0)


def cube() -> TriangleMesh:
    """[-1, 1]^3 as Mitsuba's cube (src/shapes/cube.cpp): 24 corners (four per face, so that each
    face has its own uvs over [0, 1]^2) and 12 triangles wound so that every geometric normal points
    outward; flat."""
    v = np.array([[1, -1, -1], [1, -1, 1], [-1, -1, 1], [-1, -1, -1],
                  [1, 1, -1], [-1, 1, -1], [-1, 1, 1], [1, 1, 1],
                  [1, -1, -1], [1, 1, -1], [1, 1, 1], [1, -1, 1],
                  [1, -1, 1], [1, 1, 1], [-1, 1, 1], [-1, -1, 1],
                  [-1, -1, 1], [-1, 1, 1], [-1, 1, -1], [-1, -1, -1],
                  [1, 1, -1], [1, -1, -1], [-1, -1, -1], [-1, 1, -1]], dtype=np.float64)
    uv = np.tile(np.array([[0, 1], [1, 1], [1, 0], [0, 0]], dtype=np.float64), (6, 1))
    quads = np.arange(24).reshape(6, 4)
    f = np.concatenate([quads[:, [0, 1, 2]], quads[:, [3, 0, 2]]], axis=1).reshape(-1, 3)
    return TriangleMesh(v, f.astype(np.int64), None, uv)


DISK_SEGMENTS = 512


def disk(segments: int = DISK_SEGMENTS) -> TriangleMesh:
    """The unit disk at z = 0, normal +z, as a fan of `segments` triangles around the centre.

    The polygon's area is (n / 2) sin(2 pi / n), short of pi by about pi (2 pi / n)^2 / 6; with the
    512 segments used by default that is 7.9e-5, within the 1e-4 of pi volcl promises.
    """
    angle = 2.0 * np.pi * np.arange(segments) / segments
    rim = np.column_stack([np.cos(angle), np.sin(angle), np.zeros(segments)])
    v = np.vstack([[0.0, 0.0, 0.0], rim])
    i = np.arange(segments)
    f = np.column_stack([np.zeros(segments, dtype=np.int64), 1 + i, 1 + (i + 1) % segments])
    return TriangleMesh(v, f.astype(np.int64))
