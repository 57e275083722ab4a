"""The packet renderer's bsdf steps beyond plain diffuse: which tested triangles its vector step
scatters from in the lanes as rough plastic ones (kernels/lanes_rough.h), and their numbers in the
lanes table (kernels/wavefront_state.h WF_TRI_ROUGH_..., WF_TRI_BITMAP...).

The lanes' arithmetic is the renderer's for one case of Mitsuba's roughplastic, as the shape's own
bsdf (no wrapper) on a flat, opaque, non-emitting triangle: GGX sampled by its visible normals,
isotropic roughness and specular reflectance constant, the diffuse reflectance a constant or a
bilinear bitmap of three byte-coded channels on the mesh's own uvs (kernels/lanes_bitmap.h).
Every other rough plastic stays with the megakernel's scalar step. (A step for normal-mapped
diffuse triangles, with the same bits, ran no faster than their scalar steps: README.)
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from . import layout

# a triangle's coordinates in the table (WF_TRI_...)
UV = 20
ALPHA, SW, ETA, INV_ETA2, INTERNAL, NONLINEAR, SPEC_R, TABLE, TEXTURED = 35, 36, 37, 38, 39, 40, 41, 44, 45
BITMAP, BITMAP_TO_UV = 46, 51
ROUGH = 2.0             # WF_TRI_LANES of a rough plastic triangle (1: plain diffuse)
FLAGS = layout.BSDF_FLAGS


class Surfaces(NamedTuple):
    """Per tested triangle: a rough plastic one the step takes, one of those whose reflectance is a
    bitmap, and the bitmap it reads (a texture index, -1 for none)."""
    rough: np.ndarray
    textured: np.ndarray
    bitmap: np.ndarray


def _bitmaps(packed, index, shape, codes):
    """Which texture indices name a bilinear bitmap of three byte-coded channels that the lanes read
    at the triangle's own uvs."""
    textures = packed.arrays["textures"]
    if len(textures) == 0 or not np.any(index >= 0):
        return np.zeros(len(index), bool)
    t = textures[np.maximum(index, 0)]
    return ((index >= 0) & (t["type"] == layout.TEXTURE_TYPES["bitmap"])
            & (t["filter"] == layout.TEXTURE_FILTERS["bilinear"]) & (t["channels"] == 3) & (t["lut"] >= 0)
            & (shape["uv_map"] < 0) & (packed.arrays["triangles"]["uvs"][codes] >= 0))


def surfaces(packed, codes, shape, bsdf, keep) -> Surfaces:
    """Which tested triangles (primitive codes `codes`, their shape and bsdf records) the bsdf steps
    take, of those where `keep` holds: what every lanes triangle needs (flat, not emitting, a normal
    of known bits), or all False where the renderer takes no bsdf step."""
    if not np.any(keep):
        none = np.zeros(len(codes), bool)
        return Surfaces(none, none, np.full(len(codes), -1, np.int32))
    flags = bsdf["flags"]
    bitmap = _bitmaps(packed, bsdf["color_tex"], shape, codes)
    rough = ((bsdf["type"] == layout.BSDF_TYPES["roughplastic"])
             & (bsdf["distribution"] == layout.MICROFACETS["ggx"]) & (flags & FLAGS["visible"] != 0)
             & (flags & (FLAGS["uv_frame"] | FLAGS["passes"]) == 0)
             & (bsdf["alpha_u"] == bsdf["alpha_v"]) & (bsdf["alpha_u_tex"] < 0) & (bsdf["alpha_v_tex"] < 0)
             & (bsdf["spec_r_tex"] < 0) & (bsdf["table"] >= 0) & ((bsdf["color_tex"] < 0) | bitmap) & keep)
    return Surfaces(rough, rough & bitmap, np.where(rough & bitmap, bsdf["color_tex"], -1))


def fill(tri, packed, codes, bsdf, s: Surfaces):
    """Their numbers into the table's triangle coordinates tri (coords, count, spacing), in place.
    Every triangle, taken or not, names a bitmap the lanes read where the scene has one: the lanes
    read one for every lane and select what they need."""
    as_float = lambda a: np.asarray(a, np.int32).view(np.float32)    # noqa: E731
    r = s.rough
    tri[ALPHA, r, 0] = bsdf["alpha_u"][r]
    tri[SW, r, 0] = bsdf["spec_weight"][r]
    tri[ETA, r, 0] = bsdf["eta"][r]
    tri[INV_ETA2, r, 0] = bsdf["inv_eta2"][r]
    tri[INTERNAL, r, 0] = bsdf["internal_refl"][r]
    tri[NONLINEAR, r, 0] = bsdf["flags"][r] & FLAGS["nonlinear"] != 0
    tri[SPEC_R:SPEC_R + 3, r, 0] = bsdf["spec_r"][r].T
    tri[TABLE, r, 0] = as_float(bsdf["table"][r])
    tri[TEXTURED, r, 0] = s.textured[r]
    reads = s.bitmap >= 0
    if not reads.any():
        return
    tex = packed.arrays["textures"][np.where(reads, s.bitmap, s.bitmap[reads][0])]
    for k, field in enumerate(("width", "height", "wrap", "data", "lut")):
        tri[BITMAP + k, :, 0] = as_float(tex[field])
    tri[BITMAP_TO_UV:BITMAP_TO_UV + 6, :, 0] = tex["to_uv"].T
    uvs = packed.arrays["tri_uvs"]["uv"][np.maximum(packed.arrays["triangles"]["uvs"][codes], 0)]
    tri[UV:UV + 6, reads, 0] = uvs[reads].T
