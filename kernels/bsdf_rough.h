/* Microfacet bsdfs, as Mitsuba 3.9's roughconductor, roughdielectric and roughplastic
 * (src/bsdfs/rough*.cpp): one scattering event on the microsurface, Smith shadowing-masking, the
 * Fresnel term at the microfacet, and Mitsuba's sampling (visible normals by default; with
 * sample_visible off all normals, for rough dielectrics with Walter et al.'s widened roughness).
 * Included by bsdf.h; conventions there (wo towards the viewer, value = f |cos wi|). Where Mitsuba's
 * sampler returns a direction with zero weight (a reflection below the surface), these return
 * false: the same estimate, without the dead sample. */
#ifndef VOLCL_BSDF_ROUGH_H
#define VOLCL_BSDF_ROUGH_H

inline Microfacet bsdf_microfacet(const BsdfVertex *v) {
    return microfacet_make(v->b->distribution, v->alpha_u, v->alpha_v, (v->b->flags & BSDF_FLAG_VISIBLE) != 0);
}

/* pdf of a reflection through half vector h, for the distribution d (visible: of wo's view) */
inline float microfacet_reflection_pdf(const Microfacet *d, float3 wo, float3 wi, float3 h) {
    return d->visible ? microfacet_D(d, h) * microfacet_G1(d, wo, h) / (4.0f * wo.z)
                      : microfacet_pdf(d, wo, h) / (4.0f * dot(wi, h));
}

/* ---- roughconductor ---- */

#if VOLCL_HAS_ROUGHCONDUCTOR
inline float3 roughconductor_eval(const BsdfVertex *v, float3 wo, float3 wi, float *pdf) {
    if (wo.z <= 0.0f || wi.z <= 0.0f) return (float3)(0.0f);
    float3 h = normalize(wo + wi);
    if (dot(wo, h) <= 0.0f || dot(wi, h) <= 0.0f) return (float3)(0.0f);
    Microfacet d = bsdf_microfacet(v);
    float D = microfacet_D(&d, h);
    if (D == 0.0f) return (float3)(0.0f);
    float g1_o = microfacet_G1(&d, wo, h);
    *pdf = d.visible ? D * g1_o / (4.0f * wo.z) : microfacet_pdf(&d, wo, h) / (4.0f * dot(wi, h));
    float3 F = v->b->conductor_mirror ? (float3)(1.0f) : fresnel_conductor(dot(wo, h), v->eta3, v->k3);
    return v->color * F * (D * g1_o * microfacet_G1(&d, wi, h) / (4.0f * wo.z));
}

inline bool roughconductor_sample(const BsdfVertex *v, float3 wo, float2 u2, BsdfSample *s) {
    if (wo.z <= 0.0f) return false;
    Microfacet d = bsdf_microfacet(v);
    float pdf_m;
    float3 m = microfacet_sample(&d, wo, u2, &pdf_m);
    float3 wi = reflect_about(wo, m);
    if (!(pdf_m > 0.0f) || wi.z <= 0.0f) return false;
    float w = d.visible ? microfacet_G1(&d, wi, m)
                        : microfacet_G(&d, wo, wi, m) * dot(wo, m) / (wo.z * m.z);
    if (!(w > 0.0f)) return false;
    s->wi = wi;
    s->pdf = pdf_m / (4.0f * dot(wi, m));
    float3 F = v->b->conductor_mirror ? (float3)(1.0f) : fresnel_conductor(dot(wo, m), v->eta3, v->k3);
    s->weight = v->color * F * w;
    s->delta = false;
    return true;
}
#endif

/* ---- roughdielectric ---- */

#if VOLCL_HAS_ROUGHDIELECTRIC
/* the distribution Mitsuba samples: without visible normals, roughness widened by
 * 1.2 - 0.2 sqrt(|cos|) (Walter et al. 2007), which evaluation does not use */
inline Microfacet roughdielectric_sampling(const BsdfVertex *v, float cos_o) {
    Microfacet d = bsdf_microfacet(v);
    if (!d.visible) {
        float k = 1.2f - 0.2f * sqrt(fabs(cos_o));
        d.au *= k;
        d.av *= k;
    }
    return d;
}

inline float3 roughdielectric_eval(const BsdfVertex *v, float3 wo, float3 wi, float *pdf) {
    float ci = wo.z, co = wi.z;
    if (ci == 0.0f) return (float3)(0.0f);
    bool reflect = ci * co > 0.0f;
    float eta_b = v->b->eta;
    float eta = ci > 0.0f ? eta_b : 1.0f / eta_b, inv_eta = 1.0f / eta;
    float3 m = normalize(wo + wi * (reflect ? 1.0f : eta));
    if (m.z < 0.0f) m = -m;
    float dot_o = dot(wo, m), dot_i = dot(wi, m);
    /* the micro- and macrosurface must agree on the side of each direction */
    if (!(dot_o * ci > 0.0f && dot_i * co > 0.0f)) return (float3)(0.0f);
    Microfacet d = bsdf_microfacet(v);
    float D = microfacet_D(&d, m);
    float F = fresnel_r(dot_o, eta_b);
    float G = microfacet_G(&d, wo, wi, m);
    Microfacet ds = roughdielectric_sampling(v, ci);
    float3 wo_up = ci > 0.0f ? wo : -wo;
    float p = microfacet_pdf(&ds, wo_up, m);
    float3 value;
    if (reflect) {
        value = v->spec_r * (F * D * G / (4.0f * fabs(ci)));
        p *= F / (4.0f * dot_i);
    } else {
        float den = dot_o + eta * dot_i;
        value = v->spec_t * fabs(inv_eta * inv_eta * (1.0f - F) * D * G * eta * eta * dot_o * dot_i
                                 / (ci * den * den));
        p *= (1.0f - F) * eta * eta * dot_i / (den * den);
    }
    *pdf = fabs(p);
    return value;
}

