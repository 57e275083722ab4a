/* Test-only kernels: each work item seeds its own stream with rng_init(seed, gid, 0), draws what one
 * call of a device routine needs, and writes the routine's results. Directions and colours are
 * written as 3 floats per item (vstore3). */
#include "types.h"
#include "common.h"
#include "rng.h"
#include "sampling.h"
#include "scene.h"
#include "bvh.h"
#include "surface.h"
#include "bsdf.h"
#include "phase.h"
#include "media.h"
#include "lights.h"

/* ---- rng ---- */

/* `count` consecutive floats of the stream (seed, pixel0 + i % npix, sample0 + i / npix). */
VOLCL_KERNEL void rng_floats(__global float *out, uint seed, uint pixel0, uint sample0, int npix, int count) {
    int i = get_global_id(0);
    Rng r = rng_init(seed, pixel0 + (uint)(i % npix), sample0 + (uint)(i / npix));
    for (int k = 0; k < count; k++) out[i * count + k] = rng_next_float(&r);
}

/* ---- sampling.h ---- */

VOLCL_KERNEL void warp_cosine_hemisphere(__global float *dirs, __global float *pdf, uint seed) {
    int i = get_global_id(0);
    Rng r = rng_init(seed, i, 0);
    float3 d = sample_cosine_hemisphere(rng_next_float2(&r));
    vstore3(d, i, dirs);
    pdf[i] = sample_cosine_hemisphere_pdf(d);
}

VOLCL_KERNEL void warp_uniform_sphere(__global float *dirs, __global float *pdf, uint seed) {
    int i = get_global_id(0);
    Rng r = rng_init(seed, i, 0);
    vstore3(sample_uniform_sphere(rng_next_float2(&r)), i, dirs);
    pdf[i] = sample_uniform_sphere_pdf();
}

VOLCL_KERNEL void warp_uniform_triangle(__global float *bary, uint seed) {
    int i = get_global_id(0);
    Rng r = rng_init(seed, i, 0);
    vstore2(sample_uniform_triangle(rng_next_float2(&r)), i, bary);
}

VOLCL_KERNEL void warp_concentric_disk(__global float *pts, uint seed) {
    int i = get_global_id(0);
    Rng r = rng_init(seed, i, 0);
    vstore2(sample_concentric_disk(rng_next_float2(&r)), i, pts);
}

VOLCL_KERNEL void warp_uniform_cone(__global float *dirs, __global float *pdf, uint seed, float cos_max) {
    int i = get_global_id(0);
    Rng r = rng_init(seed, i, 0);
    vstore3(sample_uniform_cone(rng_next_float2(&r), cos_max), i, dirs);
    pdf[i] = sample_uniform_cone_pdf(cos_max);
}

VOLCL_KERNEL void warp_discrete_cdf(__global const float *cdf, __global int *index, uint seed, int n) {
    int i = get_global_id(0);
    Rng r = rng_init(seed, i, 0);
    index[i] = sample_discrete_cdf(cdf, n, rng_next_float(&r));
}

/* both searches at given u, the guided one from the guide table given */
VOLCL_KERNEL void discrete_cdf_at(__global const float *cdf, __global const float *guide, __global const float *u,
                                  __global int *plain, __global int *guided, int n) {
    int i = get_global_id(0);
    plain[i] = sample_discrete_cdf(cdf, n, u[i]);
    guided[i] = sample_discrete_cdf_guided(cdf, guide, n, u[i]);
}

VOLCL_KERNEL void warp_filter_offset(__global const float *table, __global float *offset, uint seed, int size,
                                 float radius) {
    int i = get_global_id(0);
    Rng r = rng_init(seed, i, 0);
    offset[i] = sample_filter_offset(table, size, radius, rng_next_float(&r));
}

VOLCL_KERNEL void warp_filter_offset_within(__global const float *table, __global float *offset, uint seed, int size,
                                        float radius, float lo, float hi) {
    int i = get_global_id(0);
    Rng r = rng_init(seed, i, 0);
    offset[i] = sample_filter_offset_within(table, size, radius, rng_next_float(&r), lo, hi);
}

