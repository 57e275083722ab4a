"""Host-side BVH construction: a vectorized binned-SAH builder and the SAH cost of a finished tree.

The builder works breadth first: every node of one tree level is split in the same handful of numpy
calls (segment reductions with ufunc.reduceat, bin keys bin * nodes + node, np.bincount for bin
counts, ufunc.at for bin bounds, prefix scans over the bins for the SAH sweep, a cumsum-based stable
partition). Nodes with at most max_leaf primitives become leaves; larger ones always split, at the
SAH-best boundary between `bins` equal bins along their axis of largest centroid extent, or at the
centroid median when no boundary separates them or the depth budget (MAX_DEPTH) forbids the SAH
choice. Once all levels exist, nodes are relabelled into the depth-first layout of
`volcl.layout.BVH_NODE` from subtree sizes, again one level at a time. Python loops run per level
(a few dozen) or per bin, never per primitive or node.

Primitive slots: each node owns a contiguous range of the output `order` array, and a split keeps
the left child's range before the right child's, so leaves come out in depth-first order and their
`index` is simply the start of their range.
"""
import numpy as np

from volcl.layout import BVH_NODE

# The device traversal stack holds VOLCL_BVH_STACK = 64 entries and pushes at most one per level.
# Splits are constrained so that no leaf lies deeper than this (root depth 0), with headroom.
MAX_DEPTH = 48

# A binary node's box test relative to a leaf packet's test, for the splits of small nodes
# (_small_splits): collapsed into an 8-wide node it is one lane of the parent's box test and one
# stack entry. Measured on textured_cbox.xml: 0.15 takes 18% off its render time, 0.2 and 0.3 only
# 12% (they keep its ceiling and side wall, areas 0.82 of their box, in one leaf).
SMALL_SPLIT_NODE_COST = 0.15
# Small nodes below this share of the root's area stay leaves without a trial (_small_splits).
SMALL_SPLIT_MIN_AREA = 1e-4


def build_bvh(lo, hi, max_leaf=4, bins=16):
    """Build a binned-SAH BVH over axis-aligned boxes.

    lo, hi: (n, 3) float arrays, per-primitive AABB corners, finite and within float32 range.
    Returns (nodes, order): nodes is a BVH_NODE array in depth-first order with the root at 0;
    order is an int32 permutation such that a leaf's primitive slots [index, index + count) refer
    to the original primitives order[index:index + count].

    n == 0 gives an empty nodes array (length 0): count == 0 means "interior" in BVH_NODE, so no
    node can stand for an empty tree; the caller uploads its own placeholder.

    Node bounds are conservative in float32: primitive boxes are rounded outward once, and node
    boxes are exact min/max of those. Leaves hold at most max_leaf primitives (identical centroids
    are split at the index median), and no leaf is deeper than MAX_DEPTH. Deterministic.
    """
    lo64, hi64 = _check_input(lo, hi, max_leaf, bins)
    n = len(lo64)
    if n == 0:
        return np.zeros(0, BVH_NODE), np.zeros(0, np.int32)
    if _levels_needed(np.array([n]), max_leaf)[0] > MAX_DEPTH:
        raise ValueError(f"{n} primitives need leaves larger than max_leaf={max_leaf}")
    levels, order = _build_levels(_prim_data(lo64, hi64), max_leaf, bins)
    return _flatten(levels), order


def sah_cost(nodes, c_trav=1.0, c_isect=1.0):
    """Standard SAH cost of the tree relative to the root's area.

    Sum over interior nodes of c_trav * A(node) / A(root) plus sum over leaves of
    c_isect * count * A(leaf) / A(root), A being surface area. An empty tree costs 0. When the
    root's area is 0 (all primitives are points on one spot, or on a line) the ratios are undefined;
    every node is then weighted 1, as if every ray reaching the root reached every node.
    """
    if len(nodes) == 0:
        return 0.0
    area = _half_area(nodes["bmin"].T, nodes["bmax"].T)
    if area[0] > 0.0:
        weight = area / area[0]
    else:
        weight = np.ones_like(area)
    count = nodes["count"]
    terms = np.where(count > 0, c_isect * count * weight, c_trav * weight)
    return float(terms.sum())


def node_depths(nodes):
    """Depth of every node (root 0) of a depth-first BVH_NODE array, one numpy pass per level."""
    depth = np.zeros(len(nodes), np.int32)
    frontier = np.zeros(1 if len(nodes) else 0, np.int64)
    d = 0
    while len(frontier):
        depth[frontier] = d
        inner = frontier[nodes["count"][frontier] == 0]
        frontier = np.concatenate([inner + 1, nodes["index"][inner].astype(np.int64)])
        d += 1
    return depth


