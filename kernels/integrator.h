/* The volumetric path tracer: unidirectional paths with surface and medium vertices, next-event
 * estimation combined with BSDF / phase sampling by multiple importance sampling (power heuristic),
 * and Russian roulette. Directions: `d` is the travel direction of the current ray; at a vertex wo = -d
 * points back to the viewer and wi to the next vertex (see bsdf.h, phase.h for their conventions).
 *
 * Depth counts scattering vertices as in Mitsuba: max_depth = 1 shows emitters only, 2 adds direct
 * lighting. Passing through a null boundary is not a vertex and does not count.
 */
#ifndef VOLCL_INTEGRATOR_H
#define VOLCL_INTEGRATOR_H

#include "equiangular.h"   /* point lights in media (VOLCL_HAS_EQUIANGULAR) */

/* Hard bound on loop iterations (vertices plus boundary crossings): Russian roulette ends paths long
 * before it (survival is capped at 0.95, so 1e-22 of paths reach 1000 vertices); it only stops
 * pathological scenes from spinning forever. */
#define VOLCL_MAX_STEPS 1024
/* Boundaries a shadow ray may cross before it is declared blocked. */
#define VOLCL_MAX_CROSSINGS 64

/* Medium on the side of surface point `s` that direction `w` leaves on; media follow shapes that
 * name one, and otherwise stay as they were (Mitsuba's rule). */
inline int medium_after(const SceneData *sc, const SurfacePoint *s, float3 w, int current) {
#if VOLCL_HAS_MEDIUM_BOUNDARIES
    __global const ShapeInfo *sh = &sc->shapes[s->shape];
    if (sh->is_transition) return dot(w, s->ng) > 0.0f ? sh->exterior : sh->interior;
#endif
    return current;
}

/* The medium a camera ray starts in, and its origin. The sensor's medium holds at the pinhole, but
 * the ray starts at the near clip plane, and media boundaries in between were never crossed.
 * Hazard: a camera just outside a fog box (within the near clip), or exactly on a boundary (a
 * pinhole on a null sphere's surface: the crossing sits at t = 0, which every intersection test
 * rejects), sent all its rays on in the wrong medium. So the clipped part is walked from a little
 * behind the pinhole, and every boundary crossed on it applies (surfaces there are clipped away,
 * as in Mitsuba); a crossing right at the near plane moves the origin past it. */
VOLCL_STEP_INLINE
inline int camera_start_medium(const SceneData *sc, float3 *o, float3 d, float *t_max, int medium) {
#if VOLCL_HAS_MEDIUM_BOUNDARIES
    __global const RenderParams *rp = sc->params;
    if (!rp->camera_walk) return medium;
    /* where the ray leaves the camera (the pinhole, a point of the lens, or of the orthographic
     * camera's plane): back from the near clip along d, by near_clip in the camera's z units */
    float3 fwd = (float3)(rp->cam_to_world[2], rp->cam_to_world[6], rp->cam_to_world[10]);
    float3 pinhole = *o - (rp->near_clip * dot(fwd, fwd) / dot(d, fwd)) * d;
    /* behind by more than the spheres' self-intersection margin and triangle rounding, at any scale */
    float back = 1e-5f * (max_component(fabs(pinhole)) + rp->scene_radius);
    float3 p = pinhole - back * d;
    float reach = dot(*o - p, d);
    for (int i = 0; i < VOLCL_MAX_CROSSINGS && reach > 0.0f; ++i) {
        Hit h;
        if (!bvh_trace(sc, p, d, reach, TRACE_CLOSEST, &h)) break;
        SurfacePoint s = surface_point(sc, &h, p, d);
        medium = medium_after(sc, &s, d, medium);
        float3 next = offset_origin(s.p, s.mag, s.ng, d);
        reach -= dot(next - p, d);
        p = next;
    }
    if (reach < 0.0f) {
        *o = p;
        *t_max = fmax(*t_max + reach, 0.0f);
    }
#endif
    return medium;
}

/* Fraction of light that travels from o along w for distance t_max: zero if an opaque or refracting
 * surface is in the way, otherwise the product of the transmittances of the media crossed (for
 * heterogeneous media an unbiased ratio-tracking estimate, which draws from rng; tracking cut-offs
 * are counted in *cutoffs). *end_medium: the medium at the segment's far end; *last_segment: the
 * length of its last medium segment, from the boundary it entered that medium at (emission NEE).
 * `root`: the tree traced (bvh_trace_in): 0, or surface_shadow_root's for a segment between two
 * points of the scene. */
