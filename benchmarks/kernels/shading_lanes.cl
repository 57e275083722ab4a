/* Benchmark-only kernels: the shading of one surface vertex of a roughplastic bsdf whose diffuse
 * reflectance is a bilinear bitmap (textured_cbox's floor), on a wave of inputs held in global rows
 * as a wavefront stage would hold them (benchmarks/shading_lanes.py). Per input: the bsdf's
 * textures at uv (what bsdf_vertex_at evaluates), bsdf_eval for a light direction wi (value and
 * pdf), and bsdf_sample with host-given numbers u1, u2 (direction, weight, pdf). Directions are in
 * the local shading frame: the world-to-local frame change of bsdf_eval / bsdf_sample is left out
 * of both kernels.
 *
 * `shade_renderer` calls the renderer's own functions as the megakernel does (texture_eval3 /
 * texture_eval1 for every parameter of the record, bsdf_eval_local and bsdf_sample_local with
 * their dispatch on the record's type), built like the megakernel: VOLCL_KERNEL, whose vector type
 * hint keeps Intel's runtime scalar, and the scene's feature flags.
 *
 * `shade_lanes` is the same arithmetic in the lanes style: the packet renderer's rough step's
 * routines (kernels/lanes_rough.h, whose header lists what PoCL's vectorizer needed), specialized
 * to what the host checked the record to be: roughplastic, GGX, visible-normal sampling,
 * isotropic constant roughness, constant specular reflectance, diffuse reflectance a bilinear
 * bitmap of 3 byte-coded channels. Both of roughplastic_sample's lobes are sampled and one chosen.
 * Inputs (rows of n): u, v, wo.xyz, wi.xyz, u1, u2.x, u2.y. Outputs (rows of n): eval value.xyz,
 * eval pdf, sample ok (1 or 0), sample wi.xyz, weight.xyz, pdf (zeros where the sample fails).
 * SHADE_PERTURB 1 scales the eval's value by 1.001 in the lanes kernel only
 * (tests/test_shading_lanes.py). */
#include "renderer.h"

#define IN_ROWS 11
#define IN(r) in[(r) * n + i]
#define OUT(r) out[(r) * n + i]

/* The renderer's shading of one input (the rows' u, v, wo, wi, u1, u2) into the 12 outputs, for
 * shade_renderer and shade_inline alike. Inlined always: shade_renderer's rates are then the ones
 * it had with this body in the kernel (PoCL 9.4-9.8, Intel 12.1-12.3 M/s against 9.6-9.8 and
 * 12.3); left to the compilers, Intel's runtime lost 5% (scalar arguments) to 20% (arrays). */
typedef struct {
    float3 f, wi, weight;
    float pdf, ok, spdf;
} ShadeOut;

__attribute__((always_inline)) inline ShadeOut shade_floor(__global const Bsdf *bsdfs, __global const Texture *textures,
                            __global const float *texels, __global const float *bsdf_tables, int index,
                            float2 uv, float3 wo, float3 wi, float u1, float2 u2) {
    SceneData sc;
    sc.bsdfs = bsdfs;
    sc.textures = textures;
    sc.texels = texels;
    sc.bsdf_tables = bsdf_tables;
    /* bsdf_vertex_at's parameters (bsdf_vertex.h), in its order */
    BsdfVertex v;
    __global const Bsdf *b = &sc.bsdfs[index];
    v.b = b;
    v.opacity = 1.0f;
    v.bumped = false;
    v.shadowing = false;
    v.s = (float3)(1.0f, 0.0f, 0.0f);
    v.t = (float3)(0.0f, 1.0f, 0.0f);
    v.n = v.n_in = (float3)(0.0f, 0.0f, 1.0f);
    v.tan2_tilt = 0.0f;
    v.color = texture_eval3(&sc, b->color_tex, vload_f3(b->color), uv);
    v.eta3 = texture_eval3(&sc, b->eta_tex, vload_f3(b->cond_eta), uv);
    v.k3 = texture_eval3(&sc, b->k_tex, vload_f3(b->cond_k), uv);
    v.spec_r = texture_eval3(&sc, b->spec_r_tex, vload_f3(b->spec_r), uv);
    v.spec_t = texture_eval3(&sc, b->spec_t_tex, vload_f3(b->spec_t), uv);
    v.alpha_u = texture_eval1(&sc, b->alpha_u_tex, b->alpha_u, uv);
    v.alpha_v = texture_eval1(&sc, b->alpha_v_tex, b->alpha_v, uv);
    v.table = sc.bsdf_tables + max(b->table, 0);

    float pdf;
    float3 f = bsdf_eval_local(&v, wo, wi, &pdf);
    BsdfSample s;
    s.wi = (float3)(0.0f);
    s.weight = (float3)(0.0f);
    s.pdf = 0.0f;
    s.delta = false;
    bool ok = bsdf_sample_local(&v, wo, u1, u2, &s);
    ShadeOut o;
    o.f = f;
    o.pdf = pdf;
    o.ok = ok ? 1.0f : 0.0f;
    o.wi = ok ? s.wi : (float3)(0.0f);
    o.weight = ok ? s.weight : (float3)(0.0f);
    o.spdf = ok ? s.pdf : 0.0f;
    return o;
}

