/* Entry point: one launch renders one sample (or one slot of samples, or `passes` rounds of the
 * slots) for a range of pixels of a tile.
 *
 * A tile is the rectangle of the image tile_w pixels wide whose top left pixel is (tile_x, tile_y),
 * its tile_pixels pixels numbered row by row; the whole image is the tile (0, 0, width, height).
 * The accumulators hold `slots` rows of tile_pixels entries. Work item i handles tile pixel
 * first + (i % count) and sample index sample_base + i / count (and, with passes > 1, the same slot
 * of the next rounds: + slots, + 2 slots, ...), writing its own accumulator slot,
 * so tiny images still fill the device and the result never depends on how samples were grouped
 * into launches. Random streams and camera rays follow the pixel's place in the image, not in the
 * tile, so a pixel's samples are the same whatever tile renders it. Samples that come out NaN,
 * infinite or negative are counted and left out of the sums instead of poisoning them, and medium
 * segments whose tracking hit its step bound are counted in `cutoffs` (see media.h).
 */
#include "renderer.h"

/* One sample of pixel (px, py) (index `pixel` in the image), added to accumulator entry `out`. */
VOLCL_STEP_INLINE
inline void render_sample(const SceneData *sc, __global const float *filter_table, int px, int py, int pixel,
                          uint sample, int out, __global float4 *sums, __global float4 *sums_sq,
                          __global uint *invalid, __global uint *cutoffs) {
    Rng rng;
    float3 o, d;
    float t_max;
    sample_camera_ray(sc, filter_table, px, py, pixel, sample, &rng, &o, &d, &t_max);
    uint cut = 0u;
    float3 L;
#if VOLCL_HAS_DIRECT
    if (sc->params->integrator == INTEGRATOR_DIRECT) L = direct_radiance(sc, &rng, o, d, t_max);
    else
#endif
    L = integrator_radiance(sc, &rng, o, d, t_max, &cut);
    sample_add(L, cut, out, sums, sums_sq, invalid, cutoffs);
}

VOLCL_KERNEL void render_pass(VOLCL_SCENE_ARGS,
                          __global float4 *sums, __global float4 *sums_sq, __global uint *invalid,
                          __global uint *cutoffs,
                          uint sample_base, int tile_x, int tile_y, int tile_w, int tile_pixels,
                          int first, int count, int slots, int passes) {
    int gid = (int)get_global_id(0);     /* launches stay below 2^31 work items (renderer.py) */
    if (gid >= count * slots) return;
    int slot = gid / count;
    int tp = first + gid % count;    /* the pixel's index in the tile */
    int px = tile_x + tp % tile_w, py = tile_y + tp / tile_w;
    int pixel = py * params->width + px;
    SceneData sc = VOLCL_SCENE_DATA;
    int out = slot * tile_pixels + tp;
    /* pass j adds sample sample_base + j * slots + slot: the additions to this slot come in the
     * order separate launches would make them, so the sums have the same bits */
    for (int j = 0; j < passes; ++j)
        render_sample(&sc, filter_table, px, py, pixel, sample_base + (uint)(j * slots + slot), out,
                      sums, sums_sq, invalid, cutoffs);
}
