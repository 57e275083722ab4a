/* Code for the SIMD lanes: what a wavefront stage kernel (kernels/wavefront_lanes.cl) is written in,
 * so that the CPU runtimes run several work-items per vector instruction.
 *
 * PoCL vectorizes a kernel with LLVM's loop vectorizer over its work-item loop, Intel's runtime
 * with its own whole-kernel vectorizer; on the fog step (benchmarks/medium_step.py) they ran 8 and
 * 16 lanes, 6x and 10x the renderer's float3 code, once the stage kept to these rules:
 *  - scalar floats only: a vector here is a struct of three floats (V3), which LLVM splits into
 *    scalars. A float3 (any vector-typed value) in the loop stops LLVM's vectorizer ("instruction
 *    return type cannot be vectorized").
 *  - choose between two V3s one component at a time (v3_sel), never with `c ? a : b` on whole
 *    structs or by assigning one in a branch: the x86-64 calling convention passes a 12-byte
 *    struct as {<2 x float>, float}, and a whole-struct select or phi stays a <2 x float> select
 *    after inlining.
 *  - 32-bit values only: the vectorizer sizes its vectors by the widest type in the loop, and one
 *    64-bit value holds a 256-bit register to 4 lanes. The PCG32 generator of rng.h keeps its
 *    64-bit state as two 32-bit halves here (Rng32), giving the same numbers bit for bit.
 *  - no switch, no inner loop, no call left out of line, no store or load under a condition: every
 *    path's state is written back whether it changed or not, and conditions become selects (a
 *    table read only where a select takes it stayed a branch). A loop with a constant trip count
 *    is unrolled whole (lanes_triangles.h).
 *  - nothing the SLP vectorizer can pack: PoCL runs it on the kernel before it forms the work-item
 *    loop, and a <2 x float> it leaves stops the loop vectorizer. It packs neighbouring loads, and
 *    any two isomorphic computations side by side that it finds worth it: two shadow rays' tests
 *    and transmittances, their conditions' compares, two fabs, and in scenes of more than four
 *    triangles the sheared corner coordinates of a triangle test. One of the two is made to
 *    depend on the other (lanes_after, lanes_wait), or written another way. Which pairs it packs
 *    depends on the target's cost model: on AVX2 it packed dozens more all over the medium stage,
 *    which PoCL therefore runs as an explicit loop over its paths, vectorized before the SLP
 *    vectorizer runs (wavefront_lanes.cl VOLCL_WF_LOOP).
 *  - a select per candidate over a dozen table entries cost less than a gather per number on PoCL
 *    (wavefront_surface.cl's hit triangle).
 */
#ifndef VOLCL_LANES_H
#define VOLCL_LANES_H

typedef struct { float x, y, z; } V3;

