/* Constants and small vector helpers used by every other kernel file. */
#ifndef VOLCL_COMMON_H
#define VOLCL_COMMON_H

#define VOLCL_PI 3.14159265358979323846f
#define VOLCL_INV_PI 0.31830988618379067154f
#define VOLCL_INV_4PI 0.07957747154594766788f
#define VOLCL_INF INFINITY

/* Every VOLCL_HAS_* flag must come from the host as 0 or 1; a missing one is a build error, never a
 * silent default. */
#if !defined(VOLCL_HAS_SPHERES) || !defined(VOLCL_HAS_SHADING_NORMALS) || !defined(VOLCL_HAS_DIFFUSE) \
    || !defined(VOLCL_HAS_DIELECTRIC) || !defined(VOLCL_HAS_CONDUCTOR) || !defined(VOLCL_HAS_NULL_BSDF) \
    || !defined(VOLCL_HAS_AREA_LIGHTS) || !defined(VOLCL_HAS_POINT_LIGHTS) \
    || !defined(VOLCL_HAS_DIRECTIONAL_LIGHTS) || !defined(VOLCL_HAS_ENV_LIGHTS) || !defined(VOLCL_HAS_MEDIA) \
    || !defined(VOLCL_HAS_MEDIUM_BOUNDARIES) || !defined(VOLCL_HAS_CHROMATIC_MEDIA) || !defined(VOLCL_HAS_HG) \
    || !defined(VOLCL_HAS_EMISSIVE_MEDIA) || !defined(VOLCL_HAS_GRID_MEDIA) || !defined(VOLCL_HAS_EQUIANGULAR) \
    || !defined(VOLCL_HAS_CYLINDERS) || !defined(VOLCL_HAS_THINLENS) || !defined(VOLCL_HAS_ORTHOGRAPHIC) \
    || !defined(VOLCL_HAS_DIRECT) || !defined(VOLCL_HAS_ROUGHCONDUCTOR) || !defined(VOLCL_HAS_ROUGHDIELECTRIC) \
    || !defined(VOLCL_HAS_PLASTIC) || !defined(VOLCL_HAS_ROUGHPLASTIC) || !defined(VOLCL_HAS_THINDIELECTRIC) \
    || !defined(VOLCL_HAS_MASK) || !defined(VOLCL_HAS_TEXTURES) || !defined(VOLCL_HAS_BUMP_MAPS) \
    || !defined(VOLCL_HAS_ENVMAP) || !defined(VOLCL_HAS_SPOT_LIGHTS) || !defined(VOLCL_HAS_PHASE_FAMILIES)
#error "volcl: every VOLCL_HAS_* feature flag must be defined to 0 or 1 by the host"
#endif

/* Every kernel entry point is declared VOLCL_KERNEL. Hazard: Intel's CPU OpenCL runtime (2026.2)
 * miscompiles float3 values passed to or returned from a function it does not inline once its
 * implicit vectorizer has run on the kernel, even when it then keeps the scalar kernel: each work
 * item reads another's lanes (tests/test_implementations.py has the six-line reproducer). In the
 * megakernel that turned a shadow ray's transmittance into another pixel's, run to run. The vector
 * type hint makes that vectorizer leave the kernel alone (it rejected the divergent megakernel
 * anyway); the hint is honest, the kernels compute in float3, 4-wide registers, and other
 * implementations take it as the hint it is. (Building with -DVOLCL_KERNEL=__kernel brings the
 * failure back: tests/test_implementations.py checks that the self-test then rejects the device.) */
#ifndef VOLCL_KERNEL
#define VOLCL_KERNEL __kernel __attribute__((vec_type_hint(float4)))
#endif

/* Whether a surface vertex leaves its NEE shadow ray for the caller to trace (the packet renderer,
 * packets.cl, traces its lanes' shadow rays together); the megakernel traces each at once. */
#ifndef VOLCL_DEFER_SHADOWS
#define VOLCL_DEFER_SHADOWS 0
#endif

/* A step of the path tracer that PoCL kept out of line, passing the path's state (PathState,
 * SurfacePoint, Hit) through memory at every call: forcing these inline made PoCL's megakernel
 * 1-20% faster with the same bits (README, "Inlining the path's steps"). Forcing every function
 * inline gained a little more but made a first build take 3-33x as long; the BSDFs, textures and
 * the BVH walk gained nothing. The wavefront renderer's scalar stage keeps them out of line
 * (wavefront.cl). Optimized builds only: at -O0 a forced inline of a struct-returning function
 * emits an intrinsic Oclgrind cannot run (surface.h). */
#ifndef VOLCL_STEP_INLINE
#ifdef __OPTIMIZE__
#define VOLCL_STEP_INLINE __attribute__((always_inline))
#else
#define VOLCL_STEP_INLINE
#endif
#endif

