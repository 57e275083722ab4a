/* Structs shared with the host. volcl/layout.py mirrors each one byte for byte.
 *
 * Rules that keep both sides in agreement: only 4-byte scalars and arrays of them (no float3, which
 * OpenCL C aligns to 16 bytes), sizes a multiple of 16, explicit padding fields named pad*.
 * Units: positions in scene units, radiance in W/(m^2 sr), intensity in W/sr, coefficients per unit length.
 */
#ifndef VOLCL_TYPES_H
#define VOLCL_TYPES_H

/* Wide BVH node (volcl/bvh_wide.py): the boxes of up to VOLCL_BVH_WIDTH children as six rows
 * (min x, y, z, then max x, y, z) of one float per child, so one vector load reads a slab plane of
 * every child. child[i] >= 0: a node index; < 0: a leaf, ~child[i] = (first << 4) | (count - 1)
 * over the leaf packets [first, first + count). Unused slots have an inverted box (min +inf,
 * max -inf), which no ray enters. The root is node 0. */
#define VOLCL_BVH_WIDTH 8
typedef struct {
    float bounds[6][VOLCL_BVH_WIDTH];
    int child[VOLCL_BVH_WIDTH];
} BvhWideNode;

/* Up to VOLCL_LEAF_WIDTH primitives of a BVH leaf, tested together: the triangles' vertex
 * coordinates as nine rows (p0 x, y, z, p1 x, y, z, p2 x, y, z) of one float per primitive, each
 * primitive's code (>= 0: index into the Triangle array; < 0: sphere -(code + 1)), and -1 where
 * the primitive's surface is opaque (its bsdf is not null; shadow rays stop there), else 0. Lanes
 * of spheres and unused lanes hold a zero triangle, which no ray hits (its det is exactly 0);
 * unused lanes have code 0. */
#define VOLCL_LEAF_WIDTH 4
typedef struct {
    float v[9][VOLCL_LEAF_WIDTH];
    int prim[VOLCL_LEAF_WIDTH];
    int opaque[VOLCL_LEAF_WIDTH];
} LeafPacket;

/* A triangle as its three vertices: the watertight test needs the exact shared vertices (a vertex
 * rebuilt as p0 + edge rounds differently in each triangle that shares it, and rays leak between). */
typedef struct {
    float p0[3];
    int shape;
    float p1[3];
    int normals;    /* index into the shading-normal buffer, or -1 for a flat triangle */
    float p2[3];
    int uvs;        /* index into the texture-coordinate buffer (TriangleUv), or -1 where nothing reads them */
} Triangle;

/* Per-vertex shading normals of one triangle. */
typedef struct {
    float n0[3];
    float n1[3];
    float n2[3];
    int pad0[3];
} TriangleNormals;

/* Texture coordinates at a triangle's corners p0, p1, p2 (texcoords.h). A mesh without any gets
 * (0, 0), (1, 0), (0, 1) at the corners of each triangle in its file's order: Mitsuba's barycentric
 * parametrization. */
typedef struct {
    float uv[6];
    float pad0[2];
} TriangleUv;

/* The parametrization of an analytic surface (texcoords.h): a sphere's (UV_MAP_SPHERE) or a disk's
 * (UV_MAP_DISK, the disk being a triangle fan) uv and position derivatives follow from the hit
 * point in the frame of the unit shape, as Mitsuba defines them. */
#define UV_MAP_SPHERE 0
#define UV_MAP_DISK 1
typedef struct {
    int kind;
    int pad0[3];
    float to_world[12];     /* row-major 3x4: the unit shape's frame */
    float to_object[12];    /* its inverse */
} UvMap;

typedef struct {
    float center[3];
    float radius;
    int shape;
    int flip;       /* flip_normals: the outward normal points inward */
    int pad0[2];
} Sphere;

