"""The device's BVH: a binary binned-SAH tree (volcl.bvh) collapsed into a wide one.

Each wide node holds up to `width` children (volcl.layout.BVH_WIDTH, the kernels' VOLCL_BVH_WIDTH)
whose boxes the kernel tests together with one OpenCL vector per slab plane (kernels/bvh.h). The
collapse opens binary nodes top-down: a wide node starts from the two children of a binary node
and keeps replacing one of its interior children by that child's two children until it has
`width` children or only leaves are left. The child opened is the one of largest surface area
(the one a random ray is most likely to enter, which the SAH says is best to test early), all
wide nodes of one level at once in a few numpy calls per opening; a Python loop runs per level and
opening, never per node.

Stack bound. The kernel pushes every child a ray enters and pops the nearest, so a stack holding
VOLCL_BVH_STACK entries overflows only if some root-to-node path adds up more than that in
(children - 1). The collapse computes that bound; should the area order exceed it (a binary tree
far deeper on one side than the other), it collapses again opening the shallowest child first,
which takes at least log2(width) binary levels into every wide level on any path through interior
children, so no path is longer than ceil(MAX_DEPTH / log2(width)) wide levels and the stack needs
at most that many times (width - 1) entries plus width.

Child references (int32): >= 0, a wide node index; < 0, a leaf, ~ref = (first << LEAF_COUNT_BITS)
| (count - 1) for the primitive slots [first, first + count). Unused child slots carry an
inverted box (+inf, -inf), which no ray enters, and child 0 (no node refers to the root); they
come after the used ones, so a root whose slot 1 holds 0 has one child, and the kernel tests the
primitives of a tree that is one leaf without the box test (kernels/bvh.h bvh_trace).
"""
from __future__ import annotations

import numpy as np

from . import layout
from .bvh import MAX_DEPTH, build_bvh, node_depths

LEAF_COUNT_BITS = 4
MAX_LEAF = 1 << LEAF_COUNT_BITS
STACK = 128     # kernels/bvh.h VOLCL_BVH_STACK


def build_wide(lo, hi, max_leaf=4, width=layout.BVH_WIDTH):
    """The wide BVH over primitive boxes lo, hi ((n, 3) each): (wide nodes, order) with order as
    in volcl.bvh.build_bvh, leaves referring to primitive slots; an empty input gives the one
    empty node."""
    binary, order = build_bvh(lo, hi, max_leaf=max_leaf)
    return collapse(binary, width), order


def device_bvh(codes, lo, hi, triangles, opaque=None, max_leaf=4):
    """What the kernels traverse: (wide nodes, leaf packets) over primitives with codes `codes`
    (>= 0: a row of `triangles`, (m, 3, 3) vertices; < 0: an analytic primitive), boxes lo, hi,
    and whether each has an opaque surface (default: all)."""
    wide, order = build_wide(lo, hi, max_leaf=max_leaf)
    opaque = np.ones(len(codes), bool) if opaque is None else np.asarray(opaque, bool)
    return pack_leaves(wide, np.asarray(codes, np.int32)[order], triangles, opaque[order])


