"""The wavefront renderer (volcl/wavefront.py) against the megakernel: the same scene, seed and
samples on each OpenCL implementation present.

    python benchmarks/wavefront.py [--scenes scenes/point_in_fog.xml] [--size 128x128] [--spp 128]
        [--rounds 3] [--paths 4096]

Prints, in Markdown, for each scene and implementation: render-alone seconds of each renderer, wall
and CPU (the process's, the runtime's threads included: what load from other processes disturbs
less), Renderer.render after a 1-spp warm-up, best of --rounds, the two interleaved; M samples per
second (wall), the ratios (above 1: the wavefront renderer is faster), the stage pairs it launched, and
how far its image is from the megakernel's with the same seed (the share of pixel channels that
differ by more than 1e-3 relative: vector arithmetic rounds differently, and a path a rounding
sends another way changes its pixel more). --paths sets the paths in flight (at most 65536).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))
from common import cpu_model, log  # noqa: E402


def timed(renderer, spp):
    """(wall seconds, CPU seconds of the process: the runtime's threads included, result)"""
    renderer.reset()
    c0, t0 = time.process_time(), time.perf_counter()
    result = renderer.render(spp)
    return time.perf_counter() - t0, time.process_time() - c0, result


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scenes", nargs="+", default=[str(HERE.parent / "scenes" / "point_in_fog.xml")])
    p.add_argument("--size", default="128x128")
    p.add_argument("--spp", type=int, default=128)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--paths", type=int, default=None)
    args = p.parse_args(argv)
    import volcl
    from volcl import device as devmod
    from volcl import wavefront
    from volcl.renderer import Renderer
    w, h = (int(v) for v in args.size.split("x"))
    devices = [d for d in devmod.list_devices() if d.kind == "cpu"]
    print(f"# Wavefront renderer against the megakernel\n\n- CPU: {cpu_model()}, {os.cpu_count()} cores")
    print(f"- {w}x{h}, {args.spp} spp, render alone, best of {args.rounds} interleaved rounds, "
          f"{args.paths or wavefront.PATHS} paths in flight\n")
    print("| scene | device | megakernel s (wall / CPU) | wavefront s (wall / CPU) | megakernel M samples/s "
          "| wavefront M samples/s | wavefront/megakernel (wall / CPU) | stage pairs | channels off by > 1e-3 |")
    print("|---|---|---|---|---|---|---|---|---|")
    for scene_file in args.scenes:
        scene = volcl.load_file(scene_file, width=w, height=h)
        for dev in devices:
            log(f"{Path(scene_file).name} on {dev.name}")
            mk = Renderer(scene, device=dev, engine="megakernel")
            wf = Renderer(scene, device=dev, engine="wavefront")
            if args.paths:
                wf.wavefront = wavefront.Wavefront(wf.device, wf.features, wf.packed, wf.group_items, args.paths)
            for r in (mk, wf):
                r.render(1)
            best = {"mk": np.inf, "wf": np.inf}
            best_cpu = {"mk": np.inf, "wf": np.inf}
            steps0 = wf.wavefront.steps
            for _ in range(args.rounds):
                for key, r in (("mk", mk), ("wf", wf)):
                    seconds, cpu, result = timed(r, args.spp)
                    best[key] = min(best[key], seconds)
                    best_cpu[key] = min(best_cpu[key], cpu)
                    if key == "mk":
                        image_mk = result.image
                    else:
                        image_wf = result.image
            pairs = (wf.wavefront.steps - steps0) // args.rounds
            rel = np.abs(image_wf - image_mk) / np.maximum(np.abs(image_mk), 1e-6)
            n = w * h * args.spp / 1e6
            print(f"| {Path(scene_file).name} | {dev.name} ({dev.platform_name}) "
                  f"| {best['mk']:.2f} / {best_cpu['mk']:.2f} | {best['wf']:.2f} / {best_cpu['wf']:.2f} "
                  f"| {n / best['mk']:.3f} | {n / best['wf']:.3f} "
                  f"| {best['mk'] / best['wf']:.2f} / {best_cpu['mk'] / best_cpu['wf']:.2f} | {pairs} "
                  f"| {np.mean(rel > 1e-3):.2%} |", flush=True)


if __name__ == "__main__":
    main()
