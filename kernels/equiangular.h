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

/* The angles here lie in (0, pi), where short polynomials (Cephes' single-precision minimax
 * coefficients, within 2 ulp of the true values) cost a fraction of the library's atan2, sin and
 * cos, which handle every argument and, on PoCL's CPU device, were a third of a sample's time in a
 * fog lit by a point light (README, "Throughput"). */

/* atan(x) for x >= 0: reduced to |x| <= tan(pi/8) by atan(x) = pi/2 - atan(1/x) and
 * atan(x) = pi/4 + atan((x - 1) / (x + 1)), the constants in two parts (a float and the rest). */
inline float eq_atan_nonneg(float x) {
    float hi = 0.0f, lo = 0.0f;
    if (x > 2.414213562373095f) {
        hi = 1.5707963705062866f;
        lo = -4.371139000186243e-8f;
        x = -1.0f / x;
    } else if (x > 0.4142135623730950f) {
        hi = 0.7853981852531433f;
        lo = -2.1855695000931215e-8f;
        x = (x - 1.0f) / (x + 1.0f);
    }
    float z = x * x;
    return hi + (lo + ((((8.05374449538e-2f * z - 1.38776856032e-1f) * z + 1.99777106478e-1f) * z
                        - 3.33329491539e-1f) * z * x + x));
}

/* atan2(y, x) for y > 0: the angle in (0, pi). */
inline float eq_atan2_upper(float y, float x) {
    if (x > 0.0f) return eq_atan_nonneg(y / x);
    if (x < 0.0f) return (3.1415927410125732f - eq_atan_nonneg(y / -x)) - 8.742278000372485e-8f;
    return M_PI_2_F;
}

/* sin and cos of a on [-pi/4, pi/4] */
inline float eq_sin_small(float a) {
    float z = a * a;
    return ((-1.9515295891e-4f * z + 8.3321608736e-3f) * z - 1.6666654611e-1f) * z * a + a;
}

inline float eq_cos_small(float a) {
    float z = a * a;
    return ((2.443315711809948e-5f * z - 1.388731625493765e-3f) * z + 4.166664568298827e-2f) * z * z
           - 0.5f * z + 1.0f;
}

/* sin and cos of phi in [0, pi]: phi - k pi/2 for the nearest k in {0, 1, 2}, with pi/2 in two
 * parts (Cody and Waite) so the reduced angle keeps its low bits. */
inline float eq_sincos(float phi, float *c) {
    const float half_pi_hi = 1.5707963705062866f, half_pi_lo = -4.371139000186243e-8f;
    int k = (int)(phi * M_2_PI_F + 0.5f);
    float a = (phi - (float)k * half_pi_hi) - (float)k * half_pi_lo;
    float sa = eq_sin_small(a), ca = eq_cos_small(a);
    if (k == 0) { *c = ca; return sa; }
    if (k == 1) { *c = -sa; return ca; }
    *c = -ca;
    return -sa;
}

typedef struct {
    float delta;    /* t of the point on the ray closest to the light */
    float h;        /* distance from the light to the ray */
    float t0, t1;   /* the interval sampled */
    float u0;       /* t0 - delta */
    float theta;    /* angle the interval subtends at the light, in (0, pi) */
} EquiangularSegment;

/* Set up the interval; false when there is nothing to sample (the light on the ray's line, or the
 * clipped interval empty). Sampler and pdf both start here, so they agree on every rounding. */
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
    s->theta = eq_atan2_upper(s->h * (u1 - s->u0), s->h * s->h + s->u0 * u1);
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
inline bool equiangular_segment_sample(const EquiangularSegment *s, float u, float *t, float *pdf) {
    float phi = u * s->theta;
    float cp, sp = eq_sincos(phi, &cp);
    float x = s->t0 + sp * (s->h * s->h + s->u0 * s->u0) / (s->h * cp - s->u0 * sp);
    *t = clamp(x, s->t0, s->t1);
    *pdf = equiangular_segment_pdf(s, *t);
    return *pdf > 0.0f;
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
