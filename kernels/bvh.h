/* Ray queries against the BVH: closest hit, any hit, and the shadow query (the closest hit on a
 * null surface unless an opaque one is in the way), over triangles and analytic spheres.
 *
 * Triangles use the watertight test of Woop, Benthin and Wald (2013): the ray is sheared to +z and
 * edge functions decide coverage, so a ray through a shared edge or vertex hits at least one of the
 * triangles sharing it (no leaks through closed meshes). Degenerate triangles give det == 0 and
 * never hit.
 */
#ifndef VOLCL_BVH_H
#define VOLCL_BVH_H

#include "cylinder.h"   /* analytic cylinders (VOLCL_HAS_CYLINDERS) */

/* Deepest stack a traversal can reach; volcl/bvh_wide.py STACK builds trees within it. */
#define VOLCL_BVH_STACK 128

#if VOLCL_BVH_WIDTH == 8
typedef float8 floatW;
typedef int8 intW;
#define vloadW vload8
#define vstoreW vstore8
#elif VOLCL_BVH_WIDTH == 4
typedef float4 floatW;
typedef int4 intW;
#define vloadW vload4
#define vstoreW vstore4
#else
#error "VOLCL_BVH_WIDTH must be 4 or 8"
#endif

#if VOLCL_LEAF_WIDTH == 4
typedef float4 floatL;
typedef int4 intL;
#define vloadL vload4
#define vstoreL vstore4
#elif VOLCL_LEAF_WIDTH == 8
typedef float8 floatL;
typedef int8 intL;
#define vloadL vload8
#define vstoreL vstore8
#else
#error "VOLCL_LEAF_WIDTH must be 4 or 8"
#endif

/* bvh_trace queries */
#define TRACE_CLOSEST 0     /* the nearest hit */
#define TRACE_ANY 1         /* whether anything is hit (the hit reported is not the nearest) */
#define TRACE_SHADOW 2      /* the nearest hit, or some opaque hit (it is not searched beyond one) */

typedef struct {
    float t;
    int prim;       /* primitive code (LeafPacket.prim): >= 0 triangle, < 0 analytic (sphere or cylinder, cylinder.h) */
    float b1, b2;   /* barycentrics of p1 and p2 on triangles */
#if VOLCL_HAS_INSTANCES
    int inst;       /* the instance whose shape group holds prim (prim in the group's space), or -1 */
#endif
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
    if (component(d, s.kz) < 0.0f) { int tmp = s.kx; s.kx = s.ky; s.ky = tmp; }
    /* both vectors in the permuted order by one shuffle each, not a select chain per component */
    uint4 perm = (uint4)((uint)s.kx, (uint)s.ky, (uint)s.kz, 3u);
    float4 dp = shuffle((float4)(d, 0.0f), perm), op = shuffle((float4)(o, 0.0f), perm);
    s.sx = dp.x / dp.z;
    s.sy = dp.y / dp.z;
    s.sz = 1.0f / dp.z;
    s.ox = op.x;
    s.oy = op.y;
    s.oz = op.z;
    return s;
}

/* The watertight test on every lane of a leaf packet at once, for hits in (0, tmax); returns the
 * lanes hit as a mask. Vertices are read in the ray's permuted axis order straight from memory
 * (row 3 * vertex + k with a per-ray k), which costs an address computation instead of a select
 * chain per component. Every lane does the operations of the scalar test in the same order, so a
 * triangle rounds alike in whichever packet and lane it sits. */