VOLCL_STEP_INLINE
inline float3 shadow_transmittance_to(const SceneData *sc, int root, float3 o, float3 w, float t_max, int medium,
                                      Rng *rng, uint *cutoffs, int *end_medium, float *last_segment) {
    *end_medium = -2;       /* no medium: the segment was blocked before its end */
    *last_segment = 0.0f;
#if VOLCL_HAS_MEDIA || VOLCL_HAS_NULL_BSDF || VOLCL_HAS_MASK || VOLCL_HAS_THINDIELECTRIC
    float3 tr = (float3)(1.0f);
    float t_back = 0.0f;    /* from the boundary just crossed to the offset origin: see integrator_radiance */
    for (int i = 0; i < VOLCL_MAX_CROSSINGS; ++i) {
        Hit h;
        bool hit = bvh_trace_in(sc, root, o, w, t_max, TRACE_SHADOW, &h);
        SurfacePoint s;
        float3 passed = (float3)(1.0f);
        if (hit) {
            /* an opaque surface anywhere on the segment blocks it: the query stops at the first one
             * it finds, before any medium on the way is estimated. Null surfaces pass everything,
             * masks and panes a part (bsdf_vertex.h); the leaf packets mark none of them opaque
             * (volcl.pack), so the hit is then the nearest on the segment. */
            s = surface_point(sc, &h, o, w);
            passed = surface_null_transmission(sc, &h, &s, w);
            if (!(max_component(passed) > 0.0f)) return (float3)(0.0f);
        }
        float seg = (hit ? h.t : t_max) + t_back;
#if VOLCL_HAS_MEDIA
        if (medium >= 0) tr = medium_attenuate(sc, &sc->media[medium], o - t_back * w, w, seg, tr, rng, cutoffs);
#endif
        if (!hit) {
            *end_medium = medium;
            *last_segment = seg;
            return tr;
        }
        tr *= passed;
        if (max_component(tr) <= 0.0f) return tr;
        medium = medium_after(sc, &s, w, medium);
        float3 next = offset_origin(s.p, s.mag, s.ng, w);
        /* keep the segment's far end fixed while the origin moves past the boundary */
        if (t_max < INFINITY) t_max = fmax(t_max - dot(next - o, w), 0.0f);
        t_back = offset_back(next, s.p, s.ng, w);
        o = next;
    }
    return (float3)(0.0f);
#else
    Hit h;
    *end_medium = medium;
    *last_segment = t_max;
    return bvh_trace_in(sc, root, o, w, t_max, TRACE_ANY, &h) ? (float3)(0.0f) : (float3)(1.0f);
#endif
}

/* The same, where the caller does not need to know in which medium the segment ends. */
VOLCL_STEP_INLINE
inline float3 shadow_transmittance(const SceneData *sc, int root, float3 o, float3 w, float t_max, int medium,
                                   Rng *rng, uint *cutoffs) {
    int end_medium;
    float last_segment;
    return shadow_transmittance_to(sc, root, o, w, t_max, medium, rng, cutoffs, &end_medium, &last_segment);
}

/* The tree a shadow ray from a surface point towards light sample ls is traced in: where the sample
 * is a point of the scene (at a finite distance) the tree without the faces of the scene's convex
 * hull (RenderParams.shadow_root, volcl.hull), which the segment cannot cross; else the scene's. */
inline int surface_shadow_root(const SceneData *sc, const LightSample *ls) {
    return ls->dist < INFINITY ? sc->params->shadow_root : 0;
}

#if VOLCL_HAS_EMISSION_NEE
/* Whether emission NEE runs in this render (kernels/emission_nee.h). */
inline bool emission_nee_active(__global const RenderParams *rp) {
    return rp->emission_nee && rp->emission_table >= 0;
}

/* sigma_a(y) Le(y), the light medium m emits per unit length at y (y inside its grid for grid media). */
inline float3 medium_emission_at(const SceneData *sc, __global const Medium *m, float3 y) {
#if VOLCL_HAS_GRID_MEDIA
    if (m->type == MEDIUM_HETEROGENEOUS) {
        __global const GridVolume *v = &sc->grids[m->sigma_t_grid];
        float3 sigma_t = grid_lookup(sc->grid_data, v, grid_point_to_local(v, y));
        return sigma_t * (1.0f - medium_grid_albedo(sc, m, y)) * medium_grid_radiance(sc, m, y);
    }
#endif
    return vload_f3(m->emission);
}

/* Light emitted at ep->y that reaches vertex x (scattering value f towards wi, sampled there with
 * solid-angle density scatter_pdf), through the shadow ray from `origin` in `medium`, MIS-weighted
 * against the collision estimate (emission_nee.h). The point counts only if the ray ends in the
 * medium it was drawn in (a shape may cut a grid's cube, or hold another medium). */
