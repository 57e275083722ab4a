"""Does volcl render the same expected image as Mitsuba 3? An unbiasedness check per scene.

    python benchmarks/compare_mitsuba.py [SCENE.xml ...] [--spp 256] [--variant llvm_ad_rgb]
        [--seeds 0 1] [--out DIR] [--mitsuba-python PATH] [-D name=value ...]

For each scene (default: DEFAULT_SCENES, the Cornell box, the cloud under an environment map, the
rough glass holding a medium and the textured Cornell box) it renders two independent images with
volcl (seeds --seeds) and two with Mitsuba 3 (--variant, the same seeds, in a subprocess through the Python
that has Mitsuba: --mitsuba-python, $VOLCL_MITSUBA_PYTHON, or this interpreter), all at --spp,
writes the four EXRs to --out (default: a new temporary folder, kept and printed), and runs the
shared tool compare_renders.py with Mitsuba's pair as the reference and volcl's as the test.

How to read it: compare_renders prints R (mean squared difference of the two mean images over the
variance their noise predicts: about 1 when both estimate the same image, well above 2 when one is
biased), the per-channel difference of the image means in standard errors (z) and in percent, and
the share of 8x8 blocks more than 4.5 standard errors apart (where the images differ). Its last
line per scene is PASS or FAIL. This script prints that output, then `overall: PASS` or
`overall: FAIL (n of m scenes)`, and exits 1 on any FAIL (a scene a renderer cannot render counts as one;
exit 2 only when the comparison tool is missing).
Without Mitsuba it prints "skipped: Mitsuba 3 not found" and exits 0.

The comparison tool is looked up as ../shared/tools/compare_renders.py beside the checkout (or
--compare-tool).
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))
import mitsuba_ref  # noqa: E402
from common import log, parse_defines  # noqa: E402

DEFAULT_TOOL = ROOT.parent / "shared" / "tools" / "compare_renders.py"
DEFAULT_SCENES = [ROOT / "scenes" / f"{name}.xml" for name in
                  ("cbox", "cloud_sky", "rough_glass_medium", "textured_cbox")]




def render_volcl(scene_path, out, spp, seed, defines, device):
    from volcl import __version__
    from volcl.image import write_image
    from volcl.renderer import Renderer
    from volcl.scene import load
    from volcl.scene.model import Scene
    scene = load(scene_path, defines)
    if not isinstance(scene, Scene):
        raise SystemExit(f"{scene_path} is not a scene")
    for w in scene.warnings:
        log(f"volcl warning: {w}")
    r = Renderer(scene, device=device, seed=seed)
    res = r.render(spp)
    write_image(out, res.image, {"scene": str(scene_path), "spp": res.spp, "seed": r.seed, "device": res.device,
                                 "features": res.stats["features"], "render_seconds": round(res.seconds, 3),
                                 "version": __version__, "invalid_samples": res.invalid,
                                 "tracking_cutoffs": res.tracking_cutoffs},
                {"variance": res.variance})
    return res


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scenes", nargs="*", metavar="SCENE",
                   help="scene files (default: scenes/cbox.xml, cloud_sky.xml, rough_glass_medium.xml, "
                        "textured_cbox.xml)")
    p.add_argument("--spp", type=int, default=256)
    p.add_argument("--variant", default=mitsuba_ref.DEFAULT_VARIANT)
    p.add_argument("--seeds", type=int, nargs=2, default=[0, 1], metavar=("SEED0", "SEED1"))
    p.add_argument("--out", help="folder for the EXRs (default: a new temporary folder)")
    p.add_argument("--device", help="volcl device selector")
    p.add_argument("--compare-tool", default=str(DEFAULT_TOOL), help=f"default {DEFAULT_TOOL}")
    p.add_argument("-D", "--define", action="append", metavar="NAME=VALUE",
                   help="scene parameter for both renderers (e.g. max_depth=2)")
    mitsuba_ref.add_argument(p)
    args = p.parse_args(argv)

    scenes = [Path(s).resolve() for s in args.scenes] if args.scenes else DEFAULT_SCENES
    mts = mitsuba_ref.locate(args.mitsuba_python, args.variant, log=print)
    if mts is None:
        print("skipped: Mitsuba 3 not found (pass --mitsuba-python or set $VOLCL_MITSUBA_PYTHON)")
        return 0
    tool = Path(args.compare_tool)
    if not tool.is_file():
        print(f"error: comparison tool {tool} not found (pass --compare-tool)")
        return 2
    out_dir = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="volcl-vs-mitsuba-"))
    out_dir.mkdir(parents=True, exist_ok=True)
    defines = parse_defines(args.define)
    suffix = "".join(f"_{k}{v}" for k, v in defines.items())

    from volcl import device as devmod
    device = devmod.choose(args.device)
    print(f"volcl on {device.key} {device.name}; Mitsuba {mts['version']} {args.variant} via {mts['python']}")
    print(f"{args.spp} spp, seeds {args.seeds[0]} {args.seeds[1]}, defines {defines or 'none'}, EXRs in {out_dir}\n")

    failed, errors = [], []
    for scene in scenes:
        name = scene.stem + suffix
        refs = [out_dir / f"{name}_mitsuba_s{s}.exr" for s in args.seeds]
        tests = [out_dir / f"{name}_volcl_s{s}.exr" for s in args.seeds]
        try:
            for s, path in zip(args.seeds, refs):
                log(f"{name}: Mitsuba seed {s} ...")
                t0 = time.perf_counter()
                mitsuba_ref.render_mitsuba(str(scene), str(path), mts["python"], args.variant, args.spp, s,
                                           defines, repeat=1, warmup=False)
                log(f"  {time.perf_counter() - t0:.1f} s (process)")
            for s, path in zip(args.seeds, tests):
                log(f"{name}: volcl seed {s} ...")
                res = render_volcl(scene, path, args.spp, s, defines, device)
                log(f"  {res.seconds:.1f} s, invalid samples {res.invalid}")
        except Exception as exc:    # a renderer that cannot run this scene: report, go on
            print(f"ERROR {name}: {exc}")
            errors.append(name)
            continue
        proc = subprocess.run([sys.executable, str(tool), *map(str, refs), *map(str, tests), "--name", name],
                              capture_output=True, text=True)
        sys.stdout.write(proc.stdout)
        if proc.stderr.strip():
            sys.stdout.write(proc.stderr)
        last = (proc.stdout.strip().splitlines() or [""])[-1]
        if proc.returncode != 0 or not last.startswith("PASS"):
            failed.append(name)

    n = len(scenes)
    print()
    if failed or errors:
        what = f"{len(failed)} of {n} scenes FAIL" + (f", {len(errors)} could not be rendered" if errors else "")
        print(f"overall: FAIL ({what}: {', '.join(failed + errors)})")
        return 1
    print(f"overall: PASS ({n} of {n} scenes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
