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
 * `shade_lanes` is the same arithmetic in the lanes style (kernels/lanes.h: V3, scalar floats,
 * selects, no branch and no load under a condition, every function inlined, no vec_type_hint),
 * specialized to what the host checked the record to be: roughplastic, GGX, visible-normal
 * sampling, isotropic constant roughness, constant specular reflectance, diffuse reflectance a
 * bilinear bitmap of 3 channels (SHADE_LUT 1: byte-coded through a lookup table, 0: floats). The
 * texture's wrap mode and the bsdf's nonlinear switch are read from the records and applied as
 * selects. Both of roughplastic_sample's lobes are sampled and one chosen. Inputs (rows of n):
 * u, v, wo.xyz, wi.xyz, u1, u2.x, u2.y. Outputs (rows of n): eval value.xyz, eval pdf, sample ok
 * (1 or 0), sample wi.xyz, weight.xyz, pdf (zeros where the sample fails).
 *
 * What PoCL's loop vectorizer needed beyond lanes.h's rules at first reading (found in its
 * parallel.bc): the SLP vectorizer paired every x with its y (alpha_u and alpha_v's neighbouring
 * loads, au * v.x with av * v.y, D's m.x / au with m.y / av, the visible-normal sampler's stretched
 * direction, cos_phi with sin_phi), the two G1 terms, the two transmittance lookups, and the light's
 * evaluation with the sample's (two normalizations' rsqrt, two Fresnel fabs). Each second one waits
 * on the first (lanes_after, exactly the value), and alpha_v is alpha_u's value (isotropic only).
 * SHADE_PERTURB 1 scales D by 1.001 in the lanes kernel only (tests/test_shading_lanes.py). */
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

/* ---- the lanes version: every function below inlined (as the lanes stages build them) */
#pragma clang attribute push (__attribute__((always_inline)), apply_to = function)
#include "lanes.h"

#ifndef SHADE_LUT
#define SHADE_LUT 1
#endif
/* a perturbation of the lanes arithmetic, for the test that checks the comparison can fail */
#ifndef SHADE_PERTURB
#define SHADE_PERTURB 0
#endif

/* dot(a, b) as the OpenCL library computes it (no fused multiply-add; lanes_triangles.h) */
inline float sh_dot(V3 a, V3 b) {
#pragma OPENCL FP_CONTRACT OFF
    return (a.x * b.x + a.y * b.y) + a.z * b.z;
}

/* normalize (the OpenCL library's, on the unit-scale vectors met here) */
inline V3 sh_normalize(V3 a) { return v3_scale(a, rsqrt(sh_dot(a, a))); }

/* texture_wrap (textures.h) for every mode, chosen by selects; the integer division by `res` done
 * as a float quotient corrected to the exact floor (exact while |p| / res < 2^22) */
inline int sh_wrap(int p, int res, float inv_res, int mode) {
    int q = (int)floor((float)p * inv_res);
    int m = p - q * res;
    q = m < 0 ? q - 1 : q;
    m = m < 0 ? m + res : m;
    q = m >= res ? q + 1 : q;
    m = m >= res ? m - res : m;
    /* the floored period index: odd periods run backwards */
    int mirrored = (q & 1) ? res - 1 - m : m;
    int clamped = clamp(p, 0, res - 1);
    return mode == TEX_WRAP_CLAMP ? clamped : (mode == TEX_WRAP_MIRROR ? mirrored : m);
}

/* texel_at (textures.h): a colour bitmap's texel, already wrapped */
inline V3 sh_texel(__global const float *texels, int data, int lut, int width, int x, int y) {
    int at = (y * width + x) * 3;
#if SHADE_LUT
    __global const uchar *bytes = (__global const uchar *)(texels + data) + at;
    __global const float *table = texels + lut;
    return v3(table[bytes[0]], table[bytes[1]], table[bytes[2]]);
#else
    __global const float *p = texels + data + at;
    return v3(p[0], p[1], p[2]);
#endif
}

