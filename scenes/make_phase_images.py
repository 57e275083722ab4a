#!/usr/bin/env python3
"""Renders the README's phase-function images into docs/images/:

  phases_underwater.png  underwater.xml (HG, g = 0.5) beside underwater_ff.xml (Fournier-Forand,
                         Petzold's backscatter 0.0183: the same mean cosine region as ocean water)
  phases_fog.png         fog_mie.xml: the approximate Mie phase function of 10 um droplets beside
                         HG with the same mean cosine, and 2 um droplets

Each panel is labelled with its phase function and mean cosine. Run again to regenerate:
    python scenes/make_phase_images.py [--spp 256] [--width 320]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
from volcl import phase as ph  # noqa: E402
from volcl.image import srgb_encode  # noqa: E402
from volcl.renderer import render  # noqa: E402
from volcl.scene import load  # noqa: E402
from volcl.scene.model import Phase  # noqa: E402

OUT = HERE.parent / "docs" / "images"


def panel(path: Path, label: str, spp: int, width: int, phase: Phase | None = None, defines=None):
    sc = load(path, defines or {})
    sc.camera.width, sc.camera.height = width, width * 3 // 4
    if phase is not None:
        for m in sc.media:
            m.phase = phase
    r = render(sc, spp=spp)
    print(f"{path.name} {label}: {r.seconds:.1f} s, {r.invalid} invalid samples", flush=True)
    rgb = (np.clip(srgb_encode(r.image), 0, 1) * 255 + 0.5).astype(np.uint8)
    img = Image.fromarray(rgb)
    draw = ImageDraw.Draw(img)
    draw.rectangle([0, 0, img.width, 14], fill=(0, 0, 0))
    draw.text((4, 2), label, fill=(255, 255, 255))
    return img


def strip(images):
    out = Image.new("RGB", (sum(i.width for i in images) + 4 * (len(images) - 1), images[0].height), (255, 255, 255))
    x = 0
    for i in images:
        out.paste(i, (x, 0))
        x += i.width + 4
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--spp", type=int, default=256)
    p.add_argument("--width", type=int, default=320)
    args = p.parse_args(argv)
    OUT.mkdir(parents=True, exist_ok=True)

    ff = load(HERE / "underwater_ff.xml").media[0].phase
    strip([panel(HERE / "underwater.xml", "HG g = 0.5 (mean cos 0.50)", args.spp, args.width),
           panel(HERE / "underwater_ff.xml", f"Fournier-Forand B = 0.0183 (mean cos {ph.mean_cosine(ff):.2f})",
                 args.spp, args.width)]).save(OUT / "phases_underwater.png")

    mie10, mie2 = Phase("mie", diameter=10.0), Phase("mie", diameter=2.0)
    g10 = ph.mean_cosine(mie10)
    strip([panel(HERE / "fog_mie.xml", f"Mie fit, 10 um droplets (mean cos {g10:.2f})", args.spp, args.width),
           panel(HERE / "fog_mie.xml", f"HG g = {g10:.2f}", args.spp, args.width, phase=Phase("hg", g10)),
           panel(HERE / "fog_mie.xml", f"Mie fit, 2 um droplets (mean cos {ph.mean_cosine(mie2):.2f})", args.spp,
                 args.width, defines={"diameter": "2"})]).save(OUT / "phases_fog.png")
    print(f"wrote {OUT / 'phases_underwater.png'} and {OUT / 'phases_fog.png'}")


if __name__ == "__main__":
    main()
