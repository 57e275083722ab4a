"""Meshes: file loading with and without normals, world-space placement, primitives."""
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from volcl import mesh
from volcl.scene import load
from volcl.scene import transform as tf

DATA = Path(__file__).parent / "data" / "scene"
_HERE = Path(__file__).resolve()
NORI = next((p for p in (_HERE.parents[2] / "shared" / "nori", Path("/work/shared/nori"))
             if p.is_dir()), None)
needs_nori = pytest.mark.skipif(NORI is None, reason="shared/nori scenes not found")

SENSOR = '<sensor type="perspective"><float name="fov" value="40"/></sensor>'


def scene(tmp_path, body: str):
    for name in ("tetra.obj", "triangle_normals.ply", "quad.ply"):
        shutil.copy(DATA / name, tmp_path / name)
    path = tmp_path / "scene.xml"
    path.write_text(f'<scene version="3.0.0">{SENSOR}\n{body}\n</scene>\n')
    return load(path)


def geometric_normals(shape) -> np.ndarray:
    v, f = shape.vertices, shape.faces
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


@needs_nori
def test_cbox_sphere_keeps_file_normals_unless_face_normals(tmp_path):
    sphere = NORI / "cbox" / "meshes" / "sphere1.obj"
    body = (f'<shape type="obj"><string name="filename" value="{sphere}"/></shape>'
            f'<shape type="obj"><string name="filename" value="{sphere}"/>'
            f'<boolean name="face_normals" value="true"/></shape>')
    smooth, flat = scene(tmp_path, body).shapes
    assert smooth.normals is not None and smooth.normals.shape == smooth.vertices.shape
    assert np.allclose(np.linalg.norm(smooth.normals, axis=1), 1)
    # Smooth normals of a sphere point away from its centre.
    radial = smooth.vertices - smooth.vertices.mean(axis=0)
    assert (np.sum(radial * smooth.normals, axis=1) > 0).all()
    assert flat.normals is None
    assert np.array_equal(flat.faces, smooth.faces)


def test_file_without_normals_has_none(tmp_path):
    (shape,) = scene(tmp_path, '<shape type="ply"><string name="filename" value="quad.ply"/>'
                               '</shape>').shapes
    assert shape.normals is None
    assert len(shape.faces) == 2          # the quad is triangulated


def test_ply_normals_are_read_and_normalised(tmp_path):
    (shape,) = scene(tmp_path, '<shape type="ply"><string name="filename" '
                               'value="triangle_normals.ply"/></shape>').shapes
    s = math.sqrt(0.5)
    assert np.allclose(shape.normals, [[0, 0, 1], [0, s, s], [s, 0, s]])


def test_normals_follow_the_inverse_transpose(tmp_path):
    body = ('<shape type="obj"><string name="filename" value="tetra.obj"/>'
            '<transform name="to_world"><scale value="2, 1, 1"/><rotate z="1" angle="90"/>'
            '<translate value="5, 0, 0"/></transform></shape>')
    (shape,) = scene(tmp_path, body).shapes
    m = tf.translate([5, 0, 0]) @ tf.rotate([0, 0, 1], 90) @ tf.scale([2, 1, 1])
    raw = mesh.load_mesh(str(DATA / "tetra.obj"))
    assert np.allclose(shape.vertices, raw.vertices @ m[:3, :3].T + m[:3, 3])
    expected = raw.normals @ np.linalg.inv(m[:3, :3])      # n' = M^-T n, as rows
    expected /= np.linalg.norm(expected, axis=1, keepdims=True)
    assert np.allclose(shape.normals, expected)


def test_flip_normals_reverses_winding_and_normals(tmp_path):
    body = ('<shape type="obj"><string name="filename" value="tetra.obj"/></shape>'
            '<shape type="obj"><string name="filename" value="tetra.obj"/>'
            '<boolean name="flip_normals" value="true"/></shape>')
    plain, flipped = scene(tmp_path, body).shapes
    assert np.array_equal(flipped.faces, plain.faces[:, ::-1])
    assert np.allclose(flipped.normals, -plain.normals)
    assert np.allclose(geometric_normals(flipped), -geometric_normals(plain))
    assert flipped.flip_normals and not plain.flip_normals


def test_rectangle_faces_plus_z(tmp_path):
    (shape,) = scene(tmp_path, '<shape type="rectangle"/>').shapes
    assert len(shape.faces) == 2 and shape.normals is None
    assert np.allclose(geometric_normals(shape), [0, 0, 1])
    assert np.allclose(shape.vertices.min(axis=0), [-1, -1, 0])
    assert np.allclose(shape.vertices.max(axis=0), [1, 1, 0])


