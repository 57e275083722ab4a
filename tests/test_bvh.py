"""Tests of volcl.bvh: tree structure, conservative float32 bounds, leaf sizes, depth limits on
adversarial input, SAH quality against references, and closest-hit traversal against brute force.

The reference median builder and the ray tracer live here only; they are deliberately simple
(Python recursion, a per-ray Python traversal loop) and independent of the code under test.
"""
import time

import numpy as np
import pytest

from volcl.bvh import MAX_DEPTH, build_bvh, node_depths, sah_cost
from volcl.layout import BVH_NODE


# ---------------------------------------------------------------------------------------------
# Validation helpers

def walk(nodes):
    """Depth of each node, reached from the root by following child links.

    Asserts the depth-first layout: the left child is i + 1, the right child lies after it, every
    node is reached exactly once, and a left-first walk visits the nodes in index order.
    """
    count, index = nodes["count"].tolist(), nodes["index"].tolist()
    depth = [-1] * len(nodes)
    visited = []
    stack = [(0, 0)]
    while stack:
        i, d = stack.pop()
        assert depth[i] == -1, f"node {i} reached twice"
        depth[i] = d
        visited.append(i)
        if count[i] == 0:
            right = index[i]
            assert i + 1 < right < len(nodes), f"bad right child {right} of node {i}"
            stack.append((right, d + 1))
            stack.append((i + 1, d + 1))
    assert visited == list(range(len(nodes))), "nodes are not in depth-first order"
    return np.array(depth)


def check_tree(nodes, order, lo, hi, max_leaf=4):
    """Every structural and containment property the device relies on; returns node depths."""
    lo, hi = np.asarray(lo, np.float64).reshape(-1, 3), np.asarray(hi, np.float64).reshape(-1, 3)
    n = len(lo)
    assert nodes.dtype == BVH_NODE
    assert order.dtype == np.int32 and len(order) == n
    np.testing.assert_array_equal(np.sort(order), np.arange(n))
    depth = walk(nodes)
    assert depth.max() <= MAX_DEPTH < 64

    count, index = nodes["count"], nodes["index"]
    leaves = np.flatnonzero(count > 0)
    assert np.all(count >= 0)
    assert count[leaves].max() <= max_leaf
    # Leaf slot ranges tile [0, n) in depth-first order.
    np.testing.assert_array_equal(index[leaves], np.cumsum(count[leaves]) - count[leaves])
    assert count.sum() == n

    # Each leaf holds its primitives' boxes as given (float64), compared against float32 bounds.
    slot_leaf = np.repeat(leaves, count[leaves])
    assert np.all(nodes["bmin"][slot_leaf].astype(np.float64) <= lo[order])
    assert np.all(nodes["bmax"][slot_leaf].astype(np.float64) >= hi[order])

    inner = np.flatnonzero(count == 0)
    for child in (inner + 1, index[inner]):
        assert np.all(nodes["bmin"][inner] <= nodes["bmin"][child])
        assert np.all(nodes["bmax"][inner] >= nodes["bmax"][child])
    np.testing.assert_array_equal(node_depths(nodes), depth)
    return depth


def random_triangles(rng, n, size=0.02):
    """Triangle soup: small random triangles in the unit cube, as (n, 3, 3) vertices."""
    base = rng.random((n, 1, 3))
    return base + size * rng.standard_normal((n, 3, 3))


def tri_boxes(tris):
    return tris.min(axis=1), tris.max(axis=1)


# ---------------------------------------------------------------------------------------------
# Structure and bounds

@pytest.mark.parametrize("n, max_leaf, bins", [(1000, 4, 16), (5000, 1, 2), (3000, 8, 32),
                                               (777, 2, 3)])
def test_random_boxes_make_valid_trees(n, max_leaf, bins):
    rng = np.random.default_rng(n)
    # float64 coordinates that float32 cannot represent, so outward rounding is exercised.
    centre = rng.random((n, 3)) * 100.0 - 50.0
    half = rng.random((n, 3)) * 0.3
    lo, hi = centre - half, centre + half
    nodes, order = build_bvh(lo, hi, max_leaf=max_leaf, bins=bins)
    check_tree(nodes, order, lo, hi, max_leaf)