__attribute__((always_inline))
inline intL packet_triangles_hit(__global const LeafPacket *pk, const Shear *sh, float tmax, floatL *t_scaled,
                                 floatL *det, floatL *e1, floatL *e2) {
    /* the edge functions must round identically for the two triangles sharing an edge, and a fused
     * multiply-add in one of them breaks that (and makes zero-size triangles report hits) */
#pragma OPENCL FP_CONTRACT OFF
    __global const float *v = &pk->v[0][0];
    const int L = VOLCL_LEAF_WIDTH;
    floatL az = vloadL(0, v + L * sh->kz) - sh->oz;
    floatL bz = vloadL(0, v + L * (3 + sh->kz)) - sh->oz;
    floatL cz = vloadL(0, v + L * (6 + sh->kz)) - sh->oz;
    floatL ax = (vloadL(0, v + L * sh->kx) - sh->ox) - sh->sx * az;
    floatL ay = (vloadL(0, v + L * sh->ky) - sh->oy) - sh->sy * az;
    floatL bx = (vloadL(0, v + L * (3 + sh->kx)) - sh->ox) - sh->sx * bz;
    floatL by = (vloadL(0, v + L * (3 + sh->ky)) - sh->oy) - sh->sy * bz;
    floatL cx = (vloadL(0, v + L * (6 + sh->kx)) - sh->ox) - sh->sx * cz;
    floatL cy = (vloadL(0, v + L * (6 + sh->ky)) - sh->oy) - sh->sy * cz;
    floatL u = cx * by - cy * bx;
    *e1 = ax * cy - ay * cx;
    *e2 = bx * ay - by * ax;
    const floatL zero = (floatL)(0.0f);
    intL outside = ((u < zero) | (*e1 < zero) | (*e2 < zero)) & ((u > zero) | (*e1 > zero) | (*e2 > zero));
    *det = u + *e1 + *e2;
    *t_scaled = (u * az + *e1 * bz + *e2 * cz) * sh->sz;
    /* compare before dividing, with the sign of det folded in; det == 0 (degenerate) never hits */
    floatL t_det = tmax * *det;
    intL in_range = select((*t_scaled > zero) & (*t_scaled < t_det), (*t_scaled < zero) & (*t_scaled > t_det),
                           *det < zero);
    return ~outside & (*det != zero) & in_range;
}

/* The triangles of a packet: 0 when none is hit in (0, tmax); 1 after writing the nearest hit to
 * *hit (ties go to the lower lane, as to the primitive tested first one by one); 2 when the query
 * can stop: TRACE_ANY on any hit, TRACE_SHADOW on a hit of an opaque lane (*hit: that lane). */
