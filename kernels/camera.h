/* Cameras with Mitsuba's and Nori's conventions: camera space looks down +z with +x to the left of
 * the image and +y up; pixel (0, 0) is the top-left corner. The reconstruction filter is importance
 * sampled: each sample lands at an offset distributed like the filter, weight one; unless the
 * film's sample_border is set, as Mitsuba's default and Nori, the filter is cut off at the image's
 * edge.
 *
 * Image coordinates (sx, sy) in [0, 1]^2, shifted by Mitsuba's principal point offset, map to the
 * point ((1 - 2 sx) tan_half.x, (1 - 2 sy) tan_half.y, 1) of camera space:
 *  - perspective: a ray from the pinhole through that point;
 *  - thin lens (Mitsuba's thinlens): from a point of the lens disk (radius aperture_radius, uniform)
 *    through that point's image on the plane z = focus_distance;
 *  - orthographic: from (x, y, near_clip) along +z, tan_half = (1, height / width) (the frame's
 *    to_world may scale this square, as in Mitsuba).
 * Clip planes are distances along the camera's z axis, as in Mitsuba. */
#ifndef VOLCL_CAMERA_H
#define VOLCL_CAMERA_H

VOLCL_STEP_INLINE
inline void camera_ray(const SceneData *sc, __global const float *filter_table, int px, int py, float2 u,
                       float2 u_lens, float3 *o, float3 *d, float *t_max) {
    __global const RenderParams *rp = sc->params;
    /* without sample_border, offsets keep the sample on the image (pixel centre: px + 0.5, py + 0.5) */
    float r = rp->filter_radius, cx = (float)px + 0.5f, cy = (float)py + 0.5f;
    int whole = rp->sample_border;
    float fx = sample_filter_offset_within(filter_table, rp->filter_size, r, u.x, whole ? -r : -cx,
                                           whole ? r : (float)rp->width - cx);
    float fy = sample_filter_offset_within(filter_table, rp->filter_size, r, u.y, whole ? -r : -cy,
                                           whole ? r : (float)rp->height - cy);
    float sx = (cx + fx) / (float)rp->width + rp->principal_point[0];
    float sy = (cy + fy) / (float)rp->height + rp->principal_point[1];
    float3 dc = (float3)((1.0f - 2.0f * sx) * rp->tan_half[0], (1.0f - 2.0f * sy) * rp->tan_half[1], 1.0f);
    __global const float *m = rp->cam_to_world;
#if VOLCL_HAS_ORTHOGRAPHIC
    if (rp->camera_type == CAMERA_ORTHOGRAPHIC) {
        *o = affine_point(m, (float3)(dc.x, dc.y, rp->near_clip));
        *d = normalize((float3)(m[2], m[6], m[10]));
        *t_max = rp->far_clip - rp->near_clip;
        return;
    }
#endif
    float3 lens = (float3)(0.0f);
#if VOLCL_HAS_THINLENS
    if (rp->camera_type == CAMERA_THINLENS) {
        float2 a = rp->aperture_radius * sample_concentric_disk(u_lens);
        lens = (float3)(a.x, a.y, 0.0f);
        dc = dc * rp->focus_distance - lens;     /* towards the point's image on the focal plane */
    }
#endif
    float3 dl = normalize(dc);
    *d = normalize(affine_vector(m, dl));
    float near_t = rp->near_clip / dl.z;
    *o = affine_point(m, lens) + *d * near_t;
    *t_max = rp->far_clip / dl.z - near_t;
}

#endif
