/* The bsdf at a surface point (a BsdfVertex, bsdf.h): wrappers resolved outside in, textures
 * evaluated, the shading frame chosen; and the world-space eval and sample the integrators call.
 *
 * Mitsuba's wrappers, as frame changes and factors:
 *  - twosided (any record's flag): on the back side the bsdf sees its frame with the normal negated,
 *    which mirrors both directions about the tangent plane, as Mitsuba's flip of wi.z does;
 *  - mask: opaque with probability `opacity` (the product over nested masks); else the path passes
 *    straight through (a null event, no vertex, like Mitsuba's Null lobe), and eval and pdf scale
 *    by the opacity;
 *  - bump and normal maps: the frame the wrapped bsdf sees is tilted; directions on different sides
 *    of the two frames scatter nothing, and Estevez et al.'s shadowing term attenuates the result
 *    (src/bsdfs/bumpmap.cpp, normalmap.cpp, normalmap_helpers.h).
 * The frame is Mitsuba's (tangent along dp/du) where the bsdf needs it (BSDF_FLAG_UV_FRAME:
 * anisotropic roughness, bump and normal maps), otherwise any frame around the shading normal.
 */
#ifndef VOLCL_BSDF_VERTEX_H
#define VOLCL_BSDF_VERTEX_H

/* wrappers deeper than this are not followed (the host never builds such chains) */
#define VOLCL_MAX_BSDF_NESTING 8

#if VOLCL_NEEDS_UV
/* Mitsuba's shading frame: s along dp/du projected onto the tangent plane, t = n x s */
inline void uv_frame(const SurfacePoint *s, float3 *ss, float3 *ts) {
    float3 u = s->dpdu - s->ns * dot(s->ns, s->dpdu);
    float l2 = dot(u, u);
    if (l2 > 0.0f && isfinite(l2)) {
        *ss = u * rsqrt(l2);
        *ts = cross(s->ns, *ss);
    } else {
        make_frame(s->ns, ss, ts);
    }
}
#endif

#if VOLCL_HAS_BUMP_MAPS
/* Tilt the vertex's frame by bump or normal map record b. (so, to, no): the surface's own shading
 * frame, which Mitsuba's bumpmap measures the tilted normal in; wo_w: towards the viewer. */
inline void bsdf_tilt(const SceneData *sc, __global const Bsdf *b, const SurfacePoint *s, float3 wo_w,
                      float3 so, float3 to, float3 no, BsdfVertex *v) {
    float3 nl;
    if (b->type == BSDF_BUMPMAP) {
        float2 g = b->scale * texture_grad1(sc, b->map_tex, s->uv);
        float3 du = s->dpdu + no * (g.x - dot(no, s->dpdu));
        float3 dv = s->dpdv + no * (g.y - dot(no, s->dpdv));
        float3 nw = normalize(cross(du, dv));
        if (dot(s->ng, nw) < 0.0f) nw = -nw;
        nl = frame_to_local(nw, so, to, no);
    } else {
        nl = 2.0f * texture_eval3(sc, b->map_tex, (float3)(0.5f, 0.5f, 1.0f), s->uv) - 1.0f;
    }
    /* seen from wo in the frame as it is (a twosided flip included) */
    float3 wo = frame_to_local(wo_w, v->s, v->t, v->n);
    if ((b->flags & BSDF_FLAG_FLIP_INVALID) && wo.z * dot(wo, nl) <= 0.0f) nl = (float3)(-nl.x, -nl.y, nl.z);
    nl = normalize(nl);
    float3 sl;
    if (b->type == BSDF_BUMPMAP) {
        /* Mitsuba projects the world-space dp/du onto the local normal here: a frame rotated about
         * the normal, which only anisotropic bsdfs notice; kept as Mitsuba renders it */
        sl = normalize(s->dpdu - nl * dot(nl, s->dpdu));
    } else {
        sl = normalize((float3)(1.0f, 0.0f, 0.0f) - nl * nl.x);
    }
    float3 tl = cross(nl, sl);
    v->bumped = true;
    v->shadowing = (b->flags & BSDF_FLAG_SHADOWING) != 0;
    v->n_in = v->n;
    v->tan2_tilt = fmax(1.0f - nl.z * nl.z, 0.0f) / (nl.z * nl.z);
    float3 ns = frame_to_world(sl, v->s, v->t, v->n);
    float3 nt = frame_to_world(tl, v->s, v->t, v->n);
    float3 nn = frame_to_world(nl, v->s, v->t, v->n);
    v->s = ns;
    v->t = nt;
    v->n = nn;
}
#endif