inline bool roughdielectric_sample(const BsdfVertex *v, float3 wo, float u1, float2 u2, BsdfSample *s) {
    float ci = wo.z;
    if (ci == 0.0f) return false;
    Microfacet d = bsdf_microfacet(v);
    Microfacet ds = roughdielectric_sampling(v, ci);
    float pdf_m;
    float3 m = microfacet_sample(&ds, ci > 0.0f ? wo : -wo, u2, &pdf_m);
    if (!(pdf_m > 0.0f)) return false;
    float cos_t, eta_it, eta_ti;
    float dot_o = dot(wo, m);
    float F = fresnel_signed(dot_o, v->b->eta, &cos_t, &eta_it, &eta_ti);
    float3 wi, weight;
    float dwh_dwi;
    if (u1 <= F) {
        wi = reflect_about(wo, m);
        weight = v->spec_r;
        dwh_dwi = 1.0f / (4.0f * dot(wi, m));
        s->pdf = pdf_m * F;
        s->eta = 1.0f;
    } else {
        /* refraction about m; radiance is compressed by eta_ti^2 into the denser side */
        wi = m * (dot_o * eta_ti + cos_t) - wo * eta_ti;
        weight = v->spec_t * (eta_ti * eta_ti);
        float dot_i = dot(wi, m);
        dwh_dwi = eta_it * eta_it * dot_i / sqr(dot_o + eta_it * dot_i);
        s->pdf = pdf_m * (1.0f - F);
        s->eta = eta_it;
    }
    float g = d.visible ? microfacet_G1(&d, wi, m)
                        : microfacet_G(&d, wo, wi, m) * dot_o / (ci * m.z);
    if (!(g > 0.0f)) return false;
    s->wi = wi;
    s->weight = weight * g;
    s->pdf *= fabs(dwh_dwi);
    s->delta = false;
    return s->pdf > 0.0f;
}
#endif

/* ---- roughplastic: a diffuse base under a rough dielectric coating ---- */

#if VOLCL_HAS_ROUGHPLASTIC
/* the coating's transmittance for a direction at cos_theta: Mitsuba's 64-entry table over
 * [0, 1], interpolated linearly */
inline float roughplastic_transmittance(__global const float *table, float cos_theta) {
    float x = cos_theta * 63.0f;
    int i = min((int)x, 62);
    float a = table[i], b = table[i + 1];
    return a + (b - a) * (x - (float)i);
}

inline float roughplastic_prob_specular(const BsdfVertex *v, float t_i) {
    float sw = v->b->spec_weight;
    float ps = (1.0f - t_i) * sw, pd = t_i * (1.0f - sw);
    return ps / (ps + pd);
}

inline float3 roughplastic_eval(const BsdfVertex *v, float3 wo, float3 wi, float *pdf) {
    __global const float *table = v->table;
    *pdf = 0.0f;
    if (wo.z <= 0.0f || wi.z <= 0.0f) return (float3)(0.0f);
    __global const Bsdf *b = v->b;
    Microfacet d = bsdf_microfacet(v);
    float3 h = normalize(wo + wi);
    float D = microfacet_D(&d, h);
    float F = fresnel_r(dot(wo, h), b->eta);
    float G = microfacet_G(&d, wo, wi, h);
    float3 value = v->spec_r * (F * D * G / (4.0f * wo.z));
    float t_i = roughplastic_transmittance(table, wo.z), t_o = roughplastic_transmittance(table, wi.z);
    float3 r = v->color;
    float3 diff = b->flags & BSDF_FLAG_NONLINEAR ? r / (1.0f - r * b->internal_refl) : r / (1.0f - b->internal_refl);
    value += diff * (VOLCL_INV_PI * b->inv_eta2 * wi.z * t_i * t_o);
    float p_spec = roughplastic_prob_specular(v, t_i);
    *pdf = p_spec * microfacet_reflection_pdf(&d, wo, wi, h) + (1.0f - p_spec) * sample_cosine_hemisphere_pdf(wi);
    return value;
}

/* a lobe picked by the coating's reflectance, then the sample weighted by the whole bsdf */
inline bool roughplastic_sample(const BsdfVertex *v, float3 wo, float u1, float2 u2, BsdfSample *s) {
    if (wo.z <= 0.0f) return false;
    float p_spec = roughplastic_prob_specular(v, roughplastic_transmittance(v->table, wo.z));
    float3 wi;
    if (u1 < p_spec) {
        Microfacet d = bsdf_microfacet(v);
        float pdf_m;
        wi = reflect_about(wo, microfacet_sample(&d, wo, u2, &pdf_m));
    } else {
        wi = sample_cosine_hemisphere(u2);
    }
    float pdf;
    float3 value = roughplastic_eval(v, wo, wi, &pdf);
    if (!(pdf > 0.0f) || !(max_component(value) > 0.0f)) return false;
    s->wi = wi;
    s->pdf = pdf;
    s->weight = value / pdf;
    s->delta = false;
    return true;
}
#endif

#endif
