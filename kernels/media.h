/* Homogeneous media: free-flight distance sampling and analytic transmittance.
 *
 * Chromatic sigma_t uses one-sample spectral MIS (Miller et al. 2019): a channel is chosen with
 * probability proportional to the path throughput, a distance is sampled from that channel's
 * exponential, and the estimate is divided by the mixture pdf over all channels. Exponentials are
 * taken relative to the smallest extinction among the channels that can be chosen, so the ratio
 * Tr / pdf never becomes 0 / 0 when every exp(-tau) underflows in a thick medium.
 */
#ifndef VOLCL_MEDIA_H
#define VOLCL_MEDIA_H

#include "grid.h"   /* heterogeneous media look their grids up through it */
#include "trig.h"   /* log_pos */

/* exp(-sigma * t) that is 1 for sigma = 0 and 0 for t = INF, never NaN from 0 * INF. */
inline float3 transmittance_exp(float3 sigma, float t) {
    float3 tau = sigma * t;
    tau = select(tau, (float3)(0.0f), sigma == (float3)(0.0f));
#if VOLCL_HAS_CHROMATIC_MEDIA
    return exp(-tau);
#else
    /* grey extinction (every sigma passed here is a medium's sigma_t, equal in all channels):
     * one exponential instead of three, the same value in each channel */
    return (float3)(exp(-tau.x));
#endif
}

#include "emission_nee.h"   /* MIS of the emission collected here against NEE towards it */

typedef struct {
    float t;            /* distance of the scattering event, or the segment end when none */
    bool scattered;
    float3 weight;      /* factor for the path throughput */
    float3 emission;    /* emitted radiance estimate collected on the segment (emissive media) */
    float tr;           /* grey homogeneous media, scattered: the transmittance to t, exactly 1 - the
                         * variate (the distance pdf over sigma_t without an exp); else -1 */
} MediumSample;

VOLCL_STEP_INLINE
inline MediumSample medium_sample_distance(__global const Medium *m, float t_max, float3 beta,
                                           float u_channel, float u_dist) {
    MediumSample ms;
    float3 sigma_t = vload_f3(m->sigma_t), albedo = vload_f3(m->albedo);
    ms.emission = (float3)(0.0f);
    ms.tr = -1.0f;
#if VOLCL_HAS_CHROMATIC_MEDIA
    float3 p = fmax(beta, 0.0f);
    float total = p.x + p.y + p.z;
    p = total > 0.0f ? p / total : (float3)(1.0f / 3.0f);
    float sigma_c = u_channel < p.x ? sigma_t.x : (u_channel < p.x + p.y ? sigma_t.y : sigma_t.z);
    /* reference rate: the smallest extinction among channels with p > 0 */
    float sigma_ref = INFINITY;
    if (p.x > 0.0f) sigma_ref = sigma_t.x;
    if (p.y > 0.0f) sigma_ref = fmin(sigma_ref, sigma_t.y);
    if (p.z > 0.0f) sigma_ref = fmin(sigma_ref, sigma_t.z);
    /* u_dist < 1, so the log is finite (see medium_sample_tau); sigma = 0: the segment is never cut */
    float t = sigma_c > 0.0f ? -log_pos(1.0f - u_dist) / sigma_c : INFINITY;
    ms.scattered = t < t_max;
    ms.t = ms.scattered ? t : t_max;
    float3 rel = transmittance_exp(sigma_t - sigma_ref, ms.t);
    if (ms.scattered) {
        float pdf = dot(p, sigma_t * rel);
        ms.weight = albedo * sigma_t * rel / pdf;
#if VOLCL_HAS_EMISSIVE_MEDIA
        ms.emission = vload_f3(m->emission) * rel / pdf;
#endif
    } else {
        ms.weight = rel / dot(p, rel);
    }
#else
    /* grey extinction: the exponentials cancel exactly against the pdf */
    float sigma = sigma_t.x;
    float t = sigma > 0.0f ? -log_pos(1.0f - u_dist) / sigma : INFINITY;
    ms.scattered = t < t_max;
    ms.t = ms.scattered ? t : t_max;
    ms.weight = ms.scattered ? albedo : (float3)(1.0f);
    if (ms.scattered) ms.tr = 1.0f - u_dist;
#if VOLCL_HAS_EMISSIVE_MEDIA
    if (ms.scattered) ms.emission = vload_f3(m->emission) / sigma;
#endif
#endif
    return ms;
}

VOLCL_STEP_INLINE
inline float3 medium_transmittance(__global const Medium *m, float t) {
    return transmittance_exp(vload_f3(m->sigma_t), t);
}

