"""Robust ray origins at medium boundaries: rays leaving a closed mesh from the inside, at any
angle down to grazing, always find the boundary again (counted on the device)."""
import numpy as np
import pytest
import trimesh

from conftest import run_kernel
from volcl import layout
from volcl.bvh_wide import device_bvh

pytestmark = pytest.mark.every_implementation


@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e3])
@pytest.mark.parametrize("mesh", ["icosphere", "box", "torus-ish"])
def test_walks_inside_closed_mesh_never_leak(cl_env, test_program, mesh, scale):
    if mesh == "icosphere":
        m = trimesh.creation.icosphere(subdivisions=3)
    elif mesh == "box":
        m = trimesh.creation.box(extents=(2, 1, 0.5)).subdivide().subdivide()
    else:
        m = trimesh.creation.capsule(height=1.0, radius=0.4)
    # far from the origin too, where float32 spacing is coarse
    v = np.asarray(m.vertices) * scale + np.array([3.0, -2.0, 1.0]) * scale
    tris = v[np.asarray(m.faces)]
    t = np.zeros(len(tris), layout.TRIANGLE)
    t["p0"], t["p1"], t["p2"] = tris[:, 0], tris[:, 1], tris[:, 2]
    t["normals"] = -1
    nodes, leaves = device_bvh(np.arange(len(tris)), tris.min(1), tris.max(1), tris)
    n = 16384
    starts = np.repeat((np.array([3.0, -2.0, 1.0]) * scale)[None], n, 0).astype(np.float32)
    leaks, hits = run_kernel(cl_env, test_program("leak_tests.cl"), "walk_inside", n,
                             [(np.int32, ()), (np.int32, ())], np.int32(64),
                             inputs=[nodes, leaves, t, starts])
    assert hits.sum() > n * 32, "walks should bounce many times"
    assert leaks.sum() == 0, f"{leaks.sum()} of {n} walks leaked out of the closed mesh"
