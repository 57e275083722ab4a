"""The wide BVH the device traverses (volcl.bvh_wide): every primitive slot in exactly one leaf,
child boxes that hold their subtrees, the traversal stack bound (also where the area order alone
would break it), and the encodings the kernel reads. Device traversal itself: test_traversal.py."""
import numpy as np
import pytest

from volcl import layout
from volcl.bvh import build_bvh
from volcl.bvh_wide import (STACK, build_wide, collapse, decode_leaf, empty_wide, leaf_ref,
                             shallow_stack_bound, stack_need)


def used_slots(wide):
    b = wide["bounds"]
    return b[:, 0, :] <= b[:, 3, :]


def check_wide(wide, order, lo, hi, width=layout.BVH_WIDTH):
    """Reachability, leaf coverage and containment; returns the number of leaves."""
    assert wide.dtype == layout.bvh_wide_node(width)
    used = used_slots(wide)
    b = wide["bounds"]
    # unused slots: the inverted box and nothing else
    assert np.all(b[:, :3][np.broadcast_to(~used[:, None], b[:, :3].shape)] == np.inf)
    assert np.all(b[:, 3:][np.broadcast_to(~used[:, None], b[:, 3:].shape)] == -np.inf)
    assert np.isfinite(b[np.broadcast_to(used[:, None], b.shape)]).all()
    child = wide["child"]
    inner = used & (child >= 0)
    # every node but the root is the child of exactly one slot
    np.testing.assert_array_equal(np.sort(child[inner]), np.arange(1, len(wide)))
    # an interior child's box holds all of that node's child boxes
    rows, cols = np.nonzero(inner)
    for r, c in zip(rows, cols):
        sub = wide[child[r, c]]
        su = used_slots(sub[None])[0]
        assert su.any()
        assert np.all(b[r, :3, c][:, None] <= sub["bounds"][:3][:, su])
        assert np.all(b[r, 3:, c][:, None] >= sub["bounds"][3:][:, su])
    # leaves tile the primitive slots, and their boxes hold their primitives (float64 input)
    rows, cols = np.nonzero(used & (child < 0))
    first, count = decode_leaf(child[rows, cols])
    covered = np.zeros(len(order), np.int64)
    for r, c, f, k in zip(rows, cols, first, count):
        covered[f:f + k] += 1
        prims = order[f:f + k]
        assert np.all(b[r, :3, c].astype(np.float64) <= lo[prims])
        assert np.all(b[r, 3:, c].astype(np.float64) >= hi[prims])
    np.testing.assert_array_equal(covered, 1)
    assert stack_need(wide) <= STACK
    return len(rows)


def random_boxes(rng, n):
    centre = rng.random((n, 3)) * 10.0 - 5.0
    half = rng.random((n, 3)) * 0.05
    return centre - half, centre + half


@pytest.mark.parametrize("n", [1, 2, 5, 9, 300, 20_000])
@pytest.mark.parametrize("width", [4, 8])
def test_collapse_keeps_every_primitive_and_bound(n, width):
    lo, hi = random_boxes(np.random.default_rng(n), n)
    nodes, order = build_bvh(lo, hi)
    wide = collapse(nodes, width)
    leaves = check_wide(wide, order, lo, hi, width)
    assert leaves == np.count_nonzero(nodes["count"] > 0)      # binary leaves are kept as they are
    if n >= 300:
        # wide nodes really are wide: far fewer than the binary interior nodes
        assert len(wide) < 0.6 * np.count_nonzero(nodes["count"] == 0)


def test_collapse_opens_the_largest_child_first():
    """Two binary levels below the root: with width 3 the larger of the root's children is opened."""
    lo = np.array([[0, 0, 0], [1, 0, 0], [10, 0, 0], [20, 0, 0]], float)
    hi = lo + [[0.5, 0.5, 0.5], [0.5, 0.5, 0.5], [5, 5, 5], [25, 25, 25]]
    nodes, order = build_bvh(lo, hi, max_leaf=1)
    wide = collapse(nodes, 3)
    assert len(wide) == 2           # the root, and the small pair it could not open
    big = hi[order][:, 0] >= 15
    first, _ = decode_leaf(wide["child"][0][wide["child"][0] < 0])
    assert big[first].any()


