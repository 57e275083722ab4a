/* Ray queries of the packet renderer (packets.cl): VOLCL_PACKET_WIDTH rays at once in OpenCL vector
 * types, against every primitive of a scene small enough to test whole (volcl/packets.py decides
 * which). No tree: each leaf packet's primitives are loaded once, as scalars, and tested against all
 * rays, so the arithmetic runs in the SIMD lanes whichever runtime compiles it (a tree walk per lane
 * keeps each ray's own branches and loads, which no vectorizer turns into lanes: README).
 *
 * Every test is the tree's test operation for operation (bvh.h packet_triangles_hit's watertight test
 * with the ray's own axis permutation picked per lane, sphere_intersect's arithmetic with selects for
 * its branches), and a packet's hits are chosen as packet_triangles_intersect chooses them: its
 * triangles against the nearest hit of the packets before it, the nearest lane winning, ties to the
 * lower lane, then its spheres one by one. So a hit has the tree walk's bits; where the tree visits
 * packets in another order, only which of two primitives at the same distance wins can differ. */
#ifndef VOLCL_PACKET_QUERIES_H
#define VOLCL_PACKET_QUERIES_H

#if VOLCL_PACKET_WIDTH == 16
typedef float16 floatP;
typedef int16 intP;
#define vloadP vload16
#define vstoreP vstore16
#elif VOLCL_PACKET_WIDTH == 8
typedef float8 floatP;
typedef int8 intP;
#define vloadP vload8
#define vstoreP vstore8
#else
#error "VOLCL_PACKET_WIDTH must be 8 or 16"
#endif

/* The watertight test's per-ray constants (bvh.h Shear) for every lane: the axis permutation as
 * lane masks (kx == 0, kx == 1, and so on; else 2), the shear and the permuted origin. */
typedef struct {
    intP x0, x1, y0, y1, z0, z1;
    floatP sx, sy, sz, ox, oy, oz;
} PacketShear;

/* a where is0, else b where is1, else c */
inline floatP packet_pick(intP is0, intP is1, floatP a, floatP b, floatP c) {
    return select(select(c, b, is1), a, is0);
}

inline PacketShear packet_shear(floatP ox, floatP oy, floatP oz, floatP dx, floatP dy, floatP dz) {
    PacketShear s;
    floatP ax = fabs(dx), ay = fabs(dy), az = fabs(dz);
    /* kz: the largest component, as shear_make picks it */
    intP gxy = ax > ay;
    intP kz0 = gxy & (ax > az), kz1 = ~gxy & (ay > az), kz2 = ~(kz0 | kz1);
    /* kz = 0, 1, 2 give (kx, ky) = (1, 2), (2, 0), (0, 1), swapped where d's kz component is negative */
    intP flip = packet_pick(kz0, kz1, dx, dy, dz) < (floatP)(0.0f);
    s.z0 = kz0;
    s.z1 = kz1;
    s.x0 = select(kz2, kz1, flip);
    s.x1 = select(kz0, kz2, flip);
    s.y0 = select(kz1, kz2, flip);
    s.y1 = select(kz2, kz0, flip);
    floatP pdz = packet_pick(s.z0, s.z1, dx, dy, dz);
    s.sx = packet_pick(s.x0, s.x1, dx, dy, dz) / pdz;
    s.sy = packet_pick(s.y0, s.y1, dx, dy, dz) / pdz;
    s.sz = 1.0f / pdz;
    s.ox = packet_pick(s.x0, s.x1, ox, oy, oz);
    s.oy = packet_pick(s.y0, s.y1, ox, oy, oz);
    s.oz = packet_pick(s.z0, s.z1, ox, oy, oz);
    return s;
}

/* Whether lane k of packet pk holds a triangle (unused lanes and spheres' lanes hold the zero
 * triangle, which nothing hits) */
inline bool packet_lane_triangle(__global const LeafPacket *pk, int k) {
    if (pk->prim[k] < 0) return false;
    bool used = false;
    for (int r = 0; r < 9; ++r) used |= pk->v[r][k] != 0.0f;
    return used;
}

