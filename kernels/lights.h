/* Light sampling and the pdfs that multiple importance sampling needs.
 * A light is chosen uniformly; pdfs include that choice and are per unit solid angle at the
 * receiving point, except for delta lights (point, spot, directional), whose pdf is the choice
 * probability alone. Area lights emit on the side their shading normal faces. The environment (a
 * constant or an envmap, at most one: RenderParams.env_light) is at infinity.
 */
#ifndef VOLCL_LIGHTS_H
#define VOLCL_LIGHTS_H

#include "envmap.h"
#include "textures.h"

typedef struct {
    float3 wi;      /* unit direction from the receiving point towards the light */
    float dist;     /* INF for lights at infinity */
    float3 value;   /* radiance arriving along -wi before visibility (Le, I / d^2 or E) */
    float pdf;
    bool delta;
    int light;      /* index of the light sampled */
} LightSample;

/* Solid-angle pdf of reaching point `p` with normals ng/ns on area light `li` from `ref`. */
inline float light_area_pdf(const SceneData *sc, int li, float3 ref, float3 p, float3 ng) {
    float3 v = p - ref;
    float d2 = dot(v, v);
    float cos_l = fabs(dot(ng, v)) * rsqrt(d2);
    if (cos_l <= 0.0f) return 0.0f;
    return d2 / (cos_l * sc->lights[li].area * (float)sc->params->light_count);
}

/* Radiance arriving from the environment along world direction `d` (a ray leaving the scene), and
 * in *pdf the density with which light sampling (the choice of the light included) draws d. */
inline float3 light_env_emission(const SceneData *sc, float3 d, float *pdf) {
    __global const Light *l = &sc->lights[sc->params->env_light];
    float count = (float)sc->params->light_count;
#if VOLCL_HAS_ENVMAP
    if (l->type == LIGHT_ENVMAP) {
        float3 le = envmap_eval(sc, l, d, pdf);
        *pdf /= count;
        return le;
    }
#endif
    *pdf = VOLCL_INV_4PI / count;
    return vload_f3(l->value);
}

/* Mitsuba's spot falloff towards `w` in the light's frame (not necessarily unit): 1 inside the beam
 * width, falling linearly in angle to 0 at the cutoff angle, 0 beyond. A beam width above the cutoff
 * makes a hard-edged cone of the cutoff angle, as in Mitsuba (whose assertion on it is in debug
 * builds only). */
inline float spot_falloff(__global const Light *l, float3 w) {
    float cos_t = normalize(w).z;
    if (!(cos_t > l->cos_cutoff)) return 0.0f;
    if (cos_t >= l->cos_beam) return 1.0f;
    return (l->cutoff - acos(cos_t)) * l->inv_transition;
}

/* Lights at a point (point and spot): sampled from any point, equiangular sampling in media too. */
inline bool light_is_point_like(int type) { return type == LIGHT_POINT || type == LIGHT_SPOT; }

/* Intensity (W/sr) of a point or spot light towards unit world direction `w` (pointing away from it). */
inline float3 light_point_intensity(__global const Light *l, float3 w) {
    float3 intensity = vload_f3(l->value);
#if VOLCL_HAS_SPOT_LIGHTS
    if (l->type == LIGHT_SPOT) return intensity * spot_falloff(l, mat3_apply(l->to_local, w));
#endif
    return intensity;
}

/* Mitsuba's spot texture coordinates of light-frame direction `wl` (not necessarily unit): the
 * cone's cross-section at z = 1 mapped onto the unit square, so that the cutoff circle touches
 * its edges. */
inline float2 spot_texture_uv(__global const Light *l, float3 wl) {
    float f = 0.5f / (wl.z * l->tan_cutoff);
    return (float2)(0.5f + wl.x * f, 0.5f + wl.y * f);
}

/* What a point or spot light sends towards unit world direction `w`: its intensity, a spot's falloff
 * and projection texture included. */
inline float3 light_point_emission(const SceneData *sc, __global const Light *l, float3 w) {
#if VOLCL_HAS_SPOT_LIGHTS && VOLCL_HAS_TEXTURES
    if (l->type == LIGHT_SPOT && l->texture >= 0) {
        float3 wl = mat3_apply(l->to_local, w);
        float falloff = spot_falloff(l, wl);
        /* beyond the cutoff the light is dark and the texture never looked up, as in Mitsuba */
        if (falloff <= 0.0f) return (float3)(0.0f);
        return vload_f3(l->value) * falloff
               * texture_eval3(sc, l->texture, (float3)(1.0f), spot_texture_uv(l, wl));
    }
#endif
    return light_point_intensity(l, w);
}

/* Emitted radiance towards `w` (pointing away from the light) from a point with shading normal ns. */
inline float3 light_area_emission(__global const Light *l, float3 ns, float3 w) {
    return dot(ns, w) > 0.0f ? vload_f3(l->value) : (float3)(0.0f);
}

