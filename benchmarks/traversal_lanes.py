"""Can a BVH walk run in the SIMD lanes? volcl's shipped `bvh_trace` against a lanes-style walk of
the same wide tree (benchmarks/kernels/trace_lanes.cl), closest hit, on one OpenCL device.

    OPENBLAS_NUM_THREADS=1 python benchmarks/traversal_lanes.py --device 0:0 \\
        [--scenes tcbox cbox 100k] [--rays 1000000] [--repeat 5] \\
        [--variants loop regs fixed fixed-unroll loop-hint1 loop-hint4] [--fresh-cache]

Scenes: `tcbox` is scenes/textured_cbox.xml without its sphere (24 triangles; spheres are left out
of the study: the lanes walk tests triangles only), `cbox` and `100k` are benchmarks/traversal.py's
(the Nori Cornell box, whose spheres are meshes: 2,188 triangles; the bumpy sphere of ~100k). The
rays are traversal.py's: camera rays on a grid of about --rays pixels and cosine bounce rays off
their hits (the shipped kernel's hits), made by its functions.

Kernels: `bvh_trace` is benchmarks/kernels/trace.cl's trace_closest as traversal.py builds it
(VOLCL_KERNEL, which Intel's runtime keeps scalar; every feature flag on, instances included), the
reference for "agree"; `bvh_trace, scene's features` the same kernel built with the flags the
renderer would give the scene (volcl.features.detect: no instances, no cylinders). The lanes variants are trace_lanes.cl built with
  loop          while loop until the stack is empty, the stack a private array, no vec_type_hint
  regs          the same loop, the stack as scalar registers shifted on push and pop
  fixed         a loop of a fixed trip count (an upper bound on any ray's iterations), array stack
  fixed-unroll  the fixed loop unrolled whole, register stack (only where the tree is small)
  *-sel         the node, packet and pop steps of every iteration run whether needed or not,
                their effects chosen by selects (no branch, no load under a condition)
  loop-hint1 / loop-hint4   `loop` with vec_type_hint(float) / vec_type_hint(float4)
The lanes kernel runs in work-groups of 256 (PoCL compiles a work-group function per local size; a
fixed one is compiled once, at the untimed first launch, where the remarks are collected), the rays
padded to a multiple of 256 (it has no bounds test). Each figure is the
best of --repeat launches (kernel only, enqueue to finish), the kernels' launches interleaved.

Prints, per scene, ray kind (camera, bounce) and kernel: M rays/s of wall time, the share of rays
whose hit agrees with bvh_trace (same primitive, or both miss, and t within 1e-6 relative), the
share with identical t bits, and whether the runtime vectorized the kernel: Intel's runtime from
its build log ("Kernel ... was successfully vectorized (16)"), PoCL from the LLVM remarks that
POCL_VECTORIZER_REMARKS=1 makes it print (on stdout) while it compiles the work-group function (at
the first launch); --fresh-cache points POCL_CACHE_DIR at an empty folder and turns pyopencl's
binary cache off (a PoCL binary holds the compiled work-group functions) so that happens. The
remark lines are saved next to the table (--remarks-dir).
"""
from __future__ import annotations

import argparse
import copy
import dataclasses
import os
import re
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))
from common import cpu_model, log  # noqa: E402
from traversal import KERNEL as TRACE_KERNEL, Volcl, bounce_rays, camera_rays, load_scene as traversal_scene, table  # noqa: E402

LANES_KERNEL = HERE / "kernels" / "trace_lanes.cl"
PAD = 256