def test_float32_input_and_bounds_are_tight():
    rng = np.random.default_rng(7)
    lo = rng.random((500, 3)).astype(np.float32)
    hi = lo + rng.random((500, 3)).astype(np.float32) * np.float32(0.01)
    nodes, order = build_bvh(lo, hi)
    check_tree(nodes, order, lo, hi)
    # float32 input needs no rounding: the root box is exactly the scene box.
    np.testing.assert_array_equal(nodes["bmin"][0], lo.min(axis=0))
    np.testing.assert_array_equal(nodes["bmax"][0], hi.max(axis=0))


def test_build_is_vectorized():
    # A generous bound (about 0.1 s here): it only catches a per-primitive Python loop.
    lo, hi = tri_boxes(random_triangles(np.random.default_rng(2), 100_000))
    start = time.perf_counter()
    build_bvh(lo, hi)
    assert time.perf_counter() - start < 5.0


def test_deterministic():
    rng = np.random.default_rng(3)
    tris = random_triangles(rng, 4000)
    a_nodes, a_order = build_bvh(*tri_boxes(tris))
    b_nodes, b_order = build_bvh(*tri_boxes(tris.copy()))
    assert a_nodes.tobytes() == b_nodes.tobytes()
    np.testing.assert_array_equal(a_order, b_order)


# ---------------------------------------------------------------------------------------------
# Degenerate and adversarial input

def test_no_primitives():
    nodes, order = build_bvh(np.zeros((0, 3)), np.zeros((0, 3)))
    assert nodes.dtype == BVH_NODE and len(nodes) == 0
    assert order.dtype == np.int32 and len(order) == 0
    assert sah_cost(nodes) == 0.0


def test_one_primitive():
    lo, hi = np.array([[1.0, 2.0, 3.0]]), np.array([[1.5, 2.0, 4.0]])
    nodes, order = build_bvh(lo, hi)
    check_tree(nodes, order, lo, hi)
    assert len(nodes) == 1 and nodes["count"][0] == 1 and nodes["index"][0] == 0


@pytest.mark.parametrize("max_leaf", [1, 4])
def test_two_primitives(max_leaf):
    lo = np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0]])
    nodes, order = build_bvh(lo, lo + 1.0, max_leaf=max_leaf)
    depth = check_tree(nodes, order, lo, lo + 1.0, max_leaf)
    assert len(nodes) == (3 if max_leaf == 1 else 1)
    assert depth.max() == (1 if max_leaf == 1 else 0)


def room_walls():
    """The six faces of a 2 x 1.6 x 4 room, two triangles each, as (12, 3, 3) vertices (face f
    holds triangles 2f and 2f + 1)."""
    corners = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (0.0, 1.6) for z in (-1.0, 3.0)])
    faces = [(0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5)]
    return np.array([corners[[a, b, c]] for a, b, c, d in faces for (a, b, c) in ((a, b, c), (a, c, d))])


def leaf_groups(nodes, order):
    """The primitives of each leaf, as sets."""
    leaves = np.flatnonzero(nodes["count"] > 0)
    return [set(order[nodes["index"][i]:nodes["index"][i] + nodes["count"][i]].tolist()) for i in leaves]


def test_walls_of_a_room_get_a_leaf_each():
    # Any two walls fit one leaf of four, but their box spans the room: a ray inside it tests both
    # walls' packet where it would have entered only one wall's box (_small_splits).
    tris = room_walls()
    lo, hi = tri_boxes(tris)
    nodes, order = build_bvh(lo, hi)
    check_tree(nodes, order, lo, hi)
    groups = leaf_groups(nodes, order)
    assert sorted(map(sorted, groups)) == [[2 * f, 2 * f + 1] for f in range(6)]


def test_neighbouring_triangles_of_a_mesh_share_leaves():
    # A gently curved grid of 32 x 32 quads: leaves of four neighbouring triangles, whose halves'
    # boxes add up to about as much area as theirs, stay whole.
    n = 32
    x, z = np.meshgrid(np.linspace(0.0, 1.0, n + 1), np.linspace(0.0, 1.0, n + 1), indexing="ij")
    v = np.stack([x, 0.1 * np.sin(3.0 * x + 2.0 * z), z], -1)
    a, b, c, d = v[:-1, :-1], v[1:, :-1], v[1:, 1:], v[:-1, 1:]
    tris = np.concatenate([np.stack([a, b, c], -2), np.stack([a, c, d], -2)]).reshape(-1, 3, 3)
    lo, hi = tri_boxes(tris)
    nodes, order = build_bvh(lo, hi)
    check_tree(nodes, order, lo, hi)
    counts = nodes["count"][nodes["count"] > 0]
    assert counts.mean() > 3.0, np.bincount(counts)


