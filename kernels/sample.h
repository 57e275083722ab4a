/* One sample of a pixel, its two ends: the random stream and camera ray it starts from, and adding
 * the radiance it brings back to the pixel's accumulators. The megakernel (render.cl) and the
 * wavefront stages (wavefront.cl) both start and finish samples here. */
#ifndef VOLCL_SAMPLE_H
#define VOLCL_SAMPLE_H

/* The random stream of sample `sample` of pixel (px, py) (index `pixel` in the image), and its camera
 * ray o + t d, t < t_max. */
VOLCL_STEP_INLINE
inline void sample_camera_ray(const SceneData *sc, __global const float *filter_table, int px, int py, int pixel,
                              uint sample, Rng *rng, float3 *o, float3 *d, float *t_max) {
    *rng = rng_init(sc->params->seed, (uint)pixel, sample);
    float2 u_pixel = rng_next_float2(rng);
    /* drawn only where a lens needs it, so other cameras keep their random sequences */
#if VOLCL_HAS_THINLENS
    float2 u_lens = rng_next_float2(rng);
#else
    float2 u_lens = (float2)(0.0f);
#endif
    camera_ray(sc, filter_table, px, py, u_pixel, u_lens, o, d, t_max);
}

/* Add a sample's radiance L (and its count of tracking cut-offs) to accumulator entry `out`. */
inline void sample_add(float3 L, uint cut, int out, __global float4 *sums, __global float4 *sums_sq,
                       __global uint *invalid, __global uint *cutoffs) {
    if (cut) cutoffs[out] += cut;
    if (isfinite(L.x) && isfinite(L.y) && isfinite(L.z) && L.x >= 0.0f && L.y >= 0.0f && L.z >= 0.0f) {
        sums[out] += (float4)(L, 1.0f);
        sums_sq[out] += (float4)(L * L, 0.0f);
    } else {
        invalid[out] += 1u;
    }
}

#endif
