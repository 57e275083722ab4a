/* Ray queries against the BVH: closest hit and any hit, over triangles and analytic spheres.
 *
 * Triangles use the watertight test of Woop, Benthin and Wald (2013): the ray is sheared to +z and
 * edge functions decide coverage, so a ray through a shared edge or vertex hits at least one of the
 * triangles sharing it (no leaks through closed meshes). Degenerate triangles give det == 0 and
 * never hit.
 */
#ifndef VOLCL_BVH_H
#define VOLCL_BVH_H

/* Deepest stack a traversal can reach; volcl/bvh_wide.py STACK builds trees within it. */
#define VOLCL_BVH_STACK 128

#if VOLCL_BVH_WIDTH == 8
typedef float8 floatW;
#define vloadW vload8
#define vstoreW vstore8
#elif VOLCL_BVH_WIDTH == 4
typedef float4 floatW;
#define vloadW vload4
#define vstoreW vstore4
#else
#error "VOLCL_BVH_WIDTH must be 4 or 8"
#endif

typedef struct {
    float t;
    int prim;       /* code from prim_ids: >= 0 triangle, < 0 sphere */
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

__attribute__((always_inline))
inline bool prim_intersect(const SceneData *sc, int code, float3 o, float3 d, const Shear *sh, float tmax,
                           Hit *hit) {
    float t, b1 = 0.0f, b2 = 0.0f;
#if VOLCL_HAS_SPHERES
    if (code < 0) {
        if (!sphere_intersect(&sc->spheres[-code - 1], o, d, tmax, &t)) return false;
    } else
#endif
    if (!triangle_intersect(&sc->triangles[code], sh, tmax, &t, &b1, &b2)) return false;
    hit->t = t;
    hit->prim = code;
    hit->b1 = b1;
    hit->b2 = b2;
    return true;
}

/* Per-ray constants of the box tests: origin and reciprocal direction splatted over the child
 * lanes, and for each axis the bounds row (offset in floats) of the slab plane a ray meets first. */
typedef struct {
    floatW ox, oy, oz, ix, iy, iz;
    int near_x, near_y, near_z;
} BoxRay;

inline BoxRay box_ray_make(float3 o, float3 inv_d) {
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
 * inv_d is finite (see bvh_trace), so no product is NaN and plain compares replace fmin/fmax, whose
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

/* Closest hit in (0, tmax). any_hit: return at the first hit found (shadow rays).
 *
 * The traversal keeps a stack of (child, entry distance). At a node every child box the ray enters
 * goes on the stack; for closest hits they are inserted in order of entry distance, nearest on top,
 * so the nearest is visited next and a hit found there culls the others when they come off the
 * stack (an entry distance beyond the hit, with the box test's tolerance). Shadow rays skip the
 * ordering. The builder bounds the stack depth any ray can reach by VOLCL_BVH_STACK
 * (volcl/bvh_wide.py). An empty scene is one node without children, which no ray enters. */
inline bool bvh_trace(const SceneData *sc, float3 o, float3 d, float tmax, bool any_hit, Hit *hit) {
    Shear sh = shear_make(o, d);
    /* a zero direction component becomes a tiny one of the same sign: its slab then spans
     * +-1e30 instead of producing 0 * INF = NaN for an origin on the slab plane */
    float3 inv_d = 1.0f / select(d, copysign((float3)(1e-30f), d), fabs(d) < (float3)(1e-30f));
    BoxRay br = box_ray_make(o, inv_d);
    int stack[VOLCL_BVH_STACK];
    float stack_t[VOLCL_BVH_STACK];
    int top = 1;
    stack[0] = 0;
    stack_t[0] = 0.0f;
    bool found = false;
    hit->t = tmax;
    hit->prim = 0;
    hit->b1 = hit->b2 = 0.0f;
    while (top > 0) {
        --top;
        int ref = stack[top];
        if (stack_t[top] > hit->t * 1.0000004f) continue;
        if (ref >= 0) {
            __global const BvhWideNode *n = &sc->nodes[ref];
            float enter[VOLCL_BVH_WIDTH];
            vstoreW(node_children_entry(n, &br, hit->t), 0, enter);
            int base = top;
            for (int i = 0; i < VOLCL_BVH_WIDTH; ++i) {
                float t = enter[i];
                if (t == VOLCL_INF) continue;
                int j = top++;
                if (!any_hit) {
                    /* insertion into this node's run of the stack, farthest at the bottom */
                    for (; j > base && stack_t[j - 1] < t; --j) {
                        stack[j] = stack[j - 1];
                        stack_t[j] = stack_t[j - 1];
                    }
                }
                stack[j] = n->child[i];
                stack_t[j] = t;
            }
        } else {
            int leaf = ~ref;
            int first = leaf >> 4, end = first + (leaf & 15) + 1;
            for (int i = first; i < end; ++i) {
                if (prim_intersect(sc, sc->prim_ids[i], o, d, &sh, hit->t, hit)) {
                    found = true;
                    if (any_hit) return true;
                }
            }
        }
    }
    return found;
}

#endif
