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
