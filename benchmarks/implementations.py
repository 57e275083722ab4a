"""Throughput of volcl on each OpenCL implementation present, and of the configurations tried on
Intel's CPU runtime.

    python benchmarks/implementations.py [--scenes cbox,fog,...] [--size 128x96] [--spp 32]
        [--rounds 3] [--configs pocl,intel,...]

Each configuration runs in its own process (several are environment settings of the runtime), on
the scenes in scenes/ at --size and --spp: one untimed 1-spp pass (kernel build, PoCL's
first-launch compilation), then one timed render of --spp. The configurations take turns, round
after round, so load from other jobs on the machine spreads over all of them; the tables give the
best round: samples per second of process CPU time (the runtime's worker threads included; the
figure to compare on a shared machine) and per wall-clock second. Samples are camera samples,
width * height * spp; the ratio is to PoCL's figure on the same scene; "invalid" counts samples that came out NaN, infinite or
negative (0 for any configuration that computes the right image). The devices are taken by
platform name, without volcl's self-test, so a configuration the self-test would reject (the
vectorized one) can still be timed.

Configurations (those whose implementation is absent are left out):
  pocl              PoCL's CPU device as volcl uses it
  pocl-no-hint      PoCL without VOLCL_KERNEL's vec_type_hint (-DVOLCL_KERNEL=__kernel): what the
                    hint costs PoCL
  intel             Intel's CPU runtime as volcl uses it (VOLCL_KERNEL: its vectorizer kept off)
  intel-vectorized  the same with the runtime's implicit vectorizer let loose on the kernel
                    (-DVOLCL_KERNEL=__kernel): wrong images, shown for the cost alone
  intel-wg-N        Intel with every work-group forced to N work items
                    (CL_CONFIG_CPU_FORCE_WORK_GROUP_SIZE=N; volcl leaves the size to the runtime)
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))

CONFIGS = {
    "pocl": ("portable computing language", {}),
    "pocl-no-hint": ("portable computing language", {"VOLCL_BUILD_OPTIONS": "-DVOLCL_KERNEL=__kernel"}),
    "intel": ("intel", {}),
    "intel-vectorized": ("intel", {"VOLCL_BUILD_OPTIONS": "-DVOLCL_KERNEL=__kernel"}),
    "intel-wg-1": ("intel", {"CL_CONFIG_CPU_FORCE_WORK_GROUP_SIZE": "1"}),
    "intel-wg-16": ("intel", {"CL_CONFIG_CPU_FORCE_WORK_GROUP_SIZE": "16"}),
    "intel-wg-128": ("intel", {"CL_CONFIG_CPU_FORCE_WORK_GROUP_SIZE": "128"}),
    "intel-wg-1024": ("intel", {"CL_CONFIG_CPU_FORCE_WORK_GROUP_SIZE": "1024"}),
}


def log(msg):
    print(msg, file=sys.stderr, flush=True)


def worker(platform: str, scenes: list[str], width: int, height: int, spp: int):
    from volcl import device as devmod
    from volcl.renderer import Renderer
    from volcl.scene import load
    devs = [d for d in devmod.list_devices() if platform in d.platform_name.lower()]
    if not devs:
        print(json.dumps({"absent": True}))
        return
    out = {"device": f"{devs[0].name} ({devs[0].platform_name})", "scenes": {}}
    for name in scenes:
        sc = load(ROOT / "scenes" / f"{name}.xml")
        sc.camera.width, sc.camera.height = width, height
        r = Renderer(sc, device=devs[0], seed=1)
        r.render(1)
        r.reset()
        c0 = time.process_time()
        res = r.render(spp)
        cpu = time.process_time() - c0
        out["scenes"][name] = {"msps": res.samples_per_second / 1e6, "invalid": res.invalid,
                               "mspc": width * height * spp / cpu / 1e6}
    print(json.dumps(out))


def run_config(name: str, scenes, width, height, spp) -> dict:
    platform, env = CONFIGS[name]
    cmd = [sys.executable, __file__, "--worker", platform, "--scenes", ",".join(scenes),
           "--size", f"{width}x{height}", "--spp", str(spp)]
    r = subprocess.run(cmd, env=dict(os.environ, **env), capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"{name}: worker failed:\n{r.stderr[-3000:]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scenes", default="cbox,fog,underwater,smoke_sphere,smoke_grid")
    p.add_argument("--size", default="128x96")
    p.add_argument("--spp", type=int, default=32)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--configs", default=",".join(CONFIGS))
    p.add_argument("--worker", help=argparse.SUPPRESS)
    args = p.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    scenes = args.scenes.split(",")
    if args.worker:
        return worker(args.worker, scenes, width, height, args.spp)
    configs = args.configs.split(",")
    best: dict = {}
    devices = {}
    t0 = time.time()
    for rnd in range(args.rounds):
        for name in list(configs):
            res = run_config(name, scenes, width, height, args.spp)
            if res.get("absent"):
                log(f"{name}: implementation absent, left out")
                configs.remove(name)
                continue
            devices[name] = res["device"]
            for scene, v in res["scenes"].items():
                cur = best.setdefault((name, scene), dict(v))
                cur["msps"], cur["mspc"] = max(cur["msps"], v["msps"]), max(cur["mspc"], v["mspc"])
                cur["invalid"] = max(cur["invalid"], v["invalid"])
            log(f"round {rnd + 1}/{args.rounds} {name}: " + ", ".join(
                f"{s} {v['msps']:.3f}" for s, v in res["scenes"].items()) + f" ({time.time() - t0:.0f} s)")
    load = os.getloadavg()[0]
    print(f"{args.size}, {args.spp} spp, best of {args.rounds} interleaved rounds, {os.cpu_count()} cores, "
          f"load average {load:.1f} at the end\n")
    for name in configs:
        print(f"- {name}: {devices[name]}")
    for key, title in (("mspc", "M samples per CPU second (process CPU time: every thread of the runtime; "
                                "the figure that load from other jobs disturbs least)"),
                       ("msps", "M samples per second (wall clock)")):
        print(f"\n{title}; (ratio to pocl) [invalid samples]\n")
        print("| scene | " + " | ".join(configs) + " |")
        print("|---|" + "---:|" * len(configs))
        for scene in scenes:
            ref = best.get(("pocl", scene), {}).get(key)
            cells = []
            for name in configs:
                v = best[(name, scene)]
                ratio = f" ({v[key] / ref:.2f})" if ref and name != "pocl" else ""
                bad = f" [{v['invalid']}]" if v["invalid"] else ""
                cells.append(f"{v[key]:.3f}{ratio}{bad}")
            print(f"| {scene} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
