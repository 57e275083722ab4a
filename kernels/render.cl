/* Entry point: one launch renders one sample (or one slot of samples) for a range of pixels.
 *
 * Work item i handles pixel first_pixel + (i % pixel_count) and sample index
 * sample_base + i / pixel_count, writing its own accumulator slot, so tiny images still fill the
 * device and the result never depends on how samples were grouped into launches. Samples that come
 * out NaN, infinite or negative are counted and left out of the sums instead of poisoning them, and
 * medium segments whose tracking hit its step bound are counted in `cutoffs` (see media.h).
 */
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
#include "equiangular.h"
#include "camera.h"
#include "integrator.h"

__kernel void render_pass(__global const BvhWideNode *nodes, __global const LeafPacket *leaves,
                          __global const Triangle *triangles, __global const TriangleNormals *normals,
                          __global const Sphere *spheres, __global const ShapeInfo *shapes,
                          __global const Bsdf *bsdfs, __global const Light *lights,
                          __global const float *light_tri_cdf, __global const int *light_tris,
                          __global const Medium *media, __global const GridVolume *grids,
                          __global const float *grid_data, __global const RenderParams *params,
                          __global const float *filter_table,
                          __global float4 *sums, __global float4 *sums_sq, __global uint *invalid,
                          __global uint *cutoffs,
                          uint sample_base, int first_pixel, int pixel_count, int slots) {
    int gid = get_global_id(0);
    if (gid >= pixel_count * slots) return;
    int slot = gid / pixel_count;
    int pixel = first_pixel + gid % pixel_count;
    SceneData sc = {nodes, leaves, triangles, normals, spheres, shapes, bsdfs, lights,
                    light_tri_cdf, light_tris, media, grids, grid_data, params};
    int width = params->width;
    Rng rng = rng_init(params->seed, (uint)pixel, sample_base + (uint)slot);
    float3 o, d;
    float t_max;
    camera_ray(&sc, filter_table, pixel % width, pixel / width, rng_next_float2(&rng), &o, &d, &t_max);
    uint cut = 0u;
    float3 L = integrator_radiance(&sc, &rng, o, d, t_max, &cut);
    int out = slot * (params->width * params->height) + pixel;
    if (cut) cutoffs[out] += cut;
    if (isfinite(L.x) && isfinite(L.y) && isfinite(L.z) && L.x >= 0.0f && L.y >= 0.0f && L.z >= 0.0f) {
        sums[out] += (float4)(L, 1.0f);
        sums_sq[out] += (float4)(L * L, 0.0f);
    } else {
        invalid[out] += 1u;
    }
}
