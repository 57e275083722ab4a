/* The packet renderer's vector step (packets.cl): the lanes of a packet whose rays hit a plain
 * diffuse triangle (untextured or checkered with two colours, flat, not emitting:
 * volcl.wavefront.diffuse_lanes marks them) take their whole
 * step there in one loop over the lanes that LLVM's loop vectorizer runs in the SIMD lanes, as the
 * wavefront's surface stage takes it (wavefront_surface.cl, with its routines, lanes_surface.h):
 * path_surface_event at a diffuse vertex and path_roulette, draw for draw, the shadow ray left to
 * the packet's next queries as VOLCL_DEFER_SHADOWS leaves it. The loop keeps lanes.h's rules: the
 * lanes' state as structure of arrays of 32-bit scalars, every field written for every lane, no
 * branch. Other lanes run the megakernel's scalar steps. */
#ifndef VOLCL_PACKET_LANES_H
#define VOLCL_PACKET_LANES_H

#ifdef __OPTIMIZE__     /* (forced inlining at -O0 leaves calls Oclgrind cannot run: surface.h) */
#pragma clang attribute push (__attribute__((always_inline)), apply_to = function)
#endif
#include "lanes.h"
#include "wavefront_state.h"
#include "lanes_rows.h"
#include "lanes_surface.h"

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

/* Lane l's step, written for every lane (the loop over l is the vectorized one). */
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
    V3 beta_s = v3_mul(beta, tri.color);
    bool alive = cont & (v3_max(beta_s) > 0.0f);
    bool killed = lanes_roulette(&rng, &beta_s, alive, depth + 1, rp->rr_depth, z->eta[l]);
    V3 o_next = lanes_offset_origin(p, tri.mag, tri.ng, wi);

    z->going[l] = alive & !killed;
    z->shadow[l] = nee;
    z->rlo[l] = rng.lo;
    z->rhi[l] = rng.hi;
    z->ox[l] = o_next.x;
    z->oy[l] = o_next.y;
    z->oz[l] = o_next.z;
    z->dx[l] = wi.x;
    z->dy[l] = wi.y;
    z->dz[l] = wi.z;
    z->bx[l] = beta_s.x;
    z->by[l] = beta_s.y;
    z->bz[l] = beta_s.z;
    z->px[l] = p.x;
    z->py[l] = p.y;
    z->pz[l] = p.z;
    z->pdf[l] = pdf;
    z->t_back[l] = lanes_offset_back(o_next, p, tri.ng, wi);
    z->sox[l] = origin.x;
    z->soy[l] = origin.y;
    z->soz[l] = origin.z;
    z->sdx[l] = ls.wi.x;
    z->sdy[l] = ls.wi.y;
    z->sdz[l] = ls.wi.z;
    z->st[l] = ls.dist * 0.9999f;
    z->svx[l] = c.x;
    z->svy[l] = c.y;
    z->svz[l] = c.z;
}

/* Every lane's step: the loop LLVM vectorizes (each lane touches its own entries only). */
inline void packet_lanes_step(__global const float *table, __global const RenderParams *rp, PacketLanes *z) {
#pragma clang loop unroll(disable) vectorize(assume_safety) vectorize_width(PL) interleave_count(1)
    for (int l = 0; l < PL; ++l) packet_lane_step(table, rp, z, l);
}

#undef PL
#ifdef __OPTIMIZE__
#pragma clang attribute pop
#endif
#endif
