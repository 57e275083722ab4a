"""Mitsuba bsdfs (src/bsdfs): their parameters, defaults and rules as Mitsuba 3.9 reads them.

Colour parameters take <rgb>/<spectrum>/<float> or a texture (volcl.scene.textures); roughness
(alpha, alpha_u, alpha_v) and opacity take a float or a texture where Mitsuba does. Microfacet
settings follow Mitsuba's MicrofacetDistribution: `distribution` beckmann (default) or ggx, either
`alpha` or both `alpha_u` and `alpha_v`, `sample_visible` (default true). Conductor `material`
presets are Mitsuba's measured tables as its RGB variants convert them (volcl.scene.conductors).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from . import objects
from .conductors import PRESETS
from .model import Bsdf, Texture
from .parse_common import Node, Spec
from .textures import check_texture_names, float_texture_param, texture_child, texture_param

_TEX = frozenset({"texture"})
_MICROFACET = {"distribution": "string", "alpha": "color", "alpha_u": "color", "alpha_v": "color",
               "sample_visible": "bool"}
_IORS = {"int_ior": "ior", "ext_ior": "ior"}
_DIELECTRIC = {**_IORS, "specular_reflectance": "color", "specular_transmittance": "color"}
_CONDUCTOR = {"material": "string", "eta": "color", "k": "color", "specular_reflectance": "color"}
_PLASTIC = {**_IORS, "diffuse_reflectance": "color", "specular_reflectance": "color", "nonlinear": "bool"}
_NORMALS = {"flip_invalid_normals": "bool", "use_shadowing_function": "bool"}

SPECS = {
    "diffuse": Spec({"reflectance": "color"}, children=_TEX),
    "twosided": Spec(children=frozenset({"bsdf"})),
    "dielectric": Spec(_DIELECTRIC, children=_TEX),
    "thindielectric": Spec(_DIELECTRIC, children=_TEX),
    "roughdielectric": Spec({**_DIELECTRIC, **_MICROFACET}, children=_TEX),
    "conductor": Spec(_CONDUCTOR, children=_TEX),
    "roughconductor": Spec({**_CONDUCTOR, **_MICROFACET}, children=_TEX),
    "plastic": Spec(_PLASTIC, children=_TEX),
    "roughplastic": Spec({**_PLASTIC, **_MICROFACET}, children=_TEX),
    "mask": Spec({"opacity": "color"}, children=frozenset({"bsdf", "texture"})),
    "bumpmap": Spec({"scale": "float", **_NORMALS}, children=frozenset({"bsdf", "texture"})),
    "normalmap": Spec(_NORMALS, children=frozenset({"bsdf", "texture"})),
    "null": Spec(),
}

# bsdfs with a transmission (or null) lobe: Mitsuba's twosided refuses to wrap them
_TRANSMITTING = ("dielectric", "roughdielectric", "thindielectric", "null", "mask")


def _transmits(b: Bsdf) -> bool:
    while b.kind in ("bumpmap", "normalmap"):
        b = b.nested
    return b.kind in _TRANSMITTING


def _diffuse(node: Node) -> Bsdf:
    reflectance = texture_param(node, "reflectance", 0.5)
    if not isinstance(reflectance, Texture):
        objects.warn_if_above_one(node, "reflectance", reflectance)
    check_texture_names(node, ("reflectance",))
    return Bsdf("diffuse", reflectance=reflectance)


def _twosided(node: Node) -> Bsdf:
    inner = node.objects("bsdf")
    if len(inner) != 1:
        raise node.fail(None, f"twosided wraps exactly one bsdf, found {len(inner)}")
    if _transmits(inner[0].obj):
        raise inner[0].element.error(f"twosided cannot wrap a {inner[0].obj.kind} bsdf: only "
                                     f"materials without transmission can be two-sided")
    # A copy, so that a shared bsdf referenced elsewhere stays one-sided there.
    wrapped = inner[0].obj
    return replace(wrapped, twosided=True, twosided_of=wrapped.twosided_of or wrapped)


def _specular_colours(node: Node) -> dict:
    return dict(specular_reflectance=texture_param(node, "specular_reflectance", 1.0),
                specular_transmittance=texture_param(node, "specular_transmittance", 1.0))


def _dielectric(node: Node) -> Bsdf:
    bsdf = Bsdf(node.type, int_ior=objects.ior(node, "int_ior", "bk7"), ext_ior=objects.ior(node, "ext_ior", "air"),
                **_specular_colours(node))
    if node.type == "roughdielectric":
        _differing_iors(node, bsdf)
        _microfacet(node, bsdf)
        if not bsdf.sample_visible:
            node.ctx.warn(node.at("sample_visible"), "roughdielectric with sample_visible=false: Mitsuba draws from a "
                                                     "widened distribution but weights the samples as if drawn from "
                                                     "the actual one, which biases its image; volcl renders what "
                                                     "Mitsuba renders (leave sample_visible on for an unbiased one)")
    check_texture_names(node, ("specular_reflectance", "specular_transmittance")
                        + (("alpha", "alpha_u", "alpha_v") if node.type == "roughdielectric" else ()))
    return bsdf


def _differing_iors(node: Node, bsdf: Bsdf) -> None:
    if bsdf.int_ior == bsdf.ext_ior:
        raise node.fail("int_ior", f"the interior and exterior indices of refraction must differ (both "
                                   f"{bsdf.int_ior:g}), as Mitsuba requires for {node.type}")


def _conductor(node: Node) -> Bsdf:
    material = node.string("material", "none")
    bsdf = Bsdf(node.type, specular_reflectance=texture_param(node, "specular_reflectance", 1.0))
    given = node.has("eta") or node.has("k") or texture_child(node, "eta") or texture_child(node, "k")
    if given or material == "none":
        if material != "none":
            raise node.fail("material", f"give either eta and k or a conductor material, not both "
                                        f"(material {material!r})")
        if given:
            # Mitsuba's defaults when either is given: eta 0, k 1 (which is itself a perfect mirror)
            bsdf.eta = texture_param(node, "eta", 0.0, kind="unbounded")
            bsdf.k = texture_param(node, "k", 1.0, kind="unbounded")
    else:
        if material not in PRESETS:
            raise node.fail("material", f"unknown conductor material {material!r}; Mitsuba's presets: "
                                        + ", ".join(PRESETS) + ", or \"none\"")
        eta, k = PRESETS[material]
        bsdf.eta, bsdf.k, bsdf.material = np.array(eta, np.float64), np.array(k, np.float64), material
    if node.type == "roughconductor":
        _microfacet(node, bsdf)
    check_texture_names(node, ("specular_reflectance", "eta", "k")
                        + (("alpha", "alpha_u", "alpha_v") if node.type == "roughconductor" else ()))
    return bsdf


def _plastic(node: Node) -> Bsdf:
    bsdf = Bsdf(node.type, reflectance=texture_param(node, "diffuse_reflectance", 0.5),
                specular_reflectance=texture_param(node, "specular_reflectance", 1.0),
                int_ior=objects.ior(node, "int_ior", "polypropylene"), ext_ior=objects.ior(node, "ext_ior", "air"),
                nonlinear=node.bool("nonlinear", False))
    if node.type == "roughplastic":
        _differing_iors(node, bsdf)
        _microfacet(node, bsdf, textures=False)
        if bsdf.anisotropic and bsdf.alpha_u != bsdf.alpha_v:
            raise node.fail("alpha_u", "roughplastic does not support anisotropic roughness (Mitsuba refuses "
                                       "alpha_u != alpha_v)")
        bsdf.anisotropic = False
    check_texture_names(node, ("diffuse_reflectance", "specular_reflectance"))
    return bsdf


def _microfacet(node: Node, bsdf: Bsdf, textures: bool = True) -> None:
    """distribution, alpha or alpha_u/alpha_v, sample_visible, with Mitsuba's rules."""
    distribution = node.string("distribution", "beckmann").lower()
    if distribution not in ("beckmann", "ggx"):
        raise node.fail("distribution", f"unknown microfacet distribution {node.string('distribution')!r}; "
                                        f"supported: beckmann, ggx")
    bsdf.distribution = distribution
    bsdf.sample_visible = node.bool("sample_visible", True)
    u = node.has("alpha_u") or texture_child(node, "alpha_u") is not None
    v = node.has("alpha_v") or texture_child(node, "alpha_v") is not None
    if u or v:
        if not (u and v):
            raise node.fail("alpha_u" if u else "alpha_v", "give both 'alpha_u' and 'alpha_v' (or 'alpha')")
        if node.has("alpha") or texture_child(node, "alpha") is not None:
            raise node.fail("alpha", "give either 'alpha' or 'alpha_u' and 'alpha_v', not both")
        bsdf.alpha_u = _alpha(node, "alpha_u", textures)
        bsdf.alpha_v = _alpha(node, "alpha_v", textures)
        bsdf.anisotropic = True
    else:
        bsdf.alpha_u = bsdf.alpha_v = _alpha(node, "alpha", textures)


