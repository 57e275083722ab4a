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
inline int camera_start_medium(const SceneData *sc, float3 *o, float3 d, float *t_max, int medium) {
#if VOLCL_HAS_MEDIUM_BOUNDARIES
    __global const RenderParams *rp = sc->params;
    float3 pinhole = (float3)(rp->cam_to_world[3], rp->cam_to_world[7], rp->cam_to_world[11]);
    /* behind by more than the spheres' self-intersection margin and triangle rounding, at any scale */
    float back = 1e-5f * (max_component(fabs(pinhole)) + rp->scene_radius);
    float3 p = pinhole - back * d;
    float reach = dot(*o - p, d);
    for (int i = 0; i < VOLCL_MAX_CROSSINGS && reach > 0.0f; ++i) {
        Hit h;
        if (!bvh_trace(sc, p, d, reach, false, &h)) break;
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
 * are counted in *cutoffs). */
inline float3 shadow_transmittance(const SceneData *sc, float3 o, float3 w, float t_max, int medium, Rng *rng,
                                   uint *cutoffs) {
#if VOLCL_HAS_MEDIA || VOLCL_HAS_NULL_BSDF
    float3 tr = (float3)(1.0f);
    float t_back = 0.0f;    /* from the boundary just crossed to the offset origin: see integrator_radiance */
    for (int i = 0; i < VOLCL_MAX_CROSSINGS; ++i) {
        Hit h;
        bool hit = bvh_trace(sc, o, w, t_max, false, &h);
        float seg = (hit ? h.t : t_max) + t_back;
#if VOLCL_HAS_MEDIA
        if (medium >= 0) tr = medium_attenuate(sc, &sc->media[medium], o - t_back * w, w, seg, tr, rng, cutoffs);
#endif
        if (!hit) return tr;
        SurfacePoint s = surface_point(sc, &h, o, w);
        if (sc->bsdfs[sc->shapes[s.shape].bsdf].type != BSDF_NULL) return (float3)(0.0f);
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
    return bvh_trace(sc, o, w, t_max, true, &h) ? (float3)(0.0f) : (float3)(1.0f);
#endif
}

/* Weight of a light found by BSDF or phase sampling (pdf_scatter) that NEE could also have sampled
 * (pdf_light): the power heuristic with MIS on; with NEE alone such hits are NEE's to count (0);
 * without NEE they are the only estimate (1). */
inline float hit_weight(__global const RenderParams *rp, float pdf_scatter, float pdf_light) {
    if (!rp->nee) return 1.0f;
    if (!rp->mis) return 0.0f;
    return power_heuristic(pdf_scatter, pdf_light);
}

/* Light arriving at a vertex by next-event estimation, already weighted by MIS against `scatter_pdf`.
 * `f` is the vertex's scattering value towards ls.wi (BSDF value * cos, or phase value). */
inline float3 nee_contribution(const SceneData *sc, const LightSample *ls, float3 f, float scatter_pdf,
                               float3 origin, int medium, Rng *rng, uint *cutoffs) {
    /* stop a hair before the light so the shadow ray never hits the emitter itself */
    float t_max = ls->dist < INFINITY ? ls->dist * 0.9999f : INFINITY;
    float3 tr = shadow_transmittance(sc, origin, ls->wi, t_max, medium, rng, cutoffs);
    if (max_component(tr) <= 0.0f) return (float3)(0.0f);
    float w = (ls->delta || !sc->params->mis) ? 1.0f : power_heuristic(ls->pdf, scatter_pdf);
    return f * ls->value * tr * (w / ls->pdf);
}

/* Radiance arriving at o from direction -d. *cutoffs counts segments whose tracking hit its bound. */
inline float3 integrator_radiance(const SceneData *sc, Rng *rng, float3 o, float3 d, float t_max, uint *cutoffs) {
    __global const RenderParams *rp = sc->params;
    float3 L = (float3)(0.0f), beta = (float3)(1.0f);
    int depth = 0;
    int medium = camera_start_medium(sc, &o, d, &t_max, rp->camera_medium);
    bool specular = true;       /* last vertex was delta (or the camera): emission hits get no MIS */
    float prev_pdf = 0.0f;      /* solid-angle pdf of the direction sampled at the last vertex */
    float3 prev_p = o;
    float eta_scale = 1.0f;
    bool do_nee = rp->light_count > 0 && rp->nee;
    /* Distance back along d from the origin o, which offset_origin moved off the surface the ray
     * left, to that surface (offset_back). Hazard: the sliver between lies in the medium the ray
     * enters, and skipping it skips sigma_t * 1e-5 * |p| of optical depth: nothing in fog, but at
     * sigma_t = 1e6 in a unit scene ten mean free paths, so light entering a dense medium first
     * scattered far too deep (a half-space of albedo 0.9 reflected 0.002 instead of 0.46). Media
     * are sampled from the surface on; the ray is still traced from the offset origin. */
    float t_back = 0.0f;

    for (int step = 0; step < VOLCL_MAX_STEPS; ++step) {
        Hit h;
        bool hit = bvh_trace(sc, o, d, t_max, false, &h);
        bool medium_vertex = false;

#if VOLCL_HAS_MEDIA
        if (medium >= 0) {
            __global const Medium *m = &sc->media[medium];
            /* the segment starts at the surface the ray left, t_back behind the offset origin */
            MediumSample ms = medium_sample(sc, m, o - t_back * d, d, (hit ? h.t : t_max) + t_back, beta, rng,
                                            cutoffs);
#if VOLCL_HAS_EMISSIVE_MEDIA
            L += beta * ms.emission;
#endif
            beta *= ms.weight;
#if VOLCL_HAS_GRID_MEDIA
            /* null collisions left no weight, or tracking was cut off (counted): nothing more to carry */
            if (!ms.scattered && max_component(beta) <= 0.0f) break;
#endif
            if (ms.scattered) {
                float3 p = o + (ms.t - t_back) * d;
                if (rp->max_depth >= 0 && depth + 1 >= rp->max_depth) break;
                if (max_component(beta) <= 0.0f) break;
                /* next-event estimation, MIS against phase sampling */
                if (do_nee) {
                    LightSample ls;
                    float u_pick = rng_next_float(rng);
                    float2 ul = rng_next_float2(rng);
                    if (light_sample(sc, p, u_pick, ul, &ls) && max_component(ls.value) > 0.0f) {
                        float ph = phase_eval(m, d, ls.wi);
                        L += beta * nee_contribution(sc, &ls, (float3)(ph), ph, p, medium, rng, cutoffs);
                    }
                }
                float3 nd;
                prev_pdf = phase_sample(m, d, rng_next_float2(rng), &nd);
                specular = false;
                prev_p = p;
                o = p;
                d = nd;
                t_max = INFINITY;
                t_back = 0.0f;
                ++depth;
                medium_vertex = true;
            }
        }
#endif
        if (!medium_vertex) {
        if (!hit) {
#if VOLCL_HAS_ENV_LIGHTS
            if (rp->env_light >= 0 && !(rp->hide_emitters && depth == 0)) {
                float w = specular ? 1.0f : hit_weight(rp, prev_pdf, light_env_pdf(sc));
                L += beta * vload_f3(sc->lights[rp->env_light].value) * w;
            }
#endif
            break;
        }
        {
            SurfacePoint s = surface_point(sc, &h, o, d);
            __global const ShapeInfo *shape = &sc->shapes[s.shape];
            float3 wo_world = -d;
#if VOLCL_HAS_AREA_LIGHTS
            if (shape->light >= 0 && !(rp->hide_emitters && depth == 0)) {
                float3 le = light_area_emission(&sc->lights[shape->light], s.ns, wo_world);
                if (max_component(le) > 0.0f) {
                    float w = specular ? 1.0f
                                       : hit_weight(rp, prev_pdf, light_area_pdf(sc, shape->light, prev_p, s.p, s.ng));
                    L += beta * le * w;
                }
            }
#endif
            __global const Bsdf *bsdf = &sc->bsdfs[shape->bsdf];
#if VOLCL_HAS_NULL_BSDF
            if (bsdf->type == BSDF_NULL) {
                /* a bare boundary: the ray goes on unchanged, possibly into another medium */
                medium = medium_after(sc, &s, d, medium);
                float3 next = offset_origin(s.p, s.mag, s.ng, d);
                if (t_max < INFINITY) t_max = fmax(t_max - dot(next - o, d), 0.0f);
                t_back = offset_back(next, s.p, s.ng, d);
                o = next;
                continue;
            }
#endif
            if (rp->max_depth >= 0 && depth + 1 >= rp->max_depth) break;

            float3 ss, ts;
            make_frame(s.ns, &ss, &ts);
            float3 wo = frame_to_local(wo_world, ss, ts, s.ns);
            bool delta = bsdf_is_delta(bsdf);

            if (do_nee && !delta) {
                LightSample ls;
                float u_pick = rng_next_float(rng);
                float2 ul = rng_next_float2(rng);
                if (light_sample(sc, s.p, u_pick, ul, &ls) && max_component(ls.value) > 0.0f) {
                    float pdf;
                    float3 f = bsdf_eval(bsdf, wo, frame_to_local(ls.wi, ss, ts, s.ns), &pdf);
                    if (max_component(f) > 0.0f) {
                        L += beta * nee_contribution(sc, &ls, f, pdf, offset_origin(s.p, s.mag, s.ng, ls.wi),
                                                     medium_after(sc, &s, ls.wi, medium), rng, cutoffs);
                    }
                }
            } else {
                /* keep the random-number sequence aligned whatever the vertex type */
                rng_next_float(rng);
                rng_next_float2(rng);
            }
            if (rp->specular_chains_only && !delta) break;

            BsdfSample bs;
            float u1 = rng_next_float(rng);
            if (!bsdf_sample(bsdf, wo, u1, rng_next_float2(rng), &bs)) break;
            float3 wi = frame_to_world(bs.wi, ss, ts, s.ns);
            /* a shading normal can send the sampled direction below the geometric surface; the ray
             * would then start on the wrong side, so such a path ends */
            if (dot(wi, s.ng) * dot(bs.wi.z >= 0.0f ? s.ns : -s.ns, s.ng) < 0.0f) break;
            beta *= bs.weight;
            eta_scale *= bs.eta * bs.eta;
            specular = bs.delta;
            prev_pdf = bs.pdf;
            prev_p = s.p;
            medium = medium_after(sc, &s, wi, medium);
            o = offset_origin(s.p, s.mag, s.ng, wi);
            t_back = offset_back(o, s.p, s.ng, wi);
            d = wi;
            t_max = INFINITY;
            ++depth;
        }
        }
        if (max_component(beta) <= 0.0f) break;
        if (depth >= rp->rr_depth) {
            /* survival follows the throughput (undoing refraction's 1/eta^2), capped so paths end even
             * when the albedo is exactly 1 */
            float q = fmin(max_component(beta) * eta_scale, 0.95f);
            if (rng_next_float(rng) >= q) break;
            beta /= q;
        }
    }
    return L;
}

#endif
