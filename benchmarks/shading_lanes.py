"""Can a surface's shading run in the SIMD lanes? textured_cbox's floor material, shaded by the
renderer's own scalar functions and by a lanes-style rewrite, on a wave of inputs, on one device.

    OPENBLAS_NUM_THREADS=1 python benchmarks/shading_lanes.py --device 0:0 \\
        [--n 1048576] [--repeat 5] [--fresh-cache] [--remarks-dir DIR] [-D NAME=VALUE ...]
    OPENBLAS_NUM_THREADS=1 python benchmarks/shading_lanes.py --device 0:0 --round-trip \\
        [--waves 4096,65536,1048576] [--repeat 5]
    OPENBLAS_NUM_THREADS=1 python benchmarks/shading_lanes.py --device 0:0 --gather \\
        [--waves 4096,65536] [--repeat 5]

The candidate design behind it (README, "Can a wavefront stage run in the SIMD lanes?"): the BVH
walk stays scalar (benchmarks/traversal_lanes.py found no gain from running it across work-items),
and the shading after the closest hit runs in a kernel of its own, written so that the CPU
runtimes vectorize it across work-items. This times that shading for scenes/textured_cbox.xml's
floor: roughplastic, GGX, alpha 0.15, diffuse reflectance from textures/tiles.png (bilinear,
to_uv scale 2 x 4), packed as the renderer packs the scene (volcl.pack.pack). Per input: the
bsdf's textures at uv, bsdf_eval for a light direction (value, pdf) and bsdf_sample with given
random numbers (direction, weight, pdf), in the local shading frame (the frame change is left out
of both kernels). Inputs: uv uniform in [0, 1)^2, wo uniform on the upper hemisphere, wi uniform
on the upper hemisphere with every eighth one mirrored below it (a light behind the surface),
u1 and u2 uniform in [0, 1).

Kernels (benchmarks/kernels/shading_lanes.cl, one program built with the scene's features):
  renderer  one work-item per input calling texture_eval3/texture_eval1, bsdf_eval_local and
            bsdf_sample_local as the megakernel does, VOLCL_KERNEL (Intel's runtime keeps it scalar)
  lanes     the same arithmetic in the lanes style (kernels/lanes.h), no vec_type_hint
Both run in work-groups of 256 (the wave padded to a multiple), kernel time only (enqueue to
finish), best of --repeat launches, the two kernels' launches interleaved, after one untimed launch
each. "agree" compares every output of the lanes kernel with the renderer's: the share of inputs
whose 12 output numbers all have identical bits, and the largest relative difference of any number
(then per output, relative and absolute: a direction's small components make relative figures big).

--round-trip times what a shading stage would add around that kernel: in the renderer the inputs
live in the scalar megakernel's registers. Per wave size, three variants (kernels in shading_lanes.cl),
each making item i's inputs from a PCG stream of its own (kernels/rng.h, the same distributions as
above) and folding its 12 outputs into an 8-byte result (their sum in row order, a hash of their bits):
  inline          one VOLCL_KERNEL kernel: inputs made, shaded by the renderer's functions, folded,
                  all in registers (the megakernel)
  split           shade_make (VOLCL_KERNEL: the inputs written to the 11 rows), shade_lanes over the
                  rows, shade_fold (VOLCL_KERNEL: the 12 output rows read back and folded)
  split-renderer  split with shade_renderer for shade_lanes: the traffic's and launches' cost alone
A variant's time: its launches enqueued back to back on the in-order queue, then one finish; best
(and median) of interleaved runs, --repeat x (2^20 / wave) of them, at least --repeat and at most 400,
after one untimed run each. The stages are also timed one by one (a finish after each). "agree":
the share of items whose folded sum (and hash) have the bits of inline's, and the sums' largest
relative difference (on PoCL, where the lanes outputs have the renderer's bits, all of them expected).

--gather times a shading stage fed from a mixed wave: a share f (1/4, 1/2, 1) of the items are
floor hits, chosen by a hash of (seed, item) alone (gather_floor; floor_items is its host copy), the
others "other" hits that get a fixed few flops of diffuse-like work (gather_other) in every variant.
Inputs made and results folded as --round-trip's. Variants (kernels in shading_lanes.cl):
  inline           shade_ginline (VOLCL_KERNEL): floor items shaded inline by the renderer's
                   functions, the others by gather_other, in one scalar kernel (the megakernel's
                   way, divergence included)
  gather           counter zeroed, shade_gmake (VOLCL_KERNEL: a floor item takes row
                   atomic_inc(count) for its inputs and its own index, an other item is shaded and
                   folded at once), the count read back (a blocking 4-byte read), shade_lanes over
                   the first count rows rounded up to the work-group, shade_gfold (row k folded into
                   item owner[k]'s result) over as many
  gather-full      gather without the read back: shade_lanes and shade_gfold over the whole wave
                   (the rows past the count shaded from stale inputs, not folded)
  gather-count     gather-full with shade_glanes: whole work-groups past the count (read on the
                   device) skip the shading
  gather-wg        gather with shade_gmake_wg: the counting aggregated per work-group (a local
                   atomic_inc, one global atomic_add a group: each group's rows one block)
  gather-renderer  gather with shade_renderer for shade_lanes
Time per run: from the first enqueue to one finish (the read back included), best (and median) of
interleaved runs, as many as --round-trip's; all-floor is --round-trip's inline on the same wave
for reference. "agree": per item (never sums over the wave: the atomic counter's order varies from
run to run, and a row's result reaches its item through owner), the share of items whose folded
sum (and hash) have inline's bits, after each variant ran into results filled with a sentinel.

Vectorization is the runtime's own report: Intel's runtime's build log ("Kernel ... was successfully
vectorized (16)"), PoCL's LLVM remarks at the first launch (POCL_VECTORIZER_REMARKS=1, printed only
when the work-group function is compiled: --fresh-cache gives PoCL an empty cache and turns
pyopencl's binary cache off), read by benchmarks/traversal_lanes.py's vector_verdict.
"""
from __future__ import annotations