/* Mitsuba's cylinder: the open unit cylinder x^2 + y^2 = 1, 0 <= z <= 1 of its own frame (cylinder.h). */
typedef struct {
    float to_world[12];     /* row-major 3x4 */
    float to_object[12];    /* its inverse */
    int shape;
    int flip;       /* flip_normals: the outward normal points inward */
    int pad0[2];
} Cylinder;

/* An instance of a shape group (Mitsuba's instance, bvh.h): the group's own tree, from wide node
 * `root`, placed in the world by an affine map. */
typedef struct {
    float to_world[12];     /* row-major 3x4 */
    float to_object[12];    /* its inverse */
    int root;
    int pad0[3];
} Instance;

/* A shape's surface and media: what a hit on one of its primitives means. */
typedef struct {
    int bsdf;
    int light;      /* area light index, or -1 */
    int interior;   /* medium index, or -1 for vacuum */
    int exterior;
    int is_transition;  /* the shape names a medium on either side: crossing it changes the medium */
    int uv_map;     /* index into the analytic parametrizations (UvMap), or -1: a mesh's interpolated uvs */
    int pad0[2];
} ShapeInfo;

#define BSDF_DIFFUSE 0
#define BSDF_DIELECTRIC 1
#define BSDF_CONDUCTOR 2
#define BSDF_NULL 3
#define BSDF_ROUGHCONDUCTOR 4
#define BSDF_ROUGHDIELECTRIC 5
#define BSDF_PLASTIC 6
#define BSDF_ROUGHPLASTIC 7
#define BSDF_THINDIELECTRIC 8
#define BSDF_MASK 9         /* wraps `nested`: opaque with probability `opacity`, else a null crossing */
#define BSDF_BUMPMAP 10     /* wraps `nested` in a shading frame tilted by a height map's gradient */
#define BSDF_NORMALMAP 11   /* wraps `nested` in a shading frame from a normal map */

/* Bsdf.flags */
#define BSDF_FLAG_UV 1              /* this bsdf or one it wraps reads texture coordinates */
#define BSDF_FLAG_UV_FRAME 2        /* shading tangent from dp/du as in Mitsuba (anisotropy, bump and normal maps) */
#define BSDF_FLAG_PASSES 4          /* paths can pass through: a null component (mask, thindielectric) */
#define BSDF_FLAG_NONLINEAR 8       /* plastics: Mitsuba's `nonlinear` */
#define BSDF_FLAG_VISIBLE 16        /* microfacets: sample visible normals */
#define BSDF_FLAG_SHADOWING 32      /* bump and normal maps: use_shadowing_function */
#define BSDF_FLAG_FLIP_INVALID 64   /* bump and normal maps: flip_invalid_normals */

#define MICROFACET_BECKMANN 0
#define MICROFACET_GGX 1

/* One bsdf. Each colour or float that Mitsuba lets a texture give has a *_tex field: a texture
 * index (textures.h), or -1 for the constant beside it. Wrappers (mask, bump and normal maps) name
 * the bsdf they wrap in `nested`. */
typedef struct {
    int type;
    int twosided;
    float eta;              /* dielectrics and plastics: int_ior / ext_ior */
    int conductor_mirror;   /* conductor without eta/k: reflect everything, times `color` */
    float color[3];         /* diffuse reflectance; conductors' specular reflectance; plastics' diffuse reflectance */
    int color_tex;
    float cond_eta[3];
    int eta_tex;
    float cond_k[3];
    int k_tex;
    float spec_r[3];        /* dielectrics and plastics: specular reflectance */
    int spec_r_tex;
    float spec_t[3];        /* dielectrics: specular transmittance */
    int spec_t_tex;
    float alpha_u;          /* microfacet roughness along the shading frame's s and t axes */
    float alpha_v;
    int alpha_u_tex;
    int alpha_v_tex;
    int distribution;       /* MICROFACET_* */
    int flags;              /* BSDF_FLAG_* */
    int nested;
    int table;              /* roughplastic: offset of its 64-entry external transmittance table in bsdf_tables */
    float opacity;          /* mask */
    int opacity_tex;
    float scale;            /* bump map: height scale */
    int map_tex;            /* bump map: height texture; normal map: normal texture */
    float spec_weight;      /* plastics: probability weight of the specular lobe */
    float internal_refl;    /* plastic: internal diffuse Fresnel reflectance; roughplastic: rough internal reflectance */
    float inv_eta2;
    int pad0;
} Bsdf;