/* packet_triangles_hit for lane k of leaf packet pk against every ray, for hits in (0, tmax) */
inline intP packet_triangle_hit(__global const LeafPacket *pk, int k, const PacketShear *s, floatP tmax,
                                floatP *t_scaled, floatP *det, floatP *e1, floatP *e2) {
#pragma OPENCL FP_CONTRACT OFF
#define VOLCL_PV(r) ((floatP)(pk->v[r][k]))
    floatP az = packet_pick(s->z0, s->z1, VOLCL_PV(0), VOLCL_PV(1), VOLCL_PV(2)) - s->oz;
    floatP bz = packet_pick(s->z0, s->z1, VOLCL_PV(3), VOLCL_PV(4), VOLCL_PV(5)) - s->oz;
    floatP cz = packet_pick(s->z0, s->z1, VOLCL_PV(6), VOLCL_PV(7), VOLCL_PV(8)) - s->oz;
    floatP ax = (packet_pick(s->x0, s->x1, VOLCL_PV(0), VOLCL_PV(1), VOLCL_PV(2)) - s->ox) - s->sx * az;
    floatP ay = (packet_pick(s->y0, s->y1, VOLCL_PV(0), VOLCL_PV(1), VOLCL_PV(2)) - s->oy) - s->sy * az;
    floatP bx = (packet_pick(s->x0, s->x1, VOLCL_PV(3), VOLCL_PV(4), VOLCL_PV(5)) - s->ox) - s->sx * bz;
    floatP by = (packet_pick(s->y0, s->y1, VOLCL_PV(3), VOLCL_PV(4), VOLCL_PV(5)) - s->oy) - s->sy * bz;
    floatP cx = (packet_pick(s->x0, s->x1, VOLCL_PV(6), VOLCL_PV(7), VOLCL_PV(8)) - s->ox) - s->sx * cz;
    floatP cy = (packet_pick(s->y0, s->y1, VOLCL_PV(6), VOLCL_PV(7), VOLCL_PV(8)) - s->oy) - s->sy * cz;
#undef VOLCL_PV
    floatP u = cx * by - cy * bx;
    *e1 = ax * cy - ay * cx;
    *e2 = bx * ay - by * ax;
    const floatP zero = (floatP)(0.0f);
    intP outside = ((u < zero) | (*e1 < zero) | (*e2 < zero)) & ((u > zero) | (*e1 > zero) | (*e2 > zero));
    *det = u + *e1 + *e2;
    *t_scaled = (u * az + *e1 * bz + *e2 * cz) * s->sz;
    floatP t_det = tmax * *det;
    intP in_range = select((*t_scaled > zero) & (*t_scaled < t_det), (*t_scaled < zero) & (*t_scaled > t_det),
                           *det < zero);
    return ~outside & (*det != zero) & in_range;
}

/* lanes_dot's sum: the library's dot on float3, uncontracted */
inline floatP packet_dot(floatP ax, floatP ay, floatP az, floatP bx, floatP by, floatP bz) {
#pragma OPENCL FP_CONTRACT OFF
    return (ax * bx + ay * by) + az * bz;
}

/* sphere_intersect (bvh.h) against every ray: the lanes hit in (eps, tmax), their distance in *t */
inline intP packet_sphere_hit(__global const Sphere *sp, floatP ox, floatP oy, floatP oz, floatP dx, floatP dy,
                              floatP dz, floatP tmax, floatP *t) {
    /* r splatted before its square: r * r - x contracts to a fused multiply-add, as in the scalar code */
    floatP r = (floatP)(sp->radius);
    floatP fx = ox - sp->center[0], fy = oy - sp->center[1], fz = oz - sp->center[2];
    floatP b = -packet_dot(fx, fy, fz, dx, dy, dz);
    floatP lx = fx + b * dx, ly = fy + b * dy, lz = fz + b * dz;
    floatP disc = r * r - packet_dot(lx, ly, lz, lx, ly, lz);
    floatP q = b + copysign(sqrt(fmax(disc, 0.0f)), b);
    floatP ff = packet_dot(fx, fy, fz, fx, fy, fz);
    floatP c_term = ff - r * r;
    intP zero = q == (floatP)(0.0f);
    floatP t0 = select(c_term / q, (floatP)(0.0f), zero), t1 = select(q, (floatP)(0.0f), zero);
    floatP lo = select(t0, t1, t0 > t1), hi = select(t1, t0, t0 > t1);
    floatP eps = 1e-6f * fmax(r, sqrt(ff));
    *t = select(hi, lo, lo > eps);
    return ~(disc < (floatP)(0.0f)) & (*t > eps) & (*t < tmax);
}

