"""Bit-for-bit check of kernel and host refactors: render every shipped scene, record the images,
and compare a later build's images with them exactly.

    python tests/bitcheck.py record DIR      # before the change
    python tests/bitcheck.py compare DIR     # after it: exit status 1 on any differing bit
    (--only NAME,... : the cases whose names start with one of these, e.g. --only fog,cbox)

Each scene renders small (48x36, 8 spp, seed 5) with the estimator choices that apply to it
(volcl.estimator.applicable_choices) and once with every kernel feature compiled in, so the code
behind every flag and estimator switch runs. Images are only comparable on the same device and
driver: this is a tool for a change that must not change any image, not a test of correctness
(tests/test_bitcheck.py checks that the tool itself catches a changed bit).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

WIDTH, HEIGHT, SPP, SEED = 48, 36, 8, 5


def scene_files():
    return sorted((ROOT / "scenes").glob("*.xml")) + sorted((ROOT / "benchmarks" / "scenes").glob("*.xml"))


def _renderer_class():
    try:
        from volcl.renderer import Renderer
    except ImportError:         # the renderer's module before it was renamed
        from volcl.render import Renderer
    return Renderer


def cases(only=None):
    """(name, scene file, estimator choice or None, all features?) for every render the check makes
    (or those whose names start with one of `only`)."""
    from volcl.estimator import applicable_choices
    from volcl.scene import load
    out = []
    for path in scene_files():
        if only and not any(path.stem.startswith(o) for o in only):
            continue
        scene = load(path)
        for choice in applicable_choices(scene):
            out.append((f"{path.stem}-{choice}", path, choice, False))
        out.append((f"{path.stem}-all-features", path, None, True))
    return out


def render_all(device=None, only=None):
    """{case name: (image, variance, invalid, cutoffs)}"""
    from volcl import device as devmod
    from volcl.estimator import CHOICES
    from volcl.features import all_features
    from volcl.scene import load
    Renderer = _renderer_class()
    dev = devmod.choose(device)
    images = {}
    for name, path, choice, every in cases(only):
        scene = load(path)
        scene.camera.width, scene.camera.height = WIDTH, HEIGHT
        r = Renderer(scene, device=dev, seed=SEED, features=all_features() if every else None,
                     estimator=CHOICES[choice] if choice else None)
        res = r.render(SPP)
        images[name] = (res.image, res.variance, np.array(res.invalid), np.array(res.tracking_cutoffs))
    return images


def record(folder: Path, device=None, only=None):
    folder.mkdir(parents=True, exist_ok=True)
    for name, arrays in render_all(device, only).items():
        np.savez(folder / f"{name}.npz", image=arrays[0], variance=arrays[1], invalid=arrays[2],
                 cutoffs=arrays[3])
    return folder


def compare(folder: Path, device=None, only=None) -> list[str]:
    """Names of the renders that differ from the recorded ones (or have no record)."""
    recorded = {p.stem: p for p in folder.glob("*.npz")}
    bad = []
    for name, arrays in render_all(device, only).items():
        if name not in recorded:
            bad.append(f"{name}: no recorded image")
            continue
        with np.load(recorded[name]) as z:
            ref = (z["image"], z["variance"], z["invalid"], z["cutoffs"])
        for what, a, b in zip(("image", "variance", "invalid", "cutoffs"), arrays, ref):
            if a.shape != b.shape or a.tobytes() != b.tobytes():
                diff = np.abs(a.astype(np.float64) - b.astype(np.float64)).max() if a.shape == b.shape else "shape"
                bad.append(f"{name}: {what} differs (max abs difference {diff})")
    return bad


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("mode", choices=("record", "compare"))
    p.add_argument("folder", type=Path)
    p.add_argument("--device")
    p.add_argument("--only", help="comma-separated prefixes of the case names to render")
    args = p.parse_args(argv)
    only = args.only.split(",") if args.only else None
    if args.mode == "record":
        record(args.folder, args.device, only)
        print(f"recorded {len(list(args.folder.glob('*.npz')))} renders in {args.folder}")
        return 0
    bad = compare(args.folder, args.device, only)
    for line in bad:
        print(line)
    print(f"{'FAILED' if bad else 'identical'}: {len(bad)} of {len(cases(only))} renders differ")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
