/* Ray queries against the BVH: closest hit and any hit, over triangles and analytic spheres.
 *
 * Triangles use the watertight test of Woop, Benthin and Wald (2013): the ray is sheared to +z and
 * edge functions decide coverage, so a ray through a shared edge or vertex hits at least one of the
 * triangles sharing it (no leaks through closed meshes). Degenerate triangles give det == 0 and
 * never hit.
 */
#ifndef VOLCL_BVH_H
#define VOLCL_BVH_H

#include "cylinder.h"   /* analytic cylinders (VOLCL_HAS_CYLINDERS) */

#define VOLCL_BVH_STACK 64

typedef struct {
    float t;
    int prim;       /* code from prim_ids: >= 0 triangle, < 0 analytic (sphere or cylinder, cylinder.h) */
    float b1, b2;   /* barycentrics of p1 and p2 on triangles */
} Hit;

/* Per-ray constants of the watertight test: the axis permutation (kz = the direction's largest
 * component), the shear, and the origin in permuted order. */
typedef struct {
    int kx, ky, kz;
    float sx, sy, sz;
    float ox, oy, oz;
} Shear;

inline float component(float3 v, int k) { return k == 0 ? v.x : (k == 1 ? v.y : v.z); }

inline Shear shear_make(float3 o, float3 d) {
    Shear s;
    float3 a = fabs(d);
    s.kz = (a.x > a.y) ? (a.x > a.z ? 0 : 2) : (a.y > a.z ? 1 : 2);
    s.kx = s.kz == 2 ? 0 : s.kz + 1;
    s.ky = s.kx == 2 ? 0 : s.kx + 1;
    float dz = component(d, s.kz);
    if (dz < 0.0f) { int tmp = s.kx; s.kx = s.ky; s.ky = tmp; }
    s.sx = component(d, s.kx) / dz;
    s.sy = component(d, s.ky) / dz;
    s.sz = 1.0f / dz;
    s.ox = component(o, s.kx);
    s.oy = component(o, s.ky);
    s.oz = component(o, s.kz);
    return s;
}

/* Vertices are read in the ray's permuted axis order straight from memory (p[k] with a per-ray k),
 * which costs an address computation instead of a select chain per component. */
__attribute__((always_inline))
inline bool triangle_intersect(__global const Triangle *tri, const Shear *sh, float tmax,
                               float *t_out, float *b1_out, float *b2_out) {
    /* the edge functions must round identically for the two triangles sharing an edge, and a fused
     * multiply-add in one of them breaks that (and makes zero-size triangles report hits) */
#pragma OPENCL FP_CONTRACT OFF
    float az = tri->p0[sh->kz] - sh->oz, bz = tri->p1[sh->kz] - sh->oz, cz = tri->p2[sh->kz] - sh->oz;
    float ax = (tri->p0[sh->kx] - sh->ox) - sh->sx * az, ay = (tri->p0[sh->ky] - sh->oy) - sh->sy * az;
    float bx = (tri->p1[sh->kx] - sh->ox) - sh->sx * bz, by = (tri->p1[sh->ky] - sh->oy) - sh->sy * bz;
    float cx = (tri->p2[sh->kx] - sh->ox) - sh->sx * cz, cy = (tri->p2[sh->ky] - sh->oy) - sh->sy * cz;
    float u = cx * by - cy * bx;
    float v = ax * cy - ay * cx;
    float w = bx * ay - by * ax;
    if ((u < 0.0f || v < 0.0f || w < 0.0f) && (u > 0.0f || v > 0.0f || w > 0.0f)) return false;
    float det = u + v + w;
    if (det == 0.0f) return false;
    float t_scaled = (u * az + v * bz + w * cz) * sh->sz;
    /* compare before dividing, with the sign of det folded in */
    if (det < 0.0f ? (t_scaled >= 0.0f || t_scaled <= tmax * det) : (t_scaled <= 0.0f || t_scaled >= tmax * det))
        return false;
    float inv = 1.0f / det;
    *t_out = t_scaled * inv;
    *b1_out = v * inv;
    *b2_out = w * inv;
    return true;
}

/* Nearest root of |o + t d - c| = r in (0, tmax). The discriminant is formed from the distance of
 * the centre to the ray's line (Haines et al., Ray Tracing Gems ch. 7) instead of b^2 - 4ac, which
 * cancels catastrophically for small spheres far from the origin. */