/* bitmap_lookup (textures.h), bilinear */
inline V3 sh_bitmap(__global const Texture *t, __global const float *texels, float u, float v) {
    float px0 = t->to_uv[0] * u + t->to_uv[1] * v + t->to_uv[2];
    float py0 = t->to_uv[3] * u + t->to_uv[4] * v + t->to_uv[5];
    int width = t->width, height = t->height, wrap = t->wrap, data = t->data, lut = t->lut;
    float px = texel_coordinate(px0 * (float)width), py = texel_coordinate(py0 * (float)height);
    px -= 0.5f;
    py -= 0.5f;
    float fx = floor(px), fy = floor(py);
    int x = (int)fx, y = (int)fy;
    float wx = px - fx, wy = py - fy;
    float inv_w = 1.0f / (float)width, inv_h = 1.0f / (float)height;
    int x0 = sh_wrap(x, width, inv_w, wrap), x1 = sh_wrap(x + 1, width, inv_w, wrap);
    int y0 = sh_wrap(y, height, inv_h, wrap), y1 = sh_wrap(y + 1, height, inv_h, wrap);
    V3 c00 = sh_texel(texels, data, lut, width, x0, y0);
    V3 c10 = sh_texel(texels, data, lut, width, x1, y0);
    V3 c01 = sh_texel(texels, data, lut, width, x0, y1);
    V3 c11 = sh_texel(texels, data, lut, width, x1, y1);
    float ax = c00.x * (1.0f - wx) + c10.x * wx, ay = c00.y * (1.0f - wx) + c10.y * wx,
          az = c00.z * (1.0f - wx) + c10.z * wx;
    float bx = c01.x * (1.0f - wx) + c11.x * wx, by = c01.y * (1.0f - wx) + c11.y * wx,
          bz = c01.z * (1.0f - wx) + c11.z * wx;
    return v3(ax * (1.0f - wy) + bx * wy, ay * (1.0f - wy) + by * wy, az * (1.0f - wy) + bz * wy);
}

/* microfacet_D (microfacet.h), GGX */
inline float sh_ggx_D(float au, float av, V3 m) {
    float ct2 = m.z * m.z;
    /* the y term waits on the x term (lanes_after, exactly the value): the pair was packed into a
     * <2 x float> by the SLP vectorizer (lanes.h) */
    float qx = m.x / au, qy = lanes_after(m.y / av, qx);
    float r = 1.0f / (VOLCL_PI * au * av * sqr(sqr(qx) + sqr(qy) + ct2));
#if SHADE_PERTURB
    r *= 1.001f;
#endif
    return r * m.z > 1e-20f ? r : 0.0f;
}

/* microfacet_G1 (microfacet.h), GGX; made to wait on `dep` (exactly the same value) so that two
 * calls side by side are not packed together */
inline float sh_ggx_G1(float au, float av, V3 v, V3 m, float dep) {
    float tx = lanes_after(au * v.x, dep), ty = lanes_after(av * v.y, tx);
    float xy = sqr(tx) + sqr(ty);
    float tan2 = xy / sqr(v.z);
    float r = 2.0f / (1.0f + sqrt(1.0f + tan2));
    r = xy == 0.0f ? 1.0f : r;
    return sh_dot(v, m) * v.z <= 0.0f ? 0.0f : r;
}

/* fresnel_r (bsdf.h: fresnel_signed's reflectance) */
inline float sh_fresnel_r(float cos_i, float eta) {
    bool outside = cos_i >= 0.0f;
    float rcp_eta = 1.0f / eta;
    float eta_it = outside ? eta : rcp_eta;
    float eta_ti = outside ? rcp_eta : eta;
    float ct2 = 1.0f - (1.0f - cos_i * cos_i) * (eta_ti * eta_ti);
    float ci = fabs(cos_i), ct = sqrt(fmax(ct2, 0.0f));
    float a_s = (ci - eta_it * ct) / (ci + eta_it * ct);
    float a_p = (ct - eta_it * ci) / (ct + eta_it * ci);
    float r = 0.5f * (a_s * a_s + a_p * a_p);
    return eta == 1.0f ? 0.0f : (ci == 0.0f ? 1.0f : r);
}

