/* The packet renderer's vector step at a rough plastic triangle (packet_lanes.h): Mitsuba's
 * roughplastic with a GGX coating sampled by its visible normals, isotropic roughness and specular
 * reflectance constant, the diffuse reflectance a constant or a bilinear bitmap of three
 * byte-coded channels (volcl/wavefront.py _rough_surfaces checks each triangle), written for the
 * SIMD lanes (lanes.h). Each routine is the renderer's one it names, operation for operation
 * (bsdf_rough.h, microfacet.h, textures.h, bsdf_vertex.h), so that a path scatters there in the
 * lanes as it does in the megakernel.
 *
 * What PoCL's loop vectorizer needed beyond lanes.h's rules (benchmarks/kernels/shading_lanes.cl
 * found them first): the SLP vectorizer paired every x with its y (D's m.x / au with m.y / av, the
 * visible-normal sampler's stretched direction, cos_phi with sin_phi), the two G1 terms, the two
 * transmittance lookups, and the light's evaluation with the sample's. Each second one waits on the
 * first (lanes_after: exactly the value). */
#ifndef VOLCL_LANES_ROUGH_H
#define VOLCL_LANES_ROUGH_H

#include "lanes_bitmap.h"

/* A rough plastic triangle's bsdf numbers (wavefront_state.h WF_TRI_ROUGH...) */
typedef struct {
    float alpha, sw, eta, inv_eta2, internal_refl;
    bool nonlinear, textured;
    V3 spec_r;
    int table;
} LanesRough;

inline LanesRough lanes_rough_gather(__global const float *table, int slot) {
    LanesRough r;
#define TV(c) table[WF_TRI_AT(c, slot)]
    r.alpha = TV(WF_TRI_ROUGH_ALPHA);
    r.sw = TV(WF_TRI_ROUGH_SW);
    r.eta = TV(WF_TRI_ROUGH_ETA);
    r.inv_eta2 = TV(WF_TRI_ROUGH_INV_ETA2);
    r.internal_refl = TV(WF_TRI_ROUGH_INTERNAL);
    r.nonlinear = TV(WF_TRI_ROUGH_NONLINEAR) > 0.0f;
    r.textured = TV(WF_TRI_ROUGH_TEXTURED) > 0.0f;
    r.spec_r = v3(TV(WF_TRI_ROUGH_SPEC_R), TV(WF_TRI_ROUGH_SPEC_R + 1), TV(WF_TRI_ROUGH_SPEC_R + 2));
    r.table = as_int(TV(WF_TRI_ROUGH_TABLE));
#undef TV
    return r;
}


/* The diffuse reflectance at the hit's barycentrics: the bitmap's (lanes_bitmap.h), or the
 * constant */
inline V3 lanes_rough_color(__global const float *texels, const LanesTriangle *t, const LanesRough *r, float b1,
                            float b2, __global const float *table, int slot) {
#if VOLCL_PACKET_BITMAPS
    LanesBitmap bm = lanes_bitmap_gather(table, slot);
    return v3_sel(r->textured, lanes_bitmap_at(texels, &bm, b1, b2), t->color);
#else
    (void)texels;
    (void)r;
    (void)b1;
    (void)b2;
    (void)table;
    (void)slot;
    return t->color;
#endif
}

/* microfacet_D (microfacet.h), GGX */
inline float lanes_ggx_D(float a, V3 m) {
    float ct2 = m.z * m.z;
    float qx = m.x / a, qy = lanes_after(m.y / a, qx);
    float r = 1.0f / (VOLCL_PI * a * a * sqr(sqr(qx) + sqr(qy) + ct2));
    return r * m.z > 1e-20f ? r : 0.0f;
}

/* microfacet_G1 (microfacet.h), GGX; waits on `dep` so that two calls side by side stay apart */
inline float lanes_ggx_G1(float a, V3 v, V3 m, float dep) {
    float tx = lanes_after(a * v.x, dep), ty = lanes_after(a * v.y, tx);
    float xy = sqr(tx) + sqr(ty);
    float tan2 = xy / sqr(v.z);
    float r = 2.0f / (1.0f + sqrt(1.0f + tan2));
    r = xy == 0.0f ? 1.0f : r;
    return lanes_dot(v, m) * v.z <= 0.0f ? 0.0f : r;
}

