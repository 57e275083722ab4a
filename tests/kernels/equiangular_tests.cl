/* Test-only kernels for kernels/equiangular.h: samples with their pdfs, and the pdf on given
 * distances. cfg holds the ray origin, direction, light position (3 floats each) and t_max. */
#include "types.h"
#include "common.h"
#include "equiangular.h"

inline void load_cfg(__global const float *cfg, float3 *o, float3 *d, float3 *light, float *t_max) {
    *o = vload3(0, cfg);
    *d = vload3(1, cfg);
    *light = vload3(2, cfg);
    *t_max = cfg[9];
}

VOLCL_KERNEL void equiangular_sample(__global const float *cfg, __global const float *u, __global float *t_out,
                                 __global float *pdf_out, __global float *pdf_again, __global int *ok) {
    int i = get_global_id(0);
    float3 o, d, light;
    float t_max, t = -1.0f, pdf = 0.0f;
    load_cfg(cfg, &o, &d, &light, &t_max);
    ok[i] = sample_equiangular(o, d, t_max, light, u[i], &t, &pdf) ? 1 : 0;
    t_out[i] = t;
    pdf_out[i] = pdf;
    pdf_again[i] = sample_equiangular_pdf(o, d, t_max, light, t);
}

VOLCL_KERNEL void equiangular_pdf(__global const float *cfg, __global const float *t, __global float *pdf) {
    int i = get_global_id(0);
    float3 o, d, light;
    float t_max;
    load_cfg(cfg, &o, &d, &light, &t_max);
    pdf[i] = sample_equiangular_pdf(o, d, t_max, light, t[i]);
}

/* The short-range atan2 and sincos of equiangular.h on given arguments. */
VOLCL_KERNEL void equiangular_math(__global const float *y, __global const float *x, __global const float *phi,
                                   __global float *atan2_out, __global float *sin_out, __global float *cos_out) {
    int i = get_global_id(0);
    atan2_out[i] = atan2_upper(y[i], x[i]);
    float c;
    sin_out[i] = sincos_upper(phi[i], &c);
    cos_out[i] = c;
}