VARIANTS = {
    "loop": dict(LANES_REGS=0, LANES_MAXIT=0, LANES_UNROLL=0, LANES_HINT=0),
    "regs": dict(LANES_REGS=1, LANES_MAXIT=0, LANES_UNROLL=0, LANES_HINT=0),
    "fixed": dict(LANES_REGS=0, LANES_MAXIT=-1, LANES_UNROLL=0, LANES_HINT=0),
    "fixed-unroll": dict(LANES_REGS=1, LANES_MAXIT=-1, LANES_UNROLL=1, LANES_HINT=0),
    "loop-sel": dict(LANES_REGS=0, LANES_MAXIT=0, LANES_UNROLL=0, LANES_HINT=0, LANES_SELECT=1),
    "fixed-sel": dict(LANES_REGS=0, LANES_MAXIT=-1, LANES_UNROLL=0, LANES_HINT=0, LANES_SELECT=1),
    "fixed-unroll-sel": dict(LANES_REGS=1, LANES_MAXIT=-1, LANES_UNROLL=1, LANES_HINT=0, LANES_SELECT=1),
    "loop-hint1": dict(LANES_REGS=0, LANES_MAXIT=0, LANES_UNROLL=0, LANES_HINT=1),
    "loop-hint4": dict(LANES_REGS=0, LANES_MAXIT=0, LANES_UNROLL=0, LANES_HINT=4),
}
REGS_MAX = 16           # register stacks deeper than this are not built
UNROLL_MAX = 64         # nor whole unrolls of more iterations


def load_scene(name):
    if name == "tcbox":
        from volcl.scene import load
        sc = load(ROOT / "scenes" / "textured_cbox.xml")
        return "textured cbox, no sphere", dataclasses.replace(sc, shapes=[s for s in sc.shapes if s.kind == "mesh"])
    return traversal_scene(name)


class FdCapture:
    """Whatever the process writes to file descriptors 1 and 2 meanwhile (PoCL prints its LLVM
    remarks on standard output, Intel's runtime its messages on standard error)."""

    def __enter__(self):
        sys.stdout.flush()
        sys.stderr.flush()
        self.file = tempfile.TemporaryFile()
        self.saved = [os.dup(1), os.dup(2)]
        os.dup2(self.file.fileno(), 1)
        os.dup2(self.file.fileno(), 2)
        return self

    def __exit__(self, *exc):
        sys.stdout.flush()
        sys.stderr.flush()
        for fd, saved in zip((1, 2), self.saved):
            os.dup2(saved, fd)
            os.close(saved)
        self.file.seek(0)
        self.text = self.file.read().decode(errors="replace")
        self.file.close()


def vector_verdict(platform, build_log, remarks):
    """What the runtime says it did with the kernel's work-items."""
    if "intel" in platform.lower():
        m = re.search(r"Kernel \S+ was successfully vectorized \((\d+)\)", build_log)
        if m:
            return f"vectorized ({m.group(1)})"
        m = re.search(r"Kernel \S+ was not vectorized", build_log)
        return "not vectorized" if m else "? (no log line)"
    remarks = remarks.replace("<unknown>:0:0: ", "\n")
    widths = re.findall(r"vectorized loop \(vectorization width: (\d+)", remarks)
    if widths:
        return f"vectorized ({','.join(sorted(set(widths)))})"
    why = sorted(set(w.strip() for w in re.findall(r"loop not vectorized:([^\n]*)", remarks)))
    if why or "loop not vectorized" in remarks:
        return "not vectorized: " + "; ".join(why)
    return "no remark (cached build? use --fresh-cache)" if not remarks.strip() else "not vectorized"


