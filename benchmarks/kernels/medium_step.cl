/* Benchmark-only kernels: one step of a path through a grey homogeneous fog lit by a point light,
 * the work path_medium_event (kernels/integrator.h) does on point_in_fog's segments, written as a
 * wavefront stage: each launch reads every path's state from global arrays, steps it once and
 * writes it back (benchmarks/medium_step.py). The step uses the renderer's own routines
 * (equiangular.h, phase.h, trig.h, rng.h) and leaves out what other stages would do: the shadow
 * rays' and the segment's BVH queries (their transmittance through the fog is the exponential
 * they would multiply in) and surface events.
 *
 * The same body is compiled three ways: `step_hinted` carries VOLCL_KERNEL's vector type hint, as
 * the renderer's kernels do; `step_auto` carries none, so a work-group vectorizer may run it
 * several work-items to a vector register; `step_lanes` is a loop over MEDIUM_LANES paths in one
 * work-item, the shape an explicit several-paths-per-work-item kernel would have. `step_scalar`
 * (below) is the same step in scalar floats, and `step_scalar32` that step with the generator's
 * 64-bit state held as two 32-bit halves. State layout:
 * row r of `state` holds field r of every path (structure of arrays), so lanes load contiguously. */
/* MEDIUM_INLINE_ALL: every function inlined. A call left in the work-item loop (PoCL left
 * equiangular_segment_pdf, called twice, out of line) stops LLVM's loop vectorizer ("instruction
 * cannot be vectorized"); a stage kernel meant for the lanes is built this way. */
#ifdef MEDIUM_INLINE_ALL
#define inline inline __attribute__((always_inline))
#endif
#include "types.h"
#include "common.h"
#include "scene.h"
#include "rng.h"
#include "sampling.h"
#include "trig.h"
#include "phase.h"
#include "equiangular.h"
#include "lanes.h"     /* V3, Rng32 and the routines on them, as the wavefront renderer's lanes stage has them */

#define F_OX 0
#define F_DX 3
#define F_BETA 6
#define F_L 7
#define F_T 10
#define STATE_ROWS 11

typedef struct {
    float sigma, albedo, g;
    float3 light, intensity;
} Fog;

inline float3 row3(__global const float *s, int row, int i, int n) {
    return (float3)(s[row * n + i], s[(row + 1) * n + i], s[(row + 2) * n + i]);
}

inline void put3(__global float *s, int row, int i, int n, float3 v) {
    s[row * n + i] = v.x;
    s[(row + 1) * n + i] = v.y;
    s[(row + 2) * n + i] = v.z;
}

/* Radiance the point light sends to x through the fog, before the phase value and MIS weight. */
__attribute__((always_inline))
inline float3 fog_light_at(const Fog *f, float3 x, float3 *wi, float *d2) {
    float3 v = f->light - x;
    *d2 = dot(v, v);
    float dist = sqrt(*d2);
    *wi = v / dist;
    return f->intensity * (exp(-f->sigma * dist) / *d2);
}

/* One segment o + t d, t < t_seg: the equiangular sample's direct light, then a free flight; at a
 * collision, NEE from the collision (MIS against the equiangular sample) and an HG direction. Grey
 * fog, so beta is one number. */
__attribute__((always_inline))
inline void fog_step(const Fog *f, float3 *o, float3 *d, float t_seg, float *beta, float3 *L, Rng *rng) {
    float sigma_s = f->sigma * f->albedo;
    EquiangularSegment s;
    bool seg_ok = equiangular_segment(*o, *d, t_seg, f->light, &s);
    float u_e = rng_next_float(rng);
    float t_e, pdf_e;
    if (seg_ok && equiangular_segment_sample(&s, u_e, &t_e, &pdf_e)) {
        float3 wi;
        float d2;
        float3 le = fog_light_at(f, *o + t_e * *d, &wi, &d2);
        float tr = exp(-f->sigma * t_e);
        float w = power_heuristic(pdf_e, f->sigma * tr);
        *L += *beta * tr * sigma_s * phase_hg_eval_dirs(f->g, *d, wi) * w / pdf_e * le;
    }
    float u = rng_next_float(rng);
    float t = -log_pos(1.0f - u) / f->sigma;
    float2 u_dir = rng_next_float2(rng);
    if (!(t < t_seg)) return;       /* the segment's end: a surface stage's work */
    *beta *= f->albedo;
    float3 p = *o + t * *d;
    float3 wi;
    float d2;
    float3 le = fog_light_at(f, p, &wi, &d2);
    float pdf_eq = seg_ok ? equiangular_segment_pdf(&s, t) : 0.0f;
    float w = power_heuristic(f->sigma * (1.0f - u), pdf_eq);
    *L += *beta * phase_hg_eval_dirs(f->g, *d, wi) * w * le;
    float3 peak = f->g >= 0.0f ? *d : -*d;
    *d = phase_direction_at(peak, phase_hg_sample_w(fabs(f->g), u_dir.x), u_dir.y);
    *o = p;
}

