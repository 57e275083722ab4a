/* The packet renderer: render_pass (render.cl) for a scene small enough to test whole, with each
 * work item taking VOLCL_PACKET_WIDTH of render_pass's work items as the lanes of one packet.
 *
 * Each lane renders its work item's samples, one after the other, with the megakernel's functions
 * (path_start, path_surface_event, path_roulette): the same random numbers, the same additions, into
 * the same accumulator entry in the same order. What changes is who traces the rays: every step the
 * packet's continuation rays and the shadow rays their last vertices left (VOLCL_DEFER_SHADOWS) are
 * traced together in the SIMD lanes (packet_queries.h), against every primitive of the scene. A
 * shadow ray is resolved before its path's next vertex, so its light is added to L where the
 * megakernel adds it; a lane whose path ended with its shadow ray untraced starts its next sample and
 * adds the finished one once that ray is traced. A lane out of samples idles until the packet is done.
 *
 * volcl/packets.py takes scenes without media, null, mask or thin dielectric bsdfs, instances or
 * cylinders (every surface opaque: a shadow ray is an occlusion query), rendered by the path
 * integrator, with few enough primitives; the launch's last two arguments are where the scene's
 * tree's leaf packets end and where the shadow tree's (RenderParams.shadow_root: the scene without
 * the faces of its convex hull, volcl.hull) end. */
#define VOLCL_DEFER_SHADOWS 1
/* Two warnings each first build printed, about nothing wrong: without AVX-512, that a float16
 * argument's calling convention differs (every function is inlined: no call crosses a boundary);
 * and that the front end's optimizer left the vector step's loop to the work-group compiler, which
 * vectorizes it */
#pragma clang diagnostic ignored "-Wpsabi"
#pragma clang diagnostic ignored "-Wpass-failed"
#include "renderer.h"
#include "packet_queries.h"
#ifndef VOLCL_PACKET_LANES
#define VOLCL_PACKET_LANES 0
#endif
#if VOLCL_PACKET_LANES
#include "packet_lanes.h"
#endif

#define PW VOLCL_PACKET_WIDTH

/* One lane's work: its render_pass work item's pixel and accumulator entry, and the pass it is on. */
typedef struct {
    int px, py, pixel, out, slot;
    int pass;       /* the pass of the sample in progress; passes: none left */
    int steps;      /* of the path in progress (integrator_radiance's bound) */
} LaneJob;

/* Start lane l's next sample, if it has one left: false when it has none. */
inline bool lane_start(const SceneData *sc, __global const float *filter_table, LaneJob *job, int passes,
                       uint sample_base, int slots, PathState *ps, Rng *rng) {
    if (job->pass >= passes) return false;
    uint sample = sample_base + (uint)(job->pass * slots + job->slot);
    float3 o, d;
    float t_max;
    sample_camera_ray(sc, filter_table, job->px, job->py, job->pixel, sample, rng, &o, &d, &t_max);
    *ps = path_start(sc, o, d, t_max);
    job->steps = 0;
    return true;
}

/* Lane l's sample is done but for the shadow ray its last vertex may have left: the lane starts its
 * next sample, and the finished one is added now, or kept (done_L, finishing) with that ray, which
 * stays with the lane while its next sample starts. */
inline void lane_finish(const SceneData *sc, __global const float *filter_table, LaneJob *job, int passes,
                        uint sample_base, int slots, PathState *ps, Rng *rng, bool *alive, bool *finishing,
                        float3 *done_L, __global float4 *sums, __global float4 *sums_sq, __global uint *invalid,
                        __global uint *cutoffs) {
    PathState last = *ps;
    ++job->pass;
    *alive = lane_start(sc, filter_table, job, passes, sample_base, slots, ps, rng);
    if (last.shadow) {
        *finishing = true;
        *done_L = last.L;
        ps->shadow = true;
        ps->shadow_o = last.shadow_o;
        ps->shadow_d = last.shadow_d;
        ps->shadow_t = last.shadow_t;
        ps->shadow_root = last.shadow_root;
        ps->shadow_beta = last.shadow_beta;
        ps->shadow_value = last.shadow_value;
    } else {
        sample_add(last.L, 0u, job->out, sums, sums_sq, invalid, cutoffs);
    }
}