class Lanes:
    def __init__(self, v: Volcl, device, name, defines):
        from volcl.features import all_features
        from volcl.program import build_program
        cl = v.cl
        self.cl, self.v, self.name = cl, v, name
        opts = tuple(f"-D{k}={val}" for k, val in defines.items())
        with FdCapture() as cap:
            self.program = build_program(v.ctx, dict(all_features(), spheres=False), LANES_KERNEL, extra=opts)
            self.kernel = cl.Kernel(self.program, "trace_lanes_closest")
            self.build_log = self.program.get_build_info(device.device, cl.program_build_info.LOG) or ""
            # PoCL compiles the work-group function at the first launch
            o = np.zeros((PAD, 3), np.float32)
            o[:, 2] = 1.0
            b = self.upload(o, o)
            self.run(b)
        self.remarks = cap.text
        self.verdict = vector_verdict(device.platform_name, self.build_log, self.remarks)

    def upload(self, o, d):
        cl, mf, ctx = self.cl, self.cl.mem_flags, self.v.ctx
        n = len(o)
        m = -(-n // PAD) * PAD
        o = np.concatenate([o, np.repeat(o[-1:], m - n, 0)]) if m > n else o
        d = np.concatenate([d, np.repeat(d[-1:], m - n, 0)]) if m > n else d
        return {"n": n, "m": m,
                "o": cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(o, np.float32)),
                "d": cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(d, np.float32)),
                "t": cl.Buffer(ctx, mf.WRITE_ONLY, 4 * m), "prim": cl.Buffer(ctx, mf.WRITE_ONLY, 4 * m)}

    def run(self, b):
        q = self.v.queue
        q.finish()
        t0 = time.perf_counter()
        self.kernel(q, (b["m"],), (PAD,), self.v.scene_bufs[0], self.v.scene_bufs[1], b["o"], b["d"], b["t"], b["prim"])
        q.finish()
        return time.perf_counter() - t0

    def results(self, b):
        t, prim = np.empty(b["m"], np.float32), np.empty(b["m"], np.int32)
        self.cl.enqueue_copy(self.v.queue, t, b["t"])
        self.cl.enqueue_copy(self.v.queue, prim, b["prim"])
        self.v.queue.finish()
        return t[:b["n"]], prim[:b["n"]]


def agreement(ref, got):
    """(share agreeing: same prim or both miss, t within 1e-6 relative; share with identical t bits)"""
    (tr, pr), (tg, pg) = ref, got
    hr, hg = np.isfinite(tr), np.isfinite(tg)
    same = (hr == hg) & np.where(hr, pr == pg, True)
    with np.errstate(invalid="ignore"):
        close = np.where(hr & hg, np.abs(tr - tg) <= 1e-6 * np.abs(tr), True)
    bits = tr.view(np.int32) == tg.view(np.int32)
    return float(np.mean(same & close)), float(np.mean(same & bits))


