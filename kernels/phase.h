/* Phase functions. Convention: the angle is the one between the travel directions before and after
 * scattering (d_in, d_out), so g > 0 scatters forward. Values are per unit solid angle and equal the
 * sampling pdf (both phase functions are sampled exactly).
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

inline float phase_eval(__global const Medium *m, float3 d_in, float3 d_out) {
#if VOLCL_HAS_HG
    if (m->phase == PHASE_HG) {
        float3 gap = m->g >= 0.0f ? d_in - d_out : d_in + d_out;
        return phase_hg_eval_w(m->g, 0.5f * dot(gap, gap));
    }
#endif
    return VOLCL_INV_4PI;
}

/* New travel direction after scattering from d_in; returns the pdf (= phase value). */
inline float phase_sample(__global const Medium *m, float3 d_in, float2 u, float3 *d_out) {
#if VOLCL_HAS_HG
    if (m->phase == PHASE_HG) {
        float3 peak = m->g >= 0.0f ? d_in : -d_in;
        float w = phase_hg_sample_w(fabs(m->g), u.x);
        float sn = sqrt(fmax(0.0f, w * (2.0f - w)));
        /* native trig: only the azimuth, any angle error is a rotation about the peak */
        float cp = native_cos(2.0f * VOLCL_PI * u.y), sp = native_sin(2.0f * VOLCL_PI * u.y);
        float3 s, t;
        make_frame(peak, &s, &t);
        *d_out = normalize(frame_to_world((float3)(sn * cp, sn * sp, 1.0f - w), s, t, peak));
        return phase_eval(m, d_in, *d_out);
    }
#endif
    *d_out = sample_uniform_sphere(u);
    return VOLCL_INV_4PI;
}

#endif