inline bool sphere_intersect(__global const Sphere *sp, float3 o, float3 d, float tmax, float *t_out) {
    float3 c = vload_f3(sp->center);
    float r = sp->radius;
    float3 f = o - c;
    float b = -dot(f, d);
    float3 l = f + b * d;
    float disc = r * r - dot(l, l);
    if (disc < 0.0f) return false;
    float q = b + copysign(sqrt(disc), b);
    float c_term = dot(f, f) - r * r;
    float t0 = c_term / q, t1 = q;
    if (q == 0.0f) t0 = t1 = 0.0f;
    if (t0 > t1) { float tmp = t0; t0 = t1; t1 = tmp; }
    /* a root this close to zero is the surface the ray just left (its origin was offset from it) */
    float eps = 1e-6f * fmax(r, length(f));
    float t = t0 > eps ? t0 : t1;
    if (!(t > eps && t < tmax)) return false;
    *t_out = t;
    return true;
}

/* Entry distance of the ray into a node's box, or INF when it misses within [0, tmax]. The exit
 * distance is widened by a few ulps so rounding never culls a box the ray grazes. inv_d is finite
 * (see bvh_trace), so no slab product is NaN and plain compares can replace fmin/fmax, whose NaN
 * rules cost extra instructions on every node. */
__attribute__((always_inline))
inline float node_entry(__global const BvhNode *n, float3 o, float3 inv_d, float tmax) {
    float3 t0 = (vload_f3(n->bmin) - o) * inv_d;
    float3 t1 = (vload_f3(n->bmax) - o) * inv_d;
    float3 lo = select(t1, t0, t0 < t1), hi = select(t0, t1, t0 < t1);
    float enter = lo.x > lo.y ? lo.x : lo.y;
    enter = enter > lo.z ? enter : lo.z;
    enter = enter > 0.0f ? enter : 0.0f;
    float leave = hi.x < hi.y ? hi.x : hi.y;
    leave = leave < hi.z ? leave : hi.z;
    leave = (leave < tmax ? leave : tmax) * 1.0000004f;
    return enter <= leave ? enter : VOLCL_INF;
}

__attribute__((always_inline))
inline bool prim_intersect(const SceneData *sc, int code, float3 o, float3 d, const Shear *sh, float tmax,
                           Hit *hit) {
    float t, b1 = 0.0f, b2 = 0.0f;
#if VOLCL_HAS_SPHERES || VOLCL_HAS_CYLINDERS
    if (code < 0) {
        int a = -code - 1;
#if VOLCL_HAS_CYLINDERS
        if (analytic_is_cylinder(a)) {
            if (!cylinder_intersect(&sc->cylinders[a - VOLCL_CYLINDER_CODE_BASE], o, d, tmax, &t)) return false;
        } else
#endif
        if (!sphere_intersect(&sc->spheres[a], o, d, tmax, &t)) return false;
    } else
#endif
    if (!triangle_intersect(&sc->triangles[code], sh, tmax, &t, &b1, &b2)) return false;
    hit->t = t;
    hit->prim = code;
    hit->b1 = b1;
    hit->b2 = b2;
    return true;
}

/* Closest hit in (0, tmax). any_hit: return at the first hit found (shadow rays). An empty scene is
 * uploaded as one leaf with an inverted box, which no ray enters. */
inline bool bvh_trace(const SceneData *sc, float3 o, float3 d, float tmax, bool any_hit, Hit *hit) {
    Shear sh = shear_make(o, d);
    /* a zero direction component becomes a tiny one of the same sign: its slab then spans
     * +-1e30 instead of producing 0 * INF = NaN for an origin on the slab plane */
    float3 inv_d = 1.0f / select(d, copysign((float3)(1e-30f), d), fabs(d) < (float3)(1e-30f));
    int stack[VOLCL_BVH_STACK];
    int top = 0;
    int node = 0;
    bool found = false;
    hit->t = tmax;
    if (node_entry(&sc->nodes[0], o, inv_d, tmax) == VOLCL_INF) return false;
    for (;;) {
        __global const BvhNode *n = &sc->nodes[node];
        if (n->count > 0) {
            for (int i = n->index; i < n->index + n->count; ++i) {
                if (prim_intersect(sc, sc->prim_ids[i], o, d, &sh, hit->t, hit)) {
                    found = true;
                    if (any_hit) return true;
                }
            }
        } else {
            int left = node + 1, right = n->index;
            float tl = node_entry(&sc->nodes[left], o, inv_d, hit->t);
            float tr = node_entry(&sc->nodes[right], o, inv_d, hit->t);
            if (tl != VOLCL_INF || tr != VOLCL_INF) {
                if (tl == VOLCL_INF) { node = right; continue; }
                if (tr == VOLCL_INF) { node = left; continue; }
                /* visit the nearer child first; the farther waits on the stack */
                if (tr < tl) { int tmp = left; left = right; right = tmp; }
                stack[top++] = right;
                node = left;
                continue;
            }
        }
        if (top == 0) break;
        node = stack[--top];
    }
    return found;
}

#endif