@pytest.mark.parametrize("max_leaf", [1, 4])
def test_identical_boxes_split_by_index_median(max_leaf):
    lo = np.tile([[1.0, 1.0, 1.0]], (1000, 1))
    nodes, order = build_bvh(lo, lo + 0.5, max_leaf=max_leaf)
    depth = check_tree(nodes, order, lo, lo + 0.5, max_leaf)
    # Median splits give a balanced tree.
    assert depth.max() == int(np.ceil(np.log2(1000 / max_leaf)))


def test_identical_centroids_different_sizes():
    rng = np.random.default_rng(11)
    half = rng.random((300, 3))
    nodes, order = build_bvh(-half, half, max_leaf=2)
    check_tree(nodes, order, -half, half, 2)


@pytest.mark.parametrize("max_leaf", [1, 4])
def test_exponentially_spaced_points_stay_shallow(max_leaf):
    # Linear bins put all but the largest point into bin 0 at every level: a naive binned SAH
    # peels one primitive per level and grows a 4000-deep chain.
    x = 2.0 ** np.linspace(-120.0, 120.0, 4000)
    lo = np.zeros((len(x), 3))
    lo[:, 0] = x
    nodes, order = build_bvh(lo, lo, max_leaf=max_leaf)
    depth = check_tree(nodes, order, lo, lo, max_leaf)
    assert depth.max() <= MAX_DEPTH


def test_huge_and_tiny_extents():
    rng = np.random.default_rng(5)
    n = 3000
    centre = rng.uniform(-1e30, 1e30, (n, 3)) * 10.0 ** rng.uniform(-35, 0, (n, 1))
    half = 10.0 ** rng.uniform(-30, 30, (n, 3))
    lo = np.maximum(centre - half, -3e38)
    hi = np.minimum(centre + half, 3e38)
    nodes, order = build_bvh(lo, hi)
    check_tree(nodes, order, lo, hi)
    assert np.isfinite(sah_cost(nodes))


def test_zero_area_boxes():
    rng = np.random.default_rng(9)
    points = rng.random((2000, 3))
    nodes, order = build_bvh(points, points)
    check_tree(nodes, order, points, points)
    planar = points.copy()
    planar[:, 2] = 0.25
    nodes, order = build_bvh(planar, planar)
    check_tree(nodes, order, planar, planar)
    # A root without area weights every node 1.
    same = np.zeros((10, 3))
    nodes, _ = build_bvh(same, same)
    assert sah_cost(nodes) == np.count_nonzero(nodes["count"] == 0) + 10


def test_nan_is_rejected():
    lo = np.zeros((3, 3))
    lo[1, 2] = np.nan
    with pytest.raises(AssertionError):
        build_bvh(lo, np.ones((3, 3)))


# ---------------------------------------------------------------------------------------------
# SAH cost

def half_area(lo, hi):
    d = np.maximum(np.asarray(hi, np.float64) - lo, 0.0)
    return d[..., 0] * d[..., 1] + d[..., 1] * d[..., 2] + d[..., 2] * d[..., 0]


def test_sah_cost_of_hand_built_tree():
    nodes = np.zeros(3, BVH_NODE)
    nodes[0] = ((0, 0, 0), 2, (2, 1, 1), 0)
    nodes[1] = ((0, 0, 0), 0, (1, 1, 1), 1)
    nodes[2] = ((1, 0, 0), 1, (2, 1, 1), 2)
    # Half areas: root 5, leaves 3 each.
    assert sah_cost(nodes) == pytest.approx(1.0 + 1 * 3 / 5 + 2 * 3 / 5)
    assert sah_cost(nodes, c_trav=0.5, c_isect=2.0) == pytest.approx(0.5 + 2 * 9 / 5)


