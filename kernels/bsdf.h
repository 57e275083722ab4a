/* Surface scattering. Conventions for this file and its callers:
 *  - directions are in the local shading frame (normal = +z) and point away from the surface;
 *  - wo points towards the previous vertex (the viewer), wi towards the next one (pbrt's naming;
 *    Mitsuba calls them si.wi and wo);
 *  - `value` means f(wo, wi) * |cos(wi)|, and pdfs are per unit solid angle; delta lobes report
 *    their discrete probability as pdf and set `delta`.
 * Transport is radiance (from the camera), so refraction scales by 1 / eta^2.
 *
 * A BsdfVertex is a bsdf as it is at one surface point: wrappers resolved (bsdf_vertex.h), textures
 * evaluated, the shading frame chosen. This file holds the smooth models and the dispatch by type;
 * microfacet models are in bsdf_rough.h. Every model follows Mitsuba 3.9 (src/bsdfs).
 */
#ifndef VOLCL_BSDF_H
#define VOLCL_BSDF_H

#include "texcoords.h"
#include "textures.h"

typedef struct {
    float3 wi;
    float3 weight;  /* value / pdf */
    float pdf;
    float eta;      /* relative IOR crossed (1 unless refracted), for Russian roulette */
    bool delta;
    bool null_event;    /* the path passes straight through (mask, thindielectric): not a vertex */
} BsdfSample;

typedef struct {
    __global const Bsdf *b;     /* the bsdf that scatters: never a wrapper */
    float3 s, t, n;             /* the shading frame it sees, in world space */
    float3 color;               /* its parameters here (types.h Bsdf says which is which) */
    float3 eta3, k3;            /* conductors */
    float3 spec_r, spec_t;
    float alpha_u, alpha_v;
    float opacity;              /* product of the opacities of the masks around it (1 without) */
    bool bumped;                /* a bump or normal map tilted the frame */
    bool shadowing;             /* and attenuates by Estevez et al.'s shadowing term */
    float3 n_in;                /* the normal before the tilt */
    float tan2_tilt;            /* tan^2 of the tilted normal against n_in */
    __global const float *table;    /* roughplastic: its transmittance table */
} BsdfVertex;

/* Unpolarized Fresnel reflectance of a dielectric interface. eta = n_transmitted / n_incident for a
 * ray arriving with cos_i > 0; on total internal reflection returns 1 and leaves cos_t at 0. */
inline float fresnel_dielectric(float cos_i, float eta, float *cos_t) {
    /* cos_t^2 = 1 - (1 - cos_i^2) / eta^2, rearranged with eta^2 - 1 = (eta - 1)(eta + 1): the
     * textbook form cancels in float32 at eta = 1 (an index-matched interface then reflects grazing
     * rays, and totally at cos_i < 2.4e-4), while this one gives cos_t = cos_i and F = 0 there */
    float cos2_t = (cos_i * cos_i + (eta - 1.0f) * (eta + 1.0f)) / (eta * eta);
    if (cos2_t <= 0.0f) { *cos_t = 0.0f; return 1.0f; }
    float ct = sqrt(cos2_t);
    *cos_t = ct;
    float rs = (cos_i - eta * ct) / (cos_i + eta * ct);
    float rp = (eta * cos_i - ct) / (eta * cos_i + ct);
    return 0.5f * (rs * rs + rp * rp);
}

/* Mitsuba's fresnel(): cos_i signed (< 0: arriving from inside, where the relative IOR is 1 / eta),
 * with its special cases (eta == 1 reflects nothing, cos_i == 0 everything). Gives the signed cosine
 * of the refracted direction and the relative IORs eta_it = n_t / n_i and eta_ti = 1 / eta_it. */
inline float fresnel_signed(float cos_i, float eta, float *cos_t, float *eta_it, float *eta_ti) {
    bool outside = cos_i >= 0.0f;
    float rcp_eta = 1.0f / eta;
    *eta_it = outside ? eta : rcp_eta;
    *eta_ti = outside ? rcp_eta : eta;
    float ct2 = 1.0f - (1.0f - cos_i * cos_i) * (*eta_ti * *eta_ti);
    float ci = fabs(cos_i), ct = sqrt(fmax(ct2, 0.0f));
    float a_s = (ci - *eta_it * ct) / (ci + *eta_it * ct);
    float a_p = (ct - *eta_it * ci) / (ct + *eta_it * ci);
    float r = 0.5f * (a_s * a_s + a_p * a_p);
    if (eta == 1.0f) r = 0.0f;
    else if (ci == 0.0f) r = 1.0f;
    *cos_t = outside ? -ct : ct;
    return r;
}

inline float fresnel_r(float cos_i, float eta) {
    float ct, eit, eti;
    return fresnel_signed(cos_i, eta, &ct, &eit, &eti);
}