/* The bsdf of record `index` at surface point s of hit h, seen from wo_w (towards the viewer).
 * Computes s's texture coordinates where the bsdf reads them. Forced inline only in optimized
 * builds: forcing it at -O0 makes LLVM 14 mark the returned struct with
 * llvm.experimental.noalias.scope.decl, which Oclgrind cannot run. */
#ifdef __OPTIMIZE__
__attribute__((always_inline))
#endif
inline BsdfVertex bsdf_vertex_at(const SceneData *sc, const Hit *h, int index, SurfacePoint *s, float3 wo_w) {
    BsdfVertex v;
    __global const Bsdf *b = &sc->bsdfs[index];
    v.opacity = 1.0f;
    v.bumped = false;
    v.shadowing = false;
    v.n_in = s->ns;
    v.tan2_tilt = 0.0f;
    v.n = s->ns;
#if VOLCL_NEEDS_UV
    if (b->flags & BSDF_FLAG_UV) {
        surface_texcoords(sc, h, s);
    } else {
        s->uv = (float2)(0.0f);
        s->dpdu = s->dpdv = (float3)(0.0f);
    }
    if (b->flags & BSDF_FLAG_UV_FRAME) uv_frame(s, &v.s, &v.t);
    else
#endif
    make_frame(s->ns, &v.s, &v.t);
#if VOLCL_HAS_MASK || VOLCL_HAS_BUMP_MAPS
    float3 so = v.s, to = v.t, no = v.n;
    for (int depth = 0; depth < VOLCL_MAX_BSDF_NESTING; ++depth) {
        if (b->twosided && dot(wo_w, v.n) < 0.0f) v.n = -v.n;
#if VOLCL_HAS_MASK
        if (b->type == BSDF_MASK) {
            v.opacity *= clamp(texture_eval1(sc, b->opacity_tex, b->opacity, s->uv), 0.0f, 1.0f);
            b = &sc->bsdfs[b->nested];
            continue;
        }
#endif
#if VOLCL_HAS_BUMP_MAPS
        if (b->type == BSDF_BUMPMAP || b->type == BSDF_NORMALMAP) {
            bsdf_tilt(sc, b, s, wo_w, so, to, no, &v);
            b = &sc->bsdfs[b->nested];
            continue;
        }
#endif
        break;
    }
#else
    if (b->twosided && dot(wo_w, v.n) < 0.0f) v.n = -v.n;
#endif
    v.b = b;
    float2 uv = s->uv;
    v.color = texture_eval3(sc, b->color_tex, vload_f3(b->color), uv);
    v.eta3 = texture_eval3(sc, b->eta_tex, vload_f3(b->cond_eta), uv);
    v.k3 = texture_eval3(sc, b->k_tex, vload_f3(b->cond_k), uv);
    v.spec_r = texture_eval3(sc, b->spec_r_tex, vload_f3(b->spec_r), uv);
    v.spec_t = texture_eval3(sc, b->spec_t_tex, vload_f3(b->spec_t), uv);
    v.alpha_u = texture_eval1(sc, b->alpha_u_tex, b->alpha_u, uv);
    v.alpha_v = texture_eval1(sc, b->alpha_v_tex, b->alpha_v, uv);
    v.table = sc->bsdf_tables + max(b->table, 0);
    return v;
}

/* A bsdf with the identity frame, its constants as they are: for tests of the models, where world
 * and local directions coincide. */
inline BsdfVertex bsdf_vertex_local(__global const Bsdf *records, __global const float *tables, float3 wo) {
    BsdfVertex v;
    __global const Bsdf *b = records;
    v.opacity = 1.0f;
    for (int depth = 0; depth < VOLCL_MAX_BSDF_NESTING && b->type == BSDF_MASK; ++depth) {
        v.opacity *= b->opacity;
        b = &records[b->nested];
    }
    v.b = b;
    v.s = (float3)(1.0f, 0.0f, 0.0f);
    v.t = (float3)(0.0f, 1.0f, 0.0f);
    v.n = (float3)(0.0f, 0.0f, b->twosided && wo.z < 0.0f ? -1.0f : 1.0f);
    v.color = vload_f3(b->color);
    v.eta3 = vload_f3(b->cond_eta);
    v.k3 = vload_f3(b->cond_k);
    v.spec_r = vload_f3(b->spec_r);
    v.spec_t = vload_f3(b->spec_t);
    v.alpha_u = b->alpha_u;
    v.alpha_v = b->alpha_v;
    v.bumped = false;
    v.shadowing = false;
    v.n_in = v.n;
    v.tan2_tilt = 0.0f;
    v.table = tables + max(b->table, 0);
    return v;
}

