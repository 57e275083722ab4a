"""What the majorant grid buys on a sparse density grid, and whether the image agrees with Mitsuba 3.

    python benchmarks/grid_majorants.py [--scene scenes/smoke_grid.xml] [--spp 32] [--repeat 2]
        [--densities 15 60 200] [--cells 1 2 6 24] [--compare-spp 256] [--mitsuba-python PATH]
        [-D name=value ...]

1. Throughput: the scene (default scenes/smoke_grid.xml: a 48^3 smoke grid, 15% of its voxels
   non-zero, in the Cornell box) rendered by volcl with majorant grids of each --cells per axis
   (1 = a single global majorant for the whole grid) and with volcl's default (about one cell per
   grids.MAJORANT_CELL_VOXELS voxels per axis, 12^3 here), for each of --densities (the scene
   parameter `density`, the medium's scale: its largest extinction per unit length; the scene's
   own default is 15; `--densities` alone keeps the scene as it is). "seconds" is the best of
   --repeat warm renders at --spp (after a 1-spp warm-up on the same Renderer; the repeats cycle
   through the variants, so load from other processes spreads over all of them); "M samples/s" is
   width * height * spp / seconds / 1e6; "speed-up" is relative to the single global majorant.
   Every variant estimates the same image: the table also gives the difference of its image mean
   from the default's in standard errors (z per channel r g b), which should stay within a few
   (at low spp the variance estimate itself is rough: the light's edge pixels are all-or-nothing).
2. Agreement with Mitsuba 3 `volpathmis` on the same file, when Mitsuba is found (--mitsuba-python,
   $VOLCL_MITSUBA_PYTHON, or this interpreter): benchmarks/compare_mitsuba.py at --compare-spp with
   the same -D values (R about 1 and PASS when both renderers estimate the same image).
   --compare-spp 0 skips it.

The scene's defaults are 256x256; pass -D width=128 -D height=128 for a quicker run. Progress goes
to stderr, the results to stdout.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))
import compare_mitsuba  # noqa: E402
import mitsuba_ref  # noqa: E402
from common import log  # noqa: E402



def timed_renders(scene, device, spp, repeat, variants, seed):
    """Best-of-`repeat` seconds and the last result per variant (majorant cells). The repeats
    interleave the variants, so that a load change on a shared machine hits them alike."""
    from volcl.renderer import Renderer
    renderers = []
    for k, cells in enumerate(variants):
        r = Renderer(scene, device=device, seed=seed + k, majorant_cells=cells)
        r.render(1)                     # warm-up: PoCL compiles the work-group function at first launch
        renderers.append(r)
    best, results = [math.inf] * len(variants), [None] * len(variants)
    for _ in range(repeat):
        for k, r in enumerate(renderers):
            r.reset()
            t0 = time.perf_counter()
            results[k] = r.render(spp)
            best[k] = min(best[k], time.perf_counter() - t0)
    return best, results, [r.packed.stats["majorant_cells"] for r in renderers]


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scene", default=str(ROOT / "scenes" / "smoke_grid.xml"))
    p.add_argument("--spp", type=int, default=32)
    p.add_argument("--repeat", type=int, default=2)
    p.add_argument("--cells", type=int, nargs="*", default=[1, 2, 6, 24],
                   help="majorant cells per axis to time besides the default")
    p.add_argument("--densities", nargs="*", default=["15", "60", "200"],
                   help="values of the scene parameter `density` to time at")
    p.add_argument("--compare-spp", type=int, default=256)
    p.add_argument("--device")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("-D", "--define", action="append", metavar="NAME=VALUE")
    mitsuba_ref.add_argument(p)
    args = p.parse_args(argv)

    from volcl import device as devmod
    from volcl.grids import MAJORANT_CELL_VOXELS
    from volcl.scene import load
    base = compare_mitsuba.parse_defines(args.define)
    device = devmod.choose(args.device)
    print(f"scene {args.scene}, {args.spp} spp, best of {args.repeat}; volcl on {device.key} {device.name}; "
          f"default majorant cell: {MAJORANT_CELL_VOXELS} voxels per axis\n")
    print("| density | majorant cells | count | seconds | M samples/s | speed-up vs global | mean z (r g b) vs default "
          "| cut-offs |")
    print("|---:|---|---:|---:|---:|---:|---:|---:|")
    variants = [(None, "default")] + [(c, f"{c}^3" + (" (global)" if c == 1 else "")) for c in args.cells]
    for density in args.densities or [None]:
        defines = dict(base, **({"density": density} if density is not None else {}))
        scene = load(args.scene, defines)
        w, h = scene.camera.width, scene.camera.height
        log(f"density {density} ...")
        secs, results, ncells = timed_renders(scene, device, args.spp, args.repeat, [c for c, _ in variants],
                                              args.seed)
        ref = results[0]
        rows = [(label, n, t, w * h * args.spp / t / 1e6, res)
                for (_, label), n, t, res in zip(variants, ncells, secs, results)]
        global_rate = next((r[3] for r in rows if r[0].startswith("1^3")), None)
        for label, ncells, secs, rate, res in rows:
            z = "-"
            if res is not ref:
                # per channel: a pixel's channels are correlated, so only pixels add independently
                diff = (res.image.astype(np.float64) - ref.image.astype(np.float64)).reshape(-1, 3).sum(0)
                var = (res.variance.astype(np.float64) + ref.variance.astype(np.float64)).reshape(-1, 3).sum(0)
                z = " ".join(f"{v:+.1f}" for v in diff / np.sqrt(var))
            speed = f"{rate / global_rate:.2f}x" if global_rate else "-"
            print(f"| {density or 'scene'} | {label} | {ncells} | {secs:.2f} | {rate:.3f} | {speed} | {z} "
                  f"| {res.tracking_cutoffs} |", flush=True)
    print(f"\n({w}x{h} pixels)\n")

    if args.compare_spp <= 0:
        return 0
    cmp_args = [args.scene, "--spp", str(args.compare_spp)]
    for item in args.define or []:
        cmp_args += ["-D", item]
    if args.mitsuba_python:
        cmp_args += ["--mitsuba-python", args.mitsuba_python]
    if args.device:
        cmp_args += ["--device", args.device]
    print(f"Image against Mitsuba 3 volpathmis ({args.compare_spp} spp):")
    sys.stdout.flush()
    return compare_mitsuba.main(cmp_args)


if __name__ == "__main__":
    sys.exit(main())
