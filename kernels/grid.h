/* Grid volumes: lookups with Mitsuba 3's conventions, and the walk over the coarse majorant grid.
 *
 * Frames: a grid fills the unit cube [0,1]^3 of its local frame, and to_local maps world points
 * there. The local direction (the linear part of to_local applied to a unit world direction) is not
 * normalized, so the ray parameter t is the world distance in both frames and every coefficient
 * stays per unit of world length, as in Mitsuba (sigma_t values do not change with to_world).
 *
 * Voxel centres (Mitsuba 3's gridvolume, a Dr.Jit texture with the default clamp wrap mode, checked
 * against Mitsuba 3.9.1): along an axis of `res` voxels, voxel i holds the value at local
 * coordinate (i + 0.5) / res. Trilinear lookups interpolate between voxel centres; between the
 * outermost centre and the cube's face (and beyond it) the value is the outermost voxel's (clamp to
 * edge). Nearest lookups return voxel floor(x * res), clamped to the grid. For a 4-voxel row
 * [1 2 3 4]: trilinear gives 1 at x = 0.1, 2.5 at x = 0.5, 4 at x = 0.9; nearest gives 3 at x = 0.5.
 *
 * A medium's density is zero outside its extinction grid's cube even though lookups clamp: tracking
 * only runs on the part of a ray inside the cube, which is how Mitsuba 3 bounds a heterogeneous
 * medium (by its sigma_t volume's bounding box). Albedo lookups simply clamp.
 *
 * Sparse grids (OpenVDB and NanoVDB files) use the same conventions over a box padded with one
 * brick of the grid's background on every side (volcl/vdb.py), so clamping at its faces reads the
 * background, and their values outside the stored bricks are the background, as in OpenVDB.
 */
#ifndef VOLCL_GRID_H
#define VOLCL_GRID_H

inline float3 grid_point_to_local(__global const GridVolume *v, float3 p) {
    __global const float *m = v->to_local;
    return (float3)(m[0] * p.x + m[1] * p.y + m[2] * p.z + m[3],
                    m[4] * p.x + m[5] * p.y + m[6] * p.z + m[7],
                    m[8] * p.x + m[9] * p.y + m[10] * p.z + m[11]);
}

inline float3 grid_dir_to_local(__global const GridVolume *v, float3 d) {
    __global const float *m = v->to_local;
    return (float3)(m[0] * d.x + m[1] * d.y + m[2] * d.z,
                    m[4] * d.x + m[5] * d.y + m[6] * d.z,
                    m[8] * d.x + m[9] * d.y + m[10] * d.z);
}

inline float3 grid_res(__global const GridVolume *v) {
    return (float3)((float)v->res[0], (float)v->res[1], (float)v->res[2]);
}

/* One voxel's value; a one-channel grid is grey. */
inline float3 grid_voxel(__global const float *data, __global const GridVolume *v, int x, int y, int z) {
#if VOLCL_HAS_SPARSE_GRIDS
    if (v->layout == GRID_SPARSE) {
        /* the brick's index entry: its voxels, or the one value it holds */
        int nbx = v->res[0] >> 3, nby = v->res[1] >> 3;
        int e = as_int(data[v->data + ((z >> 3) * nby + (y >> 3)) * nbx + (x >> 3)]);
        __global const float *at = e >= 0
            ? data + e + (((z & 7) << 6) | ((y & 7) << 3) | (x & 7)) * v->channels
            : data + (-1 - e);
        return v->channels == 1 ? (float3)(at[0]) : vload3(0, at);
    }
#endif
    size_t i = ((size_t)z * (size_t)v->res[1] + (size_t)y) * (size_t)v->res[0] + (size_t)x;
    __global const float *base = data + v->data;
    return v->channels == 1 ? (float3)(base[i]) : vload3(i, base);
}

/* The grid's value at local point pl (any point: outside the cube the edge voxels continue). */
inline float3 grid_lookup(__global const float *data, __global const GridVolume *v, float3 pl) {
    float3 res = grid_res(v);
    if (v->filter == GRID_NEAREST) {
        /* fmax/fmin (not clamp) so that a NaN coordinate still yields an index inside the grid */
        int3 i = convert_int3(fmin(fmax(floor(pl * res), 0.0f), res - 1.0f));
        return grid_voxel(data, v, i.x, i.y, i.z);
    }
    /* continuous voxel coordinate with centres on the integers; clamping it to [0, res - 1] is
     * exactly clamp-to-edge filtering */
    float3 u = fmin(fmax(pl * res - 0.5f, 0.0f), res - 1.0f);
    float3 f = floor(u);
    float3 w = u - f;
    int3 i0 = convert_int3(f);
    int3 i1 = min(i0 + 1, convert_int3(res) - 1);
    float3 c00 = mix(grid_voxel(data, v, i0.x, i0.y, i0.z), grid_voxel(data, v, i1.x, i0.y, i0.z), w.x);
    float3 c10 = mix(grid_voxel(data, v, i0.x, i1.y, i0.z), grid_voxel(data, v, i1.x, i1.y, i0.z), w.x);
    float3 c01 = mix(grid_voxel(data, v, i0.x, i0.y, i1.z), grid_voxel(data, v, i1.x, i0.y, i1.z), w.x);
    float3 c11 = mix(grid_voxel(data, v, i0.x, i1.y, i1.z), grid_voxel(data, v, i1.x, i1.y, i1.z), w.x);
    return mix(mix(c00, c10, w.y), mix(c01, c11, w.y), w.z);
}

