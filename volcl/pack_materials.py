"""Bsdfs and textures as the kernel arrays of the `bsdfs` part (volcl.pack): bsdf records (kernels/
types.h Bsdf), texture descriptors and one texel buffer (kernels/textures.h), and roughplastic's
precomputed tables (volcl.microfacet).

The bsdfs shapes name come first, in the order volcl.pack indexes them; the bsdfs they wrap (mask,
bump and normal maps) follow. Objects shared between bsdfs (a texture used twice, a nested
checkerboard) are stored once.
"""
from __future__ import annotations

import numpy as np

from . import layout
from .microfacet import fresnel_diffuse_reflectance, roughplastic_tables
from .scene.model import Bsdf, Texture, texture_mean

ROUGH = ("roughconductor", "roughdielectric", "roughplastic")
CONDUCTORS = ("conductor", "roughconductor")
DIELECTRICS = ("dielectric", "roughdielectric", "thindielectric")
PLASTICS = ("plastic", "roughplastic")
WRAPPERS = ("mask", "bumpmap", "normalmap")


def chain(bsdf: Bsdf):
    """The bsdf and those it wraps, outermost first."""
    while bsdf is not None:
        yield bsdf
        bsdf = bsdf.nested


def textures_of(bsdf: Bsdf):
    """Every texture one bsdf record reads (not those of the bsdf it wraps)."""
    values = [bsdf.reflectance, bsdf.eta, bsdf.k, bsdf.specular_reflectance, bsdf.specular_transmittance,
              bsdf.alpha_u, bsdf.alpha_v, bsdf.opacity, bsdf.map_texture]
    return [v for v in values if isinstance(v, Texture)]


def texture_tree(tex: Texture):
    yield tex
    for child in (tex.color0, tex.color1):
        if isinstance(child, Texture):
            yield from texture_tree(child)


def reads_uv(bsdf: Bsdf) -> bool:
    """Whether the kernels need texture coordinates at a hit of this bsdf."""
    return any(textures_of(b) or b.anisotropic or b.kind in ("bumpmap", "normalmap") for b in chain(bsdf))


def uv_frame(bsdf: Bsdf) -> bool:
    """Whether it needs Mitsuba's tangent frame (dp/du) rather than any frame around the normal."""
    return any(b.anisotropic or b.kind in ("bumpmap", "normalmap") for b in chain(bsdf))


def passes(bsdf: Bsdf) -> bool:
    """Whether a path can pass through it (a null lobe): masks, thin dielectrics."""
    return any(b.kind in ("mask", "thindielectric") for b in chain(bsdf))


def transmits(bsdf: Bsdf) -> bool:
    """Whether shadow rays can pass through it (kernels/bsdf_vertex.h surface_null_transmission): null
    surfaces, masks (opacity below one somewhere) and thin dielectrics. The others are opaque to the
    BVH's shadow query, which stops at the first opaque surface. A structural property: editing an
    opacity never changes it."""
    return bsdf.kind == "null" or passes(bsdf)


# bitmaps of fewer floats (texels times channels) than this keep float32 texels: the table of
# 256 would outweigh the saving
BYTE_CODED_MIN_SIZE = 1024