inline float3 emission_nee_finish(const SceneData *sc, const EmissionPoint *ep, float3 x, float3 wi, float3 f,
                                  float scatter_pdf, float3 origin, int medium, Rng *rng, uint *cutoffs) {
    float3 v = ep->y - x;
    float d2 = dot(v, v);
    float t_max = dot(ep->y - origin, wi);
    if (!(d2 > 0.0f) || !(t_max > 0.0f)) return (float3)(0.0f);
    __global const Medium *m = &sc->media[ep->medium];
    float3 le = medium_emission_at(sc, m, ep->y);
    if (!(max_component(le) > 0.0f)) return (float3)(0.0f);
    int end_medium;
    float last_segment;
    float3 tr = shadow_transmittance_to(sc, 0, origin, wi, t_max, medium, rng, cutoffs, &end_medium, &last_segment);
    if (end_medium != ep->medium || !(max_component(tr) > 0.0f)) return (float3)(0.0f);
    float w = 1.0f;
    if (sc->params->mis) {
        float rate;
#if VOLCL_HAS_GRID_MEDIA
        if (m->type == MEDIUM_HETEROGENEOUS) {
            /* the tracking majorant at y: the cell of the majorant grid holding it (the sampling
             * cells can be finer) */
            __global const GridVolume *g = &sc->grids[m->sigma_t_grid];
            float3 res = convert_float3((int3)(g->maj_res[0], g->maj_res[1], g->maj_res[2]));
            int3 c = convert_int3(fmin(fmax(floor(grid_point_to_local(g, ep->y) * res), 0.0f), res - 1.0f));
            rate = sc->grid_data[g->majorants + (c.z * g->maj_res[1] + c.y) * g->maj_res[0] + c.x]
                   * sc->params->majorant_scale;
        } else
#endif
        rate = medium_landing_density(m, last_segment);
        w = power_heuristic(ep->pdf, scatter_pdf * rate / d2);
    }
    return f * tr * le * (w / (ep->pdf * d2));
}

/* Draw a point of an emissive medium for a vertex (five uniform numbers, drawn whether or not it
 * succeeds); false when the draw landed on no emission. */
inline bool emission_nee_point(const SceneData *sc, Rng *rng, float3 x, EmissionPoint *ep, float3 *wi) {
    float u_medium = rng_next_float(rng), u_cell = rng_next_float(rng);
    float2 u01 = rng_next_float2(rng);
    float3 u = (float3)(u01.x, u01.y, rng_next_float(rng));
    if (!emission_sample_point(sc, sc->params->emission_table, u_medium, u_cell, u, ep)) return false;
    float3 v = ep->y - x;
    float d = length(v);
    if (!(d > 0.0f)) return false;
    *wi = v / d;
    return true;
}
#endif

/* Weight of a light found by BSDF or phase sampling (pdf_scatter) that NEE could also have sampled
 * (pdf_light): the power heuristic with MIS on; with NEE alone such hits are NEE's to count (0);
 * without NEE they are the only estimate (1). */
inline float hit_weight(__global const RenderParams *rp, float pdf_scatter, float pdf_light) {
    if (!rp->nee) return 1.0f;
    if (!rp->mis) return 0.0f;
    return power_heuristic(pdf_scatter, pdf_light);
}

/* Light arriving at a vertex by next-event estimation, already weighted by MIS against `scatter_pdf`.
 * `f` is the vertex's scattering value towards ls.wi (BSDF value * cos, or phase value); `root`
 * the tree its shadow ray is traced in (shadow_transmittance_to). */
VOLCL_STEP_INLINE
inline float3 nee_contribution(const SceneData *sc, int root, const LightSample *ls, float3 f, float scatter_pdf,
                               float3 origin, int medium, Rng *rng, uint *cutoffs) {
    /* stop a hair before the light so the shadow ray never hits the emitter itself */
    float t_max = ls->dist < INFINITY ? ls->dist * 0.9999f : INFINITY;
    float3 tr = shadow_transmittance(sc, root, origin, ls->wi, t_max, medium, rng, cutoffs);
    if (max_component(tr) <= 0.0f) return (float3)(0.0f);
    float w = (ls->delta || !sc->params->mis) ? 1.0f : power_heuristic(ls->pdf, scatter_pdf);
    return f * ls->value * tr * (w / ls->pdf);
}

#if VOLCL_HAS_EQUIANGULAR
/* Point and spot lights in homogeneous media: equiangular sampling (equiangular.h) combined with
 * free-flight distance sampling by multiple importance sampling.
 *
 * On a medium segment o + t d, t in [0, t_seg], that a path with throughput beta enters, the light of
 * point light k scattered once towards the path is
 *     D_k = integral over [0, t_seg] of Tr(t) sigma_s phase(t) Tr_shadow(t) I_k(t) / dist_k(t)^2 dt
 * (I_k(t): the intensity towards o + t d, a spot's falloff included).
 * Two techniques estimate it:
 *   - distance: the path's own free-flight sample t_d, density p_d (media.h; the mixture over colour
 *     channels for chromatic extinction; it lands inside the segment only with probability
 *     1 - Tr(t_seg), which p_d already accounts for), then next-event estimation picking light k;
 *   - equiangular: light k picked as NEE picks lights (the pick probability is the same for both
 *     techniques and cancels from the weights), then t_e with density p_e towards it.
 * Two-sample MIS (EQUIANGULAR_TWO_SAMPLE) keeps one sample of each per segment, weighted by the
 * power heuristic of p_e and p_d at the sample's own distance. One-sample MIS
 * (EQUIANGULAR_ONE_SAMPLE, Cycles' arrangement) picks one technique per segment with probability
 * 1/2 and doubles its power-heuristic weight; the other technique's sample gets weight 0. Either way
 * the expected weights sum to one at every t, so the estimate stays unbiased; where p_e = 0 (outside
 * equiangular.h's clipped interval, or on the light's line) distance sampling has weight 1 on
 * average. With MIS off the equiangular sample alone covers D_k wherever p_e > 0 (weights 1 and 0).
 * The path always continues from the distance sample; the equiangular vertex only sends a shadow
 * ray. Media other than homogeneous keep distance sampling alone (their p_d is not available).
 */

