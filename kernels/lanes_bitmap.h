/* The packet renderer's bitmaps in the lanes (lanes_rough.h's diffuse reflectance): textures.h's
 * bilinear lookup of a bitmap of three byte-coded
 * channels at a triangle's uv, operation for operation, its numbers in the lanes table
 * (wavefront_state.h WF_TRI_BITMAP..., WF_TRI_UV). */
#ifndef VOLCL_LANES_BITMAP_H
#define VOLCL_LANES_BITMAP_H

#ifndef VOLCL_PACKET_BITMAPS
#define VOLCL_PACKET_BITMAPS 0      /* 1: some lanes triangle reads a bitmap */
#endif

/* normalize (the library's, on the unit-scale vectors met here) */
inline V3 lanes_normalize(V3 a) { return v3_scale(a, rsqrt(lanes_dot(a, a))); }

#if VOLCL_PACKET_BITMAPS
/* A triangle's bitmap: its size, wrap mode, data and lookup-table offsets, to_uv (row-major 2x3),
 * and the triangle's uvs */
typedef struct {
    int width, height, wrap, data, lut;
    float m0, m1, m2, m3, m4, m5;
    float u0, v0, u1, v1, u2, v2;
} LanesBitmap;

inline LanesBitmap lanes_bitmap_gather(__global const float *table, int slot) {
    LanesBitmap r;
#define TV(c) table[WF_TRI_AT(c, slot)]
    r.width = as_int(TV(WF_TRI_BITMAP));
    r.height = as_int(TV(WF_TRI_BITMAP + 1));
    r.wrap = as_int(TV(WF_TRI_BITMAP + 2));
    r.data = as_int(TV(WF_TRI_BITMAP + 3));
    r.lut = as_int(TV(WF_TRI_BITMAP + 4));
    r.m0 = TV(WF_TRI_BITMAP_TO_UV);
    r.m1 = TV(WF_TRI_BITMAP_TO_UV + 1);
    r.m2 = TV(WF_TRI_BITMAP_TO_UV + 2);
    r.m3 = TV(WF_TRI_BITMAP_TO_UV + 3);
    r.m4 = TV(WF_TRI_BITMAP_TO_UV + 4);
    r.m5 = TV(WF_TRI_BITMAP_TO_UV + 5);
    r.u0 = TV(WF_TRI_UV);
    r.v0 = TV(WF_TRI_UV + 1);
    r.u1 = TV(WF_TRI_UV + 2);
    r.v1 = TV(WF_TRI_UV + 3);
    r.u2 = TV(WF_TRI_UV + 4);
    r.v2 = TV(WF_TRI_UV + 5);
#undef TV
    return r;
}

/* texture_wrap (textures.h) for every mode, chosen by selects; the integer division by `res` done
 * as a float quotient corrected by one either way (exact while |p| / res < 2^22: texel coordinates
 * of a few million texels) */
inline int lanes_wrap(int p, int res, float inv_res, int mode) {
    float fq = floor((float)p * inv_res);
    int q = (int)fq;
    int m = p - q * res;
    q = m < 0 ? q - 1 : q;
    m = m < 0 ? m + res : m;
    q = m >= res ? q + 1 : q;
    m = m >= res ? m - res : m;
    /* the floored period index: odd periods run backwards */
    int mirrored = (q & 1) ? res - 1 - m : m;
    int clamped = clamp(p, 0, res - 1);
    return mode == TEX_WRAP_CLAMP ? clamped : (mode == TEX_WRAP_MIRROR ? mirrored : m);
}

/* texel_at (textures.h): a byte-coded colour texel, already wrapped */
inline V3 lanes_texel(__global const float *texels, const LanesBitmap *r, int x, int y) {
    int at = (y * r->width + x) * 3;
    __global const uchar *bytes = (__global const uchar *)(texels + r->data) + at;
    __global const float *lut = texels + r->lut;
    return v3(lut[bytes[0]], lut[bytes[1]], lut[bytes[2]]);
}

/* bitmap_lookup (textures.h), bilinear, at the triangle's uv (texture_map_uv first) */
inline V3 lanes_bitmap(__global const float *texels, const LanesBitmap *r, float u, float v) {
    float px0 = r->m0 * u + r->m1 * v + r->m2;
    float py0 = r->m3 * u + r->m4 * v + r->m5;
    float px = texel_coordinate(px0 * (float)r->width), py = texel_coordinate(py0 * (float)r->height);
    px -= 0.5f;
    py -= 0.5f;
    float fx = floor(px), fy = floor(py);
    int x = (int)fx, y = (int)fy;
    float wx = px - fx, wy = py - fy;
    float inv_w = 1.0f / (float)r->width, inv_h = 1.0f / (float)r->height;
    int x0 = lanes_wrap(x, r->width, inv_w, r->wrap), x1 = lanes_wrap(x + 1, r->width, inv_w, r->wrap);
    int y0 = lanes_wrap(y, r->height, inv_h, r->wrap), y1 = lanes_wrap(y + 1, r->height, inv_h, r->wrap);
    V3 c00 = lanes_texel(texels, r, x0, y0), c10 = lanes_texel(texels, r, x1, y0);
    V3 c01 = lanes_texel(texels, r, x0, y1), c11 = lanes_texel(texels, r, x1, y1);
    float ax = c00.x * (1.0f - wx) + c10.x * wx, ay = c00.y * (1.0f - wx) + c10.y * wx,
          az = c00.z * (1.0f - wx) + c10.z * wx;
    float bx = c01.x * (1.0f - wx) + c11.x * wx, by = c01.y * (1.0f - wx) + c11.y * wx,
          bz = c01.z * (1.0f - wx) + c11.z * wx;
    return v3(ax * (1.0f - wy) + bx * wy, ay * (1.0f - wy) + by * wy, az * (1.0f - wy) + bz * wy);
}

/* texcoords_triangle's uv at the hit's barycentrics (as lanes_color_at computes it) */
inline void lanes_uv_at(const LanesBitmap *r, float b1, float b2, float *u, float *v) {
    float b0 = 1.0f - b1 - b2;
    *u = r->u0 * b0 + r->u1 * b1 + r->u2 * b2;
    *v = r->v0 * b0 + r->v1 * b1 + r->v2 * b2;
}

/* The bitmap at the hit's barycentrics */
inline V3 lanes_bitmap_at(__global const float *texels, const LanesBitmap *r, float b1, float b2) {
    float u, v;
    lanes_uv_at(r, b1, b2, &u, &v);
    return lanes_bitmap(texels, r, u, v);
}
#endif

#endif