import argparse
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
from traversal_lanes import FdCapture, vector_verdict  # noqa: E402

KERNEL = HERE / "kernels" / "shading_lanes.cl"
SCENE = ROOT / "scenes" / "textured_cbox.xml"
PAD = 256
IN_ROWS, OUT_ROWS = 11, 12
OUTPUTS = ("value.x", "value.y", "value.z", "pdf", "ok", "wi.x", "wi.y", "wi.z", "weight.x", "weight.y",
           "weight.z", "sample pdf")
KERNELS = ("renderer", "lanes")
# --round-trip: the variants (timed as a whole: their launches enqueued back to back, one finish)
# and the stages timed one by one for the breakdown
TRIPS = {"inline": ("inline",), "split": ("make", "lanes", "fold"), "split-renderer": ("make", "renderer", "fold")}
STAGES = ("inline", "make", "lanes", "renderer", "fold")
WAVES = (4096, 65536, 1 << 20)
# --gather: the variants; each one's results live in b["result"][RESULT[variant]]
GATHERS = ("inline", "gather", "gather-full", "gather-count", "gather-wg", "gather-renderer")
RESULT = {"inline": "inline", "split": "lanes", "split-renderer": "renderer", "gather": "lanes",
          "gather-full": "lanes", "gather-count": "lanes", "gather-wg": "lanes", "gather-renderer": "renderer"}
GATHER_WAVES = (4096, 65536)
GATHER_QUARTERS = (1, 2, 4)


