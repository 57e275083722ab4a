/* Benchmark-only kernel: closest hit through volcl's wide BVH written in the lanes style
 * (kernels/lanes.h): one ray per work-item in scalar floats, a loop over the tree with a small
 * per-ray stack, for the CPU runtimes to run across work-items in SIMD lanes
 * (benchmarks/traversal_lanes.py measures it against bvh_trace of benchmarks/kernels/trace.cl).
 *
 * The walk is bvh_trace's (kernels/bvh_traverse.h, TRACE_CLOSEST) visit for visit: the same box
 * test (node_children_entry per child), the entered children pushed in order of entry distance
 * (nearest on top, equal distances: the higher slot on top, as bvh_traverse.h's insertion leaves
 * them), the same cull on popping (entry beyond the hit times 1.0000004), a leaf's packets in order,
 * each packet's lanes against the same tmax with the nearest lane winning (ties: the lower lane),
 * and lanes_triangle_hit's test (lanes_triangles.h: packet_triangles_hit's arithmetic on scalars).
 * So it reports the same hits, bit for bit where both runtimes round alike.
 *
 * One loop iteration is Aila and Laine's "if-if" step: at most one node (its children's boxes,
 * a sorting network over the 8 entries, the pushes) and then at most one leaf packet, then a pop
 * when the current leaf is done. Build options:
 *   LANES_STACK     stack entries (volcl.bvh_wide.stack_need of the tree; at least 1)
 *   LANES_REGS      1: the stack as LANES_STACK scalar registers shifted on push and pop (no
 *                   private array, so no indexed private memory); 0: a private array
 *   LANES_MAXIT     0: loop until the stack is empty; > 0: exactly that many iterations, each a no-op
 *                   once the ray is done (a countable loop; LANES_UNROLL then unrolls it whole)
 *   LANES_UNROLL    1: #pragma unroll on that fixed loop
 *   LANES_SELECT    1: the node, packet and pop steps run every iteration, their effects chosen by
 *                   selects and their reads at a valid index (no branch, no load under a condition)
 *   LANES_HINT      0: plain __kernel (for Intel's implicit vectorizer); 1: vec_type_hint(float);
 *                   4: vec_type_hint(float4) (as VOLCL_KERNEL, which keeps Intel's runtime scalar)
 * Spheres and other analytic primitives are not tested (the study's scenes are triangles only).
 */
#include "renderer.h"     /* what lanes.h's helpers need, as the wavefront lanes stages include it */
/* every function of the lanes headers and of this file inlined (as the lanes stages build them) */
#pragma clang attribute push (__attribute__((always_inline)), apply_to = function)
#include "lanes.h"

/* lanes_triangles.h's triangle k is read at WF_TRI_AT(c, k) of a table: here the table is a leaf
 * packet's vertex rows (LeafPacket.v[c][k]) and k its lane. Its other routines are unused. */
#define VOLCL_WF_TINY 4
#define VOLCL_WF_TINY_ENDS 8
#define VOLCL_WF_SPHERES 0
#ifndef VOLCL_WF_CHAIN
#define VOLCL_WF_CHAIN 1
#endif
#define WF_TRI_AT(c, k) ((c) * VOLCL_LEAF_WIDTH + (k))
#define WF_SPH_AT(c, k) 0
#include "lanes_triangles.h"

#ifndef LANES_STACK
#define LANES_STACK 64
#endif
#ifndef LANES_REGS
#define LANES_REGS 0
#endif
#ifndef LANES_MAXIT
#define LANES_MAXIT 0
#endif
#ifndef LANES_UNROLL
#define LANES_UNROLL 0
#endif
#ifndef LANES_HINT
#define LANES_HINT 0
#endif
#ifndef LANES_SELECT
#define LANES_SELECT 0
#endif

#if LANES_HINT == 1
#define LANES_KERNEL __kernel __attribute__((vec_type_hint(float)))
#elif LANES_HINT == 4
#define LANES_KERNEL __kernel __attribute__((vec_type_hint(float4)))
#else
#define LANES_KERNEL __kernel
#endif

