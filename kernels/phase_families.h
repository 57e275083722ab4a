/* Phase functions beyond HG (VOLCL_HAS_PHASE_FAMILIES), as mixtures of lobes: a medium's phase is
 * the PhaseLobe records [phase_lobe, phase_lobe + phase_lobe_count) with weights summing to one
 * (blends and the approximate Mie are flattened into such mixtures on the host, volcl/phase.py).
 *
 * Sampling a mixture picks a lobe by weight (one extra random number when there are several) and
 * samples it; the value and the pdf of the returned direction are then the weighted sums over
 * all lobes, evaluated from the direction itself, so phase_lobes_sample's pdf is exactly what
 * phase_lobes_eval gives the same direction (as MIS needs), and weight = value / pdf is 1 for
 * every mixture of exactly sampled lobes.
 *
 * The lobes, each with cos = dot(d_in, d_out):
 *  - HG: as in phase.h.
 *  - Rayleigh, 3 / (16 pi) (1 + cos^2): the CDF (cos^3 + 3 cos + 4) / 8 inverted by Cardano's
 *    formula (phase_rayleigh_sample_cos).
 *  - Draine (2003), HG(g) (1 + alpha cos^2) / (1 + alpha (1 + 2 g^2) / 3), alpha >= 0 (Cornette-
 *    Shanks is alpha = 1): rejection sampling from the exact HG sampler, accepting a proposal with
 *    probability (1 + alpha cos^2) / (1 + alpha). The accepted samples follow the Draine density
 *    exactly, with phase.h's HG accuracy at every g (the closed-form inversion of Jendersie and
 *    d'Eon divides by g and cancels near |g| = 1 in float32); the expected number of proposals,
 *    (1 + alpha) / (1 + alpha (1 + 2 g^2) / 3), is below 3 for any g and alpha. After
 *    PHASE_DRAINE_MAX_TRIALS proposals the last one is kept: that changes the density by less
 *    than (2/3)^63 < 1e-11 of itself.
 *  - tabulated (Mitsuba's tabphase): a piecewise-linear density over cos, sampled exactly.
 *  - Fournier-Forand: the closed form of volcl/phase.py (FournierForand.pdf) in float32, in
 *    s = sin^2(theta / 2) = w_fwd / 2, which keeps the digits of the singular forward peak
 *    (p ~ s^(a - 1)). Its CDF has no closed-form inverse, so directions come from a
 *    piecewise-linear table of the density of x = s^a (bounded on [0, 1] where the density in s
 *    is not), and the pdf is that table's: pdf = table(x) * (bin's CDF share / the line's
 *    integral over the bin, 1 up to float32 rounding) * a s^(a - 1) / (4 pi). value / pdf stays
 *    within the table's tolerance of 1 (1e-3 by default, measured on the host). Below
 *    s = PHASE_FF_S_MIN directions are d_in itself; the table's first bin holds exactly the value's
 *    probability there (0.07% of the lobe for mu = 3.58, most of it as mu -> 3) and the lobe counts
 *    value = pdf at it.
 */
#ifndef VOLCL_PHASE_FAMILIES_H
#define VOLCL_PHASE_FAMILIES_H

#define PHASE_DRAINE_MAX_TRIALS 64
/* Smallest s = sin^2(theta / 2) the Fournier-Forand lobe is evaluated at: angles below 6e-7 rad,
 * where float32 unit vectors cannot tell d_out from d_in (two roundings of the same direction are up
 * to s ~ 1e-14 apart), count as exactly forward. */
#define PHASE_FF_S_MIN 1e-13f

/* The scattering angle three ways, each accurate where it is small: 1 - cos, 1 + cos, cos. */
typedef struct {
    float w_fwd, w_back, cos;
} PhaseGeometry;

