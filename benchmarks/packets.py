"""The packet renderer (volcl/packets.py) against the megakernel: the same scene, seed and samples on
each OpenCL implementation present (or --device), render alone, interleaved.

    OPENBLAS_NUM_THREADS=1 python benchmarks/packets.py [--scenes scenes/cbox.xml scenes/textured_cbox.xml]
        [--size 128x128] [--spp 64] [--rounds 3] [--icospheres 0 1 2] [--widths 8 16] [--groups 1 64]
        [--vector-step on off] [--rough-step on off]

Prints, in Markdown, for each scene and implementation: M samples per second (wall) of the
megakernel and of the packet renderer at each packet width, packets per work-group and with or
without its vector step for diffuse lanes (kernels/packet_lanes.h), with or without the rough
step for rough plastic lanes (kernels/lanes_rough.h; only where the vector step is on), Renderer.render
after a 1-spp warm-up, best of --rounds, all of them interleaved in every round; the ratio to the
megakernel (above 1: faster); and whether the image has the megakernel's bits with the same seed.
--icospheres adds variants of the first scene with a diffuse icosphere of that many subdivisions
(20, 80, 320 triangles) hanging in it: where testing every primitive for every ray stops paying
(their packet renders ignore volcl.packets.MAX_PRIMITIVES).
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))
from common import cpu_model, log  # noqa: E402


def icosphere_variant(scene_path: Path, subdivisions: int, folder: Path) -> Path:
    """scene_path with a diffuse icosphere of radius 0.25 at (0, 1, 0.3) added, written to folder
    (its meshes resolved against the scene's own folder)."""
    import trimesh
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=0.25)
    mesh.apply_translation([0.0, 1.0, 0.3])
    obj = folder / f"icosphere{subdivisions}.obj"
    mesh.export(obj)
    text = scene_path.read_text().replace('value="meshes/', f'value="{scene_path.parent}/meshes/')
    extra = (f'<shape type="obj"><string name="filename" value="{obj}"/>'
             '<bsdf type="diffuse"><rgb name="reflectance" value="0.5"/></bsdf></shape></scene>')
    out = folder / f"{scene_path.stem}_icosphere{len(mesh.faces)}.xml"
    out.write_text(text.replace("</scene>", extra))
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scenes", nargs="+", type=Path,
                   default=[HERE.parent / "scenes" / "cbox.xml", HERE.parent / "scenes" / "textured_cbox.xml"])
    p.add_argument("--size", default="128x128")
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--device", default=None, help="one device (volcl's selector); default: every CPU device")
    p.add_argument("--icospheres", nargs="*", type=int, default=[])
    p.add_argument("--widths", nargs="+", type=int, default=[16])
    p.add_argument("--groups", nargs="+", type=int, default=[1])
    p.add_argument("--vector-step", nargs="+", choices=["on", "off"], default=["on"])
    p.add_argument("--rough-step", nargs="+", choices=["on", "off", "default"], default=["default"],
                   help="default: whichever the device's (packets.bsdf_steps_pay)")
    args = p.parse_args(argv)
    import volcl
    from volcl import device as devmod, packets
    from volcl.renderer import Renderer
    width, height = (int(v) for v in args.size.split("x"))
    devices = [devmod.resolve(args.device)] if args.device else [d for d in devmod.list_devices() if d.kind == "cpu"]
    folder = Path(tempfile.mkdtemp(prefix="volcl-packets-"))
    scenes = list(args.scenes) + [icosphere_variant(args.scenes[0], s, folder) for s in args.icospheres]
    rough = {"on": True, "off": False, "default": None}
    configs = [(w, g, v == "on", rough[r]) for w in args.widths for g in args.groups for v in args.vector_step
               for r in (args.rough_step if v == "on" else ["off"])]
    label = {True: ", rough step", False: ", no rough step", None: ""}
    print(f"- CPU: {cpu_model()}; {width}x{height}, {args.spp} spp, best of {args.rounds} interleaved rounds\n")
    print("| scene | device | primitives | megakernel M samples/s | "
          + " | ".join(f"packet {w} lanes, {g}/group{label[r] if v else ', scalar steps'}" for w, g, v, r in configs)
          + " | same bits |")
    print("|---|---|---|---|" + "---|" * len(configs) + "---|")
    for path in scenes:
        for dev in devices:
            scene = volcl.load_file(path, width=width, height=height)
            log(f"{path.name} on {dev.name}")
            limit, packets.MAX_PRIMITIVES = packets.MAX_PRIMITIVES, 1 << 30
            saved = packets.PACKET_WIDTH, packets.GROUP_PACKETS
            try:
                renderers = [Renderer(scene, device=dev, engine="megakernel")]
                for w, g, v, rs in configs:
                    packets.PACKET_WIDTH, packets.GROUP_PACKETS = w, g
                    r = Renderer(scene, device=dev, engine="packet")
                    # on or off whichever the device's default (packets.vector_step_pays)
                    r.wavefront = packets.Packets(r.device, r.features, r.packed, vector_step=v, bsdf_steps=rs)
                    renderers.append(r)
            finally:
                packets.MAX_PRIMITIVES = limit
                packets.PACKET_WIDTH, packets.GROUP_PACKETS = saved
            for r in renderers:
                r.render(1)
            best, images = [0.0] * len(renderers), [None] * len(renderers)
            for _ in range(args.rounds):
                for i, r in enumerate(renderers):
                    r.reset()
                    t0 = time.perf_counter()
                    images[i] = r.render(args.spp).image
                    best[i] = max(best[i], width * height * args.spp / (time.perf_counter() - t0) / 1e6)
            same = all(np.array_equal(images[0], im) for im in images[1:])
            cells = " | ".join(f"{b:.2f} ({b / best[0]:.2f}x)" for b in best[1:])
            print(f"| {path.name} | {dev.name} | {packets.primitive_count(renderers[0].packed)} | {best[0]:.2f} | "
                  f"{cells} | {'yes' if same else 'no'} |", flush=True)


if __name__ == "__main__":
    main()
