"""One render on several OpenCL devices of this machine (volcl.rounds, volcl.devicepool): samples/s on
one device and on two, and how the tiles split between devices of unequal speed.

    python benchmarks/multi_device.py [--scene scenes/fog.xml] [--size 160x120] [--spp 64] [--repeat 3]
                                      [--only WORD...]

PoCL makes the devices: POCL_DEVICES lists them ("pthread pthread": two pthread devices; "basic": a
device that runs kernels in the thread that launches them, one core), POCL_MAX_PTHREAD_COUNT limits
the threads of the pthread devices. Each variant runs in a process of its own (PoCL reads these
when it loads), after a warm-up render that builds the kernels; the variants' repeats are
interleaved, and the table gives the best samples/s of each and its ratio to the first variant's.
Every two-device image is checked bit for bit against the one-device image of the same
implementation and driver. 'busy' is the part of the render's wall time each device spent
rendering tiles (the rest: waiting at the end of a round for the other device, merging, the
host's work): with tiles from a shared list both stay near 100% whatever their speeds.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

# (name, POCL_DEVICES, POCL_MAX_PTHREAD_COUNT, --device)
VARIANTS = [
    ("one pthread device, 1 thread", "pthread", "1", "0:0"),
    ("two pthread devices, 1 thread", "pthread pthread", "1", "all"),
    ("one basic device (1 core)", "basic", "1", "0:0"),
    ("two basic devices (1 core each)", "basic basic", "1", "all"),
    ("one pthread device, 2 threads", "pthread", "2", "0:0"),
    ("two pthread devices, 2 threads", "pthread pthread", "2", "all"),
    ("unequal: basic (1 core) + pthread (2 threads)", "basic pthread", "2", "all"),
]


def child(args):
    sys.path.insert(0, str(ROOT))
    import numpy as np
    import volcl
    from volcl import device as devmod
    w, h = (int(v) for v in args.size.split("x"))
    scene = volcl.load_file(args.scene, width=w, height=h)
    devices = devmod.resolve_many(args.device)
    from volcl.rounds import renderer_for
    volcl.render(scene, spp=1, seed=1, device=devices)          # kernels built, scene uploaded
    r = renderer_for(scene, devices, seed=1)
    busy: dict = {}             # device label -> seconds spent rendering tiles

    def on_tile(job):
        busy[job.worker] = busy.get(job.worker, 0.0) + job.seconds
    if len(devices) > 1:
        r.on_tile = on_tile
    result = r.render(args.spp)
    digest = __import__("hashlib").sha256(np.ascontiguousarray(result.image).tobytes()).hexdigest()[:16]
    print(json.dumps({"samples_per_second": result.samples_per_second, "seconds": result.seconds,
                      "shares": result.shares, "busy": {k: v / result.seconds for k, v in busy.items()},
                      "image": digest, "devices": [d.name for d in devices]}))


def run_variant(args, pocl_devices, threads, device) -> dict:
    env = dict(os.environ, POCL_DEVICES=pocl_devices, POCL_MAX_PTHREAD_COUNT=threads)
    env.pop("VOLCL_DEVICE", None)
    cmd = [sys.executable, __file__, "--child", "--scene", str(args.scene), "--size", args.size,
           "--spp", str(args.spp), "--device", device]
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scene", type=Path, default=ROOT / "scenes" / "fog.xml")
    p.add_argument("--size", default="160x120")
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--only", nargs="*", help="the variants whose names contain one of these words")
    p.add_argument("--device")
    p.add_argument("--child", action="store_true")
    args = p.parse_args()
    if args.child:
        return child(args)
    variants = [v for v in VARIANTS if not args.only or any(word in v[0] for word in args.only)]
    runs = {name: [] for name, *_ in variants}
    for _ in range(args.repeat):
        for name, pocl_devices, threads, device in variants:
            runs[name].append(run_variant(args, pocl_devices, threads, device))
    cpus = os.cpu_count()
    print(f"{args.scene.name}, {args.size}, {args.spp} spp, best of {args.repeat} (interleaved); "
          f"{cpus} CPU cores, load average {os.getloadavg()[0]:.1f} at the end\n")
    print("| variant | M samples/s | vs first | shares | busy | image bits |")
    print("|---|---:|---:|---|---|---|")
    base = max(r["samples_per_second"] for r in runs[variants[0][0]])
    one_device = {}         # PoCL device kind -> image digest of a one-device render
    for name, pocl_devices, *_ in variants:
        best = max(runs[name], key=lambda r: r["samples_per_second"])
        # "0:1 basic 41%": the device's index and PoCL kind (the part of its name before '-')
        shares = ", ".join(f"{label.split('-')[0]} {100 * s:.0f}%" for label, s in best["shares"].items()) or "100%"
        kinds = set(pocl_devices.split())
        bits = "-"
        if len(pocl_devices.split()) == 1:
            one_device.setdefault(pocl_devices, best["image"])
        elif len(kinds) == 1 and kinds <= set(one_device):
            bits = "same as one device" if best["image"] == one_device[kinds.pop()] else "DIFFERENT"
        busy = ", ".join(f"{100 * b:.0f}%" for b in best["busy"].values()) or "-"
        print(f"| {name} | {best['samples_per_second'] / 1e6:.3f} | {best['samples_per_second'] / base:.2f}x | "
              f"{shares} | {busy} | {bits} |")

if __name__ == "__main__":
    main()
