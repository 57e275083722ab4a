/* A lanes stage's access to the path state rows and the table (wavefront_state.h), for a kernel
 * whose work-item index is `i` and whose buffers are fs, is and table. */
#ifndef VOLCL_LANES_ROWS_H
#define VOLCL_LANES_ROWS_H

#define FROW(r) fs[WF_AT(r)]
#define IROW(r) is[WF_AT(r)]
#define TROW(r, k) table[(r) * WF_TABLE_STRIDE + (k)]

/* whether a lanes stage takes the path this step: its ray was just traced, or the lanes stage took
 * its last step too */
inline bool lanes_pending(int event) { return (event == WF_EV_MEDIUM) | (event == WF_EV_NEXT); }

inline V3 frow3(__global const float *fs, int r, int i) { return v3(FROW(r), FROW(r + 1), FROW(r + 2)); }

inline V3 trow3(__global const float *table, int r, int k) { return v3(TROW(r, k), TROW(r + 1, k), TROW(r + 2, k)); }

inline void frow3_put(__global float *fs, int r, int i, V3 v) {
    FROW(r) = v.x;
    FROW(r + 1) = v.y;
    FROW(r + 2) = v.z;
}

/* The rows a scatter sets, written for every path (a store under a condition stops the
 * vectorizer): where `cont`, the path scattered at p with direction pdf `pdf` and goes on along
 * the ray from o_next in direction d_next, starting t_back behind o_next, one bounce deeper; else
 * the rows keep what they hold. The throughput and the generator are written as they are. */
inline void lanes_put_scatter(__global float *fs, __global int *is, int i, bool cont, int depth, const Rng32 *rng,
                              V3 beta, V3 p, float pdf, V3 o_next, V3 d_next, float t_back) {
    IROW(WF_DEPTH) = cont ? depth + 1 : depth;
    IROW(WF_RNG) = (int)rng->lo;
    IROW(WF_RNG + 1) = (int)rng->hi;
    frow3_put(fs, WF_BETA, i, beta);
    frow3_put(fs, WF_O, i, v3_sel(cont, o_next, frow3(fs, WF_O, i)));
    frow3_put(fs, WF_D, i, v3_sel(cont, d_next, frow3(fs, WF_D, i)));
    FROW(WF_T_MAX) = cont ? INFINITY : FROW(WF_T_MAX);
    FROW(WF_T_BACK) = cont ? t_back : FROW(WF_T_BACK);
    FROW(WF_PREV_PDF) = cont ? pdf : FROW(WF_PREV_PDF);
    frow3_put(fs, WF_PREV_P, i, v3_sel(cont, p, frow3(fs, WF_PREV_P, i)));
}

#endif
