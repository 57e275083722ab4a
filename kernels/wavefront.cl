/* The wavefront renderer's scalar stage (volcl/wavefront.py runs it): the part of a path step that
 * queries the BVH or branches too much for the SIMD lanes, one path per work-item, with the
 * megakernel's own functions.
 *
 * The stages stand in for one render_pass launch (render.cl) with the same arguments: its work-items'
 * samples, `passes` each, are jobs (job pass * items + work-item), which the paths in flight take in
 * turn from a counter as their samples end, so that no path idles while others still have samples
 * to render. Each sample's radiance goes to its job's entry in `results`, and wavefront_add then
 * adds every work-item's samples to its accumulator entry in the order render_pass adds them, so
 * the sums are the megakernel's. A path's state lives in the rows of fs and is (wavefront_state.h)
 * between launches, and each launch of wavefront_scalar takes it one step:
 *   - the medium event's shadow rays (left by the lanes stage, wavefront_lanes.cl): their
 *     transmittance, and the radiance they bring; or, for a medium the lanes stage does not handle,
 *     path_medium_event itself;
 *   - the surface event and Russian roulette (integrator.h), as integrator_radiance's loop does;
 *   - at the path's end, its radiance into `results`, and the next job;
 *   - the next ray's closest hit, for the lanes stage to step through its medium (for a scene the
 *     lanes stage tests whole, VOLCL_WF_TINY, the lanes stage finds it, and traces the shadow rays).
 * The random numbers are drawn in integrator_radiance's order, the lanes stage's in between, so a
 * sample follows the same path as in the megakernel up to the roundings of vector arithmetic. */
/* the path's steps out of line here (common.h): inlined, point_in_fog's wavefront render ran
 * 0.91-0.97x as fast on PoCL */
#define VOLCL_STEP_INLINE
#include "renderer.h"
#include "wavefront_state.h"
#ifndef VOLCL_WF_TINY
#define VOLCL_WF_TINY 0         /* a scene the lanes stage traces itself (lanes_triangles.h), or 0 */
#endif

#define FROW(r) fs[WF_AT(r)]
#define IROW(r) is[WF_AT(r)]

inline float3 wf_get3(__global const float *fs, int r, int i) {
    return (float3)(FROW(r), FROW(r + 1), FROW(r + 2));
}

inline void wf_put3(__global float *fs, int r, int i, float3 v) {
    FROW(r) = v.x;
    FROW(r + 1) = v.y;
    FROW(r + 2) = v.z;
}

inline void wf_load(__global const float *fs, __global const int *is, int i, PathState *ps, Rng *rng,
                    Hit *h, bool *hit) {
    uint flags = (uint)IROW(WF_FLAGS);
    ps->L = wf_get3(fs, WF_L, i);
    ps->beta = wf_get3(fs, WF_BETA, i);
    ps->o = wf_get3(fs, WF_O, i);
    ps->d = wf_get3(fs, WF_D, i);
    ps->t_max = FROW(WF_T_MAX);
    ps->t_back = FROW(WF_T_BACK);
    ps->prev_pdf = FROW(WF_PREV_PDF);
    ps->prev_p = wf_get3(fs, WF_PREV_P, i);
    ps->eta_scale = FROW(WF_ETA_SCALE);
    ps->medium = IROW(WF_MEDIUM);
    ps->depth = IROW(WF_DEPTH);
    ps->specular = (flags & WF_FLAG_SPECULAR) != 0u;
    ps->do_nee = (flags & WF_FLAG_DO_NEE) != 0u;
    rng->state = (ulong)(uint)IROW(WF_RNG) | ((ulong)(uint)IROW(WF_RNG + 1) << 32);
    rng->inc = (ulong)(uint)IROW(WF_RNG + 2) | ((ulong)(uint)IROW(WF_RNG + 3) << 32);
    *hit = (flags & WF_FLAG_HIT) != 0u;
    h->t = FROW(WF_HIT_T);
    h->b1 = FROW(WF_HIT_B1);
    h->b2 = FROW(WF_HIT_B2);
    h->prim = IROW(WF_HIT_PRIM);
#if VOLCL_HAS_INSTANCES
    h->inst = IROW(WF_HIT_INST);
#endif
}