typedef struct {
    int tech;
    float3 o, d, beta;  /* the segment and the throughput entering it */
    float t_seg;
    /* the equiangular interval towards light seg_light (-1: none set up yet; seg_ok: whether it
     * has one), kept for the distance sample's weight, which needs the same one when NEE there
     * picks the same light: set up once, it costs one atan2 per segment instead of two */
    int seg_light;
    bool seg_ok;
    EquiangularSegment seg;
} EquiangularSegmentState;

/* Density of the distance medium_sample_distance (media.h) draws for throughput beta, at t inside
 * the segment; it mirrors that sampler's channel choice. Absolute (not relative to the smallest
 * extinction): MIS compares it with p_e, and where it underflows p_e rightly takes all the weight. */
inline float medium_distance_pdf_tr(__global const Medium *m, float3 beta, float3 tr) {
    float3 sigma_t = vload_f3(m->sigma_t);
#if VOLCL_HAS_CHROMATIC_MEDIA
    float3 p = fmax(beta, 0.0f);
    float total = p.x + p.y + p.z;
    p = total > 0.0f ? p / total : (float3)(1.0f / 3.0f);
    return dot(p, sigma_t * tr);
#else
    return sigma_t.x * tr.x;
#endif
}

/* The same from t; medium_distance_pdf_tr takes the transmittance to t where the caller has it. */
inline float medium_distance_pdf(__global const Medium *m, float3 beta, float t) {
    return medium_distance_pdf_tr(m, beta, transmittance_exp(vload_f3(m->sigma_t), t));
}

/* weight of NEE towards a point light from the distance-sampled vertex at t */
__attribute__((always_inline))
inline float equiangular_distance_weight(const SceneData *sc, const EquiangularSegmentState *es,
                                         __global const Medium *m, const LightSample *ls, float t, float tr) {
    if (es->tech == EQ_NONE || !light_is_point_like(sc->lights[ls->light].type)) return 1.0f;
    if (es->tech == EQ_ONLY_EQUIANGULAR) return 0.0f;
    float pdf_e;
    if (ls->light == es->seg_light)
        pdf_e = es->seg_ok ? equiangular_segment_pdf(&es->seg, t) : 0.0f;
    else
        pdf_e = sample_equiangular_pdf(es->o, es->d, es->t_seg, vload_f3(sc->lights[ls->light].position), t);
    float pdf_d = tr >= 0.0f ? medium_distance_pdf_tr(m, es->beta, (float3)(tr)) : medium_distance_pdf(m, es->beta, t);
    if (es->tech == EQ_ONLY_DISTANCE) return 2.0f * power_heuristic(pdf_d, pdf_e);
    if (!sc->params->mis) return pdf_e > 0.0f ? 0.0f : 1.0f;
    return power_heuristic(pdf_d, pdf_e);
}

/* Decide the techniques for the segment the path is about to cross. */
inline EquiangularSegmentState equiangular_begin(const SceneData *sc, Rng *rng, __global const Medium *m,
                                                 float3 o, float3 d, float t_seg, float3 beta, int depth,
                                                 bool do_nee) {
    __global const RenderParams *rp = sc->params;
    EquiangularSegmentState es;
    es.tech = EQ_NONE;
    es.o = o;
    es.d = d;
    es.beta = beta;
    es.t_seg = t_seg;
    es.seg_light = -1;
    es.seg_ok = false;
    /* the vertex would be depth + 1: the same limit the distance-sampled vertex obeys */
    if (rp->equiangular == EQUIANGULAR_OFF || !do_nee || m->type != MEDIUM_HOMOGENEOUS
        || (rp->max_depth >= 0 && depth + 1 >= rp->max_depth))
        return es;
    es.tech = EQ_BOTH;
    if (rp->equiangular == EQUIANGULAR_ONE_SAMPLE && rp->mis)
        es.tech = rng_next_float(rng) < 0.5f ? EQ_ONLY_EQUIANGULAR : EQ_ONLY_DISTANCE;
    return es;
}

/* The equiangular sample's estimate of D_k for the light it picks, before the factor beta. This, the
 * distance sample's weight and the segment set-up and sampler are always inlined: PoCL left them
 * out of line, passing the segment's state through memory. (The shadow query and phase_sample,
 * forced inline too, made the Nori fog box 5% slower: they have other callers.) */
