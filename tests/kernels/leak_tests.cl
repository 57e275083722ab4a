/* Test-only kernel: random walks bouncing inside a closed mesh with the integrator's own rules: the
 * side a new direction leaves on is sign(dot(d, ng)) (medium_after) and the origin is offset to that
 * side (offset_origin). A ray that starts inside must hit the boundary again; one that finds nothing
 * has leaked. Half of the bounces leave at grazing angles (cos < 1e-3, down to rounding level), where
 * rounding may tip a direction to the outside: the walk has then crossed the boundary and ends. */
#include "types.h"
#include "common.h"
#include "rng.h"
#include "sampling.h"
#include "scene.h"
#include "bvh.h"
#include "surface.h"

VOLCL_KERNEL void walk_inside(__global const BvhWideNode *nodes, __global const LeafPacket *leaves,
                          __global const Triangle *triangles, __global const float *starts,
                          __global int *leaks, __global int *hits, int bounces) {
    int i = get_global_id(0);
    SceneData sc;
    sc.nodes = nodes;
    sc.leaves = leaves;
    sc.triangles = triangles;
    Rng rng = rng_init(12345u, (uint)i, 0u);
    float3 o = vload3(i, starts);
    float3 d = sample_uniform_sphere(rng_next_float2(&rng));
    int leaked = 0, n_hits = 0;
    for (int b = 0; b < bounces; ++b) {
        Hit h;
        if (!bvh_trace(&sc, o, d, INFINITY, TRACE_CLOSEST, &h)) { leaked = 1; break; }
        ++n_hits;
        SurfacePoint s = surface_point(&sc, &h, o, d);
        /* the inside is the side the ray arrived from */
        float3 n_in = dot(d, s.ng) > 0.0f ? -s.ng : s.ng;
        float3 t1, t2;
        make_frame(n_in, &t1, &t2);
        float3 v;
        if (rng_next_float(&rng) < 0.5f) {
            float c, sn, phi = 2.0f * VOLCL_PI * rng_next_float(&rng);
            c = 1e-3f * rng_next_float(&rng);
            sn = sqrt(1.0f - c * c);
            v = (float3)(sn * cos(phi), sn * sin(phi), c);
        } else {
            v = sample_cosine_hemisphere(rng_next_float2(&rng));
        }
        float3 d_new = normalize(frame_to_world(v, t1, t2, n_in));
        /* same side as the arriving ray's origin iff the signs of dot with ng differ */
        bool stays_inside = (dot(d_new, s.ng) > 0.0f) != (dot(d, s.ng) > 0.0f);
        d = d_new;
        o = offset_origin(s.p, s.mag, s.ng, d);
        if (!stays_inside) break;
    }
    leaks[i] = leaked;
    hits[i] = n_hits;
}
