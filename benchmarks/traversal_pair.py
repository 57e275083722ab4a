"""Is the closest-hit walk bound by latency? The shipped `bvh_trace` against the same walk cut into
steps (benchmarks/kernels/trace_pair.cl), one ray per work-item and two rays per work-item taking
turns, on one OpenCL device.

    OPENBLAS_NUM_THREADS=1 python benchmarks/traversal_pair.py --device 0:0 \\
        [--scenes tcbox cbox 100k] [--rays 1000000] [--repeat 5]

The renderer's megakernel walks one ray at a time per work-item, and perf puts its samples on the
walk's loads and branches. If the walk waits on them, a work-item holding two independent walks
(two paths' rays) could keep the core busy with one while the other waits: this measures whether
it does, before any renderer is restructured for it.

Scenes and rays are benchmarks/traversal_lanes.py's (`tcbox`: textured_cbox's 24 triangles; `cbox`:
the Nori Cornell box, 2,188 triangles; `100k`: the bumpy sphere), camera rays and cosine bounce
rays off their hits. Kernels, all built with the scene's features (volcl.features.detect):
  bvh_trace    benchmarks/kernels/trace.cl's trace_closest: the renderer's walk
  step         trace_pair.cl's trace_step_closest: the same walk as a loop of steps over a state
               struct, one ray per work-item (what the cut alone costs)
  pair         trace_pair_closest: rays 2i and 2i + 1 in work-item i, one step of each in turn
Each figure is the best of --repeat launches (enqueue to finish), the kernels interleaved; "agree"
is the share of rays with bvh_trace's primitive and t bits (the walks visit alike, so 100%).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))
from common import cpu_model, log  # noqa: E402
from traversal import KERNEL as TRACE_KERNEL, Volcl, bounce_rays, camera_rays, table  # noqa: E402
from traversal_lanes import load_scene  # noqa: E402

PAIR_KERNEL = HERE / "kernels" / "trace_pair.cl"
LOCAL = 64
KERNELS = ("bvh_trace", "step", "pair")


class Walks:
    """bvh_trace (trace.cl's trace_closest) and trace_pair.cl's two kernels over the scene buffers
    of a traversal.Volcl, built with the scene's features, launched alike: work-groups of LOCAL
    (the renderer's size), the global size padded to a multiple of it (the kernels test bounds)."""

    def __init__(self, v: Volcl, features):
        from volcl.program import build_program
        self.v = v
        trace = build_program(v.ctx, features, TRACE_KERNEL)
        pair = build_program(v.ctx, features, PAIR_KERNEL)
        self.kernels = {"bvh_trace": v.cl.Kernel(trace, "trace_closest"),
                        "step": v.cl.Kernel(pair, "trace_step_closest"),
                        "pair": v.cl.Kernel(pair, "trace_pair_closest")}

    def run(self, bufs, name):
        """Seconds of one launch of kernel `name` over the rays in bufs (traversal.Volcl.upload's)."""
        q, n = self.v.queue, bufs["n"]
        items = -(-n // 2) if name == "pair" else n
        size = -(-items // LOCAL) * LOCAL
        q.finish()
        t0 = time.perf_counter()
        self.kernels[name](q, (size,), (LOCAL,), *self.v.scene_bufs, bufs["o"], bufs["d"], bufs["t"], bufs["prim"],
                           np.int32(n))
        q.finish()
        return time.perf_counter() - t0

    def hits(self, bufs):
        return self.v.results(bufs, "closest")


def same_bits(ref, got):
    """Share of rays with the same primitive (or both missing) and the same t bits."""
    (tr, pr), (tg, pg) = ref, got
    return float(np.mean((pr == pg) & (tr.view(np.int32) == tg.view(np.int32))))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rays", type=int, default=1_000_000)
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--scenes", nargs="+", default=["tcbox", "cbox", "100k"])
    p.add_argument("--device", help="volcl device selector")
    p.add_argument("--seed", type=int, default=1)
    args = p.parse_args(argv)

    from volcl import device as devmod
    from volcl.features import detect
    device = devmod.choose(args.device)
    print("# Two rays per work-item: bvh_trace against trace_pair.cl (closest hit)\n")
    print(f"- CPU: {cpu_model()}, {os.cpu_count()} cores; load average at start "
          f"{' '.join(Path('/proc/loadavg').read_text().split()[:3])}")
    print(f"- device: {device.name} ({device.platform_name}, {device.device.max_compute_units} compute units)")
    print(f"- best of {args.repeat}, launches interleaved, work-groups of {LOCAL}\n")

    rows = []
    rng = np.random.default_rng(args.seed)
    for name in args.scenes:
        label, scene = load_scene(name)
        log(f"{label}: packing and building ...")
        v = Volcl(scene, device)
        walks = Walks(v, detect(scene))
        tris = v.triangles()
        o, d = camera_rays(scene, args.rays, rng)
        vb = v.upload(o, d)
        walks.run(vb, "bvh_trace")
        t_hit, prim = walks.hits(vb)
        bo, bd = bounce_rays(tris, o, d, t_hit, prim, rng)
        for kind, (ro, rd) in (("camera", (o, d)), ("bounce", (bo, bd))):
            log(f"{label}: {kind} rays ...")
            vb = v.upload(ro, rd)
            hits = {}
            for k in KERNELS:       # first launches untimed (PoCL compiles at the first)
                walks.run(vb, k)
                hits[k] = walks.hits(vb)
            best = dict.fromkeys(KERNELS, np.inf)
            for _ in range(args.repeat):
                for k in KERNELS:
                    best[k] = min(best[k], walks.run(vb, k))
            n = len(ro)
            base = n / best["bvh_trace"] / 1e6
            for k in KERNELS:
                rate = n / best[k] / 1e6
                agree = "–" if k == "bvh_trace" else f"{100 * same_bits(hits['bvh_trace'], hits[k]):.4f}%"
                rows.append([label, f"{len(tris):,}", kind, f"{n:,}", k, f"{rate:.2f}", f"{rate / base:.2f}", agree])
    print(table(["scene", "triangles", "rays", "count", "kernel", "M rays/s", "vs bvh_trace", "agree (bits)"], rows))
    print(f"\nload average at end: {' '.join(Path('/proc/loadavg').read_text().split()[:3])}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
