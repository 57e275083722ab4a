/* Mitsuba's cylinder (src/shapes/cylinder.cpp): the open tube x^2 + y^2 = 1, 0 <= z <= 1 of its own
 * frame, no end caps, placed by an affine to_world. Rays are intersected in that frame (so a frame
 * that scales the cross-section unevenly gives the elliptic tube Mitsuba gives); the normal is the
 * frame's normal taken to the world by the inverse transpose, pointing away from the axis unless
 * flip_normals, and an emitting cylinder is sampled uniformly in (phi, z), with the pdf of a
 * circular tube (Mitsuba's, exact unless the cross-section is scaled unevenly).
 *
 * Analytic primitives share the negative BVH codes: code -(a + 1) is analytic index a, a sphere
 * below VOLCL_CYLINDER_CODE_BASE and cylinder a - VOLCL_CYLINDER_CODE_BASE above. */
#ifndef VOLCL_CYLINDER_H
#define VOLCL_CYLINDER_H

#define VOLCL_CYLINDER_CODE_BASE (1 << 30)

inline bool analytic_is_cylinder(int analytic) { return analytic >= VOLCL_CYLINDER_CODE_BASE; }

inline float3 affine_point(__global const float *m, float3 p) {
    return (float3)(m[0] * p.x + m[1] * p.y + m[2] * p.z + m[3],
                    m[4] * p.x + m[5] * p.y + m[6] * p.z + m[7],
                    m[8] * p.x + m[9] * p.y + m[10] * p.z + m[11]);
}

inline float3 affine_vector(__global const float *m, float3 v) {
    return (float3)(m[0] * v.x + m[1] * v.y + m[2] * v.z,
                    m[4] * v.x + m[5] * v.y + m[6] * v.z,
                    m[8] * v.x + m[9] * v.y + m[10] * v.z);
}

/* A frame normal to the world: multiply by the transpose of the world-to-frame matrix. */
inline float3 cylinder_world_normal(__global const Cylinder *c, float3 n_local) {
    __global const float *m = c->to_object;
    float3 n = (float3)(m[0] * n_local.x + m[4] * n_local.y + m[8] * n_local.z,
                        m[1] * n_local.x + m[5] * n_local.y + m[9] * n_local.z,
                        m[2] * n_local.x + m[6] * n_local.y + m[10] * n_local.z);
    n = normalize(n);
    return c->flip ? -n : n;
}

/* Nearest t in (eps, tmax) where o + t d meets the tube. The ray parameter is the same in the
 * cylinder's frame (the map is affine), and the roots come from the distance of the frame ray to the
 * axis (the form that does not cancel for small tubes far away, as in sphere_intersect). */
inline bool cylinder_intersect(__global const Cylinder *c, float3 o, float3 d, float tmax, float *t_out) {
    float3 lo = affine_point(c->to_object, o), ld = affine_vector(c->to_object, d);
    float a = ld.x * ld.x + ld.y * ld.y;
    if (!(a > 0.0f)) return false;              /* along the axis: never meets the open tube */
    float tc = -(lo.x * ld.x + lo.y * ld.y) / a;   /* closest approach to the axis */
    float lx = lo.x + tc * ld.x, ly = lo.y + tc * ld.y;
    float disc = 1.0f - (lx * lx + ly * ly);
    if (disc < 0.0f) return false;
    float h = sqrt(disc / a);
    /* a root this close to zero is the surface the ray just left (its origin was offset from it) */
    float3 w0 = (float3)(c->to_world[3], c->to_world[7], c->to_world[11]);
    float eps = 1e-6f * (length(o - w0) + length(affine_vector(c->to_world, (float3)(1.0f, 0.0f, 1.0f))));
    /* the nearer root first: the far one counts where the near one misses the tube's length */
    float t = tc - h;
    float z = lo.z + t * ld.z;
    if (!(t > eps && t < tmax && z >= 0.0f && z <= 1.0f)) {
        t = tc + h;
        z = lo.z + t * ld.z;
        if (!(t > eps && t < tmax && z >= 0.0f && z <= 1.0f)) return false;
    }
    *t_out = t;
    return true;
}

/* The point of the tube nearest to world point x (the hit o + t d carries the rounding of t), in the
 * cylinder's frame: on the unit circle, z clamped to [0, 1]. */
inline float3 cylinder_local_surface(__global const Cylinder *c, float3 x) {
    float3 l = affine_point(c->to_object, x);
    float r = sqrt(l.x * l.x + l.y * l.y);
    return r > 0.0f ? (float3)(l.x / r, l.y / r, clamp(l.z, 0.0f, 1.0f)) : (float3)(1.0f, 0.0f, clamp(l.z, 0.0f, 1.0f));
}

/* The coordinates' magnitude a hit point on the tube was computed from (SurfacePoint.mag). */
inline float cylinder_magnitude(__global const Cylinder *c) {
    __global const float *m = c->to_world;
    float3 base = fabs((float3)(m[3], m[7], m[11]));
    float3 reach = fabs((float3)(m[0], m[4], m[8])) + fabs((float3)(m[1], m[5], m[9]))
                 + fabs((float3)(m[2], m[6], m[10]));
    return max_component(base + reach);
}

/* A point uniform in (phi, z) on the tube, in its frame: phi = 2 pi u.y, z = u.x (Mitsuba's
 * sample_position). */
inline float3 cylinder_local_sample(float2 u) {
    float phi = 2.0f * VOLCL_PI * u.y;
    return (float3)(cos(phi), sin(phi), u.x);
}

#endif
