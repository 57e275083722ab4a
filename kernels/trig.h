/* Sines, cosines, arctangents and the free flights' logarithm, for arguments whose range the caller
 * knows: short polynomials (Cephes' single-precision minimax coefficients, within 2 ulp of the true
 * values) after an exact or two-part reduction. They cost a fraction of the library's atan2, sin,
 * cos and log, which handle every argument: on PoCL's CPU device those were a third of a sample's
 * time in a fog lit by a point light (equiangular sampling, angles in (0, pi)), and the azimuths of
 * the direction samplers (whole turns, sincos_turn) cost 4 to 10% of a render (README,
 * "Throughput"). */
#ifndef VOLCL_TRIG_H
#define VOLCL_TRIG_H

/* atan2(y, x) for y > 0: the angle in (0, pi). atan(y / |x|) is reduced to an argument of at most
 * tan(pi/8) by atan(r) = pi/2 - atan(1/r) and atan(r) = pi/4 + atan((r - 1) / (r + 1)), each formed
 * from y and |x| in one division (-|x| / y, (y - |x|) / (y + |x|)) instead of dividing twice; the
 * constants are in two parts (a float and the rest). x = 0 gives pi/2 (-0 / y). */
inline float atan2_upper(float y, float x) {
    float ax = fabs(x);
    bool big = y > 2.414213562373095f * ax, mid = y > 0.4142135623730950f * ax;
    float num = big ? -ax : (mid ? y - ax : y);
    float den = big ? y : (mid ? y + ax : ax);
    float hi = big ? 1.5707963705062866f : (mid ? 0.7853981852531433f : 0.0f);
    float lo = big ? -4.371139000186243e-8f : (mid ? -2.1855695000931215e-8f : 0.0f);
    float r = num / den;
    float z = r * r;
    float a = hi + (lo + ((((8.05374449538e-2f * z - 1.38776856032e-1f) * z + 1.99777106478e-1f) * z
                           - 3.33329491539e-1f) * z * r + r));
    return x < 0.0f ? (3.1415927410125732f - a) - 8.742278000372485e-8f : a;
}

/* atan2(y, x) on the whole plane, by symmetry from atan2_upper; (0, 0) gives 0 as the library
 * does (a pole direction, where the azimuth is arbitrary). */
inline float atan2_full(float y, float x) {
    if (y == 0.0f && x == 0.0f) return 0.0f;
    float a = atan2_upper(fabs(y), x);
    return y < 0.0f ? -a : a;
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
    /* selects, not branches: a work-item vectorizer gives up at a switch or an early return
     * (benchmarks/medium_step.py) */
    *c = k == 0 ? ca : (k == 1 ? -sa : -ca);
    return k == 0 ? sa : (k == 1 ? ca : -sa);
}

/* sin(2 pi u), and cos(2 pi u) in *c, for u in [0, 1): the quarter turn k nearest u is taken off
 * exactly (u - k / 4 is exact in float32 for these u), which leaves an angle in [-pi/4, pi/4]. */
inline float sincos_turn(float u, float *c) {
    int k = (int)(4.0f * u + 0.5f);
    float a = (2.0f * VOLCL_PI) * (u - 0.25f * (float)k);
    float sa = sin_small(a), ca = cos_small(a);
    /* quarter turn k: (sin, cos) = (sa, ca), (ca, -sa), (-sa, -ca), (-ca, sa), as selects (see
     * sincos_upper) */
    bool odd = (k & 1) != 0;
    float s = odd ? ca : sa, co = odd ? sa : ca;
    *c = ((k + 1) & 2) != 0 ? -co : co;
    return (k & 2) != 0 ? -s : s;
}

/* log(x) for normal x > 0, as Cephes' logf: x = m 2^e with m in [sqrt(1/2), sqrt(2)), a polynomial
 * in m - 1, and e ln 2 in two parts; within 1 ulp for the free flights' x = 1 - u, u a multiple of
 * 2^-24 in [0, 1) (tests/test_trig.py), with none of the library's handling of zeros, subnormals,
 * infinities and NaN, which cost a twentieth of a point-lit fog's kernel time. */
inline float log_pos(float x) {
    uint bits = as_uint(x);
    int e = (int)((bits >> 23) & 0xffu) - 126;
    float m = as_float((bits & 0x007fffffu) | 0x3f000000u);     /* in [1/2, 1) */
    if (m < 0.70710678118654752f) {
        e -= 1;
        m = m + m - 1.0f;
    } else {
        m = m - 1.0f;
    }
    float z = m * m;
    float y = ((((((((7.0376836292e-2f * m - 1.1514610310e-1f) * m + 1.1676998740e-1f) * m
                   - 1.2420140846e-1f) * m + 1.4249322787e-1f) * m - 1.6668057665e-1f) * m
                 + 2.0000714765e-1f) * m - 2.4999993993e-1f) * m + 3.3333331174e-1f) * m * z;
    float fe = (float)e;
    y += -2.12194440e-4f * fe;
    y += -0.5f * z;
    return (m + y) + 0.693359375f * fe;
}

#endif
