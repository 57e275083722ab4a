/* Light sampling and the pdfs that multiple importance sampling needs.
 * A light is chosen uniformly; pdfs include that choice and are per unit solid angle at the
 * receiving point, except for delta lights (point, directional), whose pdf is the choice
 * probability alone. Area lights emit on the side their shading normal faces.
 */
#ifndef VOLCL_LIGHTS_H
#define VOLCL_LIGHTS_H

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

inline float light_env_pdf(const SceneData *sc) { return VOLCL_INV_4PI / (float)sc->params->light_count; }

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
#if VOLCL_HAS_POINT_LIGHTS
    if (l->type == LIGHT_POINT) {
        float3 v = vload_f3(l->position) - ref;
        float d2 = dot(v, v);
        if (!(d2 > 0.0f)) return false;
        ls->dist = sqrt(d2);
        ls->wi = v / ls->dist;
        ls->value = vload_f3(l->value) / d2;
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
    return false;
}

#endif