/* ---- media.h ---- */

VOLCL_KERNEL void medium_distance(__global const Medium *m, __global float *t, __global int *scattered,
                              __global float *weight, __global float *emission, uint seed, float t_max,
                              float beta_r, float beta_g, float beta_b) {
    int i = get_global_id(0);
    Rng r = rng_init(seed, i, 0);
    float u_channel = rng_next_float(&r);
    float u_dist = rng_next_float(&r);
    MediumSample ms = medium_sample_distance(m, t_max, (float3)(beta_r, beta_g, beta_b), u_channel, u_dist);
    t[i] = ms.t;
    scattered[i] = ms.scattered ? 1 : 0;
    vstore3(ms.weight, i, weight);
    vstore3(ms.emission, i, emission);
}

VOLCL_KERNEL void medium_tr(__global const Medium *m, __global const float *t, __global float *tr) {
    int i = get_global_id(0);
    vstore3(medium_transmittance(m, t[i]), i, tr);
}

/* ---- phase.h ---- */

/* The phase functions read the medium, its lobes and their tables through the scene bundle. */
#define PHASE_SCENE SceneData sc; sc.media = m; sc.phase_lobes = lobes; sc.phase_tables = tables

/* d_out around the travel direction d_in (3 floats), the returned pdf and weight, and phase_eval_pdf
 * of the sampled direction (value and pdf). */
VOLCL_KERNEL void phase_sample_dirs(__global const Medium *m, __global const PhaseLobe *lobes,
                                __global const float *tables, __global const float *d_in, __global float *d_out,
                                __global float *pdf, __global float *eval, __global float *eval_pdf,
                                __global float *weight, uint seed) {
    int i = get_global_id(0);
    PHASE_SCENE;
    Rng r = rng_init(seed, i, 0);
    float3 din = vload3(0, d_in), d;
    float w, ep;
    pdf[i] = phase_sample(&sc, m, din, rng_next_float2(&r), &r, &d, &w);
    vstore3(d, i, d_out);
    weight[i] = w;
    eval[i] = phase_eval_pdf(&sc, m, din, d, &ep);
    eval_pdf[i] = ep;
}

/* phase_eval_pdf from d_in (3 floats) towards each d_out[i]. */
VOLCL_KERNEL void phase_eval_dirs(__global const Medium *m, __global const PhaseLobe *lobes,
                              __global const float *tables, __global const float *d_in,
                              __global const float *d_out, __global float *value, __global float *pdf) {
    int i = get_global_id(0);
    PHASE_SCENE;
    float p;
    value[i] = phase_eval_pdf(&sc, m, vload3(0, d_in), vload3(i, d_out), &p);
    pdf[i] = p;
}

/* phase_eval between +z and the direction at cos_theta[i] from it. */
VOLCL_KERNEL void phase_eval_cos(__global const Medium *m, __global const PhaseLobe *lobes,
                             __global const float *tables, __global const float *cos_theta, __global float *value) {
    int i = get_global_id(0);
    PHASE_SCENE;
    float c = cos_theta[i];
    float3 d_out = (float3)(sqrt(fmax(0.0f, 1.0f - c * c)), 0.0f, c);
    value[i] = phase_eval(&sc, m, (float3)(0.0f, 0.0f, 1.0f), d_out);
}

/* HG at distance w[i] from its peak. */
VOLCL_KERNEL void phase_hg_eval_at_w(__global const float *w, __global float *value, float g) {
    int i = get_global_id(0);
    value[i] = phase_hg_eval_w(g, w[i]);
}

VOLCL_KERNEL void hg_sample_cos(__global float *c, uint seed, float g) {
    int i = get_global_id(0);
    Rng r = rng_init(seed, i, 0);
    float w = phase_hg_sample_w(fabs(g), rng_next_float(&r));
    c[i] = g >= 0.0f ? 1.0f - w : w - 1.0f;
}