/* The closest hits in (0, tmax) over leaf packets [first, end) (bvh_trace's TRACE_CLOSEST): where
 * *t falls below tmax, a hit at *t with barycentrics *b1, *b2 on primitive *prim. A lane with a
 * negative tmax traces nothing. */
inline void packet_closest(const SceneData *sc, int first, int end, const PacketShear *s, floatP ox, floatP oy,
                           floatP oz, floatP dx, floatP dy, floatP dz, floatP tmax, floatP *t, floatP *b1,
                           floatP *b2, intP *prim) {
    floatP best = tmax, hb1 = (floatP)(0.0f), hb2 = (floatP)(0.0f);
    intP code = (intP)(0);
    for (int p = first; p < end; ++p) {
        __global const LeafPacket *pk = &sc->leaves[p];
        /* the packet's triangles against the hits before it, the nearest winning */
        floatP pt = (floatP)(VOLCL_INF), pb1 = (floatP)(0.0f), pb2 = (floatP)(0.0f);
        intP pcode = (intP)(0), found = (intP)(0);
        for (int k = 0; k < VOLCL_LEAF_WIDTH; ++k) {
            if (!packet_lane_triangle(pk, k)) continue;
            floatP t_scaled, det, e1, e2;
            intP ok = packet_triangle_hit(pk, k, s, best, &t_scaled, &det, &e1, &e2);
            if (!any(ok)) continue;
            floatP inv = 1.0f / det;
            floatP tk = select((floatP)(VOLCL_INF), t_scaled * inv, ok);
            intP take = tk < pt;
            pt = select(pt, tk, take);
            pb1 = select(pb1, e1 * inv, take);
            pb2 = select(pb2, e2 * inv, take);
            pcode = select(pcode, (intP)(pk->prim[k]), take);
            found |= ok;
        }
        best = select(best, pt, found);
        hb1 = select(hb1, pb1, found);
        hb2 = select(hb2, pb2, found);
        code = select(code, pcode, found);
        /* then its spheres, one by one */
        for (int k = 0; k < VOLCL_LEAF_WIDTH; ++k) {
            int c = pk->prim[k];
            if (c >= 0) continue;
            floatP tk;
            intP ok = packet_sphere_hit(&sc->spheres[-c - 1], ox, oy, oz, dx, dy, dz, best, &tk);
            best = select(best, tk, ok);
            hb1 = select(hb1, (floatP)(0.0f), ok);
            hb2 = select(hb2, (floatP)(0.0f), ok);
            code = select(code, (intP)(c), ok);
        }
    }
    *t = best;
    *b1 = hb1;
    *b2 = hb2;
    *prim = code;
}

/* Which rays something blocks in (0, tmax) over leaf packets [first, end) (TRACE_ANY; every
 * primitive is opaque): -1 where blocked. Lanes with a negative tmax are left unblocked and
 * unsearched. */
inline intP packet_occluded(const SceneData *sc, int first, int end, const PacketShear *s, floatP ox, floatP oy,
                            floatP oz, floatP dx, floatP dy, floatP dz, floatP tmax) {
    intP wanted = tmax >= (floatP)(0.0f);
    intP blocked = (intP)(0);
    for (int p = first; p < end && any(wanted & ~blocked); ++p) {
        __global const LeafPacket *pk = &sc->leaves[p];
        for (int k = 0; k < VOLCL_LEAF_WIDTH; ++k) {
            int c = pk->prim[k];
            if (c < 0) {
                floatP tk;
                blocked |= packet_sphere_hit(&sc->spheres[-c - 1], ox, oy, oz, dx, dy, dz, tmax, &tk);
            } else if (packet_lane_triangle(pk, k)) {
                floatP t_scaled, det, e1, e2;
                blocked |= packet_triangle_hit(pk, k, s, tmax, &t_scaled, &det, &e1, &e2);
            }
        }
    }
    return blocked & wanted;
}

#endif
