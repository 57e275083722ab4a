"""The packet renderer's rough plastic triangles (kernels/lanes_rough.h): which tested triangles
its vector step scatters from in the lanes, and their numbers in the lanes table
(kernels/wavefront_state.h WF_TRI_ROUGH_...).

The lanes' arithmetic is the renderer's for one case of Mitsuba's roughplastic: GGX sampled by
its visible normals, isotropic roughness and specular reflectance constant, the diffuse
reflectance a constant or a bilinear bitmap of three byte-coded channels on the mesh's own uvs;
on a flat, opaque, non-emitting triangle whose bsdf record is the roughplastic itself (no
wrapper). Every other rough plastic stays with the megakernel's scalar step.
"""
from __future__ import annotations

import numpy as np

from . import layout

# a triangle's rough coordinates (WF_TRI_ROUGH_...)
ALPHA, SW, ETA, INV_ETA2, INTERNAL, NONLINEAR, SPEC_R, TABLE, TEXTURED, TEX, TO_UV = (
    35, 36, 37, 38, 39, 40, 41, 44, 45, 46, 51)
UV = 20                 # the triangle's uvs (WF_TRI_UV), shared with the checkerboards
KIND = 2.0              # WF_TRI_LANES of a rough plastic triangle (1: plain diffuse)


def _bitmaps(packed, bsdf):
    """Which records' diffuse reflectance is a bilinear bitmap of three byte-coded channels."""
    textures = packed.arrays["textures"]
    index = bsdf["color_tex"]
    if len(textures) == 0 or not np.any(index >= 0):
        return np.zeros(len(bsdf), bool)
    t = textures[np.maximum(index, 0)]
    return ((index >= 0) & (t["type"] == layout.TEXTURE_TYPES["bitmap"])
            & (t["filter"] == layout.TEXTURE_FILTERS["bilinear"]) & (t["channels"] == 3) & (t["lut"] >= 0))


def surfaces(packed, codes, shape, bsdf) -> tuple[np.ndarray, np.ndarray]:
    """(rough, textured): which tested triangles (primitive codes `codes`, their shape and bsdf
    records) are rough plastic ones the lanes take, and which of those read a bitmap. The caller
    adds what every lanes triangle needs (flat, not emitting, a normal of known bits)."""
    flags = bsdf["flags"]
    bitmap = _bitmaps(packed, bsdf) & (shape["uv_map"] < 0) & (packed.arrays["triangles"]["uvs"][codes] >= 0)
    rough = ((bsdf["type"] == layout.BSDF_TYPES["roughplastic"])
             & (bsdf["distribution"] == layout.MICROFACETS["ggx"])
             & (flags & layout.BSDF_FLAGS["visible"] != 0)
             & (flags & (layout.BSDF_FLAGS["uv_frame"] | layout.BSDF_FLAGS["passes"]) == 0)
             & (bsdf["alpha_u"] == bsdf["alpha_v"]) & (bsdf["alpha_u_tex"] < 0) & (bsdf["alpha_v_tex"] < 0)
             & (bsdf["spec_r_tex"] < 0) & (bsdf["table"] >= 0)
             & ((bsdf["color_tex"] < 0) | bitmap))
    return rough, rough & bitmap


def fill(tri, packed, codes, bsdf, rough, textured):
    """The rough triangles' numbers into the table's triangle coordinates tri (coords, count,
    spacing), in place. Every triangle, rough or not, names a bitmap of the scene's rough ones
    where there is one: the lanes read one for every lane and select the constant where there is
    none."""
    as_float = lambda a: np.asarray(a, np.int32).view(np.float32)    # noqa: E731
    r = rough
    tri[ALPHA, r, 0] = bsdf["alpha_u"][r]
    tri[SW, r, 0] = bsdf["spec_weight"][r]
    tri[ETA, r, 0] = bsdf["eta"][r]
    tri[INV_ETA2, r, 0] = bsdf["inv_eta2"][r]
    tri[INTERNAL, r, 0] = bsdf["internal_refl"][r]
    tri[NONLINEAR, r, 0] = bsdf["flags"][r] & layout.BSDF_FLAGS["nonlinear"] != 0
    tri[SPEC_R:SPEC_R + 3, r, 0] = bsdf["spec_r"][r].T
    tri[TABLE, r, 0] = as_float(bsdf["table"][r])
    tri[TEXTURED, r, 0] = textured[r]
    if not textured.any():
        return
    textures = packed.arrays["textures"]
    tex = textures[np.where(textured, bsdf["color_tex"], bsdf["color_tex"][textured][0])]
    for k, field in enumerate(("width", "height", "wrap", "data", "lut")):
        tri[TEX + k, :, 0] = as_float(tex[field])
    tri[TO_UV:TO_UV + 6, :, 0] = tex["to_uv"].T
    uvs = packed.arrays["tri_uvs"]["uv"][np.maximum(packed.arrays["triangles"]["uvs"][codes], 0)]
    tri[UV:UV + 6, textured, 0] = uvs[textured].T
