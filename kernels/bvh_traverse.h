/* The traversal loop of kernels/bvh.h, included once per tree level: it defines
 * VOLCL_TRAVERSE_NAME(sc, root, o, d, tmax, mode, hit), the query (TRACE_*) over the tree whose root
 * is wide node `root`, testing a leaf packet's analytic lanes with VOLCL_TRAVERSE_LEAF (as
 * packet_analytic_intersect does). It returns 0 when nothing is hit in (0, tmax), 1 for a hit in
 * *hit, 2 when the query stopped early (TRACE_ANY on any hit, TRACE_SHADOW on an opaque one).
 * OpenCL C has no recursion, so the top level (whose leaves hold instances) and a shape group's
 * tree are two functions from this one text. */

#define VOLCL_TRAVERSE_CAT2(a, b) a##b
#define VOLCL_TRAVERSE_CAT(a, b) VOLCL_TRAVERSE_CAT2(a, b)
#define VOLCL_TRAVERSE_LEAVES VOLCL_TRAVERSE_CAT(VOLCL_TRAVERSE_NAME, _leaves)
#define VOLCL_TRAVERSE_PACKET VOLCL_TRAVERSE_CAT(VOLCL_TRAVERSE_NAME, _packet)

/* One leaf packet, its triangles and then its analytic lanes: 0, 1 or 2 as the traversal returns. */
__attribute__((always_inline))
inline int VOLCL_TRAVERSE_PACKET(const SceneData *sc, __global const LeafPacket *pk, const Shear *sh, float3 o,
                                 float3 d, int mode, Hit *hit) {
    int h = packet_triangles_intersect(pk, sh, hit->t, mode, hit);
    if (h == 2) return 2;
    int ha = VOLCL_TRAVERSE_LEAF(sc, pk, o, d, mode, hit);
    return ha == 2 ? 2 : h | ha;
}

/* The packets of leaf reference ref (< 0) against the query: 0, 1 or 2 as the traversal returns. */
__attribute__((always_inline))
inline int VOLCL_TRAVERSE_LEAVES(const SceneData *sc, int ref, const Shear *sh, float3 o, float3 d, int mode,
                                 Hit *hit) {
    int leaf = ~ref;
    int first = leaf >> 4, end = first + (leaf & 15) + 1;
    int found = 0;
    for (int i = first; i < end; ++i) {
        int h = VOLCL_TRAVERSE_PACKET(sc, &sc->leaves[i], sh, o, d, mode, hit);
        if (h == 2) return 2;
        found |= h;
    }
    return found != 0;
}

/* The traversal keeps a stack of (child, entry distance). At a node every child box the ray enters
 * goes on the stack; for closest hits they are inserted in order of entry distance, nearest on top,
 * so the nearest is visited next and a hit found there culls the others when they come off the
 * stack (an entry distance beyond the hit, with the box test's tolerance). Occlusion tests
 * (TRACE_ANY) skip the ordering; the shadow query keeps it, for the nearest null surface. The builder
 * bounds the stack depth any ray can reach by VOLCL_BVH_STACK (volcl/bvh_wide.py). An empty scene is one node without children, which no ray enters. */
inline int VOLCL_TRAVERSE_NAME(const SceneData *sc, int root, float3 o, float3 d, float tmax, int mode, Hit *hit) {
    Shear sh = shear_make(o, d);
    hit->t = tmax;
    hit->prim = 0;
    hit->b1 = hit->b2 = 0.0f;
#if VOLCL_HAS_INSTANCES
    hit->inst = -1;
#endif
    /* A tree that is one leaf (a scene or group of a few primitives): its packets without the box
     * test and the stack. Slots of a node are filled first to last and no node refers to the top
     * root (0), so child[1] == 0 says this root has one child. The box test culls nothing the
     * primitives' own tests would not, so the hit is the same. */
    __global const BvhWideNode *rn = &sc->nodes[root];
    if (rn->child[0] < 0 && rn->child[1] == 0) {
        int leaf = ~rn->child[0];
        /* one packet: its test alone, without the loop's spilled state */
        if ((leaf & 15) == 0) return VOLCL_TRAVERSE_PACKET(sc, &sc->leaves[leaf >> 4], &sh, o, d, mode, hit);
        return VOLCL_TRAVERSE_LEAVES(sc, rn->child[0], &sh, o, d, mode, hit);
    }
    int ref = root;         /* the node or leaf visited now: the root first */
    /* a zero direction component becomes a tiny one of the same sign: its slab then spans
     * +-1e30 instead of producing 0 * INF = NaN for an origin on the slab plane */
    float3 inv_d = 1.0f / select(d, copysign((float3)(1e-30f), d), fabs(d) < (float3)(1e-30f));
    BoxRay br = box_ray_make(o, inv_d);
    int stack[VOLCL_BVH_STACK];
    float stack_t[VOLCL_BVH_STACK];
    int top = 0;
    bool found = false;
    for (;;) {
        if (ref >= 0) {
            __global const BvhWideNode *n = &sc->nodes[ref];
            floatW entry = node_children_entry(n, &br, hit->t);
            int mask = lane_mask(entry < (floatW)(VOLCL_INF));
            if (mask != 0) {
                int i = lowest_lane(mask);
                mask &= mask - 1;
                if (mask == 0) {        /* one child entered: visit it without the stack */
                    ref = n->child[i];
                    continue;
                }
                float enter[VOLCL_BVH_WIDTH];
                vstoreW(entry, 0, enter);
                /* every entered child on the stack; for closest hits each goes into this node's run
                 * of the stack in order of entry distance, farthest at the bottom */
                int base = top;
                for (;;) {
                    float t = enter[i];
                    int j = top++;
                    if (mode != TRACE_ANY) {
                        for (; j > base && stack_t[j - 1] < t; --j) {
                            stack[j] = stack[j - 1];
                            stack_t[j] = stack_t[j - 1];
                        }
                    }
                    stack[j] = n->child[i];
                    stack_t[j] = t;
                    if (mask == 0) break;
                    i = lowest_lane(mask);
                    mask &= mask - 1;
                }
                ref = stack[--top];     /* the nearest, which just passed the box test */
                continue;
            }
        } else {
            int h = VOLCL_TRAVERSE_LEAVES(sc, ref, &sh, o, d, mode, hit);
            if (h == 2) return 2;
            found |= h != 0;
        }
        /* next from the stack, skipping entries whose box the ray enters beyond the closest hit */
        do {
            if (top == 0) return found ? 1 : 0;
            --top;
        } while (stack_t[top] > hit->t * 1.0000004f);
        ref = stack[top];
    }
}

#undef VOLCL_TRAVERSE_NAME
#undef VOLCL_TRAVERSE_LEAF
#undef VOLCL_TRAVERSE_LEAVES
#undef VOLCL_TRAVERSE_PACKET