__attribute__((always_inline))
inline float3 equiangular_direct(const SceneData *sc, Rng *rng, EquiangularSegmentState *es,
                                 __global const Medium *m, int medium, uint *cutoffs) {
    if (es->tech != EQ_BOTH && es->tech != EQ_ONLY_EQUIANGULAR) return (float3)(0.0f);
    int count = sc->params->light_count;
    float u_pick = rng_next_float(rng);
    float u = rng_next_float(rng);
    int li = min((int)(u_pick * (float)count), count - 1);
    __global const Light *l = &sc->lights[li];
    if (!light_is_point_like(l->type)) return (float3)(0.0f);   /* other lights: NEE at the distance sample */
    float3 lp = vload_f3(l->position);
    float t, pdf_e;
    es->seg_light = li;
    es->seg_ok = equiangular_segment(es->o, es->d, es->t_seg, lp, &es->seg);
    if (!es->seg_ok || !equiangular_segment_sample(&es->seg, u, &t, &pdf_e)) return (float3)(0.0f);
    float3 x = es->o + t * es->d;
    float3 v = lp - x;
    float d2 = dot(v, v);
    if (!(d2 > 0.0f)) return (float3)(0.0f);
    float dist = sqrt(d2);
    float3 wi = v / dist;
    float3 sigma_t = vload_f3(m->sigma_t);
    float3 tr = transmittance_exp(sigma_t, t);
    float w = equiangular_weight(es->tech, sc->params->mis, pdf_e, medium_distance_pdf_tr(m, es->beta, tr));
    if (!(w > 0.0f)) return (float3)(0.0f);
    float3 tr_shadow = shadow_transmittance(sc, 0, x, wi, dist * 0.9999f, medium, rng, cutoffs);
    if (max_component(tr_shadow) <= 0.0f) return (float3)(0.0f);
    float3 sigma_s = sigma_t * vload_f3(m->albedo);
    float ph = phase_eval(sc, m, es->d, wi);
    return tr * sigma_s * tr_shadow * light_point_emission(sc, l, -wi) * (ph * w * (float)count / (pdf_e * d2));
}
#endif

/* The state of a path between steps: the radiance gathered and the throughput, the ray traced next
 * (o, d up to t_max, the medium it travels in), and what the vertex behind it leaves for MIS. */
typedef struct {
    float3 L, beta;
    float3 o, d;
    float t_max;
    /* Distance back along d from the origin o, which offset_origin moved off the surface the ray
     * left, to that surface (offset_back). Hazard: the sliver between lies in the medium the ray
     * enters, and skipping it skips sigma_t * 1e-5 * |p| of optical depth: nothing in fog, but at
     * sigma_t = 1e6 in a unit scene ten mean free paths, so light entering a dense medium first
     * scattered far too deep (a half-space of albedo 0.9 reflected 0.002 instead of 0.46). Media
     * are sampled from the surface on; the ray is still traced from the offset origin. */
    float t_back;
    int medium;
    int depth;
    bool specular;      /* last vertex was delta (or the camera): emission hits get no MIS */
    float prev_pdf;     /* solid-angle pdf of the direction sampled at the last vertex */
    float3 prev_p;
    float eta_scale;
    bool do_nee;
#if VOLCL_DEFER_SHADOWS
    /* the vertex's NEE shadow ray, left for the packet renderer to trace with its other lanes'
     * (packets.cl): where nothing blocks it, L += shadow_beta * shadow_value, as path_surface_nee adds */
    bool shadow;
    float3 shadow_o, shadow_d, shadow_beta, shadow_value;
    float shadow_t;
    int shadow_root;
#endif
} PathState;

/* what a step leaves the path to do next */
#define PATH_CONTINUE 0     /* trace the ray in ps->o, ps->d */
#define PATH_END 1
#define PATH_SURFACE 2      /* nothing happened in the medium: the ray reaches the surface it hit, or escapes */
#define PATH_CROSSED 3      /* the ray passed a null boundary: trace on, with no roulette */

/* The ray's segment through its medium: equiangular sampling towards point lights, then a free
 * flight; at a scattering event, next-event estimation against phase sampling and a new
 * direction from the phase function. */
