#!/usr/bin/env python3
"""What compiling only the effects a scene uses buys, per shipped scene.

For each scene: its features; the kernel build time cold (empty PoCL and pyopencl caches, fresh
process) and warm (caches filled, fresh process), for the specialized kernel and for the kernel
with every feature on; and samples/s of both kernels, measured alternately in one process (best of
--repeat), with their ratio (above 1: specialization is faster). Prints a Markdown table.

    python benchmarks/specialization.py [SCENE.xml ...] [--spp 16] [--width 128] [--height 96]
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from common import cpu_model

ROOT = Path(__file__).resolve().parent.parent

BUILD_PROBE = """
import json, sys, time
sys.path.insert(0, {root!r})
from volcl.scene import load
from volcl.features import detect, all_features
from volcl import device as devmod
from volcl.device import cl
from volcl.program import build_program
scene = load({scene!r})
feats = all_features() if {all!r} else detect(scene)
dev = devmod.list_devices()[0] if {dev!r} is None else devmod.choose({dev!r})
ctx = cl.Context([dev.device])
t = time.perf_counter()
prog = build_program(ctx, feats)
cl.Kernel(prog, "render_pass")
print(json.dumps(time.perf_counter() - t))
"""


def build_seconds(scene, all_on, cache_dir, device):
    env = dict(os.environ, POCL_CACHE_DIR=str(cache_dir / "pocl"), PYOPENCL_CACHE_DIR=str(cache_dir / "pyopencl"),
               XDG_CACHE_HOME=str(cache_dir))
    (cache_dir / "pocl").mkdir(parents=True, exist_ok=True)
    src = BUILD_PROBE.format(root=str(ROOT), scene=str(scene), all=all_on, dev=device)
    out = subprocess.run([sys.executable, "-c", src], env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def throughput(scene, spp, width, height, repeat, device):
    sys.path.insert(0, str(ROOT))
    from volcl import device as devmod
    from volcl.features import all_features, describe
    from volcl.renderer import Renderer
    from volcl.scene import load
    sc = load(scene)
    sc.camera.width, sc.camera.height = width, height
    dev = devmod.choose(device)
    spec, every = Renderer(sc, device=dev), Renderer(sc, device=dev, features=all_features())
    best = {"spec": 0.0, "all": 0.0}
    for _ in range(repeat):
        for key, r in (("spec", spec), ("all", every)):
            r.reset()
            best[key] = max(best[key], r.render(spp).samples_per_second)
    return describe(spec.packed.features), best["spec"], best["all"], dev.name


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", type=Path)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--width", type=int, default=128)
    ap.add_argument("--height", type=int, default=96)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--device")
    args = ap.parse_args()
    scenes = args.scenes or sorted((ROOT / "scenes").glob("*.xml"))
    rows = []
    device_name = ""
    for scene in scenes:
        with tempfile.TemporaryDirectory() as tmp:
            cache = Path(tmp)
            cold_s = build_seconds(scene, False, cache / "spec", args.device)
            warm_s = build_seconds(scene, False, cache / "spec", args.device)
            cold_a = build_seconds(scene, True, cache / "all", args.device)
            warm_a = build_seconds(scene, True, cache / "all", args.device)
        feats, sps_spec, sps_all, device_name = throughput(scene, args.spp, args.width, args.height, args.repeat,
                                                           args.device)
        rows.append((scene.name, feats, cold_s, warm_s, cold_a, warm_a, sps_spec, sps_all))
        print(f"{scene.name}: done", file=sys.stderr)
    print(f"device {device_name}; CPU {cpu_model()}, {os.cpu_count()} cores; {args.width}x{args.height}, {args.spp} spp, "
          f"best of {args.repeat}\n")
    print("| scene | features | build cold / warm s | all-features build cold / warm s | M samples/s specialized | "
          "M samples/s all features | ratio |")
    print("|---|---|---|---|---|---|---|")
    for name, feats, cs, ws, ca, wa, s, a in rows:
        print(f"| {name} | {feats.replace(',', ', ')} | {cs:.2f} / {ws:.2f} | {ca:.2f} / {wa:.2f} | {s / 1e6:.2f} | "
              f"{a / 1e6:.2f} | {s / a:.2f} |")


if __name__ == "__main__":
    main()