#if VOLCL_PACKET_LANES
/* Entry k of a vector step: the path of a lane that takes the step there (slot: its triangle's in
 * the table). */
inline void lane_load(PacketLanes *z, int k, int slot, const PathState *ps, const Rng *rng, const Hit *h) {
    z->take[k] = true;
    z->slot[k] = slot;
    z->depth[k] = ps->depth;
    z->do_nee[k] = ps->do_nee;
    z->dx[k] = ps->d.x;
    z->dy[k] = ps->d.y;
    z->dz[k] = ps->d.z;
    z->bx[k] = ps->beta.x;
    z->by[k] = ps->beta.y;
    z->bz[k] = ps->beta.z;
    z->b1[k] = h->b1;
    z->b2[k] = h->b2;
    z->eta[k] = ps->eta_scale;
    z->rlo[k] = (uint)rng->state;
    z->rhi[k] = (uint)(rng->state >> 32);
    z->rinc_lo[k] = (uint)rng->inc;
    z->rinc_hi[k] = (uint)(rng->inc >> 32);
}

/* Entry k unused: zeros, which the step runs on, its results unread. */
inline void lane_clear(PacketLanes *z, int k) {
    z->take[k] = false;
    z->slot[k] = z->depth[k] = z->do_nee[k] = 0;
    z->dx[k] = z->dy[k] = z->dz[k] = z->bx[k] = z->by[k] = z->bz[k] = z->b1[k] = z->b2[k] = 0.0f;
    z->eta[k] = 1.0f;
    z->rlo[k] = z->rhi[k] = z->rinc_lo[k] = z->rinc_hi[k] = 0u;
}

/* What entry l's vector step did to its path, as path_surface_event and path_roulette would have
 * left it: the shadow ray (nee_defer's), the generator, and the scattered ray where it goes on.
 * Whether the path ended. */
inline bool lane_store(const PacketLanes *z, int l, int shadow_root, PathState *ps, Rng *rng) {
    if (z->shadow[l]) {
        ps->shadow = true;
        ps->shadow_o = (float3)(z->sox[l], z->soy[l], z->soz[l]);
        ps->shadow_d = (float3)(z->sdx[l], z->sdy[l], z->sdz[l]);
        ps->shadow_t = z->st[l];
        ps->shadow_root = shadow_root;  /* (the light samples are points of the scene) */
        ps->shadow_beta = ps->beta;
        ps->shadow_value = (float3)(z->svx[l], z->svy[l], z->svz[l]);
    }
    rng->state = ((ulong)z->rhi[l] << 32) | (ulong)z->rlo[l];
    if (!z->going[l]) return true;
    ps->beta = (float3)(z->bx[l], z->by[l], z->bz[l]);
    ps->specular = false;
    ps->prev_pdf = z->pdf[l];
    ps->prev_p = (float3)(z->px[l], z->py[l], z->pz[l]);
    ps->o = (float3)(z->ox[l], z->oy[l], z->oz[l]);
    ps->t_back = z->t_back[l];
    ps->d = (float3)(z->dx[l], z->dy[l], z->dz[l]);
    ps->t_max = INFINITY;
    ++ps->depth;
    return false;
}

/* Zero entries after the first n of a step, up to a whole number of its vectors (VOLCL_PACKET_STEP_WIDTH):
 * how many entries the step runs. */
inline int lanes_pad(PacketLanes *z, int n) {
    int padded = (n + VOLCL_PACKET_STEP_WIDTH - 1) / VOLCL_PACKET_STEP_WIDTH * VOLCL_PACKET_STEP_WIDTH;
    for (int k = n; k < padded; ++k) lane_clear(z, k);
    return padded;
}

/* What a step did to the paths of its first n entries (entry k: lane owner[k]), as the scalar steps
 * take it back: the sample of a path that ended finished, the lane's next one started. */
#define LANES_TAKE_BACK(z, owner, n)                                                                           \
    do {                                                                                                      \
        for (int k = 0; k < (n); ++k) {                                                                       \
            int l = (owner)[k];                                                                               \
            if (lane_store(&(z), k, shadow_root, &ps[l], &rng[l]) || ++job[l].steps >= VOLCL_MAX_STEPS)      \
                lane_finish(&sc, filter_table, &job[l], passes, sample_base, slots, &ps[l], &rng[l],         \
                            &alive[l], &finishing[l], &done_L[l], sums, sums_sq, invalid, cutoffs);           \
        }                                                                                                     \
    } while (0)