#define TEX_BITMAP 0
#define TEX_CHECKERBOARD 1
#define TEX_FILTER_BILINEAR 0
#define TEX_FILTER_NEAREST 1
#define TEX_WRAP_REPEAT 0
#define TEX_WRAP_MIRROR 1
#define TEX_WRAP_CLAMP 2

/* A texture (textures.h). Bitmaps: texel (x, y) channel c at texels[data + (y * width + x) *
 * channels + c], row 0 the image's top row, linear values; or, where lut >= 0 (a bitmap of at most
 * 256 distinct values, as every 8-bit image is), texels[lut + b] for the byte b at that index of
 * the bytes that start at texels + data. Checkerboards: child0/child1 are the
 * textures of color0/color1, or -1 for the constants color0/color1 (mean0/mean1 their channel
 * means, what a float parameter reads from them). to_uv maps the surface's uv first. */
typedef struct {
    int type;
    int channels;
    int width;
    int height;
    int data;
    int filter;
    int wrap;
    int child0;
    int child1;
    int lut;
    int pad0[2];
    float to_uv[6];         /* row-major 2x3 affine */
    float pad1[2];
    float color0[3];
    float mean0;
    float color1[3];
    float mean1;
} Texture;

#define LIGHT_AREA 0
#define LIGHT_POINT 1
#define LIGHT_DIRECTIONAL 2
#define LIGHT_CONSTANT 3
#define LIGHT_ENVMAP 4
#define LIGHT_SPOT 5

typedef struct {
    int type;
    int tri_start;  /* area light on a mesh: its triangles are light_tris[tri_start, tri_start + tri_count) */
    int tri_count;
    int sphere;     /* area light on an analytic shape, else -1: a sphere's index, or a cylinder's index
                     * plus VOLCL_CYLINDER_CODE_BASE (the analytic index of cylinder.h) */
    float value[3]; /* radiance (area, constant), intensity (point, spot), irradiance (directional); envmap: 1 */
    float area;     /* total emitting area (area lights) */
    float position[3];  /* point and spot light position */
    float pad0;
    float direction[3]; /* directional light: the direction light travels */
    float pad1;
    float to_local[9];  /* spot, envmap: world directions to the light's own frame (row-major 3x3); an
                         * envmap's is a rotation (its transpose maps back) */
    float cos_cutoff;   /* spot: Mitsuba's falloff (lights.h) */
    float cos_beam;
    float cutoff;       /* radians */
    float inv_transition;   /* 1 / (cutoff - beam width), radians */
    int env_res[2];     /* envmap: image width and height (envmap.h has the layout of its tables) */
    int env_data;       /* envmap: offset of its tables in env_data */
    float env_norm;     /* envmap: W (H - 1) / (2 pi^2): patch probability density to solid angle, times sin */
    int texture;        /* spot: its projection texture's index in textures, or -1 */
    float tan_cutoff;   /* spot: tan of the cutoff angle (its texture coordinates) */
    int pad2;
} Light;

#define MEDIUM_HOMOGENEOUS 0
#define MEDIUM_HETEROGENEOUS 1

#define PHASE_ISOTROPIC 0
#define PHASE_HG 1          /* g in the Medium record */
#define PHASE_LOBES 2       /* a mixture of PhaseLobe records (VOLCL_HAS_PHASE_FAMILIES) */

/* Homogeneous media use sigma_t, albedo and emission. Heterogeneous media read extinction and albedo
 * from the GridVolumes sigma_t_grid and albedo_grid, and `emission` holds the radiance Le: the
 * medium emits sigma_a(x) * Le per unit length. */
