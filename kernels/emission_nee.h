/* Next-event estimation towards emissive media: a point y drawn in proportion to an upper bound of
 * sigma_a * Le over cells (volcl/emission_sampler.py builds the tables in grid_data: a medium by its
 * total bound, a cell by its bound, then uniformly in the cell), so its density per unit volume is
 * p_B(y) = p_medium * p_cell / cell volume, zero outside the cells.
 *
 * The same light is found by the path itself: the collision estimate adds sigma_a Le / mu at every
 * tentative collision (media.h). The two are combined by the power heuristic in the measure of
 * volume around y. The path's density there is that of the direction it sampled at its last vertex x
 * (pdf_dir, solid angle) times the density of collisions at distance t along it, over |y - x|^2:
 *   grid media: mu(y), the majorant at y (the rate of tentative collisions, every one of which adds
 *     emission);
 *   homogeneous media: the density of the free flight landing at y, sigma_t exp(-sigma_t s) with s
 *     the distance from where the ray entered the medium (averaged over channels when they differ).
 * Both are read from the majorants or coefficients alone, never from a transmittance estimate, so
 * the two weights are the same deterministic function of the path on both sides and sum to 1 at
 * every y: any choice of these densities keeps the estimate unbiased, and these follow what each
 * technique really samples. With MIS off, NEE takes every y it can reach (weight 1) and the collision
 * estimate only the rest (weight 1 where p_B = 0). Vertices NEE was not run from (the camera, delta
 * bsdfs) leave the collision estimate its full weight.
 */
#ifndef VOLCL_EMISSION_NEE_H
#define VOLCL_EMISSION_NEE_H

/* NEE towards emission exists only where emission does */
#if VOLCL_HAS_EMISSION_NEE && !VOLCL_HAS_EMISSIVE_MEDIA
#undef VOLCL_HAS_EMISSION_NEE
#define VOLCL_HAS_EMISSION_NEE 0
#endif

/* words of a medium's sampler block (volcl/emission_sampler.py) */
#define ES_KIND 0
#define ES_CELLS 1
#define ES_P_MEDIUM 2
#define ES_INV_VOLUME 3
#define ES_RES 4
#define ES_TO_WORLD 7
#define ES_TO_LOCAL 19
#define ES_PROBS 31
#define ES_KIND_BOX 0
#define ES_KIND_GRID 1

/* what the path's last vertex leaves the collision estimate for its MIS weight */
typedef struct {
    bool on;            /* NEE towards emissive media was run from the vertex */
    float3 x;           /* the vertex */
    float pdf_dir;      /* the solid-angle density of the direction sampled there */
} EmissionMis;

#if VOLCL_HAS_EMISSION_NEE
inline float3 es_affine(__global const float *m, float3 p) {
    return (float3)(m[0] * p.x + m[1] * p.y + m[2] * p.z + m[3],
                    m[4] * p.x + m[5] * p.y + m[6] * p.z + m[7],
                    m[8] * p.x + m[9] * p.y + m[10] * p.z + m[11]);
}

inline int3 es_res(__global const float *b) {
    return (int3)(as_int(b[ES_RES]), as_int(b[ES_RES + 1]), as_int(b[ES_RES + 2]));
}

/* The sampler's cell holding world point y, or -1 outside its cells. */
inline int emission_cell_of(__global const float *b, float3 y) {
    float3 pl = es_affine(b + ES_TO_LOCAL, y);
    if (!(pl.x >= 0.0f && pl.y >= 0.0f && pl.z >= 0.0f && pl.x <= 1.0f && pl.y <= 1.0f && pl.z <= 1.0f))
        return -1;
    int3 res = es_res(b);
    int3 c = min(convert_int3(pl * convert_float3(res)), res - 1);
    return (c.z * res.y + c.y) * res.x + c.x;
}

/* p_B(y): the density per unit volume with which emission NEE draws y in medium m. */
inline float emission_point_pdf(const SceneData *sc, __global const Medium *m, float3 y) {
    if (m->emission_sampler < 0) return 0.0f;
    __global const float *b = sc->grid_data + m->emission_sampler;
    int c = emission_cell_of(b, y);
    return c < 0 ? 0.0f : b[ES_P_MEDIUM] * b[ES_PROBS + c] * b[ES_INV_VOLUME];
}

/* The collision estimate's density at y for the medium it is in, per unit volume (see above);
 * `rate`: the majorant at y (grid media) or the landing density of the free flight (homogeneous). */
inline float emission_collision_pdf(const EmissionMis *em, float3 y, float rate) {
    float3 v = y - em->x;
    float d2 = dot(v, v);
    return d2 > 0.0f ? em->pdf_dir * rate / d2 : INFINITY;
}

/* MIS weight of the collision estimate's emission at y in medium m (rate as above). */
inline float emission_collision_weight(const SceneData *sc, const EmissionMis *em, __global const Medium *m,
                                       float3 y, float rate) {
    if (!em->on) return 1.0f;
    float p_b = emission_point_pdf(sc, m, y);
    if (!sc->params->mis) return p_b > 0.0f ? 0.0f : 1.0f;
    return power_heuristic(emission_collision_pdf(em, y, rate), p_b);
}

/* Density of a homogeneous medium's free flight landing at distance s from where it started,
 * averaged over the colour channels (a deterministic stand-in for the throughput-weighted mixture
 * that media.h samples when the channels differ; the same number for the exact grey case). */
inline float medium_landing_density(__global const Medium *m, float s) {
    float3 st = vload_f3(m->sigma_t);
    float3 d = st * transmittance_exp(st, s);
    return (d.x + d.y + d.z) * (1.0f / 3.0f);
}

/* A point drawn by emission NEE. */
typedef struct {
    float3 y;
    int medium;
    int cell;
    float pdf;          /* p_B(y), per unit volume */
} EmissionPoint;

/* Index i with cdf[i] <= u < cdf[i + 1] (cdf from 0 to 1 over n intervals; empty ones never chosen). */
inline int es_find(__global const float *cdf, int n, float u) {
    int lo = 0, hi = n;
    while (hi - lo > 1) {
        int mid = (lo + hi) >> 1;
        if (cdf[mid] <= u) lo = mid; else hi = mid;
    }
    return lo;
}

/* Draw y from the scene's table (at grid_data[table]) with five uniform numbers. */
inline bool emission_sample_point(const SceneData *sc, int table, float u_medium, float u_cell, float3 u_point,
                                  EmissionPoint *ep) {
    __global const float *t = sc->grid_data + table;
    int count = as_int(t[0]);
    int k = 0;
    while (k < count - 1 && !(u_medium < t[2 + 2 * k])) ++k;
    ep->medium = as_int(t[1 + 2 * k]);
    __global const Medium *m = &sc->media[ep->medium];
    __global const float *b = sc->grid_data + m->emission_sampler;
    int n = as_int(b[ES_CELLS]);
    ep->cell = es_find(b + ES_PROBS + n, n, u_cell);
    float p = b[ES_P_MEDIUM] * b[ES_PROBS + ep->cell] * b[ES_INV_VOLUME];
    if (!(p > 0.0f)) return false;
    int3 res = es_res(b);
    int c = ep->cell;
    float3 cell = (float3)((float)(c % res.x), (float)((c / res.x) % res.y), (float)(c / (res.x * res.y)));
    ep->y = es_affine(b + ES_TO_WORLD, (cell + u_point) / convert_float3(res));
    ep->pdf = p;
    return true;
}
#endif

#endif