/* The Fournier-Forand lobe's value and table pdf at s[i] = sin^2(theta / 2) (at the floor, where
 * the lobe counts value = pdf, both are the pdf). */
VOLCL_KERNEL void phase_ff_at_s(__global const PhaseLobe *lobes, __global const float *tables,
                            __global const float *s, __global float *value, __global float *pdf) {
    int i = get_global_id(0);
    SceneData sc;
    sc.phase_tables = tables;
    float p;
    value[i] = phase_ff_eval_pdf(&sc, &lobes[0], s[i], &p);
    pdf[i] = p;
}

/* Rayleigh cosines from u[i]. */
VOLCL_KERNEL void phase_rayleigh_cos(__global const float *u, __global float *c) {
    int i = get_global_id(0);
    c[i] = phase_rayleigh_sample_cos(u[i]);
}

/* ---- bsdf.h ---- */

/* One bsdf_sample per item for wo[i] with the bsdf's constants in the identity frame; u1[i] >= 0
 * replaces the random component choice (edge cases). info: (sampled, delta, null event). The sampled
 * wi is evaluated again with bsdf_eval. */
VOLCL_KERNEL void bsdf_sample_dirs(__global const Bsdf *b, __global const float *tables, __global const float *wo_in,
                               __global const float *u1_in, __global float *wi_out, __global float *weight,
                               __global float *pdf, __global float *eta, __global int *info, __global float *value,
                               __global float *eval_pdf, uint seed) {
    int i = get_global_id(0);
    Rng r = rng_init(seed, i, 0);
    float u1 = rng_next_float(&r);
    float2 u2 = rng_next_float2(&r);
    if (u1_in[i] >= 0.0f) u1 = u1_in[i];
    float3 wo = vload3(i, wo_in);
    BsdfVertex v = bsdf_vertex_local(b, tables, wo);
    BsdfSample s;
    s.wi = (float3)(0.0f);
    s.weight = (float3)(0.0f);
    s.pdf = 0.0f;
    s.eta = 1.0f;
    s.delta = false;
    s.null_event = false;
    bool ok = bsdf_sample(&v, wo, u1, u2, &s);
    vstore3(ok ? s.wi : (float3)(0.0f), i, wi_out);
    vstore3(ok ? s.weight : (float3)(0.0f), i, weight);
    pdf[i] = ok ? s.pdf : 0.0f;
    eta[i] = s.eta;
    info[3 * i] = ok ? 1 : 0;
    info[3 * i + 1] = (ok && s.delta) ? 1 : 0;
    info[3 * i + 2] = (ok && s.null_event) ? 1 : 0;
    float p;
    vstore3(bsdf_eval(&v, wo, ok ? s.wi : (float3)(0.0f, 0.0f, 1.0f), &p), i, value);
    eval_pdf[i] = p;
}

/* bsdf_eval for host-given pairs (wo, wi). */
VOLCL_KERNEL void bsdf_eval_pairs(__global const Bsdf *b, __global const float *tables, __global const float *wo,
                              __global const float *wi, __global float *value, __global float *pdf) {
    int i = get_global_id(0);
    float3 o = vload3(i, wo);
    BsdfVertex v = bsdf_vertex_local(b, tables, o);
    float p;
    vstore3(bsdf_eval(&v, o, vload3(i, wi), &p), i, value);
    pdf[i] = p;
}

VOLCL_KERNEL void fresnel_dielectric_grid(__global const float *cos_i, __global float *f, __global float *cos_t,
                                      float eta) {
    int i = get_global_id(0);
    float ct;
    f[i] = fresnel_dielectric(cos_i[i], eta, &ct);
    cos_t[i] = ct;
}

VOLCL_KERNEL void fresnel_conductor_grid(__global const float *cos_i, __global const float *eta_k, __global float *f) {
    int i = get_global_id(0);
    vstore3(fresnel_conductor(cos_i[i], vload3(0, eta_k), vload3(1, eta_k)), i, f);
}