VOLCL_KERNEL void shade_renderer(__global const Bsdf *bsdfs, __global const Texture *textures,
                                 __global const float *texels, __global const float *bsdf_tables, int index,
                                 __global const float *in, __global float *out, int n) {
    int i = get_global_id(0);
    ShadeOut o = shade_floor(bsdfs, textures, texels, bsdf_tables, index, (float2)(IN(0), IN(1)),
                             (float3)(IN(2), IN(3), IN(4)), (float3)(IN(5), IN(6), IN(7)), IN(8),
                             (float2)(IN(9), IN(10)));
    OUT(0) = o.f.x;
    OUT(1) = o.f.y;
    OUT(2) = o.f.z;
    OUT(3) = o.pdf;
    OUT(4) = o.ok;
    OUT(5) = o.wi.x;
    OUT(6) = o.wi.y;
    OUT(7) = o.wi.z;
    OUT(8) = o.weight.x;
    OUT(9) = o.weight.y;
    OUT(10) = o.weight.z;
    OUT(11) = o.spdf;
}

/* ---- the round trip (benchmarks/shading_lanes.py --round-trip): what handing the shading to a
 * stage of its own adds to a scalar megakernel that holds the inputs in registers.
 *
 * trip_input makes item i's inputs from a PCG stream of its own (rng.h's rng_next_uint), in
 * the rows' order and distributions (make_inputs: uv and u in [0, 1), wo and wi uniform on the
 * upper hemisphere, every eighth wi mirrored below it); trip_fold folds the 12 outputs into the
 * item's result: their sum in row order and a hash of their bits (any differing bit shows).
 *   shade_inline  inputs made, shaded by the renderer's functions and folded in registers (the
 *                 megakernel: no traffic)
 *   shade_make    inputs made and written to the rows (the scalar stage handing them over)
 *   shade_fold    the 12 output rows read back and folded (the scalar stage taking them back)
 * split: shade_make, shade_lanes (or shade_renderer), shade_fold. */
inline void trip_input(uint seed, int i, float *x) {
    /* a PCG stream per item, seeded without rng_init's four splitmix rounds (the renderer seeds once
     * per sample, not per bounce) */
    Rng r;
    r.state = ((ulong)seed << 32) ^ ((ulong)(uint)i * 0x9e3779b97f4a7c15UL);
    r.inc = ((ulong)seed << 1) | 1u;
    rng_next_uint(&r);
    x[0] = rng_next_float(&r);
    x[1] = rng_next_float(&r);
    for (int k = 0; k < 2; k++) {
        float z = rng_next_float(&r);
        float phi = 2.0f * VOLCL_PI * rng_next_float(&r);
        float rr = sqrt(fmax(0.0f, 1.0f - z * z)), c, s = sincos(phi, &c);
        x[2 + 3 * k] = rr * c;
        x[3 + 3 * k] = rr * s;
        x[4 + 3 * k] = (k == 1 && (i & 7) == 0) ? -z : z;
    }
    x[8] = rng_next_float(&r);
    x[9] = rng_next_float(&r);
    x[10] = rng_next_float(&r);
}

