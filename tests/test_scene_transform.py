"""Transform ops against hand-computed matrices, directly and through scene XML."""
import math

import numpy as np
import pytest

from volcl.scene import load, transform as tf
from volcl.scene.properties import parse_property
from volcl.scene.xml import parse_bytes


def _sensor_matrix(tmp_path, ops: str) -> np.ndarray:
    """The matrix of <transform name="to_world">ops</transform>, parsed as a scene file would."""
    el = parse_bytes(f'<transform name="to_world">{ops}</transform>'.encode(), "t.xml")
    return parse_property(el).value


def _loaded_sensor_matrix(tmp_path, ops: str) -> np.ndarray:
    path = tmp_path / "t.xml"
    path.write_text(f"""<scene version="3.0.0">
        <sensor type="perspective"><float name="fov" value="40"/>
            <transform name="to_world">{ops}</transform>
        </sensor></scene>""")
    return load(path).camera.to_world


def _nori_camera_matrix(tmp_path, ops: str) -> np.ndarray:
    path = tmp_path / "n.xml"
    path.write_text(f"""<scene><integrator type="path_mis"/>
        <camera type="perspective"><transform name="toWorld">{ops}</transform></camera>
        </scene>""")
    return load(path).camera.to_world


def test_translate_forms(tmp_path):
    expected = np.array([[1, 0, 0, 1], [0, 1, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]], float)
    assert np.allclose(_sensor_matrix(tmp_path, '<translate value="1, 2, 3"/>'), expected)
    assert np.allclose(_sensor_matrix(tmp_path, '<translate x="1" y="2" z="3"/>'), expected)
    assert np.allclose(_sensor_matrix(tmp_path, '<translate value="1 2 3"/>'), expected)
    # Missing components default to 0.
    assert np.allclose(_sensor_matrix(tmp_path, '<translate y="2"/>')[:3, 3], [0, 2, 0])


def test_scale_forms(tmp_path):
    assert np.allclose(_sensor_matrix(tmp_path, '<scale value="2"/>'), np.diag([2, 2, 2, 1]))
    assert np.allclose(_sensor_matrix(tmp_path, '<scale value="2, 3, 4"/>'), np.diag([2, 3, 4, 1]))
    # Missing components default to 1.
    assert np.allclose(_sensor_matrix(tmp_path, '<scale x="2" z="4"/>'), np.diag([2, 1, 4, 1]))


@pytest.mark.parametrize("axis, expected", [
    ("x", [[1, 0, 0], [0, 0, -1], [0, 1, 0]]),
    ("y", [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]),
    ("z", [[0, -1, 0], [1, 0, 0], [0, 0, 1]]),
])
def test_rotate_90_degrees_about_each_axis_is_right_handed(tmp_path, axis, expected):
    m = _sensor_matrix(tmp_path, f'<rotate {axis}="1" angle="90"/>')
    assert np.allclose(m[:3, :3], expected)
    assert np.allclose(m[:3, 3], 0)


def test_rotate_about_an_arbitrary_axis(tmp_path):
    # 120 degrees about (1,1,1) cycles the axes: x -> y -> z -> x.
    m = _sensor_matrix(tmp_path, '<rotate value="1, 1, 1" angle="120"/>')
    assert np.allclose(m[:3, :3], [[0, 0, 1], [1, 0, 0], [0, 1, 0]])
    # 45 degrees about z, axis not normalised, given as x/y/z attributes.
    c = math.sqrt(0.5)
    m = _sensor_matrix(tmp_path, '<rotate z="5" angle="45"/>')
    assert np.allclose(m[:3, :3], [[c, -c, 0], [c, c, 0], [0, 0, 1]])


def test_matrix_is_row_major(tmp_path):
    values = "1 0 0 5  0 0 -1 6  0 1 0 7  0 0 0 1"
    m = _sensor_matrix(tmp_path, f'<matrix value="{values}"/>')
    assert np.allclose(m, np.array(values.split(), float).reshape(4, 4))


def test_lookat_columns(tmp_path):
    m = _loaded_sensor_matrix(tmp_path, '<lookat origin="1, 2, 3" target="1, 2, 4" up="0, 1, 0"/>')
    # dir = +z, left = normalize(cross(up, dir)) = +x, up' = cross(dir, left) = +y.
    assert np.allclose(m, [[1, 0, 0, 1], [0, 1, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]])
    m = _sensor_matrix(tmp_path, '<lookat origin="0, 0, 0" target="-2, 0, 0" up="0, 0, 1"/>')
    # dir = -x, left = cross(+z, -x) = -y, up' = cross(-x, -y) = +z.
    assert np.allclose(m[:3, :3], [[0, 0, -1], [-1, 0, 0], [0, 1, 0]])


def test_lookat_without_up_uses_mitsubas_coordinate_system(tmp_path):
    m = _sensor_matrix(tmp_path, '<lookat origin="0, 0, 0" target="0, 0, 1"/>')
    # For dir = +z, Mitsuba's coordinate_system gives (1, 0, 0) as up; left = cross(x, z) = -y.
    assert np.allclose(m[:3, 2], [0, 0, 1])
    assert np.allclose(m[:3, 1], [1, 0, 0])
    assert np.allclose(m[:3, 0], [0, -1, 0])
    r = m[:3, :3]
    assert np.allclose(r.T @ r, np.eye(3))


def test_composition_applies_each_op_after_the_previous(tmp_path):
    # scale then translate: p -> 2 p + t.
    m = _sensor_matrix(tmp_path, '<scale value="2"/><translate value="1, 0, 0"/>')
    assert np.allclose(tf.apply_point(m, [1, 1, 1]), [3, 2, 2])
    # translate then scale: p -> 2 (p + t).
    m = _sensor_matrix(tmp_path, '<translate value="1, 0, 0"/><scale value="2"/>')
    assert np.allclose(tf.apply_point(m, [1, 1, 1]), [4, 2, 2])
    # rotate z 90 then translate x: (1, 0, 0) -> (0, 1, 0) -> (1, 1, 0).
    m = _sensor_matrix(tmp_path, '<rotate z="1" angle="90"/><translate x="1"/>')
    assert np.allclose(tf.apply_point(m, [1, 0, 0]), [1, 1, 0])


def test_nori_mirror_scale_before_lookat(tmp_path):
    # The cbox idiom: scale -1,1,1 then lookat mirrors the camera's left axis.
    ops = '<scale value="-1,1,1"/><lookat origin="0, 0, 0" target="0, 0, 1" up="0, 1, 0"/>'
    m = _nori_camera_matrix(tmp_path, ops)
    # left = cross(up, dir) = cross(+y, +z) = +x, so lookat = I, and the scale flips x.
    assert np.allclose(m, np.diag([-1, 1, 1, 1]))


def test_normals_use_the_inverse_transpose():
    m = tf.scale([2, 1, 1])
    n = tf.apply_normal(m, [[1, 1, 0]])
    assert np.allclose(n, [[1 / math.sqrt(5), 2 / math.sqrt(5), 0]])


def test_similarity_scale():
    m = tf.translate([1, 2, 3]) @ tf.rotate([1, 2, 3], 33) @ tf.scale(2.5)
    assert tf.similarity_scale(m) == pytest.approx(2.5)
    assert tf.similarity_scale(tf.scale([1, 2, 1])) is None