def floor_material(packed):
    """The index of textured_cbox's floor bsdf in the packed records (the roughplastic of alpha 0.15
    with a bitmap diffuse reflectance), checked against what shade_lanes is specialized to."""
    from volcl import layout
    a = packed.arrays
    b, t = a["bsdfs"], a["textures"]
    hits = [k for k in range(len(b)) if b[k]["type"] == layout.BSDF_TYPES["roughplastic"]
            and abs(float(b[k]["alpha_u"]) - 0.15) < 1e-6 and b[k]["color_tex"] >= 0]
    if len(hits) != 1:
        raise SystemExit(f"expected one roughplastic floor bsdf, found {hits}")
    k = hits[0]
    r, tex = b[k], t[b[k]["color_tex"]]
    checks = {
        "ggx": r["distribution"] == layout.MICROFACETS["ggx"],
        "visible normals": r["flags"] & layout.BSDF_FLAGS["visible"],
        "isotropic": r["alpha_u"] == r["alpha_v"],
        "constant roughness and specular": r["alpha_u_tex"] < 0 and r["alpha_v_tex"] < 0 and r["spec_r_tex"] < 0,
        "bitmap": tex["type"] == layout.TEXTURE_TYPES["bitmap"],
        "bilinear": tex["filter"] == layout.TEXTURE_FILTERS["bilinear"],
        "3 channels": tex["channels"] == 3,
        "byte-coded texels": tex["lut"] >= 0,
    }
    bad = [name for name, ok in checks.items() if not ok]
    if bad:
        raise SystemExit(f"the floor bsdf is not what shade_lanes handles: {bad}")
    return k, bool(tex["lut"] >= 0)


def make_inputs(n, seed=1):
    """(IN_ROWS, n) float32 rows: u, v, wo.xyz, wi.xyz, u1, u2.x, u2.y (see the module's text)."""
    rng = np.random.default_rng(seed)

    def unit():     # uniform in [0, 1) with float32's 24 bits, never rounding up to 1
        return (rng.integers(0, 1 << 24, n) / float(1 << 24)).astype(np.float32)

    def hemisphere():
        z = rng.random(n)
        phi = 2.0 * np.pi * rng.random(n)
        r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
        return np.stack([r * np.cos(phi), r * np.sin(phi), z])

    rows = np.empty((IN_ROWS, n), np.float32)
    rows[0], rows[1] = unit(), unit()
    rows[2:5] = hemisphere()
    wi = hemisphere()
    wi[2, ::8] *= -1.0
    rows[5:8] = wi
    rows[8], rows[9], rows[10] = unit(), unit(), unit()
    return rows


