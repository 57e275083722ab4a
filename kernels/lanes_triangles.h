/* Ray queries for the SIMD lanes over a scene small enough to test whole: the lanes stages
 * (wavefront_lanes.cl, wavefront_surface.cl) trace with these when volcl/wavefront.py (tiny_lanes)
 * finds the scene's leaf packets hold at most TINY_LANES opaque triangles and TINY_SPHERES opaque
 * spheres, and builds the stage with VOLCL_WF_TINY set to the triangles' number,
 * VOLCL_WF_TINY_ENDS to a mask of the triangles that end a packet and VOLCL_WF_SPHERES to the
 * spheres' number. A tree walk is an inner loop, which stops the vectorizers; a fixed list of
 * primitives unrolls into straight-line code.
 *
 * The triangles are the leaf packets' used lanes in packet order, in the stage's table
 * (wavefront_state.h WF_TRI_AT). Every test is packet_triangles_hit's
 * watertight test (bvh.h), operation for operation, and the closest hit is chosen as the
 * traversal chooses it within a one-leaf tree: each packet against the nearest hit of the packets
 * before it, the nearest lane of a packet winning, ties to the lower lane. So a hit has the
 * megakernel's bits (in a tree of several leaves, the traversal visits packets in another order,
 * which can only change which of two triangles at the same distance wins). */
#ifndef VOLCL_LANES_TRIANGLES_H
#define VOLCL_LANES_TRIANGLES_H

/* shear_make (bvh.h) on scalars, the permutation as booleans: a chain of compares on one int
 * would become a switch */
typedef struct {
    bool x0, x1, y0, y1, z0, z1;    /* kx == 0, kx == 1, ... (else 2) */
    float sx, sy, sz, ox, oy, oz;
} LanesShear;

inline float lanes_pick(bool is0, bool is1, float a, float b, float c) { return is0 ? a : (is1 ? b : c); }

/* v, made to wait for `dep`: v itself unless dep is NaN, and then the triangle test that uses it
 * finds no hit either way (a NaN corner coordinate makes det and the distance NaN). Only in scenes
 * of more than 4 triangles, where the SLP vectorizer packed the test's coordinates (lanes.h): the
 * waits cost point_in_fog's 4 triangles 10-20% of the wavefront renderer's speed on PoCL. */
#ifndef VOLCL_WF_CHAIN
#define VOLCL_WF_CHAIN (VOLCL_WF_TINY > 4)
#endif
#if VOLCL_WF_CHAIN
inline float lanes_wait(float v, float dep) { return dep == dep ? v : dep; }
#else
inline float lanes_wait(float v, float dep) { (void)dep; return v; }
#endif

inline LanesShear lanes_shear(V3 o, V3 d) {
    LanesShear s;
    /* |d| three ways: the same values, but two fabs side by side were packed into a <2 x float>,
     * which stops the loop vectorizer (lanes.h) */
    float ax = fabs(d.x), ay = d.y < 0.0f ? -d.y : d.y, az = fmax(d.z, -d.z);
    int kz = (ax > ay) ? (ax > az ? 0 : 2) : (ay > az ? 1 : 2);
    int kx = kz == 2 ? 0 : kz + 1;
    int ky = kx == 2 ? 0 : kx + 1;
    bool flip = lanes_pick(kz == 0, kz == 1, d.x, d.y, d.z) < 0.0f;
    int fx = flip ? ky : kx, fy = flip ? kx : ky;
    s.x0 = fx == 0;
    s.x1 = fx == 1;
    s.y0 = fy == 0;
    s.y1 = fy == 1;
    s.z0 = kz == 0;
    s.z1 = kz == 1;
    float dx = lanes_pick(s.x0, s.x1, d.x, d.y, d.z), dy = lanes_pick(s.y0, s.y1, d.x, d.y, d.z);
    float dz = lanes_pick(s.z0, s.z1, d.x, d.y, d.z);
    s.sx = dx / dz;
    s.sy = lanes_wait(dy, s.sx) / dz;       /* (the two divisions side by side were packed: lanes.h) */
    s.sz = 1.0f / dz;
    s.ox = lanes_pick(s.x0, s.x1, o.x, o.y, o.z);
    s.oy = lanes_pick(s.y0, s.y1, o.x, o.y, o.z);
    s.oz = lanes_pick(s.z0, s.z1, o.x, o.y, o.z);
    return s;
}

