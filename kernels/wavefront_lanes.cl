/* The wavefront renderer's lanes stage: the medium segment of every path whose ray was just traced,
 * for homogeneous media lit by point lights, written for the SIMD lanes (kernels/lanes.h) so that
 * the CPU runtimes run 8 or 16 paths per instruction. It is path_medium_event (integrator.h) for
 * that case, draw for draw: the equiangular sample towards a point light, the free flight, NEE from
 * the collision and the phase function's new direction, with the same random numbers in the same
 * order. NEE towards a light other than a point light is left to the scalar stage, with the numbers
 * drawn for it here (WF_FLAG_NEE). What needs a BVH query is left to the scalar stage (kernels/wavefront.cl): the two shadow
 * rays are written out with the radiance they add if nothing blocks them, before their
 * transmittance (homogeneous media draw no random numbers for it, so tracing them later changes
 * nothing). Paths in no medium go on to their surface; paths in other media keep WF_EV_MEDIUM and
 * the scalar stage runs path_medium_event for them.
 *
 * A scene small enough to test whole (VOLCL_WF_TINY, lanes_triangles.h) needs no BVH: here the stage
 * also finds the closest hit of the ray the scalar stage left, and traces the two shadow rays, with
 * the BVH's bits; the scalar stage then neither traces nor reads shadow rows.
 *
 * Built as its own program, every function inlined (the pragma below marks every function declared
 * up to the kernel always_inline): LLVM's loop vectorizer (PoCL) stops at a call left out of line,
 * and the renderer's helpers used here are plain `inline`. */
#ifdef __OPTIMIZE__     /* (forced inlining at -O0 leaves calls Oclgrind cannot run: surface.h) */
#pragma clang attribute push (__attribute__((always_inline)), apply_to = function)
#endif
#include "renderer.h"
#include "lanes.h"
#include "wavefront_state.h"
#ifndef VOLCL_WF_TINY
#define VOLCL_WF_TINY 0         /* triangle lanes of a scene tested whole (lanes_triangles.h), or 0 */
#endif
#if VOLCL_WF_TINY
#include "lanes_triangles.h"
#endif

#include "lanes_rows.h"

/* transmittance_exp (media.h) */
inline V3 lanes_transmittance(V3 sigma, float t) {
#if VOLCL_HAS_CHROMATIC_MEDIA
    return v3(sigma.x == 0.0f ? 1.0f : exp(-(sigma.x * t)), sigma.y == 0.0f ? 1.0f : exp(-(sigma.y * t)),
              sigma.z == 0.0f ? 1.0f : exp(-(sigma.z * t)));
#else
    float tr = sigma.x == 0.0f ? 1.0f : exp(-(sigma.x * t));
    return v3(tr, tr, tr);
#endif
}

/* the channel probabilities of chromatic distance sampling: throughput-proportional (media.h) */
inline V3 lanes_channel_p(V3 beta) {
    V3 p = v3(fmax(beta.x, 0.0f), fmax(beta.y, 0.0f), fmax(beta.z, 0.0f));
    float total = p.x + p.y + p.z;
    float third = 1.0f / 3.0f;
    return v3_sel(total > 0.0f, v3(p.x / total, p.y / total, p.z / total), v3(third, third, third));
}

/* medium_distance_pdf_tr (integrator.h) */
inline float lanes_distance_pdf(V3 sigma_t, V3 beta, V3 tr) {
#if VOLCL_HAS_CHROMATIC_MEDIA
    return v3_dot(lanes_channel_p(beta), v3_mul(sigma_t, tr));
#else
    return sigma_t.x * tr.x;
#endif
}

/* Path i's medium step. No bounds test: the host launches whole work-groups over the wave (a store
 * under a condition would stop the vectorizer); paths past the wave's end are never alive. */
