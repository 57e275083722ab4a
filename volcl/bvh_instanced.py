"""The two-level BVH of scenes with instances (Mitsuba's shapegroup and instance).

Every shape group's primitives (in the group's own space) get a wide BVH of their own, built once
however many instances place the group. A top-level wide BVH covers the scene's own primitives and
one primitive per instance, whose box is the group's box taken to the world by the instance's
to_world (the eight corners, padded by a few ulps so that float32 rounding of the top-level box
never culls a ray the group's tree would hit). All trees share the node and leaf-packet buffers:
the top-level tree first (its root is node 0, as the kernels expect), then each group's, with the
group's child and leaf references moved by where its nodes and packets start. The kernels enter an
instance by taking the ray into the group's space (kernels/bvh.h).

An instance's BVH code is -(INSTANCE_CODE_BASE + k + 1) for its record k (layout.INSTANCE).
"""
from __future__ import annotations

import numpy as np

from . import layout
from .bvh_wide import decode_leaf, device_bvh, empty_wide, leaf_ref, used_slots


def box_corners(lo, hi):
    """The eight corners of the box (lo, hi): (8, 3)."""
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])],
                    np.float64)


def world_box(lo, hi, to_world):
    """The axis-aligned world box around box (lo, hi) mapped by the affine to_world (4x4), padded."""
    m = np.asarray(to_world, np.float64)
    corners = box_corners(lo, hi) @ m[:3, :3].T + m[:3, 3]
    wlo, whi = corners.min(0), corners.max(0)
    pad = 1e-6 * (np.abs(corners).max(0) + (whi - wlo)) + 1e-30
    return wlo - pad, whi + pad


def relocate(nodes, node_base, leaf_base):
    """Wide nodes of a tree stored from node node_base on, its packets from leaf_base on."""
    nodes = nodes.copy()
    child = nodes["child"]
    used = used_slots(nodes)
    inner = used & (child >= 0)
    leaf = used & (child < 0)
    child[inner] += node_base
    first, count = decode_leaf(child[leaf])
    child[leaf] = leaf_ref(first + leaf_base, count)
    return nodes


def instance_record(to_world, root):
    rec = np.zeros((), layout.INSTANCE)
    m = np.asarray(to_world, np.float64)
    rec["to_world"] = m[:3, :4].reshape(12)
    rec["to_object"] = np.linalg.inv(m)[:3, :4].reshape(12)
    rec["root"] = root
    return rec


def two_level_bvh(codes, lo, hi, triangles, opaque, prim_group, instances, max_leaf=4):
    """(nodes, leaf packets, instance records, world bounds (lo, hi) or None) over primitives with
    BVH codes `codes`, boxes lo, hi and opacity `opaque` (as bvh_wide.device_bvh takes them), where
    prim_group[i] is the group primitive i belongs to (-1: the scene's own). `instances` lists
    (group, to_world) placements; an instance of a group without primitives places nothing and gets
    no record."""
    codes, lo, hi = np.asarray(codes, np.int32), np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    opaque, prim_group = np.asarray(opaque, bool), np.asarray(prim_group, np.int64)
    groups = {}             # group -> (nodes, packets, box)
    for g in sorted({g for g, _ in instances}):
        sel = prim_group == g
        if not sel.any():
            continue
        nodes, packets = device_bvh(codes[sel], lo[sel], hi[sel], triangles, opaque[sel], max_leaf=max_leaf)
        groups[g] = (nodes, packets, (lo[sel].min(0), hi[sel].max(0)))
    placed = [(g, m) for g, m in instances if g in groups]
    own = prim_group < 0
    top_lo, top_hi, top_codes = [lo[own]], [hi[own]], [codes[own]]
    for k, (g, m) in enumerate(placed):
        wlo, whi = world_box(*groups[g][2], m)
        top_lo.append(wlo[None])
        top_hi.append(whi[None])
        top_codes.append(np.array([-1 - (layout.INSTANCE_CODE_BASE + k)], np.int32))
    top_lo, top_hi, top_codes = np.concatenate(top_lo), np.concatenate(top_hi), np.concatenate(top_codes)
    top_opaque = np.concatenate([opaque[own], np.zeros(len(placed), bool)])
    if len(top_codes):
        nodes, packets = device_bvh(top_codes, top_lo, top_hi, triangles, top_opaque, max_leaf=max_leaf)
        bounds = (top_lo.min(0), top_hi.max(0))
    else:
        nodes, packets, bounds = empty_wide(), np.zeros(1, layout.LEAF_PACKET), None
    all_nodes, all_packets, roots = [nodes], [packets], {}
    node_base, leaf_base = len(nodes), len(packets)
    for g, (gn, gp, _) in groups.items():
        roots[g] = node_base
        all_nodes.append(relocate(gn, node_base, leaf_base))
        all_packets.append(gp)
        node_base += len(gn)
        leaf_base += len(gp)
    records = np.zeros(max(len(placed), 1), layout.INSTANCE)
    for k, (g, m) in enumerate(placed):
        records[k] = instance_record(m, roots[g])
    return np.concatenate(all_nodes), np.concatenate(all_packets), records, bounds