/* The watertight test of triangle k of the table (vertex coordinate c at WF_TRI_AT(c, k)) for
 * hits in (0, tmax): whether it is hit, and the distance and barycentrics scaled by det. */
inline bool lanes_triangle_hit(__global const float *table, int k, const LanesShear *s, float tmax,
                               float *t_scaled, float *det, float *e1, float *e2) {
#pragma OPENCL FP_CONTRACT OFF
#define VOLCL_TV(c) table[WF_TRI_AT(c, k)]
    float az = lanes_pick(s->z0, s->z1, VOLCL_TV(0), VOLCL_TV(1), VOLCL_TV(2)) - s->oz;
    float bz = lanes_pick(s->z0, s->z1, VOLCL_TV(3), VOLCL_TV(4), VOLCL_TV(5)) - s->oz;
    float cz = lanes_pick(s->z0, s->z1, VOLCL_TV(6), VOLCL_TV(7), VOLCL_TV(8)) - s->oz;
    /* the six sheared coordinates in a chain, each waiting for the one before (lanes_wait): any two
     * of them side by side were packed into <2 x float> vectors, in scenes of 12 triangles */
    float ax = (lanes_pick(s->x0, s->x1, VOLCL_TV(0), VOLCL_TV(1), VOLCL_TV(2)) - s->ox) - s->sx * az;
    float ay = (lanes_pick(s->y0, s->y1, VOLCL_TV(0), VOLCL_TV(1), VOLCL_TV(2)) - lanes_wait(s->oy, ax)) - s->sy * az;
    float bx = (lanes_pick(s->x0, s->x1, VOLCL_TV(3), VOLCL_TV(4), VOLCL_TV(5)) - lanes_wait(s->ox, ay)) - s->sx * bz;
    float by = (lanes_pick(s->y0, s->y1, VOLCL_TV(3), VOLCL_TV(4), VOLCL_TV(5)) - lanes_wait(s->oy, bx)) - s->sy * bz;
    float cx = (lanes_pick(s->x0, s->x1, VOLCL_TV(6), VOLCL_TV(7), VOLCL_TV(8)) - lanes_wait(s->ox, by)) - s->sx * cz;
    float cy = (lanes_pick(s->y0, s->y1, VOLCL_TV(6), VOLCL_TV(7), VOLCL_TV(8)) - lanes_wait(s->oy, cx)) - s->sy * cz;
#undef VOLCL_TV
    float u = cx * by - cy * bx;
    *e1 = ax * cy - ay * cx;
    *e2 = bx * ay - by * ax;
    bool outside = ((u < 0.0f) | (*e1 < 0.0f) | (*e2 < 0.0f)) & ((u > 0.0f) | (*e1 > 0.0f) | (*e2 > 0.0f));
    *det = u + *e1 + *e2;
    *t_scaled = (u * az + *e1 * bz + *e2 * cz) * s->sz;
    float t_det = tmax * *det;
    bool in_range = *det < 0.0f ? (*t_scaled < 0.0f) & (*t_scaled > t_det) : (*t_scaled > 0.0f) & (*t_scaled < t_det);
    return !outside & (*det != 0.0f) & in_range;
}

/* sphere_intersect (bvh.h) on sphere k of the table: the same arithmetic, selects for its branches */
inline bool lanes_sphere_hit(__global const float *table, int k, V3 o, V3 d, float tmax, float *t_out) {
#define VOLCL_SV(c) table[WF_SPH_AT(c, k)]
    V3 f = v3_sub(o, v3(VOLCL_SV(0), VOLCL_SV(1), VOLCL_SV(2)));
    float r = VOLCL_SV(3);
#undef VOLCL_SV
    float b = -lanes_dot(f, d);
    V3 l = v3_madd(f, b, d);
    float disc = r * r - lanes_dot(l, l);
    float q = b + copysign(sqrt(fmax(disc, 0.0f)), b);
    float ff = lanes_dot(f, f);
    float c_term = ff - r * r;
    bool zero = q == 0.0f;
    float t0 = zero ? 0.0f : c_term / q, t1 = zero ? 0.0f : q;
    float lo = t0 > t1 ? t1 : t0, hi = t0 > t1 ? t0 : t1;
    /* a root this close to zero is the surface the ray just left */
    float eps = 1e-6f * fmax(r, sqrt(ff));
    float t = lo > eps ? lo : hi;
    *t_out = t;
    return !(disc < 0.0f) & (t > eps) & (t < tmax);
}

