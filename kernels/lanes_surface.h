/* The surface stage's routines on V3 (wavefront_surface.cl): each is the renderer's float3 routine
 * it names, operation for operation, so that a path scatters from a diffuse triangle in the lanes as
 * it does in the megakernel. The library's dot and cross take no fused multiply-adds (lanes_dot);
 * the renderer's own float3 expressions contract as the same expressions on scalars do. */
#ifndef VOLCL_LANES_SURFACE_H
#define VOLCL_LANES_SURFACE_H

#define LT(c, j) table[WF_LT_AT(c, j)]

/* A tested triangle's numbers (wavefront_state.h WF_TRI_AT) */
typedef struct {
    V3 p0, p1, p2, ng, color;
    float mag, lanes, twosided;
#if VOLCL_WF_CHECKERS
    /* (scalars, not arrays: a private array's loads stopped the packet step's loop vectorizer) */
    float checker, u0, v0, u1, v1, u2, v2, m0, m1, m2, m3, m4, m5;
    V3 color1;
#endif
} LanesTriangle;

/* Triangle `slot` of the table (zeros for -1): a select per triangle and number, which cost less
 * than a gather per number (89 against 66 ns a path for the surface stage on PoCL; 38 against 42
 * on Intel's runtime) */
inline LanesTriangle lanes_triangle_at(__global const float *table, int slot) {
    LanesTriangle t;
    t.p0 = t.p1 = t.p2 = t.ng = t.color = v3(0.0f, 0.0f, 0.0f);
    t.mag = t.lanes = t.twosided = 0.0f;
#if VOLCL_WF_CHECKERS
    t.checker = t.u0 = t.v0 = t.u1 = t.v1 = t.u2 = t.v2 = 0.0f;
    t.m0 = t.m1 = t.m2 = t.m3 = t.m4 = t.m5 = 0.0f;
    t.color1 = t.color;
#endif
#define TV(c) table[WF_TRI_AT(c, k)]
#pragma unroll
    for (int k = 0; k < VOLCL_WF_TINY; ++k) {
        bool is_k = slot == k;
        t.p0 = v3_sel(is_k, v3(TV(0), TV(1), TV(2)), t.p0);
        t.p1 = v3_sel(is_k, v3(TV(3), TV(4), TV(5)), t.p1);
        t.p2 = v3_sel(is_k, v3(TV(6), TV(7), TV(8)), t.p2);
        t.ng = v3_sel(is_k, v3(TV(WF_TRI_NG), TV(WF_TRI_NG + 1), TV(WF_TRI_NG + 2)), t.ng);
        t.color = v3_sel(is_k, v3(TV(WF_TRI_COLOR), TV(WF_TRI_COLOR + 1), TV(WF_TRI_COLOR + 2)), t.color);
        t.mag = is_k ? TV(WF_TRI_MAG) : t.mag;
        t.lanes = is_k ? TV(WF_TRI_LANES) : t.lanes;
        t.twosided = is_k ? TV(WF_TRI_TWOSIDED) : t.twosided;
#if VOLCL_WF_CHECKERS
        t.checker = is_k ? TV(WF_TRI_CHECKER) : t.checker;
        t.u0 = is_k ? TV(WF_TRI_UV) : t.u0;
        t.v0 = is_k ? TV(WF_TRI_UV + 1) : t.v0;
        t.u1 = is_k ? TV(WF_TRI_UV + 2) : t.u1;
        t.v1 = is_k ? TV(WF_TRI_UV + 3) : t.v1;
        t.u2 = is_k ? TV(WF_TRI_UV + 4) : t.u2;
        t.v2 = is_k ? TV(WF_TRI_UV + 5) : t.v2;
        t.m0 = is_k ? TV(WF_TRI_TO_UV) : t.m0;
        t.m1 = is_k ? TV(WF_TRI_TO_UV + 1) : t.m1;
        t.m2 = is_k ? TV(WF_TRI_TO_UV + 2) : t.m2;
        t.m3 = is_k ? TV(WF_TRI_TO_UV + 3) : t.m3;
        t.m4 = is_k ? TV(WF_TRI_TO_UV + 4) : t.m4;
        t.m5 = is_k ? TV(WF_TRI_TO_UV + 5) : t.m5;
        t.color1 = v3_sel(is_k, v3(TV(WF_TRI_COLOR1), TV(WF_TRI_COLOR1 + 1), TV(WF_TRI_COLOR1 + 2)), t.color1);
#endif
    }
#undef TV
    return t;
}