/* roughplastic_transmittance (bsdf_rough.h) */
inline float sh_transmittance(__global const float *table, float cos_theta) {
    float x = cos_theta * 63.0f;
    int k = min((int)x, 62);
    /* a cosine at or below 0 (an input the caller discards) read at entry 0, not before the table */
    k = max(k, 0);
    float a = table[k], b = table[k + 1];
    return a + (b - a) * (x - (float)k);
}

inline float sh_prob_specular(float sw, float t_i) {
    float ps = (1.0f - t_i) * sw, pd = t_i * (1.0f - sw);
    return ps / (ps + pd);
}

/* microfacet_reflection_pdf (bsdf_rough.h), visible normals */
inline float sh_reflection_pdf(float au, float av, V3 wo, V3 h) {
    return sh_ggx_D(au, av, h) * sh_ggx_G1(au, av, wo, h, 0.0f) / (4.0f * wo.z);
}

inline float sh_cosine_pdf(V3 v) { return v.z > 0.0f ? v.z * VOLCL_INV_PI : 0.0f; }

typedef struct {
    float sw, eta, inv_eta2, internal_refl, au, av;
    bool nonlinear;
    V3 spec_r;
} ShadeBsdf;

/* roughplastic_eval (bsdf_rough.h) */
inline V3 sh_eval(const ShadeBsdf *pb, __global const float *table, V3 color, V3 wo, V3 wi, float *pdf) {
    float au = pb->au, av = pb->av;
    V3 h = sh_normalize(v3_add(wo, wi));
    float D = sh_ggx_D(au, av, h);
    float F = sh_fresnel_r(sh_dot(wo, h), pb->eta);
    float g_o = sh_ggx_G1(au, av, wo, h, 0.0f);
    float G = g_o * sh_ggx_G1(au, av, wi, h, g_o);
    float k = F * D * G / (4.0f * wo.z);
    V3 value = v3_scale(pb->spec_r, k);
    float t_i = sh_transmittance(table, wo.z), t_o = sh_transmittance(table, lanes_after(wi.z, t_i));
    V3 diff = v3_sel(pb->nonlinear,
                     v3(color.x / (1.0f - color.x * pb->internal_refl), color.y / (1.0f - color.y * pb->internal_refl),
                        color.z / (1.0f - color.z * pb->internal_refl)),
                     lanes_div(color, 1.0f - pb->internal_refl));
    float kd = VOLCL_INV_PI * pb->inv_eta2 * wi.z * t_i * t_o;
    value.x += diff.x * kd;
    value.y += diff.y * kd;
    value.z += diff.z * kd;
    float p_spec = sh_prob_specular(pb->sw, t_i);
    float p = p_spec * sh_reflection_pdf(au, av, wo, h) + (1.0f - p_spec) * sh_cosine_pdf(wi);
    bool valid = (wo.z > 0.0f) & (wi.z > 0.0f);
    *pdf = valid ? p : 0.0f;
    return v3_sel(valid, value, v3(0.0f, 0.0f, 0.0f));
}