typedef struct {
    int type;
    int phase;
    float g;
    int sigma_t_grid;   /* heterogeneous: index into the grid descriptors, else -1 */
    float sigma_t[3];   /* extinction, scale already applied */
    int albedo_grid;    /* heterogeneous: index into the grid descriptors, else -1 */
    float albedo[3];
    int phase_lobe;     /* PHASE_LOBES: the first of its lobes in phase_lobes */
    float emission[3];  /* homogeneous: sigma_a * radiance (per unit length); heterogeneous: radiance */
    int phase_lobe_count;
    /* heterogeneous media with a spatially varying emission (VOLCL_HAS_EMISSIVE_MEDIA): the medium
     * emits sigma_a(x) * Le(x), Le = emission_scale * the emission grid's value (EMISSION_RADIANCE),
     * or emission_scale * the blackbody colour of (value - temperature_offset) * temperature_scale
     * (EMISSION_TEMPERATURE), read from the table at grid_data[blackbody] (volcl/blackbody.py) */
    int emission_mode;
    int emission_grid;
    float emission_scale;
    int blackbody;
    float temperature_scale;
    float temperature_offset;
    int emission_sampler;   /* emission NEE: offset of the medium's EmissionSampler words, or -1 */
    int sealed;             /* 1: inside a closed surface that stops shadow rays, no light inside:
                             * NEE from it always adds 0 and is skipped (volcl/sealed.py) */
} Medium;

#define EMISSION_CONSTANT 0     /* emission[] alone (or nothing) */
#define EMISSION_RADIANCE 1
#define EMISSION_TEMPERATURE 2

#define LOBE_ISOTROPIC 0
#define LOBE_HG 1               /* p[0] = g */
#define LOBE_RAYLEIGH 2
#define LOBE_DRAINE 3           /* p = (g, alpha, 1 / (1 + alpha (1 + 2 g^2) / 3)) */
#define LOBE_TABULATED 4        /* table over cos */
#define LOBE_FOURNIER_FORAND 5  /* p = (a, q, c3 / 16 pi, q^-a) (volcl/phase.py), table over x = sin^2(theta/2)^a */

/* One lobe of a mixture phase function. A table is a piecewise-linear density on table_size knots
 * at phase_tables[table]: the knots, then the density at each knot, then the CDF at each knot. */
typedef struct {
    int type;
    float weight;       /* the lobe's probability in the mixture (the weights of a medium sum to 1) */
    int table;          /* offset into phase_tables, or -1 */
    int table_size;
    float p[4];
} PhaseLobe;

#define GRID_TRILINEAR 0
#define GRID_NEAREST 1

#define GRID_DENSE 0
#define GRID_SPARSE 1   /* bricks of 8^3 voxels (OpenVDB and NanoVDB files; VOLCL_HAS_SPARSE_GRIDS) */

/* A grid of 1 or 3 channels filling the unit cube [0,1]^3 of its own frame (kernels/grid.h has the
 * lookup conventions). Voxel (x, y, z) channel c is grid_data[data + ((z * res[1] + y) * res[0] + x)
 * * channels + c], the .vol file's order. Extinction grids carry the medium's scale already, and a
 * coarse majorant grid of maj_res cells over the same cube at grid_data[majorants], x fastest: each
 * cell the largest value (over channels) that a lookup anywhere in the cell can return. Constant
 * volumes are 1x1x1 grids. A sparse grid (layout GRID_SPARSE) has res voxels in bricks of 8^3:
 * grid_data[data] starts its brick index (res / 8 entries, x fastest, int32 bit patterns): an entry
 * e >= 0 is the offset of the brick's voxels (z slowest, x fastest, channels interleaved), e < 0
 * the offset -1 - e of the one value every voxel of the brick holds; its majorant cells are the
 * bricks (maj_res = res / 8). */