/* Triangle `slot` of the table (0 <= slot < VOLCL_WF_TINY): a gather per number, where the slots
 * are too many for a select per slot (the packet renderer's, up to volcl.packets.MAX_PRIMITIVES) */
inline LanesTriangle lanes_triangle_gather(__global const float *table, int slot) {
    LanesTriangle t;
#define TV(c) table[WF_TRI_AT(c, slot)]
    t.p0 = v3(TV(0), TV(1), TV(2));
    t.p1 = v3(TV(3), TV(4), TV(5));
    t.p2 = v3(TV(6), TV(7), TV(8));
    t.ng = v3(TV(WF_TRI_NG), TV(WF_TRI_NG + 1), TV(WF_TRI_NG + 2));
    t.color = v3(TV(WF_TRI_COLOR), TV(WF_TRI_COLOR + 1), TV(WF_TRI_COLOR + 2));
    t.mag = TV(WF_TRI_MAG);
    t.lanes = TV(WF_TRI_LANES);
    t.twosided = TV(WF_TRI_TWOSIDED);
#if VOLCL_WF_CHECKERS
    t.checker = TV(WF_TRI_CHECKER);
    t.u0 = TV(WF_TRI_UV);
    t.v0 = TV(WF_TRI_UV + 1);
    t.u1 = TV(WF_TRI_UV + 2);
    t.v1 = TV(WF_TRI_UV + 3);
    t.u2 = TV(WF_TRI_UV + 4);
    t.v2 = TV(WF_TRI_UV + 5);
    t.m0 = TV(WF_TRI_TO_UV);
    t.m1 = TV(WF_TRI_TO_UV + 1);
    t.m2 = TV(WF_TRI_TO_UV + 2);
    t.m3 = TV(WF_TRI_TO_UV + 3);
    t.m4 = TV(WF_TRI_TO_UV + 4);
    t.m5 = TV(WF_TRI_TO_UV + 5);
    t.color1 = v3(TV(WF_TRI_COLOR1), TV(WF_TRI_COLOR1 + 1), TV(WF_TRI_COLOR1 + 2));
#endif
#undef TV
    return t;
}

/* The triangle's reflectance at the hit's barycentrics: for a checkerboard of two colours, the
 * colour texture_leaf (textures.h) picks at texcoords_triangle's uv (texcoords.h), expression
 * for expression; else its one colour */
inline V3 lanes_color_at(const LanesTriangle *t, float b1, float b2) {
#if VOLCL_WF_CHECKERS
    float b0 = 1.0f - b1 - b2;
    float u = t->u0 * b0 + t->u1 * b1 + t->u2 * b2;
    float v = t->v0 * b0 + t->v1 * b1 + t->v2 * b2;
    float px = t->m0 * u + t->m1 * v + t->m2;
    float py = t->m3 * u + t->m4 * v + t->m5;
    bool hx = px - floor(px) > 0.5f, hy = py - floor(py) > 0.5f;
    return v3_sel((t->checker > 0.0f) & (hx != hy), t->color1, t->color);
#else
    (void)b1;
    (void)b2;
    return t->color;
#endif
}

/* surface_point (surface.h) on a triangle: the barycentric point pulled a hair into it */
inline V3 lanes_surface_point(const LanesTriangle *t, float hit_b1, float hit_b2) {
    float b1 = fmax(hit_b1, 1e-5f), b2 = fmax(hit_b2, 1e-5f), b0 = fmax(1.0f - hit_b1 - hit_b2, 1e-5f);
    float inv_sum = 1.0f / (b0 + b1 + b2);
    b0 *= inv_sum;
    b1 *= inv_sum;
    b2 *= inv_sum;
    return v3(b0 * t->p0.x + b1 * t->p1.x + b2 * t->p2.x, b0 * t->p0.y + b1 * t->p1.y + b2 * t->p2.y,
              b0 * t->p0.z + b1 * t->p1.z + b2 * t->p2.z);
}

/* make_frame (common.h) */
inline void lanes_make_frame(V3 n, V3 *s, V3 *t) {
    float sign = copysign(1.0f, n.z);
    float a = -1.0f / (sign + n.z);
    float b = n.x * n.y * a;
    *s = v3(1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x);
    *t = v3(b, sign + n.y * n.y * a, -n.y);
}

/* frame_to_world (common.h) */
inline V3 lanes_to_world(V3 v, V3 s, V3 t, V3 n) {
    return v3(v.x * s.x + v.y * t.x + v.z * n.x, v.x * s.y + v.y * t.y + v.z * n.y, v.x * s.z + v.y * t.z + v.z * n.z);
}