#define TRIP_FOLD(y) \
    sum += (y);      \
    h = rotate(h ^ as_uint(y), 5u) * 0x01000193u;

inline void trip_fold(ShadeOut o, int i, __global uint *result) {
    float sum = 0.0f;
    uint h = 0x9e3779b9u;
    TRIP_FOLD(o.f.x) TRIP_FOLD(o.f.y) TRIP_FOLD(o.f.z) TRIP_FOLD(o.pdf) TRIP_FOLD(o.ok)
    TRIP_FOLD(o.wi.x) TRIP_FOLD(o.wi.y) TRIP_FOLD(o.wi.z)
    TRIP_FOLD(o.weight.x) TRIP_FOLD(o.weight.y) TRIP_FOLD(o.weight.z) TRIP_FOLD(o.spdf)
    vstore2((uint2)(as_uint(sum), h), i, result);
}

VOLCL_KERNEL void shade_inline(__global const Bsdf *bsdfs, __global const Texture *textures,
                               __global const float *texels, __global const float *bsdf_tables, int index,
                               uint seed, __global uint *result) {
    int i = get_global_id(0);
    float x[IN_ROWS];
    trip_input(seed, i, x);
    trip_fold(shade_floor(bsdfs, textures, texels, bsdf_tables, index, (float2)(x[0], x[1]),
                          (float3)(x[2], x[3], x[4]), (float3)(x[5], x[6], x[7]), x[8], (float2)(x[9], x[10])),
              i, result);
}

VOLCL_KERNEL void shade_make(uint seed, __global float *in, int n) {
    int i = get_global_id(0);
    float x[IN_ROWS];
    trip_input(seed, i, x);
    for (int r = 0; r < IN_ROWS; r++)
        IN(r) = x[r];
}

/* the 12 output rows' column i */
inline ShadeOut trip_read(__global const float *out, int n, int i) {
    ShadeOut o;
    o.f = (float3)(OUT(0), OUT(1), OUT(2));
    o.pdf = OUT(3);
    o.ok = OUT(4);
    o.wi = (float3)(OUT(5), OUT(6), OUT(7));
    o.weight = (float3)(OUT(8), OUT(9), OUT(10));
    o.spdf = OUT(11);
    return o;
}

VOLCL_KERNEL void shade_fold(__global const float *out, int n, __global uint *result) {
    int i = get_global_id(0);
    trip_fold(trip_read(out, n, i), i, result);
}

/* ---- the gather (benchmarks/shading_lanes.py --gather): a wave of mixed hits. gather_floor says
 * by a hash of (seed, i) alone whether item i is a floor hit (a share fq / 4 of them); the others
 * get gather_other, a fixed diffuse-like few flops, in every variant. Per-item results never
 * depend on the order in which atomic_inc hands out rows: each row carries its item's inputs and
 * index, and the fold writes item owner[k]'s result.
 *   shade_ginline  inputs made, floor items shaded by the renderer's functions, others by
 *                  gather_other, folded (the megakernel, divergence included)
 *   shade_gmake    inputs made; floor items' inputs written to row atomic_inc(count) with their
 *                  index in owner; others shaded and folded at once
 *   shade_gfold    rows k < count read back and folded into item owner[k]'s result
 * gather: shade_gmake, shade_lanes (or shade_renderer) over the first rows, shade_gfold. */
inline bool gather_floor(uint seed, int i, int fq) {
    uint h = ((uint)i * 0x9e3779b9u) ^ (seed * 0x85ebca6bu);
    h ^= h >> 16;
    h *= 0x7feb352du;
    h ^= h >> 15;
    h *= 0x846ca68bu;
    h ^= h >> 16;
    return (int)(h & 3u) < fq;
}