#if VOLCL_HAS_GRID_MEDIA
/* Heterogeneous media: delta tracking (free flights) and ratio tracking (transmittance) against a
 * piecewise-constant majorant mu >= max over channels of sigma_t, read from the density grid's coarse
 * majorant grid along the ray (kernels/grid.h walks it).
 *
 * The estimator (null-collision form, per colour channel c, with sigma_n = mu - sigma_t >= 0):
 *   L_c(0) = int_0^T exp(-int_0^t mu) [sigma_a,c Le_c + sigma_s,c Ls_c + sigma_n,c L_c(t)] dt
 *            + exp(-int_0^T mu) L_c(T).
 * The majorant is the same for all channels, so tentative collisions are drawn from the density
 * mu exp(-int mu) of every channel at once, and reaching the segment end has probability
 * exp(-int mu): both cancel exactly, per channel. At a tentative collision the emission term is
 * added in full (sigma_a Le / mu) and one of the two remaining terms is chosen: the real collision
 * with probability P_r = <p, sigma_t> / (<p, sigma_t> + <p, sigma_n>), else the null collision,
 * where p are channel probabilities proportional to the current path weight. The chosen term is
 * divided by mu times its probability, which gives the weights
 *   real: albedo * sigma_t * (<p, sigma_t> + <p, sigma_n>) / (mu <p, sigma_t>)
 *   null: sigma_n * (<p, sigma_t> + <p, sigma_n>) / (mu <p, sigma_n>)
 * per channel. This is unbiased for every channel simultaneously because a term is chosen with
 * non-zero probability whenever it is non-zero in any channel the path still carries (p_c > 0), and
 * divided by exactly that probability; it is the one-sample balance heuristic over channels
 * (spectral MIS, Miller et al. 2019), so no channel's weight exceeds 1 / p_c times its own ratio.
 * For grey extinction both weights reduce to classic delta tracking (albedo, and 1).
 * Ratio tracking multiplies the transmittance by sigma_n / mu at every tentative collision.
 *
 * The bound VOLCL_MAX_TRACKING_STEPS (cells visited plus tentative collisions per segment) cannot
 * bias ordinary scenes: the number of tentative collisions is Poisson with mean equal to the
 * majorant optical depth of the segment (less for delta tracking, which stops at the first real
 * collision), and P(N >= 65536) is below 1e-1000 for any mean under 10^4, i.e. optical depths far
 * beyond visible detail. A segment that hits it ends the path (or blocks the shadow ray), which
 * is biased, so every hit is counted in *cutoffs and reported. */
#define VOLCL_MAX_TRACKING_STEPS 65536
/* Ratio tracking plays Russian roulette below this transmittance (as pbrt-v4 does). */
#define VOLCL_RR_TRANSMITTANCE 0.05f

/* Probability of each channel for choosing between collision types: proportional to the weight the
 * path carries in it, uniform when it carries none. */
inline float3 medium_channel_probs(float3 beta) {
    float3 p = fmax(beta, 0.0f);
    float total = p.x + p.y + p.z;
    return total > 0.0f ? p / total : (float3)(1.0f / 3.0f);
}

inline float3 medium_grid_albedo(const SceneData *sc, __global const Medium *m, float3 p) {
    __global const GridVolume *v = &sc->grids[m->albedo_grid];
    return grid_lookup(sc->grid_data, v, grid_point_to_local(v, p));
}

#if VOLCL_HAS_EMISSIVE_MEDIA
/* The normalized blackbody's linear sRGB colour at temperature t (kelvin): the table at
 * grid_data[at] (t_min, log(t_max / t_min), size, then size colours evenly spaced in log t),
 * interpolated linearly; nothing at or below t_min (volcl/blackbody.py). */
inline float3 blackbody_rgb(__global const float *data, int at, float t) {
    __global const float *tab = data + at;
    if (!(t > tab[0])) return (float3)(0.0f);
    float n = tab[2];
    float x = fmin(log(t / tab[0]) / tab[1] * (n - 1.0f), n - 1.0f);
    int i = min((int)x, (int)n - 2);
    float w = x - (float)i;
    return mix(vload3((size_t)i, tab + 3), vload3((size_t)i + 1, tab + 3), w);   /* i >= 0: t > t_min */
}

/* The radiance Le(p) of a heterogeneous medium (it emits sigma_a(p) Le(p) per unit length). */
inline float3 medium_grid_radiance(const SceneData *sc, __global const Medium *m, float3 p) {
    if (m->emission_mode == EMISSION_CONSTANT) return vload_f3(m->emission);
    __global const GridVolume *v = &sc->grids[m->emission_grid];
    float3 value = grid_lookup(sc->grid_data, v, grid_point_to_local(v, p));
    if (m->emission_mode == EMISSION_RADIANCE) return m->emission_scale * value;
    float t = (value.x - m->temperature_offset) * m->temperature_scale;
    return m->emission_scale * blackbody_rgb(sc->grid_data, m->blackbody, t);
}

