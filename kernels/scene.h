/* The scene buffers as one bundle of pointers, so device functions take one argument for them. */
#ifndef VOLCL_SCENE_H
#define VOLCL_SCENE_H

typedef struct {
    __global const BvhWideNode *nodes;
    __global const LeafPacket *leaves;  /* the BVH leaves' primitives, in packets */
    __global const Triangle *triangles;
    __global const TriangleNormals *normals;
    __global const Sphere *spheres;
    __global const Cylinder *cylinders;
    __global const ShapeInfo *shapes;
    __global const Bsdf *bsdfs;
    __global const Light *lights;
    __global const float *light_tri_cdf;    /* per area light: normalized prefix sums of triangle areas */
    __global const int *light_tris;
    __global const float *env_data;     /* environment maps' texels and sampling tables (envmap.h) */
    __global const Medium *media;
    __global const GridVolume *grids;   /* grid descriptors of heterogeneous media */
    __global const float *grid_data;    /* every grid's voxels and majorant cells, concatenated */
    __global const RenderParams *params;
    __global const TriangleUv *tri_uvs;     /* texture coordinates of triangles whose bsdf reads them */
    __global const UvMap *uv_maps;          /* parametrizations of spheres and disks */
    __global const Texture *textures;
    __global const float *texels;           /* every bitmap's texels, concatenated */
    __global const float *bsdf_tables;      /* roughplastic transmittance tables */
    __global const PhaseLobe *phase_lobes;  /* lobes of the mixture phase functions (PHASE_LOBES) */
    __global const float *phase_tables;     /* their piecewise-linear tables, concatenated */
    __global const Instance *instances;     /* placements of shape groups (bvh.h, INSTANCES) */
} SceneData;

/* The scene's buffers as an entry point's leading arguments (volcl.pack.ARG_ORDER, which adds the
 * camera's filter table after params), and the SceneData made of them. */
#define VOLCL_SCENE_ARGS \
    __global const BvhWideNode *nodes, __global const LeafPacket *leaves, __global const Triangle *triangles, \
    __global const TriangleNormals *normals, __global const Sphere *spheres, __global const Cylinder *cylinders, \
    __global const ShapeInfo *shapes, __global const Bsdf *bsdfs, __global const Light *lights, \
    __global const float *light_tri_cdf, __global const int *light_tris, __global const float *env_data, \
    __global const Medium *media, __global const GridVolume *grids, __global const float *grid_data, \
    __global const RenderParams *params, __global const float *filter_table, __global const TriangleUv *tri_uvs, \
    __global const UvMap *uv_maps, __global const Texture *textures, __global const float *texels, \
    __global const float *bsdf_tables, __global const PhaseLobe *phase_lobes, __global const float *phase_tables, \
    __global const Instance *instances
#define VOLCL_SCENE_DATA {nodes, leaves, triangles, normals, spheres, cylinders, shapes, bsdfs, lights, \
    light_tri_cdf, light_tris, env_data, media, grids, grid_data, params, tri_uvs, uv_maps, textures, texels, \
    bsdf_tables, phase_lobes, phase_tables, instances}

#endif
