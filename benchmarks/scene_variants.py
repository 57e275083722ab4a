"""Where a scene's time goes, by taking its parts away: the megakernel's rate on a Mitsuba-dialect
scene and on variants of it with parts made plain, on every CPU OpenCL implementation present.

    python benchmarks/scene_variants.py [--scene scenes/textured_cbox.xml] [--size 128x128]
        [--spp 64] [--rounds 3] [--engine megakernel|auto] [--albedo]

Variants, each a copy of the file edited with ElementTree:
  - "plain textures on SHAPE": that shape's textures replaced by constants (a colour parameter by
    grey 0.5, a float one by 0.2) and its normal or bump map by the bsdf inside it;
  - "plain textures": that on every shape;
  - "plain textures, GGX": also every rough bsdf's distribution set to GGX (Mitsuba's roughplastic
    and roughconductor default to Beckmann);
  - "plain textures, rough bsdfs Beckmann with sample_visible false": the Beckmann ones sampling all
    normals instead of the visible ones;
  - "every bsdf diffuse": every shape's bsdf a grey diffuse one (emitters kept);
with --albedo instead (the paths as long as in the scene, so that a variant's rate moves by what
its bsdfs cost, not by how far its paths go):
  - "diffuse on SHAPE, ...": those shapes' bsdfs made diffuse with their own albedo (a constant
    reflectance as it is, a bitmap's mean linear colour; 0.5 grey for a conductor), plain diffuse
    triangles that the packet renderer's vector step takes.
Prints, in Markdown, M samples/s of Renderer.render (--engine, default "megakernel"; "auto" the
renderer each implementation takes by default; after a 1-spp warm-up,
best of --rounds, the implementations interleaved) and each implementation's rate over the first
one's: where an implementation loses against another, the variant whose ratio moves names the part.
"""
from __future__ import annotations

import argparse
import copy
import os
import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))
from common import cpu_model, log  # noqa: E402
from render_throughput import volcl_render_alone  # noqa: E402

WRAPPERS = ("normalmap", "bumpmap")
ROUGH = ("roughplastic", "roughconductor", "roughdielectric")
FLOAT_PARAMS = ("alpha", "alpha_u", "alpha_v", "opacity")


def short_name(platform: str) -> str:
    return "PoCL" if "Portable" in platform else platform.split()[0].replace("(R)", "")


def shape_label(shape, k: int) -> str:
    return shape.get("id") or f"{shape.get('type')} {k}"


def plain_textures(bsdf):
    """Constants for the textures of `bsdf` and of the bsdfs nested in it, in place; a normal or
    bump map wrapper is replaced by its inner bsdf (returned)."""
    while bsdf.get("type") in WRAPPERS:
        bsdf = bsdf.find("bsdf")
    for parent in bsdf.iter("bsdf"):        # bsdf itself first
        for i, child in enumerate(list(parent)):
            if child.tag != "texture":
                continue
            name = child.get("name")
            const = (ET.Element("float", name=name, value="0.2") if name in FLOAT_PARAMS
                     else ET.Element("rgb", name=name, value="0.5, 0.5, 0.5"))
            parent.remove(child)
            parent.insert(i, const)
    return bsdf


def edit_bsdfs(root, fn, only=None):
    """Every shape's bsdf (or shape `only`'s) replaced by fn(bsdf)."""
    for k, shape in enumerate(root.iter("shape")):
        if only is not None and k != only:
            continue
        bsdf = shape.find("bsdf")
        if bsdf is None:
            continue
        i = list(shape).index(bsdf)
        shape.remove(bsdf)
        shape.insert(i, fn(bsdf))


def set_rough(bsdf, distribution=None, visible=None):
    for b in bsdf.iter("bsdf"):
        if b.get("type") not in ROUGH:
            continue
        dist = b.find("string[@name='distribution']")
        beckmann = dist is None or dist.get("value") == "beckmann"
        if distribution and beckmann:
            if dist is None:
                dist = ET.SubElement(b, "string", name="distribution")
            dist.set("value", distribution)
        if visible is not None and beckmann:
            ET.SubElement(b, "boolean", name="sample_visible", value=str(visible).lower())
    return bsdf


def diffuse(_bsdf):
    b = ET.Element("bsdf", type="diffuse")
    ET.SubElement(b, "rgb", name="reflectance", value="0.5, 0.5, 0.5")
    return b


def albedo(bsdf, folder: Path) -> str:
    """The diffuse albedo of `bsdf` (inside its wrappers) as an rgb value: its reflectance or
    diffuse_reflectance parameter, a bitmap's mean linear colour, 0.5 grey for anything else."""
    while bsdf.get("type") in WRAPPERS:
        bsdf = bsdf.find("bsdf")
    for name in ("reflectance", "diffuse_reflectance"):
        rgb = bsdf.find(f"rgb[@name='{name}']")
        if rgb is not None:
            return rgb.get("value")
        tex = bsdf.find(f"texture[@name='{name}']")
        if tex is not None and tex.get("type") == "bitmap":
            from volcl.scene.images import read_image
            raw = tex.find("boolean[@name='raw']")
            pixels = read_image(str(folder / tex.find("string[@name='filename']").get("value")),
                                raw=raw is not None and raw.get("value") == "true")
            colour = pixels[..., :3]
            mean = colour.reshape(-1, colour.shape[-1]).mean(axis=0)
            return ", ".join(f"{float(v):.4f}" for v in np.broadcast_to(mean, 3))
    return "0.5, 0.5, 0.5"