def iteration_bound(nodes, leaves):
    """Iterations no ray exceeds: every node visit, packet test and culled pop takes at most one."""
    slots = int(np.sum(np.isfinite(nodes["bounds"][:, 0, :]) & (nodes["bounds"][:, 0, :] <= nodes["bounds"][:, 3, :])))
    return len(nodes) + slots + len(leaves) + 1


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rays", type=int, default=1_000_000)
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--scenes", nargs="+", default=["tcbox", "cbox", "100k"])
    p.add_argument("--variants", nargs="+", default=["loop", "regs", "fixed", "fixed-unroll"],
                   choices=list(VARIANTS))
    p.add_argument("--device", help="volcl device selector")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--fresh-cache", action="store_true", help="an empty POCL_CACHE_DIR (PoCL prints remarks)")
    p.add_argument("--remarks-dir", default=None, help="save each lanes build's log and remarks here")
    args = p.parse_args(argv)

    os.environ.setdefault("POCL_VECTORIZER_REMARKS", "1")
    if args.fresh_cache:
        os.environ["POCL_CACHE_DIR"] = tempfile.mkdtemp(prefix="pocl-fresh-")
        os.environ["PYOPENCL_NO_CACHE"] = "1"    # pyopencl's binary cache carries PoCL's compiled kernels
    from volcl import device as devmod
    from volcl.bvh_wide import stack_need
    device = devmod.choose(args.device)
    print("# BVH walk in the lanes: bvh_trace against trace_lanes.cl (closest hit)\n")
    print(f"- CPU: {cpu_model()}, {os.cpu_count()} cores; load average at start "
          f"{' '.join(Path('/proc/loadavg').read_text().split()[:3])}")
    print(f"- device: {device.name} ({device.platform_name}, {device.device.max_compute_units} compute units)")
    print(f"- best of {args.repeat}, launches interleaved; rays padded to a multiple of {PAD} for the lanes kernel\n")

    rows, verdicts = [], []
    rng = np.random.default_rng(args.seed)
    for name in args.scenes:
        label, scene = load_scene(name)
        log(f"{label}: packing and building ...")
        v = Volcl(scene, device)
        a = v.packed.arrays
        nodes, leaves = a["nodes"], a["leaves"]
        need, bound = max(1, stack_need(nodes)), iteration_bound(nodes, leaves)
        tris = v.triangles()
        # bvh_trace as the renderer builds it for this scene (traversal.py builds every feature in,
        # instances included, which puts the top-level walk around the tree)
        from volcl.features import detect
        from volcl.program import build_program
        vs = copy.copy(v)
        vs.closest = v.cl.Kernel(build_program(v.ctx, detect(scene), TRACE_KERNEL), "trace_closest")
        lanes = []
        for var in args.variants:
            d = dict(VARIANTS[var], LANES_STACK=need)
            if d["LANES_MAXIT"] < 0:
                d["LANES_MAXIT"] = bound
            if (d["LANES_REGS"] and need > REGS_MAX) or (d["LANES_UNROLL"] and bound > UNROLL_MAX):
                verdicts.append([label, var, "skipped (tree too big)", "–"])
                continue
            log(f"{label}: building lanes variant {var} {d} ...")
            t0 = time.perf_counter()
            ln = Lanes(v, device, var, d)
            verdicts.append([label, var, ln.verdict, f"{time.perf_counter() - t0:.1f}"])
            if args.remarks_dir:
                out = Path(args.remarks_dir)
                out.mkdir(parents=True, exist_ok=True)
                (out / f"{name}-{var}.txt").write_text(f"defines {d}\n--- build log\n{ln.build_log}\n--- output\n{ln.remarks}")
            lanes.append(ln)
        o, dd = camera_rays(scene, args.rays, rng)
        vb = v.upload(o, dd)
        v.run(vb, "closest")
        t_hit, prim = v.results(vb, "closest")
        bo, bd = bounce_rays(tris, o, dd, t_hit, prim, rng)
        for kind, (ro, rd) in (("camera", (o, dd)), ("bounce", (bo, bd))):
            vb = v.upload(ro, rd)
            lb = [ln.upload(ro, rd) for ln in lanes]
            log(f"{label}: {kind} rays ...")
            v.run(vb, "closest")
            vs.run(vb, "closest")
            for ln, b in zip(lanes, lb):
                ln.run(b)
            best_v, best_s, best_l = np.inf, np.inf, [np.inf] * len(lanes)
            for _ in range(args.repeat):
                best_v = min(best_v, v.run(vb, "closest")[0])
                best_s = min(best_s, vs.run(vb, "closest")[0])
                for k, (ln, b) in enumerate(zip(lanes, lb)):
                    best_l[k] = min(best_l[k], ln.run(b))
            n = len(ro)
            ref = v.results(vb, "closest")
            base = n / best_v / 1e6
            rows.append([label, f"{len(tris):,}", kind, f"{n:,}", "bvh_trace", f"{base:.2f}", "1.00", "–", "–"])
            ref_s = vs.results(vb, "closest")
            agree, bits = agreement(ref, ref_s)
            rate = n / best_s / 1e6
            rows.append([label, f"{len(tris):,}", kind, f"{n:,}", "bvh_trace, scene's features", f"{rate:.2f}",
                         f"{rate / base:.2f}", f"{100 * agree:.4f}%", f"{100 * bits:.4f}%"])
            for ln, b, secs in zip(lanes, lb, best_l):
                agree, bits = agreement(ref, ln.results(b))
                rate = n / secs / 1e6
                rows.append([label, f"{len(tris):,}", kind, f"{n:,}", f"lanes {ln.name}", f"{rate:.2f}",
                             f"{rate / base:.2f}", f"{100 * agree:.4f}%", f"{100 * bits:.4f}%"])
    print(table(["scene", "triangles", "rays", "count", "kernel", "M rays/s", "vs bvh_trace", "agree",
                 "same bits"], rows))
    print("\nVectorization of the lanes kernel (runtime's own report) and build + first launch seconds:\n")
    print(table(["scene", "variant", "vectorization", "build s"], verdicts))
    print(f"\nload average at end: {' '.join(Path('/proc/loadavg').read_text().split()[:3])}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