inline V3 v3(float x, float y, float z) { V3 v = {x, y, z}; return v; }
inline V3 v3_add(V3 a, V3 b) { return v3(a.x + b.x, a.y + b.y, a.z + b.z); }
inline V3 v3_sub(V3 a, V3 b) { return v3(a.x - b.x, a.y - b.y, a.z - b.z); }
inline V3 v3_mul(V3 a, V3 b) { return v3(a.x * b.x, a.y * b.y, a.z * b.z); }
inline V3 v3_scale(V3 a, float s) { return v3(a.x * s, a.y * s, a.z * s); }
inline V3 v3_madd(V3 o, float t, V3 d) { return v3(o.x + t * d.x, o.y + t * d.y, o.z + t * d.z); }
inline float v3_dot(V3 a, V3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline float v3_max(V3 a) { return fmax(a.x, fmax(a.y, a.z)); }
inline V3 v3_sel(bool c, V3 a, V3 b) { return v3(c ? a.x : b.x, c ? a.y : b.y, c ? a.z : b.z); }
inline V3 lanes_div(V3 v, float s) { return v3(v.x / s, v.y / s, v.z / s); }

/* dot(a, b) as the OpenCL library computes it (no fused multiply-add) */
inline float lanes_dot(V3 a, V3 b) {
#pragma OPENCL FP_CONTRACT OFF
    return (a.x * b.x + a.y * b.y) + a.z * b.z;
}

/* v, made to depend on `dep` (exactly v, whatever dep is): two isomorphic computations side by side
 * (two shadow rays' tests and transmittances) were packed into <2 x float> vectors by the SLP
 * vectorizer, which stops the loop vectorizer; one that needs the other's result cannot be packed
 * with it */
inline float lanes_after(float v, float dep) { return v + 0.0f * fmax(fmin(dep, 0.0f), -1.0f); }
inline V3 lanes_after3(V3 v, float dep) { return v3(lanes_after(v.x, dep), lanes_after(v.y, dep), lanes_after(v.z, dep)); }

/* ---- PCG32 (rng.h) on 32-bit halves of its state and increment: the same numbers, bit for bit */
typedef struct { uint lo, hi, inc_lo, inc_hi; } Rng32;

/* the high 32 bits of a 32 x 32-bit product from 16-bit pieces: PoCL's mul_hi widens to 64 bits */
inline uint lanes_mul_hi(uint a, uint b) {
    uint a0 = a & 0xFFFFu, a1 = a >> 16, b0 = b & 0xFFFFu, b1 = b >> 16;
    uint p01 = a0 * b1, p10 = a1 * b0;
    uint mid = ((a0 * b0) >> 16) + (p01 & 0xFFFFu) + (p10 & 0xFFFFu);
    return a1 * b1 + (p01 >> 16) + (p10 >> 16) + (mid >> 16);
}

/* rng_next_uint's output for the state (lo, hi), and the state after it in *r; `step` false leaves
 * *r as it was (a draw that the scalar code makes only on some paths) */
inline uint rng32_next_uint_if(Rng32 *r, bool step) {
    uint l = r->lo, h = r->hi;
    const uint m_lo = 0x4C957F2Du, m_hi = 0x5851F42Du;    /* 6364136223846793005 */
    uint p_lo = l * m_lo;
    uint p_hi = lanes_mul_hi(l, m_lo) + l * m_hi + h * m_lo;
    uint n_lo = p_lo + r->inc_lo;
    uint n_hi = p_hi + r->inc_hi + (n_lo < p_lo ? 1u : 0u);
    r->lo = step ? n_lo : l;
    r->hi = step ? n_hi : h;
    /* ((old >> 18) ^ old) >> 27, its low 32 bits, rotated by old >> 59 */
    uint x_lo = l ^ ((l >> 18) | (h << 14)), x_hi = h ^ (h >> 18);
    uint xorshifted = (x_lo >> 27) | (x_hi << 5);
    uint rot = h >> 27;
    return (xorshifted >> rot) | (xorshifted << ((-rot) & 31u));
}

/* rng_next_float's number, drawn only where `step` holds (else the state stays and the value is
 * the one the next draw will give) */
inline float rng32_float_if(Rng32 *r, bool step) {
    return (float)(rng32_next_uint_if(r, step) >> 8) * (1.0f / 16777216.0f);
}

/* ---- The renderer's routines on V3, each the float3 version's arithmetic */

/* path_roulette (integrator.h) for the paths that go on (`going`), at their depth after the
 * scatter: whether it ends the path; a survivor's throughput is divided by its survival chance */
inline bool lanes_roulette(Rng32 *rng, V3 *beta, bool going, int depth, int rr_depth, float eta_scale) {
    bool rr = going & (depth >= rr_depth);
    float u_rr = rng32_float_if(rng, rr);
    float q = fmin(v3_max(*beta) * eta_scale, 0.95f);
    bool killed = rr & (u_rr >= q);
    *beta = v3_sel(rr & !killed, lanes_div(*beta, q), *beta);
    return killed;
}

/* sample_concentric_disk (sampling.h): its two cases as selects */
inline void lanes_concentric_disk(float u0, float u1, float *dx, float *dy) {
    float ox = 2.0f * u0 - 1.0f, oy = 2.0f * u1 - 1.0f;
    /* |o| two ways: two fabs side by side were packed into a <2 x float> */
    bool wide = fabs(ox) > (oy < 0.0f ? -oy : oy);
    float r = wide ? ox : oy;
    float a = (VOLCL_PI / 4.0f) * ((wide ? oy : ox) / r);
    float c = cos_small(a), s = sin_small(a);
    bool centre = (ox == 0.0f) & (oy == 0.0f);
    *dx = centre ? 0.0f : r * (wide ? c : s);
    *dy = centre ? 0.0f : r * (wide ? s : c);
}

/* phase_direction_at (phase.h): make_frame's basis about the unit `peak`, then normalized */
inline V3 lanes_direction_at(V3 n, float w, float u) {
    float sn = sqrt(fmax(0.0f, w * (2.0f - w)));
    float cp, sp = sincos_turn(u, &cp);
    float sign = copysign(1.0f, n.z);
    float a = -1.0f / (sign + n.z);
    float b = n.x * n.y * a;
    V3 s = v3(1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x), t = v3(b, sign + n.y * n.y * a, -n.y);
    float lx = sn * cp, ly = sn * sp, lz = 1.0f - w;
    V3 r = v3(lx * s.x + ly * t.x + lz * n.x, lx * s.y + ly * t.y + lz * n.y, lx * s.z + ly * t.z + lz * n.z);
    return v3_scale(r, rsqrt(v3_dot(r, r)));
}

/* sample_uniform_sphere (sampling.h) */
inline V3 lanes_uniform_sphere(float u0, float u1) {
    float z = 1.0f - 2.0f * u0;
    float r = sqrt(fmax(0.0f, 1.0f - z * z));
    float c, s = sincos_turn(u1, &c);
    return v3(r * c, r * s, z);
}

/* phase_hg_eval_dirs (phase.h) */
inline float lanes_hg_eval(float g, V3 d_in, V3 d_out) {
    V3 gap = v3_sub(d_in, v3_scale(d_out, g >= 0.0f ? 1.0f : -1.0f));
    return phase_hg_eval_w(g, 0.5f * v3_dot(gap, gap));
}

/* equiangular_segment (equiangular.h) on V3: the same set-up, the same roundings */
inline bool lanes_equiangular_segment(V3 o, V3 d, float t_max, V3 light, EquiangularSegment *s) {
    V3 v = v3_sub(light, o);
    s->delta = v3_dot(v, d);
    V3 perp = v3_madd(v, -s->delta, d);
    s->h = sqrt(v3_dot(perp, perp));
    float reach = EQUIANGULAR_SPAN * s->h;
    s->t0 = fmax(0.0f, s->delta - reach);
    s->t1 = fmin(t_max, s->delta + reach);
    s->u0 = s->t0 - s->delta;
    float u1 = s->t1 - s->delta;
    s->theta = atan2_upper(s->h * (u1 - s->u0), s->h * s->h + s->u0 * u1);
    return s->h * s->h > 0.0f && s->t1 > s->t0 && s->theta > 0.0f;
}

#endif
