/* Test-only kernels for the lights of kernels/lights.h and envmap.h: each work item draws what one
 * call needs from rng_init(seed, gid, 0) and writes the results (3 floats per direction or colour).
 * Only the buffers lights need are passed: lights, env_data and the RenderParams record. */
#include "types.h"
#include "common.h"
#include "rng.h"
#include "sampling.h"
#include "scene.h"
#include "bvh.h"
#include "lights.h"

#define LIGHT_SCENE                                                                                     \
    SceneData sc;                                                                                       \
    sc.lights = lights;                                                                                 \
    sc.env_data = env_data;                                                                             \
    sc.params = params;

/* envmap_sample of light `light`: direction, radiance and solid-angle pdf (0 where it fails). */
VOLCL_KERNEL void envmap_samples(__global const Light *lights, __global const float *env_data,
                             __global const RenderParams *params, __global float *dirs, __global float *values,
                             __global float *pdfs, int light, uint seed) {
    int i = get_global_id(0);
    LIGHT_SCENE
    Rng r = rng_init(seed, (uint)i, 0u);
    float3 wi = (float3)(0.0f), value = (float3)(0.0f);
    float pdf = 0.0f;
    if (!envmap_sample(&sc, &lights[light], rng_next_float2(&r), &wi, &value, &pdf)) pdf = 0.0f;
    vstore3(wi, i, dirs);
    vstore3(value, i, values);
    pdfs[i] = pdf;
}

/* light_sample from point `ref` (the light picked by u_pick as the integrator picks it). */
VOLCL_KERNEL void light_samples(__global const Light *lights, __global const float *env_data,
                            __global const RenderParams *params, __global float *dirs, __global float *values,
                            __global float *pdfs, __global int *picked, float rx, float ry, float rz, uint seed) {
    int i = get_global_id(0);
    LIGHT_SCENE
    Rng r = rng_init(seed, (uint)i, 0u);
    float u_pick = rng_next_float(&r);
    LightSample ls;
    bool ok = light_sample(&sc, (float3)(rx, ry, rz), u_pick, rng_next_float2(&r), &ls);
    vstore3(ok ? ls.wi : (float3)(0.0f), i, dirs);
    vstore3(ok ? ls.value : (float3)(0.0f), i, values);
    pdfs[i] = ok ? ls.pdf : 0.0f;
    picked[i] = ok ? ls.light : -1;
}

/* The environment's radiance and light-sampling pdf (light choice included) along given directions. */
VOLCL_KERNEL void env_emission(__global const Light *lights, __global const float *env_data,
                           __global const RenderParams *params, __global const float *dirs_in,
                           __global float *values, __global float *pdfs) {
    int i = get_global_id(0);
    LIGHT_SCENE
    float pdf;
    vstore3(light_env_emission(&sc, vload3(i, dirs_in), &pdf), i, values);
    pdfs[i] = pdf;
}

/* Intensity of point or spot light `light` towards given world directions (away from the light). */
VOLCL_KERNEL void point_intensity(__global const Light *lights, __global const float *dirs_in, __global float *values,
                              int light) {
    int i = get_global_id(0);
    vstore3(light_point_intensity(&lights[light], normalize(vload3(i, dirs_in))), i, values);
}

/* sample_linear on (a, b): points in [0, 1). */
VOLCL_KERNEL void linear_samples(__global float *out, float a, float b, uint seed) {
    int i = get_global_id(0);
    Rng r = rng_init(seed, (uint)i, 0u);
    out[i] = sample_linear(rng_next_float(&r), a, b);
}
