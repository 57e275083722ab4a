/* Test-only kernels for kernels/trig.h: sin and cos of whole turns, as the samplers use them, and the
 * free flights' log. */
#include "types.h"
#include "common.h"
#include "trig.h"

VOLCL_KERNEL void trig_turn(__global const float *u, __global float *sin_out, __global float *cos_out) {
    int i = get_global_id(0);
    float c;
    sin_out[i] = sincos_turn(u[i], &c);
    cos_out[i] = c;
}

VOLCL_KERNEL void trig_log(__global const float *x, __global float *out) {
    int i = get_global_id(0);
    out[i] = log_pos(x[i]);
}

VOLCL_KERNEL void trig_atan2_full(__global const float *y, __global const float *x, __global float *out) {
    int i = get_global_id(0);
    out[i] = atan2_full(y[i], x[i]);
}
