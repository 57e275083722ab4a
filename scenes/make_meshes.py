#!/usr/bin/env python3
"""Writes the OBJ meshes the shipped scenes use (scenes/meshes/), so no geometry is downloaded.

The Cornell box: floor, ceiling and back wall, a red wall at x = -1 and a blue one at x = +1, all
facing into the box; a ceiling light facing down; and two spheres as OBJ meshes with vertex normals
for the Nori-dialect scenes (the Mitsuba-dialect scenes use analytic spheres at the same place).
Run it again to regenerate: python scenes/make_meshes.py
"""
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parent / "meshes"

# box extent: x in [-1, 1], y in [0, 1.59], z in [-1.04, 0.99]
X0, X1, Y0, Y1, Z0, Z1 = -1.0, 1.0, 0.0, 1.59, -1.04, 0.99
SPHERES = {"mirror_sphere": ((-0.421, 0.332, -0.28), 0.3263), "glass_sphere": ((0.446, 0.332, 0.377), 0.3263)}


def quad(p0, p1, p2, p3):
    """Two triangles p0 p1 p2, p0 p2 p3: counter-clockwise seen from the side the normal faces."""
    return np.array([p0, p1, p2, p3], float), np.array([[0, 1, 2], [0, 2, 3]])


def write_obj(name, verts, faces, normals=None):
    lines = [f"# {name}: written by scenes/make_meshes.py"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in verts]
    if normals is not None:
        lines += [f"vn {x:.6f} {y:.6f} {z:.6f}" for x, y, z in normals]
        lines += [f"f {a + 1}//{a + 1} {b + 1}//{b + 1} {c + 1}//{c + 1}" for a, b, c in faces]
    else:
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    (OUT / f"{name}.obj").write_text("\n".join(lines) + "\n")


def uv_sphere(center, radius, rings=32, segments=64):
    """A UV sphere with outward winding and exact per-vertex normals."""
    theta = np.linspace(0, np.pi, rings + 1)
    phi = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    t, p = np.meshgrid(theta[1:-1], phi, indexing="ij")
    n = np.stack([np.sin(t) * np.cos(p), np.cos(t), np.sin(t) * np.sin(p)], -1).reshape(-1, 3)
    n = np.concatenate([[[0, 1, 0]], n, [[0, -1, 0]]])
    faces = []
    ring = lambda i, j: 1 + i * segments + j % segments      # noqa: E731
    bottom = len(n) - 1
    for j in range(segments):
        faces.append((0, ring(0, j + 1), ring(0, j)))
        faces.append((bottom, ring(rings - 2, j), ring(rings - 2, j + 1)))
    for i in range(rings - 2):
        for j in range(segments):
            a, b, c, d = ring(i, j), ring(i, j + 1), ring(i + 1, j + 1), ring(i + 1, j)
            faces += [(a, b, c), (a, c, d)]
    return np.asarray(center) + radius * n, np.array(faces), n


def main():
    OUT.mkdir(exist_ok=True)
    walls = {
        "floor": quad((X0, Y0, Z1), (X1, Y0, Z1), (X1, Y0, Z0), (X0, Y0, Z0)),        # normal +y
        "ceiling": quad((X0, Y1, Z0), (X1, Y1, Z0), (X1, Y1, Z1), (X0, Y1, Z1)),      # normal -y
        "back": quad((X0, Y0, Z0), (X1, Y0, Z0), (X1, Y1, Z0), (X0, Y1, Z0)),         # normal +z
        "red_wall": quad((X0, Y0, Z1), (X0, Y0, Z0), (X0, Y1, Z0), (X0, Y1, Z1)),     # normal +x
        "blue_wall": quad((X1, Y0, Z0), (X1, Y0, Z1), (X1, Y1, Z1), (X1, Y1, Z0)),    # normal -x
        "light": quad((-0.24, 1.58, -0.22), (0.23, 1.58, -0.22), (0.23, 1.58, 0.16), (-0.24, 1.58, 0.16)),
    }
    for name, (v, f) in walls.items():
        write_obj(name, v, f)
    for name, (c, r) in SPHERES.items():
        write_obj(name, *uv_sphere(c, r))


if __name__ == "__main__":
    main()