def _check_input(lo, hi, max_leaf, bins):
    lo64 = np.asarray(lo, dtype=np.float64).reshape(-1, 3)
    hi64 = np.asarray(hi, dtype=np.float64).reshape(-1, 3)
    assert lo64.shape == hi64.shape, "lo and hi must both be (n, 3)"
    assert not (np.isnan(lo64).any() or np.isnan(hi64).any()), "NaN in primitive bounds"
    f32max = float(np.finfo(np.float32).max)
    assert np.all(np.abs(lo64) <= f32max) and np.all(np.abs(hi64) <= f32max), \
        "primitive bounds must be finite float32 values"
    assert np.all(lo64 <= hi64), "primitive boxes must have lo <= hi"
    assert max_leaf >= 1 and bins >= 2
    assert len(lo64) < 2**31, "primitive indices are int32 on the device"
    return lo64, hi64


def _prim_data(lo64, hi64):
    """Per-primitive rows lo xyz, hi xyz, centroid xyz as one (9, n) float32 array.

    lo/hi are rounded outward to float32 once; every node box is an exact min/max of these, which
    makes all node boxes conservative without any further rounding care. Centroids only steer the
    splits, so plain rounding is fine for them. Axis-major rows keep per-axis work contiguous.
    """
    data = np.empty((9, len(lo64)), np.float32)
    data[0:3] = _round_down(lo64).T
    data[3:6] = _round_up(hi64).T
    data[6:9] = (0.5 * lo64 + 0.5 * hi64).T
    return data


def _round_down(x64):
    x32 = x64.astype(np.float32)
    over = x32.astype(np.float64) > x64
    x32[over] = np.nextafter(x32[over], np.float32(-np.inf))
    return x32


def _round_up(x64):
    x32 = x64.astype(np.float32)
    under = x32.astype(np.float64) < x64
    x32[under] = np.nextafter(x32[under], np.float32(np.inf))
    return x32


def _levels_needed(count, max_leaf):
    """Tree levels below a node that median splits need to bring `count` down to max_leaf.

    ceil(log2(ceil(count / max_leaf))), computed exactly via the binary exponent of q - 1.
    """
    q = (count.astype(np.int64) + max_leaf - 1) // max_leaf
    return np.frexp((q - 1).astype(np.float64))[1]


class _Active:
    """The unfinished nodes of one level, ascending by slot start, and their primitives.

    prim holds the primitives of node 0, then node 1, ...; node j's primitives sit at
    prim[off[j]:off[j] + count[j]] and will end up at order[start[j]:start[j] + count[j]].
    data holds the matching columns of _prim_data: moving it along with prim costs less than
    gathering it from the original (spatially random) order on every level.
    """

    def __init__(self, prim, data, start, count):
        self.prim, self.data, self.start, self.count = prim, data, start, count
        self.off = _offsets(count)
        self.seg = np.repeat(np.arange(len(count)), count)
        self.rank = np.arange(len(prim)) - self.off[self.seg]

    def subset(self, keep_node):
        keep = keep_node[self.seg]
        return _Active(self.prim[keep], self.data[:, keep], self.start[keep_node],
                       self.count[keep_node])


def _offsets(count):
    """Start of each node's run in a packed primitive array."""
    return (np.cumsum(count) - count).astype(np.int64)


def _build_levels(data, max_leaf, bins):
    """Split level after level until every node is a leaf.

    Returns the per-level node records (see _split_level) and the finished `order` array.
    """
    n = data.shape[1]
    order = np.empty(n, np.int32)
    act = _Active(np.arange(n, dtype=np.int32), data, np.zeros(1, np.int64),
                  np.array([n], np.int64))
    levels = []
    depth = 0
    root_area = float(_half_area(data[0:3].min(axis=1), data[3:6].max(axis=1))) if n else 0.0
    while len(act.count):
        record, act = _split_level(act, order, depth, max_leaf, bins, root_area)
        levels.append(record)
        depth += 1
    return levels, order


