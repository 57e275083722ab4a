/* Test-only kernels: texture lookups (textures.h) at host-given uvs, and texture coordinates
 * (texcoords.h) where host-given rays hit a packed scene. */
#include "types.h"
#include "common.h"
#include "rng.h"
#include "sampling.h"
#include "scene.h"
#include "bvh.h"
#include "surface.h"
#include "bsdf.h"

/* Texture `index` at uv[i]: as a colour (eval3), as a float (eval1) and its gradient (grad1). */
VOLCL_KERNEL void texture_lookups(__global const Texture *textures, __global const float *texels,
                              __global const float *uvs, __global float *colour, __global float *value,
                              __global float *grad, int index) {
    int i = get_global_id(0);
    SceneData sc;
    sc.textures = textures;
    sc.texels = texels;
    float2 uv = vload2(i, uvs);
    vstore3(texture_eval3(&sc, index, (float3)(-1.0f), uv), i, colour);
    value[i] = texture_eval1(&sc, index, -1.0f, uv);
    vstore2(texture_grad1(&sc, index, uv), i, grad);
}

/* uv, dp/du and dp/dv where ray i first hits the scene; hit[i] the shape index, or -1. */
VOLCL_KERNEL void surface_uvs(__global const BvhWideNode *nodes, __global const LeafPacket *leaves,
                          __global const Triangle *triangles, __global const TriangleNormals *normals,
                          __global const Sphere *spheres, __global const Cylinder *cylinders,
                          __global const ShapeInfo *shapes, __global const TriangleUv *tri_uvs,
                          __global const UvMap *uv_maps, __global const float *origins,
                          __global const float *dirs, __global float *uv_out, __global float *dpdu_out,
                          __global float *dpdv_out, __global int *hit_out) {
    int i = get_global_id(0);
    SceneData sc;
    sc.nodes = nodes;
    sc.leaves = leaves;
    sc.triangles = triangles;
    sc.normals = normals;
    sc.spheres = spheres;
    sc.cylinders = cylinders;
    sc.shapes = shapes;
    sc.tri_uvs = tri_uvs;
    sc.uv_maps = uv_maps;
    float3 o = vload3(i, origins), d = vload3(i, dirs);
    Hit h;
    hit_out[i] = -1;
    vstore2((float2)(0.0f), i, uv_out);
    vstore3((float3)(0.0f), i, dpdu_out);
    vstore3((float3)(0.0f), i, dpdv_out);
    if (!bvh_trace(&sc, o, d, INFINITY, TRACE_CLOSEST, &h)) return;
    SurfacePoint s = surface_point(&sc, &h, o, d);
    surface_texcoords(&sc, &h, &s);
    hit_out[i] = s.shape;
    vstore2(s.uv, i, uv_out);
    vstore3(s.dpdu, i, dpdu_out);
    vstore3(s.dpdv, i, dpdv_out);
}