inline PhaseGeometry phase_geometry(float3 d_in, float3 d_out) {
    float3 a = d_in - d_out, b = d_in + d_out;
    PhaseGeometry pg;
    pg.w_fwd = 0.5f * dot(a, a);
    pg.w_back = 0.5f * dot(b, b);
    pg.cos = pg.w_fwd <= 1.0f ? 1.0f - pg.w_fwd : pg.w_back - 1.0f;
    return pg;
}

/* ---- piecewise-linear tables: knots x, densities y, CDF c (size entries each) ---- */

/* The largest j in [0, size - 2] with v[j] <= t, for increasing v with v[0] <= t. */
inline int phase_table_find(const __global float *v, int size, float t) {
    int lo = 0, hi = size - 2;
    while (lo < hi) {
        int mid = (lo + hi + 1) >> 1;
        if (v[mid] <= t) lo = mid; else hi = mid - 1;
    }
    return lo;
}

/* A position distributed as the table's density, for u in [0, 1): the bin by the CDF, then the
 * position within it by inverting the line's integral (written without cancellation). */
inline float phase_table_sample(const __global float *tab, int size, float u) {
    const __global float *x = tab, *y = tab + size, *c = tab + 2 * size;
    int j = phase_table_find(c, size, u);
    float y0 = y[j], y1 = y[j + 1];
    float share = clamp((u - c[j]) / (c[j + 1] - c[j]), 0.0f, 1.0f);
    float r = share * 0.5f * (y0 + y1);
    float den = y0 + sqrt(fmax(y0 * y0 + 2.0f * r * (y1 - y0), 0.0f));
    float tau = den > 0.0f ? clamp(2.0f * r / den, 0.0f, 1.0f) : 0.0f;
    return x[j] + tau * (x[j + 1] - x[j]);
}

/* The table's density at t, with *scale: the bin's share of the CDF over the line's integral
 * (what the sampler's density is in units of the line). */
inline float phase_table_density(const __global float *tab, int size, float t, float *scale) {
    const __global float *x = tab, *y = tab + size, *c = tab + 2 * size;
    t = clamp(t, x[0], x[size - 1]);
    int j = phase_table_find(x, size, t);
    float dx = x[j + 1] - x[j];
    float f = dx > 0.0f ? clamp((t - x[j]) / dx, 0.0f, 1.0f) : 0.0f;
    float line = 0.5f * (y[j] + y[j + 1]) * dx;
    *scale = line > 0.0f ? (c[j + 1] - c[j]) / line : 0.0f;
    return y[j] + f * (y[j + 1] - y[j]);
}

/* ---- the lobes ---- */

inline float phase_rayleigh_eval(float c) { return (3.0f / (16.0f * VOLCL_PI)) * (1.0f + c * c); }

/* The cube root of v in [1, 2 + sqrt(5)]: a quadratic start within 1.4% and two Newton steps, to
 * 2 ulp (PoCL's cbrt is several times slower). */
inline float phase_rayleigh_cbrt(float v) {
    float A = (-0.02568702f * v + 0.31866124f) * v + 0.72097468f;
    A = (2.0f * A + v / (A * A)) * (1.0f / 3.0f);
    return (2.0f * A + v / (A * A)) * (1.0f / 3.0f);
}

/* cos^3 + 3 cos = 2z with z = 4u - 2 has the one real root A - 1/A, A = cbrt(z + sqrt(z^2 + 1));
 * taken for |z| (and the sign put back) so that z + sqrt(z^2 + 1) never cancels. */
inline float phase_rayleigh_sample_cos(float u) {
    float z = 4.0f * u - 2.0f;
    float A = phase_rayleigh_cbrt(fabs(z) + sqrt(z * z + 1.0f));
    return copysign(clamp(A - 1.0f / A, 0.0f, 1.0f), z);
}

inline float phase_draine_eval(__global const PhaseLobe *l, const PhaseGeometry *pg) {
    float g = l->p[0];
    return phase_hg_eval_w(g, g >= 0.0f ? pg->w_fwd : pg->w_back) * (1.0f + l->p[1] * pg->cos * pg->cos) * l->p[2];
}