/* microfacet_sample (microfacet.h), GGX, visible normals: the normal only (roughplastic drops its pdf) */
inline V3 sh_ggx_sample(float au, float av, V3 wi, float u0, float u1) {
    /* each y below waits on its x (lanes_after): the pairs were packed into <2 x float> */
    float sx0 = au * wi.x;
    V3 a = v3(sx0, lanes_after(av * wi.y, sx0), wi.z);
    float ra = rsqrt(sh_dot(a, a));
    float wpx = a.x * ra, wpy = lanes_after(a.y, wpx) * ra, wpz = a.z * ra;
    float st2 = wpx * wpx + wpy * wpy;
    float inv = rsqrt(st2);
    bool tilted = st2 > 4.0f * 5.9604645e-8f;
    float cx = clamp(wpx * inv, -1.0f, 1.0f);
    float cy = clamp(lanes_after(wpy, cx) * inv, -1.0f, 1.0f);
    float cos_phi = tilted ? cx : 1.0f;
    float sin_phi = tilted ? cy : 0.0f;
    /* microfacet_visible_slope_11, GGX */
    float cos_i = wpz;
    float px, py;
    lanes_concentric_disk(u0, u1, &px, &py);
    float s = 0.5f * (1.0f + cos_i);
    py = (1.0f - s) * sqrt(fmax(1.0f - px * px, 0.0f)) + s * py;
    float z = sqrt(fmax(1.0f - px * px - py * py, 0.0f));
    float sin_i = sqrt(fmax(1.0f - cos_i * cos_i, 0.0f));
    float norm = 1.0f / (sin_i * py + cos_i * z);
    float slx = (cos_i * py - sin_i * z) * norm, sly = px * norm;
    float sx = (cos_phi * slx - sin_phi * sly) * au;
    float sy = lanes_after((sin_phi * slx + cos_phi * sly) * av, sx);
    return sh_normalize(v3(-sx, -sy, 1.0f));
}

/* shade_lanes' work-item i (shade_glanes's too) */
inline void sh_shade(__global const Bsdf *bsdfs, __global const Texture *textures, __global const float *texels,
                     __global const float *bsdf_tables, int index, __global const float *in, __global float *out,
                     int n, int i) {
    __global const Bsdf *b = &bsdfs[index];
    ShadeBsdf pb;
    pb.sw = b->spec_weight;
    pb.eta = b->eta;
    pb.inv_eta2 = b->inv_eta2;
    pb.internal_refl = b->internal_refl;
    /* isotropic (the host checked alpha_u == alpha_v): alpha_v's value read from alpha_u, since two
     * neighbouring loads feeding the same operations were packed into a <2 x float> by the SLP
     * vectorizer (lanes.h), which stops the loop vectorizer */
    pb.au = fmax(b->alpha_u, 1e-4f);
    pb.av = pb.au;
    pb.nonlinear = (b->flags & BSDF_FLAG_NONLINEAR) != 0;
    pb.spec_r = v3(b->spec_r[0], b->spec_r[1], b->spec_r[2]);
    __global const float *table = bsdf_tables + max(b->table, 0);
    float u = IN(0), v = IN(1);
    V3 wo = v3(IN(2), IN(3), IN(4)), wi = v3(IN(5), IN(6), IN(7));
    float u1 = IN(8), u20 = IN(9), u21 = IN(10);

    V3 color = sh_bitmap(&textures[b->color_tex], texels, u, v);

    float pdf;
    V3 f = sh_eval(&pb, table, color, wo, wi, &pdf);

    /* roughplastic_sample: both lobes' directions, one taken. The sampling waits on the light's
     * evaluation (lanes_after: the same numbers), whose operations the SLP vectorizer otherwise
     * pairs with the sampler's into <2 x float> */
    float done = lanes_after(pdf, f.x);
    V3 wo_s = lanes_after3(wo, done);
    float u20_s = lanes_after(u20, done), u21_s = lanes_after(u21, done);
    float p_spec = sh_prob_specular(pb.sw, sh_transmittance(table, wo_s.z));
    V3 m = sh_ggx_sample(pb.au, pb.av, wo_s, u20_s, u21_s);
    float t = 2.0f * sh_dot(wo_s, m);
    V3 w_spec = v3(t * m.x - wo_s.x, t * m.y - wo_s.y, t * m.z - wo_s.z);
    float dx, dy;
    lanes_concentric_disk(u20_s, u21_s, &dx, &dy);
    V3 w_diff = v3(dx, dy, sqrt(fmax(0.0f, 1.0f - dx * dx - dy * dy)));
    V3 ws = v3_sel(u1 < p_spec, w_spec, w_diff);
    float spdf;
    /* the sample's evaluation waits on the light's (two evaluations side by side get packed) */
    V3 sv = sh_eval(&pb, table, color, wo, lanes_after3(ws, done), &spdf);
    bool ok = (wo.z > 0.0f) & (spdf > 0.0f) & (v3_max(sv) > 0.0f);

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
