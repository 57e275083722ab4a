"""Device BVH traversal against brute-force intersection in numpy (float64), on random rays over
random meshes with degenerate triangles, and over analytic spheres."""
import numpy as np
import pytest

from conftest import run_kernel
from volcl import layout
from volcl.bvh_wide import device_bvh

pytestmark = pytest.mark.every_implementation


def random_scene(rng, n_tri=3000, n_sph=40):
    centers = rng.uniform(-1, 1, (n_tri, 1, 3))
    tris = centers + rng.normal(0, 0.08, (n_tri, 3, 3))
    k = n_tri // 20     # degenerate: collinear, repeated-vertex and zero-size triangles
    tris[:k, 2] = tris[:k, 0] + 0.5 * (tris[:k, 1] - tris[:k, 0])
    tris[k:2 * k, 1] = tris[k:2 * k, 0]
    tris[2 * k:3 * k, :] = tris[2 * k:3 * k, :1]
    sph_c = rng.uniform(-1, 1, (n_sph, 3))
    sph_r = rng.uniform(0.01, 0.15, n_sph)
    return tris, sph_c, sph_r


def upload_arrays(tris, sph_c, sph_r, opaque=None):
    t = np.zeros(max(len(tris), 1), layout.TRIANGLE)     # OpenCL has no empty buffers
    t["p0"][:len(tris)], t["p1"][:len(tris)], t["p2"][:len(tris)] = tris[:, 0], tris[:, 1], tris[:, 2]
    t["normals"] = -1
    s = np.zeros(max(len(sph_c), 1), layout.SPHERE)
    s["center"][:len(sph_c)], s["radius"][:len(sph_c)] = sph_c, sph_r
    lo = np.concatenate([tris.min(1), sph_c - sph_r[:, None]])
    hi = np.concatenate([tris.max(1), sph_c + sph_r[:, None]])
    codes = np.concatenate([np.arange(len(tris)), -1 - np.arange(len(sph_c))]).astype(np.int32)
    nodes, leaves = device_bvh(codes, lo, hi, tris, opaque)
    return nodes, leaves, t, s