__attribute__((always_inline))
inline void step_path(const Fog *f, __global float *state, __global ulong *rng_state, __global const ulong *rng_inc,
                      int i, int n) {
    float3 o = row3(state, F_OX, i, n), d = row3(state, F_DX, i, n), L = row3(state, F_L, i, n);
    float beta = state[F_BETA * n + i];
    Rng rng;
    rng.state = rng_state[i];
    rng.inc = rng_inc[i];
    fog_step(f, &o, &d, state[F_T * n + i], &beta, &L, &rng);
    put3(state, F_OX, i, n, o);
    put3(state, F_DX, i, n, d);
    put3(state, F_L, i, n, L);
    state[F_BETA * n + i] = beta;
    rng_state[i] = rng.state;
}

#define STEP_ARGS float sigma, float albedo, float g, float lx, float ly, float lz, float ix, float iy, float iz, \
    __global float *state, __global ulong *rng_state, __global const ulong *rng_inc, int n

inline Fog fog_make(float sigma, float albedo, float g, float lx, float ly, float lz, float ix, float iy, float iz) {
    Fog f;
    f.sigma = sigma;
    f.albedo = albedo;
    f.g = g;
    f.light = (float3)(lx, ly, lz);
    f.intensity = (float3)(ix, iy, iz);
    return f;
}

VOLCL_KERNEL void step_hinted(STEP_ARGS) {
    int i = get_global_id(0);
    if (i >= n) return;
    Fog f = fog_make(sigma, albedo, g, lx, ly, lz, ix, iy, iz);
    step_path(&f, state, rng_state, rng_inc, i, n);
}

__kernel void step_auto(STEP_ARGS) {
    int i = get_global_id(0);
    if (i >= n) return;
    Fog f = fog_make(sigma, albedo, g, lx, ly, lz, ix, iy, iz);
    step_path(&f, state, rng_state, rng_inc, i, n);
}

/* ---- The same step in scalar floats, in kernels/lanes.h's terms (V3, Rng32, the routines on
 * them), under the rules lanes.h states. The two this benchmark found: choose between two V3s one
 * component at a time (v3_sel), never `c ? a : b` on whole structs (the x86-64 calling convention
 * passes a 12-byte struct as {<2 x float>, float}, and a whole-struct select stays a <2 x float>
 * select, which stops LLVM's loop vectorizer as a float3 does); and no 64-bit values
 * (step_scalar32). The routines that are scalar already (equiangular sampling and pdf on a set-up
 * segment, atan2_upper, sincos_turn, log_pos, the HG sampler and value in w) are the renderer's own. */
/* Fog with V3 fields: a float3 even in a loop-invariant struct stops the vectorizer */
typedef struct {
    float sigma, albedo, g;
    V3 light, intensity;
} FogS;

inline float heuristic(float a, float b) {
    float a2 = a * a, b2 = b * b;

    return isinf(a2) ? (isinf(b2) ? 0.5f : 1.0f) : (a2 + b2 > 0.0f ? a2 / (a2 + b2) : 0.0f);
}

/* fog_light_at on V3 */
inline V3 light_v3(const FogS *f, V3 x, V3 *wi) {
    V3 v = v3_sub(f->light, x);
    float d2 = v3_dot(v, v), dist = sqrt(d2);
    *wi = v3_scale(v, 1.0f / dist);
    float k = exp(-f->sigma * dist) / d2;
    return v3(f->intensity.x * k, f->intensity.y * k, f->intensity.z * k);
}

/* The step's random numbers: the renderer's PCG32 (rng.h), or the same generator with its 64-bit
 * state held as two 32-bit halves (lanes.h's Rng32): LLVM's loop vectorizer sizes its vectors by the
 * widest type in the loop, so one 64-bit integer (the state, its multiply) holds a 256-bit register
 * to 4 lanes, where 32-bit values alone fill 8. The halves give the same numbers, bit for bit. */
inline float rng32_next_float(Rng32 *r) { return rng32_float_if(r, true); }

/* fog_step in scalar floats: the same estimator, written as selects where fog_step branches; u_e, u,
 * u_w, u_phi: its uniform numbers, in the order fog_step draws them (the caller draws them with its
 * generator; not a float4, a vector type, which would stop the loop vectorizer) */
