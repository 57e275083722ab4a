/* Phase functions. Convention: the angle is the one between the travel directions before and after
 * scattering (d_in, d_out), so g > 0 scatters forward. Values are per unit solid angle.
 *
 * The interface the integrator uses:
 *   phase_eval_pdf(sc, m, d_in, d_out, &pdf): the phase value towards d_out, and the pdf with which
 *       phase_sample would have chosen d_out (for MIS weights);
 *   phase_sample(sc, m, d_in, u, rng, &d_out, &weight): a new direction, its pdf (returned), and
 *       weight = value / pdf, the factor for the path throughput.
 * Every phase function but Fournier-Forand is sampled exactly (pdf = value, weight = 1); the
 * Fournier-Forand sampler is a table whose pdf differs from the value (phase_families.h).
 * Isotropic and HG live in the Medium record; everything else is a mixture of lobes
 * (PHASE_LOBES, compiled only with VOLCL_HAS_PHASE_FAMILIES, phase_families.h).
 *
 * Henyey-Greenstein for every float g in (-1, 1), with no clamp of g. The lobe is carried as its
 * distance from the peak, w = 1 - cos(angle to the peak) (the peak is d_in for g >= 0, -d_in for
 * g < 0), never as a cosine: near |g| = 1 the lobe is (1 - |g|)^2 / 2|g| wide in w (5e-11 at
 * g = 0.99999) while float32 cosines near 1 are 6e-8 apart, so a cosine would quantize the lobe and
 * put most samples exactly on the peak.
 *  - sampling: w = (1 - |g|)^2 (1 - s)(2 + |g| + |g| s) / (2 (1 + |g| s)^2) with s = 2u - 1, the
 *    textbook CDF inversion rearranged so it neither divides by g (exact at g = 0; the textbook form
 *    gives |cos| > 1 and the wrong mean at g ~ 1e-4 in float32) nor cancels near |g| = 1;
 *  - evaluation: w from the directions themselves, |d_in -+ d_out|^2 / 2, which keeps its digits for
 *    tiny angles, and 1 + g^2 - 2 g cos written as (1 - |g|)^2 + 2 |g| w, a sum of non-negative
 *    terms that never rounds to zero.
 * The pdf returned by phase_sample is phase_eval of the direction it returns, so the two agree exactly.
 */
#ifndef VOLCL_PHASE_H
#define VOLCL_PHASE_H

inline float phase_hg_eval_w(float g, float w) {
    float ag = fabs(g);
    float denom = (1.0f - ag) * (1.0f - ag) + 2.0f * ag * w;
    /* (1 - |g|)(1 + |g|), not 1 - g * g, which cancels as |g| -> 1 */
    return VOLCL_INV_4PI * (1.0f - ag) * (1.0f + ag) / (denom * sqrt(denom));
}

/* Distance from the peak, w in [0, 2], of an HG sample for |g| = ag. */
inline float phase_hg_sample_w(float ag, float u) {
    float s = 2.0f * u - 1.0f;
    float gs = 1.0f + ag * s;
    float w = (1.0f - ag) * (1.0f - ag) * (1.0f - s) * (2.0f + ag + ag * s) / (2.0f * gs * gs);
    return clamp(w, 0.0f, 2.0f);
}

/* The unit direction at distance w = 1 - cos from the unit vector `peak`, at azimuth 2 pi u. */
inline float3 phase_direction_at(float3 peak, float w, float u) {
    float sn = sqrt(fmax(0.0f, w * (2.0f - w)));
    /* the azimuth: an error in it is only a rotation about the peak */
    float cp, sp = sincos_turn(u, &cp);
    float3 s, t;
    make_frame(peak, &s, &t);
    return normalize(frame_to_world((float3)(sn * cp, sn * sp, 1.0f - w), s, t, peak));
}

inline float phase_hg_eval_dirs(float g, float3 d_in, float3 d_out) {
    float3 gap = g >= 0.0f ? d_in - d_out : d_in + d_out;
    return phase_hg_eval_w(g, 0.5f * dot(gap, gap));
}

#if VOLCL_HAS_PHASE_FAMILIES
#include "phase_families.h"
#endif

/* The phase value towards d_out; *pdf: the density phase_sample gives d_out. */
VOLCL_STEP_INLINE
inline float phase_eval_pdf(const SceneData *sc, __global const Medium *m, float3 d_in, float3 d_out,
                            float *pdf) {
#if VOLCL_HAS_PHASE_FAMILIES
    if (m->phase == PHASE_LOBES) return phase_lobes_eval(sc, m, d_in, d_out, pdf);
#endif
#if VOLCL_HAS_HG
    if (m->phase == PHASE_HG) {
        float v = phase_hg_eval_dirs(m->g, d_in, d_out);
        *pdf = v;
        return v;
    }
#endif
    *pdf = VOLCL_INV_4PI;
    return VOLCL_INV_4PI;
}

inline float phase_eval(const SceneData *sc, __global const Medium *m, float3 d_in, float3 d_out) {
    float pdf;
    return phase_eval_pdf(sc, m, d_in, d_out, &pdf);
}

/* New travel direction after scattering from d_in, from the uniform pair u (and, for phase
 * functions that need more random numbers, rng); returns its pdf, *weight = value / pdf. */
VOLCL_STEP_INLINE
inline float phase_sample(const SceneData *sc, __global const Medium *m, float3 d_in, float2 u, Rng *rng,
                          float3 *d_out, float *weight) {
#if VOLCL_HAS_PHASE_FAMILIES
    if (m->phase == PHASE_LOBES) return phase_lobes_sample(sc, m, d_in, u, rng, d_out, weight);
#endif
    *weight = 1.0f;
#if VOLCL_HAS_HG
    if (m->phase == PHASE_HG) {
        float3 peak = m->g >= 0.0f ? d_in : -d_in;
        *d_out = phase_direction_at(peak, phase_hg_sample_w(fabs(m->g), u.x), u.y);
        return phase_hg_eval_dirs(m->g, d_in, *d_out);
    }
#endif
    *d_out = sample_uniform_sphere(u);
    return VOLCL_INV_4PI;
}

#endif