/* frame_to_local (common.h) */
inline V3 lanes_to_local(V3 v, V3 s, V3 t, V3 n) { return v3(lanes_dot(v, s), lanes_dot(v, t), lanes_dot(v, n)); }

/* sample_cosine_hemisphere (sampling.h) */
inline V3 lanes_cosine_hemisphere(float u0, float u1) {
    float dx, dy;
    lanes_concentric_disk(u0, u1, &dx, &dy);
    return v3(dx, dy, sqrt(fmax(0.0f, 1.0f - dx * dx - dy * dy)));
}

/* offset_origin (common.h) */
inline V3 lanes_offset_origin(V3 p, float mag, V3 ng, V3 d) {
    /* |p| three ways (see lanes_cosine_hemisphere) */
    mag = fmax(mag, fmax(fmax(fabs(p.x), p.y < 0.0f ? -p.y : p.y), fmax(p.z, -p.z)));
    float eps = mag * 1e-5f;
    return v3_madd(p, lanes_dot(d, ng) > 0.0f ? eps : -eps, ng);
}

/* offset_back (common.h) */
inline float lanes_offset_back(V3 o, V3 p, V3 ng, V3 d) {
    float den = lanes_dot(d, ng);
    return fabs(lanes_dot(v3_sub(o, p), ng)) / fmax(den < 0.0f ? -den : den, 1.0f / 16.0f);
}

/* power_heuristic (common.h) */
inline float lanes_power_heuristic(float pdf_a, float pdf_b) {
    float a = pdf_a * pdf_a, b = pdf_b * pdf_b;
    return isinf(a) ? (isinf(b) ? 0.5f : 1.0f) : (a + b > 0.0f ? a / (a + b) : 0.0f);
}

typedef struct {
    V3 wi, value;
    float dist, pdf;
    bool delta;
} LanesLight;

/* light_sample (lights.h) for point lights and area lights on triangles, light `li` of `count`
 * (picked by the caller as light_sample picks it): whether it gives a sample. The area light's
 * triangle is sample_discrete_cdf's (the first of its triangles whose cdf passes ux, else its last),
 * found by a pass over every light triangle of the table. */
inline bool lanes_light_sample(__global const float *table, V3 ref, int li, int count, float ux, float uy,
                               LanesLight *ls) {
    float choice = 1.0f / (float)count;
    bool point = TROW(WF_T_POINT, li) > 0.0f;
    bool found = false;
    float lo = 0.0f, hi = 1.0f;
    V3 p0 = v3(0.0f, 0.0f, 0.0f), p1 = p0, p2 = p0, ng = p0;
#pragma unroll
    for (int j = 0; j < VOLCL_WF_LIGHT_TRIS; ++j) {
        bool take = !found & (as_int(LT(WF_LT_LIGHT, j)) == li) & ((LT(WF_LT_CDF, j) > ux) | (LT(WF_LT_LAST, j) > 0.0f));
        lo = take ? LT(WF_LT_BEFORE, j) : lo;
        hi = take ? LT(WF_LT_CDF, j) : hi;
        p0 = v3_sel(take, v3(LT(WF_LT_P, j), LT(WF_LT_P + 1, j), LT(WF_LT_P + 2, j)), p0);
        p1 = v3_sel(take, v3(LT(WF_LT_P + 3, j), LT(WF_LT_P + 4, j), LT(WF_LT_P + 5, j)), p1);
        p2 = v3_sel(take, v3(LT(WF_LT_P + 6, j), LT(WF_LT_P + 7, j), LT(WF_LT_P + 8, j)), p2);
        ng = v3_sel(take, v3(LT(WF_LT_NG, j), LT(WF_LT_NG + 1, j), LT(WF_LT_NG + 2, j)), ng);
        found = found | take;
    }
    float u = clamp((ux - lo) / fmax(hi - lo, 1e-30f), 0.0f, 0.99999994f);
    float su = sqrt(u);
    float bx = 1.0f - su, by = uy * su;
    float w0 = 1.0f - bx - by;
    V3 pa = v3(w0 * p0.x + bx * p1.x + by * p2.x, w0 * p0.y + bx * p1.y + by * p2.y, w0 * p0.z + bx * p1.z + by * p2.z);
    V3 v = v3_sel(point, v3_sub(trow3(table, WF_T_LIGHT_POS, li), ref), v3_sub(pa, ref));
    float d2 = lanes_dot(v, v);
    ls->dist = sqrt(d2);
    ls->wi = lanes_div(v, ls->dist);
    V3 lv = trow3(table, WF_T_LIGHT_VALUE, li);
    bool facing = lanes_dot(ng, v3(-ls->wi.x, -ls->wi.y, -ls->wi.z)) > 0.0f;
    float cos_l = fabs(lanes_dot(ng, ls->wi));
    ls->value = v3_sel(point, lanes_div(lv, d2), v3_sel(facing, lv, v3(0.0f, 0.0f, 0.0f)));
    ls->pdf = point ? choice : choice * d2 / (cos_l * TROW(WF_T_AREA, li));
    ls->delta = point;
    return (d2 > 0.0f) & (point | (cos_l > 0.0f));
}

