/* What a ray hit: position, geometric and shading normals, and the shape it belongs to.
 * The geometric normal follows the triangle's winding (or points out of a sphere) and decides sides:
 * media transitions and ray offsets. The shading normal (interpolated vertex normals) frames the
 * BSDF and decides which side an area light emits on, as in Mitsuba. */
#ifndef VOLCL_SURFACE_H
#define VOLCL_SURFACE_H

typedef struct {
    float3 p;
    float3 ng;
    float3 ns;
    int shape;
    float mag;      /* magnitude of the coordinates p was computed from: scales offset_origin */
    float2 uv;      /* texture coordinates and position derivatives: set by surface_texcoords */
    float3 dpdu, dpdv;  /* (texcoords.h) where the bsdf reads them */
} SurfacePoint;

/* Hazard: forcing the inlining of a function that returns a struct makes LLVM 14 (at -O0 too) mark
 * the returned copy with llvm.experimental.noalias.scope.decl, which Oclgrind 21.10 cannot run
 * ("Undefined external function"); unoptimized builds (-cl-opt-disable, no __OPTIMIZE__) leave
 * inlining to the compiler, optimized ones keep forcing it. */
#if VOLCL_HAS_INSTANCES
#define VOLCL_SURFACE_POINT surface_point_local     /* a hit in the space its primitive is stored in */
#else
#define VOLCL_SURFACE_POINT surface_point
#endif
#ifdef __OPTIMIZE__
__attribute__((always_inline))
#endif
inline SurfacePoint VOLCL_SURFACE_POINT(const SceneData *sc, const Hit *h, float3 o, float3 d) {
    SurfacePoint s;
#if VOLCL_HAS_CYLINDERS
    if (h->prim < 0 && analytic_is_cylinder(-h->prim - 1)) {
        __global const Cylinder *c = &sc->cylinders[-h->prim - 1 - VOLCL_CYLINDER_CODE_BASE];
        float3 l = cylinder_local_surface(c, o + h->t * d);
        s.p = affine_point(c->to_world, l);
        s.ng = cylinder_world_normal(c, (float3)(l.x, l.y, 0.0f));
        s.ns = s.ng;
        s.shape = c->shape;
        s.mag = cylinder_magnitude(c);
        return s;
    }
#endif
#if VOLCL_HAS_SPHERES
    if (h->prim < 0) {
        __global const Sphere *sp = &sc->spheres[-h->prim - 1];
        float3 c = vload_f3(sp->center);
        float3 n = normalize(o + h->t * d - c);
        /* project back onto the sphere: o + t d carries the rounding of t */
        s.p = c + sp->radius * n;
        s.ng = sp->flip ? -n : n;
        s.ns = s.ng;
        s.shape = sp->shape;
        s.mag = max_component(fabs(c)) + sp->radius;
        return s;
    }
#endif
    __global const Triangle *tri = &sc->triangles[h->prim];
    float3 p0 = vload_f3(tri->p0), p1 = vload_f3(tri->p1), p2 = vload_f3(tri->p2);
    /* A hit exactly on an edge would leave the next ray's origin on the neighbouring face's plane
     * too; a direction through that face then crosses it at t = 0, which the intersection test
     * rejects, and the path slips out of a closed mesh unseen (at a box's corner edges, offsetting
     * along this face's normal does not help). Pulling the point a hair into the triangle's
     * interior gives every neighbour a positive distance. Barycentric interpolation also keeps the
     * point on the triangle's plane, unlike o + t d. */
    float b1 = fmax(h->b1, 1e-5f), b2 = fmax(h->b2, 1e-5f), b0 = fmax(1.0f - h->b1 - h->b2, 1e-5f);
    float inv_sum = 1.0f / (b0 + b1 + b2);
    b0 *= inv_sum;
    b1 *= inv_sum;
    b2 *= inv_sum;
    s.p = b0 * p0 + b1 * p1 + b2 * p2;
    /* Hazard: a sliver the watertight test still hits (its det is taken in the ray's sheared frame)
     * can have a cross product that rounds to zero, and normalizing it gives NaN or zero; such a hit
     * faces the ray (its own winding is lost to rounding) instead of poisoning the path */
    float3 ng = normalize(cross(p1 - p0, p2 - p0));
    s.ng = dot(ng, ng) > 0.5f ? ng : -d;    /* false for NaN and for a zero vector */
    s.ns = s.ng;
#if VOLCL_HAS_SHADING_NORMALS
    if (tri->normals >= 0) {
        __global const TriangleNormals *tn = &sc->normals[tri->normals];
        float3 n = b0 * vload_f3(tn->n0) + b1 * vload_f3(tn->n1) + b2 * vload_f3(tn->n2);
        float len = length(n);
        if (len > 0.0f) s.ns = n / len;
    }
#endif
    s.shape = tri->shape;
    s.mag = max_component(fmax(fabs(p0), fmax(fabs(p1), fabs(p2))));
    return s;
}

#if VOLCL_HAS_INSTANCES
/* A group-space normal to the world: by the inverse transpose of the instance's to_world, i.e. the
 * transpose of its to_object (Mitsuba's Instance: normalize(to_world * Normal3f), which ignores the
 * sign of the map's determinant). */
inline float3 instance_normal_to_world(__global const Instance *in, float3 n) {
    __global const float *m = in->to_object;
    return normalize((float3)(m[0] * n.x + m[4] * n.y + m[8] * n.z,
                              m[1] * n.x + m[5] * n.y + m[9] * n.z,
                              m[2] * n.x + m[6] * n.y + m[10] * n.z));
}

/* A world normal back to the group's space: by the transpose of to_world. */
inline float3 instance_normal_to_object(__global const Instance *in, float3 n) {
    __global const float *m = in->to_world;
    return normalize((float3)(m[0] * n.x + m[4] * n.y + m[8] * n.z,
                              m[1] * n.x + m[5] * n.y + m[9] * n.z,
                              m[2] * n.x + m[6] * n.y + m[10] * n.z));
}

/* The world point of a hit: the group-space point (computed from the ray taken into the group's
 * space, whose parameter is the world one) mapped back, its normals by the inverse transpose. */
#ifdef __OPTIMIZE__
__attribute__((always_inline))
#endif
inline SurfacePoint surface_point(const SceneData *sc, const Hit *h, float3 o, float3 d) {
    if (h->inst < 0) return surface_point_local(sc, h, o, d);
    __global const Instance *in = &sc->instances[h->inst];
    SurfacePoint s = surface_point_local(sc, h, affine_point(in->to_object, o), affine_vector(in->to_object, d));
    s.p = affine_point(in->to_world, s.p);
    s.ng = instance_normal_to_world(in, s.ng);
    s.ns = instance_normal_to_world(in, s.ns);
    /* the world coordinates' magnitude: the translation plus the linear part's row sums times the
     * group-space magnitude (offset_origin scales its offset by it) */
    __global const float *m = in->to_world;
    float3 rows = fabs((float3)(m[0], m[4], m[8])) + fabs((float3)(m[1], m[5], m[9]))
                + fabs((float3)(m[2], m[6], m[10]));
    s.mag = max_component(fabs((float3)(m[3], m[7], m[11])) + rows * s.mag);
    return s;
}
#endif

#endif