inline void wf_store(__global float *fs, __global int *is, int i, const PathState *ps, const Rng *rng,
                     const Hit *h, bool hit) {
    wf_put3(fs, WF_L, i, ps->L);
    wf_put3(fs, WF_BETA, i, ps->beta);
    wf_put3(fs, WF_O, i, ps->o);
    wf_put3(fs, WF_D, i, ps->d);
    FROW(WF_T_MAX) = ps->t_max;
    FROW(WF_T_BACK) = ps->t_back;
    FROW(WF_PREV_PDF) = ps->prev_pdf;
    wf_put3(fs, WF_PREV_P, i, ps->prev_p);
    FROW(WF_ETA_SCALE) = ps->eta_scale;
    IROW(WF_MEDIUM) = ps->medium;
    IROW(WF_DEPTH) = ps->depth;
    IROW(WF_FLAGS) = (int)(WF_FLAG_ALIVE | (ps->specular ? WF_FLAG_SPECULAR : 0u)
                           | (ps->do_nee ? WF_FLAG_DO_NEE : 0u) | (hit ? WF_FLAG_HIT : 0u));
    IROW(WF_RNG) = (int)(uint)rng->state;
    IROW(WF_RNG + 1) = (int)(uint)(rng->state >> 32);
    IROW(WF_RNG + 2) = (int)(uint)rng->inc;
    IROW(WF_RNG + 3) = (int)(uint)(rng->inc >> 32);
#if VOLCL_WF_TINY           /* the lanes stage traces the ray */
    (void)h;
#else
    FROW(WF_HIT_T) = h->t;
    FROW(WF_HIT_B1) = h->b1;
    FROW(WF_HIT_B2) = h->b2;
    IROW(WF_HIT_PRIM) = h->prim;
#if VOLCL_HAS_INSTANCES
    IROW(WF_HIT_INST) = h->inst;
#else
    IROW(WF_HIT_INST) = -1;
#endif
#endif
}

/* The radiance of the lanes stage's shadow ray k, if its flag is set: its transmittance in the
 * path's medium times what it carries. */
inline float3 wf_shadow(const SceneData *sc, __global const float *fs, int i, int k, int medium, Rng *rng,
                        uint *cut) {
    int r = WF_SHADOW(k);
    float3 tr = shadow_transmittance(sc, 0, wf_get3(fs, r + WF_SHADOW_O, i), wf_get3(fs, r + WF_SHADOW_D, i),
                                     FROW(r + WF_SHADOW_T), medium, rng, cut);
    return max_component(tr) > 0.0f ? wf_get3(fs, r + WF_SHADOW_C, i) * tr : (float3)(0.0f);
}

/* Start job `job`'s sample (the work-item's slot and tile pixel as render_pass finds them). */
inline PathState wf_start_job(const SceneData *sc, __global const float *filter_table, int job, uint sample_base,
                              int tile_x, int tile_y, int tile_w, int first, int count, int slots, Rng *rng) {
    int items = count * slots;
    int item = job % items, pass = job / items;
    int slot = item / count;
    int tp = first + item % count;
    int px = tile_x + tp % tile_w, py = tile_y + tp / tile_w;
    float3 o, d;
    float t_max;
    sample_camera_ray(sc, filter_table, px, py, py * sc->params->width + px,
                      sample_base + (uint)(pass * slots + slot), rng, &o, &d, &t_max);
    return path_start(sc, o, d, t_max);
}

/* NEE from a collision towards a light the lanes stage does not sample (WF_FLAG_NEE), as
 * path_medium_event does it: the light is not point-like, so the equiangular weight is 1 and
 * the phase function's value and pdf are MIS'd with it; the throughput is the path's (the phase
 * samplers of the lanes stage have weight 1). */
inline float3 wf_nee(const SceneData *sc, __global const float *fs, int i, const PathState *ps, Rng *rng,
                     uint *cut) {
    int r = WF_SHADOW(1);
    float3 p = wf_get3(fs, r + WF_SHADOW_O, i), d_in = wf_get3(fs, r + WF_SHADOW_D, i);
    float3 u = wf_get3(fs, r + WF_SHADOW_C, i);
    LightSample ls;
    if (!light_sample(sc, p, u.x, (float2)(u.y, u.z), &ls) || !(max_component(ls.value) > 0.0f))
        return (float3)(0.0f);
    __global const Medium *m = &sc->media[ps->medium];
    float ph_pdf;
    float ph = phase_eval_pdf(sc, m, d_in, ls.wi, &ph_pdf);
    return ps->beta * nee_contribution(sc, 0, &ls, (float3)(ph), ph_pdf, p, ps->medium, rng, cut);
}

