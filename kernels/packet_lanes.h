/* The packet renderer's vector step (packets.cl): the lanes of a packet whose rays hit a plain
 * diffuse triangle (untextured or checkered with two colours, flat, not emitting:
 * volcl.wavefront.diffuse_lanes marks them) take their whole
 * step there in one loop over the lanes that LLVM's loop vectorizer runs in the SIMD lanes, as the
 * wavefront's surface stage takes it (wavefront_surface.cl, with its routines, lanes_surface.h):
 * path_surface_event at a diffuse vertex and path_roulette, draw for draw, the shadow ray left to
 * the packet's next queries as VOLCL_DEFER_SHADOWS leaves it. The loop keeps lanes.h's rules: the
 * lanes' state as structure of arrays of 32-bit scalars, every field written for every lane, no
 * branch. Lanes whose rays hit a rough plastic triangle (a GGX coating over a constant or bitmap
 * reflectance: lanes_rough.h) take theirs in a second such loop, where the scene has them and the
 * runtime's vector code rounds as its scalar code does (volcl.packets.bsdf_steps_pay). Other lanes
 * run the megakernel's scalar steps. */
#ifndef VOLCL_PACKET_LANES_H
#define VOLCL_PACKET_LANES_H

#ifdef __OPTIMIZE__     /* (forced inlining at -O0 leaves calls Oclgrind cannot run: surface.h) */
#pragma clang attribute push (__attribute__((always_inline)), apply_to = function)
#endif
#include "lanes.h"
#include "wavefront_state.h"
#include "lanes_rows.h"
#include "lanes_surface.h"
#ifndef VOLCL_PACKET_ROUGH
#define VOLCL_PACKET_ROUGH 0    /* 1: some lanes scatter from rough plastic triangles (lanes_rough.h) */
#endif
#if VOLCL_PACKET_ROUGH
#include "lanes_rough.h"
#endif

#define PL VOLCL_PACKET_WIDTH

/* The vector step's state of every lane: what it reads (the ray's direction, throughput, depth,
 * generator, hit), and what it leaves (the next ray, whose origin ox/oy/oz is only written, and
 * the shadow ray). A lane that does not take the step (take 0) runs it on its numbers all the
 * same, its results unused. */
typedef struct {
    int take[PL], slot[PL], depth[PL], do_nee[PL];
    float ox[PL], oy[PL], oz[PL], dx[PL], dy[PL], dz[PL], bx[PL], by[PL], bz[PL], b1[PL], b2[PL], eta[PL];
    uint rlo[PL], rhi[PL], rinc_lo[PL], rinc_hi[PL];
    /* out: going on (1), a shadow ray left (1); the scatter point and the direction's pdf */
    int going[PL], shadow[PL];
    float px[PL], py[PL], pz[PL], pdf[PL], t_back[PL];
    float sox[PL], soy[PL], soz[PL], sdx[PL], sdy[PL], sdz[PL], st[PL], svx[PL], svy[PL], svz[PL];
} PacketLanes;

/* What lane l's step leaves (written for every lane): whether the path goes on, the shadow ray
 * from `origin` towards ls's light with what it brings (c), the generator, the next ray from p
 * (its origin o_next, direction wi), the throughput and the direction's pdf. */
inline void packet_lane_put(PacketLanes *z, int l, bool going, bool nee, const Rng32 *rng, V3 p, V3 ng, V3 o_next,
                            V3 wi, V3 beta, float pdf, V3 origin, const LanesLight *ls, V3 c) {
    z->going[l] = going;
    z->shadow[l] = nee;
    z->rlo[l] = rng->lo;
    z->rhi[l] = rng->hi;
    z->ox[l] = o_next.x;
    z->oy[l] = o_next.y;
    z->oz[l] = o_next.z;
    z->dx[l] = wi.x;
    z->dy[l] = wi.y;
    z->dz[l] = wi.z;
    z->bx[l] = beta.x;
    z->by[l] = beta.y;
    z->bz[l] = beta.z;
    z->px[l] = p.x;
    z->py[l] = p.y;
    z->pz[l] = p.z;
    z->pdf[l] = pdf;
    z->t_back[l] = lanes_offset_back(o_next, p, ng, wi);
    z->sox[l] = origin.x;
    z->soy[l] = origin.y;
    z->soz[l] = origin.z;
    z->sdx[l] = ls->wi.x;
    z->sdy[l] = ls->wi.y;
    z->sdz[l] = ls->wi.z;
    z->st[l] = ls->dist * 0.9999f;
    z->svx[l] = c.x;
    z->svy[l] = c.y;
    z->svz[l] = c.z;
}

/* The end of lane l's step at triangle tri, whose scatter from p went on (cont) towards wi with
 * throughput beta_s and pdf: path_roulette, the next ray's origin, and packet_lane_put. */
inline void packet_lane_end(PacketLanes *z, int l, const LanesTriangle *tri, int depth, __global const RenderParams *rp,
                            bool cont, V3 beta_s, Rng32 *rng, V3 p, V3 wi, float pdf, bool nee, V3 origin,
                            const LanesLight *ls, V3 c) {
    bool alive = cont & (v3_max(beta_s) > 0.0f);
    bool killed = lanes_roulette(rng, &beta_s, alive, depth + 1, rp->rr_depth, z->eta[l]);
    V3 o_next = lanes_offset_origin(p, tri->mag, tri->ng, wi);
    packet_lane_put(z, l, alive & !killed, nee, rng, p, tri->ng, o_next, wi, beta_s, pdf, origin, ls, c);
}

/* Lane l's step at a diffuse triangle, written for every lane (the loop over l is the vectorized
 * one). */