/* The closest hit in (0, tmax) (bvh_trace's TRACE_CLOSEST): whether there is one, and its
 * distance, barycentrics, primitive code and, for a triangle, its lane in the table (else -1).
 * Spheres come after the triangles: in a tree they can come before, which changes only which of a
 * sphere and a triangle at the same distance wins. */
inline bool lanes_closest_hit(__global const float *table, V3 o, V3 d, float tmax, float *t, float *b1, float *b2,
                              int *prim, int *slot) {
    LanesShear s = lanes_shear(o, d);
    float best = tmax, pt = 0.0f, pb1 = 0.0f, pb2 = 0.0f;
    int pprim = 0, pslot = -1;
    bool found = false, any = false;
    *t = tmax;
    *b1 = *b2 = 0.0f;
    *prim = 0;
    *slot = -1;
#pragma unroll
    for (int k = 0; k < VOLCL_WF_TINY; ++k) {
        float ts, det, e1, e2;
        bool ok = lanes_triangle_hit(table, k, &s, best, &ts, &det, &e1, &e2);
        float inv = 1.0f / det;
        float tk = ok ? ts * inv : VOLCL_INF;
        int code = as_int(table[WF_TRI_AT(9, k)]);     /* read either way: a load under a condition stops the vectorizer */
        /* a packet's lanes against the same tmax, the nearest (first on ties) kept */
        bool take = (k == 0 || ((VOLCL_WF_TINY_ENDS >> (k - 1)) & 1)) | (tk < pt);
        pt = take ? tk : pt;
        pb1 = take ? e1 * inv : pb1;
        pb2 = take ? e2 * inv : pb2;
        pprim = take ? code : pprim;
        pslot = take ? k : pslot;
        any = any | ok;
        if ((VOLCL_WF_TINY_ENDS >> k) & 1) {     /* the packet's end: its hit, if any */
            *t = any ? pt : *t;
            *b1 = any ? pb1 : *b1;
            *b2 = any ? pb2 : *b2;
            *prim = any ? pprim : *prim;
            *slot = any ? pslot : *slot;
            found = found | any;
            best = *t;
            any = false;
        }
    }
#pragma unroll
    for (int k = 0; k < VOLCL_WF_SPHERES; ++k) {
        float tk;
        bool ok = lanes_sphere_hit(table, k, o, d, *t, &tk);
        int code = as_int(table[WF_SPH_AT(4, k)]);
        *t = ok ? tk : *t;
        *b1 = ok ? 0.0f : *b1;
        *b2 = ok ? 0.0f : *b2;
        *prim = ok ? code : *prim;
        *slot = ok ? -1 : *slot;
        found = found | ok;
    }
    return found;
}

/* Whether anything blocks the segment (0, tmax) (every triangle is opaque, so this is what
 * shadow_transmittance's shadow query decides): tmax if not, else -1. Triangle k is left out where
 * bit k of `skip` is set (a constant: the unrolled loop keeps only the others): VOLCL_WF_HULL_SKIP
 * for a segment between two points of the scene, the faces of its convex hull (volcl.hull). */
inline float lanes_reach(__global const float *table, V3 o, V3 d, float tmax, int skip) {
    LanesShear s = lanes_shear(o, d);
    /* a hit makes the segment empty for the triangles after it: a chain of selects, where an OR of
     * the tests was packed into a vector as a horizontal reduction (which stops the loop vectorizer) */
    float reach = tmax;
#pragma unroll
    for (int k = 0; k < VOLCL_WF_TINY; ++k) {
        if ((skip >> k) & 1) continue;
        float ts, det, e1, e2;
        reach = lanes_triangle_hit(table, k, &s, reach, &ts, &det, &e1, &e2) ? -1.0f : reach;
    }
#pragma unroll
    for (int k = 0; k < VOLCL_WF_SPHERES; ++k) {
        float tk;
        reach = lanes_sphere_hit(table, k, o, d, reach, &tk) ? -1.0f : reach;
    }
    return reach;
}

#endif