inline void wf_medium_step(__global float *fs, __global int *is, __global const float *table,
                           __global const RenderParams *rp, int i) {
    int event = IROW(WF_EVENT), mi = IROW(WF_MEDIUM), depth = IROW(WF_DEPTH);
    uint flags = (uint)IROW(WF_FLAGS);
    bool pending = lanes_pending(event);
    int mk = max(mi, 0);
    bool run = pending & (mi >= 0) & (TROW(WF_T_LANES, mk) > 0.0f);
    /* in a sealed medium every shadow ray ends on the surface around it: no NEE (volcl/sealed.py) */
    bool do_nee = ((flags & WF_FLAG_DO_NEE) != 0u) & !(TROW(WF_T_SEALED, mk) > 0.0f);
    V3 o = frow3(fs, WF_O, i), d = frow3(fs, WF_D, i), beta = frow3(fs, WF_BETA, i);
    float t_back = FROW(WF_T_BACK);
#if VOLCL_WF_TINY
    /* the closest hit of the ray the scalar stage left (a scene tested whole) */
    float hit_t, hit_b1, hit_b2;
    int hit_prim, hit_slot;
    bool hit = lanes_closest_hit(table, o, d, FROW(WF_T_MAX), &hit_t, &hit_b1, &hit_b2, &hit_prim, &hit_slot);
    flags = hit ? flags | WF_FLAG_HIT : flags & ~WF_FLAG_HIT;
#else
    bool hit = (flags & WF_FLAG_HIT) != 0u;
    float hit_t = FROW(WF_HIT_T);
#endif
    Rng32 rng = {(uint)IROW(WF_RNG), (uint)IROW(WF_RNG + 1), (uint)IROW(WF_RNG + 2), (uint)IROW(WF_RNG + 3)};
    V3 sigma_t = trow3(table, WF_T_SIGMA_T, mk), albedo = trow3(table, WF_T_ALBEDO, mk);
    float g = TROW(WF_T_G, mk);
    int count = rp->light_count;
    bool at_limit = rp->max_depth >= 0 && depth + 1 >= rp->max_depth;

    /* the segment starts at the surface the ray left, t_back behind the offset origin */
    V3 seg_o = v3_madd(o, -t_back, d);
    float seg_t = (hit ? hit_t : FROW(WF_T_MAX)) + t_back;

#if VOLCL_HAS_EQUIANGULAR
    /* equiangular_begin: which techniques estimate the point lights' light on this segment */
    bool eq_on = run & (rp->equiangular != EQUIANGULAR_OFF) & do_nee & !at_limit;
    bool one = eq_on & (rp->equiangular == EQUIANGULAR_ONE_SAMPLE) & (rp->mis != 0);
    float u_tech = rng32_float_if(&rng, one);
    /* equiangular_begin's technique as three booleans (a chain of compares on one int becomes a
     * switch, which stops the vectorizer): both samples, the equiangular one alone, the distance
     * one alone; none of them: distance sampling without MIS */
    bool only_eq = one & (u_tech < 0.5f), only_dist = one & !(u_tech < 0.5f), both = eq_on & !one;
    int tech = both ? EQ_BOTH : (only_eq ? EQ_ONLY_EQUIANGULAR : EQ_NONE);   /* for equiangular_weight */
    /* equiangular_direct: a distance towards the light it picks, and that vertex's shadow ray */
    bool eq_sample = both | only_eq;
    float u_pick_e = rng32_float_if(&rng, eq_sample), u_e = rng32_float_if(&rng, eq_sample);
    int li_e = clamp((int)(u_pick_e * (float)count), 0, max(count - 1, 0));
    V3 lp_e = trow3(table, WF_T_LIGHT_POS, li_e);
    /* a light that is not a point light gets no equiangular sample (NEE covers it) */
    bool eq_point = eq_sample & (TROW(WF_T_POINT, li_e) > 0.0f);
    int seg_light = eq_point ? li_e : -1;
    EquiangularSegment seg;
    bool seg_ok = lanes_equiangular_segment(seg_o, d, seg_t, lp_e, &seg) & eq_point;
    float t_e, pdf_e;
    bool eq_ok = equiangular_segment_sample(&seg, u_e, &t_e, &pdf_e) & seg_ok;
    V3 x = v3_madd(seg_o, t_e, d);
    V3 v = v3_sub(lp_e, x);
    float d2 = v3_dot(v, v);
    float dist = sqrt(d2);
    V3 wi = lanes_div(v, dist);
    V3 tr_e = lanes_transmittance(sigma_t, t_e);
    float w_e = equiangular_weight(tech, rp->mis, pdf_e, lanes_distance_pdf(sigma_t, beta, tr_e));
    bool shadow0 = eq_ok & (d2 > 0.0f) & (w_e > 0.0f);
    float ph_e = lanes_hg_eval(g, d, wi);
    float s_e = ph_e * w_e * (float)count / (pdf_e * d2);
    /* L += beta * (tr sigma_s Tr_shadow I s_e), Tr_shadow to come */
    V3 c_e = v3_mul(beta, v3_scale(v3_mul(v3_mul(tr_e, v3_mul(sigma_t, albedo)), trow3(table, WF_T_LIGHT_VALUE, li_e)), s_e));
#else
    bool shadow0 = false;
    V3 x = o, wi = d, c_e = v3(0.0f, 0.0f, 0.0f);
    float dist = 0.0f;
#endif

    /* medium_sample_distance: the free flight */
    float u_channel = rng32_float_if(&rng, run), u_dist = rng32_float_if(&rng, run);
    V3 beta_in = beta;
#if VOLCL_HAS_CHROMATIC_MEDIA
    V3 pc = lanes_channel_p(beta);
    float sigma_c = u_channel < pc.x ? sigma_t.x : (u_channel < pc.x + pc.y ? sigma_t.y : sigma_t.z);
    float sigma_ref = fmin(pc.x > 0.0f ? sigma_t.x : INFINITY,
                           fmin(pc.y > 0.0f ? sigma_t.y : INFINITY, pc.z > 0.0f ? sigma_t.z : INFINITY));
    float t_free = sigma_c > 0.0f ? -log_pos(1.0f - u_dist) / sigma_c : INFINITY;
    bool scattered = t_free < seg_t;
    float t_ms = scattered ? t_free : seg_t;
    V3 rel = lanes_transmittance(v3(sigma_t.x - sigma_ref, sigma_t.y - sigma_ref, sigma_t.z - sigma_ref), t_ms);
    float pdf_s = v3_dot(pc, v3_mul(sigma_t, rel)), pdf_n = v3_dot(pc, rel);
    V3 weight = v3_sel(scattered, lanes_div(v3_mul(v3_mul(albedo, sigma_t), rel), pdf_s), lanes_div(rel, pdf_n));
    float tr_ms = -1.0f;
#else
    float sigma = sigma_t.x;
    float t_free = sigma > 0.0f ? -log_pos(1.0f - u_dist) / sigma : INFINITY;
    bool scattered = t_free < seg_t;
    float t_ms = scattered ? t_free : seg_t;
    V3 weight = v3_sel(scattered, albedo, v3(1.0f, 1.0f, 1.0f));
    float tr_ms = scattered ? 1.0f - u_dist : -1.0f;
#endif
    beta = v3_sel(run, v3_mul(beta, weight), beta);
    V3 p = v3_madd(o, t_ms - t_back, d);
    bool ended = at_limit | !(v3_max(beta) > 0.0f);
    bool cont = run & scattered & !ended;

    /* next-event estimation from the collision (light_sample for a point light) */
    bool nee = cont & do_nee;
    float u_pick = rng32_float_if(&rng, nee);
    float ul_x = rng32_float_if(&rng, nee), ul_y = rng32_float_if(&rng, nee);  /* a point light uses neither */
    int li = clamp((int)(u_pick * (float)count), 0, max(count - 1, 0));
    bool point = TROW(WF_T_POINT, li) > 0.0f;
    bool nee_later = nee & !point;      /* the scalar stage samples other lights */
    V3 lp = trow3(table, WF_T_LIGHT_POS, li);
    V3 vl = v3_sub(lp, p);
    float d2l = v3_dot(vl, vl);
    float dist_l = sqrt(d2l);
    V3 wl = lanes_div(vl, dist_l);
    V3 value = lanes_div(trow3(table, WF_T_LIGHT_VALUE, li), d2l);
    bool shadow1 = nee & point & (d2l > 0.0f) & (v3_max(value) > 0.0f);
#if VOLCL_HAS_EQUIANGULAR
    /* equiangular_distance_weight: this vertex's share against the equiangular sample */
    EquiangularSegment seg_l;
    bool seg_l_ok = lanes_equiangular_segment(seg_o, d, seg_t, lp, &seg_l);
    float pdf_e_here = li == seg_light ? (seg_ok ? equiangular_segment_pdf(&seg, t_ms) : 0.0f)
                                       : (seg_l_ok ? equiangular_segment_pdf(&seg_l, t_ms) : 0.0f);
    float pdf_d = lanes_distance_pdf(sigma_t, beta_in,
                                     v3_sel(tr_ms >= 0.0f, v3(tr_ms, tr_ms, tr_ms), lanes_transmittance(sigma_t, t_ms)));
    float ph_d = power_heuristic(pdf_d, pdf_e_here);
    float w_mis = rp->mis ? ph_d : (pdf_e_here > 0.0f ? 0.0f : 1.0f);
    float w_eq = only_eq ? 0.0f : (only_dist ? 2.0f * ph_d : (both ? w_mis : 1.0f));
    shadow1 = shadow1 & (w_eq > 0.0f);
#else
    float w_eq = 1.0f;
#endif
    float ph_l = lanes_hg_eval(g, d, wl);
    /* L += beta * (w_eq * (ph value Tr_shadow (1 / pdf))), pdf = 1 / count (the pick; delta light: weight 1) */
    float inv_pdf = 1.0f / (1.0f / (float)count);
    V3 c_l = v3_mul(beta, v3_scale(v3_scale(value, ph_l * inv_pdf), w_eq));

    /* phase_sample: the new direction (the isotropic phase function's value is HG's at g = 0; it
     * is sampled as the uniform sphere, as phase.h does) */
    float u_w = rng32_float_if(&rng, cont), u_phi = rng32_float_if(&rng, cont);
    bool iso = TROW(WF_T_ISO, mk) > 0.0f;
    V3 peak = v3_scale(d, g >= 0.0f ? 1.0f : -1.0f);
    V3 nd = v3_sel(iso, lanes_uniform_sphere(u_w, u_phi), lanes_direction_at(peak, phase_hg_sample_w(fabs(g), u_w), u_phi));
    float pdf_hg = lanes_hg_eval(g, d, nd);
    float pdf_dir = iso ? VOLCL_INV_4PI : pdf_hg;

    /* write back: every field, changed or not */
    int next = !pending ? event : (mi < 0 ? PATH_SURFACE : (!run ? WF_EV_MEDIUM
               : (!scattered ? PATH_SURFACE : (ended ? PATH_END : PATH_CONTINUE))));
#if VOLCL_WF_TINY
    /* path_roulette and the step count, as the scalar stage's loop takes them after a medium event:
     * a path that scattered needs nothing of the scalar stage then (the stage traces it next) */
    /* (not where NEE towards a light other than a point light is left to the scalar stage: it
     * comes before the roulette, with the throughput before it) */
    bool going = cont & !nee_later;
    bool killed = lanes_roulette(&rng, &beta, going, depth + 1, rp->rr_depth, FROW(WF_ETA_SCALE));
    int steps = IROW(WF_STEPS) + (going ? 1 : 0);
    next = going ? ((killed | (steps >= VOLCL_MAX_STEPS)) ? PATH_END : WF_EV_NEXT) : next;
    IROW(WF_STEPS) = steps;
#endif
    IROW(WF_EVENT) = next;
    uint keep = flags & ~(WF_FLAG_SHADOW0 | WF_FLAG_SHADOW1 | WF_FLAG_NEE | (cont ? WF_FLAG_SPECULAR : 0u));
#if VOLCL_WF_TINY
    uint traced = 0u;       /* the shadow rays are traced below */
#else
    uint traced = ((run & shadow0) ? WF_FLAG_SHADOW0 : 0u) | (shadow1 ? WF_FLAG_SHADOW1 : 0u);
#endif
    IROW(WF_FLAGS) = (int)(keep | traced | (nee_later ? WF_FLAG_NEE : 0u));
    lanes_put_scatter(fs, is, i, cont, depth, &rng, beta, p, pdf_dir, p, nd, 0.0f);
#if VOLCL_WF_TINY
    /* the shadow rays here too, as wf_shadow (wavefront.cl) traces them: the segment's
     * transmittance in the path's medium unless a triangle blocks it */
    FROW(WF_HIT_T) = hit_t;
    FROW(WF_HIT_B1) = hit_b1;
    FROW(WF_HIT_B2) = hit_b2;
    IROW(WF_HIT_PRIM) = hit_prim;
    IROW(WF_HIT_INST) = -1;
    V3 L = frow3(fs, WF_L, i);
    /* a ray that is not to be traced gets an empty segment (reach -1), and the second ray's numbers
     * wait for the first's (lanes_after): the two rays' conditions and tests side by side were
     * packed into <2 x ...> vectors */
    float t0 = dist * 0.9999f;
    float reach0 = lanes_reach(table, x, wi, (run & shadow0) ? t0 : -1.0f, 0);
    V3 tr0 = lanes_transmittance(sigma_t, t0);
    float t1 = lanes_after(dist_l * 0.9999f, reach0);
    float reach1 = lanes_reach(table, lanes_after3(p, reach0), lanes_after3(wl, reach0), shadow1 ? t1 : -1.0f, 0);
    V3 tr1 = lanes_transmittance(sigma_t, t1);
    bool pass0 = (reach0 >= 0.0f) & (v3_max(tr0) > 0.0f);
    bool pass1 = (reach1 >= 0.0f) & (v3_max(tr1) > 0.0f);
    L = v3_sel(pass0, v3_add(L, v3_mul(c_e, tr0)), L);
    L = v3_sel(pass1, v3_add(L, v3_mul(c_l, tr1)), L);
    frow3_put(fs, WF_L, i, L);
#else
    frow3_put(fs, WF_SHADOW(0) + WF_SHADOW_O, i, x);
    frow3_put(fs, WF_SHADOW(0) + WF_SHADOW_D, i, wi);
    FROW(WF_SHADOW(0) + WF_SHADOW_T) = dist * 0.9999f;
    frow3_put(fs, WF_SHADOW(0) + WF_SHADOW_C, i, c_e);
#endif
    frow3_put(fs, WF_SHADOW(1) + WF_SHADOW_O, i, p);
    frow3_put(fs, WF_SHADOW(1) + WF_SHADOW_D, i, v3_sel(nee_later, d, wl));
    FROW(WF_SHADOW(1) + WF_SHADOW_T) = dist_l * 0.9999f;
    frow3_put(fs, WF_SHADOW(1) + WF_SHADOW_C, i, v3_sel(nee_later, v3(u_pick, ul_x, ul_y), c_l));
}