def test_stack_bound_holds_when_the_area_order_would_break_it():
    """Exponentially shrinking clusters make a deep, lopsided binary tree on which the area order
    needs a deep stack; a stack smaller than that gets the shallowest-first collapse, whose bound
    (shallow_stack_bound) holds for any tree no deeper than MAX_DEPTH."""
    rng = np.random.default_rng(5)
    lo = np.concatenate([rng.random((40, 3)) * 2.0 ** -k for k in range(30)])
    hi = lo + 1e-9
    nodes, order = build_bvh(lo, hi, max_leaf=1)
    by_area = stack_need(collapse(nodes, 8, order="area"))
    shallow = collapse(nodes, 8, order="shallow")
    assert stack_need(shallow) < by_area
    assert stack_need(shallow) <= shallow_stack_bound(8) <= STACK
    auto = collapse(nodes, 8, stack=by_area - 1)
    assert auto.tobytes() == shallow.tobytes()
    check_wide(auto, order, lo, hi)
    with pytest.raises(ValueError, match="stack"):
        collapse(nodes, 8, stack=stack_need(shallow) - 1)


def test_leaf_references_round_trip_and_are_negative():
    first = np.array([0, 1, 12345, 2 ** 27 - 1])
    count = np.array([1, 16, 4, 7])
    ref = leaf_ref(first, count)
    assert np.all(ref < 0)
    f, c = decode_leaf(ref)
    np.testing.assert_array_equal(f, first)
    np.testing.assert_array_equal(c, count)
    with pytest.raises(AssertionError):
        leaf_ref([2 ** 27], [1])


def test_empty_scene_has_one_node_no_ray_enters():
    wide, order = build_wide(np.zeros((0, 3)), np.zeros((0, 3)))
    assert len(wide) == 1 and len(order) == 0
    assert not used_slots(wide).any()
    assert empty_wide().tobytes() == wide.tobytes()


def test_deterministic():
    lo, hi = random_boxes(np.random.default_rng(9), 5000)
    a, _ = build_wide(lo, hi)
    b, _ = build_wide(lo.copy(), hi.copy())
    assert a.tobytes() == b.tobytes()


def test_leaf_packets_mark_only_surfaces_that_block_shadow_rays():
    """The shadow query stops at the first opaque lane, so every surface that lets light through
    (null, masks of any opacity, thin dielectrics, also when wrapped) must be packed non-opaque."""
    from volcl import pack
    from volcl.scene import load_string
    bsdfs = {
        "diffuse": ('<bsdf type="diffuse"/>', True),
        "null": ('<bsdf type="null"/>', False),
        "mask": ('<bsdf type="mask"><float name="opacity" value="0.999"/><bsdf type="diffuse"/></bsdf>', False),
        "pane": ('<bsdf type="thindielectric"/>', False),
        "mask_twosided": ('<bsdf type="mask"><bsdf type="twosided"><bsdf type="diffuse"/></bsdf></bsdf>', False),
        "conductor": ('<bsdf type="conductor"/>', True),
    }
    shapes = "".join(f'<shape type="sphere"><point name="center" x="{3 * i}" y="0" z="0"/>{xml}</shape>'
                     f'<shape type="rectangle"><transform name="to_world"><translate x="{3 * i}" y="5"/>'
                     f'</transform>{xml}</shape>'
                     for i, (xml, _) in enumerate(bsdfs.values()))
    scene = load_string(f'<scene version="3.0.0">{shapes}</scene>')
    a = pack.pack(scene).arrays
    packets = a["leaves"]
    used = packets["prim"].ravel()
    lanes = packets["opaque"].ravel()
    shape_of = np.where(used >= 0, a["triangles"]["shape"][np.maximum(used, 0)],
                        a["spheres"]["shape"][np.maximum(-1 - used, 0)])
    want = np.array([o for _, o in bsdfs.values() for _ in range(2)])    # sphere, rectangle per bsdf
    real = (packets["v"] != 0).any(axis=1).ravel() | (used < 0)    # unused lanes: code 0, no vertices
    assert set(shape_of[real]) == set(range(len(want)))
    np.testing.assert_array_equal(lanes[real] != 0, want[shape_of[real]])