inline ShadeOut gather_other(const float *x) {
    ShadeOut o;
    float c = 0.5f + 0.25f * x[0], cos_i = fmax(x[7], 0.0f);
    float3 albedo = (float3)(c, 0.8f * c, 0.6f * c);
    o.f = albedo * (cos_i * VOLCL_INV_PI);
    o.pdf = cos_i * VOLCL_INV_PI;
    o.ok = 1.0f;
    o.wi = (float3)(-x[2], -x[3], x[4]);
    o.weight = albedo;
    o.spdf = x[4] * VOLCL_INV_PI;
    return o;
}

VOLCL_KERNEL void shade_ginline(__global const Bsdf *bsdfs, __global const Texture *textures,
                                __global const float *texels, __global const float *bsdf_tables, int index,
                                uint seed, int fq, __global uint *result) {
    int i = get_global_id(0);
    float x[IN_ROWS];
    trip_input(seed, i, x);
    ShadeOut o;
    if (gather_floor(seed, i, fq))
        o = shade_floor(bsdfs, textures, texels, bsdf_tables, index, (float2)(x[0], x[1]),
                        (float3)(x[2], x[3], x[4]), (float3)(x[5], x[6], x[7]), x[8], (float2)(x[9], x[10]));
    else
        o = gather_other(x);
    trip_fold(o, i, result);
}

VOLCL_KERNEL void shade_gmake(uint seed, int fq, __global float *in, int n, volatile __global int *count,
                              __global int *owner, __global uint *result) {
    int i = get_global_id(0);
    float x[IN_ROWS];
    trip_input(seed, i, x);
    if (gather_floor(seed, i, fq)) {
        int k = atomic_inc(count);
        for (int r = 0; r < IN_ROWS; r++)
            in[r * n + k] = x[r];
        owner[k] = i;
    } else {
        trip_fold(gather_other(x), i, result);
    }
}

/* shade_gmake with the counting aggregated per work-group: a local atomic_inc numbers the group's
 * floor items, one global atomic_add reserves the group's block of rows (one atomic per group, and
 * each group's rows contiguous instead of interleaved with the other cores' items) */
VOLCL_KERNEL void shade_gmake_wg(uint seed, int fq, __global float *in, int n, volatile __global int *count,
                                 __global int *owner, __global uint *result) {
    __local int lcount, lbase;
    int i = get_global_id(0);
    if (get_local_id(0) == 0)
        lcount = 0;
    barrier(CLK_LOCAL_MEM_FENCE);
    float x[IN_ROWS];
    trip_input(seed, i, x);
    bool floor_hit = gather_floor(seed, i, fq);
    int j = floor_hit ? atomic_inc((volatile __local int *)&lcount) : 0;
    barrier(CLK_LOCAL_MEM_FENCE);
    if (get_local_id(0) == 0)
        lbase = atomic_add(count, lcount);
    barrier(CLK_LOCAL_MEM_FENCE);
    if (floor_hit) {
        int k = lbase + j;
        for (int r = 0; r < IN_ROWS; r++)
            in[r * n + k] = x[r];
        owner[k] = i;
    } else {
        trip_fold(gather_other(x), i, result);
    }
}

VOLCL_KERNEL void shade_gfold(__global const float *out, int n, __global const int *count,
                              __global const int *owner, __global uint *result) {
    int i = get_global_id(0);    /* the row */
    if (i < *count)
        trip_fold(trip_read(out, n, i), owner[i], result);
}

/* ---- the lanes version: the packet renderer's rough step's routines (kernels/lanes_rough.h),
 * every function inlined (as the lanes stages build them) */
#pragma clang attribute push (__attribute__((always_inline)), apply_to = function)
#define VOLCL_WF_TINY 1                 /* (the rough step's table, unread here, needs a size) */
#define VOLCL_PACKET_BITMAPS 1
#include "lanes.h"
#include "wavefront_state.h"
#include "lanes_rows.h"
#include "lanes_surface.h"
#include "lanes_rough.h"

/* a perturbation of the lanes arithmetic, for the test that checks the comparison can fail */
#ifndef SHADE_PERTURB
#define SHADE_PERTURB 0
#endif