VOLCL_KERNEL void wavefront_scalar(VOLCL_SCENE_ARGS,
                          __global float4 *results, __global int *next_job,
                          uint sample_base, int tile_x, int tile_y, int tile_w, int tile_pixels,
                          int first, int count, int slots, int passes,
                          __global float *fs, __global int *is) {
    int i = (int)get_global_id(0);      /* the path's place in the wave */
    (void)tile_pixels;                  /* render_pass's arguments all; wavefront_add places the sums */
    if (!((uint)IROW(WF_FLAGS) & WF_FLAG_ALIVE)) return;
    SceneData sc = VOLCL_SCENE_DATA;
    int event = IROW(WF_EVENT);
    if (event == WF_EV_NEXT) return;    /* the lanes stage took the step (VOLCL_WF_TINY) */
    int job = IROW(WF_JOB), steps = IROW(WF_STEPS);
    uint cut = (uint)IROW(WF_CUTOFFS);
    PathState ps;
    Rng rng;
    Hit h;
    bool hit;
    if (event != WF_EV_START) {
        uint flags = (uint)IROW(WF_FLAGS);
        wf_load(fs, is, i, &ps, &rng, &h, &hit);
        if (event == WF_EV_MEDIUM) {
            event = path_medium_event(&sc, &rng, &ps, hit, &h, &cut);
        } else {
            if (flags & WF_FLAG_SHADOW0) ps.L += wf_shadow(&sc, fs, i, 0, ps.medium, &rng, &cut);
            if (flags & WF_FLAG_SHADOW1) ps.L += wf_shadow(&sc, fs, i, 1, ps.medium, &rng, &cut);
            if (flags & WF_FLAG_NEE) ps.L += wf_nee(&sc, fs, i, &ps, &rng, &cut);
        }
        if (event == PATH_SURFACE) event = path_surface_event(&sc, &rng, &ps, hit, &h, &cut);
        if (event == PATH_CONTINUE && !path_roulette(&sc, &rng, &ps)) event = PATH_END;
        if (++steps >= VOLCL_MAX_STEPS) event = PATH_END;
        if (event == PATH_END) results[job] = (float4)(ps.L, as_float(cut));
    }
    if (event == WF_EV_START || event == PATH_END) {
        job = atomic_inc(next_job);
        if (job >= count * slots * passes) {
            IROW(WF_FLAGS) = 0;
            IROW(WF_EVENT) = PATH_END;
            return;
        }
        ps = wf_start_job(&sc, filter_table, job, sample_base, tile_x, tile_y, tile_w, first, count, slots, &rng);
        steps = 0;
        cut = 0u;
    }
#if VOLCL_WF_TINY
    hit = false;        /* the lanes stage traces the ray */
#else
    hit = bvh_trace(&sc, ps.o, ps.d, ps.t_max, TRACE_CLOSEST, &h);
#endif
    wf_store(fs, is, i, &ps, &rng, &h, hit);
    IROW(WF_EVENT) = WF_EV_MEDIUM;
    IROW(WF_JOB) = job;
    IROW(WF_STEPS) = steps;
    IROW(WF_CUTOFFS) = (int)cut;
}

/* The start of a run: paths 0 to n - 1 alive, each about to take its first job. */
VOLCL_KERNEL void wavefront_begin(__global int *is, int n) {
    int i = (int)get_global_id(0);
    if (i >= n) return;
    IROW(WF_FLAGS) = (int)WF_FLAG_ALIVE;
    IROW(WF_EVENT) = WF_EV_START;
}

/* Every work-item's samples from `results` into its accumulator entry, in render_pass's order. */
VOLCL_KERNEL void wavefront_add(__global const float4 *results, __global float4 *sums, __global float4 *sums_sq,
                                __global uint *invalid, __global uint *cutoffs, int tile_pixels, int first,
                                int count, int slots, int passes) {
    int item = (int)get_global_id(0);
    if (item >= count * slots) return;
    int out = (item / count) * tile_pixels + first + item % count;
    for (int pass = 0; pass < passes; ++pass) {
        float4 r = results[pass * count * slots + item];
        sample_add(r.xyz, as_uint(r.w), out, sums, sums_sq, invalid, cutoffs);
    }
}
