/* Phase functions. Convention: cos_theta is the cosine between the travel directions before and
 * after scattering (dot(d_in, d_out)), so g > 0 scatters forward. Values are per unit solid angle
 * and equal the sampling pdf (both phase functions are sampled exactly).
 *
 * Henyey-Greenstein for every float g in (-1, 1):
 *  - sampling inverts the CDF; for |g| < 0.5 in a rearranged form with no division by g, exact at
 *    g = 0 and free of the cancellation of the textbook (1 + g^2 - ...) / 2g form, which gives
 *    |cos| > 1 and a wrong mean cosine for |g| ~ 1e-4 in float32; for |g| >= 0.5 in the textbook
 *    form, which is the accurate one there;
 *  - the denominator 1 + g^2 - 2 g cos is evaluated as (1 - |g|)^2 + 2|g| (1 -+ cos), a sum of
 *    non-negative terms, so it never rounds to zero or below as |g| -> 1 (the pdf stays finite:
 *    about 1e9 at g = 0.99999); no clamp of g is applied.
 */
#ifndef VOLCL_PHASE_H
#define VOLCL_PHASE_H

inline float phase_hg_eval(float g, float cos_theta) {
    float ag = fabs(g);
    float c = g >= 0.0f ? cos_theta : -cos_theta;
    float denom = (1.0f - ag) * (1.0f - ag) + 2.0f * ag * (1.0f - c);
    return VOLCL_INV_4PI * (1.0f - g * g) / (denom * sqrt(denom));
}

inline float phase_hg_sample_cos(float g, float u) {
    float s = 2.0f * u - 1.0f;
    float gs = 1.0f + g * s;
    float c;
    if (fabs(g) < 0.5f) {
        /* the textbook inversion multiplied out and divided by 2g symbolically */
        float num = s + 0.5f * g * (s * s + 3.0f) + g * g * s + 0.5f * g * g * g * (s * s - 1.0f);
        c = num / (gs * gs);
    } else {
        /* for large |g| the product form above cancels near s = -1/g; the textbook form does not */
        float k = (1.0f - g * g) / gs;
        c = (1.0f + g * g - k * k) / (2.0f * g);
    }
    return clamp(c, -1.0f, 1.0f);
}

inline float phase_eval(__global const Medium *m, float cos_theta) {
#if VOLCL_HAS_HG
    if (m->phase == PHASE_HG) return phase_hg_eval(m->g, cos_theta);
#endif
    return VOLCL_INV_4PI;
}

/* New travel direction around d_in; returns the pdf (= phase value). */
inline float phase_sample(__global const Medium *m, float3 d_in, float2 u, float3 *d_out) {
#if VOLCL_HAS_HG
    if (m->phase == PHASE_HG) {
        float c = phase_hg_sample_cos(m->g, u.x);
        float sn = sqrt(fmax(0.0f, 1.0f - c * c));
        float cp = native_cos(2.0f * VOLCL_PI * u.y), sp = native_sin(2.0f * VOLCL_PI * u.y);
        float3 s, t;
        make_frame(d_in, &s, &t);
        *d_out = normalize(frame_to_world((float3)(sn * cp, sn * sp, c), s, t, d_in));
        return phase_hg_eval(m->g, c);
    }
#endif
    *d_out = sample_uniform_sphere(u);
    return VOLCL_INV_4PI;
}

#endif
