#!/usr/bin/env python3
"""What each bsdf costs to render, in volcl and in Mitsuba 3: one small scene per bsdf (a sphere
of that material on a checkerboard floor, under the sky map of scenes/textures/sky.exr and a
panel light; the same Mitsuba-dialect file for both renderers), measured as
benchmarks/render_throughput.py measures "render alone" (after a warm-up pass, so no kernel build
counts), in CPU seconds of the rendering process (load from other jobs disturbs them less than
wall time), best of --rounds with the scenes and renderers interleaved.

    python benchmarks/bsdf_cost.py [--bsdfs diffuse roughconductor ...] [--size 128x128]
        [--spp 64] [--rounds 2] [--mitsuba-python PY] [--variant V] [--keep DIR]

The diffuse sphere is the baseline: "vs diffuse" is each bsdf's rate over the diffuse sphere's,
in volcl and in Mitsuba, from the same run; "volcl/Mitsuba" is volcl's rate over Mitsuba's.
"""
from __future__ import annotations

import argparse
import re
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
import mitsuba_ref  # noqa: E402
import render_throughput  # noqa: E402
from common import cpu_model, log  # noqa: E402

TEXTURES = ROOT / "scenes" / "textures"

# the sphere's material in each scene (Mitsuba 3 syntax)
BSDFS = {
    "diffuse": '<bsdf type="diffuse"><rgb name="reflectance" value="0.6, 0.4, 0.3"/></bsdf>',
    "conductor": '<bsdf type="conductor"><string name="material" value="Au"/></bsdf>',
    "dielectric": '<bsdf type="dielectric"/>',
    "thindielectric": '<bsdf type="thindielectric"/>',
    "plastic": '<bsdf type="plastic"><rgb name="diffuse_reflectance" value="0.6, 0.2, 0.2"/></bsdf>',
    "roughconductor-ggx-0.1": '<bsdf type="roughconductor"><string name="material" value="Cu"/>'
                              '<float name="alpha" value="0.1"/></bsdf>',
    "roughconductor-beckmann-0.3": '<bsdf type="roughconductor"><string name="distribution" value="beckmann"/>'
                                   '<float name="alpha" value="0.3"/></bsdf>',
    "roughconductor-anisotropic": '<bsdf type="roughconductor"><float name="alpha_u" value="0.05"/>'
                                  '<float name="alpha_v" value="0.3"/></bsdf>',
    "roughdielectric-ggx-0.1": '<bsdf type="roughdielectric"><float name="alpha" value="0.1"/></bsdf>',
    "roughdielectric-beckmann-0.3": '<bsdf type="roughdielectric"><string name="distribution" value="beckmann"/>'
                                    '<float name="alpha" value="0.3"/></bsdf>',
    "roughplastic-ggx-0.1": '<bsdf type="roughplastic"><rgb name="diffuse_reflectance" value="0.2, 0.3, 0.6"/>'
                            '<float name="alpha" value="0.1"/></bsdf>',
    "mask-0.5": '<bsdf type="mask"><float name="opacity" value="0.5"/><bsdf type="diffuse"/></bsdf>',
    "bumpmap": f'<bsdf type="bumpmap"><texture type="bitmap"><string name="filename" value="{TEXTURES / "bumps.exr"}"/>'
               '<boolean name="raw" value="true"/></texture><float name="scale" value="0.5"/>'
               '<bsdf type="roughplastic"><float name="alpha" value="0.1"/></bsdf></bsdf>',
    "normalmap": f'<bsdf type="normalmap"><texture type="bitmap" name="normalmap"><string name="filename" '
                 f'value="{TEXTURES / "plaster_normals.png"}"/><boolean name="raw" value="true"/></texture>'
                 '<bsdf type="diffuse"/></bsdf>',
    "textured diffuse": f'<bsdf type="diffuse"><texture type="bitmap" name="reflectance"><string name="filename" '
                        f'value="{TEXTURES / "wood.png"}"/></texture></bsdf>',
}

