"""numpy structured dtypes that mirror kernels/types.h byte for byte.

Shared structs hold no float3 (16-byte aligned in OpenCL C, packed in numpy); every field is a
4-byte scalar or an array of them, so both sides agree on offsets without padding rules.
tests/test_layout.py checks every size and offset against the device compiler with a probe kernel.
"""
import numpy as np

f3 = (np.float32, 3)

# Binary BVH node of the host-side builder (volcl.bvh), depth-first order; the device gets the
# wide nodes below, collapsed from these. Interior (count == 0): left child is the next node,
# `index` is the right child. Leaf (count > 0): primitives [index, index + count) of the
# BVH-ordered primitive list.
BVH_NODE = np.dtype([
    ("bmin", *f3), ("index", np.int32),
    ("bmax", *f3), ("count", np.int32),
])

# The device's wide BVH node (kernels/types.h BvhWideNode; built by volcl.bvh_wide): the boxes of
# up to BVH_WIDTH children as six rows (min x, y, z, max x, y, z) of BVH_WIDTH floats, so one
# vector load fetches a slab plane of every child, then the child references.
BVH_WIDTH = 8


def bvh_wide_node(width=BVH_WIDTH):
    return np.dtype([("bounds", np.float32, (6, width)), ("child", np.int32, width)])


BVH_WIDE_NODE = bvh_wide_node()

# Up to LEAF_WIDTH primitives of a BVH leaf (kernels/types.h LeafPacket): triangle vertices as nine
# rows (p0 xyz, p1 xyz, p2 xyz) of LEAF_WIDTH floats, the primitives' codes, and -1 for each
# primitive with an opaque surface (0 for null surfaces and unused lanes).
LEAF_WIDTH = 4
LEAF_PACKET = np.dtype([("v", np.float32, (9, LEAF_WIDTH)), ("prim", np.int32, LEAF_WIDTH),
                        ("opaque", np.int32, LEAF_WIDTH)])

TRIANGLE = np.dtype([
    ("p0", *f3), ("shape", np.int32),
    ("p1", *f3), ("normals", np.int32),
    ("p2", *f3), ("uvs", np.int32),
])

TRIANGLE_NORMALS = np.dtype([("n0", *f3), ("n1", *f3), ("n2", *f3), ("pad0", np.int32, 3)])

# corner texture coordinates of a triangle (kernels/texcoords.h)
TRIANGLE_UV = np.dtype([("uv", np.float32, 6), ("pad0", np.float32, 2)])

UV_MAP_KINDS = {"sphere": 0, "disk": 1}
UV_MAP = np.dtype([("kind", np.int32), ("pad0", np.int32, 3),
                   ("to_world", np.float32, 12), ("to_object", np.float32, 12)])

SPHERE = np.dtype([
    ("center", *f3), ("radius", np.float32),
    ("shape", np.int32), ("flip", np.int32), ("pad0", np.int32, 2),
])

CYLINDER = np.dtype([
    ("to_world", np.float32, 12), ("to_object", np.float32, 12),
    ("shape", np.int32), ("flip", np.int32), ("pad0", np.int32, 2),
])
# analytic index of cylinder k (kernels/cylinder.h): BVH code -(index + 1), and Light.sphere
CYLINDER_CODE_BASE = 1 << 30
# an instance of a shape group (kernels/bvh.h): analytic index INSTANCE_CODE_BASE + k in the top-level
# tree, below the cylinders' base; its group's tree starts at wide node `root`
INSTANCE = np.dtype([
    ("to_world", np.float32, 12), ("to_object", np.float32, 12),
    ("root", np.int32), ("pad0", np.int32, 3),
])
INSTANCE_CODE_BASE = 1 << 29

SHAPE_INFO = np.dtype([
    ("bsdf", np.int32), ("light", np.int32), ("interior", np.int32), ("exterior", np.int32),
    ("is_transition", np.int32), ("uv_map", np.int32), ("pad0", np.int32, 2),
])