/* the record's numbers as the rough step's table holds them (the host checked what they are) */
inline LanesRough sh_record(__global const Bsdf *b) {
    LanesRough r;
    r.alpha = b->alpha_u;
    r.sw = b->spec_weight;
    r.eta = b->eta;
    r.inv_eta2 = b->inv_eta2;
    r.internal_refl = b->internal_refl;
    r.nonlinear = (b->flags & BSDF_FLAG_NONLINEAR) != 0;
    r.textured = true;
    r.spec_r = v3(b->spec_r[0], b->spec_r[1], b->spec_r[2]);
    r.table = max(b->table, 0);
    return r;
}

/* the texture's, likewise */
inline LanesBitmap sh_bitmap_record(__global const Texture *t) {
    LanesBitmap r;
    r.width = t->width;
    r.height = t->height;
    r.wrap = t->wrap;
    r.data = t->data;
    r.lut = t->lut;
    r.m0 = t->to_uv[0];
    r.m1 = t->to_uv[1];
    r.m2 = t->to_uv[2];
    r.m3 = t->to_uv[3];
    r.m4 = t->to_uv[4];
    r.m5 = t->to_uv[5];
    return r;
}

/* shade_lanes' work-item i (shade_glanes's too) */
inline void sh_shade(__global const Bsdf *bsdfs, __global const Texture *textures, __global const float *texels,
                     __global const float *bsdf_tables, int index, __global const float *in, __global float *out,
                     int n, int i) {
    __global const Bsdf *b = &bsdfs[index];
    LanesRough r = sh_record(b);
    LanesBitmap bm = sh_bitmap_record(&textures[b->color_tex]);
    float u = IN(0), v = IN(1);
    V3 wo = v3(IN(2), IN(3), IN(4)), wi = v3(IN(5), IN(6), IN(7));
    float u1 = IN(8), u20 = IN(9), u21 = IN(10);

    V3 color = lanes_bitmap(texels, &bm, u, v);
    float pdf;
    V3 f = lanes_rough_eval(&r, bsdf_tables, color, wo, wi, &pdf);
#if SHADE_PERTURB
    f.x *= 1.001f;
#endif
    V3 ws, sv;
    float spdf;
    bool ok = lanes_rough_sample(&r, bsdf_tables, color, wo, u1, u20, u21, lanes_after(pdf, f.x), &ws, &sv, &spdf);

    OUT(0) = f.x;
    OUT(1) = f.y;
    OUT(2) = f.z;
    OUT(3) = pdf;
    OUT(4) = ok ? 1.0f : 0.0f;
    OUT(5) = ok ? ws.x : 0.0f;
    OUT(6) = ok ? ws.y : 0.0f;
    OUT(7) = ok ? ws.z : 0.0f;
    OUT(8) = ok ? sv.x / spdf : 0.0f;
    OUT(9) = ok ? sv.y / spdf : 0.0f;
    OUT(10) = ok ? sv.z / spdf : 0.0f;
    OUT(11) = ok ? spdf : 0.0f;
}

__kernel void shade_lanes(__global const Bsdf *bsdfs, __global const Texture *textures,
                          __global const float *texels, __global const float *bsdf_tables, int index,
                          __global const float *in, __global float *out, int n) {
    sh_shade(bsdfs, textures, texels, bsdf_tables, index, in, out, n, get_global_id(0));
}

/* --gather's gather-count: launched over the whole wave, the count read on the device (no read
 * back to the host) */
__kernel void shade_glanes(__global const Bsdf *bsdfs, __global const Texture *textures,
                           __global const float *texels, __global const float *bsdf_tables, int index,
                           __global const float *in, __global float *out, int n,
                           __global const int *restrict count) {
    /* whole work-groups past the count skip (a condition the same for all their work-items, which
     * PoCL's loop vectorizer takes; a per-item i < count stopped it); the last group's items past
     * the count shade stale rows, their outputs unread */
    if ((int)(get_group_id(0) * get_local_size(0)) < *count)
        sh_shade(bsdfs, textures, texels, bsdf_tables, index, in, out, n, get_global_id(0));
}

#pragma clang attribute pop