/* node_children_entry (bvh.h) for child slot c: the entry distance, INF where the ray misses the
 * box within [0, tmax] */
__attribute__((always_inline))
inline float lanes_child_entry(__global const float *b, int c, V3 o, V3 inv, int near_x, int near_y, int near_z,
                               float tmax) {
    float nx = (b[near_x + c] - o.x) * inv.x;
    float ny = (b[near_y + c] - o.y) * inv.y;
    float nz = (b[near_z + c] - o.z) * inv.z;
    float fx = (b[3 * VOLCL_BVH_WIDTH - near_x + c] - o.x) * inv.x;
    float fy = (b[5 * VOLCL_BVH_WIDTH - near_y + c] - o.y) * inv.y;
    float fz = (b[7 * VOLCL_BVH_WIDTH - near_z + c] - o.z) * inv.z;
    float enter = nx > ny ? nx : ny;
    enter = enter > nz ? enter : nz;
    enter = enter > 0.0f ? enter : 0.0f;
    float leave = fx < fy ? fx : fy;
    leave = leave < fz ? leave : fz;
    leave = (leave < tmax ? leave : tmax) * 1.0000004f;
    return enter <= leave ? enter : VOLCL_INF;
}

/* compare-exchange of the sorting network: afterwards (ta, ca, la) is pushed before (tb, cb, lb),
 * i.e. lies deeper: the farther entry, or of equal entries the lower slot */