/* Fresnel reflectance of a conductor with complex IOR eta + i k (per channel), from the outside. */
inline float3 fresnel_conductor(float cos_i, float3 eta, float3 k) {
    float c2 = cos_i * cos_i, s2 = 1.0f - c2;
    float3 t0 = eta * eta - k * k - s2;
    float3 a2b2 = sqrt(fmax(t0 * t0 + 4.0f * eta * eta * k * k, 0.0f));
    float3 a = sqrt(fmax(0.5f * (a2b2 + t0), 0.0f));
    float3 t1 = a2b2 + c2, t2 = 2.0f * cos_i * a;
    float3 rs = (t1 - t2) / (t1 + t2);
    float3 t3 = c2 * a2b2 + s2 * s2, t4 = t2 * s2;
    float3 rp = rs * (t3 - t4) / (t3 + t4);
    return 0.5f * (rp + rs);
}

inline float3 reflect_about(float3 w, float3 m) { return 2.0f * dot(w, m) * m - w; }

/* Whether the bsdf has a lobe light sampling can meet (not delta only). */
inline bool bsdf_is_smooth(int type) {
    return type == BSDF_DIFFUSE || type == BSDF_ROUGHCONDUCTOR || type == BSDF_ROUGHDIELECTRIC
           || type == BSDF_PLASTIC || type == BSDF_ROUGHPLASTIC;
}

/* ---- smooth plastic (src/bsdfs/plastic.cpp): a diffuse base under a smooth dielectric coating ---- */

#if VOLCL_HAS_PLASTIC
/* the diffuse lobe's reflectance after internal reflections (Mitsuba's nonlinear switch) */
inline float3 plastic_diffuse(const BsdfVertex *v) {
    float3 r = v->color;
    return v->b->flags & BSDF_FLAG_NONLINEAR ? r / (1.0f - r * v->b->internal_refl)
                                              : r / (1.0f - v->b->internal_refl);
}

inline float plastic_prob_specular(const BsdfVertex *v, float f_i) {
    float sw = v->b->spec_weight;
    float ps = f_i * sw, pd = (1.0f - f_i) * (1.0f - sw);
    return ps / (ps + pd);
}

inline float3 plastic_eval(const BsdfVertex *v, float3 wo, float3 wi, float *pdf) {
    if (wo.z <= 0.0f || wi.z <= 0.0f) return (float3)(0.0f);
    float eta = v->b->eta;
    float f_i = fresnel_r(wo.z, eta), f_o = fresnel_r(wi.z, eta);
    *pdf = sample_cosine_hemisphere_pdf(wi) * (1.0f - plastic_prob_specular(v, f_i));
    return plastic_diffuse(v) * (wi.z * VOLCL_INV_PI * v->b->inv_eta2 * (1.0f - f_i) * (1.0f - f_o));
}

inline bool plastic_sample(const BsdfVertex *v, float3 wo, float u1, float2 u2, BsdfSample *s) {
    if (wo.z <= 0.0f) return false;
    float eta = v->b->eta;
    float f_i = fresnel_r(wo.z, eta);
    float p_spec = plastic_prob_specular(v, f_i);
    if (u1 < p_spec) {
        s->wi = (float3)(-wo.x, -wo.y, wo.z);
        s->pdf = p_spec;
        s->weight = v->spec_r * (f_i / p_spec);
        s->delta = true;
        return true;
    }
    float3 wi = sample_cosine_hemisphere(u2);
    float p_diff = 1.0f - p_spec;
    s->pdf = p_diff * sample_cosine_hemisphere_pdf(wi);
    if (!(s->pdf > 0.0f)) return false;
    float f_o = fresnel_r(wi.z, eta);
    s->wi = wi;
    s->weight = plastic_diffuse(v) * (v->b->inv_eta2 * (1.0f - f_i) * (1.0f - f_o) / p_diff);
    s->delta = false;
    return true;
}
#endif

/* ---- thin dielectric (src/bsdfs/thindielectric.cpp): a pane, reflecting or passing straight on ---- */

/* reflectance of the pane with its internal reflections summed: r' = r + t r t + t r^3 t + ... */
inline float thindielectric_reflectance(float cos_i, float eta) {
    float r = fresnel_r(fabs(cos_i), eta);
    return r * 2.0f / (1.0f + r);
}

#if VOLCL_HAS_THINDIELECTRIC
inline bool thindielectric_sample(const BsdfVertex *v, float3 wo, float u1, BsdfSample *s) {
    float r = thindielectric_reflectance(wo.z, v->b->eta);
    s->delta = true;
    if (u1 <= r) {
        s->wi = (float3)(-wo.x, -wo.y, wo.z);
        s->pdf = r;
        s->weight = v->spec_r;
    } else {
        s->wi = -wo;
        s->pdf = 1.0f - r;
        s->weight = v->spec_t;
        s->null_event = true;
    }
    return s->pdf > 0.0f;
}
#endif

