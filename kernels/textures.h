/* Texture lookups with Mitsuba 3.9's conventions (src/textures/bitmap.cpp, checkerboard.cpp and
 * Dr.Jit's texture sampling):
 *  - uv is first mapped by the texture's to_uv; u runs along the image's width and v down its
 *    rows from the top (row 0 is the first row of the file);
 *  - texel (x, y) covers [x, x + 1) / width: bilinear lookups interpolate between texel centres,
 *    at uv * size - 0.5, nearest ones take floor(uv * size);
 *  - wrap modes act on integer texel coordinates: repeat, mirror (edges repeated once: ..., 1, 0,
 *    0, 1, ...) and clamp;
 *  - a colour parameter reads a one-channel bitmap as grey; a float parameter reads a colour
 *    bitmap's luminance, a constant colour's channel mean;
 *  - a checkerboard picks color0 where the fractional parts of u and v lie on the same side of
 *    1/2 for a colour parameter, and color1 there for a float parameter (Mitsuba's eval_1 swaps
 *    the two; kept, since files render with it). Checkerboards may nest: the colours are textures.
 */
#ifndef VOLCL_TEXTURES_H
#define VOLCL_TEXTURES_H

/* textures nested deeper than this (checkerboards of checkerboards) read as black */
#define VOLCL_MAX_TEXTURE_NESTING 8

inline int texture_wrap(int p, int res, int mode) {
    if (mode == TEX_WRAP_CLAMP) return clamp(p, 0, res - 1);
    int m = p % res;
    if (m < 0) m += res;
    if (mode == TEX_WRAP_MIRROR) {
        /* the period index, floored: odd periods run backwards */
        int period = (p < 0 ? p + 1 : p) / res - (p < 0 ? 1 : 0);
        if (period & 1) m = res - 1 - m;
    }
    return m;
}

inline float2 texture_map_uv(__global const Texture *t, float2 uv) {
    return (float2)(t->to_uv[0] * uv.x + t->to_uv[1] * uv.y + t->to_uv[2],
                    t->to_uv[3] * uv.x + t->to_uv[4] * uv.y + t->to_uv[5]);
}

/* texel (x, y), already wrapped, as a colour (one channel: grey) */
inline float3 texel_at(const SceneData *sc, __global const Texture *t, int x, int y) {
    int at = (y * t->width + x) * t->channels;
    if (t->lut >= 0) {
        /* a quarter of the float texels' memory, which a textured scene's lookups missed in cache */
        __global const uchar *b = (__global const uchar *)(sc->texels + t->data) + at;
        __global const float *lut = sc->texels + t->lut;
        return t->channels == 1 ? (float3)(lut[b[0]]) : (float3)(lut[b[0]], lut[b[1]], lut[b[2]]);
    }
    __global const float *p = sc->texels + t->data + at;
    return t->channels == 1 ? (float3)(p[0]) : (float3)(p[0], p[1], p[2]);
}

/* texel (x, y) after wrapping */
inline float3 texel_fetch(const SceneData *sc, __global const Texture *t, int x, int y) {
    return texel_at(sc, t, texture_wrap(x, t->width, t->wrap), texture_wrap(y, t->height, t->wrap));
}

/* the texels (x, y), (x + 1, y), (x, y + 1) and (x + 1, y + 1) of a bilinear lookup, the two
 * columns and rows wrapped once each (a wrap is an integer division), not once per texel */
inline void texel_square(const SceneData *sc, __global const Texture *t, int x, int y, float3 *c00, float3 *c10,
                         float3 *c01, float3 *c11) {
    int x0 = texture_wrap(x, t->width, t->wrap), x1 = texture_wrap(x + 1, t->width, t->wrap);
    int y0 = texture_wrap(y, t->height, t->wrap), y1 = texture_wrap(y + 1, t->height, t->wrap);
    *c00 = texel_at(sc, t, x0, y0);
    *c10 = texel_at(sc, t, x1, y0);
    *c01 = texel_at(sc, t, x0, y1);
    *c11 = texel_at(sc, t, x1, y1);
}

/* continuous texel coordinates, kept in the range where int conversion is defined (float32 has no
 * fractional digits there anyway) */
inline float texel_coordinate(float c) { return clamp(c, -16777216.0f, 16777216.0f); }