#define LANES_CE(a, b)                                                                            \
    {                                                                                             \
        bool sw = (t##b > t##a) | ((t##b == t##a) & (l##b < l##a));                               \
        float tt = sw ? t##b : t##a;                                                              \
        t##b = sw ? t##a : t##b;                                                                  \
        t##a = tt;                                                                                \
        int cc = sw ? c##b : c##a;                                                                \
        c##b = sw ? c##a : c##b;                                                                  \
        c##a = cc;                                                                                \
        int ll = sw ? l##b : l##a;                                                                \
        l##b = sw ? l##a : l##b;                                                                  \
        l##a = ll;                                                                                \
    }

#if LANES_REGS
/* a stack of LANES_STACK registers, entry 0 on top: every push and pop shifts all of them */
#define STACK_DECL int sc[LANES_STACK]; float st[LANES_STACK]; int top = 0;   \
    _Pragma("unroll") for (int k = 0; k < LANES_STACK; ++k) { sc[k] = 0; st[k] = VOLCL_INF; }
#define STACK_PUSH(cond, ref, t)                                                                 \
    {                                                                                             \
        bool pc = (cond);                                                                         \
        _Pragma("unroll") for (int k = LANES_STACK - 1; k > 0; --k) {                            \
            sc[k] = pc ? sc[k - 1] : sc[k];                                                       \
            st[k] = pc ? st[k - 1] : st[k];                                                       \
        }                                                                                         \
        sc[0] = pc ? (ref) : sc[0];                                                               \
        st[0] = pc ? (t) : st[0];                                                                 \
        top += pc ? 1 : 0;                                                                        \
    }
#define STACK_POP(cond, ref, t)                                                                  \
    {                                                                                             \
        bool pc = (cond);                                                                         \
        ref = sc[0];                                                                              \
        t = st[0];                                                                                \
        _Pragma("unroll") for (int k = 0; k < LANES_STACK - 1; ++k) {                            \
            sc[k] = pc ? sc[k + 1] : sc[k];                                                       \
            st[k] = pc ? st[k + 1] : st[k];                                                       \
        }                                                                                         \
        top -= pc ? 1 : 0;                                                                        \
    }
#else
/* a private array; a push stores whether or not it is taken (the next one overwrites it) */
#define STACK_DECL int sc[LANES_STACK + 1]; float st[LANES_STACK + 1]; int top = 0;
#define STACK_PUSH(cond, ref, t)                                                                 \
    {                                                                                             \
        sc[top] = (ref);                                                                          \
        st[top] = (t);                                                                            \
        top += (cond) ? 1 : 0;                                                                    \
    }
#define STACK_POP(cond, ref, t)                                                                  \
    {                                                                                             \
        int at = top > 0 ? top - 1 : 0;                                                           \
        ref = sc[at];                                                                             \
        t = st[at];                                                                               \
        top -= (cond) ? 1 : 0;                                                                    \
    }
#endif

/* The closest hit of ray (o, d) in (0, INF) through the tree of `nodes` (root 0): whether there is
 * one, its distance and primitive code. */
__attribute__((always_inline))
inline bool lanes_walk_closest(__global const BvhWideNode *nodes, __global const LeafPacket *leaves, V3 o, V3 d,
                               float *t_hit, int *prim_hit) {
    LanesShear sh = lanes_shear(o, d);
    /* bvh_traverse.h's inverse direction: a zero component becomes a tiny one of its sign */
    float ix = 1.0f / (fabs(d.x) < 1e-30f ? copysign(1e-30f, d.x) : d.x);
    float iy = 1.0f / (fabs(d.y) < 1e-30f ? copysign(1e-30f, d.y) : d.y);
    float iz = 1.0f / (fabs(d.z) < 1e-30f ? copysign(1e-30f, d.z) : d.z);
    V3 inv = v3(ix, iy, iz);
    int near_x = (ix < 0.0f ? 3 : 0) * VOLCL_BVH_WIDTH;
    int near_y = (iy < 0.0f ? 4 : 1) * VOLCL_BVH_WIDTH;
    int near_z = (iz < 0.0f ? 5 : 2) * VOLCL_BVH_WIDTH;

    float best = VOLCL_INF;
    int bprim = 0;
    bool found = false;
    int cur = 0;            /* the node to visit in this iteration, -1 for none: the root first */
    int pk = 0, pk_end = 0; /* the leaf packets still to test */
    bool done = false;
    STACK_DECL

#if LANES_MAXIT > 0
#if LANES_UNROLL
#pragma unroll
#endif
    for (int it = 0; it < LANES_MAXIT; ++it) {
#else
    while (!done) {
#endif
        /* ---- a node: its entered children on the stack, nearest on top, and that one popped */
        bool act_n = cur >= 0;
        if (LANES_SELECT || act_n) {
            __global const BvhWideNode *n = &nodes[act_n ? cur : 0];
            __global const float *b = &n->bounds[0][0];
            float t0 = lanes_child_entry(b, 0, o, inv, near_x, near_y, near_z, best);
            float t1 = lanes_child_entry(b, 1, o, inv, near_x, near_y, near_z, best);
            float t2 = lanes_child_entry(b, 2, o, inv, near_x, near_y, near_z, best);
            float t3 = lanes_child_entry(b, 3, o, inv, near_x, near_y, near_z, best);
            float t4 = lanes_child_entry(b, 4, o, inv, near_x, near_y, near_z, best);
            float t5 = lanes_child_entry(b, 5, o, inv, near_x, near_y, near_z, best);
            float t6 = lanes_child_entry(b, 6, o, inv, near_x, near_y, near_z, best);
            float t7 = lanes_child_entry(b, 7, o, inv, near_x, near_y, near_z, best);
            int c0 = n->child[0], c1 = n->child[1], c2 = n->child[2], c3 = n->child[3];
            int c4 = n->child[4], c5 = n->child[5], c6 = n->child[6], c7 = n->child[7];
            int l0 = 0, l1 = 1, l2 = 2, l3 = 3, l4 = 4, l5 = 5, l6 = 6, l7 = 7;
            /* Batcher's odd-even merge sort of 8 (19 compare-exchanges): farthest first */
            LANES_CE(0, 1) LANES_CE(2, 3) LANES_CE(4, 5) LANES_CE(6, 7)
            LANES_CE(0, 2) LANES_CE(1, 3) LANES_CE(4, 6) LANES_CE(5, 7)
            LANES_CE(1, 2) LANES_CE(5, 6)
            LANES_CE(0, 4) LANES_CE(1, 5) LANES_CE(2, 6) LANES_CE(3, 7)
            LANES_CE(2, 4) LANES_CE(3, 5)
            LANES_CE(1, 2) LANES_CE(3, 4) LANES_CE(5, 6)
            /* the missed ones (INF) sort first and are not kept */
            STACK_PUSH(act_n & (t0 < VOLCL_INF), c0, t0) STACK_PUSH(act_n & (t1 < VOLCL_INF), c1, t1)
            STACK_PUSH(act_n & (t2 < VOLCL_INF), c2, t2) STACK_PUSH(act_n & (t3 < VOLCL_INF), c3, t3)
            STACK_PUSH(act_n & (t4 < VOLCL_INF), c4, t4) STACK_PUSH(act_n & (t5 < VOLCL_INF), c5, t5)
            STACK_PUSH(act_n & (t6 < VOLCL_INF), c6, t6) STACK_PUSH(act_n & (t7 < VOLCL_INF), c7, t7)
            /* the nearest child passed its box test against this hit: no cull */
            bool any_child = act_n & (t7 < VOLCL_INF);
            int r;
            float rt;
            STACK_POP(any_child, r, rt)
            (void)rt;
            int leaf = ~r;
            pk = act_n ? leaf >> 4 : pk;
            pk_end = act_n ? ((any_child & (r < 0)) ? pk + (leaf & 15) + 1 : pk) : pk_end;
            cur = (any_child & (r >= 0)) ? r : -1;
        }
        /* ---- a leaf packet: its lanes against the same tmax, the nearest (lower on ties) kept */
        bool act_p = pk < pk_end;
        if (LANES_SELECT || act_p) {
            int pkc = act_p ? pk : 0;
            __global const float *v = &leaves[pkc].v[0][0];
            float pt = VOLCL_INF;
            int pp = 0;
            bool any = false;
#pragma unroll
            for (int j = 0; j < VOLCL_LEAF_WIDTH; ++j) {
                float ts, det, e1, e2;
                bool ok = lanes_triangle_hit(v, j, &sh, best, &ts, &det, &e1, &e2);
                float inv_det = 1.0f / det;
                float tj = ok ? ts * inv_det : VOLCL_INF;
                bool take = tj < pt;
                pt = take ? tj : pt;
                pp = take ? leaves[pkc].prim[j] : pp;
                any = any | ok;
            }
            any = any & act_p;
            best = any ? pt : best;
            bprim = any ? pp : bprim;
            found = found | any;
            pk += act_p ? 1 : 0;
        }
        /* ---- nothing left in hand: the next entry from the stack, or the end */
        bool act_s = (cur < 0) & (pk >= pk_end) & !done;
        if (LANES_SELECT || act_s) {
            bool empty = top == 0;
            int r;
            float rt;
            STACK_POP(act_s & !empty, r, rt)
            bool live = act_s & !empty & !(rt > best * 1.0000004f);
            int leaf = ~r;
            cur = act_s ? ((live & (r >= 0)) ? r : -1) : cur;
            pk = act_s ? leaf >> 4 : pk;
            pk_end = act_s ? ((live & (r < 0)) ? pk + (leaf & 15) + 1 : pk) : pk_end;
            done = done | (act_s & empty);
        }
    }
    *t_hit = found ? best : VOLCL_INF;
    *prim_hit = found ? bprim : 0x7fffffff;
    return found;
}

#pragma clang attribute pop

/* restrict: the tree's reads are at per-ray indices, whose bounds LLVM cannot check against the
 * stores at run time ("cannot identify array bounds"). No bounds test: the host pads the rays to a multiple of the work-group size (a store under a
 * condition keeps LLVM's loop vectorizer off, lanes.h). */
LANES_KERNEL void trace_lanes_closest(__global const BvhWideNode *restrict nodes,
                                      __global const LeafPacket *restrict leaves,
                                      __global const float *restrict origins, __global const float *restrict dirs,
                                      __global float *restrict t_out, __global int *restrict prim_out) {
    int i = get_global_id(0);
    V3 o = v3(origins[3 * i], origins[3 * i + 1], origins[3 * i + 2]);
    V3 d = v3(dirs[3 * i], dirs[3 * i + 1], dirs[3 * i + 2]);
    float t;
    int prim;
    lanes_walk_closest(nodes, leaves, o, d, &t, &prim);
    t_out[i] = t;
    prim_out[i] = prim;
}