BSDF_TYPES = {"diffuse": 0, "dielectric": 1, "conductor": 2, "null": 3, "roughconductor": 4, "roughdielectric": 5,
              "plastic": 6, "roughplastic": 7, "thindielectric": 8, "mask": 9, "bumpmap": 10, "normalmap": 11}
BSDF_FLAGS = {"uv": 1, "uv_frame": 2, "passes": 4, "nonlinear": 8, "visible": 16, "shadowing": 32,
              "flip_invalid": 64}
MICROFACETS = {"beckmann": 0, "ggx": 1}
BSDF = np.dtype([
    ("type", np.int32), ("twosided", np.int32), ("eta", np.float32), ("conductor_mirror", np.int32),
    ("color", *f3), ("color_tex", np.int32),
    ("cond_eta", *f3), ("eta_tex", np.int32),
    ("cond_k", *f3), ("k_tex", np.int32),
    ("spec_r", *f3), ("spec_r_tex", np.int32),
    ("spec_t", *f3), ("spec_t_tex", np.int32),
    ("alpha_u", np.float32), ("alpha_v", np.float32), ("alpha_u_tex", np.int32), ("alpha_v_tex", np.int32),
    ("distribution", np.int32), ("flags", np.int32), ("nested", np.int32), ("table", np.int32),
    ("opacity", np.float32), ("opacity_tex", np.int32), ("scale", np.float32), ("map_tex", np.int32),
    ("spec_weight", np.float32), ("internal_refl", np.float32), ("inv_eta2", np.float32), ("pad0", np.int32),
])
# the texture-index fields of a BSDF record, -1 for "the constant beside it"
BSDF_TEXTURE_FIELDS = ("color_tex", "eta_tex", "k_tex", "spec_r_tex", "spec_t_tex", "alpha_u_tex", "alpha_v_tex",
                       "opacity_tex", "map_tex")

TEXTURE_TYPES = {"bitmap": 0, "checkerboard": 1}
TEXTURE_FILTERS = {"bilinear": 0, "nearest": 1}
TEXTURE_WRAPS = {"repeat": 0, "mirror": 1, "clamp": 2}
TEXTURE = np.dtype([
    ("type", np.int32), ("channels", np.int32), ("width", np.int32), ("height", np.int32),
    ("data", np.int32), ("filter", np.int32), ("wrap", np.int32), ("child0", np.int32),
    ("child1", np.int32), ("lut", np.int32), ("pad0", np.int32, 2),
    ("to_uv", np.float32, 6), ("pad1", np.float32, 2),
    ("color0", *f3), ("mean0", np.float32),
    ("color1", *f3), ("mean1", np.float32),
])

LIGHT_TYPES = {"area": 0, "point": 1, "directional": 2, "constant": 3, "envmap": 4, "spot": 5}
LIGHT = np.dtype([
    ("type", np.int32), ("tri_start", np.int32), ("tri_count", np.int32), ("sphere", np.int32),
    ("value", *f3), ("area", np.float32),
    ("position", *f3), ("pad0", np.float32),
    ("direction", *f3), ("pad1", np.float32),
    ("to_local", np.float32, 9),
    ("cos_cutoff", np.float32), ("cos_beam", np.float32), ("cutoff", np.float32), ("inv_transition", np.float32),
    ("env_res", np.int32, 2), ("env_data", np.int32), ("env_norm", np.float32), ("texture", np.int32), ("tan_cutoff", np.float32), ("pad2", np.int32),
])

MEDIUM_TYPES = {"homogeneous": 0, "heterogeneous": 1}
# Medium.phase: isotropic and HG in the medium record itself, anything else a mixture of lobes
PHASE_TYPES = {"isotropic": 0, "hg": 1, "lobes": 2}
# Heterogeneous media name their grids (sigma_t_grid, albedo_grid), and `emission` holds the
# radiance; homogeneous media use sigma_t, albedo, and emission = sigma_a * radiance.
# A mixture phase is PHASE_LOBE records [phase_lobe, phase_lobe + phase_lobe_count).
MEDIUM = np.dtype([
    ("type", np.int32), ("phase", np.int32), ("g", np.float32), ("sigma_t_grid", np.int32),
    ("sigma_t", *f3), ("albedo_grid", np.int32),
    ("albedo", *f3), ("phase_lobe", np.int32),
    ("emission", *f3), ("phase_lobe_count", np.int32),
    ("emission_mode", np.int32), ("emission_grid", np.int32), ("emission_scale", np.float32),
    ("blackbody", np.int32), ("temperature_scale", np.float32), ("temperature_offset", np.float32),
    ("emission_sampler", np.int32), ("sealed", np.int32),
])
EMISSION_MODES = {"none": 0, "radiance": 1, "temperature": 2}