def _split_level(act, order, depth, max_leaf, bins, root_area):
    """Bound every active node of one level, finish the small ones as leaves, split the rest.

    A node of at most max_leaf primitives becomes a leaf unless splitting it pays (_small_splits);
    a root that small always does, since the kernel tests a tree of one leaf without any box test.
    Returns a record (bmin, bmax, start, count, is_leaf, child) where child is the level-local
    index of the left child in the next level (right child = child + 1), and the next level.
    """
    bmin = np.minimum.reduceat(act.data[0:3], act.off, axis=1).T
    bmax = np.maximum.reduceat(act.data[3:6], act.off, axis=1).T
    inner = act.count > max_leaf
    small_left = None
    if 0 < depth < MAX_DEPTH:
        small, small_left = _small_splits(act, _half_area(bmin.T, bmax.T), root_area, max_leaf)
        inner |= small
    _emit_leaves(act, ~inner, order)
    child = np.full(len(act.count), -1, np.int64)
    child[inner] = 2 * np.arange(np.count_nonzero(inner))
    record = (bmin, bmax, act.start, act.count, ~inner, child)

    keep = inner[act.seg]
    act = act.subset(inner)
    goes_left, value, median = _choose_splits(act, depth, max_leaf, bins)
    if small_left is not None:
        # the small nodes' own splits (their binned SAH planes are not used)
        small_node = act.count <= max_leaf
        goes_left = np.where(small_node[act.seg], small_left[keep], goes_left)
        median &= ~small_node
    return record, _partition(act, goes_left, value, median)


def _small_splits(act, area, root_area, max_leaf):
    """Which nodes of 2 to max_leaf primitives split further, by the SAH with the costs of leaf
    packets, and for them each primitive's side (True = left; a per-primitive array over act).

    A leaf of up to max_leaf primitives is one packet test whatever its count, so a split replaces
    one test by the node's box test and a test of each child, each paid by the rays that enter its
    box. It pays when the children's areas add up to less than the node's by more than the box
    test's cost (SMALL_SPLIT_NODE_COST packet tests). Large primitives that share a leaf only
    because there are few of them, such as the walls of a room, whose boxes together span the room,
    split; a leaf of neighbouring triangles of a mesh mostly does not (on benchmarks/common.py's
    bumpy sphere 9% of the small nodes split at 100k triangles, 1.3% at 200k, none at 1M).

    Every split between consecutive primitives in centroid order along the axis of largest
    centroid extent is tried (at most max_leaf - 1 per node, on arrays padded to max_leaf slots):
    exact, and cheaper than binning the many small nodes of a large mesh's last levels. A node
    whose area is below SMALL_SPLIT_MIN_AREA of the root's stays a leaf untried: the SAH saving
    of a split is at most that share of a ray's cost, and the last levels of a large mesh hold
    hundreds of thousands of such nodes, whose trial would add a quarter to the build time.
    """
    tried = (act.count >= 2) & (act.count <= max_leaf) & (area >= SMALL_SPLIT_MIN_AREA * root_area)
    nodes = np.flatnonzero(tried)
    split = np.zeros(len(act.count), bool)
    goes_left = np.zeros(len(act.prim), bool)
    if len(nodes) == 0:
        return split, goes_left
    k, lanes = len(nodes), np.arange(max_leaf)
    valid = lanes < act.count[nodes][:, None]
    slot = act.off[nodes][:, None] + np.where(valid, lanes, 0)           # padding repeats slot 0
    cen = act.data[6:9][:, slot].astype(np.float64)                       # (3, k, max_leaf)
    axis = np.argmax(cen.max(axis=2) - cen.min(axis=2), axis=0)
    value = np.where(valid, cen[axis, np.arange(k)], np.inf)
    by_value = np.argsort(value, axis=1, kind="stable")
    value = np.take_along_axis(value, by_value, 1)
    slot = np.take_along_axis(slot, by_value, 1)
    valid = np.take_along_axis(valid, by_value, 1)
    lo = np.where(valid, act.data[0:3][:, slot], np.inf)
    hi = np.where(valid, act.data[3:6][:, slot], -np.inf)
    a_left = _half_area(np.minimum.accumulate(lo, axis=2), np.maximum.accumulate(hi, axis=2))[:, :-1]
    a_right = _half_area(np.minimum.accumulate(lo[:, :, ::-1], axis=2)[:, :, ::-1],
                         np.maximum.accumulate(hi[:, :, ::-1], axis=2)[:, :, ::-1])[:, 1:]
    # a plane lies between two different centroids, with a primitive on each side
    cost = np.where(valid[:, 1:] & (value[:, :-1] < value[:, 1:]), a_left + a_right, np.inf)
    best = np.argmin(cost, axis=1)
    ok = cost[np.arange(k), best] < (1.0 - SMALL_SPLIT_NODE_COST) * area[nodes]
    split[nodes[ok]] = True
    # left: the primitives of split nodes whose centroid lies below the first one right of the plane
    threshold = np.zeros(len(act.count))
    threshold[nodes[ok]] = value[ok, best[ok] + 1]
    node_axis = np.zeros(len(act.count), np.int64)
    node_axis[nodes] = axis
    mine = np.flatnonzero(split[act.seg])
    seg = act.seg[mine]
    goes_left[mine] = act.data[6:9][node_axis[seg], mine].astype(np.float64) < threshold[seg]
    return split, goes_left