#endif

VOLCL_KERNEL void render_packets(VOLCL_SCENE_ARGS,
                             __global float4 *sums, __global float4 *sums_sq, __global uint *invalid,
                             __global uint *cutoffs,
                             uint sample_base, int tile_x, int tile_y, int tile_w, int tile_pixels,
                             int first, int count, int slots, int passes, int scene_leaves, int shadow_leaves,
                             __global const float *lanes_table, __global const int *lanes_slots) {
    SceneData sc = VOLCL_SCENE_DATA;
    int base = (int)get_global_id(0) * PW;
    LaneJob job[PW];
    PathState ps[PW];
    Rng rng[PW];
    bool alive[PW];         /* a path in progress, its next ray untraced */
    bool finishing[PW];     /* a finished sample waits for its last shadow ray: its L is done_L */
    float3 done_L[PW];
    int live = 0;
    for (int l = 0; l < PW; ++l) {
        int gid = base + l;
        job[l].pass = passes;       /* past the launch's work items: nothing to do */
        if (gid < count * slots) {
            job[l].slot = gid / count;
            int tp = first + gid % count;
            job[l].px = tile_x + tp % tile_w;
            job[l].py = tile_y + tp / tile_w;
            job[l].pixel = job[l].py * params->width + job[l].px;
            job[l].out = job[l].slot * tile_pixels + tp;
            job[l].pass = 0;
        }
        /* (a lane without work still hands the queries a ray: a zero one, never traced) */
        ps[l].o = ps[l].d = (float3)(0.0f);
        ps[l].shadow = false;
        alive[l] = lane_start(&sc, filter_table, &job[l], passes, sample_base, slots, &ps[l], &rng[l]);
        finishing[l] = false;
        live += alive[l];
    }
    int closest_end = scene_leaves;
    int shadow_root = params->shadow_root;
    while (live > 0) {
        /* the rays of every lane: its path's next ray, and the shadow ray its last vertex left */
        float ox[PW], oy[PW], oz[PW], dx[PW], dy[PW], dz[PW], tm[PW];
        float sox[PW], soy[PW], soz[PW], sdx[PW], sdy[PW], sdz[PW], st_scene[PW], st_shadow[PW];
        bool any_shadow = false, any_scene = false, any_hull = false;
        for (int l = 0; l < PW; ++l) {
            ox[l] = ps[l].o.x;
            oy[l] = ps[l].o.y;
            oz[l] = ps[l].o.z;
            dx[l] = ps[l].d.x;
            dy[l] = ps[l].d.y;
            dz[l] = ps[l].d.z;
            tm[l] = alive[l] ? ps[l].t_max : -1.0f;
            /* a lane without a shadow ray hands the queries a zero one (its fields are unset) */
            bool sh = ps[l].shadow;
            float3 so = sh ? ps[l].shadow_o : (float3)(0.0f), sd = sh ? ps[l].shadow_d : (float3)(0.0f);
            sox[l] = so.x;
            soy[l] = so.y;
            soz[l] = so.z;
            sdx[l] = sd.x;
            sdy[l] = sd.y;
            sdz[l] = sd.z;
            st_scene[l] = sh && ps[l].shadow_root == 0 ? ps[l].shadow_t : -1.0f;
            st_shadow[l] = sh && ps[l].shadow_root != 0 ? ps[l].shadow_t : -1.0f;
            any_shadow |= sh;
            any_scene |= sh && ps[l].shadow_root == 0;
            any_hull |= sh && ps[l].shadow_root != 0;
        }
        float ht[PW], hb1[PW], hb2[PW];
        int hprim[PW], blocked[PW];
        {
            floatP Ox = vloadP(0, ox), Oy = vloadP(0, oy), Oz = vloadP(0, oz);
            floatP Dx = vloadP(0, dx), Dy = vloadP(0, dy), Dz = vloadP(0, dz);
            PacketShear s = packet_shear(Ox, Oy, Oz, Dx, Dy, Dz);
            floatP t, b1, b2;
            intP prim;
            packet_closest(&sc, 0, closest_end, &s, Ox, Oy, Oz, Dx, Dy, Dz, vloadP(0, tm), &t, &b1, &b2, &prim);
            vstoreP(t, 0, ht);
            vstoreP(b1, 0, hb1);
            vstoreP(b2, 0, hb2);
            vstoreP(prim, 0, hprim);
        }
        if (any_shadow) {
            floatP Ox = vloadP(0, sox), Oy = vloadP(0, soy), Oz = vloadP(0, soz);
            floatP Dx = vloadP(0, sdx), Dy = vloadP(0, sdy), Dz = vloadP(0, sdz);
            PacketShear s = packet_shear(Ox, Oy, Oz, Dx, Dy, Dz);
            intP b = (intP)(0);
            if (any_scene)
                b |= packet_occluded(&sc, 0, scene_leaves, &s, Ox, Oy, Oz, Dx, Dy, Dz, vloadP(0, st_scene));
            if (any_hull)
                b |= packet_occluded(&sc, shadow_root ? scene_leaves : 0, shadow_root ? shadow_leaves : scene_leaves,
                                     &s, Ox, Oy, Oz, Dx, Dy, Dz, vloadP(0, st_shadow));
            vstoreP(b, 0, blocked);
        }
        /* each lane's step, as integrator_radiance takes it; the lanes whose rays hit a plain diffuse
         * triangle take theirs together in the vector step after the others', and those at a rough
         * plastic one in the rough step; each step's lanes packed to the front of its entries (lane
         * owner[k] at entry k) */
#if VOLCL_PACKET_LANES
        PacketLanes z;
        int owner[PW], n_lanes = 0;
#if VOLCL_PACKET_ROUGH
        PacketLanes zr;
        int owner_r[PW], n_rough = 0;
#endif
#endif
        for (int l = 0; l < PW; ++l) {
            if (ps[l].shadow) {
                ps[l].shadow = false;
                if (!blocked[l]) {
                    if (finishing[l]) done_L[l] += ps[l].shadow_beta * ps[l].shadow_value;
                    else ps[l].L += ps[l].shadow_beta * ps[l].shadow_value;
                }
            }
            if (finishing[l]) {
                finishing[l] = false;
                sample_add(done_L[l], 0u, job[l].out, sums, sums_sq, invalid, cutoffs);
            }
            Hit h;
            h.t = ht[l];
            h.prim = hprim[l];
            h.b1 = hb1[l];
            h.b2 = hb2[l];
            bool hit = alive[l] && h.t < ps[l].t_max;
#if VOLCL_PACKET_LANES
            int slot = hit && h.prim >= 0 ? lanes_slots[h.prim] : -1;
            if (slot >= 0) {
#if VOLCL_PACKET_ROUGH
                if (lanes_table[WF_TRI_AT(WF_TRI_LANES, slot)] == 2.0f) {
                    lane_load(&zr, n_rough, slot, &ps[l], &rng[l], &h);
                    owner_r[n_rough++] = l;
                    continue;
                }
#endif
                lane_load(&z, n_lanes, slot, &ps[l], &rng[l], &h);
                owner[n_lanes++] = l;
                continue;
            }
#endif
            if (!alive[l]) continue;
            uint cut = 0u;
            int next = path_surface_event(&sc, &rng[l], &ps[l], hit, &h, &cut);
            bool ended = next == PATH_END || (next != PATH_CROSSED && !path_roulette(&sc, &rng[l], &ps[l]))
                         || ++job[l].steps >= VOLCL_MAX_STEPS;
            if (ended)
                lane_finish(&sc, filter_table, &job[l], passes, sample_base, slots, &ps[l], &rng[l], &alive[l],
                            &finishing[l], &done_L[l], sums, sums_sq, invalid, cutoffs);
        }
#if VOLCL_PACKET_LANES
        if (n_lanes > 0) {
            packet_lanes_step(lanes_table, params, &z, lanes_pad(&z, n_lanes));
            LANES_TAKE_BACK(z, owner, n_lanes);
        }
#if VOLCL_PACKET_ROUGH
        if (n_rough > 0) {
            packet_rough_step(lanes_table, sc.texels, sc.bsdf_tables, params, &zr, lanes_pad(&zr, n_rough));
            LANES_TAKE_BACK(zr, owner_r, n_rough);
        }
#endif
#endif
        live = 0;
        for (int l = 0; l < PW; ++l) live += alive[l] || finishing[l];
    }
}
