/* Test-only kernel: closest-hit, any-hit and shadow queries over a scene with instances (a
 * two-level BVH), with the world-space point and geometric normal of each closest hit. */
#include "types.h"
#include "common.h"
#include "rng.h"
#include "sampling.h"
#include "scene.h"
#include "bvh.h"
#include "surface.h"

VOLCL_KERNEL void trace_instanced(__global const BvhWideNode *nodes, __global const LeafPacket *leaves,
                                  __global const Triangle *triangles, __global const TriangleNormals *normals,
                                  __global const Sphere *spheres, __global const Cylinder *cylinders,
                                  __global const Instance *instances,
                                  __global const float *origins, __global const float *dirs,
                                  __global float *t_out, __global int *prim_out, __global int *inst_out,
                                  __global float *p_out, __global float *n_out, __global int *occluded_out,
                                  __global int *shadow_prim_out, __global int *shadow_inst_out) {
    int i = get_global_id(0);
    SceneData sc;
    sc.nodes = nodes;
    sc.leaves = leaves;
    sc.triangles = triangles;
    sc.normals = normals;
    sc.spheres = spheres;
    sc.cylinders = cylinders;
    sc.instances = instances;
    float3 o = vload3(i, origins), d = vload3(i, dirs);
    Hit h;
    bool hit = bvh_trace(&sc, o, d, INFINITY, TRACE_CLOSEST, &h);
    t_out[i] = hit ? h.t : INFINITY;
    prim_out[i] = hit ? h.prim : 0x7fffffff;
    inst_out[i] = hit ? h.inst : -2;
    float3 p = (float3)(0.0f), n = (float3)(0.0f);
    if (hit) {
        SurfacePoint s = surface_point(&sc, &h, o, d);
        p = s.p;
        n = s.ng;
    }
    vstore3(p, i, p_out);
    vstore3(n, i, n_out);
    Hit h2;
    occluded_out[i] = bvh_trace(&sc, o, d, INFINITY, TRACE_ANY, &h2) ? 1 : 0;
    Hit h3;
    bool shadow = bvh_trace(&sc, o, d, INFINITY, TRACE_SHADOW, &h3);
    shadow_prim_out[i] = shadow ? h3.prim : 0x7fffffff;
    shadow_inst_out[i] = shadow ? h3.inst : -2;
}