def pack_leaves(wide, slot_codes, triangles, slot_opaque, lanes=layout.LEAF_WIDTH):
    """Leaf packets (layout.LEAF_PACKET) for the leaves of `wide`, whose references name primitive
    slots: slot i holds the primitive of code slot_codes[i], opaque where slot_opaque[i]. Returns
    (wide with leaf references to packets instead, packets). A leaf of k primitives takes
    ceil(k / lanes) packets, in slot order; triangle lanes get their vertices (float32), other
    lanes a zero triangle."""
    wide = wide.copy()
    child = wide["child"]
    is_leaf = used_slots(wide) & (child < 0)
    first, count = decode_leaf(child[is_leaf])
    n_packets = -(-count // lanes)
    by_slot = np.argsort(first, kind="stable")
    start = np.empty_like(first)
    start[by_slot] = np.cumsum(n_packets[by_slot]) - n_packets[by_slot]
    child[is_leaf] = leaf_ref(start, n_packets)
    packets = np.zeros(max(int(n_packets.sum()), 1), layout.LEAF_PACKET)
    # every slot's packet and lane (leaves tile the slots in order of their first slot)
    leaf_of_slot = np.repeat(by_slot, count[by_slot])
    rank = np.arange(len(slot_codes)) - first[leaf_of_slot]
    packet, lane = start[leaf_of_slot] + rank // lanes, rank % lanes
    codes = np.asarray(slot_codes, np.int32)
    packets["prim"][packet, lane] = codes
    packets["opaque"][packet, lane] = np.where(slot_opaque, -1, 0)
    tri = codes >= 0
    verts = np.asarray(triangles, np.float32).reshape(-1, 9)
    packets["v"][packet[tri], :, lane[tri]] = verts[codes[tri]]
    return wide, packets


def used_slots(wide):
    """(nodes, width) mask of the child slots in use (the others hold inverted boxes)."""
    b = wide["bounds"]
    return b[:, 0, :] <= b[:, 3, :]


def leaf_ref(first, count):
    """Child reference of a leaf holding primitive slots [first, first + count)."""
    first, count = np.asarray(first, np.int64), np.asarray(count, np.int64)
    assert np.all((count >= 1) & (count <= MAX_LEAF)), "leaf sizes must be 1..16"
    assert np.all(first < 2 ** (31 - LEAF_COUNT_BITS)), "too many primitives for a leaf reference"
    return (~((first << LEAF_COUNT_BITS) | (count - 1))).astype(np.int32)


def decode_leaf(ref):
    """(first, count) of leaf references (ref < 0)."""
    v = ~np.asarray(ref, np.int64)
    return v >> LEAF_COUNT_BITS, (v & (MAX_LEAF - 1)) + 1


def empty_wide(width=layout.BVH_WIDTH):
    """One wide node with no children: the tree of an empty scene, which no ray enters."""
    nodes = np.zeros(1, layout.bvh_wide_node(width))
    nodes["bounds"][:, :3] = np.inf
    nodes["bounds"][:, 3:] = -np.inf
    return nodes


def collapse(nodes, width=layout.BVH_WIDTH, stack=STACK, order="auto"):
    """Wide nodes (layout.bvh_wide_node(width)) for a depth-first binary BVH_NODE array.

    order: which child a wide node opens next, "area" (largest first), "shallow" (shallowest
    first, larger first among equals) or "auto": by area unless that needs a deeper stack than
    `stack`, else shallow. Primitive slots (leaf ranges into the binary builder's `order`) are kept
    as they are. Children of a wide node are stored in the order the collapse produced them; the
    kernel orders them per ray. Wide nodes are numbered level by level, each level's nodes in the
    order of their parents.
    """
    if len(nodes) == 0:
        return empty_wide(width)
    assert width >= 2 and nodes["count"].max() <= MAX_LEAF
    area = _half_area(nodes)
    if order in ("area", "auto"):
        wide, need = _collapse(nodes, width, area)
        if order == "area" or need <= stack:
            return wide
    depth = node_depths(nodes).astype(np.float64)
    # area / root area <= 1 < one level, halved so it only breaks ties
    wide, need = _collapse(nodes, width, -depth + 0.5 * area / max(area[0], np.finfo(np.float64).tiny))
    assert need <= shallow_stack_bound(width), "the shallowest-first collapse broke its bound"
    if need > stack:
        raise ValueError(f"the wide BVH needs a traversal stack of {need} entries, more than {stack}")
    return wide


def shallow_stack_bound(width, max_depth=MAX_DEPTH):
    """Stack need of a shallowest-first collapse of any binary tree no deeper than max_depth: every
    wide level on a path through interior children spans at least log2(width) binary levels."""
    levels = -(-max_depth // int(np.log2(width)))
    return levels * (width - 1) + width


def stack_need(wide):
    """Largest stack depth a traversal of `wide` can reach: over every root-to-node path, the sum
    of (children - 1) of the nodes above plus the children of the node itself."""
    child = wide["child"]
    valid = np.isfinite(wide["bounds"][:, 0, :]) & (wide["bounds"][:, 0, :] <= wide["bounds"][:, 3, :])
    kids = valid.sum(1)
    need = np.zeros(len(wide), np.int64)
    frontier = np.array([0])
    best = int(kids[0])
    width = child.shape[1]
    while len(frontier):
        rows = np.repeat(frontier, width)
        c = child[frontier].ravel()
        ok = valid[frontier].ravel() & (c >= 0)
        nxt = c[ok]
        need[nxt] = need[rows[ok]] + kids[rows[ok]] - 1
        if len(nxt):
            best = max(best, int((need[nxt] + kids[nxt]).max()))
        frontier = nxt
    return best


def _half_area(nodes):
    d = np.maximum(nodes["bmax"].astype(np.float64) - nodes["bmin"].astype(np.float64), 0.0)
    return d[:, 0] * d[:, 1] + d[:, 1] * d[:, 2] + d[:, 2] * d[:, 0]


def _collapse(nodes, width, score):
    """Collapse opening the child of highest `score` first; returns (wide nodes, stack need)."""
    count = nodes["count"]
    inner = count == 0
    right = nodes["index"].astype(np.int64)
    levels = []             # per level: (m, width) binary ids of the children, -1 unused
    if not inner[0]:        # a single leaf: one wide node holding it
        levels.append(np.array([[0] + [-1] * (width - 1)], np.int64))
    else:
        frontier = np.array([0], np.int64)
        while len(frontier):
            slots = _open(frontier, inner, right, score, width)
            levels.append(slots)
            flat = slots.ravel()
            frontier = flat[(flat >= 0) & inner[np.maximum(flat, 0)]]
    return _emit(nodes, levels, width, inner)


def _open(frontier, inner, right, score, width):
    """The children of the wide nodes made from binary nodes `frontier`: (m, width) binary ids."""
    m = len(frontier)
    slots = np.full((m, width), -1, np.int64)
    slots[:, 0] = frontier + 1
    slots[:, 1] = right[frontier]
    used = np.full(m, 2, np.int64)
    rows = np.arange(m)
    for _ in range(width - 2):
        valid = slots >= 0
        ids = np.maximum(slots, 0)
        s = np.where(valid & inner[ids], score[ids], -np.inf)
        best = np.argmax(s, axis=1)
        go = np.isfinite(s[rows, best])
        if not go.any():
            break
        r, b = rows[go], best[go]
        opened = slots[r, b]
        slots[r, b] = opened + 1
        slots[r, used[r]] = right[opened]
        used[r] += 1
    return slots


def _emit(nodes, levels, width, inner):
    """Wide node records from the per-level child slots, and the stack need of the tree."""
    total = sum(len(s) for s in levels)
    wide = np.zeros(total, layout.bvh_wide_node(width))
    base = 0
    need = np.zeros(total, np.int64)
    best = 0
    for lvl, slots in enumerate(levels):
        m = len(slots)
        valid = slots >= 0
        ids = np.maximum(slots, 0)
        is_inner = valid & inner[ids]
        # the next level's wide nodes are this level's interior children, in row-major order
        nxt = base + m + np.cumsum(is_inner.ravel()).reshape(m, width) - 1
        leaf = leaf_ref(np.where(valid & ~is_inner, nodes["index"][ids], 0),
                        np.where(valid & ~is_inner, nodes["count"][ids], 1))
        wide["child"][base:base + m] = np.where(is_inner, nxt, np.where(valid, leaf, 0))
        lo = np.where(valid[..., None], nodes["bmin"][ids], np.inf).transpose(0, 2, 1)
        hi = np.where(valid[..., None], nodes["bmax"][ids], -np.inf).transpose(0, 2, 1)
        wide["bounds"][base:base + m, :3] = lo
        wide["bounds"][base:base + m, 3:] = hi
        kids = valid.sum(1)
        here = need[base:base + m]
        best = max(best, int((here + kids).max()))
        child_need = np.repeat(here + kids - 1, width).reshape(m, width)
        need[nxt[is_inner]] = child_need[is_inner]
        base += m
    return wide, best