inline void packet_lane_step(__global const float *table, __global const RenderParams *rp, PacketLanes *z, int l) {
    bool take = z->take[l] != 0;
    LanesTriangle tri = lanes_triangle_gather(table, z->slot[l]);
    tri.color = lanes_color_at(&tri, z->b1[l], z->b2[l]);
    V3 d = v3(z->dx[l], z->dy[l], z->dz[l]), beta = v3(z->bx[l], z->by[l], z->bz[l]);
    int depth = z->depth[l];
    bool at_limit = (rp->max_depth >= 0) & (depth + 1 >= rp->max_depth);
    bool scatter = take & !at_limit;    /* a diffuse surface passes nothing at the depth limit */

    V3 p, frame_s, frame_t, n;
    float wo_z;
    lanes_diffuse_vertex(&tri, z->b1[l], z->b2[l], d, &p, &frame_s, &frame_t, &n, &wo_z);
    Rng32 rng = {z->rlo[l], z->rhi[l], z->rinc_lo[l], z->rinc_hi[l]};
    LanesLight ls;
    V3 c;
    bool nee = lanes_diffuse_nee(table, rp, tri.color, p, n, wo_z, scatter, z->do_nee[l] != 0, &rng, &ls, &c);
    V3 origin = lanes_offset_origin(p, tri.mag, tri.ng, ls.wi);

    bool sampling = scatter & !rp->specular_chains_only;
    V3 wi;
    float pdf;
    bool cont = lanes_diffuse_bounce(&rng, sampling, 0.0f, frame_s, frame_t, n, wo_z, &wi, &pdf);
    packet_lane_end(z, l, &tri, depth, rp, cont, v3_mul(beta, tri.color), &rng, p, wi, pdf, nee, origin, &ls, c);
}

#if VOLCL_PACKET_ROUGH
/* Lane l's step at a rough plastic triangle (lanes_rough.h), written for every lane: as
 * path_surface_event and path_roulette take it there, draw for draw. */
inline void packet_rough_lane_step(__global const float *table, __global const float *texels,
                                   __global const float *tables, __global const RenderParams *rp, PacketLanes *z,
                                   int l) {
    bool take = z->take[l] != 0;
    LanesTriangle tri = lanes_triangle_gather(table, z->slot[l]);
    LanesRough r = lanes_rough_gather(table, z->slot[l]);
    V3 color = lanes_rough_color(texels, &tri, &r, z->b1[l], z->b2[l], table, z->slot[l]);
    V3 d = v3(z->dx[l], z->dy[l], z->dz[l]), beta = v3(z->bx[l], z->by[l], z->bz[l]);
    int depth = z->depth[l];
    bool at_limit = (rp->max_depth >= 0) & (depth + 1 >= rp->max_depth);
    bool scatter = take & !at_limit;    /* nor does a rough plastic one */

    V3 p, frame_s, frame_t, n;
    float wo_z;
    lanes_diffuse_vertex(&tri, z->b1[l], z->b2[l], d, &p, &frame_s, &frame_t, &n, &wo_z);
    V3 wo = lanes_to_local(v3(-d.x, -d.y, -d.z), frame_s, frame_t, n);
    Rng32 rng = {z->rlo[l], z->rhi[l], z->rinc_lo[l], z->rinc_hi[l]};
    LanesLight ls;
    V3 c;
    float dep;
    bool nee = lanes_rough_nee(table, tables, rp, &r, color, p, frame_s, frame_t, n, wo, scatter, z->do_nee[l] != 0,
                               &rng, &ls, &c, &dep);
    V3 origin = lanes_offset_origin(p, tri.mag, tri.ng, ls.wi);

    bool sampling = scatter & !rp->specular_chains_only;
    V3 wi, weight;
    float pdf;
    bool cont = lanes_rough_bounce(&r, tables, color, &rng, sampling, dep, frame_s, frame_t, n, wo, &wi, &weight, &pdf);
    packet_lane_end(z, l, &tri, depth, rp, cont, v3_mul(beta, weight), &rng, p, wi, pdf, nee, origin, &ls, c);
}
#endif

#ifndef VOLCL_PACKET_STEP_WIDTH
/* the vectors of a step: a packet's lanes at one kind of surface are a few of its 16, packed to
 * the front of the step's entries, and a step over all 16 cost more than the scalar steps of
 * those few at a rough plastic triangle (textured_cbox, PoCL, AMD AVX-512 host: a rough step of
 * width 4, 8, 16 ran 1.06x, 1.05x, 0.94x the speed of the same build without it) */
#define VOLCL_PACKET_STEP_WIDTH 8
#endif

/* The first n entries' steps (n a multiple of VOLCL_PACKET_STEP_WIDTH): the loop LLVM vectorizes
 * (each entry touches its own numbers only). */
inline void packet_lanes_step(__global const float *table, __global const RenderParams *rp, PacketLanes *z, int n) {
#pragma clang loop unroll(disable) vectorize(assume_safety) vectorize_width(VOLCL_PACKET_STEP_WIDTH) interleave_count(1)
    for (int k = 0; k < n; ++k) packet_lane_step(table, rp, z, k);
}

#if VOLCL_PACKET_ROUGH
/* The same at rough plastic triangles */
inline void packet_rough_step(__global const float *table, __global const float *texels, __global const float *tables,
                              __global const RenderParams *rp, PacketLanes *z, int n) {
#pragma clang loop unroll(disable) vectorize(assume_safety) vectorize_width(VOLCL_PACKET_STEP_WIDTH) interleave_count(1)
    for (int k = 0; k < n; ++k) packet_rough_lane_step(table, texels, tables, rp, z, k);
}
#endif

#undef PL
#ifdef __OPTIMIZE__
#pragma clang attribute pop
#endif
#endif