__attribute__((always_inline))
inline bool light_sample(const SceneData *sc, float3 ref, float u_pick, float2 u, LightSample *ls) {
    int count = sc->params->light_count;
    int li = min((int)(u_pick * (float)count), count - 1);
    __global const Light *l = &sc->lights[li];
    float choice = 1.0f / (float)count;
    ls->delta = false;
    ls->light = li;
#if VOLCL_HAS_AREA_LIGHTS
    if (l->type == LIGHT_AREA) {
        float3 p, ng, ns;
#if VOLCL_HAS_CYLINDERS
        if (l->sphere >= 0 && analytic_is_cylinder(l->sphere)) {
            __global const Cylinder *c = &sc->cylinders[l->sphere - VOLCL_CYLINDER_CODE_BASE];
            float3 q = cylinder_local_sample(u);
            p = affine_point(c->to_world, q);
            ng = cylinder_world_normal(c, (float3)(q.x, q.y, 0.0f));
            ns = ng;
        } else
#endif
#if VOLCL_HAS_SPHERES
        if (l->sphere >= 0) {
            __global const Sphere *sp = &sc->spheres[l->sphere];
            float3 n = sample_uniform_sphere(u);
            p = vload_f3(sp->center) + sp->radius * n;
            ng = sp->flip ? -n : n;
            ns = ng;
        } else
#endif
        {
            /* reuse the part of u.x below the chosen triangle's cdf step for the position */
            __global const float *cdf = sc->light_tri_cdf + l->tri_start;
            int k = sample_discrete_cdf(cdf, l->tri_count, u.x);
            float lo = k > 0 ? cdf[k - 1] : 0.0f;
            float ux = clamp((u.x - lo) / fmax(cdf[k] - lo, 1e-30f), 0.0f, 0.99999994f);
            __global const Triangle *tri = &sc->triangles[sc->light_tris[l->tri_start + k]];
            float2 b = sample_uniform_triangle((float2)(ux, u.y));
            float3 p0 = vload_f3(tri->p0), p1 = vload_f3(tri->p1), p2 = vload_f3(tri->p2);
            p = (1.0f - b.x - b.y) * p0 + b.x * p1 + b.y * p2;
            ng = normalize(cross(p1 - p0, p2 - p0));
            ns = ng;
#if VOLCL_HAS_SHADING_NORMALS
            if (tri->normals >= 0) {
                __global const TriangleNormals *tn = &sc->normals[tri->normals];
                float3 n = (1.0f - b.x - b.y) * vload_f3(tn->n0) + b.x * vload_f3(tn->n1) + b.y * vload_f3(tn->n2);
                if (length(n) > 0.0f) ns = normalize(n);
            }
#endif
        }
        float3 v = p - ref;
        float d2 = dot(v, v);
        if (!(d2 > 0.0f)) return false;
        ls->dist = sqrt(d2);
        ls->wi = v / ls->dist;
        ls->value = light_area_emission(l, ns, -ls->wi);
        float cos_l = fabs(dot(ng, ls->wi));
        /* written to be false for NaN too: a sliver whose float32 cross product rounds to zero
         * (the host computes areas in float64, from the float32 corners) has a NaN normal here */
        if (!(cos_l > 0.0f)) return false;
        ls->pdf = choice * d2 / (cos_l * l->area);
        return true;
    }
#endif
#if VOLCL_HAS_POINT_LIGHTS || VOLCL_HAS_SPOT_LIGHTS
    if (light_is_point_like(l->type)) {
        float3 v = vload_f3(l->position) - ref;
        float d2 = dot(v, v);
        if (!(d2 > 0.0f)) return false;
        ls->dist = sqrt(d2);
        ls->wi = v / ls->dist;
        ls->value = light_point_emission(sc, l, -ls->wi) / d2;
        ls->pdf = choice;
        ls->delta = true;
        return true;
    }
#endif
#if VOLCL_HAS_DIRECTIONAL_LIGHTS
    if (l->type == LIGHT_DIRECTIONAL) {
        ls->wi = -vload_f3(l->direction);
        ls->dist = INFINITY;
        ls->value = vload_f3(l->value);
        ls->pdf = choice;
        ls->delta = true;
        return true;
    }
#endif
#if VOLCL_HAS_ENV_LIGHTS
    if (l->type == LIGHT_CONSTANT) {
        ls->wi = sample_uniform_sphere(u);
        ls->dist = INFINITY;
        ls->value = vload_f3(l->value);
        ls->pdf = choice * VOLCL_INV_4PI;
        return true;
    }
#endif
#if VOLCL_HAS_ENVMAP
    if (l->type == LIGHT_ENVMAP) {
        if (!envmap_sample(sc, l, u, &ls->wi, &ls->value, &ls->pdf)) return false;
        ls->dist = INFINITY;
        ls->pdf *= choice;
        return true;
    }
#endif
    return false;
}

#endif