SCENE = """<scene version="3.0.0">
    <default name="spp" value="64"/>
    <default name="width" value="128"/>
    <default name="height" value="128"/>
    <integrator type="path"><integer name="max_depth" value="8"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="30"/>
        <transform name="to_world"><lookat origin="0, 1.2, 4" target="0, 0.5, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
        <film type="hdrfilm"><integer name="width" value="$width"/><integer name="height" value="$height"/>
            <rfilter type="box"/></film>
    </sensor>
    <emitter type="envmap"><string name="filename" value="{sky}"/><float name="scale" value="0.5"/></emitter>
    <shape type="rectangle">
        <transform name="to_world"><scale value="0.5"/><rotate x="1" angle="120"/><translate x="-1" y="2.5" z="1"/></transform>
        <emitter type="area"><rgb name="radiance" value="12"/></emitter>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><scale value="3"/><rotate x="1" angle="-90"/></transform>
        <bsdf type="diffuse"><texture type="checkerboard" name="reflectance"><rgb name="color0" value="0.7"/>
            <rgb name="color1" value="0.15"/><transform name="to_uv"><scale value="8"/></transform></texture></bsdf>
    </shape>
    <shape type="sphere">
        <point name="center" value="0, 0.5, 0"/><float name="radius" value="0.5"/>
        {bsdf}
    </shape>
</scene>
"""


def write_scenes(folder: Path, names) -> list[Path]:
    paths = []
    for name in names:
        path = folder / f"bsdf_{re.sub(r'[^A-Za-z0-9.-]+', '_', name)}.xml"
        path.write_text(SCENE.format(sky=TEXTURES / "sky.exr", bsdf=BSDFS[name]))
        paths.append(path)
    return paths


def measure(paths, args, mts, device):
    """Best render-alone CPU seconds of each scene in volcl and in Mitsuba, interleaved by round."""
    size = tuple(int(x) for x in args.size.lower().split("x"))
    best = {}
    for rnd in range(args.rounds):
        for path in paths:
            log(f"round {rnd + 1}: {path.name}")
            r = render_throughput.volcl_renderer(path, {}, size, 0, device)
            _, cpu, invalid = render_throughput.volcl_render_alone(r, args.spp)
            del r
            best[path, "volcl"] = min(best.get((path, "volcl"), float("inf")), cpu)
            best[path, "invalid"] = max(best.get((path, "invalid"), 0), invalid)
            if mts:
                res = mitsuba_ref.render_mitsuba(str(path), None, mts["python"], args.variant, args.spp, 0,
                                                 {"width": size[0], "height": size[1]}, 1, details=True)
                best[path, "mitsuba"] = min(best.get((path, "mitsuba"), float("inf")), res["cpu_seconds"])
    return best


def table(names, paths, best, samples) -> str:
    base = paths[names.index("diffuse")]
    rows = ["| bsdf | volcl M samples/CPU s | vs diffuse | Mitsuba M samples/CPU s | vs diffuse | volcl/Mitsuba |",
            "|---|---:|---:|---:|---:|---:|"]
    for name, path in zip(names, paths):
        v, vb = best[path, "volcl"], best[base, "volcl"]
        cells = [name + (f" ({best[path, 'invalid']} invalid)" if best[path, "invalid"] else ""),
                 f"{samples / v / 1e6:.3f}", f"{vb / v:.2f}"]
        if (path, "mitsuba") in best:
            m, mb = best[path, "mitsuba"], best[base, "mitsuba"]
            cells += [f"{samples / m / 1e6:.3f}", f"{mb / m:.2f}", f"{m / v:.2f}"]
        else:
            cells += ["–", "–", "–"]
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--bsdfs", nargs="+", default=list(BSDFS), choices=list(BSDFS), metavar="BSDF")
    p.add_argument("--size", default="128x128")
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--device", help="volcl device selector")
    p.add_argument("--variant", default=mitsuba_ref.DEFAULT_VARIANT)
    p.add_argument("--keep", help="write the scene files here (default: a temporary folder)")
    mitsuba_ref.add_argument(p)
    args = p.parse_args(argv)
    from volcl import device as devmod
    device = devmod.choose(args.device)
    mts = mitsuba_ref.locate(args.mitsuba_python, args.variant, log=log)
    names = args.bsdfs if "diffuse" in args.bsdfs else ["diffuse"] + args.bsdfs
    w, h = (int(x) for x in args.size.lower().split("x"))
    with tempfile.TemporaryDirectory(prefix="volcl-bsdf-cost-") as tmp:
        folder = Path(args.keep) if args.keep else Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        paths = write_scenes(folder, names)
        best = measure(paths, args, mts, device)
    print(f"{cpu_model()}; volcl on {device.key} {device.name}"
          + (f", Mitsuba {mts['version']} {args.variant}" if mts else ", no Mitsuba")
          + f"; {w}x{h}, {args.spp} spp, render alone (after a warm-up), best of {args.rounds} interleaved rounds\n")
    print(table(names, paths, best, w * h * args.spp))


if __name__ == "__main__":
    main()