VOLCL_STEP_INLINE
inline int path_medium_event(const SceneData *sc, Rng *rng, PathState *ps, bool hit, const Hit *h, uint *cutoffs) {
#if VOLCL_HAS_MEDIA
    __global const RenderParams *rp = sc->params;
    if (ps->medium < 0) return PATH_SURFACE;
    __global const Medium *m = &sc->media[ps->medium];
    /* the segment starts at the surface the ray left, t_back behind the offset origin */
    float3 seg_o = ps->o - ps->t_back * ps->d;
    float seg_t = (hit ? h->t : ps->t_max) + ps->t_back;
    /* in a sealed medium every shadow ray ends on the surface around it: no NEE (volcl/sealed.py) */
    bool do_nee = ps->do_nee && !m->sealed;
#if VOLCL_HAS_EQUIANGULAR
    EquiangularSegmentState es = equiangular_begin(sc, rng, m, seg_o, ps->d, seg_t, ps->beta, ps->depth, do_nee);
    ps->L += ps->beta * equiangular_direct(sc, rng, &es, m, ps->medium, cutoffs);
#endif
    EmissionMis em;
    em.on = false;
#if VOLCL_HAS_EMISSION_NEE
    em.on = emission_nee_active(rp) && !ps->specular;
    em.x = ps->prev_p;
    em.pdf_dir = ps->prev_pdf;
#endif
    MediumSample ms = medium_sample(sc, m, seg_o, ps->d, seg_t, ps->beta, rng, cutoffs, &em);
#if VOLCL_HAS_EMISSION_NEE
    /* a homogeneous medium's emission comes from the one collision, at ms.t from the segment's start */
    if (m->type == MEDIUM_HOMOGENEOUS && ms.scattered)
        ms.emission *= emission_collision_weight(sc, &em, m, seg_o + ms.t * ps->d, medium_landing_density(m, ms.t));
#endif
#if VOLCL_HAS_EMISSIVE_MEDIA
    ps->L += ps->beta * ms.emission;
#endif
    ps->beta *= ms.weight;
#if VOLCL_HAS_GRID_MEDIA
    /* null collisions left no weight, or tracking was cut off (counted): nothing more to carry */
    if (!ms.scattered && max_component(ps->beta) <= 0.0f) return PATH_END;
#endif
    if (!ms.scattered) return PATH_SURFACE;
    float3 p = ps->o + (ms.t - ps->t_back) * ps->d;
    if (rp->max_depth >= 0 && ps->depth + 1 >= rp->max_depth) return PATH_END;
    if (max_component(ps->beta) <= 0.0f) return PATH_END;
    /* next-event estimation, MIS against phase sampling */
    if (do_nee) {
        LightSample ls;
        float u_pick = rng_next_float(rng);
        float2 ul = rng_next_float2(rng);
        if (light_sample(sc, p, u_pick, ul, &ls) && max_component(ls.value) > 0.0f) {
            /* the phase value in the estimate, the phase sampler's pdf in the MIS weight */
            /* the equiangular combination's weight first: where it is 0 (one-sample MIS chose the
             * equiangular sample for this segment) the shadow ray would be traced for nothing */
            float w_eq = 1.0f;
#if VOLCL_HAS_EQUIANGULAR
            w_eq = equiangular_distance_weight(sc, &es, m, &ls, ms.t, ms.tr);
#endif
            if (w_eq > 0.0f) {
                float ph_pdf;
                float ph = phase_eval_pdf(sc, m, ps->d, ls.wi, &ph_pdf);
                ps->L += ps->beta * (w_eq * nee_contribution(sc, 0, &ls, (float3)(ph), ph_pdf, p, ps->medium, rng, cutoffs));
            }
        }
    }
#if VOLCL_HAS_EMISSION_NEE
    if (emission_nee_active(rp)) {
        EmissionPoint ep;
        float3 wi;
        if (emission_nee_point(sc, rng, p, &ep, &wi)) {
            float ph_pdf;
            float ph = phase_eval_pdf(sc, m, ps->d, wi, &ph_pdf);
            ps->L += ps->beta * emission_nee_finish(sc, &ep, p, wi, (float3)(ph), ph_pdf, p, ps->medium, rng, cutoffs);
        }
    }
#endif
    float3 nd;
    float ph_weight;    /* value / pdf: 1 for every phase sampled exactly */
    ps->prev_pdf = phase_sample(sc, m, ps->d, rng_next_float2(rng), rng, &nd, &ph_weight);
    ps->beta *= ph_weight;
    ps->specular = false;
    ps->prev_p = p;
    ps->o = p;
    ps->d = nd;
    ps->t_max = INFINITY;
    ps->t_back = 0.0f;
    ++ps->depth;
    return PATH_CONTINUE;
#else
    return PATH_SURFACE;
#endif
}

/* The ray left the scene: the environment's light, weighted by MIS against light sampling. */
VOLCL_STEP_INLINE
inline void path_escape(const SceneData *sc, PathState *ps) {
#if VOLCL_HAS_ENV_LIGHTS
    __global const RenderParams *rp = sc->params;
    if (rp->env_light >= 0 && !(rp->hide_emitters && ps->depth == 0)) {
        float pdf_light;
        float3 le = light_env_emission(sc, ps->d, &pdf_light);
        float w = ps->specular ? 1.0f : hit_weight(rp, ps->prev_pdf, pdf_light);
        ps->L += ps->beta * le * w;
    }
#endif
}

/* A bare (null) boundary: the ray goes on unchanged, possibly into another medium. */
VOLCL_STEP_INLINE
inline void path_null_crossing(const SceneData *sc, PathState *ps, const SurfacePoint *s) {
    ps->medium = medium_after(sc, s, ps->d, ps->medium);
    float3 next = offset_origin(s->p, s->mag, s->ng, ps->d);
    if (ps->t_max < INFINITY) ps->t_max = fmax(ps->t_max - dot(next - ps->o, ps->d), 0.0f);
    ps->t_back = offset_back(next, s->p, s->ng, ps->d);
    ps->o = next;
}