def albedo_diffuse(folder: Path):
    def make(bsdf):
        b = ET.Element("bsdf", type="diffuse")
        ET.SubElement(b, "rgb", name="reflectance", value=albedo(bsdf, folder))
        return b
    return make


def albedo_variants(tree, folder: Path) -> list[tuple[str, ET.ElementTree]]:
    """"as shipped", then the non-diffuse shapes made diffuse of their own albedo one by one, then
    cumulatively in file order."""
    out = [("as shipped", tree)]
    shapes = [(k, shape_label(s, k)) for k, s in enumerate(tree.getroot().iter("shape"))
              if s.find("bsdf") is not None and s.find("bsdf").get("type") != "diffuse"]

    def edited(ks):
        t = copy.deepcopy(tree)
        for k in ks:
            edit_bsdfs(t.getroot(), albedo_diffuse(folder), k)
        return t
    for k, label in shapes:
        out.append((f"diffuse on {label}", edited([k])))
    for n in range(2, len(shapes) + 1):
        out.append(("diffuse on " + ", ".join(label for _, label in shapes[:n]), edited([k for k, _ in shapes[:n]])))
    return out


def has_texture(shape) -> bool:
    bsdf = shape.find("bsdf")
    return bsdf is not None and (bsdf.get("type") in WRAPPERS or bsdf.find(".//texture") is not None)


def variants(tree) -> list[tuple[str, ET.ElementTree]]:
    out = [("as shipped", tree)]

    def edited(*edits):
        t = copy.deepcopy(tree)
        for fn, only in edits:
            edit_bsdfs(t.getroot(), fn, only)
        return t
    for k, shape in enumerate(tree.getroot().iter("shape")):
        if has_texture(shape):
            out.append((f"plain textures on {shape_label(shape, k)}", edited((plain_textures, k))))
    out.append(("plain textures", edited((plain_textures, None))))
    out.append(("plain textures, GGX", edited((plain_textures, None), (lambda b: set_rough(b, "ggx"), None))))
    out.append(("plain textures, Beckmann with sample_visible false",
                edited((plain_textures, None), (lambda b: set_rough(b, visible=False), None))))
    out.append(("every bsdf diffuse", edited((diffuse, None))))
    return out


def write_variants(scene: Path, folder: Path, by_albedo: bool = False) -> list[tuple[str, Path]]:
    """(label, file) of every variant of `scene` (albedo_variants with by_albedo), written into
    `folder` beside links to the scene folder's subfolders (textures, meshes), so that relative file
    names resolve."""
    for entry in scene.parent.iterdir():
        if entry.is_dir():
            os.symlink(entry, folder / entry.name)
    out = []
    made = albedo_variants(ET.parse(scene), scene.parent) if by_albedo else variants(ET.parse(scene))
    for k, (label, tree) in enumerate(made):
        path = folder / f"variant{k}.xml"
        tree.write(path)
        out.append((label, path))
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scene", default=str(HERE.parent / "scenes" / "textured_cbox.xml"))
    p.add_argument("--size", default="128x128")
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--engine", default="megakernel", choices=["megakernel", "auto"])
    p.add_argument("--albedo", action="store_true", help="the albedo-matched diffuse variants")
    args = p.parse_args(argv)
    import volcl
    from volcl import device as devmod
    from volcl.renderer import Renderer
    w, h = (int(v) for v in args.size.split("x"))
    scene = Path(args.scene).resolve()
    devices = [d for d in devmod.list_devices() if d.kind == "cpu"]
    names = [short_name(d.platform_name) for d in devices]
    print(f"# Scene variants of {scene.name}\n\n- CPU: {cpu_model()}, {os.cpu_count()} cores")
    print(f"- {w}x{h}, {args.spp} spp, engine {args.engine}, render alone, best of {args.rounds} interleaved rounds\n")
    print("| variant | " + " | ".join(f"{n} M samples/s" for n in names)
          + "".join(f" | {n}/{names[0]}" for n in names[1:]) + " |")
    print("|---|" + "---|" * (2 * len(names) - 1))
    with tempfile.TemporaryDirectory() as tmp:
        for label, path in write_variants(scene, Path(tmp), args.albedo):
            log(label)
            model = volcl.load_file(str(path), width=w, height=h)
            renderers = [Renderer(model, device=d, engine=args.engine) for d in devices]
            for r in renderers:
                r.render(1)
            best = [float("inf")] * len(renderers)
            for _ in range(args.rounds):
                for i, r in enumerate(renderers):
                    best[i] = min(best[i], volcl_render_alone(r, args.spp)[0])
            rates = [w * h * args.spp / b / 1e6 for b in best]
            print(f"| {label} | " + " | ".join(f"{x:.3f}" for x in rates)
                  + "".join(f" | {x / rates[0]:.2f}" for x in rates[1:]) + " |", flush=True)


if __name__ == "__main__":
    main()