inline bool medium_emits(__global const Medium *m) {
    return m->emission_mode != EMISSION_CONSTANT || max_component(vload_f3(m->emission)) > 0.0f;
}
#endif

/* Exponential optical depth to the next tentative collision (u < 1, so always finite). The
 * variates are multiples of 2^-24 (rng.h), so 1 - u is exact and log(1 - u) is log1p(-u) up to
 * the log's own rounding, at a lower cost than log1p. */
inline float medium_sample_tau(Rng *rng) { return -log_pos(1.0f - rng_next_float(rng)); }

/* The majorant walk both trackers share: tentative collisions along a segment through an extinction
 * grid, drawn from the piecewise-constant majorant of the cells the ray crosses (grid.h). The
 * optical depth left over at a cell's end carries into the next cell (the exponential is
 * memoryless), and every step (a cell entered or a tentative collision) counts towards
 * VOLCL_MAX_TRACKING_STEPS. */
typedef struct {
    GridWalk walk;
    float ta, tb, mu;   /* the current cell's span and its (scaled) majorant */
    float tau;          /* optical depth to the next tentative collision */
    float maj_scale;
    int steps;
    bool in_cell;
} MajorantWalk;

#define MAJORANT_END 0          /* the segment ends before the next tentative collision */
#define MAJORANT_COLLISION 1
#define MAJORANT_CUTOFF 2       /* the step bound was hit (count it: the estimate is cut short) */

/* Start a walk of grid v along o + t d, t in [0, t_max]; false when the segment misses the grid. */
inline bool majorant_walk_begin(const SceneData *sc, __global const GridVolume *v, float3 o, float3 d, float t_max,
                                Rng *rng, MajorantWalk *w) {
    float3 ol = grid_point_to_local(v, o), dl = grid_dir_to_local(v, d);
    float t0, t1;
    if (!grid_clip(ol, dl, t_max, &t0, &t1)) return false;
    w->walk = grid_walk_begin(v, ol, dl, t0, t1);
    w->maj_scale = sc->params->majorant_scale;
    w->tau = medium_sample_tau(rng);
    w->steps = 0;
    w->in_cell = false;
    return true;
}

/* The next tentative collision: its distance *t, the majorant *mu there and the extinction
 * *sigma_t looked up at it. The optical depth to the one after is drawn before returning, so
 * the caller's own random numbers come after it. */
inline int majorant_walk_next(const SceneData *sc, __global const GridVolume *v, MajorantWalk *w, Rng *rng,
                              float *t, float *mu, float3 *sigma_t) {
    for (;;) {
        if (!w->in_cell) {
            if (!grid_walk_next(&w->walk, sc->grid_data, v, &w->ta, &w->tb, &w->mu)) return MAJORANT_END;
            w->mu *= w->maj_scale;
            w->in_cell = true;
        }
        if (++w->steps > VOLCL_MAX_TRACKING_STEPS) return MAJORANT_CUTOFF;
        float span = w->mu * (w->tb - w->ta);
        if (w->tau >= span) {
            w->tau -= span;
            w->in_cell = false;
            continue;
        }
        *t = w->ta + w->tau / w->mu;
        w->ta = *t;
        w->tau = medium_sample_tau(rng);
        *mu = w->mu;
        *sigma_t = grid_lookup(sc->grid_data, v, w->walk.pe + (*t - w->walk.t0) * w->walk.dl);
        return MAJORANT_COLLISION;
    }
}

