/* The wavefront renderer's path state (kernels/wavefront.cl, wavefront_lanes.cl, volcl/wavefront.py):
 * structure of arrays, row r of a buffer holding field r of every path in flight, so that the
 * lanes of a stage load and store neighbouring words. Shared by the scalar and the lanes stage,
 * which are built as two programs.
 *
 * Rows are WF_STRIDE words apart, a constant, so that a field's address is the path's plus a
 * constant: with the row length a kernel argument, the SLP vectorizer (which PoCL runs on the
 * kernel before it forms its work-item loops) packed the rows' index arithmetic into a <4 x i32>,
 * and that vector stopped the loop vectorizer (kernels/lanes.h). At most WF_STRIDE - 16 paths are
 * in flight: the 16 more words put consecutive rows a cache line apart, where a power of two put
 * every field of a path in the same L1 cache set (0.88x the megakernel's speed instead of 1.23x).
 * (Rows of 8208 words, for 8192 paths at most, measured 1.03x against 1.26x with these, on PoCL.) */
#ifndef VOLCL_WAVEFRONT_STATE_H
#define VOLCL_WAVEFRONT_STATE_H

#ifndef VOLCL_WF_SPHERES
#define VOLCL_WF_SPHERES 0      /* spheres of a scene tested whole (lanes_triangles.h) */
#endif
#ifndef VOLCL_WF_LIGHT_TRIS
#define VOLCL_WF_LIGHT_TRIS 0   /* area-light triangles the surface stage samples (wavefront_surface.cl) */
#endif
#ifndef VOLCL_WF_CHECKERS
#define VOLCL_WF_CHECKERS 0     /* 1: some tested triangle's reflectance is a checkerboard (lanes_surface.h) */
#endif
#ifndef VOLCL_WF_HULL_SKIP
#define VOLCL_WF_HULL_SKIP 0    /* tested triangles the surface stage's shadow rays skip (lanes_reach) */
#endif

#define WF_STRIDE 65552
#define WF_AT(r) ((r) * WF_STRIDE + i)

/* The lights' and media's parameters the lanes stage reads, as rows of WF_TABLE_STRIDE words (light
 * or medium k at word k of each row): fields of one record read as neighbouring words were packed
 * into <2 x float> loads by the SLP vectorizer. volcl/wavefront.py fills it. */
#define WF_TABLE_STRIDE 64
#define WF_T_LIGHT_POS 0        /* 3 rows */
#define WF_T_LIGHT_VALUE 3      /* 3 rows: a point light's intensity */
#define WF_T_SIGMA_T 6          /* 3 rows */
#define WF_T_ALBEDO 9           /* 3 rows */
#define WF_T_G 12               /* HG's g, or 0 for the isotropic phase function */
#define WF_T_ISO 13             /* 1 for the isotropic phase function, else 0 */
#define WF_T_LANES 14           /* 1 where the lanes stage handles the medium (homogeneous), else 0 */
#define WF_T_POINT 15           /* 1 for a point light, which the lanes stage samples itself, else 0 */
#define WF_T_AREA 16            /* an area light's area */
#define WF_T_SEALED 17          /* 1 for a sealed medium (Medium.sealed: no NEE from it), else 0 */
#define WF_TABLE_ROWS 18
/* then a tiny scene's triangle lanes (lanes_triangles.h): coordinate c of lane k, every number a
 * cache line from the next (neighbouring words were packed into vectors again). Coordinates: p0
 * xyz, p1 xyz, p2 xyz, the primitive code's int bits; for the surface stage (wavefront_surface.cl)
 * the geometric normal xyz (the library's normalize, computed by the host), the magnitude of the
 * corners, 1 where the stage scatters from the triangle itself (plain diffuse), its reflectance
 * rgb (a checkerboard's first colour), 1 for a two-sided bsdf; with VOLCL_WF_CHECKERS, 1 where
 * the reflectance is a checkerboard of two colours on the triangle's uvs, its uvs (u0 v0 u1 v1 u2
 * v2), the texture's to_uv (row-major 2x3) and its second colour rgb. Only in the packet
 * renderer's table where it takes the rough step (VOLCL_PACKET_ROUGH), which holds no spheres, for its rough
 * plastic triangles (1 above is 2 there; lanes_rough.h) the roughness, the specular
 * sampling weight, eta, 1 / eta^2, the internal reflectance, 1 for a nonlinear bsdf, the specular
 * reflectance rgb, where its transmittance table starts in the bsdf tables (int bits), 1 where the
 * diffuse reflectance is a bitmap, the bitmap's width, height, wrap mode, data and lookup table
 * offsets (int bits; on every triangle a bitmap of the scene's, so that every lane reads within
 * one) and its to_uv (lanes_bitmap.h; the triangle's uvs above). (The wavefront's stages read none
 * of those: their tables keep 35.) */
