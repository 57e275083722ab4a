/* Homogeneous media: free-flight distance sampling and analytic transmittance.
 *
 * Chromatic sigma_t uses one-sample spectral MIS (Miller et al. 2019): a channel is chosen with
 * probability proportional to the path throughput, a distance is sampled from that channel's
 * exponential, and the estimate is divided by the mixture pdf over all channels. Exponentials are
 * taken relative to the smallest extinction among the channels that can be chosen, so the ratio
 * Tr / pdf never becomes 0 / 0 when every exp(-tau) underflows in a thick medium.
 */
#ifndef VOLCL_MEDIA_H
#define VOLCL_MEDIA_H

/* exp(-sigma * t) that is 1 for sigma = 0 and 0 for t = INF, never NaN from 0 * INF. */
inline float3 transmittance_exp(float3 sigma, float t) {
    float3 tau = sigma * t;
    tau = select(tau, (float3)(0.0f), sigma == (float3)(0.0f));
    return exp(-tau);
}

typedef struct {
    float t;            /* distance of the scattering event, or the segment end when none */
    bool scattered;
    float3 weight;      /* factor for the path throughput */
    float3 emission;    /* emitted radiance estimate collected on the segment (emissive media) */
} MediumSample;

inline MediumSample medium_sample_distance(__global const Medium *m, float t_max, float3 beta,
                                           float u_channel, float u_dist) {
    MediumSample ms;
    float3 sigma_t = vload_f3(m->sigma_t), albedo = vload_f3(m->albedo);
    ms.emission = (float3)(0.0f);
#if VOLCL_HAS_CHROMATIC_MEDIA
    float3 p = fmax(beta, 0.0f);
    float total = p.x + p.y + p.z;
    p = total > 0.0f ? p / total : (float3)(1.0f / 3.0f);
    float sigma_c = u_channel < p.x ? sigma_t.x : (u_channel < p.x + p.y ? sigma_t.y : sigma_t.z);
    /* reference rate: the smallest extinction among channels with p > 0 */
    float sigma_ref = INFINITY;
    if (p.x > 0.0f) sigma_ref = sigma_t.x;
    if (p.y > 0.0f) sigma_ref = fmin(sigma_ref, sigma_t.y);
    if (p.z > 0.0f) sigma_ref = fmin(sigma_ref, sigma_t.z);
    /* u_dist < 1, so log1p(-u) is finite; sigma = 0 means the segment is never cut */
    float t = sigma_c > 0.0f ? -log1p(-u_dist) / sigma_c : INFINITY;
    ms.scattered = t < t_max;
    ms.t = ms.scattered ? t : t_max;
    float3 rel = transmittance_exp(sigma_t - sigma_ref, ms.t);
    if (ms.scattered) {
        float pdf = dot(p, sigma_t * rel);
        ms.weight = albedo * sigma_t * rel / pdf;
#if VOLCL_HAS_EMISSIVE_MEDIA
        ms.emission = vload_f3(m->emission) * rel / pdf;
#endif
    } else {
        ms.weight = rel / dot(p, rel);
    }
#else
    /* grey extinction: the exponentials cancel exactly against the pdf */
    float sigma = sigma_t.x;
    float t = sigma > 0.0f ? -log1p(-u_dist) / sigma : INFINITY;
    ms.scattered = t < t_max;
    ms.t = ms.scattered ? t : t_max;
    ms.weight = ms.scattered ? albedo : (float3)(1.0f);
#if VOLCL_HAS_EMISSIVE_MEDIA
    if (ms.scattered) ms.emission = vload_f3(m->emission) / sigma;
#endif
#endif
    return ms;
}

inline float3 medium_transmittance(__global const Medium *m, float t) {
    return transmittance_exp(vload_f3(m->sigma_t), t);
}

#endif