#include "microfacet.h"
#include "bsdf_rough.h"

/* value = f * |cos wi| at this vertex in its local frame, with its pdf. Delta lobes evaluate to
 * zero: they are reached only by sampling. */
__attribute__((always_inline))
inline float3 bsdf_eval_local(const BsdfVertex *v, float3 wo, float3 wi, float *pdf) {
    *pdf = 0.0f;
    int type = v->b->type;
#if VOLCL_HAS_DIFFUSE
    if (type == BSDF_DIFFUSE) {
        if (wo.z <= 0.0f || wi.z <= 0.0f) return (float3)(0.0f);
        *pdf = sample_cosine_hemisphere_pdf(wi);
        return v->color * (wi.z * VOLCL_INV_PI);
    }
#endif
#if VOLCL_HAS_ROUGHCONDUCTOR
    if (type == BSDF_ROUGHCONDUCTOR) return roughconductor_eval(v, wo, wi, pdf);
#endif
#if VOLCL_HAS_ROUGHDIELECTRIC
    if (type == BSDF_ROUGHDIELECTRIC) return roughdielectric_eval(v, wo, wi, pdf);
#endif
#if VOLCL_HAS_PLASTIC
    if (type == BSDF_PLASTIC) return plastic_eval(v, wo, wi, pdf);
#endif
#if VOLCL_HAS_ROUGHPLASTIC
    if (type == BSDF_ROUGHPLASTIC) return roughplastic_eval(v, wo, wi, pdf);
#endif
    return (float3)(0.0f);
}

__attribute__((always_inline))
inline bool bsdf_sample_local(const BsdfVertex *v, float3 wo, float u1, float2 u2, BsdfSample *s) {
    __global const Bsdf *b = v->b;
    int type = b->type;
    s->eta = 1.0f;
    s->null_event = false;
#if VOLCL_HAS_DIFFUSE
    if (type == BSDF_DIFFUSE) {
        if (wo.z <= 0.0f) return false;
        float3 wi = sample_cosine_hemisphere(u2);
        s->pdf = sample_cosine_hemisphere_pdf(wi);
        if (s->pdf <= 0.0f) return false;
        s->wi = wi;
        s->weight = v->color;  /* (R / pi) cos / (cos / pi) */
        s->delta = false;
        return true;
    }
#endif
#if VOLCL_HAS_CONDUCTOR
    if (type == BSDF_CONDUCTOR) {
        if (wo.z <= 0.0f) return false;
        s->wi = (float3)(-wo.x, -wo.y, wo.z);
        s->pdf = 1.0f;
        s->delta = true;
        s->weight = v->color;
        if (!b->conductor_mirror) s->weight *= fresnel_conductor(wo.z, v->eta3, v->k3);
        return true;
    }
#endif
#if VOLCL_HAS_DIELECTRIC
    if (type == BSDF_DIELECTRIC) {
        bool outside = wo.z > 0.0f;
        float eta = outside ? b->eta : 1.0f / b->eta;
        float cos_i = fabs(wo.z), cos_t;
        float f = fresnel_dielectric(cos_i, eta, &cos_t);
        s->delta = true;
        if (u1 < f) {
            s->wi = (float3)(-wo.x, -wo.y, wo.z);
            s->pdf = f;
            s->weight = v->spec_r;
        } else {
            /* Snell: the tangential part shrinks by 1/eta, the normal part flips side */
            s->wi = (float3)(-wo.x / eta, -wo.y / eta, outside ? -cos_t : cos_t);
            s->wi = normalize(s->wi);
            s->pdf = 1.0f - f;
            s->weight = v->spec_t * (1.0f / (eta * eta));
            s->eta = eta;
        }
        return true;
    }
#endif
#if VOLCL_HAS_ROUGHCONDUCTOR
    if (type == BSDF_ROUGHCONDUCTOR) return roughconductor_sample(v, wo, u2, s);
#endif
#if VOLCL_HAS_ROUGHDIELECTRIC
    if (type == BSDF_ROUGHDIELECTRIC) return roughdielectric_sample(v, wo, u1, u2, s);
#endif
#if VOLCL_HAS_PLASTIC
    if (type == BSDF_PLASTIC) return plastic_sample(v, wo, u1, u2, s);
#endif
#if VOLCL_HAS_ROUGHPLASTIC
    if (type == BSDF_ROUGHPLASTIC) return roughplastic_sample(v, wo, u1, u2, s);
#endif
#if VOLCL_HAS_THINDIELECTRIC
    if (type == BSDF_THINDIELECTRIC) return thindielectric_sample(v, wo, u1, s);
#endif
    return false;
}

#include "bsdf_vertex.h"

#endif
