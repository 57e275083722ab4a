"""Does a wavefront stage of the fog step run in the CPU's SIMD lanes, and what does it gain?

    python benchmarks/medium_step.py [--paths 1048576] [--launches 8] [--rounds 3]
        [--configs pocl,pocl-loops,intel] [--lanes 8]

The question behind it (README, "Render throughput against Mitsuba 3"): volcl's megakernel runs
one path per work-item in scalar code, and no OpenCL CPU runtime vectorizes it across
work-items, while Mitsuba's LLVM backend runs 8 or 16 paths per instruction. A wavefront design
would split the path into stages, each a kernel simple enough for a work-group vectorizer. This
measures the stage that dominates point_in_fog's time (path_medium_event: equiangular sample,
free flight, NEE from the collision, HG direction; benchmarks/kernels/medium_step.cl, the
renderer's own routines) in isolation, on a million paths whose state lives in global arrays as a
wavefront renderer's would, so the loads and stores of that state are counted.

Kernels: `hinted` (VOLCL_KERNEL's vector type hint, as the renderer builds), `auto` (no hint, for
the runtime's vectorizer to take), `lanes` (--lanes paths looped in one work-item), `scalar` (the
same step in scalar floats instead of float3, built with every function inlined and launched
without a bounds test: what LLVM's loop vectorizer needs, see the kernel file), `scalar32` (that
step with the generator's 64-bit state as two 32-bit halves, in rows of low and high halves: the
same random numbers, and no 64-bit value to narrow the vectors). Configurations,
each in its own process (they are environment settings of the runtime):
  pocl        PoCL as volcl uses it (work-group method loopvec: LLVM's loop vectorizer on the
              work-item loop)
  pocl-loops  PoCL with POCL_WORK_GROUP_METHOD=loops: the same loops without the vectorizer, the
              scalar baseline of the same code
  intel       Intel's CPU runtime
Figures: M path steps per second of wall time and per CPU second (all the runtime's threads), best
of --rounds interleaved rounds, after one untimed launch per kernel. "agree" is the largest
relative difference of any path's radiance from the first configuration's `hinted` kernel after
the same launches (vector exp, log and sqrt may round differently; 0 means the same bits).
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))
from common import cpu_model, log  # noqa: E402

KERNEL = HERE / "kernels" / "medium_step.cl"
KERNELS = ("hinted", "auto", "lanes", "scalar", "scalar32")
CONFIGS = {
    "pocl": ("portable computing language", {}),
    "pocl-loops": ("portable computing language", {"POCL_WORK_GROUP_METHOD": "loops"}),
    "intel": ("intel", {}),
}
# point_in_fog.xml's fog and light: sigma_t, albedo, HG g, position, intensity
FOG = (0.15, 0.8, 0.3, 0.4, 1.3, 0.8, 12.0, 10.0, 7.0)
STATE_ROWS = 11


def cpu_seconds():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def initial_state(n, seed=1):
    """Paths spread over point_in_fog's space: origins over the floor and before the wall,
    directions uniform on the sphere, half the segments ending at a surface within 8 units and half
    unbounded (fog to infinity); beta 1, no radiance yet."""
    rng = np.random.default_rng(seed)
    o = rng.uniform((-3.0, 0.0, -2.0), (3.0, 3.0, 3.0), (n, 3))
    d = rng.standard_normal((n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t = np.where(rng.random(n) < 0.5, np.inf, rng.uniform(0.0, 8.0, n))
    state = np.zeros((STATE_ROWS, n), np.float32)
    state[0:3], state[3:6], state[6], state[10] = o.T, d.T, 1.0, t
    rng_state = rng.integers(0, 2**63, n, dtype=np.uint64)
    rng_inc = rng.integers(0, 2**63, n, dtype=np.uint64) * np.uint64(2) + np.uint64(1)
    return state, rng_state, rng_inc


def rng_rows(state):
    """64-bit generator states as the uint rows step_scalar32 reads: every low half, then every
    high half."""
    halves = state.view(np.uint32).reshape(-1, 2)       # little-endian: (low, high) per state
    return np.ascontiguousarray(halves.T).ravel()


def worker(platform, n, launches, rounds, lanes):
    import pyopencl as cl
    from volcl import device as devmod
    from volcl.features import all_features
    from volcl.program import build_program
    devs = [d for d in devmod.list_devices() if platform in d.platform_name.lower()]
    if not devs:
        print(json.dumps({"absent": True}))
        return
    dev = devs[0]
    ctx = cl.Context([dev.device])
    queue = cl.CommandQueue(ctx)
    feats = dict.fromkeys(all_features(), False)
    feats.update(MEDIA=True, HG=True, EQUIANGULAR=True, POINT_LIGHTS=True)
    lanes_opt = f"-DMEDIUM_LANES={lanes}"
    programs = {"renderer": build_program(ctx, feats, KERNEL, extra=(lanes_opt,)),
                "inlined": build_program(ctx, feats, KERNEL, extra=(lanes_opt, "-DMEDIUM_INLINE_ALL"))}
    state0, rs0, inc = initial_state(n)
    mf = cl.mem_flags
    bufs = [cl.Buffer(ctx, mf.READ_WRITE, state0.nbytes), cl.Buffer(ctx, mf.READ_WRITE, rs0.nbytes),
            cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=inc)]
    inc_rows = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=rng_rows(inc))
    fog = [np.float32(v) for v in FOG]
    out = {"device": f"{dev.name} ({dev.platform_name})", "kernels": {}}
    for name in KERNELS:
        kernel = cl.Kernel(programs["inlined" if name.startswith("scalar") else "renderer"], f"step_{name}")
        items = -(-n // lanes) if name == "lanes" else n

        # scalar32 reads the generator's state as rows of low and high 32-bit halves
        rs_init = rng_rows(rs0) if name == "scalar32" else rs0
        args = [bufs[0], bufs[1], inc_rows if name == "scalar32" else bufs[2]]

        def launch_all():
            cl.enqueue_copy(queue, bufs[0], state0)
            cl.enqueue_copy(queue, bufs[1], rs_init)
            queue.finish()
            c0, t0 = cpu_seconds(), time.perf_counter()
            for _ in range(launches):
                kernel(queue, (items,), None, *fog, *args, np.int32(n))
            queue.finish()
            return time.perf_counter() - t0, cpu_seconds() - c0

        launch_all()     # untimed: the runtime's first launch
        wall, cpu = min(launch_all() for _ in range(rounds))
        state = np.empty_like(state0)
        cl.enqueue_copy(queue, state, bufs[0])
        queue.finish()
        out["kernels"][name] = {"wall": wall, "cpu": cpu, "L": state[7:10].tolist()}
    print(json.dumps(out))


def run_config(name, args):
    platform, env = CONFIGS[name]
    cmd = [sys.executable, __file__, "--worker", platform, "--paths", str(args.paths), "--launches",
           str(args.launches), "--rounds", "1", "--lanes", str(args.lanes)]
    r = subprocess.run(cmd, env=dict(os.environ, **env), capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"{name}: worker failed:\n{r.stderr[-3000:]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def relative_difference(a, b):
    a, b = np.asarray(a), np.asarray(b)
    scale = np.maximum(np.abs(a), np.abs(b))
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.where(scale > 0, np.abs(a - b) / scale, 0.0)
    return float(np.nanmax(r)) if np.isfinite(a).all() and np.isfinite(b).all() else float("inf")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--paths", type=int, default=1 << 20)
    p.add_argument("--launches", type=int, default=8)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--lanes", type=int, default=8)
    p.add_argument("--configs", default=",".join(CONFIGS))
    p.add_argument("--worker", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker:
        return worker(args.worker, args.paths, args.launches, args.rounds, args.lanes)
    configs = args.configs.split(",")
    best, devices, radiance = {}, {}, {}
    for rnd in range(args.rounds):
        for name in list(configs):
            res = run_config(name, args)
            if res.get("absent"):
                log(f"{name}: implementation absent, left out")
                configs.remove(name)
                continue
            devices[name] = res["device"]
            for k, v in res["kernels"].items():
                cur = best.setdefault((name, k), {"wall": v["wall"], "cpu": v["cpu"]})
                cur["wall"], cur["cpu"] = min(cur["wall"], v["wall"]), min(cur["cpu"], v["cpu"])
                radiance[(name, k)] = v["L"]
            log(f"round {rnd + 1}/{args.rounds} {name}: " + ", ".join(
                f"{k} {args.paths * args.launches / v['wall'] / 1e6:.1f}" for k, v in res["kernels"].items()))
    steps = args.paths * args.launches
    ref = radiance[(configs[0], "hinted")]
    print(f"{cpu_model()}, {os.cpu_count()} cores; {args.paths} paths x {args.launches} launches, best of "
          f"{args.rounds} interleaved rounds, --lanes {args.lanes}; load average {os.getloadavg()[0]:.1f} "
          "at the end\n")
    for name in configs:
        print(f"- {name}: {devices[name]}")
    print("\n| configuration | kernel | M steps/s (wall) | M steps/CPU s | agree |")
    print("|---|---|---:|---:|---:|")
    for name in configs:
        for k in KERNELS:
            v = best[(name, k)]
            print(f"| {name} | {k} | {steps / v['wall'] / 1e6:.1f} | {steps / v['cpu'] / 1e6:.1f} | "
                  f"{relative_difference(ref, radiance[(name, k)]):.1e} |")


if __name__ == "__main__":
    main()