#if VOLCL_DEFER_SHADOWS
#if VOLCL_HAS_MEDIA || VOLCL_HAS_NULL_BSDF || VOLCL_HAS_MASK || VOLCL_HAS_THINDIELECTRIC || VOLCL_HAS_EMISSION_NEE
#error "deferred shadow rays are occlusion queries: every surface opaque, no media"
#endif
/* nee_contribution with the shadow ray left untraced: its ray, and what it adds where nothing
 * blocks it (the transmittance is then exactly 1, so the value has nee_contribution's bits). */
inline void nee_defer(const SceneData *sc, PathState *ps, const LightSample *ls, float3 f, float scatter_pdf,
                      float3 origin) {
    float w = (ls->delta || !sc->params->mis) ? 1.0f : power_heuristic(ls->pdf, scatter_pdf);
    ps->shadow = true;
    ps->shadow_o = origin;
    ps->shadow_d = ls->wi;
    ps->shadow_t = ls->dist < INFINITY ? ls->dist * 0.9999f : INFINITY;
    ps->shadow_root = surface_shadow_root(sc, ls);
    ps->shadow_beta = ps->beta;
    ps->shadow_value = f * ls->value * (w / ls->pdf);
}
#endif

/* Next-event estimation at a surface vertex, MIS against BSDF sampling. Delta BSDFs draw the same
 * random numbers without using them, so the sequence stays aligned whatever the vertex type. */
VOLCL_STEP_INLINE
inline void path_surface_nee(const SceneData *sc, Rng *rng, PathState *ps, const SurfacePoint *s,
                             const BsdfVertex *bsdf, float3 wo, bool delta, uint *cutoffs) {
    if (ps->do_nee && !delta) {
        LightSample ls;
        float u_pick = rng_next_float(rng);
        float2 ul = rng_next_float2(rng);
        if (light_sample(sc, s->p, u_pick, ul, &ls) && max_component(ls.value) > 0.0f) {
            float pdf;
            float3 f = bsdf_eval(bsdf, wo, ls.wi, &pdf);
            if (max_component(f) > 0.0f) {
#if VOLCL_DEFER_SHADOWS
                nee_defer(sc, ps, &ls, f, pdf, offset_origin(s->p, s->mag, s->ng, ls.wi));
#else
                ps->L += ps->beta * nee_contribution(sc, surface_shadow_root(sc, &ls), &ls, f, pdf,
                                                     offset_origin(s->p, s->mag, s->ng, ls.wi),
                                                     medium_after(sc, s, ls.wi, ps->medium), rng, cutoffs);
#endif
            }
        }
    } else {
        rng_next_float(rng);
        rng_next_float2(rng);
    }
#if VOLCL_HAS_EMISSION_NEE
    if (!delta && emission_nee_active(sc->params)) {
        EmissionPoint ep;
        float3 wi;
        if (emission_nee_point(sc, rng, s->p, &ep, &wi)) {
            float pdf;
            float3 f = bsdf_eval(bsdf, wo, wi, &pdf);
            if (max_component(f) > 0.0f)
                ps->L += ps->beta * emission_nee_finish(sc, &ep, s->p, wi, f, pdf,
                                                        offset_origin(s->p, s->mag, s->ng, wi),
                                                        medium_after(sc, s, wi, ps->medium), rng, cutoffs);
        }
    }
#endif
}

/* The ray reached a surface (or escaped): emission found by the last sampled direction, then a
 * null crossing, or a scattering vertex with next-event estimation and a BSDF-sampled direction. */