inline float3 bitmap_lookup(const SceneData *sc, __global const Texture *t, float2 uv) {
    float2 p = texture_map_uv(t, uv);
    float px = texel_coordinate(p.x * (float)t->width), py = texel_coordinate(p.y * (float)t->height);
    if (t->filter == TEX_FILTER_NEAREST) {
        float nx = floor(px), ny = floor(py);
        return texel_fetch(sc, t, (int)nx, (int)ny);
    }
    px -= 0.5f;
    py -= 0.5f;
    float fx = floor(px), fy = floor(py);
    int x = (int)fx, y = (int)fy;
    float wx = px - fx, wy = py - fy;
    float3 c00, c10, c01, c11;
    texel_square(sc, t, x, y, &c00, &c10, &c01, &c11);
    float3 a = c00 * (1.0f - wx) + c10 * wx;
    float3 b = c01 * (1.0f - wx) + c11 * wx;
    return a * (1.0f - wy) + b * wy;
}

/* The leaf a (possibly nested) checkerboard picks at uv: a bitmap's index, or -1 with *fixed
 * set. as_float: the pick of a float parameter. */
inline int texture_leaf(const SceneData *sc, int index, float2 uv, bool as_float, float3 *fixed) {
    for (int depth = 0; depth < VOLCL_MAX_TEXTURE_NESTING; ++depth) {
        __global const Texture *t = &sc->textures[index];
        if (t->type == TEX_BITMAP) return index;
        float2 p = texture_map_uv(t, uv);
        bool hx = p.x - floor(p.x) > 0.5f, hy = p.y - floor(p.y) > 0.5f;
        bool first = as_float ? hx != hy : hx == hy;
        int child = first ? t->child0 : t->child1;
        if (child < 0) {
            *fixed = first ? (as_float ? (float3)(t->mean0) : vload_f3(t->color0))
                              : (as_float ? (float3)(t->mean1) : vload_f3(t->color1));
            return -1;
        }
        index = child;
    }
    *fixed = (float3)(0.0f);
    return -1;
}

/* A colour parameter: `fixed` where index < 0, else texture `index` at uv. */
inline float3 texture_eval3(const SceneData *sc, int index, float3 fixed, float2 uv) {
#if VOLCL_HAS_TEXTURES
    if (index < 0) return fixed;
    index = texture_leaf(sc, index, uv, false, &fixed);
    return index < 0 ? fixed : bitmap_lookup(sc, &sc->textures[index], uv);
#else
    return fixed;
#endif
}

/* A float parameter (roughness, opacity). */
inline float texture_eval1(const SceneData *sc, int index, float fixed, float2 uv) {
#if VOLCL_HAS_TEXTURES
    if (index < 0) return fixed;
    float3 c;
    index = texture_leaf(sc, index, uv, true, &c);
    if (index < 0) return c.x;
    __global const Texture *t = &sc->textures[index];
    float3 v = bitmap_lookup(sc, t, uv);
    return t->channels == 1 ? v.x : luminance(v);
#else
    return fixed;
#endif
}

#if VOLCL_HAS_BUMP_MAPS
/* Gradient in uv of a float bitmap (bump maps), as Mitsuba's eval_1_grad computes it: the bilinear
 * interpolant's derivatives in texel units, through the transpose of to_uv's linear part, then
 * scaled by the resolution (after the transpose, not before: Mitsuba's order, which differs where
 * to_uv rotates a non-square image). Zero for nearest lookups. */
inline float2 texture_grad1(const SceneData *sc, int index, float2 uv) {
    __global const Texture *t = &sc->textures[index];
    if (t->type != TEX_BITMAP || t->filter == TEX_FILTER_NEAREST) return (float2)(0.0f);
    float2 p = texture_map_uv(t, uv);
    float px = texel_coordinate(p.x * (float)t->width) - 0.5f, py = texel_coordinate(p.y * (float)t->height) - 0.5f;
    float fx = floor(px), fy = floor(py);
    int x = (int)fx, y = (int)fy;
    float w1x = px - fx, w1y = py - fy, w0x = 1.0f - w1x, w0y = 1.0f - w1y;
    float3 c00, c10, c01, c11;
    texel_square(sc, t, x, y, &c00, &c10, &c01, &c11);
    float f00 = t->channels == 1 ? c00.x : luminance(c00), f10 = t->channels == 1 ? c10.x : luminance(c10);
    float f01 = t->channels == 1 ? c01.x : luminance(c01), f11 = t->channels == 1 ? c11.x : luminance(c11);
    float dx = w0y * (f10 - f00) + w1y * (f11 - f01);
    float dy = w0x * (f01 - f00) + w1x * (f11 - f10);
    float du = t->to_uv[0] * dx + t->to_uv[3] * dy, dv = t->to_uv[1] * dx + t->to_uv[4] * dy;
    return (float2)(du * (float)t->width, dv * (float)t->height);
}
#endif

#endif
