/* Microfacet normal distributions with Mitsuba 3.9's definitions (include/mitsuba/render/microfacet.h):
 * Beckmann and GGX, anisotropic roughness alpha_u along the shading frame's s axis and alpha_v
 * along t, Smith's separable shadowing-masking, and sampling of either all normals (D(m) cos) or
 * the normals visible from a direction (Heitz and d'Eon 2014). Directions are in the local frame
 * (normal +z); roughness is clamped to 1e-4 as Mitsuba clamps it.
 */
#ifndef VOLCL_MICROFACET_H
#define VOLCL_MICROFACET_H

typedef struct {
    int type;       /* MICROFACET_BECKMANN or MICROFACET_GGX */
    float au, av;
    bool visible;   /* sample visible normals */
} Microfacet;

inline Microfacet microfacet_make(int type, float au, float av, bool visible) {
    Microfacet d;
    d.type = type;
    d.au = fmax(au, 1e-4f);
    d.av = fmax(av, 1e-4f);
    d.visible = visible;
    return d;
}

inline float sqr(float x) { return x * x; }

/* D(m): the density of microfacet normals per unit solid angle, projected: integral D cos = 1 */
inline float microfacet_D(const Microfacet *d, float3 m) {
    float ct2 = m.z * m.z, r;
    if (d->type == MICROFACET_BECKMANN) {
        r = exp(-(sqr(m.x / d->au) + sqr(m.y / d->av)) / ct2) / (VOLCL_PI * d->au * d->av * ct2 * ct2);
    } else {
        r = 1.0f / (VOLCL_PI * d->au * d->av * sqr(sqr(m.x / d->au) + sqr(m.y / d->av) + ct2));
    }
    /* also zero on the back side, and for the NaN of a grazing Beckmann normal */
    return r * m.z > 1e-20f ? r : 0.0f;
}

/* Smith's G1 for direction v and microfacet normal m; zero where v sees m's back. */
inline float microfacet_G1(const Microfacet *d, float3 v, float3 m) {
    float xy = sqr(d->au * v.x) + sqr(d->av * v.y);
    float tan2 = xy / sqr(v.z), r;
    if (d->type == MICROFACET_BECKMANN) {
        /* Mitsuba's rational fit of the Beckmann masking function (< 0.35% relative error) */
        float a = rsqrt(tan2), a2 = a * a;
        r = a >= 1.6f ? 1.0f : (3.535f * a + 2.181f * a2) / (1.0f + 2.276f * a + 2.577f * a2);
    } else {
        r = 2.0f / (1.0f + sqrt(1.0f + tan2));
    }
    if (xy == 0.0f) r = 1.0f;
    if (dot(v, m) * v.z <= 0.0f) r = 0.0f;
    return r;
}

inline float microfacet_G(const Microfacet *d, float3 wi, float3 wo, float3 m) {
    return microfacet_G1(d, wi, m) * microfacet_G1(d, wo, m);
}

/* Density of microfacet_sample(wi, .) producing m, per unit solid angle of m. */
inline float microfacet_pdf(const Microfacet *d, float3 wi, float3 m) {
    float r = microfacet_D(d, m);
    return d->visible ? r * microfacet_G1(d, wi, m) * fabs(dot(wi, m)) / wi.z : r * m.z;
}

/* Inverse error function, single precision (Giles, "Approximating the erfinv function", 2010). */
inline float erfinv_approx(float x) {
    float w = -log((1.0f - x) * (1.0f + x)), p;
    if (w < 5.0f) {
        w -= 2.5f;
        p = 2.81022636e-08f;
        p = 3.43273939e-07f + p * w;
        p = -3.5233877e-06f + p * w;
        p = -4.39150654e-06f + p * w;
        p = 0.00021858087f + p * w;
        p = -0.00125372503f + p * w;
        p = -0.00417768164f + p * w;
        p = 0.246640727f + p * w;
        p = 1.50140941f + p * w;
    } else {
        w = sqrt(w) - 3.0f;
        p = -0.000200214257f;
        p = 0.000100950558f + p * w;
        p = 0.00134934322f + p * w;
        p = -0.00367342844f + p * w;
        p = 0.00573950773f + p * w;
        p = -0.0076224613f + p * w;
        p = 0.00943887047f + p * w;
        p = 1.00167406f + p * w;
        p = 2.83297682f + p * w;
    }
    return p * x;
}

