/* Surface scattering. Conventions for this file and its callers:
 *  - directions are in the local shading frame (normal = +z) and point away from the surface;
 *  - wo points towards the previous vertex (the viewer), wi towards the next one (pbrt's naming);
 *  - `value` means f(wo, wi) * |cos(wi)|, and pdfs are per unit solid angle; delta lobes report
 *    their discrete probability as pdf and set `delta`.
 * Transport is radiance (from the camera), so refraction scales by 1 / eta^2.
 */
#ifndef VOLCL_BSDF_H
#define VOLCL_BSDF_H

typedef struct {
    float3 wi;
    float3 weight;  /* value / pdf */
    float pdf;
    float eta;      /* relative IOR crossed (1 unless refracted), for Russian roulette */
    bool delta;
} BsdfSample;

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

inline float3 bsdf_color(__global const Bsdf *b) { return vload_f3(b->color); }

inline bool bsdf_is_delta(__global const Bsdf *b) { return b->type != BSDF_DIFFUSE; }

/* value = f * |cos wi|, with its pdf. Delta lobes evaluate to zero: they are reached only by sampling. */
__attribute__((always_inline))
inline float3 bsdf_eval(__global const Bsdf *b, float3 wo, float3 wi, float *pdf) {
    *pdf = 0.0f;
#if VOLCL_HAS_DIFFUSE
    if (b->type == BSDF_DIFFUSE) {
        if (b->twosided && wo.z < 0.0f) { wo.z = -wo.z; wi.z = -wi.z; }
        if (wo.z <= 0.0f || wi.z <= 0.0f) return (float3)(0.0f);
        *pdf = sample_cosine_hemisphere_pdf(wi);
        return bsdf_color(b) * (wi.z * VOLCL_INV_PI);
    }
#endif
    return (float3)(0.0f);
}

__attribute__((always_inline))
inline bool bsdf_sample(__global const Bsdf *b, float3 wo, float u1, float2 u2, BsdfSample *s) {
    s->eta = 1.0f;
#if VOLCL_HAS_DIFFUSE
    if (b->type == BSDF_DIFFUSE) {
        float flip = 1.0f;
        if (b->twosided && wo.z < 0.0f) flip = -1.0f;
        if (wo.z * flip <= 0.0f) return false;
        float3 wi = sample_cosine_hemisphere(u2);
        s->pdf = sample_cosine_hemisphere_pdf(wi);
        if (s->pdf <= 0.0f) return false;
        s->wi = (float3)(wi.x, wi.y, wi.z * flip);
        s->weight = bsdf_color(b);  /* (R / pi) cos / (cos / pi) */
        s->delta = false;
        return true;
    }
#endif
#if VOLCL_HAS_CONDUCTOR
    if (b->type == BSDF_CONDUCTOR) {
        float flip = (b->twosided && wo.z < 0.0f) ? -1.0f : 1.0f;
        float cos_o = wo.z * flip;
        if (cos_o <= 0.0f) return false;
        s->wi = (float3)(-wo.x, -wo.y, wo.z);
        s->pdf = 1.0f;
        s->delta = true;
        s->weight = bsdf_color(b);
        if (!b->conductor_mirror) s->weight *= fresnel_conductor(cos_o, vload_f3(b->cond_eta), vload_f3(b->cond_k));
        return true;
    }
#endif
#if VOLCL_HAS_DIELECTRIC
    if (b->type == BSDF_DIELECTRIC) {
        bool outside = wo.z > 0.0f;
        float eta = outside ? b->eta : 1.0f / b->eta;
        float cos_i = fabs(wo.z), cos_t;
        float f = fresnel_dielectric(cos_i, eta, &cos_t);
        s->delta = true;
        if (u1 < f) {
            s->wi = (float3)(-wo.x, -wo.y, wo.z);
            s->pdf = f;
            s->weight = (float3)(1.0f);
        } else {
            /* Snell: the tangential part shrinks by 1/eta, the normal part flips side */
            s->wi = (float3)(-wo.x / eta, -wo.y / eta, outside ? -cos_t : cos_t);
            s->wi = normalize(s->wi);
            s->pdf = 1.0f - f;
            s->weight = (float3)(1.0f / (eta * eta));
            s->eta = eta;
        }
        return true;
    }
#endif
    return false;
}

#endif
