"""4x4 homogeneous transforms: the ops a scene file composes, and applying them to points and normals.

Matrices act on column vectors (p' = M @ p). A scene's ops compose in document order with each new op
applied after the ones before it, so the accumulated matrix is updated as M = op @ M.
"""
from __future__ import annotations

import math

import numpy as np


def translate(v) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = v
    return m


def scale(v) -> np.ndarray:
    return np.diag([*np.broadcast_to(np.asarray(v, dtype=np.float64), (3,)), 1.0])


def normalize(v) -> np.ndarray:
    """Unit vector along `v`; zero stays zero. Dividing by the largest component first keeps
    the norm of huge vectors from overflowing."""
    v = np.asarray(v, dtype=np.float64)
    biggest = np.abs(v).max()
    if not biggest > 0:
        return np.zeros_like(v)
    v = v / biggest
    return v / np.linalg.norm(v)


def rotate(axis, angle_degrees: float, normalize_axis: bool = True) -> np.ndarray:
    """Right-handed rotation about `axis` (not zero) by Rodrigues' formula,
    cos I + sin [a]x + (1 - cos) a a^T. With normalize_axis=False the axis is used as given, as
    Mitsuba 3 does (Dr.Jit's rotate): an axis that is not of unit length then also scales and shears."""
    k = normalize(axis) if normalize_axis else np.asarray(axis, dtype=np.float64)
    theta = np.radians(angle_degrees)
    cross = np.array([[0.0, -k[2], k[1]],
                      [k[2], 0.0, -k[0]],
                      [-k[1], k[0], 0.0]])
    m = np.eye(4)
    m[:3, :3] = np.cos(theta) * np.eye(3) + np.sin(theta) * cross + (1 - np.cos(theta)) * np.outer(k, k)
    return m


def coordinate_system(n) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors perpendicular to unit `n` (Duff et al. 2017, the basis Mitsuba 3 builds).

    Mitsuba 3 takes the first one as the `up` of a lookat that gives none, so a file without `up`
    frames the same image in both renderers.
    """
    n = np.asarray(n, dtype=np.float64)
    sign = math.copysign(1.0, n[2])
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    s = np.array([1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]])
    t = np.array([b, sign + n[1] * n[1] * a, -n[1]])
    return s, t


def lookat(origin, target, up=None) -> np.ndarray:
    """Camera-to-world frame at `origin` looking at `target`: columns left, up, dir, origin.

    Raises ValueError when the frame is degenerate (origin == target, or up parallel to the view).
    """
    origin = np.asarray(origin, dtype=np.float64)
    direction = normalize(np.asarray(target, dtype=np.float64) - origin)
    if not np.isfinite(direction).all() or not np.any(direction):
        raise ValueError("origin and target coincide (or are not finite)")
    if up is None or not np.any(up):
        up = coordinate_system(direction)[0]
    left = np.cross(normalize(up), direction)
    if not np.linalg.norm(left) > 1e-9:
        raise ValueError("up is parallel to the viewing direction")
    left = normalize(left)
    new_up = np.cross(direction, left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, new_up, direction, origin
    return m


def apply_point(m: np.ndarray, p) -> np.ndarray:
    """Transform points (..., 3) by the affine 4x4 `m`."""
    p = np.asarray(p, dtype=np.float64)
    return p @ m[:3, :3].T + m[:3, 3]


def apply_vector(m: np.ndarray, v) -> np.ndarray:
    return np.asarray(v, dtype=np.float64) @ m[:3, :3].T


def apply_normal(m: np.ndarray, n) -> np.ndarray:
    """Transform normals (..., 3) by the inverse transpose of `m` and renormalise them."""
    inv_t = np.linalg.inv(m[:3, :3]).T
    out = np.asarray(n, dtype=np.float64) @ inv_t.T
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def is_invertible(m: np.ndarray) -> bool:
    """Finite and well-conditioned; the condition number (not the determinant) decides, so a tiny
    uniform scale is fine while a flattening one is not."""
    if not np.isfinite(m).all():
        return False
    return bool(np.linalg.cond(m[:3, :3]) < 1e12)


def similarity_scale(m: np.ndarray, rtol: float = 1e-4) -> float | None:
    """The uniform scale s if the linear part of `m` is s times an orthogonal matrix, else None.

    The tolerance admits matrices typed into a file with five or six significant digits.
    """
    lin = m[:3, :3]
    gram = lin.T @ lin
    s2 = np.trace(gram) / 3.0
    if not s2 > 0 or np.abs(gram - s2 * np.eye(3)).max() > rtol * s2:
        return None
    if np.abs(m[3] - [0, 0, 0, 1]).max() > 0:
        return None
    return float(np.sqrt(s2))