inline void fog_step_v3(const FogS *f, V3 *o, V3 *d, float t_seg, float *beta, V3 *L, float u_e, float u,
                        float u_w, float u_phi) {
    float sigma_s = f->sigma * f->albedo;
    EquiangularSegment s;
    bool seg_ok = lanes_equiangular_segment(*o, *d, t_seg, f->light, &s);
    float t_e, pdf_e;
    bool eq = seg_ok && equiangular_segment_sample(&s, u_e, &t_e, &pdf_e);
    V3 wi;
    V3 le = light_v3(f, v3_madd(*o, eq ? t_e : 0.0f, *d), &wi);
    float tr = exp(-f->sigma * t_e);
    float c = eq ? *beta * tr * sigma_s * lanes_hg_eval(f->g, *d, wi) * heuristic(pdf_e, f->sigma * tr) / pdf_e : 0.0f;
    *L = v3_madd(*L, c, le);
    float t = -log_pos(1.0f - u) / f->sigma;
    bool scattered = t < t_seg;
    float b = scattered ? *beta * f->albedo : *beta;
    V3 p = v3_madd(*o, scattered ? t : 0.0f, *d);
    le = light_v3(f, p, &wi);
    float pdf_eq = seg_ok ? equiangular_segment_pdf(&s, t) : 0.0f;
    c = scattered ? b * lanes_hg_eval(f->g, *d, wi) * heuristic(f->sigma * (1.0f - u), pdf_eq) : 0.0f;
    *L = v3_madd(*L, c, le);
    V3 peak = v3_scale(*d, f->g >= 0.0f ? 1.0f : -1.0f);
    V3 nd = lanes_direction_at(peak, phase_hg_sample_w(fabs(f->g), u_w), u_phi);
    *d = v3_sel(scattered, nd, *d);
    *o = v3_sel(scattered, p, *o);
    *beta = b;
}

/* fog_step_v3 on path i's state in its rows (the uniform numbers drawn by the caller's generator) */
inline void step_v3_rows(__global float *state, int i, int n, const FogS *f, float u_e, float u, float u_w,
                         float u_phi) {
    V3 o = v3(state[(F_OX) * n + i], state[(F_OX + 1) * n + i], state[(F_OX + 2) * n + i]);
    V3 d = v3(state[(F_DX) * n + i], state[(F_DX + 1) * n + i], state[(F_DX + 2) * n + i]);
    V3 L = v3(state[(F_L) * n + i], state[(F_L + 1) * n + i], state[(F_L + 2) * n + i]);
    float beta = state[F_BETA * n + i];
    fog_step_v3(f, &o, &d, state[F_T * n + i], &beta, &L, u_e, u, u_w, u_phi);
    state[F_OX * n + i] = o.x; state[(F_OX + 1) * n + i] = o.y; state[(F_OX + 2) * n + i] = o.z;
    state[F_DX * n + i] = d.x; state[(F_DX + 1) * n + i] = d.y; state[(F_DX + 2) * n + i] = d.z;
    state[F_L * n + i] = L.x; state[(F_L + 1) * n + i] = L.y; state[(F_L + 2) * n + i] = L.z;
    state[F_BETA * n + i] = beta;
}

/* No bounds test: a store under a condition keeps LLVM from vectorizing the loop ("control flow
 * cannot be substituted for a select"), so the host launches n work-items exactly, as a wavefront
 * renderer would pad its path arrays to the work-group size. */
__kernel void step_scalar(STEP_ARGS) {
    int i = get_global_id(0);
    FogS f = {sigma, albedo, g, {lx, ly, lz}, {ix, iy, iz}};
    Rng rng;
    rng.state = rng_state[i];
    rng.inc = rng_inc[i];
    float u_e = rng_next_float(&rng), u = rng_next_float(&rng);
    float u_w = rng_next_float(&rng), u_phi = rng_next_float(&rng);
    step_v3_rows(state, i, n, &f, u_e, u, u_w, u_phi);
    rng_state[i] = rng.state;
}

/* step_scalar with the 32-bit halves of the generator's state */
__kernel void step_scalar32(STEP_ARGS) {
    int i = get_global_id(0);
    FogS f = {sigma, albedo, g, {lx, ly, lz}, {ix, iy, iz}};
    /* the generator's state as rows of 32-bit halves (low halves of every path, then high halves),
     * so no 64-bit value is in the loop and no pair of adjacent halves for the SLP vectorizer to
     * pack into a <2 x i32>, which stops the loop vectorizer as a float3 does */
    __global uint *rs = (__global uint *)rng_state;
    __global const uint *ri = (__global const uint *)rng_inc;
    Rng32 rng = {rs[i], rs[n + i], ri[i], ri[n + i]};
    float u_e = rng32_next_float(&rng), u = rng32_next_float(&rng);
    float u_w = rng32_next_float(&rng), u_phi = rng32_next_float(&rng);
    step_v3_rows(state, i, n, &f, u_e, u, u_w, u_phi);
    rs[i] = rng.lo;
    rs[n + i] = rng.hi;
}

#ifndef MEDIUM_LANES
#define MEDIUM_LANES 8
#endif

VOLCL_KERNEL void step_lanes(STEP_ARGS) {
    int first = get_global_id(0) * MEDIUM_LANES;
    Fog f = fog_make(sigma, albedo, g, lx, ly, lz, ix, iy, iz);
    for (int k = 0; k < MEDIUM_LANES; ++k)
        if (first + k < n) step_path(&f, state, rng_state, rng_inc, first + k, n);
}
