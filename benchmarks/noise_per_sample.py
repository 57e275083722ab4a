"""Noise per sample of volcl against Mitsuba 3, robust to fireflies, with the scene's own
reconstruction filter and with a box filter.

    python benchmarks/noise_per_sample.py [--scenes scenes/cbox.xml ...] [--size 128x128] [--spp 512]
        [--block 4] [--seeds 11 12] [--no-box] [--out DIR] [--mitsuba-python PATH]

Samples per second say how fast a renderer draws samples; what a user waits for also depends on
how much each sample tells. For each scene, each renderer renders two images with independent
seeds; over blocks of --block x --block pixels, (A - B)^2 / 2 of the two block means, over the
squared block mean and times spp, estimates the relative variance one sample per pixel would
leave in a block mean. The table gives its median over the blocks (which a few fireflies in one
render barely move, unlike the mean that render_throughput.py --noise uses), its mean and 90th
percentile, and volcl's figures over Mitsuba's: above 1, volcl needs that many times more samples
for the same block noise. Blocks whose mean is below 1e-3 (black) are left out.

With the box filter (a copy of the scene beside it with its <rfilter> made a box, unless
--no-box) both renderers put each sample into one pixel; with a wider filter Mitsuba splats a
sample into every pixel the filter reaches, with weights, and volcl draws the sample's position
from the filter and adds it to one pixel: the two rows of a scene show what that choice costs.
"""
from __future__ import annotations

import argparse
import re
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))

import compare_mitsuba  # noqa: E402
import mitsuba_ref  # noqa: E402
from render_throughput import block_means  # noqa: E402

DEFAULT_SCENES = ["scenes/cbox.xml", "scenes/textured_cbox.xml", "scenes/rough_glass_medium.xml"]
RFILTER = re.compile(r"<rfilter\b[^>]*?(/>|>.*?</rfilter>)", re.S)


def box_variant(scene: Path) -> Path | None:
    """A copy of the scene beside it (relative paths still resolve) with a box filter; None if the
    scene has no <rfilter> or already uses a box."""
    text = scene.read_text()
    m = RFILTER.search(text)
    if not m or 'type="box"' in m.group(0):
        return None
    out = scene.with_name(f"_box_{scene.name}")
    out.write_text(text[:m.start()] + '<rfilter type="box"/>' + text[m.end():])
    return out


def per_sample_noise(a: np.ndarray, b: np.ndarray, spp: int, block: int) -> tuple[float, float, float]:
    """(median, mean, 90th percentile) over blocks of the relative variance of a block mean at one
    sample per pixel, from two independent renders of spp samples."""
    A, B = (block_means(x, block).mean(axis=2) for x in (a, b))
    m = 0.5 * (A + B)
    keep = m > 1e-3
    rel = 0.5 * (A - B) ** 2 / np.where(keep, m, 1.0) ** 2 * spp
    r = rel[keep]
    return float(np.median(r)), float(r.mean()), float(np.percentile(r, 90))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenes", nargs="+", default=DEFAULT_SCENES)
    p.add_argument("--size", default="128x128")
    p.add_argument("--spp", type=int, default=512)
    p.add_argument("--block", type=int, default=4)
    p.add_argument("--seeds", type=int, nargs=2, default=[11, 12])
    p.add_argument("--no-box", action="store_true", help="leave out the box-filter variants")
    p.add_argument("--out", help="folder for the EXRs (default: a new temporary folder)")
    p.add_argument("--variant", default=mitsuba_ref.DEFAULT_VARIANT)
    p.add_argument("--mitsuba-python")
    args = p.parse_args(argv)
    python = mitsuba_ref.find_mitsuba_python(args.mitsuba_python)
    if python is None:
        print("skipped: Mitsuba 3 not found: pass --mitsuba-python")
        return 0
    from volcl import device as devmod
    from volcl.image import read_image
    dev = devmod.choose()
    w, h = args.size.lower().split("x")
    defines = {"width": w, "height": h}
    out = Path(args.out or tempfile.mkdtemp(prefix="volcl-noise-"))
    out.mkdir(parents=True, exist_ok=True)
    print(f"# Noise per sample, volcl ({dev.label}) against Mitsuba 3 ({args.variant})\n")
    print(f"{args.size}, {args.spp} spp, seeds {args.seeds[0]} and {args.seeds[1]}, "
          f"{args.block}x{args.block}-pixel blocks; images in {out}\n")
    print("| scene | filter | volcl median / mean / p90 | Mitsuba median / mean / p90 "
          "| volcl/Mitsuba median / mean / p90 |")
    print("|---|---|---|---|---|")
    for name in args.scenes:
        scene = Path(name).resolve()
        variants = [("scene's", "own", scene)]
        box = None if args.no_box else box_variant(scene)
        if box is not None:
            variants.append(("box", "box", box))
        try:
            for label, tag, path in variants:
                figures = {}
                for who in ("volcl", "mitsuba"):
                    imgs = []
                    for seed in args.seeds:
                        exr = out / f"{scene.stem}_{tag}_{who}_{seed}.exr"
                        print(f"{scene.name} ({label} filter): {who}, seed {seed} ...", file=sys.stderr)
                        if who == "volcl":
                            compare_mitsuba.render_volcl(path, exr, args.spp, seed, defines, dev)
                        else:
                            mitsuba_ref.render_mitsuba(str(path), str(exr), python, args.variant, args.spp, seed,
                                                       defines, repeat=1, warmup=False)
                        imgs.append(read_image(exr)[0])
                    figures[who] = per_sample_noise(imgs[0], imgs[1], args.spp, args.block)
                v, m = figures["volcl"], figures["mitsuba"]
                ratio = " / ".join(f"{a / b:.2f}" for a, b in zip(v, m))
                print(f"| {scene.name} | {label} | " + " / ".join(f"{x:.3g}" for x in v) + " | "
                      + " / ".join(f"{x:.3g}" for x in m) + f" | {ratio} |", flush=True)
        finally:
            if box is not None:
                box.unlink(missing_ok=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
