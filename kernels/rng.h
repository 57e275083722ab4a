/* Random numbers: PCG32 (O'Neill 2014), one independent stream per (seed, pixel, sample index).
 *
 * Each sample seeds its own generator from a hash of the three, so the image depends only on the
 * seed and the sample indices rendered, never on how samples are batched into launches or tiles.
 */
#ifndef VOLCL_RNG_H
#define VOLCL_RNG_H

typedef struct { ulong state; ulong inc; } Rng;

inline uint rng_next_uint(Rng *r) {
    ulong old = r->state;
    r->state = old * 6364136223846793005UL + r->inc;
    uint xorshifted = (uint)(((old >> 18u) ^ old) >> 27u);
    uint rot = (uint)(old >> 59u);
    return (xorshifted >> rot) | (xorshifted << ((-rot) & 31u));
}

/* splitmix64 finalizer: spreads nearby counters over the whole state space */
inline ulong rng_mix64(ulong z) {
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9UL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebUL;
    return z ^ (z >> 31);
}

inline Rng rng_init(uint seed, uint pixel, uint sample) {
    Rng r;
    ulong key = rng_mix64(((ulong)seed << 32) ^ (ulong)pixel ^ 0x9e3779b97f4a7c15UL);
    r.state = 0;
    r.inc = (rng_mix64(key ^ (ulong)sample) << 1u) | 1u;
    rng_next_uint(&r);
    r.state += rng_mix64(key + (ulong)sample * 0x632be59bd9b4e019UL);
    rng_next_uint(&r);
    return r;
}

/* Uniform float in [0, 1): 24 random bits, so 1.0f is never returned. */
inline float rng_next_float(Rng *r) { return (float)(rng_next_uint(r) >> 8) * (1.0f / 16777216.0f); }

inline float2 rng_next_float2(Rng *r) {
    float a = rng_next_float(r);
    return (float2)(a, rng_next_float(r));
}

#endif
