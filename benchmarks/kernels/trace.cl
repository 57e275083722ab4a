/* Benchmark-only kernels: one closest-hit or any-hit query per host-supplied ray, through the same
 * bvh_trace the renderer uses (benchmarks/traversal.py). */
#include "types.h"
#include "common.h"
#include "scene.h"
#include "bvh.h"

inline SceneData trace_scene(__global const BvhWideNode *nodes, __global const LeafPacket *leaves,
                             __global const Triangle *triangles, __global const Sphere *spheres) {
    SceneData sc;
    sc.nodes = nodes;
    sc.leaves = leaves;
    sc.triangles = triangles;
    sc.normals = 0;
    sc.spheres = spheres;
    sc.shapes = 0;
    sc.bsdfs = 0;
    sc.lights = 0;
    sc.light_tri_cdf = 0;
    sc.light_tris = 0;
    sc.media = 0;
    sc.grids = 0;
    sc.grid_data = 0;
    sc.params = 0;
    return sc;
}

VOLCL_KERNEL void trace_closest(__global const BvhWideNode *nodes, __global const LeafPacket *leaves,
                            __global const Triangle *triangles, __global const Sphere *spheres,
                            __global const float *origins, __global const float *dirs,
                            __global float *t_out, __global int *prim_out, int n) {
    int i = get_global_id(0);
    if (i >= n) return;
    SceneData sc = trace_scene(nodes, leaves, triangles, spheres);
    Hit h;
    bool hit = bvh_trace(&sc, vload3(i, origins), vload3(i, dirs), INFINITY, TRACE_CLOSEST, &h);
    t_out[i] = hit ? h.t : INFINITY;
    prim_out[i] = hit ? h.prim : 0x7fffffff;
}

VOLCL_KERNEL void trace_any(__global const BvhWideNode *nodes, __global const LeafPacket *leaves,
                        __global const Triangle *triangles, __global const Sphere *spheres,
                        __global const float *origins, __global const float *dirs,
                        __global const float *t_max, __global int *occluded, int n) {
    int i = get_global_id(0);
    if (i >= n) return;
    SceneData sc = trace_scene(nodes, leaves, triangles, spheres);
    Hit h;
    occluded[i] = bvh_trace(&sc, vload3(i, origins), vload3(i, dirs), t_max[i], TRACE_ANY, &h) ? 1 : 0;
}