/* The part [*t0, *t1] of the ray o + t d, 0 <= t <= t_max, inside the unit cube (local frame);
 * false when the ray misses it. A zero direction component divides to +-inf, which the slab
 * comparisons handle (fmin/fmax drop the NaN of a ray lying exactly in a face plane). */
inline bool grid_clip(float3 o, float3 d, float t_max, float *t0, float *t1) {
    float3 inv = 1.0f / d;
    float3 ta = -o * inv, tb = (1.0f - o) * inv;
    float3 lo = fmin(ta, tb), hi = fmax(ta, tb);
    *t0 = fmax(fmax(lo.x, lo.y), fmax(lo.z, 0.0f));
    *t1 = fmin(fmin(hi.x, hi.y), fmin(hi.z, t_max));
    return *t0 < *t1;
}

/* A 3D DDA (Amanatides and Woo 1987) over the majorant cells a ray segment crosses inside the cube.
 * Cell boundaries are computed from the entry point each time, never by adding up increments, so
 * rounding does not drift along long walks. */
typedef struct {
    float3 pe;          /* local entry point, at t = t0 */
    float3 dl;          /* local direction */
    float t0, t, t_end; /* entry, start of the current cell's span, exit */
    int3 cell, res;
    float3 t_next;      /* where the ray crosses the current cell's far plane along each axis */
    bool done;
} GridWalk;

inline float grid_walk_plane(const GridWalk *w, float cell, float res, float pe, float d) {
    if (d == 0.0f) return INFINITY;
    float plane = (cell + (d > 0.0f ? 1.0f : 0.0f)) / res;
    return w->t0 + (plane - pe) / d;
}

inline GridWalk grid_walk_begin(__global const GridVolume *v, float3 ol, float3 dl, float t0, float t1) {
    GridWalk w;
    w.pe = ol + t0 * dl;
    w.dl = dl;
    w.t0 = t0;
    w.t = t0;
    w.t_end = t1;
    w.res = (int3)(v->maj_res[0], v->maj_res[1], v->maj_res[2]);
    float3 res = convert_float3(w.res);
    /* the entry point lies on the cube (up to rounding): clamp it into a valid cell */
    w.cell = convert_int3(fmin(fmax(floor(w.pe * res), 0.0f), res - 1.0f));
    w.t_next = (float3)(grid_walk_plane(&w, (float)w.cell.x, res.x, w.pe.x, dl.x),
                        grid_walk_plane(&w, (float)w.cell.y, res.y, w.pe.y, dl.y),
                        grid_walk_plane(&w, (float)w.cell.z, res.z, w.pe.z, dl.z));
    w.done = false;
    return w;
}

/* The current cell's span [*ta, *tb] of the ray and its majorant; then steps to the next cell.
 * Returns false once the segment is used up. */
inline bool grid_walk_next(GridWalk *w, __global const float *data, __global const GridVolume *v,
                           float *ta, float *tb, float *majorant) {
    if (w->done) return false;
    float tx = w->t_next.x, ty = w->t_next.y, tz = w->t_next.z;
    int axis = tx <= ty ? (tx <= tz ? 0 : 2) : (ty <= tz ? 1 : 2);
    float exit = fmin(axis == 0 ? tx : (axis == 1 ? ty : tz), w->t_end);
    *ta = w->t;
    *tb = fmax(exit, w->t);
    *majorant = data[v->majorants + (w->cell.z * w->res.y + w->cell.y) * w->res.x + w->cell.x];
    w->t = *tb;
    if (exit >= w->t_end) {
        w->done = true;
        return true;
    }
    if (axis == 0) {
        w->cell.x += w->dl.x > 0.0f ? 1 : -1;
        w->done = w->cell.x < 0 || w->cell.x >= w->res.x;
        w->t_next.x = grid_walk_plane(w, (float)w->cell.x, (float)w->res.x, w->pe.x, w->dl.x);
    } else if (axis == 1) {
        w->cell.y += w->dl.y > 0.0f ? 1 : -1;
        w->done = w->cell.y < 0 || w->cell.y >= w->res.y;
        w->t_next.y = grid_walk_plane(w, (float)w->cell.y, (float)w->res.y, w->pe.y, w->dl.y);
    } else {
        w->cell.z += w->dl.z > 0.0f ? 1 : -1;
        w->done = w->cell.z < 0 || w->cell.z >= w->res.z;
        w->t_next.z = grid_walk_plane(w, (float)w->cell.z, (float)w->res.z, w->pe.z, w->dl.z);
    }
    return true;
}

#endif
