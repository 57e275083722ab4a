/* The wavefront renderer's surface stage: the lanes stage of a scene without media that is small
 * enough to test whole (volcl/wavefront.py surface_lanes), written for the SIMD lanes (lanes.h).
 * For every path whose ray the scalar stage (wavefront.cl) left, it finds the closest hit
 * (lanes_triangles.h); where that is a plain diffuse triangle (the table marks them: untextured,
 * flat, not emitting) it takes the whole step there, as path_surface_event and path_roulette do it
 * (integrator.h), draw for draw: next-event estimation towards a point light or an area light on
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
    bool surf = pending & hit & (tri.lanes > 0.0f);     /* (a sphere's slot is -1: no triangle's numbers) */
    bool at_limit = rp->max_depth >= 0 && depth + 1 >= rp->max_depth;
    bool scatter = surf & !at_limit;    /* a diffuse surface passes nothing at the depth limit */

    V3 p = lanes_surface_point(&tri, hit_b1, hit_b2), ng = tri.ng, color = tri.color;
    V3 wo = v3(-d.x, -d.y, -d.z);
    /* bsdf_vertex_at: the frame about the normal; a two-sided bsdf seen from behind turns the
     * normal (after the frame is made) */
    V3 frame_s, frame_t;
    lanes_make_frame(ng, &frame_s, &frame_t);
    bool flip = (tri.twosided > 0.0f) & (lanes_dot(wo, ng) < 0.0f);
    V3 n = v3_sel(flip, v3(-ng.x, -ng.y, -ng.z), ng);
    float wo_z = lanes_dot(wo, n);

    /* path_surface_nee */
    Rng32 rng = {(uint)IROW(WF_RNG), (uint)IROW(WF_RNG + 1), (uint)IROW(WF_RNG + 2), (uint)IROW(WF_RNG + 3)};
    float u_pick = rng32_float_if(&rng, scatter);
    float ul_x = rng32_float_if(&rng, scatter), ul_y = rng32_float_if(&rng, scatter);
    int count = rp->light_count;
    int li = clamp((int)(u_pick * (float)count), 0, max(count - 1, 0));
    LanesLight ls;
    bool nee = scatter & ((flags & WF_FLAG_DO_NEE) != 0u);
    nee = nee & lanes_light_sample(table, p, li, count, ul_x, ul_y, &ls);
    float value_max = v3_max(ls.value);
    float wi_z = lanes_dot(ls.wi, n);
    float pdf_b = wi_z * VOLCL_INV_PI;
    V3 f = v3_scale(color, wi_z * VOLCL_INV_PI);
    /* (the two maxima side by side were packed into a <2 x float>: lanes.h) */
    nee = nee & (value_max > 0.0f) & (wo_z > 0.0f) & (wi_z > 0.0f) & (lanes_after(v3_max(f), value_max) > 0.0f);
    V3 origin = lanes_offset_origin(p, tri.mag, ng, ls.wi);
    /* (the ray's direction waits for its origin: the |.| of both, side by side, were packed) */
    float reach = lanes_reach(table, origin, lanes_after3(ls.wi, origin.x), nee ? ls.dist * 0.9999f : -1.0f,
                              VOLCL_WF_HULL_SKIP);
    float w = (ls.delta | !rp->mis) ? 1.0f : lanes_power_heuristic(ls.pdf, pdf_b);
    V3 c = v3_scale(v3_mul(f, ls.value), w / ls.pdf);
    L = v3_sel(nee & (reach >= 0.0f), v3(L.x + beta.x * c.x, L.y + beta.y * c.y, L.z + beta.z * c.z), L);

    /* bsdf_sample: the cosine-weighted direction (three numbers drawn, the first unused) */
    bool sampling = scatter & !rp->specular_chains_only;
    rng32_float_if(&rng, sampling);
    float u0 = rng32_float_if(&rng, sampling), u1 = rng32_float_if(&rng, sampling);
    /* the new direction waits for the shadow ray (lanes_after): their set-ups side by side were
     * packed into <2 x float> vectors */
    V3 wl = lanes_cosine_hemisphere(lanes_after(u0, reach), u1);
    float pdf = wl.z > 0.0f ? wl.z * VOLCL_INV_PI : 0.0f;
    bool cont = sampling & (wo_z > 0.0f) & (pdf > 0.0f);
    V3 wi = lanes_to_world(wl, frame_s, frame_t, n);
    V3 beta_s = v3_mul(beta, color);

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