VOLCL_STEP_INLINE
inline int path_surface_event(const SceneData *sc, Rng *rng, PathState *ps, bool hit, const Hit *h, uint *cutoffs) {
    __global const RenderParams *rp = sc->params;
    if (!hit) {
        path_escape(sc, ps);
        return PATH_END;
    }
    SurfacePoint s = surface_point(sc, h, ps->o, ps->d);
    __global const ShapeInfo *shape = &sc->shapes[s.shape];
    float3 wo_world = -ps->d;
    if (rp->hide_emitters == HIDE_EMITTERS_SKIP && ps->depth == 0 && shape->light >= 0) {
        /* Mitsuba's path and volpath: camera rays pass through area emitters, in the same medium */
        int medium = ps->medium;
        path_null_crossing(sc, ps, &s);
        ps->medium = medium;
        return PATH_CROSSED;
    }
#if VOLCL_HAS_AREA_LIGHTS
    if (shape->light >= 0 && !(rp->hide_emitters && ps->depth == 0)) {
        float3 le = light_area_emission(&sc->lights[shape->light], s.ns, wo_world);
        if (max_component(le) > 0.0f) {
            float w = ps->specular ? 1.0f
                                   : hit_weight(rp, ps->prev_pdf,
                                                light_area_pdf(sc, shape->light, ps->prev_p, s.p, s.ng));
            ps->L += ps->beta * le * w;
        }
    }
#endif
    __global const Bsdf *bsdf = &sc->bsdfs[shape->bsdf];
#if VOLCL_HAS_NULL_BSDF
    if (bsdf->type == BSDF_NULL) {
        path_null_crossing(sc, ps, &s);
        return PATH_CROSSED;
    }
#endif
    /* at the depth limit a path still passes through masks and panes: Mitsuba's null events are
     * no bounce */
    bool at_limit = rp->max_depth >= 0 && ps->depth + 1 >= rp->max_depth;
    if (at_limit && !(bsdf->flags & BSDF_FLAG_PASSES)) return PATH_END;

    BsdfVertex bv = bsdf_vertex_at(sc, h, shape->bsdf, &s, wo_world);
    bool delta = !bsdf_vertex_smooth(&bv);
    if (!at_limit) path_surface_nee(sc, rng, ps, &s, &bv, wo_world, delta, cutoffs);
    if (rp->specular_chains_only && !delta) return PATH_END;

    BsdfSample bs;
    float u1 = rng_next_float(rng);
    if (!bsdf_sample(&bv, wo_world, u1, rng_next_float2(rng), &bs)) return PATH_END;
    if (bs.null_event) {
        ps->beta *= bs.weight;
        path_null_crossing(sc, ps, &s);
        return PATH_CROSSED;
    }
    if (at_limit) return PATH_END;
    /* As in Mitsuba, a direction that a shading normal sends to the other side of the geometric
     * surface than its own hemisphere is followed there: the medium and the ray's offset follow the
     * side it leaves on (geometric normal); ending such paths darkened dielectric boundaries by up
     * to 2% at grazing angles against Mitsuba. */
    float3 wi = bs.wi;
    ps->beta *= bs.weight;
    ps->eta_scale *= bs.eta * bs.eta;
    ps->specular = bs.delta;
    ps->prev_pdf = bs.pdf;
    ps->prev_p = s.p;
    ps->medium = medium_after(sc, &s, wi, ps->medium);
    ps->o = offset_origin(s.p, s.mag, s.ng, wi);
    ps->t_back = offset_back(ps->o, s.p, s.ng, wi);
    ps->d = wi;
    ps->t_max = INFINITY;
    ++ps->depth;
    return PATH_CONTINUE;
}

/* Russian roulette from rr_depth on: survival follows the throughput (undoing refraction's
 * 1/eta^2), capped so paths end even when the albedo is exactly 1. False: the path ends. */
VOLCL_STEP_INLINE
inline bool path_roulette(const SceneData *sc, Rng *rng, PathState *ps) {
    if (max_component(ps->beta) <= 0.0f) return false;
    if (ps->depth >= sc->params->rr_depth) {
        float q = fmin(max_component(ps->beta) * ps->eta_scale, 0.95f);
        if (rng_next_float(rng) >= q) return false;
        ps->beta /= q;
    }
    return true;
}

/* The state of a path that starts with the camera ray o + t d, t < t_max. */
VOLCL_STEP_INLINE
inline PathState path_start(const SceneData *sc, float3 o, float3 d, float t_max) {
    __global const RenderParams *rp = sc->params;
    PathState ps;
    ps.L = (float3)(0.0f);
    ps.beta = (float3)(1.0f);
    ps.depth = 0;
    ps.medium = camera_start_medium(sc, &o, d, &t_max, rp->camera_medium);
    ps.o = o;
    ps.d = d;
    ps.t_max = t_max;
    ps.specular = true;
    ps.prev_pdf = 0.0f;
    ps.prev_p = o;
    ps.eta_scale = 1.0f;
    ps.do_nee = rp->light_count > 0 && rp->nee;
    ps.t_back = 0.0f;
#if VOLCL_DEFER_SHADOWS
    ps.shadow = false;
#endif
    return ps;
}

/* Radiance arriving at o from direction -d. *cutoffs counts segments whose tracking hit its bound.
 * Each step traces the ray, lets the medium act on its segment (path_medium_event) and, where the
 * ray gets through, the surface it reaches (path_surface_event). */
VOLCL_STEP_INLINE
inline float3 integrator_radiance(const SceneData *sc, Rng *rng, float3 o, float3 d, float t_max, uint *cutoffs) {
    PathState ps = path_start(sc, o, d, t_max);
    for (int step = 0; step < VOLCL_MAX_STEPS; ++step) {
        Hit h;
        bool hit = bvh_trace(sc, ps.o, ps.d, ps.t_max, TRACE_CLOSEST, &h);
        int next = path_medium_event(sc, rng, &ps, hit, &h, cutoffs);
        if (next == PATH_SURFACE) next = path_surface_event(sc, rng, &ps, hit, &h, cutoffs);
        if (next == PATH_END) break;
        if (next == PATH_CROSSED) continue;
        if (!path_roulette(sc, rng, &ps)) break;
    }
    return ps.L;
}

#endif