VOLCL_STEP_INLINE
inline MediumSample medium_grid_sample_distance(const SceneData *sc, __global const Medium *m, float3 o,
                                                float3 d, float t_max, float3 beta, Rng *rng,
                                                uint *cutoffs, const EmissionMis *em) {
    MediumSample ms;
    ms.t = t_max;
    ms.scattered = false;
    ms.weight = (float3)(1.0f);
    ms.emission = (float3)(0.0f);
    ms.tr = -1.0f;
    __global const GridVolume *v = &sc->grids[m->sigma_t_grid];
    MajorantWalk walk;
    if (!majorant_walk_begin(sc, v, o, d, t_max, rng, &walk)) return ms;
#if VOLCL_HAS_EMISSIVE_MEDIA
    bool emits = medium_emits(m);
#endif
    float3 w = (float3)(1.0f);      /* weight of the null collisions so far */
    float t, mu;
    float3 sigma_t;
    int event;
    while ((event = majorant_walk_next(sc, v, &walk, rng, &t, &mu, &sigma_t)) == MAJORANT_COLLISION) {
        float3 sigma_n = fmax(mu - sigma_t, 0.0f);
        float3 albedo = (float3)(-1.0f);
#if VOLCL_HAS_EMISSIVE_MEDIA
        if (emits) {
            albedo = medium_grid_albedo(sc, m, o + t * d);
#if VOLCL_HAS_EMISSION_NEE
            /* MIS against next-event estimation of the same point (emission_nee.h) */
            float mis_w = em->on ? emission_collision_weight(sc, em, m, o + t * d, mu) : 1.0f;
            if (mis_w > 0.0f) {
                /* off, the same arithmetic as without the feature (the same bits) */
                float3 e = w * sigma_t * (1.0f - albedo) * medium_grid_radiance(sc, m, o + t * d);
                ms.emission += (em->on ? e * mis_w : e) / mu;
            }
#else
            ms.emission += w * sigma_t * (1.0f - albedo) * medium_grid_radiance(sc, m, o + t * d) / mu;
#endif
        }
#endif
        float3 p = medium_channel_probs(beta * w);
        float pt = dot(p, sigma_t), pn = dot(p, sigma_n);
        /* pn = 0 only where sigma_t reaches the majorant in every carried channel (then the
         * collision is real for sure); the test keeps rounding from dividing by it */
        if (rng_next_float(rng) * (pt + pn) < pt || !(pn > 0.0f)) {
            if (albedo.x < 0.0f) albedo = medium_grid_albedo(sc, m, o + t * d);
            ms.t = t;
            ms.scattered = true;
            ms.weight = pt > 0.0f ? w * albedo * sigma_t * ((pt + pn) / (mu * pt)) : (float3)(0.0f);
            return ms;
        }
        w *= sigma_n * ((pt + pn) / (mu * pn));
        if (!(max_component(w) > 0.0f)) {
            ms.weight = (float3)(0.0f);
            return ms;
        }
    }
    if (event == MAJORANT_CUTOFF) {
        *cutoffs += 1u;
        w = (float3)(0.0f);
    }
    ms.weight = w;
    return ms;
}

/* `tr` times a ratio-tracking estimate of the transmittance of the segment [0, t_max]. Russian
 * roulette acts on the product, so a shadow ray through several media stops once the light it
 * could still carry is small; survival probability max(T) / 0.05 keeps the estimate unbiased. */
VOLCL_STEP_INLINE
inline float3 medium_grid_transmittance(const SceneData *sc, __global const Medium *m, float3 o, float3 d,
                                        float t_max, float3 tr, Rng *rng, uint *cutoffs) {
    __global const GridVolume *v = &sc->grids[m->sigma_t_grid];
    MajorantWalk walk;
    if (!majorant_walk_begin(sc, v, o, d, t_max, rng, &walk)) return tr;
    float t, mu;
    float3 sigma_t;
    int event;
    while ((event = majorant_walk_next(sc, v, &walk, rng, &t, &mu, &sigma_t)) == MAJORANT_COLLISION) {
        tr *= fmax(mu - sigma_t, 0.0f) / mu;
        float t_big = max_component(tr);
        if (t_big < VOLCL_RR_TRANSMITTANCE) {
            float q = t_big / VOLCL_RR_TRANSMITTANCE;
            if (!(rng_next_float(rng) < q)) return (float3)(0.0f);
            tr /= q;
        }
    }
    if (event == MAJORANT_CUTOFF) {
        *cutoffs += 1u;
        return (float3)(0.0f);
    }
    return tr;
}
#endif

/* Free flight through medium m from o along d, up to t_max (the next surface or the ray's end). */
VOLCL_STEP_INLINE
inline MediumSample medium_sample(const SceneData *sc, __global const Medium *m, float3 o, float3 d,
                                  float t_max, float3 beta, Rng *rng, uint *cutoffs, const EmissionMis *em) {
#if VOLCL_HAS_GRID_MEDIA
    if (m->type == MEDIUM_HETEROGENEOUS) return medium_grid_sample_distance(sc, m, o, d, t_max, beta, rng, cutoffs, em);
#endif
    float u_channel = rng_next_float(rng);
    return medium_sample_distance(m, t_max, beta, u_channel, rng_next_float(rng));
}

/* tr times the transmittance (or an unbiased estimate of it) of medium m along o + t d, t in [0, t_max]. */
VOLCL_STEP_INLINE
inline float3 medium_attenuate(const SceneData *sc, __global const Medium *m, float3 o, float3 d, float t_max,
                               float3 tr, Rng *rng, uint *cutoffs) {
#if VOLCL_HAS_GRID_MEDIA
    if (m->type == MEDIUM_HETEROGENEOUS) return medium_grid_transmittance(sc, m, o, d, t_max, tr, rng, cutoffs);
#endif
    return tr * medium_transmittance(m, t_max);
}

#endif
