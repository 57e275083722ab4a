/* Test-only kernel: closest-hit, any-hit and shadow BVH queries for host-supplied rays. */
#include "types.h"
#include "common.h"
#include "rng.h"
#include "sampling.h"
#include "scene.h"
#include "bvh.h"

VOLCL_KERNEL void trace_rays(__global const BvhWideNode *nodes, __global const LeafPacket *leaves,
                         __global const Triangle *triangles, __global const Sphere *spheres,
                         __global const float *origins, __global const float *dirs,
                         __global float *t_out, __global int *prim_out, __global int *occluded_out,
                         __global int *shadow_out) {
    int i = get_global_id(0);
    SceneData sc;
    sc.nodes = nodes;
    sc.leaves = leaves;
    sc.triangles = triangles;
    sc.spheres = spheres;
    float3 o = vload3(i, origins), d = vload3(i, dirs);
    Hit h;
    bool hit = bvh_trace(&sc, o, d, INFINITY, TRACE_CLOSEST, &h);
    t_out[i] = hit ? h.t : INFINITY;
    prim_out[i] = hit ? h.prim : 0x7fffffff;
    Hit h2;
    occluded_out[i] = bvh_trace(&sc, o, d, INFINITY, TRACE_ANY, &h2) ? 1 : 0;
    Hit h3;
    shadow_out[i] = bvh_trace(&sc, o, d, INFINITY, TRACE_SHADOW, &h3) ? h3.prim : 0x7fffffff;
}
