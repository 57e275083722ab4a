/* Texture coordinates and position derivatives (dp/du, dp/dv) at a hit, as Mitsuba 3.9 defines them
 * per shape (src/render/mesh.cpp, src/shapes):
 *  - meshes interpolate their corners' uvs; without any, uv = (b1, b2) and dp/du, dp/dv = the
 *    triangle's edges p1 - p0, p2 - p0 (the host stores those as corner uvs (0,0), (1,0), (0,1));
 *    a degenerate uv triangle falls back to a frame around the normal;
 *  - spheres: u = phi / 2 pi, v = theta / pi in the unit sphere's frame;
 *  - disks: u = r, v = phi / 2 pi (the disk is a triangle fan here, its uv analytic);
 *  - cylinders: u = phi / 2 pi, v = z;
 *  - rectangles and cubes are meshes with Mitsuba's corner uvs.
 * Only hits whose bsdf reads them (BSDF_FLAG_UV) compute these.
 */
#ifndef VOLCL_TEXCOORDS_H
#define VOLCL_TEXCOORDS_H

#define VOLCL_NEEDS_UV (VOLCL_HAS_TEXTURES || VOLCL_HAS_BUMP_MAPS || VOLCL_HAS_ROUGHCONDUCTOR \
                        || VOLCL_HAS_ROUGHDIELECTRIC)

#if VOLCL_NEEDS_UV
#if VOLCL_HAS_INSTANCES
#define VOLCL_SURFACE_TEXCOORDS surface_texcoords_local
#else
#define VOLCL_SURFACE_TEXCOORDS surface_texcoords
#endif

inline float phi_of(float x, float y) {
    float phi = atan2(y, x);
    return phi < 0.0f ? phi + 2.0f * VOLCL_PI : phi;
}

inline void texcoords_triangle(const SceneData *sc, const Hit *h, SurfacePoint *s) {
    __global const Triangle *tri = &sc->triangles[h->prim];
    if (tri->uvs < 0) {
        s->uv = (float2)(0.0f);
        make_frame(s->ng, &s->dpdu, &s->dpdv);
        return;
    }
    __global const float *c = sc->tri_uvs[tri->uvs].uv;
    float2 uv0 = (float2)(c[0], c[1]), uv1 = (float2)(c[2], c[3]), uv2 = (float2)(c[4], c[5]);
    float b1 = h->b1, b2 = h->b2;
    s->uv = uv0 * (1.0f - b1 - b2) + uv1 * b1 + uv2 * b2;
    float3 p0 = vload_f3(tri->p0);
    float3 e1 = vload_f3(tri->p1) - p0, e2 = vload_f3(tri->p2) - p0;
    float2 d1 = uv1 - uv0, d2 = uv2 - uv0;
    float det = d1.x * d2.y - d1.y * d2.x;
    if (det != 0.0f) {
        float inv = 1.0f / det;
        s->dpdu = (d2.y * e1 - d1.y * e2) * inv;
        s->dpdv = (d1.x * e2 - d2.x * e1) * inv;
    } else {
        make_frame(s->ng, &s->dpdu, &s->dpdv);
    }
}

inline void texcoords_analytic(__global const UvMap *m, SurfacePoint *s) {
    float3 l = affine_point(m->to_object, s->p);
    if (m->kind == UV_MAP_SPHERE) {
        float phi = phi_of(l.x, l.y);
        float theta = acos(clamp(l.z, -1.0f, 1.0f));
        s->uv = (float2)(phi * (0.5f * VOLCL_INV_PI), theta * VOLCL_INV_PI);
        float rd = sqrt(l.x * l.x + l.y * l.y);
        float3 dv = rd > 0.0f ? (float3)(l.z * l.x / rd, l.z * l.y / rd, -rd) : (float3)(1.0f, 0.0f, 0.0f);
        s->dpdu = affine_vector(m->to_world, (float3)(-l.y, l.x, 0.0f)) * (2.0f * VOLCL_PI);
        s->dpdv = affine_vector(m->to_world, dv) * VOLCL_PI;
    } else {
        float r = sqrt(l.x * l.x + l.y * l.y);
        float inv_r = r > 0.0f ? 1.0f / r : 0.0f;
        float c = l.x * inv_r, sn = l.y * inv_r;
        s->uv = (float2)(r, phi_of(l.x, l.y) * (0.5f * VOLCL_INV_PI));
        s->dpdu = affine_vector(m->to_world, (float3)(c, sn, 0.0f));
        s->dpdv = affine_vector(m->to_world, (float3)(-sn, c, 0.0f)) * (2.0f * VOLCL_PI * r);
    }
}

/* Fill s->uv, s->dpdu and s->dpdv for the hit h that surface_point made s from. */
inline void VOLCL_SURFACE_TEXCOORDS(const SceneData *sc, const Hit *h, SurfacePoint *s) {
#if VOLCL_HAS_CYLINDERS
    if (h->prim < 0 && analytic_is_cylinder(-h->prim - 1)) {
        __global const Cylinder *c = &sc->cylinders[-h->prim - 1 - VOLCL_CYLINDER_CODE_BASE];
        float3 l = affine_point(c->to_object, s->p);
        s->uv = (float2)(phi_of(l.x, l.y) * (0.5f * VOLCL_INV_PI), l.z);
        s->dpdu = affine_vector(c->to_world, (float3)(-l.y, l.x, 0.0f)) * (2.0f * VOLCL_PI);
        s->dpdv = affine_vector(c->to_world, (float3)(0.0f, 0.0f, 1.0f));
        return;
    }
#endif
    int map = sc->shapes[s->shape].uv_map;
    if (map >= 0) {
        texcoords_analytic(&sc->uv_maps[map], s);
        return;
    }
    if (h->prim >= 0) {
        texcoords_triangle(sc, h, s);
        return;
    }
    s->uv = (float2)(0.0f);
    make_frame(s->ng, &s->dpdu, &s->dpdv);
}

#if VOLCL_HAS_INSTANCES
/* On an instance, Mitsuba's: the group shape's uv, and its dp/du, dp/dv mapped by to_world. */
inline void surface_texcoords(const SceneData *sc, const Hit *h, SurfacePoint *s) {
    if (h->inst < 0) {
        surface_texcoords_local(sc, h, s);
        return;
    }
    __global const Instance *in = &sc->instances[h->inst];
    SurfacePoint l = *s;
    l.p = affine_point(in->to_object, s->p);
    l.ng = instance_normal_to_object(in, s->ng);
    l.ns = instance_normal_to_object(in, s->ns);
    surface_texcoords_local(sc, h, &l);
    s->uv = l.uv;
    s->dpdu = affine_vector(in->to_world, l.dpdu);
    s->dpdv = affine_vector(in->to_world, l.dpdv);
}
#endif
#endif

#endif
