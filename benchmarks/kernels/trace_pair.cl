/* Benchmark-only kernels: is the shipped closest-hit walk (kernels/bvh_traverse.h) bound by the
 * latency of its dependent loads and branches, so that one work-item walking two rays at once,
 * a step of each in turn, gets more rays through per second? (benchmarks/traversal_pair.py)
 *
 * The walk is bvh_traverse.h's TRACE_CLOSEST visit for visit, cut into steps: one step visits one
 * node (its children's boxes, the entered ones pushed in order of entry distance, the nearest
 * taken next) or tests one leaf packet, and pops the stack (culling entries beyond the hit) when
 * the current leaf or node leads nowhere. Its state lives in a struct, so two walks can take turns
 * in one loop; the box test, the packet test and the stack order are bvh.h's own functions and
 * rules (node_visit, stack_next), so the hits are the shipped kernel's, bit for bit. Triangles only: analytic lanes are not
 * tested (the study's scenes are meshes).
 *   trace_step_closest   one ray per work-item through the step walk (what the cut alone costs)
 *   trace_pair_closest   rays 2i and 2i + 1 in work-item i, their steps alternating
 */
#include "types.h"
#include "common.h"
#include "scene.h"
#include "bvh.h"

#define WALK_DONE VOLCL_NO_CHILD     /* the walk has finished */

typedef struct {
    Shear sh;
    BoxRay br;
    Hit hit;
    int ref;                    /* the node (>= 0) or leaf (< 0) to visit next, or WALK_DONE */
    int packet, packet_end;     /* the current leaf's packets still to test */
    int top;
    bool found;
    int stack[VOLCL_BVH_STACK];
    float stack_t[VOLCL_BVH_STACK];
} Walk;

__attribute__((always_inline))
inline void walk_begin(Walk *w, float3 o, float3 d, float tmax) {
    w->sh = shear_make(o, d);
    w->br = box_ray_make(o, d);
    w->hit.t = tmax;
    w->hit.prim = 0;
    w->hit.b1 = w->hit.b2 = 0.0f;
    w->ref = 0;
    w->packet = w->packet_end = 0;
    w->top = 0;
    w->found = false;
}

/* one node visit or one packet test (entering a leaf tests its first packet) */
__attribute__((always_inline))
inline void walk_step(Walk *w, const SceneData *sc) {
    if (w->packet == w->packet_end) {
        int ref = w->ref;
        if (ref < 0) {
            int leaf = ~ref;
            w->packet = leaf >> 4;
            w->packet_end = w->packet + (leaf & 15) + 1;
        } else {
            int next = node_visit(&sc->nodes[ref], &w->br, w->hit.t, TRACE_CLOSEST, w->stack, w->stack_t, &w->top);
            w->ref = next != VOLCL_NO_CHILD ? next : stack_next(w->stack, w->stack_t, &w->top, w->hit.t);
            return;
        }
    }
    if (packet_triangles_intersect(&sc->leaves[w->packet], &w->sh, w->hit.t, TRACE_CLOSEST, &w->hit))
        w->found = true;
    if (++w->packet == w->packet_end) w->ref = stack_next(w->stack, w->stack_t, &w->top, w->hit.t);
}

inline SceneData pair_scene(__global const BvhWideNode *nodes, __global const LeafPacket *leaves) {
    SceneData sc;
    sc.nodes = nodes;
    sc.leaves = leaves;
    return sc;
}

__attribute__((always_inline))
inline void walk_store(const Walk *w, int i, __global float *t_out, __global int *prim_out) {
    t_out[i] = w->found ? w->hit.t : INFINITY;
    prim_out[i] = w->found ? w->hit.prim : 0x7fffffff;
}

VOLCL_KERNEL void trace_step_closest(__global const BvhWideNode *nodes, __global const LeafPacket *leaves,
                                     __global const Triangle *triangles, __global const Sphere *spheres,
                                     __global const float *origins, __global const float *dirs,
                                     __global float *t_out, __global int *prim_out, int n) {
    int i = get_global_id(0);
    if (i >= n) return;
    SceneData sc = pair_scene(nodes, leaves);
    Walk w;
    walk_begin(&w, vload3(i, origins), vload3(i, dirs), INFINITY);
    while (w.ref != WALK_DONE) walk_step(&w, &sc);
    walk_store(&w, i, t_out, prim_out);
}

VOLCL_KERNEL void trace_pair_closest(__global const BvhWideNode *nodes, __global const LeafPacket *leaves,
                                     __global const Triangle *triangles, __global const Sphere *spheres,
                                     __global const float *origins, __global const float *dirs,
                                     __global float *t_out, __global int *prim_out, int n) {
    int i = 2 * (int)get_global_id(0);
    if (i >= n) return;
    int k = min(i + 1, n - 1);
    SceneData sc = pair_scene(nodes, leaves);
    Walk a, b;
    walk_begin(&a, vload3(i, origins), vload3(i, dirs), INFINITY);
    walk_begin(&b, vload3(k, origins), vload3(k, dirs), INFINITY);
    while ((a.ref != WALK_DONE) | (b.ref != WALK_DONE)) {
        if (a.ref != WALK_DONE) walk_step(&a, &sc);
        if (b.ref != WALK_DONE) walk_step(&b, &sc);
    }
    walk_store(&a, i, t_out, prim_out);
    walk_store(&b, k, t_out, prim_out);
}