#if defined(VOLCL_PACKET_ROUGH) && VOLCL_PACKET_ROUGH
#define WF_TRI_COORDS 57
#else
#define WF_TRI_COORDS 35
#endif
#define WF_TRI_AT(c, k) (WF_TABLE_ROWS * WF_TABLE_STRIDE + ((c) * VOLCL_WF_TINY + (k)) * 16)
#define WF_TRI_NG 10
#define WF_TRI_MAG 13
#define WF_TRI_LANES 14
#define WF_TRI_COLOR 15
#define WF_TRI_TWOSIDED 18
#define WF_TRI_CHECKER 19
#define WF_TRI_UV 20
#define WF_TRI_TO_UV 26
#define WF_TRI_COLOR1 32
#define WF_TRI_ROUGH_ALPHA 35
#define WF_TRI_ROUGH_SW 36
#define WF_TRI_ROUGH_ETA 37
#define WF_TRI_ROUGH_INV_ETA2 38
#define WF_TRI_ROUGH_INTERNAL 39
#define WF_TRI_ROUGH_NONLINEAR 40
#define WF_TRI_ROUGH_SPEC_R 41
#define WF_TRI_ROUGH_TABLE 44
#define WF_TRI_ROUGH_TEXTURED 45
#define WF_TRI_BITMAP 46         /* width, height, wrap, data, lut */
#define WF_TRI_BITMAP_TO_UV 51
/* then the spheres (VOLCL_WF_SPHERES): centre xyz, radius, primitive code's int bits */
#define WF_SPH_COORDS 5
#define WF_SPH_AT(c, k) (WF_TRI_AT(WF_TRI_COORDS, 0) + ((c) * VOLCL_WF_SPHERES + (k)) * 16)
/* then the area lights' triangles in light order (VOLCL_WF_LIGHT_TRIS, the surface stage): the
 * light's index (int bits), the cdf over its triangles at this one and before it, 1 for its last
 * triangle, p0 xyz, p1 xyz, p2 xyz, the normal xyz */
#define WF_LT_AT(c, j) (WF_SPH_AT(WF_SPH_COORDS, 0) + ((c) * VOLCL_WF_LIGHT_TRIS + (j)) * 16)
#define WF_LT_LIGHT 0
#define WF_LT_CDF 1
#define WF_LT_BEFORE 2
#define WF_LT_LAST 3
#define WF_LT_P 4
#define WF_LT_NG 13

/* float rows */
#define WF_L 0              /* 3 rows each: x, y, z */
#define WF_BETA 3
#define WF_O 6
#define WF_D 9
#define WF_T_MAX 12
#define WF_T_BACK 13
#define WF_PREV_PDF 14
#define WF_PREV_P 15
#define WF_ETA_SCALE 18
#define WF_HIT_T 19
#define WF_HIT_B1 20
#define WF_HIT_B2 21
/* the two shadow rays a medium event leaves (the equiangular sample's and the collision's NEE): origin,
 * direction, length, and the radiance they add if unblocked, to be multiplied by their transmittance */
#define WF_SHADOW(k) (22 + 10 * (k))
#define WF_SHADOW_O 0
#define WF_SHADOW_D 3
#define WF_SHADOW_T 6
#define WF_SHADOW_C 7
#define WF_FLOAT_ROWS 42

/* int rows */
#define WF_MEDIUM 0
#define WF_DEPTH 1
#define WF_FLAGS 2
#define WF_HIT_PRIM 3
#define WF_HIT_INST 4
#define WF_EVENT 5
#define WF_JOB 6            /* the sample the path renders: pass * items + work-item (wavefront.cl) */
#define WF_STEPS 7          /* loop steps of the sample so far (VOLCL_MAX_STEPS) */
#define WF_CUTOFFS 8        /* tracking cut-offs of the sample so far */
#define WF_RNG 9            /* 4 rows: the generator's state and increment as 32-bit halves, low first */
#define WF_INT_ROWS 13

/* WF_FLAGS bits */
#define WF_FLAG_ALIVE 1u    /* the path's work-item has samples left */
#define WF_FLAG_SPECULAR 2u
#define WF_FLAG_DO_NEE 4u
#define WF_FLAG_HIT 8u      /* the ray traced last hit a surface (WF_HIT_*) */
#define WF_FLAG_SHADOW0 16u /* shadow ray 0 is to be traced */
#define WF_FLAG_SHADOW1 32u
/* NEE from the collision picked a light other than a point light: light_sample is the scalar stage's,
 * from the collision at shadow ray 1's origin, the direction before scattering in its direction
 * slot, and the three numbers the lanes stage drew for it (pick, then the pair) in its radiance slot */
#define WF_FLAG_NEE 64u

/* WF_EVENT: what the next stage does with the path, beyond integrator.h's PATH_* codes */
#define WF_EV_MEDIUM 16     /* the ray is traced: its medium segment is next */
#define WF_EV_START 17      /* a new sample starts */
#define WF_EV_NEXT 18       /* (VOLCL_WF_TINY) the lanes stage took the whole step, roulette included:
                             * the scalar stage leaves the path alone, the lanes stage traces it next
                             * (a scatter in a medium, or from a diffuse surface: wavefront_surface.cl) */

#endif