def median_tree_cost(lo, hi, max_leaf):
    """SAH cost (c_trav = c_isect = 1) of an object-median tree: split on the axis of largest
    centroid extent at the median centroid until leaves hold at most max_leaf primitives."""
    centre = 0.5 * (lo + hi)
    root_area = half_area(lo.min(axis=0), hi.max(axis=0))

    def cost(ids):
        area = half_area(lo[ids].min(axis=0), hi[ids].max(axis=0)) / root_area
        if len(ids) <= max_leaf:
            return len(ids) * area
        c = centre[ids]
        axis = np.argmax(c.max(axis=0) - c.min(axis=0))
        ids = ids[np.argsort(c[:, axis], kind="stable")]
        half = len(ids) // 2
        return area + cost(ids[:half]) + cost(ids[half:])

    return cost(np.arange(len(lo)))


def clustered_triangles(rng, n):
    """Small triangles in a few dense clusters plus a sparse background: SAH territory."""
    centres = rng.random((8, 3)) * 10.0
    which = rng.integers(0, 8, n)
    spread = np.where(rng.random(n) < 0.9, 0.3, 5.0)[:, None, None]
    base = centres[which][:, None, :] + spread * rng.standard_normal((n, 1, 3))
    return base + 0.02 * rng.standard_normal((n, 3, 3))


@pytest.mark.parametrize("kind", ["uniform", "clustered"])
def test_sah_beats_median_split(kind):
    rng = np.random.default_rng(21)
    n = 8000
    tris = random_triangles(rng, n) if kind == "uniform" else clustered_triangles(rng, n)
    lo, hi = tri_boxes(tris)
    nodes, order = build_bvh(lo, hi)
    check_tree(nodes, order, lo, hi)
    ours, median = sah_cost(nodes), median_tree_cost(lo, hi, 4)
    assert ours < median


def test_grid_cost_near_balanced_optimum():
    # 16^3 boxes of size 0.5 on a unit grid. The reference is the perfectly balanced tree that
    # halves the longest side of the cell block at every level down to 4-cell leaves.
    side, size = 16, 0.5
    cells = np.stack(np.meshgrid(*[np.arange(side)] * 3, indexing="ij"), -1).reshape(-1, 3)
    lo, hi = cells - size / 2, cells + size / 2
    nodes, order = build_bvh(lo.astype(np.float64), hi.astype(np.float64))
    check_tree(nodes, order, lo, hi)

    def block_area(dims):
        return half_area(np.zeros(3), np.array(dims, np.float64) - 1.0 + size)

    dims, per_node, count, ideal = [side] * 3, 1, side ** 3, 0.0
    while count > 4:
        ideal += per_node * block_area(dims)
        dims[int(np.argmax(dims))] //= 2
        per_node, count = per_node * 2, count // 2
    ideal = (ideal + per_node * count * block_area(dims)) / block_area([side] * 3)
    assert 0.8 * ideal < sah_cost(nodes) < 1.1 * ideal


# ---------------------------------------------------------------------------------------------
# Ray traversal against brute force

def intersect(o, d, v0, v1, v2):
    """Moller-Trumbore hit distance of rays (o, d) against triangles, inf on a miss; broadcasts.

    Written with elementwise products only, so a triangle gives bit-identical t whether it is
    tested alone or in a batch.
    """
    def cross(a, b):
        return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                         a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                         a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], -1)

    def dot(a, b):
        return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]

    e1, e2 = v1 - v0, v2 - v0
    p = cross(d, e2)
    det = dot(e1, p)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = o - v0
        u = dot(s, p) * inv
        q = cross(s, e1)
        v = dot(d, q) * inv
        t = dot(e2, q) * inv
        hit = (det != 0.0) & (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0) & (t > 0.0)
    return np.where(hit, t, np.inf)


def brute_force(tris, origins, dirs, chunk=32):
    best = []
    for i in range(0, len(origins), chunk):
        o, d = origins[i:i + chunk, None, :], dirs[i:i + chunk, None, :]
        t = intersect(o, d, tris[None, :, 0], tris[None, :, 1], tris[None, :, 2])
        best.append(t.min(axis=1))
    return np.concatenate(best)


