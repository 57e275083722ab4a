/* Environment maps with Mitsuba 3.9's meaning (src/emitters/envmap.cpp): a latitude-longitude image
 * at infinity, bilinearly filtered, importance sampled by the bilinear interpolant of its luminance
 * times sin(theta).
 *
 * The frame. Light.to_local turns world directions into the map's frame, where direction d has
 * theta = acos(d.y) (the image's top row is the +y pole) and phi = atan2(d.x, -d.z); image
 * coordinates u = phi / (2 pi) wrapped into [0, 1), v = theta / pi: the left edge of the image looks
 * along -z, a quarter across along +x, the middle along +z. As in Mitsuba, columns are
 * texel-centred and periodic (texel i at u = (i + 0.5) / W) and rows sit on the poles (row j at
 * v = j / (H - 1)), whatever the image's aspect ratio. Patch coordinates x = u W - 0.5 (mod W) and
 * y = v (H - 1): patch (i, j) spans texel columns i and i + 1 (mod W) and rows j and j + 1, and
 * (s, t) = (x - i, y - j) is the point's place in it. Lookups and sampling share these coordinates.
 *
 * Tables at env_data + Light.env_data, for an image of W x H texels (volcl/envmap.py writes them):
 *   texels  3 W H        linear RGB times `scale`, row by row from the +y pole
 *   nodes   (W + 1) H    luminance x sin(theta) per texel, the first column repeated at the end
 *   cond    W (H - 1)    per row of patches, the normalized CDF of the patch masses (mean of 4 nodes)
 *   marg    H - 1        the normalized CDF of the rows' masses
 *   guides  W (H - 1)    per row, where the search of cond starts (sample_discrete_cdf_guided)
 *           H - 1        the same for marg
 * Density: a patch is picked with the probability its two CDF steps give, then a point in it with the
 * density of the bilinear interpolant of its nodes. The pdf is evaluated from the same CDF steps, so
 * it is the sampler's own density even where float32 rounding makes a step differ from the patch's
 * exact share, or vanish (such a patch is then never sampled and has pdf 0: MIS leaves it to BSDF and
 * phase sampling). Without float rounding it is Mitsuba's density (its Hierarchical2D warp), in solid
 * angle: p(u, v) / (2 pi^2 sin theta).
 */
#ifndef VOLCL_ENVMAP_H
#define VOLCL_ENVMAP_H

typedef struct {
    int i, j;       /* the patch */
    float s, t;     /* the place in it, each in [0, 1] */
} EnvPatch;

/* The patch of a unit direction in the map's frame, whose sin(theta) is sin_theta. */
inline EnvPatch envmap_patch(__global const Light *l, float3 d, float sin_theta) {
    int w = l->env_res[0], h = l->env_res[1];
    float u = atan2_full(d.x, -d.z) * (0.5f * VOLCL_INV_PI);
    /* not acos(d.y): near the poles a float32 d.y holds theta to only ~ulp / sin(theta) (0.5% of
     * the first row's patch at 0.2 degrees from the pole of a 6-row map) */
    float v = atan2_upper(sin_theta, d.y) * VOLCL_INV_PI;
    float x = u * (float)w - 0.5f;
    if (x < 0.0f) x += (float)w;
    EnvPatch p;
    p.i = clamp((int)x, 0, w - 1);      /* x + w can round up to w itself */
    p.s = clamp(x - (float)p.i, 0.0f, 1.0f);
    float y = v * (float)(h - 1);
    p.j = clamp((int)y, 0, h - 2);
    p.t = clamp(y - (float)p.j, 0.0f, 1.0f);
    return p;
}

/* i, j >= 0: texel indices within the map */
inline float3 envmap_texel(__global const float *texels, int w, int i, int j) {
    return vload3((size_t)j * (size_t)w + (size_t)i, texels);
}

/* Radiance of the map at a patch point: the bilinear lookup, periodic across the seam. */
inline float3 envmap_value(const SceneData *sc, __global const Light *l, EnvPatch p) {
    int w = l->env_res[0];
    __global const float *texels = sc->env_data + l->env_data;
    int i1 = p.i + 1 < w ? p.i + 1 : 0;
    float3 top = mix(envmap_texel(texels, w, p.i, p.j), envmap_texel(texels, w, i1, p.j), p.s);
    float3 bottom = mix(envmap_texel(texels, w, p.i, p.j + 1), envmap_texel(texels, w, i1, p.j + 1), p.s);
    return mix(top, bottom, p.t);
}