/* A plain diffuse triangle's vertex as surface_point and bsdf_vertex_at make it, for the ray
 * direction d and the hit's barycentrics: the point, the frame about the geometric normal, the
 * normal (turned towards wo on a two-sided bsdf seen from behind, after the frame is made) and wo's
 * cosine to it. */
inline void lanes_diffuse_vertex(const LanesTriangle *tri, float b1, float b2, V3 d, V3 *p, V3 *frame_s,
                                 V3 *frame_t, V3 *n, float *wo_z) {
    *p = lanes_surface_point(tri, b1, b2);
    V3 ng = tri->ng, wo = v3(-d.x, -d.y, -d.z);
    lanes_make_frame(ng, frame_s, frame_t);
    bool flip = (tri->twosided > 0.0f) & (lanes_dot(wo, ng) < 0.0f);
    *n = v3_sel(flip, v3(-ng.x, -ng.y, -ng.z), ng);
    *wo_z = lanes_dot(wo, *n);
}

/* path_surface_nee's light at point p: three numbers drawn where the path scatters (`scatter`), a
 * light picked and sampled as light_sample does where it does next-event estimation (`do_nee`);
 * whether that gives a sample, in *ls */
inline bool lanes_nee_light(__global const float *table, __global const RenderParams *rp, V3 p, bool scatter,
                            bool do_nee, Rng32 *rng, LanesLight *ls) {
    float u_pick = rng32_float_if(rng, scatter);
    float ul_x = rng32_float_if(rng, scatter), ul_y = rng32_float_if(rng, scatter);
    int count = rp->light_count;
    int li = clamp((int)(u_pick * (float)count), 0, max(count - 1, 0));
    bool nee = scatter & do_nee;
    return nee & lanes_light_sample(table, p, li, count, ul_x, ul_y, ls);
}

/* path_surface_nee at such a vertex (lanes_nee_light's light): whether it leaves a shadow ray
 * (towards ls->wi, ls->dist away), and what the ray brings where nothing blocks it: f Le w / pdf. */
inline bool lanes_diffuse_nee(__global const float *table, __global const RenderParams *rp, V3 color, V3 p, V3 n,
                              float wo_z, bool scatter, bool do_nee, Rng32 *rng, LanesLight *ls, V3 *value) {
    bool nee = lanes_nee_light(table, rp, p, scatter, do_nee, rng, ls);
    float value_max = v3_max(ls->value);
    float wi_z = lanes_dot(ls->wi, n);
    float pdf_b = wi_z * VOLCL_INV_PI;
    V3 f = v3_scale(color, wi_z * VOLCL_INV_PI);
    /* (the two maxima side by side were packed into a <2 x float>: lanes.h) */
    nee = nee & (value_max > 0.0f) & (wo_z > 0.0f) & (wi_z > 0.0f) & (lanes_after(v3_max(f), value_max) > 0.0f);
    float w = (ls->delta | !rp->mis) ? 1.0f : lanes_power_heuristic(ls->pdf, pdf_b);
    *value = v3_scale(v3_mul(f, ls->value), w / ls->pdf);
    return nee;
}

/* bsdf_sample at such a vertex: the cosine-weighted direction, three numbers drawn where the path
 * samples one (`sampling`), the first unused; whether the path goes on, its direction and pdf. The
 * first number used waits for `dep` (lanes_after): the wavefront's shadow ray traced just before,
 * whose set-up side by side with this one's was packed into <2 x float> vectors. */
inline bool lanes_diffuse_bounce(Rng32 *rng, bool sampling, float dep, V3 frame_s, V3 frame_t, V3 n, float wo_z,
                                 V3 *wi, float *pdf) {
    rng32_float_if(rng, sampling);
    float u0 = rng32_float_if(rng, sampling), u1 = rng32_float_if(rng, sampling);
    V3 wl = lanes_cosine_hemisphere(lanes_after(u0, dep), u1);
    *pdf = wl.z > 0.0f ? wl.z * VOLCL_INV_PI : 0.0f;
    *wi = lanes_to_world(wl, frame_s, frame_t, n);
    return sampling & (wo_z > 0.0f) & (*pdf > 0.0f);
}

#endif