def box_entry(o, d, bmin, bmax, t_max):
    """Entry distance into a box within [0, t_max], or None. Slightly widened so rounding never
    culls a box the ray grazes; zero direction components use the slab containment test."""
    near, far = 0.0, t_max
    for a in range(3):
        if d[a] == 0.0:
            if not bmin[a] <= o[a] <= bmax[a]:
                return None
            continue
        t0, t1 = (bmin[a] - o[a]) / d[a], (bmax[a] - o[a]) / d[a]
        near, far = max(near, min(t0, t1)), min(far, max(t0, t1))
    return near if near <= far * (1.0 + 1e-9) + 1e-12 else None


def traverse(nodes, tris_ordered, o, d):
    """Closest hit by front-to-back traversal with pruning against the best hit so far."""
    bmin, bmax = nodes["bmin"].tolist(), nodes["bmax"].tolist()
    count, index = nodes["count"].tolist(), nodes["index"].tolist()
    best = np.inf
    stack = [0]
    while stack:
        i = stack.pop()
        if box_entry(o, d, bmin[i], bmax[i], best) is None:
            continue
        if count[i] > 0:
            leaf = tris_ordered[index[i]:index[i] + count[i]]
            best = min(best, intersect(o, d, leaf[:, 0], leaf[:, 1], leaf[:, 2]).min())
            continue
        left, right = i + 1, index[i]
        tl = box_entry(o, d, bmin[left], bmax[left], best)
        tr = box_entry(o, d, bmin[right], bmax[right], best)
        near_first = [c for _, c in sorted([(tl, left), (tr, right)],
                                           key=lambda tc: np.inf if tc[0] is None else tc[0])]
        stack.extend(reversed(near_first))
    return best


def sphere_mesh(rng, rows=24, cols=48):
    """Bumpy tessellated sphere: a closed mesh whose poles make many sliver and zero-area tris."""
    theta = np.linspace(0.0, np.pi, rows + 1)
    phi = np.linspace(0.0, 2.0 * np.pi, cols + 1)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    r = 1.0 + 0.1 * rng.random(t.shape)
    verts = np.stack([r * np.sin(t) * np.cos(p), r * np.sin(t) * np.sin(p), r * np.cos(t)], -1)
    a, b = verts[:-1, :-1], verts[:-1, 1:]
    c, e = verts[1:, :-1], verts[1:, 1:]
    quads = np.concatenate([np.stack([a, b, e], -2), np.stack([a, e, c], -2)])
    return quads.reshape(-1, 3, 3)


def degenerate_triangles(rng, n):
    """Zero-area triangles: repeated vertices, collinear vertices, single points."""
    p = rng.random((n, 3)) * 2.0 - 1.0
    q = rng.random((n, 3)) * 2.0 - 1.0
    kinds = [np.stack([p, p, q], 1), np.stack([p, 0.5 * (p + q), q], 1), np.stack([p, p, p], 1)]
    return np.concatenate(kinds)


def test_traversal_matches_brute_force():
    rng = np.random.default_rng(1234)
    tris = np.concatenate([
        sphere_mesh(rng),
        sphere_mesh(rng, 8, 12) * 0.3 + [1.5, 0.0, 0.0],
        random_triangles(rng, 1500, size=0.05) * 3.0 - 1.5,
        degenerate_triangles(rng, 100),
        rng.random((5, 3, 3)) * 6.0 - 3.0,  # a few large ones spanning the scene
    ])
    nodes, order = build_bvh(*tri_boxes(tris))
    check_tree(nodes, order, *tri_boxes(tris))

    n_rays = 300
    origins = rng.uniform(-4.0, 4.0, (n_rays, 3))
    targets = rng.uniform(-1.2, 1.2, (n_rays, 3))
    dirs = targets - origins
    dirs[:20] = np.eye(3)[rng.integers(0, 3, 20)] * rng.choice([-1.0, 1.0], (20, 1))
    dirs[20:40, rng.integers(0, 3)] = 0.0  # rays parallel to a coordinate plane
    expected = brute_force(tris, origins, dirs)
    tris_ordered = tris[order]
    got = np.array([traverse(nodes, tris_ordered, o, d) for o, d in zip(origins, dirs)])
    np.testing.assert_array_equal(got, expected)
    assert np.isfinite(expected).mean() > 0.5
