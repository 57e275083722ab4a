/* The wavefront renderer's surface stage: the lanes stage of a scene without media that is small
 * enough to test whole (volcl/wavefront.py surface_lanes), written for the SIMD lanes (lanes.h).
 * For every path whose ray the scalar stage (wavefront.cl) left, it finds the closest hit
 * (lanes_triangles.h); where that is a plain diffuse triangle (the table marks them: untextured
 * or checkered with two colours, flat, not emitting) it takes the whole step there, as
 * path_surface_event and path_roulette do it (integrator.h), draw for draw: next-event estimation towards a point light or an area light on
 * triangles with its shadow ray, the cosine-weighted new direction, the roulette; and marks the
 * path WF_EV_NEXT, which the scalar stage leaves alone. Every other hit (spheres, other bsdfs,
 * emitters) and every miss goes to the scalar stage as PATH_SURFACE, with the hit's rows.
 *
 * Built as its own program, every function inlined, as wavefront_lanes.cl is. */
#ifdef __OPTIMIZE__     /* (forced inlining at -O0 leaves calls Oclgrind cannot run: surface.h) */
#pragma clang attribute push (__attribute__((always_inline)), apply_to = function)
#endif
#include "renderer.h"
#include "lanes.h"
#include "wavefront_state.h"
#include "lanes_rows.h"
#include "lanes_triangles.h"
#include "lanes_surface.h"
#ifdef __OPTIMIZE__
#pragma clang attribute pop
#endif

/* No bounds test: the host launches whole work-groups over the wave; paths past the wave's end are
 * never alive. */
__kernel void wavefront_surface(__global float *fs, __global int *is, __global const float *table,
                                __global const RenderParams *rp) {
    int i = (int)get_global_id(0);
    int event = IROW(WF_EVENT), depth = IROW(WF_DEPTH);
    uint flags = (uint)IROW(WF_FLAGS);
    bool pending = lanes_pending(event);
    V3 o = frow3(fs, WF_O, i), d = frow3(fs, WF_D, i), beta = frow3(fs, WF_BETA, i), L = frow3(fs, WF_L, i);
    float hit_t, hit_b1, hit_b2;
    int hit_prim, slot;
    bool hit = lanes_closest_hit(table, o, d, FROW(WF_T_MAX), &hit_t, &hit_b1, &hit_b2, &hit_prim, &slot);

    LanesTriangle tri = lanes_triangle_at(table, slot);
    tri.color = lanes_color_at(&tri, hit_b1, hit_b2);
    bool surf = pending & hit & (tri.lanes > 0.0f);     /* (a sphere's slot is -1: no triangle's numbers) */
    bool at_limit = rp->max_depth >= 0 && depth + 1 >= rp->max_depth;
    bool scatter = surf & !at_limit;    /* a diffuse surface passes nothing at the depth limit */

    V3 p, frame_s, frame_t, n;
    float wo_z;
    lanes_diffuse_vertex(&tri, hit_b1, hit_b2, d, &p, &frame_s, &frame_t, &n, &wo_z);
    V3 ng = tri.ng;

    Rng32 rng = {(uint)IROW(WF_RNG), (uint)IROW(WF_RNG + 1), (uint)IROW(WF_RNG + 2), (uint)IROW(WF_RNG + 3)};
    LanesLight ls;
    V3 c;
    bool nee = lanes_diffuse_nee(table, rp, tri.color, p, n, wo_z, scatter, (flags & WF_FLAG_DO_NEE) != 0u, &rng,
                                 &ls, &c);
    V3 origin = lanes_offset_origin(p, tri.mag, ng, ls.wi);
    /* (the ray's direction waits for its origin: the |.| of both, side by side, were packed) */
    float reach = lanes_reach(table, origin, lanes_after3(ls.wi, origin.x), nee ? ls.dist * 0.9999f : -1.0f,
                              VOLCL_WF_HULL_SKIP);
    L = v3_sel(nee & (reach >= 0.0f), v3(L.x + beta.x * c.x, L.y + beta.y * c.y, L.z + beta.z * c.z), L);

    bool sampling = scatter & !rp->specular_chains_only;
    V3 wi;
    float pdf;
    bool cont = lanes_diffuse_bounce(&rng, sampling, reach, frame_s, frame_t, n, wo_z, &wi, &pdf);
    V3 beta_s = v3_mul(beta, tri.color);

    /* path_roulette, and the step count */
    bool alive = cont & (v3_max(beta_s) > 0.0f);
    bool killed = lanes_roulette(&rng, &beta_s, alive, depth + 1, rp->rr_depth, FROW(WF_ETA_SCALE));
    int steps = IROW(WF_STEPS) + (surf ? 1 : 0);
    int next = !pending ? event : (!surf ? PATH_SURFACE
               : ((alive & !killed & (steps < VOLCL_MAX_STEPS)) ? WF_EV_NEXT : PATH_END));
    V3 o_next = lanes_offset_origin(p, tri.mag, ng, wi);

    /* write back: every field, changed or not */
    IROW(WF_EVENT) = next;
    IROW(WF_STEPS) = steps;
    uint keep = flags & ~(WF_FLAG_SHADOW0 | WF_FLAG_SHADOW1 | WF_FLAG_NEE | WF_FLAG_HIT | (cont ? WF_FLAG_SPECULAR : 0u));
    IROW(WF_FLAGS) = (int)(keep | (hit ? WF_FLAG_HIT : 0u));
    frow3_put(fs, WF_L, i, L);
    lanes_put_scatter(fs, is, i, cont, depth, &rng, v3_sel(cont, beta_s, beta), p, pdf, o_next, wi,
                      lanes_offset_back(o_next, p, ng, wi));
    FROW(WF_HIT_T) = hit_t;
    FROW(WF_HIT_B1) = hit_b1;
    FROW(WF_HIT_B2) = hit_b2;
    IROW(WF_HIT_PRIM) = hit_prim;
    IROW(WF_HIT_INST) = -1;
}