def _emit_leaves(act, leaf, order):
    """Write the primitives of this level's leaves into their final slots."""
    mine = leaf[act.seg]
    order[act.start[act.seg[mine]] + act.rank[mine]] = act.prim[mine]


def _choose_splits(act, depth, max_leaf, bins):
    """Binned SAH over every node of `act` (all of which must split).

    Returns the per-primitive side (True = left) of the SAH plane, the centroid coordinate on the
    split axis per primitive, and which nodes use a median split instead (see _needs_median).
    """
    m = len(act.count)
    key, value, flat = _bin_keys(act, act.data[6:9], bins)
    counts, bin_lo, bin_hi = _bin_stats(key, act.data[0:3], act.data[3:6], m, bins)
    split_bin, n_left = _sah_sweep(counts, bin_lo, bin_hi)
    median = _needs_median(act.count, n_left, flat, depth, max_leaf)
    goes_left = key // m <= split_bin[act.seg]
    return goes_left, value, median


def _bin_keys(act, cen, bins):
    """Per-primitive bin along each node's axis of largest centroid extent.

    Returns key = bin * nodes + node per primitive, the centroid coordinate on that axis per
    primitive, and a mask of nodes whose centroids all coincide.
    """
    cmin = np.minimum.reduceat(cen, act.off, axis=1).astype(np.float64)
    cmax = np.maximum.reduceat(cen, act.off, axis=1).astype(np.float64)
    ext = cmax - cmin
    axis = np.argmax(ext, axis=0)
    nodes = np.arange(len(axis))
    width = ext[axis, nodes]
    flat = width <= 0.0
    # float64 keeps bins / width finite even for denormal widths.
    scale = np.where(flat, 0.0, bins / np.where(flat, 1.0, width))
    value = cen[axis[act.seg], np.arange(len(act.prim))]
    b = ((value - cmin[axis, nodes][act.seg]) * scale[act.seg]).astype(np.int64)
    np.clip(b, 0, bins - 1, out=b)
    # Bin-major keys make the per-bin arrays (bins, 3, m): the SAH scans then run over long
    # contiguous rows instead of along many length-`bins` rows.
    return b * len(axis) + act.seg, value, flat


def _bin_stats(key, lo, hi, m, bins):
    """Primitive count and bounds of every (bin, node); empty bins get inverted (+inf, -inf) boxes.

    Returns counts (bins, m) and bounds (bins, 3, m).
    """
    counts = np.bincount(key, minlength=m * bins).reshape(bins, m)
    bin_lo = np.full((3, bins * m), np.inf, np.float32)
    bin_hi = np.full((3, bins * m), -np.inf, np.float32)
    for a in range(3):
        np.minimum.at(bin_lo[a], key, lo[a])
        np.maximum.at(bin_hi[a], key, hi[a])
    bin_lo = bin_lo.reshape(3, bins, m).transpose(1, 0, 2)
    bin_hi = bin_hi.reshape(3, bins, m).transpose(1, 0, 2)
    return counts, bin_lo, bin_hi


def _half_area(lo, hi):
    """Half surface area of boxes given axis-major (3, ...) corners; inverted boxes give 0.

    Differences are taken in float64 so boxes spanning most of the float32 range stay finite.
    """
    d = np.subtract(hi, lo, dtype=np.float64)
    np.maximum(d, 0.0, out=d)
    return d[0] * d[1] + d[1] * d[2] + d[2] * d[0]


def _scan(ufunc, x):
    """Inclusive scan along axis 0; a loop over the few bins beats ufunc.accumulate on axis 0
    several times over."""
    out = np.empty_like(x)
    out[0] = x[0]
    for i in range(1, len(x)):
        ufunc(out[i - 1], x[i], out=out[i])
    return out