def _alpha(node: Node, name: str, textures: bool):
    alpha = float_texture_param(node, name, 0.1, textures=textures)
    if not isinstance(alpha, Texture) and alpha <= 0:
        node.ctx.warn(node.at(name), f"'{name}' = {alpha:g}: Mitsuba clamps microfacet roughness to 1e-4 (use the "
                                     f"smooth model for a smooth surface); volcl does the same")
    return alpha


def _nested(node: Node) -> Bsdf:
    inner = node.objects("bsdf")
    if len(inner) != 1:
        raise node.fail(None, f"{node.type} wraps exactly one bsdf, found {len(inner)}")
    return inner[0].obj


def _mask(node: Node) -> Bsdf:
    opacity = float_texture_param(node, "opacity", 0.5)
    check_texture_names(node, ("opacity",))
    return Bsdf("mask", opacity=opacity, nested=_nested(node))


def _wraps_mask(b: Bsdf) -> bool:
    return b.kind == "mask" or (b.nested is not None and _wraps_mask(b.nested))


def _normal_wrapper(node: Node) -> Bsdf:
    nested = _nested(node)
    if _wraps_mask(nested):
        raise node.objects("bsdf")[0].element.error(
            f"{node.type} around a mask: shadow rays would not pass the mask's holes in Mitsuba either "
            f"(its {node.type} passes no light); put the mask outermost: mask({node.type}(...))")
    textures = node.objects("texture")
    if node.type == "bumpmap":
        if len(textures) != 1:
            raise node.fail(None, f"bumpmap needs exactly one texture (the heights), found {len(textures)}")
        tex = textures[0].obj
        if tex.kind != "bitmap":
            raise textures[0].element.error("bumpmap needs a bitmap texture: Mitsuba differentiates bitmaps only")
    else:
        child = texture_child(node, "normalmap")
        if child is None:
            raise node.fail(None, "normalmap needs a texture named 'normalmap'")
        check_texture_names(node, ("normalmap",))
        tex = child.obj
        if tex.kind != "bitmap" or tex.data.shape[2] != 3:
            raise child.element.error("the normal map must be an RGB bitmap (Mitsuba reads it as a colour, "
                                      "2 rgb - 1); use raw=true for its texels to be the stored numbers")
    return Bsdf(node.type, nested=nested, map_texture=tex, scale=node.float("scale", 1.0),
                flip_invalid_normals=node.bool("flip_invalid_normals", True),
                use_shadowing_function=node.bool("use_shadowing_function", True))


_BSDFS = {"diffuse": _diffuse, "twosided": _twosided, "dielectric": _dielectric, "thindielectric": _dielectric,
          "roughdielectric": _dielectric, "conductor": _conductor, "roughconductor": _conductor,
          "plastic": _plastic, "roughplastic": _plastic, "mask": _mask, "bumpmap": _normal_wrapper,
          "normalmap": _normal_wrapper, "null": lambda node: Bsdf("null")}


def build_bsdf(node: Node) -> Bsdf:
    bsdf = _BSDFS[node.type](node)
    bsdf.id = node.element.attrs.get("id", "")
    bsdf.source = node.source()
    return bsdf
