/* Warps from the unit square, each paired with its pdf (Nori's habit: a routine and its density are
 * never apart). Directions are unit vectors; pdfs are per unit solid angle unless the name says area. */
#ifndef VOLCL_SAMPLING_H
#define VOLCL_SAMPLING_H

#include "trig.h"

/* Concentric map (Shirley and Chiu): keeps strata compact, unlike the polar map. */
inline float2 sample_concentric_disk(float2 u) {
    float2 o = 2.0f * u - 1.0f;
    if (o.x == 0.0f && o.y == 0.0f) return (float2)(0.0f, 0.0f);
    /* the angle is a in [-pi/4, pi/4] in the first case and pi/2 - a in the second, whose cosine and
     * sine are a's sine and cosine */
    if (fabs(o.x) > fabs(o.y)) {
        float a = (VOLCL_PI / 4.0f) * (o.y / o.x);
        return o.x * (float2)(cos_small(a), sin_small(a));
    }
    float a = (VOLCL_PI / 4.0f) * (o.x / o.y);
    return o.y * (float2)(sin_small(a), cos_small(a));
}

inline float3 sample_cosine_hemisphere(float2 u) {
    float2 d = sample_concentric_disk(u);
    float z = sqrt(fmax(0.0f, 1.0f - d.x * d.x - d.y * d.y));
    return (float3)(d.x, d.y, z);
}

inline float sample_cosine_hemisphere_pdf(float3 v) { return v.z > 0.0f ? v.z * VOLCL_INV_PI : 0.0f; }

inline float3 sample_uniform_sphere(float2 u) {
    float z = 1.0f - 2.0f * u.x;
    float r = sqrt(fmax(0.0f, 1.0f - z * z));
    float c, s = sincos_turn(u.y, &c);
    return (float3)(r * c, r * s, z);
}

inline float sample_uniform_sphere_pdf(void) { return VOLCL_INV_4PI; }

/* Uniform point on a triangle as barycentrics (b1, b2); the square-root map. */
inline float2 sample_uniform_triangle(float2 u) {
    float su = sqrt(u.x);
    return (float2)(1.0f - su, u.y * su);
}

/* Direction in the cone of half-angle acos(cos_max) around +z, uniform in solid angle. */
inline float3 sample_uniform_cone(float2 u, float cos_max) {
    float cos_t = 1.0f - u.x * (1.0f - cos_max);
    float sin_t = sqrt(fmax(0.0f, 1.0f - cos_t * cos_t));
    float c, s = sincos_turn(u.y, &c);
    return (float3)(sin_t * c, sin_t * s, cos_t);
}

inline float sample_uniform_cone_pdf(float cos_max) { return 1.0f / (2.0f * VOLCL_PI * (1.0f - cos_max)); }

/* Index of the first cdf entry above u*total in cdf[0..n): a binary search over an inclusive prefix
 * sum, which the host normalizes to end at exactly 1. */
inline int sample_discrete_cdf(const __global float *cdf, int n, float u) {
    int lo = 0, hi = n - 1;
    while (lo < hi) {
        int mid = (lo + hi) >> 1;
        if (cdf[mid] > u) hi = mid; else lo = mid + 1;
    }
    return lo;
}

/* The same index, searched from guide[(int)(u n)] (a start near it, volcl.guides.guide): the walk
 * back and then forward ends at the first entry above u from any start, so the index is the binary
 * search's, in a step or two on average. */
__attribute__((always_inline))
inline int sample_discrete_cdf_guided(const __global float *cdf, const __global float *guide, int n, float u) {
    int k = (int)guide[min((int)(u * (float)n), n - 1)];   /* u in [0, 1] */
    while (k > 0 && cdf[k - 1] > u) --k;
    while (k < n - 1 && cdf[k] <= u) ++k;
    return k;
}

/* Offset from a pixel centre distributed like the reconstruction filter along one axis. The host
 * tabulates the filter's normalized CDF at `size` equally spaced x in [-radius, radius]; inverting
 * it interval by interval samples each interval's exact share of the filter (sampling the filter,
 * instead of splatting weighted samples, converges to the same normalized filtered image). Within an
 * interval (radius / 2048 wide) the density is flat, far below any visible or measurable error.
 * After the CDF come size - 1 guide entries: entry i is the first interval whose CDF passes
 * i / (size - 1), so finding u's interval takes a step or two instead of a binary search (which
 * cost a fifth of a Cornell-box sample on PoCL). */
VOLCL_STEP_INLINE
inline float sample_filter_offset(const __global float *table, int size, float radius, float u) {
    int n = size - 1;
    /* interval k ends at the first CDF entry past table[0] = 0 that lies above u */
    int k = sample_discrete_cdf_guided(table + 1, table + size, n, u);
    float lo = table[k], hi = table[k + 1];
    float f = hi > lo ? clamp((u - lo) / (hi - lo), 0.0f, 1.0f) : 0.5f;
    return radius * (2.0f * ((float)k + f) / (float)n - 1.0f);
}

/* The table's CDF at offset x, linear within an interval as sample_filter_offset inverts it. */
inline float filter_cdf_at(const __global float *table, int size, float radius, float x) {
    int n = size - 1;
    float t = clamp((x / radius + 1.0f) * 0.5f * (float)n, 0.0f, (float)n);
    int k = min((int)t, n - 1);
    return mix(table[k], table[k + 1], t - (float)k);
}

/* An offset distributed like the filter cut to [lo, hi] and renormalized: Mitsuba's film (without
 * sample_border) and Nori's draw no samples outside the image, so a pixel within the filter's
 * radius of the edge averages only the part of its filter that lies inside. Mapping u into that
 * part's share of the CDF samples the table's own distribution restricted to it. */
VOLCL_STEP_INLINE
inline float sample_filter_offset_within(const __global float *table, int size, float radius, float u,
                                         float lo, float hi) {
    if (lo <= -radius && hi >= radius) return sample_filter_offset(table, size, radius, u);
    float c0 = lo > -radius ? filter_cdf_at(table, size, radius, lo) : 0.0f;
    float c1 = hi < radius ? filter_cdf_at(table, size, radius, hi) : 1.0f;
    return clamp(sample_filter_offset(table, size, radius, mix(c0, c1, u)), lo, hi);
}

#endif