__attribute__((always_inline))
inline int packet_triangles_intersect(__global const LeafPacket *pk, const Shear *sh, float tmax, int mode,
                                      Hit *hit) {
    floatL t_scaled, det, e1, e2;
    intL ok = packet_triangles_hit(pk, sh, tmax, &t_scaled, &det, &e1, &e2);
    if (!any(ok)) return 0;
    if (mode == TRACE_ANY) return 2;    /* an occlusion test needs no distance */
    int stop = 0;
    if (mode == TRACE_SHADOW) {
        intL opaque = ok & vloadL(0, pk->opaque);
        if (any(opaque)) {
            ok = opaque;
            stop = 2;
        }
    }
    floatL inv = 1.0f / det;
    float t[VOLCL_LEAF_WIDTH], b1[VOLCL_LEAF_WIDTH], b2[VOLCL_LEAF_WIDTH];
    vstoreL(select((floatL)(VOLCL_INF), t_scaled * inv, ok), 0, t);
    vstoreL(e1 * inv, 0, b1);
    vstoreL(e2 * inv, 0, b2);
    int best = 0;
    for (int i = 1; i < VOLCL_LEAF_WIDTH; ++i)
        if (t[i] < t[best]) best = i;
    hit->t = t[best];
    hit->prim = pk->prim[best];
    hit->b1 = b1[best];
    hit->b2 = b2[best];
#if VOLCL_HAS_INSTANCES
    hit->inst = -1;
#endif
    return stop ? stop : 1;
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

/* Nearest hit in (eps, tmax) on analytic primitive a (a sphere, or a cylinder from
 * VOLCL_CYLINDER_CODE_BASE, cylinder.h). */
inline bool analytic_intersect(const SceneData *sc, int a, float3 o, float3 d, float tmax, float *t) {
#if VOLCL_HAS_CYLINDERS
    if (analytic_is_cylinder(a)) return cylinder_intersect(&sc->cylinders[a - VOLCL_CYLINDER_CODE_BASE], o, d, tmax, t);
#endif
    return sphere_intersect(&sc->spheres[a], o, d, tmax, t);
}

/* The analytic primitives of a packet (codes < 0: spheres and cylinders, cylinder.h), one by one
 * after its triangles; returns as packet_triangles_intersect does. */
inline int packet_analytic_intersect(const SceneData *sc, __global const LeafPacket *pk, float3 o, float3 d,
                                     int mode, Hit *hit) {
    int found = 0;
#if VOLCL_HAS_SPHERES || VOLCL_HAS_CYLINDERS
    for (int i = 0; i < VOLCL_LEAF_WIDTH; ++i) {
        int code = pk->prim[i];
        if (code >= 0) continue;
        float t;
        if (analytic_intersect(sc, -code - 1, o, d, hit->t, &t)) {
            hit->t = t;
            hit->prim = code;
            hit->b1 = hit->b2 = 0.0f;
#if VOLCL_HAS_INSTANCES
            hit->inst = -1;
#endif
            if (mode == TRACE_ANY || (mode == TRACE_SHADOW && pk->opaque[i])) return 2;
            found = 1;
        }
    }
#endif
    return found;
}

/* Per-ray constants of the box tests: origin and reciprocal direction splatted over the child
 * lanes, and for each axis the bounds row (offset in floats) of the slab plane a ray meets first. */
typedef struct {
    floatW ox, oy, oz, ix, iy, iz;
    int near_x, near_y, near_z;
} BoxRay;

inline BoxRay box_ray_make(float3 o, float3 d) {
    /* a zero direction component becomes a tiny one of the same sign: its slab then spans
     * +-1e30 instead of producing 0 * INF = NaN for an origin on the slab plane */
    float3 inv_d = 1.0f / select(d, copysign((float3)(1e-30f), d), fabs(d) < (float3)(1e-30f));
    BoxRay r;
    r.ox = (floatW)(o.x);
    r.oy = (floatW)(o.y);
    r.oz = (floatW)(o.z);
    r.ix = (floatW)(inv_d.x);
    r.iy = (floatW)(inv_d.y);
    r.iz = (floatW)(inv_d.z);
    /* rows 0-2 hold the minima, 3-5 the maxima: a negative direction meets the maximum first */
    r.near_x = (inv_d.x < 0.0f ? 3 : 0) * VOLCL_BVH_WIDTH;
    r.near_y = (inv_d.y < 0.0f ? 4 : 1) * VOLCL_BVH_WIDTH;
    r.near_z = (inv_d.z < 0.0f ? 5 : 2) * VOLCL_BVH_WIDTH;
    return r;
}

/* Entry distances of the ray into the boxes of all children of node n, INF where it misses a box
 * within [0, tmax]. The slab distances are (bound - o) * inv_d, so the exit distance is exact up to
 * one rounding and widening it by a few ulps means rounding never culls a box the ray grazes.
 * inv_d is finite (box_ray_make), so no product is NaN and plain compares replace fmin/fmax, whose
 * NaN rules cost extra instructions on every node; the inverted boxes of unused slots give
 * enter = +inf > leave = -inf. */
__attribute__((always_inline))
inline floatW node_children_entry(__global const BvhWideNode *n, const BoxRay *r, float tmax) {
    __global const float *b = &n->bounds[0][0];
    floatW nx = (vloadW(0, b + r->near_x) - r->ox) * r->ix;
    floatW ny = (vloadW(0, b + r->near_y) - r->oy) * r->iy;
    floatW nz = (vloadW(0, b + r->near_z) - r->oz) * r->iz;
    floatW fx = (vloadW(0, b + (3 * VOLCL_BVH_WIDTH - r->near_x)) - r->ox) * r->ix;
    floatW fy = (vloadW(0, b + (5 * VOLCL_BVH_WIDTH - r->near_y)) - r->oy) * r->iy;
    floatW fz = (vloadW(0, b + (7 * VOLCL_BVH_WIDTH - r->near_z)) - r->oz) * r->iz;
    floatW enter = select(ny, nx, nx > ny);
    enter = select(nz, enter, enter > nz);
    enter = select((floatW)(0.0f), enter, enter > (floatW)(0.0f));
    floatW leave = select(fy, fx, fx < fy);
    leave = select(fz, leave, leave < fz);
    leave = select((floatW)(tmax), leave, leave < (floatW)(tmax)) * 1.0000004f;
    return select((floatW)(VOLCL_INF), enter, enter <= leave);
}

/* Bit i set where lane i of m is true (-1). */
inline int lane_mask(intW m) {
#if VOLCL_BVH_WIDTH == 8
    int8 bits = m & (int8)(1, 2, 4, 8, 16, 32, 64, 128);
    int4 b4 = bits.lo | bits.hi;
#else
    int4 b4 = m & (int4)(1, 2, 4, 8);
#endif
    int2 b2 = b4.lo | b4.hi;
    return b2.x | b2.y;
}

/* Index of the lowest set bit of a non-zero mask (OpenCL C 1.2 has clz but not ctz). */
inline int lowest_lane(int mask) { return 31 - clz(mask & -mask); }

/* No child entered, or nothing left on the stack (node_visit, stack_next); no node or leaf
 * reference takes this value. */
#define VOLCL_NO_CHILD 0x7fffffff

/* A walk's visit of node n: the child to visit next, or VOLCL_NO_CHILD when the ray enters none of
 * its boxes within tmax. Where it enters several, every one goes on the stack (stack, stack_t,
 * *top) with its entry distance; for closest hits each goes into this node's run of the stack in
 * order of entry distance, farthest at the bottom (TRACE_ANY skips the ordering), and the nearest
 * comes off again as the one returned, having just passed the box test. */
__attribute__((always_inline))
inline int node_visit(__global const BvhWideNode *n, const BoxRay *br, float tmax, int mode, int *stack,
                      float *stack_t, int *top) {
    floatW entry = node_children_entry(n, br, tmax);
    int mask = lane_mask(entry < (floatW)(VOLCL_INF));
    if (mask == 0) return VOLCL_NO_CHILD;
    int i = lowest_lane(mask);
    mask &= mask - 1;
    if (mask == 0) return n->child[i];      /* one child entered: visit it without the stack */
    float enter[VOLCL_BVH_WIDTH];
    vstoreW(entry, 0, enter);
    int base = *top;
    for (;;) {
        float t = enter[i];
        int j = (*top)++;
        if (mode != TRACE_ANY) {
            for (; j > base && stack_t[j - 1] < t; --j) {
                stack[j] = stack[j - 1];
                stack_t[j] = stack_t[j - 1];
            }
        }
        stack[j] = n->child[i];
        stack_t[j] = t;
        if (mask == 0) break;
        i = lowest_lane(mask);
        mask &= mask - 1;
    }
    return stack[--(*top)];
}

/* The next stack entry whose box the ray enters before the closest hit t_hit (with the box test's
 * tolerance), or VOLCL_NO_CHILD when none is left. */
__attribute__((always_inline))
inline int stack_next(const int *stack, const float *stack_t, int *top, float t_hit) {
    do {
        if (*top == 0) return VOLCL_NO_CHILD;
        --(*top);
    } while (stack_t[*top] > t_hit * 1.0000004f);
    return stack[*top];
}

#if !VOLCL_HAS_INSTANCES
#define VOLCL_TRAVERSE_NAME bvh_traverse_scene
#define VOLCL_TRAVERSE_LEAF packet_analytic_intersect
#include "bvh_traverse.h"
#else
/* Instances (Mitsuba's instance of a shapegroup). The top-level tree's leaves hold the scene's own
 * primitives and instances (analytic index VOLCL_INSTANCE_CODE_BASE + k); entering one takes the ray
 * into the group's space by the instance's affine world-to-object map and traverses the group's own
 * tree there, so each group's geometry is stored once however often it is placed. The group-space
 * direction is normalized (the sphere and cylinder tests expect a unit direction), and distances
 * scale by its length: a group-space distance t' is the world distance t' / |M^-1 d| along the
 * same ray, so hit->t stays the world-space distance every query compares against. */
#define VOLCL_INSTANCE_CODE_BASE (1 << 29)

#define VOLCL_TRAVERSE_NAME bvh_traverse_group
#define VOLCL_TRAVERSE_LEAF packet_analytic_intersect
#include "bvh_traverse.h"

inline int instance_intersect(const SceneData *sc, int k, float3 o, float3 d, int mode, Hit *hit) {
    __global const Instance *in = &sc->instances[k];
    float3 lo = affine_point(in->to_object, o), ld = affine_vector(in->to_object, d);
    float len = length(ld);
    if (!(len > 0.0f && len < VOLCL_INF)) return 0;
    Hit h;
    int r = bvh_traverse_group(sc, in->root, lo, ld / len, hit->t * len, mode, &h);
    if (r == 0 || mode == TRACE_ANY) return r;
    hit->t = h.t / len;
    hit->prim = h.prim;
    hit->b1 = h.b1;
    hit->b2 = h.b2;
    hit->inst = k;
    return r;
}

/* A top-level packet's analytic lanes: instances, and the scene's own spheres and cylinders. */
inline int packet_top_intersect(const SceneData *sc, __global const LeafPacket *pk, float3 o, float3 d,
                                int mode, Hit *hit) {
    int found = 0;
    for (int i = 0; i < VOLCL_LEAF_WIDTH; ++i) {
        int code = pk->prim[i];
        if (code >= 0) continue;
        int a = -code - 1;
        if (a >= VOLCL_INSTANCE_CODE_BASE && !analytic_is_cylinder(a)) {
            int r = instance_intersect(sc, a - VOLCL_INSTANCE_CODE_BASE, o, d, mode, hit);
            if (r == 2) return 2;
            found |= r;
            continue;
        }
#if VOLCL_HAS_SPHERES || VOLCL_HAS_CYLINDERS
        float t;
        if (analytic_intersect(sc, a, o, d, hit->t, &t)) {
            hit->t = t;
            hit->prim = code;
            hit->b1 = hit->b2 = 0.0f;
            hit->inst = -1;
            if (mode == TRACE_ANY || (mode == TRACE_SHADOW && pk->opaque[i])) return 2;
            found = 1;
        }
#endif
    }
    return found;
}

#define VOLCL_TRAVERSE_NAME bvh_traverse_top
#define VOLCL_TRAVERSE_LEAF packet_top_intersect
#include "bvh_traverse.h"
#endif

/* A query (TRACE_*) for hits in (0, tmax) in the tree whose root is wide node `root`; true when
 * something is hit, with *hit as the mode says (bvh_traverse.h; with INSTANCES, hit->inst names the
 * instance whose group was hit, or -1). */
inline bool bvh_trace_in(const SceneData *sc, int root, float3 o, float3 d, float tmax, int mode, Hit *hit) {
#if VOLCL_HAS_INSTANCES
    return bvh_traverse_top(sc, root, o, d, tmax, mode, hit) != 0;
#else
    return bvh_traverse_scene(sc, root, o, d, tmax, mode, hit) != 0;
#endif
}

/* The same query over the whole scene. */
inline bool bvh_trace(const SceneData *sc, float3 o, float3 d, float tmax, int mode, Hit *hit) {
    return bvh_trace_in(sc, 0, o, d, tmax, mode, hit);
}

#endif