#ifdef __OPTIMIZE__
#pragma clang attribute pop
#endif

/* VOLCL_WF_LOOP paths per work-item, in a loop that LLVM's loop vectorizer runs in the SIMD lanes
 * (volcl.wavefront.lanes_loop: PoCL), or 0: one path per work-item, for the runtime's own
 * vectorizer across work-items. PoCL vectorizes its loop over a work-group's items only after the
 * SLP vectorizer has run on the one work-item's code, and on AVX2 that packed pairs of the
 * stage's scalars into <2 x float> vectors all over it, which stopped the loop vectorizer (README,
 * "The medium stage as a loop of its own"); an explicit loop is vectorized before the SLP
 * vectorizer runs. */
#ifndef VOLCL_WF_LOOP
#define VOLCL_WF_LOOP 0
#endif

/* (the front end's optimizer leaves the loop to the work-group compiler, which vectorizes it, and
 * says so in a warning every first build printed) */
#pragma clang diagnostic ignored "-Wpass-failed"
__kernel void wavefront_medium(__global float *fs, __global int *is, __global const float *table,
                               __global const RenderParams *rp) {
#if VOLCL_WF_LOOP
    int base = (int)get_global_id(0) * VOLCL_WF_LOOP;
#pragma clang loop unroll(disable) vectorize(assume_safety) vectorize_width(VOLCL_WF_LOOP) interleave_count(1)
    for (int l = 0; l < VOLCL_WF_LOOP; ++l) wf_medium_step(fs, is, table, rp, base + l);
#else
    wf_medium_step(fs, is, table, rp, (int)get_global_id(0));
#endif
}