/* Solid-angle density of sampling the patch point p, whose direction has sin(theta) = sin_theta. */
inline float envmap_patch_pdf(const SceneData *sc, __global const Light *l, EnvPatch p, float sin_theta) {
    int w = l->env_res[0], h = l->env_res[1];
    __global const float *node = sc->env_data + l->env_data + 3 * w * h;
    __global const float *cond = node + (w + 1) * h;
    __global const float *marg = cond + w * (h - 1);
    __global const float *row = cond + p.j * w;
    float pick = (marg[p.j] - (p.j > 0 ? marg[p.j - 1] : 0.0f)) * (row[p.i] - (p.i > 0 ? row[p.i - 1] : 0.0f));
    __global const float *n0 = node + p.j * (w + 1) + p.i;
    __global const float *n1 = n0 + (w + 1);
    float mass = 0.25f * (n0[0] + n0[1] + n1[0] + n1[1]);
    float bil = mix(mix(n0[0], n0[1], p.s), mix(n1[0], n1[1], p.s), p.t);
    if (!(mass > 0.0f) || !(bil > 0.0f)) return 0.0f;
    return pick * (bil / mass) * l->env_norm / fmax(sin_theta, 1e-30f);
}

/* Radiance arriving from world direction `d` (pointing away from the scene) and the density with
 * which envmap_sample draws that direction. */
inline float3 envmap_eval(const SceneData *sc, __global const Light *l, float3 d, float *pdf) {
    float3 dl = mat3_apply(l->to_local, d);
    float sin_theta = sqrt(dl.x * dl.x + dl.z * dl.z);
    EnvPatch p = envmap_patch(l, dl, sin_theta);
    *pdf = envmap_patch_pdf(sc, l, p, sin_theta);
    return envmap_value(sc, l, p);
}

/* x in [0, 1) with density proportional to (1 - x) a + x b (a, b >= 0, not both 0): the root of the
 * quadratic CDF in the form that neither cancels nor divides by b - a. */
inline float sample_linear(float u, float a, float b) {
    float m = fmax(a, b);
    if (!(m > 0.0f)) return u;
    a /= m;     /* keeps the squares below from overflowing */
    b /= m;
    float x = u * (a + b) / (a + sqrt(mix(a * a, b * b, u)));
    return fmin(x, 0x1.fffffep-1f);
}

/* u rescaled to [0, 1) within the CDF step [lo, hi) that it fell into. */
inline float cdf_remap(float u, float lo, float hi) {
    return clamp((u - lo) / (hi - lo), 0.0f, 0x1.fffffep-1f);
}

/* A world direction towards the map with its radiance and solid-angle density; false for a map
 * without light. */
inline bool envmap_sample(const SceneData *sc, __global const Light *l, float2 u, float3 *wi, float3 *value,
                          float *pdf) {
    if (!(l->env_norm > 0.0f)) return false;
    int w = l->env_res[0], h = l->env_res[1];
    __global const float *node = sc->env_data + l->env_data + 3 * w * h;
    __global const float *cond = node + (w + 1) * h;
    __global const float *marg = cond + w * (h - 1);
    __global const float *cond_guide = marg + (h - 1);
    __global const float *marg_guide = cond_guide + w * (h - 1);
    EnvPatch p;
    p.j = sample_discrete_cdf_guided(marg, marg_guide, h - 1, u.y);
    float uy = cdf_remap(u.y, p.j > 0 ? marg[p.j - 1] : 0.0f, marg[p.j]);
    __global const float *row = cond + p.j * w;
    p.i = sample_discrete_cdf_guided(row, cond_guide + p.j * w, w, u.x);
    float ux = cdf_remap(u.x, p.i > 0 ? row[p.i - 1] : 0.0f, row[p.i]);
    __global const float *n0 = node + p.j * (w + 1) + p.i;
    __global const float *n1 = n0 + (w + 1);
    /* the bilinear patch: its marginal in t, then s given t */
    p.t = sample_linear(uy, n0[0] + n0[1], n1[0] + n1[1]);
    p.s = sample_linear(ux, mix(n0[0], n1[0], p.t), mix(n0[1], n1[1], p.t));
    /* the azimuth in turns, in [0, 1 + 1/(2 w)): sincos_turn's exact quarter-turn reduction holds
     * to 1.125 */
    float turns = ((float)p.i + p.s + 0.5f) / (float)w;
    float theta = VOLCL_PI * (((float)p.j + p.t) / (float)(h - 1));
    float cos_t, sin_t = sincos_upper(theta, &cos_t);
    float cos_p, sin_p = sincos_turn(turns, &cos_p);
    float3 dl = (float3)(sin_p * sin_t, cos_t, -cos_p * sin_t);
    *pdf = envmap_patch_pdf(sc, l, p, sin_t);
    if (!(*pdf > 0.0f)) return false;
    *wi = mat3_apply_transposed(l->to_local, dl);
    *value = envmap_value(sc, l, p);
    return true;
}

#endif