# One lobe of a mixture phase function (kernels/types.h says what `p` holds for each type); a
# table is a piecewise-linear density at phase_tables[table ...]: knots, densities, CDF.
LOBE_TYPES = {"isotropic": 0, "hg": 1, "rayleigh": 2, "draine": 3, "tabulated": 4, "fournier_forand": 5}
PHASE_LOBE = np.dtype([
    ("type", np.int32), ("weight", np.float32), ("table", np.int32), ("table_size", np.int32),
    ("p", np.float32, 4),
])

GRID_FILTERS = {"trilinear": 0, "nearest": 1}
GRID_LAYOUTS = {"dense": 0, "sparse": 1}
# A grid of 1 or 3 channels filling its unit cube; voxels and majorant cells live in one float
# buffer at offsets `data` and `majorants` (see kernels/types.h).
GRID_VOLUME = np.dtype([
    ("to_local", np.float32, 12), ("res", np.int32, 3), ("channels", np.int32),
    ("maj_res", np.int32, 3), ("filter", np.int32),
    ("data", np.int32), ("majorants", np.int32), ("layout", np.int32), ("pad0", np.int32),
])

RENDER_PARAMS = np.dtype([
    ("cam_to_world", np.float32, 12), ("tan_half", np.float32, 2),
    ("near_clip", np.float32), ("far_clip", np.float32),
    ("width", np.int32), ("height", np.int32), ("max_depth", np.int32), ("rr_depth", np.int32),
    ("hide_emitters", np.int32), ("specular_chains_only", np.int32), ("camera_medium", np.int32),
    ("light_count", np.int32), ("env_light", np.int32), ("filter_size", np.int32),
    ("filter_radius", np.float32), ("seed", np.uint32), ("scene_radius", np.float32),
    ("scene_center", *f3), ("nee", np.int32), ("mis", np.int32), ("majorant_scale", np.float32),
    ("equiangular", np.int32), ("camera_type", np.int32), ("aperture_radius", np.float32),
    ("focus_distance", np.float32), ("principal_point", np.float32, 2), ("emitter_samples", np.int32),
    ("bsdf_samples", np.int32), ("integrator", np.int32), ("emission_table", np.int32),
    ("emission_nee", np.int32), ("sample_border", np.int32), ("camera_walk", np.int32),
    ("shadow_root", np.int32), ("pad0", np.int32, 3),
])
INTEGRATORS = {"path": 0, "direct": 1}
CAMERA_TYPES = {"perspective": 0, "thinlens": 1, "orthographic": 2}
HIDE_EMITTERS = {"off": 0, "dark": 1, "skip": 2}

# name in kernels/types.h -> dtype, for the layout probe
SHARED_STRUCTS = {
    "BvhWideNode": BVH_WIDE_NODE, "LeafPacket": LEAF_PACKET, "Triangle": TRIANGLE, "TriangleNormals": TRIANGLE_NORMALS, "Sphere": SPHERE,
    "Cylinder": CYLINDER, "Instance": INSTANCE,
    "ShapeInfo": SHAPE_INFO, "Bsdf": BSDF, "Light": LIGHT, "Medium": MEDIUM, "GridVolume": GRID_VOLUME,
    "RenderParams": RENDER_PARAMS, "TriangleUv": TRIANGLE_UV, "UvMap": UV_MAP, "Texture": TEXTURE,
    "PhaseLobe": PHASE_LOBE,
}
