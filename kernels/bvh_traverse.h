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
    BoxRay br = box_ray_make(o, d);
    int stack[VOLCL_BVH_STACK];
    float stack_t[VOLCL_BVH_STACK];
    int top = 0;
    bool found = false;
    for (;;) {
        if (ref >= 0) {
            int next = node_visit(&sc->nodes[ref], &br, hit->t, mode, stack, stack_t, &top);
            if (next != VOLCL_NO_CHILD) {
                ref = next;
                continue;
            }
        } else {
            int h = VOLCL_TRAVERSE_LEAVES(sc, ref, &sh, o, d, mode, hit);
            if (h == 2) return 2;
            found |= h != 0;
        }
        ref = stack_next(stack, stack_t, &top, hit->t);
        if (ref == VOLCL_NO_CHILD) return found ? 1 : 0;
    }
}

#undef VOLCL_TRAVERSE_NAME
#undef VOLCL_TRAVERSE_LEAF
#undef VOLCL_TRAVERSE_LEAVES
#undef VOLCL_TRAVERSE_PACKET