class Shading:
    """The scene packed, the program built and its two kernels ready on one device."""

    def __init__(self, device, extra=()):
        from volcl.device import cl
        from volcl.pack import pack
        from volcl.program import build_program
        from volcl.scene import load
        self.cl, self.device = cl, device
        scene = load(SCENE)
        self.packed = pack(scene)
        self.index, self.lut = floor_material(self.packed)
        a = self.packed.arrays
        self.ctx = cl.Context([device.device])
        self.queue = cl.CommandQueue(self.ctx)
        mf = cl.mem_flags
        self.scene_bufs = [cl.Buffer(self.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(a[k]))
                           for k in ("bsdfs", "textures", "texels", "bsdf_tables")]
        opts = tuple(extra)
        with FdCapture() as cap:
            t0 = time.perf_counter()
            self.program = build_program(self.ctx, self.packed.features, KERNEL, extra=opts)
            self.build_seconds = time.perf_counter() - t0
        self.build_output = cap.text
        self.build_log = self.program.get_build_info(device.device, cl.program_build_info.LOG) or ""
        self.kernels = {name: cl.Kernel(self.program, f"shade_{name}")
                        for name in KERNELS + ("inline", "make", "fold", "ginline", "gmake", "gfold", "glanes", "gmake_wg")}
        self.first_launch = {}

    def upload(self, rows):
        cl, mf = self.cl, self.cl.mem_flags
        n = rows.shape[1]
        m = -(-n // PAD) * PAD
        if m > n:
            rows = np.concatenate([rows, np.repeat(rows[:, -1:], m - n, 1)], 1)
        return {"n": n, "m": m,
                "in": cl.Buffer(self.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(rows)),
                "out": {k: cl.Buffer(self.ctx, mf.WRITE_ONLY, 4 * OUT_ROWS * m) for k in KERNELS}}

    def enqueue(self, name, b, out=None, size=None):
        """Launch kernel `name` over wave `b` (no finish), over `size` work-items (a multiple of PAD)
        or the whole wave: one of KERNELS (rows to rows, into b["out"][out or name]), a round-trip
        stage (inline, make, fold) or a gather stage (ginline, gmake, gfold; their results
        b["result"][out])."""
        q, m, k = self.queue, np.int32(b["m"]), self.kernels[name]
        gs, ls = (size or b["m"],), (PAD,)
        if name == "ginline":
            k(q, gs, ls, *self.scene_bufs, np.int32(self.index), np.uint32(b["seed"]), np.int32(b["fq"]),
              b["result"]["inline"])
        elif name in ("gmake", "gmake_wg"):
            k(q, gs, ls, np.uint32(b["seed"]), np.int32(b["fq"]), b["in"], m, b["count"], b["owner"], b["result"][out])
        elif name == "glanes":
            k(q, gs, ls, *self.scene_bufs, np.int32(self.index), b["in"], b["out"]["lanes"], m, b["count"])
        elif name == "gfold":
            k(q, gs, ls, b["out"][out], m, b["count"], b["owner"], b["result"][out])
        elif name == "inline":
            k(q, gs, ls, *self.scene_bufs, np.int32(self.index), np.uint32(b["seed"]), b["result"]["inline"])
        elif name == "make":
            k(q, gs, ls, np.uint32(b["seed"]), b["in"], m)
        elif name == "fold":
            k(q, gs, ls, b["out"][out], m, b["result"][out])
        else:
            k(q, gs, ls, *self.scene_bufs, np.int32(self.index), b["in"], b["out"][out or name], m)

    def run(self, name, b):
        return self.run_all(((name, None),), b)

    def run_all(self, launches, b):
        """Kernel time of the (name, out) launches enqueued back to back, one finish at the end."""
        q = self.queue
        q.finish()
        t0 = time.perf_counter()
        for name, out in launches:
            self.enqueue(name, b, out)
        q.finish()
        return time.perf_counter() - t0

    def trip_wave(self, n, seed):
        """Buffers for a --round-trip wave of n items: the rows (as upload's) and each variant's
        8-byte results."""
        m = -(-n // PAD) * PAD
        b = self.upload(np.zeros((IN_ROWS, m), np.float32))
        b.update(n=n, seed=seed, result={k: self.cl.Buffer(self.ctx, self.cl.mem_flags.WRITE_ONLY, 8 * m)
                                         for k in ("inline",) + KERNELS})
        return b

    @staticmethod
    def trip_launches(variant):
        """A round-trip variant's launches as (name, out) pairs: the split ones' shading kernel
        writes, and shade_fold reads, b["out"][shading kernel]."""
        if variant == "inline":
            return (("inline", None),)
        shade = "lanes" if variant == "split" else "renderer"
        return (("make", None), (shade, None), ("fold", shade))

    def trip_result(self, variant, b):
        """(sum as float32, hash as uint32) per item of a round-trip variant's last run."""
        key = RESULT[variant]
        out = np.empty((b["m"], 2), np.uint32)
        self.cl.enqueue_copy(self.queue, out, b["result"][key])
        self.queue.finish()
        return out[:b["n"], 0].view(np.float32), out[:b["n"], 1]

    def gather_wave(self, n, seed, fq):
        """Buffers for a --gather wave of n items, fq / 4 of them floor hits: trip_wave's, the row
        counter and the rows' owners."""
        b = self.trip_wave(n, seed)
        mf = self.cl.mem_flags
        b.update(fq=fq, count=self.cl.Buffer(self.ctx, mf.READ_WRITE, 4),
                 owner=self.cl.Buffer(self.ctx, mf.READ_WRITE, 4 * b["m"]), count_host=np.zeros(1, np.int32))
        return b

    def run_gather(self, variant, b):
        """Time of one run of a --gather variant (see the module's text), from the first enqueue to
        the finish; the floor rows' count is left in b["count_host"] (where read)."""
        q = self.queue
        q.finish()
        t0 = time.perf_counter()
        if variant == "inline":
            self.enqueue("ginline", b)
        else:
            shade = RESULT[variant]
            self.cl.enqueue_fill_buffer(q, b["count"], np.int32(0), 0, 4)
            self.enqueue("gmake_wg" if variant == "gather-wg" else "gmake", b, shade)
            if variant == "gather-count":       # the lanes kernel reads the count itself
                self.enqueue("glanes", b)
                self.enqueue("gfold", b, shade)
                q.finish()
                return time.perf_counter() - t0
            if variant == "gather-full":
                size = b["m"]
            else:
                self.cl.enqueue_copy(q, b["count_host"], b["count"])     # blocking: make has run
                size = -(-int(b["count_host"][0]) // PAD) * PAD
            if size:
                self.enqueue(shade, b, size=size)
                self.enqueue("gfold", b, shade, size=size)
        q.finish()
        return time.perf_counter() - t0

    def launch_first(self, name, b):
        """The untimed first launch, its output captured (PoCL prints its remarks then)."""
        with FdCapture() as cap:
            self.run(name, b)
        self.first_launch[name] = cap.text

    def verdict(self, name):
        """What the runtime says it did with kernel `name`'s work-items."""
        kernel = f"shade_{name}"
        text = self.build_log + "\n" + self.build_output
        if "intel" in self.device.platform_name.lower():
            lines = "\n".join(ln for ln in text.splitlines() if re.search(rf"\b{kernel}\b", ln))
            return vector_verdict(self.device.platform_name, lines, "")
        return vector_verdict(self.device.platform_name, "", self.first_launch.get(name, ""))

    def results(self, name, b):
        out = np.empty((OUT_ROWS, b["m"]), np.float32)
        self.cl.enqueue_copy(self.queue, out, b["out"][name])
        self.queue.finish()
        return out[:, :b["n"]]


def agreement(ref, got):
    """(share of inputs whose outputs all have identical bits, largest relative difference of any
    output number, per output row the largest relative difference, per row the largest absolute
    difference)"""
    same = np.all(ref.view(np.int32) == got.view(np.int32), axis=0)
    a, b = ref.astype(np.float64), got.astype(np.float64)
    scale = np.maximum(np.abs(a), np.abs(b))
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = np.where(scale > 0, np.abs(a - b) / scale, 0.0)
    rel = np.where(np.isnan(a) & np.isnan(b), 0.0, np.where(np.isnan(a) | np.isnan(b), np.inf, rel))
    per_row = rel.max(axis=1)
    with np.errstate(invalid="ignore"):
        absolute = np.where(np.isnan(a) & np.isnan(b), 0.0, np.abs(a - b)).max(axis=1)
    return float(np.mean(same)), float(per_row.max()), per_row, absolute


def fold_agreement(ref, got):
    """(share of items whose folded sum has the same bits, share whose hash is the same, the sums'
    largest relative difference): a round-trip variant's results against inline's."""
    (s0, h0), (s1, h1) = ref, got
    a, b = s0.astype(np.float64), s1.astype(np.float64)
    scale = np.maximum(np.abs(a), np.abs(b))
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = np.where(scale > 0, np.abs(a - b) / scale, 0.0)
    rel = np.where(np.isnan(a) & np.isnan(b), 0.0, np.where(np.isnan(a) | np.isnan(b), np.inf, rel))
    return float(np.mean(s0.view(np.uint32) == s1.view(np.uint32))), float(np.mean(h0 == h1)), float(rel.max())


def round_trip(sh, waves, repeat, seed):
    """The --round-trip tables (see the module's text)."""
    rate_rows, stage_rows, agree_rows = [], [], []
    for n in waves:
        b = sh.trip_wave(n, seed)
        runs = int(max(repeat, min(400, repeat * (1 << 20) // b["m"])))
        with FdCapture():       # PoCL's remarks at a first launch
            for v in TRIPS:
                sh.run_all(sh.trip_launches(v), b)
        stage_launch = {"inline": (("inline", None),), "make": (("make", None),), "lanes": (("lanes", None),),
                        "renderer": (("renderer", None),), "fold": (("fold", "lanes"),)}
        times = {k: [] for k in list(TRIPS) + [f"stage {s}" for s in STAGES]}
        t0 = time.perf_counter()
        for _ in range(runs):
            for v in TRIPS:
                times[v].append(sh.run_all(sh.trip_launches(v), b))
            for s in STAGES:
                times[f"stage {s}"].append(sh.run_all(stage_launch[s], b))
        log(f"wave {n:,}: {runs} runs in {time.perf_counter() - t0:.1f} s")
        # the results of a whole variant last (the stages above overwrote split's fold)
        res = {}
        for v in TRIPS:
            sh.run_all(sh.trip_launches(v), b)
            res[v] = sh.trip_result(v, b)
        best = {k: min(t) for k, t in times.items()}
        med = {k: float(np.median(t)) for k, t in times.items()}
        rate = {v: b["m"] / best[v] / 1e6 for v in TRIPS}
        rate_med = {v: b["m"] / med[v] / 1e6 for v in TRIPS}
        rate_rows.append([f"{b['m']:,}", runs] + [f"{rate[v]:.2f} ({rate_med[v]:.2f})" for v in TRIPS]
                         + [f"{rate['inline'] / rate['split']:.2f} ({rate_med['inline'] / rate_med['split']:.2f})",
                            f"{rate['split'] / rate['inline']:.2f}", f"{rate['inline'] / rate['split-renderer']:.2f}"])
        stage_rows.append([f"{b['m']:,}"] + [f"{1e6 * best[f'stage {s}']:.0f}" for s in STAGES]
                          + [f"{1e6 * best['split']:.0f}", f"{1e6 * best['split-renderer']:.0f}"])
        for v in ("split", "split-renderer"):
            same, hashes, worst = fold_agreement(res["inline"], res[v])
            agree_rows.append([f"{b['m']:,}", v, f"{100 * same:.4f}%", f"{100 * hashes:.4f}%", f"{worst:.1e}"])
    print(table(["wave", "runs", "inline M/s", "split M/s", "split-renderer M/s", "inline / split",
                 "split / inline", "inline / split-renderer"], rate_rows))
    print("\nM shadings/s from the best run (the median run's in brackets); split / inline: the net gain of a "
          "lanes shading stage, inline / split-renderer: what the traffic and launches alone cost.\n")
    print(table(["wave", "inline µs"] + [f"{s} µs" for s in STAGES[1:]] + ["split µs", "split-renderer µs"],
                stage_rows))
    print("\nBest kernel times, µs: each stage launched alone (a finish after each), then the split variants "
          "as timed above (their launches back to back).\n")
    print(table(["wave", "variant", "sums with inline's bits", "hashes with inline's", "max rel diff of sums"],
                agree_rows))
    return agree_rows


def floor_items(n, seed, fq):
    """gather_floor (shading_lanes.cl) on the host: which of n items are floor hits."""
    with np.errstate(over="ignore"):
        h = (np.arange(n, dtype=np.uint32) * np.uint32(0x9e3779b9)) ^ (np.uint32(seed) * np.uint32(0x85ebca6b))
        h ^= h >> np.uint32(16)
        h *= np.uint32(0x7feb352d)
        h ^= h >> np.uint32(15)
        h *= np.uint32(0x846ca68b)
        h ^= h >> np.uint32(16)
    return (h & np.uint32(3)).astype(np.int32) < fq


def gather_check(sh, b):
    """Each --gather variant run once into results filled with a sentinel: (per variant its (sum,
    hash) per item, the floor rows counted by the last gather run)."""
    res = {}
    for v in GATHERS:
        sh.cl.enqueue_fill_buffer(sh.queue, b["result"][RESULT[v]], np.uint32(0xFFFFFFFF), 0, 8 * b["m"])
        sh.run_gather(v, b)
        res[v] = sh.trip_result(v, b)
    return res, int(b["count_host"][0])


def gather(sh, waves, quarters, repeat, seed):
    """The --gather tables (see the module's text)."""
    rate_rows, agree_rows = [], []
    for n in waves:
        for fq in quarters:
            b = sh.gather_wave(n, seed, fq)
            runs = int(max(repeat, min(400, repeat * (1 << 20) // b["m"])))
            with FdCapture():       # PoCL's remarks at a first launch
                res, count = gather_check(sh, b)
            floor = floor_items(b["n"], seed, fq)
            assert count == int(floor.sum()), (count, int(floor.sum()))
            times = {v: [] for v in GATHERS + ("all-floor",)}
            t0 = time.perf_counter()
            for _ in range(runs):
                for v in GATHERS:
                    times[v].append(sh.run_gather(v, b))
                times["all-floor"].append(sh.run("inline", b))      # --round-trip's inline: f = 1, no hash
            log(f"wave {n:,}, f {fq}/4: {runs} runs in {time.perf_counter() - t0:.1f} s")
            best = {v: min(t) for v, t in times.items()}
            med = {v: float(np.median(t)) for v, t in times.items()}
            rate = {v: b["n"] / best[v] / 1e6 for v in times}
            rate_med = {v: b["n"] / med[v] / 1e6 for v in times}
            rate_rows.append([f"{b['n']:,}", f"{fq}/4", f"{100 * floor.mean():.1f}%", runs]
                             + [f"{rate[v]:.2f} ({rate_med[v]:.2f})" for v in GATHERS + ("all-floor",)]
                             + [f"{rate[v] / rate['inline']:.2f} ({rate_med[v] / rate_med['inline']:.2f})"
                                for v in ("gather", "gather-full", "gather-count", "gather-wg")])
            for v in GATHERS[1:]:
                same, hashes, worst = fold_agreement(res["inline"], res[v])
                agree_rows.append([f"{b['n']:,}", f"{fq}/4", v, f"{100 * same:.4f}%", f"{100 * hashes:.4f}%",
                                   f"{worst:.1e}"])
    print(table(["wave", "f", "floor items", "runs"] + [f"{v} M/s" for v in GATHERS + ("all-floor",)]
                + [f"{v} / inline" for v in ("gather", "gather-full", "gather-count", "gather-wg")], rate_rows))
    print("\nM items/s (floor and other hits) from the best run (the median run's in brackets); all-floor: "
          "--round-trip's inline on the same wave (every item a floor hit, no hash), for reference.\n")
    print(table(["wave", "f", "variant", "items' sums with inline's bits", "hashes with inline's",
                 "max rel diff of sums"], agree_rows))
    return agree_rows


def table(header, rows):
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(out)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--n", type=int, default=1 << 20, help="inputs in the wave")
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--device", help="volcl device selector")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--fresh-cache", action="store_true", help="an empty POCL_CACHE_DIR (PoCL prints remarks)")
    p.add_argument("--remarks-dir", default=None, help="save the build log and first launches' output here")
    p.add_argument("-D", "--define", action="append", default=[], help="extra -D option for the kernels' build")
    p.add_argument("--round-trip", action="store_true",
                   help="time inline shading against a shading stage's round trip (see above)")
    p.add_argument("--waves", default=None, help="--round-trip's (--gather's) wave sizes, "
                   f"default {','.join(str(w) for w in WAVES)} ({','.join(str(w) for w in GATHER_WAVES)})")
    p.add_argument("--gather", action="store_true",
                   help="time inline shading of a mixed wave against gathering its floor hits (see above)")
    args = p.parse_args(argv)

    os.environ.setdefault("POCL_VECTORIZER_REMARKS", "1")
    if args.fresh_cache:
        os.environ["POCL_CACHE_DIR"] = tempfile.mkdtemp(prefix="pocl-fresh-")
        os.environ["PYOPENCL_NO_CACHE"] = "1"
    from volcl import device as devmod
    with FdCapture():       # the device check's builds print their remarks too
        device = devmod.choose(args.device)
    print("# Shading in the lanes: textured_cbox's floor (roughplastic, GGX 0.15, bitmap diffuse)\n")
    print(f"- CPU: {cpu_model()}, {os.cpu_count()} cores; load average at start "
          f"{' '.join(Path('/proc/loadavg').read_text().split()[:3])}")
    print(f"- device: {device.name} ({device.platform_name}, {device.device.max_compute_units} compute units)")
    log("packing textured_cbox and building ...")
    sh = Shading(device, tuple(f"-D{d}" for d in args.define))
    if args.round_trip:
        print(f"- round trip: work-groups of {PAD}; texels {'byte-coded' if sh.lut else 'float'}; "
              f"build {sh.build_seconds:.1f} s\n")
        round_trip(sh, [int(w) for w in (args.waves or ",".join(map(str, WAVES))).split(",")], args.repeat,
                   args.seed)
        print(f"\nload average at end: {' '.join(Path('/proc/loadavg').read_text().split()[:3])}")
        return 0
    if args.gather:
        print(f"- gather: work-groups of {PAD}; texels {'byte-coded' if sh.lut else 'float'}; "
              f"build {sh.build_seconds:.1f} s\n")
        gather(sh, [int(w) for w in (args.waves or ",".join(map(str, GATHER_WAVES))).split(",")], GATHER_QUARTERS,
               args.repeat, args.seed)
        print(f"\nload average at end: {' '.join(Path('/proc/loadavg').read_text().split()[:3])}")
        return 0
    rows = make_inputs(args.n, args.seed)
    b = sh.upload(rows)
    print(f"- {b['n']:,} inputs (padded to {b['m']:,}), work-groups of {PAD}; best of {args.repeat} launches, "
          f"interleaved; texels {'byte-coded' if sh.lut else 'float'}; build {sh.build_seconds:.1f} s\n")
    for name in KERNELS:
        t0 = time.perf_counter()
        sh.launch_first(name, b)
        log(f"first launch of {name}: {time.perf_counter() - t0:.1f} s")
    best = dict.fromkeys(KERNELS, np.inf)
    for _ in range(args.repeat):
        for name in KERNELS:
            best[name] = min(best[name], sh.run(name, b))
    ref = sh.results("renderer", b)
    got = sh.results("lanes", b)
    same, worst, per_row, absolute = agreement(ref, got)
    rate = {k: b["m"] / best[k] / 1e6 for k in KERNELS}
    print(table(["kernel", "M shadings/s", "vs renderer", "vectorization", "same bits", "max rel diff"], [
        ["renderer", f"{rate['renderer']:.2f}", "1.00", sh.verdict("renderer"), "–", "–"],
        ["lanes", f"{rate['lanes']:.2f}", f"{rate['lanes'] / rate['renderer']:.2f}", sh.verdict("lanes"),
         f"{100 * same:.4f}%", f"{worst:.1e}"]]))
    print("\nLargest relative difference per output: " + ", ".join(
        f"{name} {v:.1e}" for name, v in zip(OUTPUTS, per_row)))
    print("Largest absolute difference per output: " + ", ".join(
        f"{name} {v:.1e}" for name, v in zip(OUTPUTS, absolute)))
    differ = np.any(ref.view(np.int32) != got.view(np.int32), axis=0)
    if differ.any():
        print(f"Inputs with any differing bits: {100 * np.mean(differ):.2f}%; on the sampled direction "
              f"{100 * np.mean(np.any(ref[5:8].view(np.int32) != got[5:8].view(np.int32), axis=0)):.2f}%, "
              f"on eval's value and pdf {100 * np.mean(np.any(ref[:4].view(np.int32) != got[:4].view(np.int32), axis=0)):.2f}%")
    ok = ref[4] > 0
    print(f"\nSamples that succeed: renderer {100 * np.mean(ok):.2f}%, lanes {100 * np.mean(got[4] > 0):.2f}%")
    if args.remarks_dir:
        out = Path(args.remarks_dir)
        out.mkdir(parents=True, exist_ok=True)
        safe = re.sub(r"[^A-Za-z0-9]+", "_", device.platform_name.lower()).strip("_")
        (out / f"shading-{safe}.txt").write_text(
            f"--- build log\n{sh.build_log}\n--- build output\n{sh.build_output}\n"
            + "".join(f"--- first launch of {k}\n{sh.first_launch.get(k, '')}\n" for k in KERNELS))
    print(f"\nload average at end: {' '.join(Path('/proc/loadavg').read_text().split()[:3])}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
