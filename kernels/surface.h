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
} SurfacePoint;

inline SurfacePoint surface_point(const SceneData *sc, const Hit *h, float3 o, float3 d) {
    SurfacePoint s;
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
        return s;
    }
#endif
    __global const Triangle *tri = &sc->triangles[h->prim];
    float3 p0 = vload_f3(tri->p0), p1 = vload_f3(tri->p1), p2 = vload_f3(tri->p2);
    float b0 = 1.0f - h->b1 - h->b2;
    /* barycentric interpolation stays on the triangle's plane, unlike o + t d */
    s.p = b0 * p0 + h->b1 * p1 + h->b2 * p2;
    s.ng = normalize(cross(p1 - p0, p2 - p0));
    s.ns = s.ng;
#if VOLCL_HAS_SHADING_NORMALS
    if (tri->normals >= 0) {
        __global const TriangleNormals *tn = &sc->normals[tri->normals];
        float3 n = b0 * vload_f3(tn->n0) + h->b1 * vload_f3(tn->n1) + h->b2 * vload_f3(tn->n2);
        float len = length(n);
        if (len > 0.0f) s.ns = n / len;
    }
#endif
    s.shape = tri->shape;
    return s;
}

#endif
