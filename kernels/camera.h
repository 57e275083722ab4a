/* Perspective camera with Mitsuba's and Nori's conventions: camera space looks down +z with +x to
 * the left of the image and +y up; pixel (0, 0) is the top-left corner. The reconstruction filter is
 * importance sampled: each sample lands at an offset distributed like the filter, weight one. */
#ifndef VOLCL_CAMERA_H
#define VOLCL_CAMERA_H

inline void camera_ray(const SceneData *sc, __global const float *filter_table, int px, int py, float2 u,
                       float3 *o, float3 *d, float *t_max) {
    __global const RenderParams *rp = sc->params;
    float fx = sample_filter_offset(filter_table, rp->filter_size, rp->filter_radius, u.x);
    float fy = sample_filter_offset(filter_table, rp->filter_size, rp->filter_radius, u.y);
    float sx = ((float)px + 0.5f + fx) / (float)rp->width;
    float sy = ((float)py + 0.5f + fy) / (float)rp->height;
    float3 dc = (float3)((1.0f - 2.0f * sx) * rp->tan_half[0], (1.0f - 2.0f * sy) * rp->tan_half[1], 1.0f);
    __global const float *m = rp->cam_to_world;
    float3 dw = (float3)(m[0] * dc.x + m[1] * dc.y + m[2] * dc.z,
                         m[4] * dc.x + m[5] * dc.y + m[6] * dc.z,
                         m[8] * dc.x + m[9] * dc.y + m[10] * dc.z);
    float3 origin = (float3)(m[3], m[7], m[11]);
    /* clip planes are distances along the camera's z axis, as in Mitsuba */
    float along = length(dc);
    *d = normalize(dw);
    *o = origin + *d * (rp->near_clip * along);
    *t_max = (rp->far_clip - rp->near_clip) * along;
}

#endif