inline bool bsdf_vertex_smooth(const BsdfVertex *v) { return bsdf_is_smooth(v->b->type); }

/* The bump or normal map's factor for direction w: 0 where w lies on different sides of the frame
 * before and after the tilt, else the shadowing term (1 without a map). */
inline float bsdf_tilt_factor(const BsdfVertex *v, float3 w) {
    if (!v->bumped) return 1.0f;
    float c_in = dot(w, v->n_in), c_p = dot(w, v->n);
    if (!(c_in * c_p > 0.0f)) return 0.0f;
    if (!v->shadowing) return 1.0f;
    float tan2 = fmax(1.0f - c_in * c_in, 0.0f) / (c_in * c_in);
    float a2 = fmin(0.125f * v->tan2_tilt, 1.0f);
    return 2.0f / (1.0f + sqrt(1.0f + a2 * tan2));
}

/* value = f |cos wi| for world directions wo_w (towards the viewer) and wi_w, with its pdf. */
__attribute__((always_inline))
inline float3 bsdf_eval(const BsdfVertex *v, float3 wo_w, float3 wi_w, float *pdf) {
    float3 f = bsdf_eval_local(v, frame_to_local(wo_w, v->s, v->t, v->n), frame_to_local(wi_w, v->s, v->t, v->n), pdf);
    if (v->bumped) {
        float k = bsdf_tilt_factor(v, wi_w);
        if (!(k > 0.0f)) *pdf = 0.0f;
        f *= k;
    }
    if (v->opacity != 1.0f) {
        f *= v->opacity;
        *pdf *= v->opacity;
    }
    return f;
}

/* A direction from the vertex's bsdf; s->wi in world space. */
__attribute__((always_inline))
inline bool bsdf_sample(const BsdfVertex *v, float3 wo_w, float u1, float2 u2, BsdfSample *s) {
    if (v->opacity != 1.0f) {
        if (!(u1 < v->opacity)) {
            s->wi = -wo_w;
            s->weight = (float3)(1.0f);
            s->pdf = 1.0f - v->opacity;
            s->eta = 1.0f;
            s->delta = true;
            s->null_event = true;
            return true;
        }
        u1 /= v->opacity;
    }
    if (!bsdf_sample_local(v, frame_to_local(wo_w, v->s, v->t, v->n), u1, u2, s)) return false;
    s->wi = s->null_event ? -wo_w : frame_to_world(s->wi, v->s, v->t, v->n);
    if (v->bumped) {
        float k = bsdf_tilt_factor(v, s->wi);
        if (!(k > 0.0f)) return false;
        s->weight *= k;
    }
    if (v->opacity != 1.0f) s->pdf *= v->opacity;
    return true;
}

/* The fraction of light a shadow ray along w passes on through surface point s of hit h: 1 for a
 * null surface, 0 for an opaque one, and for masks and panes what Mitsuba's eval_null_transmission
 * gives (1 - opacity (1 - what the wrapped bsdf passes)). */
inline float3 surface_null_transmission(const SceneData *sc, const Hit *h, SurfacePoint *s, float3 w) {
    __global const Bsdf *b = &sc->bsdfs[sc->shapes[s->shape].bsdf];
    if (b->type == BSDF_NULL) return (float3)(1.0f);
    if (!(b->flags & BSDF_FLAG_PASSES)) return (float3)(0.0f);
#if VOLCL_HAS_MASK || VOLCL_HAS_THINDIELECTRIC
#if VOLCL_NEEDS_UV
    if (b->flags & BSDF_FLAG_UV) surface_texcoords(sc, h, s);
    else s->uv = (float2)(0.0f);
#else
    s->uv = (float2)(0.0f);
#endif
    float opacity = 1.0f;
    for (int depth = 0; depth < VOLCL_MAX_BSDF_NESTING && b->type == BSDF_MASK; ++depth) {
        opacity *= clamp(texture_eval1(sc, b->opacity_tex, b->opacity, s->uv), 0.0f, 1.0f);
        b = &sc->bsdfs[b->nested];
    }
    float3 passed = (float3)(0.0f);
    if (b->type == BSDF_NULL) passed = (float3)(1.0f);
    if (b->type == BSDF_THINDIELECTRIC)
        passed = (1.0f - thindielectric_reflectance(dot(w, s->ns), b->eta))
                 * texture_eval3(sc, b->spec_t_tex, vload_f3(b->spec_t), s->uv);
    return 1.0f - opacity * (1.0f - passed);
#else
    return (float3)(0.0f);
#endif
}

#endif