typedef struct {
    float to_local[12];     /* world -> unit cube, row-major 3x4 */
    int res[3];
    int channels;
    int maj_res[3];         /* 0 0 0 for grids that are never tracked (albedo) */
    int filter;
    int data;
    int majorants;          /* -1 without a majorant grid */
    int layout;             /* GRID_DENSE | GRID_SPARSE */
    int pad0;
} GridVolume;

/* RenderParams.equiangular: how point-light direct lighting in homogeneous media is estimated */
#define EQUIANGULAR_OFF 0           /* free-flight distance sampling and NEE alone */
#define EQUIANGULAR_TWO_SAMPLE 1    /* one equiangular and one distance sample per segment, both kept */
#define EQUIANGULAR_ONE_SAMPLE 2    /* one of the two per segment, chosen at random */

#define CAMERA_PERSPECTIVE 0
#define CAMERA_THINLENS 1
#define CAMERA_ORTHOGRAPHIC 2

#define INTEGRATOR_PATH 0           /* the volumetric path tracer (integrator.h) */
#define INTEGRATOR_DIRECT 1         /* Mitsuba's direct integrator (direct.h, VOLCL_HAS_DIRECT builds) */

/* RenderParams.hide_emitters */
#define HIDE_EMITTERS_OFF 0
#define HIDE_EMITTERS_DARK 1        /* camera rays do not count emission, and shade the emitter's bsdf */
#define HIDE_EMITTERS_SKIP 2        /* camera rays pass through area emitters (Mitsuba's path, volpath, direct) */

/* Everything a sample pass needs besides the scene buffers. */
typedef struct {
    float cam_to_world[12]; /* row-major 3x4: rotation/scale columns then translation */
    float tan_half[2];      /* tangent of half the field of view along x and y */
    float near_clip;
    float far_clip;
    int width;
    int height;
    int max_depth;          /* Mitsuba's meaning: 1 emitters only, 2 direct lighting, < 0 unlimited */
    int rr_depth;
    int hide_emitters;
    int specular_chains_only;
    int camera_medium;      /* -1: vacuum */
    int light_count;
    int env_light;          /* index of the environment light (constant or envmap), or -1 */
    int filter_size;        /* entries of the filter's inverse-CDF table */
    float filter_radius;    /* pixels */
    uint seed;
    float scene_radius;     /* bounding sphere, for directional lights */
    float scene_center[3];
    int nee;                /* next-event estimation on (1) or off (0: lights are found by hitting them) */
    int mis;                /* with nee: combine with BSDF / phase sampling by MIS (1) or not (0) */
    float majorant_scale;   /* every majorant is multiplied by this (>= 1; 1 = tight); a test knob */
    int equiangular;        /* EQUIANGULAR_*; read only by VOLCL_HAS_EQUIANGULAR builds (integrator.h) */
    int camera_type;        /* CAMERA_* (camera.h) */
    float aperture_radius;  /* thin lens */
    float focus_distance;   /* thin lens: along the view axis */
    float principal_point[2];   /* image-plane shift, in fractions of the image's width and height */
    int emitter_samples;    /* direct integrator (direct.h) */
    int bsdf_samples;
    int integrator;         /* INTEGRATOR_* */
    int emission_table;     /* emission NEE: offset in grid_data of its table of media (volcl/emission_sampler.py), or -1 */
    int emission_nee;       /* emission NEE on (1) or off (0); read only by VOLCL_HAS_EMISSION_NEE builds */
    int sample_border;      /* 1: pixels at the image's edge sample their whole filter (Mitsuba's hdrfilm) */
    int camera_walk;        /* 0: no surface lies where camera rays reach the near clip plane (volcl.pack
                             * near_clip_bounds): camera_start_medium has nothing to find */
    int shadow_root;        /* the wide node of the tree without the faces of the scene's convex hull
                             * (volcl.hull), for shadow rays from surfaces to points of the scene;
                             * 0: the scene's own tree */
    int pad0[3];
} RenderParams;

#endif
