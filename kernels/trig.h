/* Sines, cosines and arctangents of arguments whose range the caller knows: short polynomials
 * (Cephes' single-precision minimax coefficients, within 2 ulp of the true values) after an exact
 * or two-part reduction. They cost a fraction of the library's atan2, sin and cos, which handle
 * every argument: on PoCL's CPU device those were a third of a sample's time in a fog lit by a
 * point light (equiangular sampling, angles in (0, pi)), and the azimuths of the direction samplers
 * (whole turns, sincos_turn) cost 4 to 10% of a render (README, "Throughput"). */
#ifndef VOLCL_TRIG_H
#define VOLCL_TRIG_H

/* atan(x) for x >= 0: reduced to |x| <= tan(pi/8) by atan(x) = pi/2 - atan(1/x) and
 * atan(x) = pi/4 + atan((x - 1) / (x + 1)), the constants in two parts (a float and the rest). */
inline float atan_nonneg(float x) {
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
inline float atan2_upper(float y, float x) {
    if (x > 0.0f) return atan_nonneg(y / x);
    if (x < 0.0f) return (3.1415927410125732f - atan_nonneg(y / -x)) - 8.742278000372485e-8f;
    return M_PI_2_F;
}

/* sin and cos of a on [-pi/4, pi/4] */
inline float sin_small(float a) {
    float z = a * a;
    return ((-1.9515295891e-4f * z + 8.3321608736e-3f) * z - 1.6666654611e-1f) * z * a + a;
}

inline float cos_small(float a) {
    float z = a * a;
    return ((2.443315711809948e-5f * z - 1.388731625493765e-3f) * z + 4.166664568298827e-2f) * z * z
           - 0.5f * z + 1.0f;
}

/* sin and cos of phi in [0, pi]: phi - k pi/2 for the nearest k in {0, 1, 2}, with pi/2 in two
 * parts (Cody and Waite) so the reduced angle keeps its low bits. */
inline float sincos_upper(float phi, float *c) {
    const float half_pi_hi = 1.5707963705062866f, half_pi_lo = -4.371139000186243e-8f;
    int k = (int)(phi * M_2_PI_F + 0.5f);
    float a = (phi - (float)k * half_pi_hi) - (float)k * half_pi_lo;
    float sa = sin_small(a), ca = cos_small(a);
    if (k == 0) { *c = ca; return sa; }
    if (k == 1) { *c = -sa; return ca; }
    *c = -ca;
    return -sa;
}

/* sin(2 pi u), and cos(2 pi u) in *c, for u in [0, 1): the quarter turn k nearest u is taken off
 * exactly (u - k / 4 is exact in float32 for these u), which leaves an angle in [-pi/4, pi/4]. */
inline float sincos_turn(float u, float *c) {
    int k = (int)(4.0f * u + 0.5f);
    float a = (2.0f * VOLCL_PI) * (u - 0.25f * (float)k);
    float sa = sin_small(a), ca = cos_small(a);
    switch (k & 3) {
    case 0: *c = ca; return sa;
    case 1: *c = -sa; return ca;
    case 2: *c = -ca; return -sa;
    default: *c = sa; return -ca;
    }
}

#endif