def _sah_sweep(counts, bin_lo, bin_hi):
    """Best split plane per node from prefix (left) and suffix (right) scans over the bins.

    counts (bins, m), bin_lo / bin_hi (bins, 3, m). Returns the split bin s (bins <= s go left)
    minimizing A_left * N_left + A_right * N_right, and its left count (0 or the node's count when
    no plane separates the primitives).
    """
    n_left = np.cumsum(counts, axis=0)[:-1]
    n_right = n_left[-1] + counts[-1] - n_left
    a_left = _half_area(_scan(np.minimum, bin_lo)[:-1].transpose(1, 0, 2),
                        _scan(np.maximum, bin_hi)[:-1].transpose(1, 0, 2))
    a_right = _half_area(_scan(np.minimum, bin_lo[::-1])[-2::-1].transpose(1, 0, 2),
                         _scan(np.maximum, bin_hi[::-1])[-2::-1].transpose(1, 0, 2))
    cost = a_left * n_left + a_right * n_right
    cost[(n_left == 0) | (n_right == 0)] = np.inf
    split_bin = np.argmin(cost, axis=0)
    return split_bin, n_left[split_bin, np.arange(len(split_bin))]


def _needs_median(count, n_left, flat, depth, max_leaf):
    """Nodes whose SAH split is replaced by a median split.

    That happens when no plane separates the centroids (all in one bin), or when the SAH children
    could not be finished by median splits within MAX_DEPTH: a median split needs
    _levels_needed(count) more levels, so checking that budget keeps every leaf at depth
    <= MAX_DEPTH by induction, whatever the input.
    """
    separable = ~flat & (n_left > 0) & (n_left < count)
    larger_child = np.maximum(n_left, count - n_left)
    in_budget = depth + 1 + _levels_needed(larger_child, max_leaf) <= MAX_DEPTH
    return ~(separable & in_budget)


def _partition(act, goes_left, value, median):
    """Order median nodes' primitives by centroid, then stably partition every node's primitives
    into a left and a right run. Returns the next level: children in order L0, R0, L1, R1, ..."""
    prim, data, count, off, seg = act.prim, act.data, act.count, act.off, act.seg
    med = median[seg]
    if med.any():
        # Sorting only the median nodes' primitives by (node, centroid) keeps them within their
        # node's run; lexsort is stable, so identical centroids fall back to index order.
        idx = np.flatnonzero(med)
        perm = idx[np.lexsort((value[idx], seg[idx]))]
        prim, data = prim.copy(), data.copy()
        prim[idx] = prim[perm]
        data[:, idx] = data[:, perm]
        goes_left = np.where(med, act.rank < count[seg] // 2, goes_left)

    lefts = np.cumsum(goes_left)
    before = lefts[off] - goes_left[off]
    n_left = lefts[off + count - 1] - before
    lefts_before = lefts - goes_left - before[seg]
    dest = np.where(goes_left, off[seg] + lefts_before,
                    off[seg] + n_left[seg] + (act.rank - lefts_before))
    moved = np.empty_like(prim)
    moved[dest] = prim
    moved_data = np.empty_like(data)
    moved_data[:, dest] = data

    child_start = np.stack([act.start, act.start + n_left], axis=1).ravel()
    child_count = np.stack([n_left, count - n_left], axis=1).ravel()
    return _Active(moved, moved_data, child_start, child_count)


def _flatten(levels):
    """Relabel breadth-first level records into the depth-first BVH_NODE array."""
    base = np.concatenate([[0], np.cumsum([len(r[3]) for r in levels])]).astype(np.int64)
    total = int(base[-1])
    size = np.ones(total, np.int64)
    for lvl in range(len(levels) - 2, -1, -1):
        inner, left = _children(levels, base, lvl)
        size[inner] = 1 + size[left] + size[left + 1]
    dfs = np.zeros(total, np.int64)
    for lvl in range(len(levels) - 1):
        inner, left = _children(levels, base, lvl)
        dfs[left] = dfs[inner] + 1
        dfs[left + 1] = dfs[inner] + 1 + size[left]

    nodes = np.empty(total, BVH_NODE)
    for lvl, (bmin, bmax, start, count, leaf, child) in enumerate(levels):
        at = dfs[base[lvl]:base[lvl + 1]]
        right = dfs[np.where(leaf, 0, base[lvl + 1] + child + 1)]
        nodes["bmin"][at] = bmin
        nodes["bmax"][at] = bmax
        nodes["index"][at] = np.where(leaf, start, right)
        nodes["count"][at] = np.where(leaf, count, 0)
    return nodes


def _children(levels, base, lvl):
    """Global breadth-first ids of a level's inner nodes and of their left children."""
    leaf, child = levels[lvl][4], levels[lvl][5]
    inner = np.flatnonzero(~leaf)
    return base[lvl] + inner, base[lvl + 1] + child[inner]
