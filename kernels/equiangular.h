/* Equiangular sampling (Kulla and Fajardo 2012): distances along a ray segment in a medium, chosen
 * so that every angle seen from a point light is equally likely. The pdf is proportional to
 * 1 / (h^2 + (t - delta)^2), which cancels the 1 / distance^2 falloff of the light's in-scattered
 * radiance: the halo around a point light in thin fog, which free-flight distance sampling almost
 * never lands in, becomes a low-variance estimate.
 *
 * Geometry: the ray is o + t d (d unit) for t in [0, t_max]; `delta` is the t of the point closest
 * to the light and `h` the light's distance from the ray. Angles theta are measured at the light
 * from the perpendicular onto the ray, so t - delta = h tan(theta). pdfs are per unit length along
 * the ray.
 *
 * The sampled interval is the segment clipped to |t - delta| <= EQUIANGULAR_SPAN * h. Outside it the
 * integrand's share is below 1 / (pi * EQUIANGULAR_SPAN); the clip keeps theta away from +-pi/2,
 * where float32 tan loses its accuracy and an infinite segment would give inf / inf. Distances
 * outside the interval have pdf 0 here and are left entirely to distance sampling by the MIS
 * weights (integrator.h), so the clip costs no bias.
 */
#ifndef VOLCL_EQUIANGULAR_H
#define VOLCL_EQUIANGULAR_H

#define EQUIANGULAR_SPAN 1000.0f

#include "trig.h"

typedef struct {
    float delta;    /* t of the point on the ray closest to the light */
    float h;        /* distance from the light to the ray */
    float t0, t1;   /* the interval sampled */
    float u0;       /* t0 - delta */
    float theta;    /* angle the interval subtends at the light, in (0, pi) */
} EquiangularSegment;

/* Set up the interval; false when there is nothing to sample (the light on the ray's line, or the
 * clipped interval empty). Sampler and pdf both start here, so they agree on every rounding. */
__attribute__((always_inline))
inline bool equiangular_segment(float3 o, float3 d, float t_max, float3 light, EquiangularSegment *s) {
    float3 v = light - o;
    s->delta = dot(v, d);
    s->h = length(v - s->delta * d);
    /* h^2 must not underflow: the pdf divides by h^2 + (t - delta)^2, which is h^2 at t = delta */
    if (!(s->h * s->h > 0.0f)) return false;
    float reach = EQUIANGULAR_SPAN * s->h;
    s->t0 = fmax(0.0f, s->delta - reach);
    s->t1 = fmin(t_max, s->delta + reach);
    if (!(s->t1 > s->t0)) return false;
    s->u0 = s->t0 - s->delta;
    float u1 = s->t1 - s->delta;
    /* theta1 - theta0 as one atan2 (tan of a difference): exact even when both angles are close to
     * each other near +-pi/2, where subtracting two atan results would cancel */
    s->theta = atan2_upper(s->h * (u1 - s->u0), s->h * s->h + s->u0 * u1);
    return s->theta > 0.0f;
}

inline float equiangular_segment_pdf(const EquiangularSegment *s, float t) {
    if (!(t >= s->t0 && t <= s->t1)) return 0.0f;
    float u = t - s->delta;
    return s->h / (s->theta * (s->h * s->h + u * u));
}

/* A distance in [t0, t1] for the uniform variate u in [0, 1); false when there is nothing to sample.
 * With phi = u * theta the angle past theta0, tan(theta0 + phi) expanded and t0 subtracted gives
 *     t = t0 + sin(phi) (h^2 + u0^2) / (h cos(phi) - u0 sin(phi)),
 * which has no cancellation at t0 and a denominator that stays positive (it is
 * sqrt(h^2 + u0^2) cos(theta0 + phi) with theta0 + phi < atan(EQUIANGULAR_SPAN) < pi/2). */
__attribute__((always_inline))
inline bool equiangular_segment_sample(const EquiangularSegment *s, float u, float *t, float *pdf) {
    float phi = u * s->theta;
    float cp, sp = sincos_upper(phi, &cp);
    float x = s->t0 + sp * (s->h * s->h + s->u0 * s->u0) / (s->h * cp - s->u0 * sp);
    *t = clamp(x, s->t0, s->t1);
    *pdf = equiangular_segment_pdf(s, *t);
    return *pdf > 0.0f;
}

/* Which techniques estimate point-light direct light on a segment (integrator.h has the estimator) */
#define EQ_NONE 0           /* distance sampling alone */
#define EQ_BOTH 1
#define EQ_ONLY_EQUIANGULAR 2
#define EQ_ONLY_DISTANCE 3

/* MIS weight of the equiangular sample (pdf_e) against distance sampling (pdf_d) at its distance */
inline float equiangular_weight(int tech, int mis, float pdf_e, float pdf_d) {
    if (tech == EQ_ONLY_EQUIANGULAR) return 2.0f * power_heuristic(pdf_e, pdf_d);
    return mis ? power_heuristic(pdf_e, pdf_d) : 1.0f;
}

inline bool sample_equiangular(float3 o, float3 d, float t_max, float3 light, float u, float *t, float *pdf) {
    EquiangularSegment s;
    if (!equiangular_segment(o, d, t_max, light, &s)) return false;
    return equiangular_segment_sample(&s, u, t, pdf);
}

inline float sample_equiangular_pdf(float3 o, float3 d, float t_max, float3 light, float t) {
    EquiangularSegment s;
    if (!equiangular_segment(o, d, t_max, light, &s)) return 0.0f;
    return equiangular_segment_pdf(&s, t);
}

#endif
