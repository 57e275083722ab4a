/* Mitsuba's direct integrator (src/integrators/direct.cpp): light reaching the first surface a camera
 * ray hits, from emitter_samples light samples and bsdf_samples BSDF samples combined by the power
 * heuristic on their sample-count-weighted pdfs, plus emitters seen directly. Surfaces only (the host
 * refuses media and null boundaries with it, as Mitsuba would not render them).
 *
 * Mitsuba's weights, bugs included: a light sample of a smooth BSDF towards an area or environment
 * light counts w(E p_light, B p_bsdf) / E; one towards a delta light (point, directional) counts
 * fully, not divided by E, so E > 1 multiplies point and directional light by E (the host warns);
 * light sampling is skipped at delta BSDFs. A BSDF sample that hits an emitter counts
 * w(B p_bsdf, E p_light) / B, with p_light = 0 for a delta BSDF lobe. hide_emitters: camera rays pass
 * through area emitters and do not see the environment. */
#ifndef VOLCL_DIRECT_H
#define VOLCL_DIRECT_H

#if VOLCL_HAS_DIRECT
/* Emission arriving along -d from the surface hit h (or from the environment when !hit), and the
 * pdf with which light sampling from ref would have picked that point. */
inline float3 direct_emission(const SceneData *sc, bool hit, const Hit *h, float3 o, float3 d, float3 ref,
                              float *pdf_light) {
    *pdf_light = 0.0f;
    if (!hit) {
#if VOLCL_HAS_ENV_LIGHTS
        if (sc->params->env_light >= 0) return light_env_emission(sc, d, pdf_light);
#endif
        return (float3)(0.0f);
    }
#if VOLCL_HAS_AREA_LIGHTS
    SurfacePoint s = surface_point(sc, h, o, d);
    int li = sc->shapes[s.shape].light;
    if (li >= 0) {
        *pdf_light = light_area_pdf(sc, li, ref, s.p, s.ng);
        return light_area_emission(&sc->lights[li], s.ns, -d);
    }
#endif
    return (float3)(0.0f);
}

inline float3 direct_radiance(const SceneData *sc, Rng *rng, float3 o, float3 d, float t_max) {
    __global const RenderParams *rp = sc->params;
    Hit h;
    bool hit = bvh_trace(sc, o, d, t_max, TRACE_CLOSEST, &h);
    /* hide_emitters: pass through area emitters (bounded like shadow rays' boundary crossings) */
    for (int i = 0; hit && rp->hide_emitters && i < VOLCL_MAX_CROSSINGS; ++i) {
        SurfacePoint s = surface_point(sc, &h, o, d);
        if (sc->shapes[s.shape].light < 0) break;
        float3 next = offset_origin(s.p, s.mag, s.ng, d);
        if (t_max < INFINITY) t_max = fmax(t_max - dot(next - o, d), 0.0f);
        o = next;
        hit = bvh_trace(sc, o, d, t_max, TRACE_CLOSEST, &h);
    }
    float3 L = (float3)(0.0f);
    if (!rp->hide_emitters) {
        float unused;
        L += direct_emission(sc, hit, &h, o, d, o, &unused);
    }
    if (!hit) return L;

    SurfacePoint s = surface_point(sc, &h, o, d);
    BsdfVertex bsdf = bsdf_vertex_at(sc, &h, sc->shapes[s.shape].bsdf, &s, -d);
    float n_e = (float)rp->emitter_samples, n_b = (float)rp->bsdf_samples;
    float frac_e = n_e / (n_e + n_b), frac_b = n_b / (n_e + n_b);
    if (bsdf_vertex_smooth(&bsdf) && rp->light_count > 0) {
        for (int i = 0; i < rp->emitter_samples; ++i) {
            LightSample ls;
            float u_pick = rng_next_float(rng);
            float2 ul = rng_next_float2(rng);
            if (!light_sample(sc, s.p, u_pick, ul, &ls) || !(max_component(ls.value) > 0.0f)) continue;
            float pdf_b;
            float3 f = bsdf_eval(&bsdf, -d, ls.wi, &pdf_b);
            if (!(max_component(f) > 0.0f)) continue;
            /* Mitsuba's direct integrator tests visibility: every surface blocks, masks included */
            float t = ls.dist < INFINITY ? ls.dist * 0.9999f : INFINITY;
            Hit blocker;
            if (bvh_trace_in(sc, surface_shadow_root(sc, &ls), offset_origin(s.p, s.mag, s.ng, ls.wi), ls.wi, t,
                             TRACE_ANY, &blocker))
                continue;
            float w = ls.delta ? 1.0f : power_heuristic(ls.pdf * frac_e, pdf_b * frac_b) / n_e;
            L += f * ls.value * (w / ls.pdf);
        }
    }
    for (int i = 0; i < rp->bsdf_samples; ++i) {
        BsdfSample bs;
        float u1 = rng_next_float(rng);
        if (!bsdf_sample(&bsdf, -d, u1, rng_next_float2(rng), &bs)) continue;
        float3 wi = bs.wi;
        float3 origin = offset_origin(s.p, s.mag, s.ng, wi);
        Hit h2;
        bool hit2 = bvh_trace(sc, origin, wi, INFINITY, TRACE_CLOSEST, &h2);
        float pdf_l;
        float3 le = direct_emission(sc, hit2, &h2, origin, wi, s.p, &pdf_l);
        if (!(max_component(le) > 0.0f)) continue;
        float w = power_heuristic(bs.pdf * frac_b, bs.delta ? 0.0f : pdf_l * frac_e);
        L += bs.weight * le * (w / n_b);
    }
    return L;
}
#endif

#endif
