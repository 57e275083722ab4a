/* Test-only kernels for grid volumes: lookups at given points, and the tracking routines the
 * integrator uses (free flights by delta tracking, shadow-ray transmittance by ratio tracking) on
 * given rays, one estimate per work item. The scene buffers come in Renderer.ARG_ORDER. */
#include "types.h"
#include "common.h"
#include "rng.h"
#include "sampling.h"
#include "scene.h"
#include "bvh.h"
#include "surface.h"
#include "bsdf.h"
#include "phase.h"
#include "grid.h"
#include "media.h"
#include "lights.h"
#include "integrator.h"

#define SCENE_ARGS                                                                                      \
    __global const BvhWideNode *nodes, __global const LeafPacket *leaves, __global const Triangle *triangles,   \
    __global const TriangleNormals *normals, __global const Sphere *spheres,                            \
    __global const Cylinder *cylinders, __global const ShapeInfo *shapes, __global const Bsdf *bsdfs, __global const Light *lights,         \
    __global const float *light_tri_cdf, __global const int *light_tris, __global const float *env_data,  \
    __global const Medium *media,                                                                       \
    __global const GridVolume *grids, __global const float *grid_data,                                  \
    __global const RenderParams *params, __global const float *filter_table,                            \
    __global const TriangleUv *tri_uvs, __global const UvMap *uv_maps, __global const Texture *textures, \
    __global const float *texels, __global const float *bsdf_tables,                                    \
    __global const PhaseLobe *phase_lobes, __global const float *phase_tables,                          \
    __global const Instance *instances
#define SCENE_INIT {nodes, leaves, triangles, normals, spheres, cylinders, shapes, bsdfs, lights, light_tri_cdf, \
                    light_tris, env_data, media, grids, grid_data, params, tri_uvs, uv_maps, textures, texels, \
                    bsdf_tables, phase_lobes, phase_tables, instances}

/* grid_lookup of descriptor `grid` at local points (3 floats each). */
VOLCL_KERNEL void lookups(__global const GridVolume *grids, __global const float *grid_data,
                      __global const float *points, __global float *out, int grid) {
    int i = get_global_id(0);
    vstore3(grid_lookup(grid_data, &grids[grid], vload3(i, points)), i, out);
}

/* Work item i: ray i % nrays (o, d, t_max as 7 floats), estimate number i / nrays. */
VOLCL_KERNEL void shadow_rays(SCENE_ARGS, __global const float *rays, __global float *out, __global uint *cutoffs,
                          int nrays, int medium, uint seed) {
    int i = get_global_id(0);
    SceneData sc = SCENE_INIT;
    __global const float *r = rays + 7 * (i % nrays);
    Rng rng = rng_init(seed, (uint)(i % nrays), (uint)(i / nrays));
    uint cut = 0u;
    float3 tr = shadow_transmittance(&sc, 0, vload3(0, r), vload3(1, r), r[6], medium, &rng, &cut);
    vstore3(tr, i, out);
    cutoffs[i] = cut;
}

/* Free flights with path weight (1, 1, 1): out = t, scattered, weight.xyz per work item. */
VOLCL_KERNEL void free_flights(SCENE_ARGS, __global const float *rays, __global float *out, __global uint *cutoffs,
                           int nrays, int medium, uint seed) {
    int i = get_global_id(0);
    SceneData sc = SCENE_INIT;
    __global const float *r = rays + 7 * (i % nrays);
    Rng rng = rng_init(seed, (uint)(i % nrays), (uint)(i / nrays));
    uint cut = 0u;
    EmissionMis em;
    em.on = false;
    MediumSample ms = medium_sample(&sc, &media[medium], vload3(0, r), vload3(1, r), r[6], (float3)(1.0f),
                                    &rng, &cut, &em);
    out[5 * i] = ms.t;
    out[5 * i + 1] = ms.scattered ? 1.0f : 0.0f;
    out[5 * i + 2] = ms.weight.x;
    out[5 * i + 3] = ms.weight.y;
    out[5 * i + 4] = ms.weight.z;
    cutoffs[i] = cut;
}

/* Emission NEE's point sampler (emission_nee.h): out = y.xyz, the density it was drawn with, the
 * density emission_point_pdf gives back at y; ids = (medium, cell), or (-1, -1) for a refused draw. */
VOLCL_KERNEL void emission_points(SCENE_ARGS, __global float *out, __global int *ids, uint seed) {
    int i = get_global_id(0);
    SceneData sc = SCENE_INIT;
    Rng rng = rng_init(seed, (uint)i, 0u);
    float u_medium = rng_next_float(&rng), u_cell = rng_next_float(&rng);
    float3 u = (float3)(rng_next_float(&rng), rng_next_float(&rng), rng_next_float(&rng));
    EmissionPoint ep;
    bool ok = emission_sample_point(&sc, sc.params->emission_table, u_medium, u_cell, u, &ep);
    out[5 * i] = ok ? ep.y.x : 0.0f;
    out[5 * i + 1] = ok ? ep.y.y : 0.0f;
    out[5 * i + 2] = ok ? ep.y.z : 0.0f;
    out[5 * i + 3] = ok ? ep.pdf : 0.0f;
    out[5 * i + 4] = ok ? emission_point_pdf(&sc, &sc.media[ep.medium], ep.y) : 0.0f;
    ids[2 * i] = ok ? ep.medium : -1;
    ids[2 * i + 1] = ok ? ep.cell : -1;
}