inline float3 phase_draine_sample(__global const PhaseLobe *l, float3 d_in, float2 u, Rng *rng) {
    float g = l->p[0], alpha = l->p[1];
    float w = 0.0f;
    for (int k = 0;; ++k) {
        w = phase_hg_sample_w(fabs(g), u.x);
        float c = 1.0f - w;     /* cosine to the peak, +-cos */
        if (k == PHASE_DRAINE_MAX_TRIALS - 1 || rng_next_float(rng) * (1.0f + alpha) < 1.0f + alpha * c * c) break;
        u = rng_next_float2(rng);
    }
    return phase_direction_at(g >= 0.0f ? d_in : -d_in, w, u.y);
}

/* Fournier-Forand's value at s = sin^2(theta / 2) (volcl/phase.py FournierForand.pdf), and in
 * *pdf the density phase_ff_sample_s gives it. With delta = q s, L = ln delta and P = delta^a, the
 * exponentials of the closed form are all P, delta and expm1's of aL and (a - 1)L: one log, one
 * exp, and an expm1 only where the plain difference would cancel. */
inline float phase_ff_eval_pdf(const SceneData *sc, __global const PhaseLobe *l, float s, float *pdf) {
    float a = l->p[0], q = l->p[1];
    s = fmax(s, PHASE_FF_S_MIN);
    float delta = q * s;
    float L = log(delta);
    float P = exp(a * L);
    float ratio;            /* D(L) / expm1(L)^2 */
    if (fabs(L) < 0.5f) {
        /* a (1 - a) S / (expm1(L) / L)^2, S = sum_{m >= 2} (a^(m-1) - (a-1)^(m-1)) L^(m-2) / m!
         * (to m = 9: the rest is below 1e-7 of S for |L| < 1/2); delta - 1 is expm1(L) of the
         * rounded delta whose log L is, exactly */
        float pa = a, pb = a - 1.0f, fact = 2.0f, pl = 1.0f, S = 0.5f;
        for (int m = 3; m <= 9; ++m) {
            pa *= a;
            pb *= a - 1.0f;
            fact *= (float)m;
            pl *= L;
            S += (pa - pb) * pl / fact;
        }
        float e = L != 0.0f ? (delta - 1.0f) / L : 1.0f;
        ratio = a * (1.0f - a) * S / (e * e);
    } else {
        /* D = (1 - a) expm1(aL) + a expm1((a - 1)L): the two terms have opposite signs and D is
         * their difference (within a factor 4 of either, for |L| >= 1/2), so each needs its digits:
         * P - 1 keeps them to eps / 0.1 where |aL| >= 0.1, expm1 (costly) below */
        float ea = fabs(a * L) < 0.1f ? expm1(a * L) : P - 1.0f;
        float eb = fabs((a - 1.0f) * L) < 0.1f ? expm1((a - 1.0f) * L) : P / delta - 1.0f;
        float e = delta - 1.0f;
        ratio = ((1.0f - a) * ea + a * eb) / (e * e);
    }
    float c = 1.0f - 2.0f * s;
    float value = ((q - 1.0f) * ratio + a * (P / delta)) * VOLCL_INV_4PI + l->p[2] * (3.0f * c * c - 1.0f);
    /* the table holds the density of x = s^a = P q^-a; dx / dOmega = a s^(a - 1) / (4 pi) = a (x / s) / (4 pi) */
    float x = P * l->p[3], scale;
    float y = phase_table_density(sc->phase_tables + l->table, l->table_size, x, &scale);
    *pdf = y * scale * a * (x / s) * VOLCL_INV_4PI;
    /* below the floor the lobe is its table's first bin, which holds the value's own probability
     * there (volcl/phase.py): value = pdf keeps its weight exactly 1 (float32 values at the floor
     * differ from the table's by ~1e-5, and near mu = 3 most samples land there) */
    return s > PHASE_FF_S_MIN ? value : *pdf;
}