/* fresnel_r (bsdf.h: fresnel_signed's reflectance) */
inline float lanes_fresnel_r(float cos_i, float eta) {
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

/* roughplastic_transmittance (bsdf_rough.h); a cosine at or below 0 (whose result the caller
 * discards) reads entry 0, not before the table */
inline float lanes_rough_transmittance(__global const float *tables, int table, float cos_theta) {
    float x = cos_theta * 63.0f;
    int k = max(min((int)x, 62), 0);
    float a = tables[table + k], b = tables[table + k + 1];
    return a + (b - a) * (x - (float)k);
}

inline float lanes_prob_specular(float sw, float t_i) {
    float ps = (1.0f - t_i) * sw, pd = t_i * (1.0f - sw);
    return ps / (ps + pd);
}

/* roughplastic_eval (bsdf_rough.h) in the local frame: f |cos wi| and its pdf, zeros where wo or
 * wi lies below the surface */
inline V3 lanes_rough_eval(const LanesRough *r, __global const float *tables, V3 color, V3 wo, V3 wi, float *pdf) {
    float a = fmax(r->alpha, 1e-4f);
    V3 h = lanes_normalize(v3_add(wo, wi));
    float D = lanes_ggx_D(a, h);
    float F = lanes_fresnel_r(lanes_dot(wo, h), r->eta);
    float g_o = lanes_ggx_G1(a, wo, h, 0.0f);
    float G = g_o * lanes_ggx_G1(a, wi, h, g_o);
    V3 value = v3_scale(r->spec_r, F * D * G / (4.0f * wo.z));
    float t_i = lanes_rough_transmittance(tables, r->table, wo.z);
    float t_o = lanes_rough_transmittance(tables, r->table, lanes_after(wi.z, t_i));
    float ir = r->internal_refl;
    V3 diff = v3_sel(r->nonlinear,
                     v3(color.x / (1.0f - color.x * ir), color.y / (1.0f - color.y * ir), color.z / (1.0f - color.z * ir)),
                     lanes_div(color, 1.0f - ir));
    float kd = VOLCL_INV_PI * r->inv_eta2 * wi.z * t_i * t_o;
    value.x += diff.x * kd;
    value.y += diff.y * kd;
    value.z += diff.z * kd;
    float p_spec = lanes_prob_specular(r->sw, t_i);
    /* microfacet_reflection_pdf (visible normals) and sample_cosine_hemisphere_pdf */
    float pdf_spec = D * g_o / (4.0f * wo.z), pdf_diff = wi.z > 0.0f ? wi.z * VOLCL_INV_PI : 0.0f;
    float p = p_spec * pdf_spec + (1.0f - p_spec) * pdf_diff;
    bool valid = (wo.z > 0.0f) & (wi.z > 0.0f);
    *pdf = valid ? p : 0.0f;
    return v3_sel(valid, value, v3(0.0f, 0.0f, 0.0f));
}

/* microfacet_sample (microfacet.h), GGX, visible normals: the normal alone (roughplastic drops its
 * pdf) */
inline V3 lanes_ggx_sample(float a, V3 wi, float u0, float u1) {
    float sx0 = a * wi.x;
    V3 s = v3(sx0, lanes_after(a * wi.y, sx0), wi.z);
    float rs = rsqrt(lanes_dot(s, s));
    float wpx = s.x * rs, wpy = lanes_after(s.y, wpx) * rs, wpz = s.z * rs;
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
    float h = 0.5f * (1.0f + cos_i);
    py = (1.0f - h) * sqrt(fmax(1.0f - px * px, 0.0f)) + h * py;
    float z = sqrt(fmax(1.0f - px * px - py * py, 0.0f));
    float sin_i = sqrt(fmax(1.0f - cos_i * cos_i, 0.0f));
    float norm = 1.0f / (sin_i * py + cos_i * z);
    float slx = (cos_i * py - sin_i * z) * norm, sly = px * norm;
    float mx = (cos_phi * slx - sin_phi * sly) * a;
    float my = lanes_after((sin_phi * slx + cos_phi * sly) * a, mx);
    return lanes_normalize(v3(-mx, -my, 1.0f));
}

/* path_surface_nee at a rough plastic vertex (lanes_nee_light's light), with bsdf_eval in the
 * frame (s, t, n): whether it leaves a shadow ray, and what the ray brings where nothing blocks
 * it. *f_x: the light's f.x, which the bounce waits on. */
inline bool lanes_rough_nee(__global const float *table, __global const float *tables, __global const RenderParams *rp,
                            const LanesRough *r, V3 color, V3 p, V3 s, V3 t, V3 n, V3 wo, bool scatter, bool do_nee,
                            Rng32 *rng, LanesLight *ls, V3 *value, float *f_x) {
    bool nee = lanes_nee_light(table, rp, p, scatter, do_nee, rng, ls);
    float value_max = v3_max(ls->value);
    float pdf_b;
    V3 f = lanes_rough_eval(r, tables, color, wo, lanes_to_local(ls->wi, s, t, n), &pdf_b);
    nee = nee & (value_max > 0.0f) & (lanes_after(v3_max(f), value_max) > 0.0f);
    float w = (ls->delta | !rp->mis) ? 1.0f : lanes_power_heuristic(ls->pdf, pdf_b);
    *value = v3_scale(v3_mul(f, ls->value), w / ls->pdf);
    *f_x = lanes_after(pdf_b, f.x);
    return nee;
}

/* roughplastic_sample (bsdf_rough.h) in the local frame, for the numbers u1 (the lobe) and
 * (u20, u21): a lobe picked by the coating's reflectance, the sample weighted by the whole bsdf.
 * Both lobes' directions are made and one taken; everything waits on `dep` (the light's
 * evaluation, which the SLP vectorizer otherwise pairs with this one). Whether it gives a sample;
 * its direction wl, f |cos| (value) and pdf. */
inline bool lanes_rough_sample(const LanesRough *r, __global const float *tables, V3 color, V3 wo, float u1,
                               float u20, float u21, float dep, V3 *wl, V3 *value, float *pdf) {
    u20 = lanes_after(u20, dep);
    u21 = lanes_after(u21, dep);
    V3 wo_s = lanes_after3(wo, dep);
    float a = fmax(r->alpha, 1e-4f);
    float p_spec = lanes_prob_specular(r->sw, lanes_rough_transmittance(tables, r->table, wo_s.z));
    V3 m = lanes_ggx_sample(a, wo_s, u20, u21);
    float k = 2.0f * lanes_dot(wo_s, m);
    V3 w_spec = v3(k * m.x - wo_s.x, k * m.y - wo_s.y, k * m.z - wo_s.z);
    float dx, dy;
    lanes_concentric_disk(u20, u21, &dx, &dy);
    V3 w_diff = v3(dx, dy, sqrt(fmax(0.0f, 1.0f - dx * dx - dy * dy)));
    *wl = v3_sel(u1 < p_spec, w_spec, w_diff);
    *value = lanes_rough_eval(r, tables, color, wo, lanes_after3(*wl, dep), pdf);
    return (wo.z > 0.0f) & (*pdf > 0.0f) & (v3_max(*value) > 0.0f);
}

/* bsdf_sample at such a vertex, three numbers drawn where the path samples one (`sampling`):
 * whether the path goes on, its world direction, weight and pdf. */
inline bool lanes_rough_bounce(const LanesRough *r, __global const float *tables, V3 color, Rng32 *rng, bool sampling,
                               float dep, V3 s, V3 t, V3 n, V3 wo, V3 *wi, V3 *weight, float *pdf) {
    float u1 = rng32_float_if(rng, sampling);
    float u20 = rng32_float_if(rng, sampling), u21 = rng32_float_if(rng, sampling);
    V3 wl, value;
    bool ok = sampling & lanes_rough_sample(r, tables, color, wo, u1, u20, u21, dep, &wl, &value, pdf);
    *weight = v3(value.x / *pdf, value.y / *pdf, value.z / *pdf);
    *wi = lanes_to_world(wl, s, t, n);
    return ok;
}

#endif