def byte_coded(data: np.ndarray):
    """(the 256-entry table of a bitmap's distinct float32 values, its texels as byte indices into
    the table, packed four to a float32 word) or None where it has more than 256 distinct values
    (a float image) or too few texels for it to pay. The kernel's lookup gives back the same bits
    (an 8-bit image decodes to at most 256 values: its bytes, through sRGB or not)."""
    flat = np.ascontiguousarray(data, np.float32).reshape(-1)
    if flat.size < BYTE_CODED_MIN_SIZE:
        return None
    values, codes = np.unique(flat.view(np.uint32), return_inverse=True)
    if len(values) > 256:
        return None
    lut = np.zeros(256, np.uint32)
    lut[:len(values)] = values
    packed = np.zeros(-(-flat.size // 4) * 4, np.uint8)
    packed[:flat.size] = codes.reshape(-1)
    return lut.view(np.float32), packed.view(np.float32)


class MaterialPacker:
    """Indices of every bsdf record and texture of a scene (its structure), and their packing."""

    def __init__(self, roots: list, extra_textures=()):
        self.records: list = []
        self.index: dict = {}
        for b in roots:
            self._add(b)
        for b in list(roots):
            for inner in list(chain(b))[1:]:
                self._add(inner)
        self.textures: list = []
        self.texture_index: dict = {}
        for b in self.records:
            for t in textures_of(b):
                self._add_texture(t)
        for t in extra_textures:
            self._add_texture(t)

    def _add_texture(self, root: Texture) -> None:
        for tex in texture_tree(root):
            if id(tex) not in self.texture_index:
                self.texture_index[id(tex)] = len(self.textures)
                self.textures.append(tex)

    def _add(self, b: Bsdf) -> None:
        if id(b) not in self.index:
            self.index[id(b)] = len(self.records)
            self.records.append(b)

    def tex(self, value) -> int:
        return self.texture_index[id(value)] if isinstance(value, Texture) else -1

    def arrays(self) -> dict:
        tables: list = []
        records = np.zeros(max(len(self.records), 1), layout.BSDF)
        for name in layout.BSDF_TEXTURE_FIELDS:
            records[name] = -1
        records["nested"] = records["table"] = -1
        for i, b in enumerate(self.records):
            self._record(records[i], b, tables)
        textures, texels = self._textures()
        return {"bsdfs": records, "textures": textures, "texels": texels,
                "bsdf_tables": np.asarray(np.concatenate(tables) if tables else np.zeros(1), np.float32)}

    def _colour(self, r, field: str, tex_field: str, value) -> None:
        """A colour parameter: its texture's index, or the constant."""
        if isinstance(value, Texture):
            r[tex_field] = self.tex(value)
        elif value is not None:
            r[field] = value

    def _scalar(self, r, field: str, tex_field: str, value) -> None:
        if isinstance(value, Texture):
            r[tex_field] = self.tex(value)
        else:
            r[field] = value

    def _record(self, r, b: Bsdf, tables: list) -> None:
        r["type"] = layout.BSDF_TYPES[b.kind]
        r["twosided"] = int(b.twosided)
        flags = 0
        if reads_uv(b):
            flags |= layout.BSDF_FLAGS["uv"]
        if uv_frame(b):
            flags |= layout.BSDF_FLAGS["uv_frame"]
        if passes(b):
            flags |= layout.BSDF_FLAGS["passes"]
        if b.nonlinear:
            flags |= layout.BSDF_FLAGS["nonlinear"]
        if b.sample_visible:
            flags |= layout.BSDF_FLAGS["visible"]
        if b.use_shadowing_function:
            flags |= layout.BSDF_FLAGS["shadowing"]
        if b.flip_invalid_normals:
            flags |= layout.BSDF_FLAGS["flip_invalid"]
        r["flags"] = flags
        r["spec_r"], r["spec_t"] = 1.0, 1.0
        r["eta"] = b.int_ior / b.ext_ior
        if b.kind == "diffuse":
            self._colour(r, "color", "color_tex", b.reflectance)
        elif b.kind in CONDUCTORS:
            self._colour(r, "color", "color_tex", b.specular_reflectance)
            r["conductor_mirror"] = int(b.eta is None)
            if b.eta is not None:
                self._colour(r, "cond_eta", "eta_tex", b.eta)
                self._colour(r, "cond_k", "k_tex", b.k)
        elif b.kind in DIELECTRICS:
            self._colour(r, "spec_r", "spec_r_tex", b.specular_reflectance)
            self._colour(r, "spec_t", "spec_t_tex", b.specular_transmittance)
        elif b.kind in PLASTICS:
            self._colour(r, "color", "color_tex", b.reflectance)
            self._colour(r, "spec_r", "spec_r_tex", b.specular_reflectance)
            eta = b.int_ior / b.ext_ior
            r["inv_eta2"] = 1.0 / (eta * eta)
            d_mean, s_mean = texture_mean(b.reflectance), texture_mean(b.specular_reflectance)
            r["spec_weight"] = s_mean / (d_mean + s_mean)
            if b.kind == "plastic":
                r["internal_refl"] = fresnel_diffuse_reflectance(1.0 / eta)
        if b.kind in ROUGH:
            r["distribution"] = layout.MICROFACETS[b.distribution]
            self._scalar(r, "alpha_u", "alpha_u_tex", b.alpha_u)
            self._scalar(r, "alpha_v", "alpha_v_tex", b.alpha_v)
        if b.kind == "roughplastic":
            table, internal = roughplastic_tables(b.distribution, float(b.alpha_u), float(r["eta"]))
            r["table"] = sum(len(t) for t in tables)
            tables.append(table)
            r["internal_refl"] = internal
        if b.kind in WRAPPERS:
            r["nested"] = self.index[id(b.nested)]
        if b.kind == "mask":
            self._scalar(r, "opacity", "opacity_tex", b.opacity)
        if b.kind in ("bumpmap", "normalmap"):
            r["map_tex"] = self.tex(b.map_texture)
            r["scale"] = b.scale

    def _textures(self):
        arr = np.zeros(max(len(self.textures), 1), layout.TEXTURE)
        arr["child0"] = arr["child1"] = arr["lut"] = -1
        texels, offset = [], 0
        for i, t in enumerate(self.textures):
            r = arr[i]
            r["type"] = layout.TEXTURE_TYPES[t.kind]
            r["to_uv"] = np.asarray(t.to_uv, np.float64)[:2].reshape(6)
            if t.kind == "bitmap":
                h, w, c = t.data.shape
                r["channels"], r["width"], r["height"] = c, w, h
                r["data"] = offset
                r["filter"], r["wrap"] = layout.TEXTURE_FILTERS[t.filter], layout.TEXTURE_WRAPS[t.wrap]
                coded = byte_coded(t.data)
                if coded is not None:
                    lut, words = coded
                    r["lut"], r["data"] = offset, offset + len(lut)
                    texels += [lut, words]
                    offset += len(lut) + len(words)
                else:
                    texels.append(np.ascontiguousarray(t.data, np.float32).reshape(-1))
                    offset += t.data.size
                continue
            for k, value in enumerate((t.color0, t.color1)):
                if isinstance(value, Texture):
                    r[f"child{k}"] = self.tex(value)
                else:
                    r[f"color{k}"] = value
                    r[f"mean{k}"] = float(np.mean(value))
        data = np.concatenate(texels) if texels else np.zeros(1, np.float32)
        return arr, data.astype(np.float32)