inline float phase_ff_sample_s(const SceneData *sc, __global const PhaseLobe *l, float u) {
    float x = phase_table_sample(sc->phase_tables + l->table, l->table_size, u);
    return x > 0.0f ? fmin(exp(log(x) / l->p[0]), 1.0f) : 0.0f;
}

/* A lobe's value towards the direction pg describes; *pdf: the density its sampler gives it. */
inline float phase_lobe_eval(const SceneData *sc, __global const PhaseLobe *l, const PhaseGeometry *pg, float *pdf) {
    float v;
    switch (l->type) {
    case LOBE_HG:
        v = phase_hg_eval_w(l->p[0], l->p[0] >= 0.0f ? pg->w_fwd : pg->w_back);
        break;
    case LOBE_RAYLEIGH:
        v = phase_rayleigh_eval(pg->cos);
        break;
    case LOBE_DRAINE:
        v = phase_draine_eval(l, pg);
        break;
    case LOBE_TABULATED: {
        float scale;
        v = phase_table_density(sc->phase_tables + l->table, l->table_size, pg->cos, &scale) * (0.5f * VOLCL_INV_PI);
        break;
    }
    case LOBE_FOURNIER_FORAND:
        return phase_ff_eval_pdf(sc, l, 0.5f * pg->w_fwd, pdf);
    default:
        v = VOLCL_INV_4PI;
    }
    *pdf = v;
    return v;
}

inline float3 phase_lobe_sample(const SceneData *sc, __global const PhaseLobe *l, float3 d_in, float2 u, Rng *rng) {
    switch (l->type) {
    case LOBE_HG: {
        float g = l->p[0];
        return phase_direction_at(g >= 0.0f ? d_in : -d_in, phase_hg_sample_w(fabs(g), u.x), u.y);
    }
    case LOBE_RAYLEIGH:
        return phase_direction_at(d_in, 1.0f - phase_rayleigh_sample_cos(u.x), u.y);
    case LOBE_DRAINE:
        return phase_draine_sample(l, d_in, u, rng);
    case LOBE_TABULATED:
        return phase_direction_at(d_in, 1.0f - phase_table_sample(sc->phase_tables + l->table, l->table_size, u.x),
                                  u.y);
    case LOBE_FOURNIER_FORAND:
        return phase_direction_at(d_in, 2.0f * phase_ff_sample_s(sc, l, u.x), u.y);
    default:
        return sample_uniform_sphere(u);
    }
}

/* ---- mixtures ---- */

inline float phase_lobes_eval(const SceneData *sc, __global const Medium *m, float3 d_in, float3 d_out, float *pdf) {
    PhaseGeometry pg = phase_geometry(d_in, d_out);
    __global const PhaseLobe *lobes = sc->phase_lobes + m->phase_lobe;
    float v = 0.0f, p = 0.0f;
    for (int i = 0; i < m->phase_lobe_count; ++i) {
        float pi;
        float vi = phase_lobe_eval(sc, &lobes[i], &pg, &pi);
        v += lobes[i].weight * vi;
        p += lobes[i].weight * pi;
    }
    *pdf = p;
    return v;
}

inline float phase_lobes_sample(const SceneData *sc, __global const Medium *m, float3 d_in, float2 u, Rng *rng,
                                float3 *d_out, float *weight) {
    __global const PhaseLobe *lobes = sc->phase_lobes + m->phase_lobe;
    int n = m->phase_lobe_count, k = 0;
    if (n > 1) {
        float pick = rng_next_float(rng), acc = 0.0f;
        for (; k < n - 1; ++k) {
            acc += lobes[k].weight;
            if (pick < acc) break;
        }
    }
    *d_out = phase_lobe_sample(sc, &lobes[k], d_in, u, rng);
    float pdf;
    float v = phase_lobes_eval(sc, m, d_in, *d_out, &pdf);
    *weight = pdf > 0.0f ? v / pdf : 0.0f;
    return pdf;
}

#endif