def test_cube_is_outward_and_flat(tmp_path):
    (shape,) = scene(tmp_path, '<shape type="cube"/>').shapes
    assert len(shape.faces) == 12 and shape.normals is None
    centres = shape.vertices[shape.faces].mean(axis=1)
    n = geometric_normals(shape)
    assert (np.sum(n * centres, axis=1) > 0).all()
    # Each face normal is an axis: the triangles lie on the cube's faces.
    assert np.allclose(np.abs(n).max(axis=1), 1)


def test_disk_area_and_normal(tmp_path):
    (shape,) = scene(tmp_path, '<shape type="disk"/>').shapes
    v, f = shape.vertices, shape.faces
    area = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]),
                                axis=1).sum()
    assert abs(area - math.pi) < 1e-4
    assert np.allclose(geometric_normals(shape), [0, 0, 1])
    assert np.allclose(np.linalg.norm(v[1:], axis=1), 1)


def test_primitives_follow_to_world(tmp_path):
    body = ('<shape type="rectangle"><transform name="to_world"><rotate x="1" angle="90"/>'
            '</transform></shape>')
    (shape,) = scene(tmp_path, body).shapes
    assert np.allclose(geometric_normals(shape), [0, -1, 0])   # +z rotated 90 about x


OBJ_CASES = {
    # triangles, a quad and a pentagon in between, in file order
    "polygons.obj": "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 2 0\n"
                    "f 1 2 3\nf 1 2 3 4\nf 2 3 4\nf 1 3 4 5 2\nf 3 4 5\n",
    # normals per corner, negative (relative) indices; texture coordinates on some corners only
    "normals.obj": "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\nvn 0 0 -1\n"
                   "f 1/1/1 2/1/2 3/1/1\nf -4//-2 -2//-1 -1//-2\n",
    # texture coordinates on every corner: a shared position with two coordinates splits
    "uvs.obj": "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0.25 0.5\n"
               "f 1/1 2/2 3/3\nf 1/4 3/3 4/2\n",
    # objects and smoothing groups change nothing; a shared position with two normals splits
    "groups.obj": "o a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nvn 1 0 0\ns 1\nf 1//1 2//1 3//1\n"
                  "o b\nv 0 0 1\nf 1//2 2//2 4//2\n",
}


@pytest.mark.parametrize("name", sorted(OBJ_CASES))
def test_obj_reader_matches_trimesh_corner_for_corner(tmp_path, name):
    """volcl reads OBJ files itself (trimesh's import is slow); without material groups its result
    is trimesh's, triangle by triangle: positions, normals and texture coordinates of every corner,
    in the same order."""
    from trimesh.exchange.obj import load_obj
    path = tmp_path / name
    path.write_text(OBJ_CASES[name])
    ours = mesh.load_mesh(str(path))
    with open(path, "rb") as fh:
        parts = list(load_obj(fh, skip_materials=True)["geometry"].values())
    ref = mesh._concatenate(parts)
    np.testing.assert_array_equal(ours.vertices[ours.faces], ref.vertices[ref.faces])
    assert (ours.normals is None) == (ref.normals is None)
    if ours.normals is not None:
        np.testing.assert_array_equal(ours.normals[ours.faces], ref.normals[ref.faces] /
                                      np.linalg.norm(ref.normals[ref.faces], axis=-1, keepdims=True))
    assert (ours.uvs is None) == (ref.uvs is None)
    if ours.uvs is not None:
        np.testing.assert_array_equal(ours.uvs[ours.faces], ref.uvs[ref.faces])


@needs_nori
def test_obj_reader_keeps_file_order_across_material_groups():
    """The Nori walls: three objects with their own materials; faces stay in file order (trimesh
    regroups them by material), as Mitsuba reads them."""
    m = mesh.load_mesh(str(NORI / "cbox" / "meshes" / "walls.obj"))
    corners = m.vertices[m.faces]
    assert len(corners) == 6
    np.testing.assert_allclose(corners[0], [[1.0, 1.59, -1.04], [1.0, 1.59, 0.99], [-1.02, 1.59, 0.99]])
    assert np.all(corners[2:4, :, 1] == 0.0) and np.all(corners[4:, :, 2] == -1.04)


def test_closure_check_without_trimesh():
    """Closed and consistently wound, open, non-manifold and inconsistently wound surfaces."""
    cube = mesh.cube()
    assert mesh.closure_problem(cube.vertices, cube.faces) is None
    assert "not closed" in mesh.closure_problem(cube.vertices, cube.faces[:-1])
    flipped = cube.faces.copy()
    flipped[0] = flipped[0, ::-1]
    assert "not wound consistently" in mesh.closure_problem(cube.vertices, flipped)
    fin = np.vstack([cube.faces, [[0, 1, 7]], [[0, 7, 1]]])
    assert "more than two" in mesh.closure_problem(cube.vertices, fin)