/* A slope drawn from the visible slopes of the unit-roughness distribution seen at cos_i. */
inline float2 microfacet_visible_slope_11(int type, float cos_i, float2 u) {
    if (type == MICROFACET_BECKMANN) {
        /* the numerical inversion of the visible-slope CDF in erf space that Mitsuba uses: an
         * initial guess exact at grazing incidence, then Newton steps */
        float tan_i = sqrt(fmax(1.0f - cos_i * cos_i, 0.0f)) / cos_i;
        float cot_i = 1.0f / tan_i;
        float maxval = erf(cot_i);
        u = fmax(fmin(u, 1.0f - 1e-6f), 1e-6f);
        float x = maxval - (maxval + 1.0f) * erf(sqrt(-log(u.x)));
        float ux = u.x * (1.0f + maxval + 0.56418958354775628695f * tan_i * exp(-cot_i * cot_i));
        for (int i = 0; i < 3; ++i) {
            float slope = erfinv_approx(x);
            float value = 1.0f + x + 0.56418958354775628695f * tan_i * exp(-slope * slope) - ux;
            float derivative = 1.0f - slope * tan_i;
            x -= value / derivative;
        }
        return (float2)(erfinv_approx(x), erfinv_approx(2.0f * u.y - 1.0f));
    }
    /* GGX: a point of the projected hemisphere, as Heitz's 2018 construction */
    float2 p = sample_concentric_disk(u);
    float s = 0.5f * (1.0f + cos_i);
    p.y = (1.0f - s) * sqrt(fmax(1.0f - p.x * p.x, 0.0f)) + s * p.y;
    float z = sqrt(fmax(1.0f - p.x * p.x - p.y * p.y, 0.0f));
    float sin_i = sqrt(fmax(1.0f - cos_i * cos_i, 0.0f));
    float norm = 1.0f / (sin_i * p.y + cos_i * z);
    return (float2)((cos_i * p.y - sin_i * z) * norm, p.x * norm);
}

/* A microfacet normal for direction wi (upper hemisphere), and its microfacet_pdf. */
inline float3 microfacet_sample(const Microfacet *d, float3 wi, float2 u, float *pdf) {
    if (!d->visible) {
        float sin_phi, cos_phi, alpha2;
        if (d->au == d->av) {
            sin_phi = sin(2.0f * VOLCL_PI * u.y);
            cos_phi = cos(2.0f * VOLCL_PI * u.y);
            alpha2 = d->au * d->au;
        } else {
            float tmp = (d->av / d->au) * tan(2.0f * VOLCL_PI * u.y);
            cos_phi = copysign(rsqrt(tmp * tmp + 1.0f), fabs(u.y - 0.5f) - 0.25f);
            sin_phi = cos_phi * tmp;
            alpha2 = 1.0f / (sqr(cos_phi / d->au) + sqr(sin_phi / d->av));
        }
        /* tan^2 theta first: sin theta from 1 - cos^2 theta loses the digits a narrow lobe lives on */
        float tan2 = d->type == MICROFACET_BECKMANN ? -alpha2 * log(1.0f - u.x) : alpha2 * u.x / (1.0f - u.x);
        float cos_t = rsqrt(1.0f + tan2), sin_t = sqrt(tan2) * cos_t, p;
        if (d->type == MICROFACET_BECKMANN) {
            p = (1.0f - u.x) / (VOLCL_PI * d->au * d->av * fmax(cos_t * cos_t * cos_t, 1e-20f));
        } else {
            p = 1.0f / (VOLCL_PI * d->au * d->av * fmax(cos_t * cos_t * cos_t, 1e-20f) * sqr(1.0f + tan2 / alpha2));
        }
        if (!(sin_t <= 1.0f)) {     /* u.x at 1: the horizon */
            sin_t = 1.0f;
            cos_t = 0.0f;
        }
        *pdf = p;
        return (float3)(cos_phi * sin_t, sin_phi * sin_t, cos_t);
    }
    /* stretch wi to unit roughness, take a visible slope there, rotate and unstretch it */
    float3 wp = normalize((float3)(d->au * wi.x, d->av * wi.y, wi.z));
    float st2 = wp.x * wp.x + wp.y * wp.y;
    float cos_phi = 1.0f, sin_phi = 0.0f;
    if (st2 > 4.0f * 5.9604645e-8f) {
        float inv = rsqrt(st2);
        cos_phi = clamp(wp.x * inv, -1.0f, 1.0f);
        sin_phi = clamp(wp.y * inv, -1.0f, 1.0f);
    }
    float2 sl = microfacet_visible_slope_11(d->type, wp.z, u);
    float2 slope = (float2)((cos_phi * sl.x - sin_phi * sl.y) * d->au, (sin_phi * sl.x + cos_phi * sl.y) * d->av);
    float3 m = normalize((float3)(-slope.x, -slope.y, 1.0f));
    *pdf = microfacet_D(d, m) * microfacet_G1(d, wi, m) * fabs(dot(wi, m)) / wi.z;
    return m;
}

#endif