inline float3 vload_f3(const __global float *p) { return (float3)(p[0], p[1], p[2]); }

/* A row-major 3x3 matrix in global memory times v, and its transpose times v. */
inline float3 mat3_apply(const __global float *m, float3 v) {
    return (float3)(m[0] * v.x + m[1] * v.y + m[2] * v.z, m[3] * v.x + m[4] * v.y + m[5] * v.z,
                    m[6] * v.x + m[7] * v.y + m[8] * v.z);
}

inline float3 mat3_apply_transposed(const __global float *m, float3 v) {
    return (float3)(m[0] * v.x + m[3] * v.y + m[6] * v.z, m[1] * v.x + m[4] * v.y + m[7] * v.z,
                    m[2] * v.x + m[5] * v.y + m[8] * v.z);
}

inline float max_component(float3 v) { return fmax(v.x, fmax(v.y, v.z)); }
inline float mean_component(float3 v) { return (v.x + v.y + v.z) * (1.0f / 3.0f); }
inline float luminance(float3 v) { return 0.212671f * v.x + 0.715160f * v.y + 0.072169f * v.z; }

/* Orthonormal basis around a unit normal (Duff et al. 2017), free of the singularity of the
 * cross-product-with-an-axis construction. */
inline void make_frame(float3 n, float3 *s, float3 *t) {
    float sign = copysign(1.0f, n.z);
    float a = -1.0f / (sign + n.z);
    float b = n.x * n.y * a;
    *s = (float3)(1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x);
    *t = (float3)(b, sign + n.y * n.y * a, -n.y);
}

inline float3 frame_to_world(float3 v, float3 s, float3 t, float3 n) { return v.x * s + v.y * t + v.z * n; }

inline float3 frame_to_local(float3 v, float3 s, float3 t, float3 n) {
    return (float3)(dot(v, s), dot(v, t), dot(v, n));
}

inline float power_heuristic(float pdf_a, float pdf_b) {
    float a = pdf_a * pdf_a, b = pdf_b * pdf_b;
    /* both pdfs can be huge (near-delta lobes); a/(a+b) on squares overflows to inf/inf */
    if (isinf(a)) return isinf(b) ? 0.5f : 1.0f;
    return a + b > 0.0f ? a / (a + b) : 0.0f;
}

/* Ray origin offset off a surface, along the geometric normal towards the side `d` leaves on.
 * The offset scales with the magnitude of the coordinates because float32 spacing does (Mitsuba's
 * approach); a fixed epsilon either self-intersects far from the origin or leaks through thin walls
 * near it. Used for every ray that leaves a surface: continuation rays and shadow rays alike.
 * `mag` is the magnitude of the coordinates p was computed from (SurfacePoint.mag: a triangle's
 * vertices, a sphere's centre plus radius), which bounds the rounding error of p even where p
 * itself is near zero. Hazards: a floor of 1 (Mitsuba's 1 + |p|) broke both ends of the scale.
 * Large triangles hit near the origin (a slab 800 units wide) got an offset smaller than the
 * rounding of p, which then sat on either side of the surface at random; in a scene 1e-4 units
 * across, 1e-5 skipped a tenth of every medium entered, and at 1e-6 whole objects. Relative to mag
 * the offset is the same fraction of the geometry at every scale. */
inline float3 offset_origin(float3 p, float mag, float3 ng, float3 d) {
    mag = fmax(mag, fmax(fmax(fabs(p.x), fabs(p.y)), fabs(p.z)));
    float eps = mag * 1e-5f;
    /* the same side rule as medium_after (> 0: the side ng points to), so a direction exactly in the
     * tangent plane starts on the side whose medium it is given */
    return p + (dot(d, ng) > 0.0f ? eps : -eps) * ng;
}

/* How far back along d the plane of the surface at p (normal ng) lies from the offset origin o:
 * where a medium segment that starts at that surface begins, measured on the traced ray.
 * Hazard: the offset puts o at depth eps below the surface, and sampling a medium from o skips
 * sigma_t * eps of optical depth (ten mean free paths at sigma_t = 1e6 in a unit scene). Going
 * back by eps / cos instead of eps * cos (the offset's component along d) restores the depth of
 * every point on the traced ray: depth = t * cos, as from the surface point itself. Points are
 * not taken on the line through p, which can end beyond the boundary the traced ray stops at.
 * Grazing rays go back at most 16 offsets, keeping the virtual entry point on the tangent plane
 * within a second-order distance of a curved surface (their depth error stays below eps). */
inline float offset_back(float3 o, float3 p, float3 ng, float3 d) {
    return fabs(dot(o - p, ng)) / fmax(fabs(dot(d, ng)), 1.0f / 16.0f);
}

#endif