def moller_trumbore(o, d, tris):
    """Rays x triangles in float64: (t along each ray's plane crossing, the determinant, the
    barycentric margin min(u, v, 1 - u - v), negative outside the triangle)."""
    p0, e1, e2 = tris[:, 0], tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    pvec = np.cross(d[:, None, :], e2[None])
    det = np.einsum("rtk,tk->rt", pvec, e1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        tvec = o[:, None, :] - p0[None]
        u = np.einsum("rtk,rtk->rt", tvec, pvec) * inv
        qvec = np.cross(tvec, e1[None])
        v = np.einsum("rk,rtk->rt", d, qvec) * inv
        t = np.einsum("tk,rtk->rt", e2, qvec) * inv
        margin = np.minimum(np.minimum(u, v), 1 - u - v)
    return t, det, margin


def brute_force(tris, sph_c, sph_r, o, d):
    """Closest t per ray over all primitives (float64), with each triangle hit's barycentric margin."""
    t, det, margin = moller_trumbore(o, d, tris)
    ok = (np.abs(det) > 1e-14) & (margin >= 0) & (t > 1e-9)
    t_tri = np.where(ok, t, np.inf)
    # spheres
    f = o[:, None, :] - sph_c[None]
    b = np.einsum("rsk,rk->rs", f, d)
    c = np.einsum("rsk,rsk->rs", f, f) - sph_r[None] ** 2
    disc = b * b - c
    sq = np.sqrt(np.maximum(disc, 0))
    t0, t1 = -b - sq, -b + sq
    t_s = np.where(t0 > 1e-9, t0, np.where(t1 > 1e-9, t1, np.inf))
    t_s = np.where(disc >= 0, t_s, np.inf)
    t_all = np.concatenate([t_tri, t_s], axis=1)
    best = t_all.argmin(1)
    near_edge = np.where(ok, np.abs(margin), np.inf).min(1) < 1e-4
    # rays that graze an edge of some triangle within tolerance, hit or not
    grazing = (np.abs(det) > 1e-14) & (margin > -1e-4) & (margin < 1e-4) & (t > 0)
    return t_all[np.arange(len(o)), best], best, near_edge | grazing.any(1), t_all


OUTPUTS = [(np.float32, ()), (np.int32, ()), (np.int32, ()), (np.int32, ())]
NO_HIT = 0x7fffffff


@pytest.mark.parametrize("seed", [1, 2])
def test_device_traversal_matches_brute_force(cl_env, test_program, seed):
    rng = np.random.default_rng(seed)
    tris, sph_c, sph_r = random_scene(rng)
    # half the primitives null surfaces, for the shadow query
    opaque = rng.random(len(tris) + len(sph_c)) < 0.5
    nodes, leaves, t_arr, s_arr = upload_arrays(tris, sph_c, sph_r, opaque)
    n = 2000
    o = rng.uniform(-1.5, 1.5, (n, 3))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    # a quarter of the rays along the axes, where 1/d is infinite in two components
    axis = rng.integers(0, 3, n // 4)
    d[: n // 4] = 0
    d[np.arange(n // 4), axis] = rng.choice([-1.0, 1.0], n // 4)
    prog = test_program("traversal_tests.cl")
    t_dev, prim_dev, occ, shadow = run_kernel(
        cl_env, prog, "trace_rays", n, OUTPUTS,
        inputs=[nodes, leaves, t_arr, s_arr, o.astype(np.float32), d.astype(np.float32)])
    t_ref, _, ambiguous, t_all = brute_force(tris, sph_c, sph_r, o.astype(np.float32).astype(np.float64),
                                             d.astype(np.float32).astype(np.float64))
    hit_ref = np.isfinite(t_ref)
    hit_dev = np.isfinite(t_dev)
    assert hit_ref.sum() > n // 4, "the test scene should be hit by many rays"
    # hit/miss agreement, except for rays grazing an edge within float32 precision
    disagree = (hit_ref != hit_dev) & ~ambiguous
    assert not disagree.any(), f"{disagree.sum()} rays disagree on hit/miss, e.g. ray {np.nonzero(disagree)[0][:5]}"
    both = hit_ref & hit_dev
    rel = np.abs(t_dev[both] - t_ref[both]) / np.maximum(t_ref[both], 1e-3)
    bad = (rel > 1e-4) & ~ambiguous[both]
    assert not bad.any(), f"{bad.sum()} rays with wrong distance, worst relative error {rel.max():.3g}"
    # any-hit agrees with closest-hit
    assert np.array_equal(occ.astype(bool), hit_dev)
    # shadow query: the closest hit when that is a null surface, else some opaque primitive hit
    column = np.where(shadow >= 0, shadow, len(tris) - 1 - shadow)     # primitive codes to columns
    got = shadow != NO_HIT
    got_opaque = got & opaque[np.where(got, column, 0)]
    assert np.array_equal(got, hit_dev)
    assert np.isfinite(t_all[np.flatnonzero(got_opaque), column[got_opaque]]).all()
    unblocked = got & ~got_opaque
    assert np.array_equal(shadow[unblocked], prim_dev[unblocked])
    nearest_opaque = hit_dev & opaque[np.where(prim_dev >= 0, prim_dev, len(tris) - 1 - prim_dev) * hit_dev]
    assert got_opaque[nearest_opaque].all()
    assert got_opaque.sum() > n // 10 and unblocked.sum() > n // 20, "both outcomes should occur"


def test_closed_mesh_does_not_leak_through_shared_edges(cl_env, test_program):
    """Rays aimed exactly at shared edges and vertices of a closed tessellated box always hit it."""
    import trimesh
    box = trimesh.creation.box(extents=(2, 2, 2))
    box = box.subdivide().subdivide()
    tris = np.asarray(box.vertices)[np.asarray(box.faces)]
    nodes, leaves, t_arr, s_arr = upload_arrays(tris, np.zeros((0, 3)), np.zeros(0))
    edges = np.asarray(box.edges_unique)
    v = np.asarray(box.vertices)
    rng = np.random.default_rng(3)
    targets = np.concatenate([v, 0.5 * (v[edges[:, 0]] + v[edges[:, 1]])])
    o = rng.uniform(-0.5, 0.5, (len(targets), 3))
    d = targets - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    prog = test_program("traversal_tests.cl")
    t_dev, _, _, _ = run_kernel(cl_env, prog, "trace_rays", len(o), OUTPUTS,
                             inputs=[nodes, leaves, t_arr, s_arr, o.astype(np.float32), d.astype(np.float32)])
    assert np.isfinite(t_dev).all(), f"{(~np.isfinite(t_dev)).sum()} rays escaped the closed box"


@pytest.mark.parametrize("n_tri, n_sph", [(2, 1), (1, 3), (4, 0)])
def test_a_tree_of_one_leaf_matches_brute_force(cl_env, test_program, n_tri, n_sph):
    """Scenes of a few primitives, whose tree is one leaf the kernel tests without the box test:
    closest hit, any hit and the shadow query against brute force."""
    rng = np.random.default_rng(10 + n_tri + n_sph)
    tris = rng.uniform(-1, 1, (n_tri, 1, 3)) + rng.normal(0, 0.6, (n_tri, 3, 3))
    sph_c = rng.uniform(-0.7, 0.7, (n_sph, 3))
    sph_r = rng.uniform(0.3, 0.6, n_sph)
    opaque = np.arange(n_tri + n_sph) % 2 == 0
    nodes, leaves, t_arr, s_arr = upload_arrays(tris.reshape(-1, 3, 3), sph_c, sph_r, opaque)
    assert len(nodes) == 1 and nodes["child"][0, 0] < 0 and nodes["child"][0, 1] == 0
    n = 2000
    o = rng.uniform(-2, 2, (n, 3))
    d = rng.uniform(-0.8, 0.8, (n, 3)) - o      # towards the primitives, mostly
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    prog = test_program("traversal_tests.cl")
    t_dev, prim_dev, occ, shadow = run_kernel(
        cl_env, prog, "trace_rays", n, OUTPUTS,
        inputs=[nodes, leaves, t_arr, s_arr, o.astype(np.float32), d.astype(np.float32)])
    t_ref, _, ambiguous, t_all = brute_force(tris.reshape(-1, 3, 3), sph_c, sph_r,
                                             o.astype(np.float32).astype(np.float64),
                                             d.astype(np.float32).astype(np.float64))
    hit_ref, hit_dev = np.isfinite(t_ref), np.isfinite(t_dev)
    assert hit_ref.sum() > n // 10, "the test scene should be hit by many rays"
    assert not ((hit_ref != hit_dev) & ~ambiguous).any()
    both = hit_ref & hit_dev & ~ambiguous
    assert np.allclose(t_dev[both], t_ref[both], rtol=1e-4, atol=1e-5)
    assert np.array_equal(occ.astype(bool), hit_dev)
    assert np.array_equal(shadow != NO_HIT, hit_dev)
