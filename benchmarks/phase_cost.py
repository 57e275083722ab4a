#!/usr/bin/env python3
"""What the phase functions beyond HG cost, in samples per CPU second of the rendering process
(which other jobs on shared cores disturb far less than wall time: +-4% against +-20% here), best
of --repeat with the variants interleaved (a process of its own renders the best of 3). Prints
three Markdown tables:

 1. HG-only scenes, this checkout against --baseline-rev (a commit from before the phase families,
    exported with `git archive` and run in its own processes): is the homogeneous HG path's cost
    unchanged?
 2. HG-only scenes, the specialized kernel against the same kernel with PHASE_FAMILIES compiled in
    but unused: what the one coarse flag would cost a scene that needs none of its code (an upper
    bound on what finer flags, each keeping only one family, could save).
 3. One scene with each phase function in turn, against the same scene with HG of the same mean
    cosine (light goes much the same ways, so the difference is what evaluating and sampling the
    phase function costs): what each costs where it is used.

    python benchmarks/phase_cost.py [--baseline-rev REV] [--scenes SCENE.xml ...] [--spp 16]
        [--width 160] [--height 120] [--repeat 5] [--phase-scene SCENE.xml] [--tables 123]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from common import cpu_model

ROOT = Path(__file__).resolve().parent.parent

# Runs in a process of its own against the volcl of `root`: only API both sides of the comparison have.
WORKER = """
import json, sys, time
sys.path.insert(0, {root!r})
try:
    from volcl.renderer import Renderer
except ImportError:                                 # checkouts from before volcl/renderer.py
    from volcl.render import Renderer
from volcl.scene import load
sc = load({scene!r})
sc.camera.width, sc.camera.height = {width}, {height}
r = Renderer(sc)
r.render({spp})                                     # build and warm up
best = 0.0
for _ in range(3):
    t = time.process_time()
    r.render({spp})
    best = max(best, {width} * {height} * {spp} / (time.process_time() - t))
print(json.dumps(best))
"""

PHASES = {
    "Rayleigh": {"kind": "rayleigh"},
    "Draine g = 0.6, alpha = 1": {"kind": "draine", "g": 0.6, "alpha": 1.0},
    "tabphase (8 values)": {"kind": "tabulated", "values": [4, 1, 0.3, 0.2, 0.3, 1, 6, 12]},
    "blend of 3 lobes": {"kind": "blend", "weight": 0.3, "phases": [{"kind": "hg", "g": 0.8}, {
        "kind": "blend", "weight": 0.6, "phases": [{"kind": "rayleigh"}, {"kind": "hg", "g": -0.6}]}]},
    "Fournier-Forand B = 0.0183": {"kind": "fournier_forand", "backscatter": 0.0183},
    "approximate Mie, 10 um": {"kind": "mie", "diameter": 10.0},
}


def phase_of(spec):
    from volcl import phase as ph
    from volcl.scene.model import Phase
    spec = dict(spec)
    if "phases" in spec:
        spec["phases"] = tuple(phase_of(p) for p in spec["phases"])
    if "values" in spec:
        import numpy as np
        spec["values"] = np.array(spec["values"], float)
    if "backscatter" in spec:
        ff = ph.fournier_forand_from_backscatter(spec.pop("backscatter"))
        spec["n"], spec["mu"] = ff.n, ff.mu
    return Phase(**spec)


def worker_rate(root, scene, args):
    src = WORKER.format(root=str(root), scene=str(scene), width=args.width, height=args.height, spp=args.spp)
    out = subprocess.run([sys.executable, "-c", src], capture_output=True, text=True, check=True,
                         env=dict(os.environ, PYTHONPATH=str(root)))
    return json.loads(out.stdout.strip().splitlines()[-1])


def best_rates(variants, repeat):
    """variants: {name: callable() -> samples/s}; best of `repeat`, interleaved."""
    best = dict.fromkeys(variants, 0.0)
    for _ in range(repeat):
        for name, fn in variants.items():
            best[name] = max(best[name], fn())
    return best


def against_baseline(args):
    with tempfile.TemporaryDirectory(prefix="volcl-baseline-") as tmp:
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", args.baseline_rev], capture_output=True, check=True)
        subprocess.run(["tar", "-x", "-C", tmp], input=archive.stdout, check=True)
        print(f"\n### 1. HG-only scenes: this checkout against {args.baseline_rev} (separate processes)\n")
        print("| scene | baseline M samples/CPU s | this checkout M samples/CPU s | ratio |")
        print("|---|---:|---:|---:|")
        for scene in args.scenes:
            rates = best_rates({"base": lambda: worker_rate(tmp, scene, args),
                                "this": lambda: worker_rate(ROOT, scene, args)}, args.repeat)
            print(f"| {Path(scene).name} | {rates['base'] / 1e6:.3f} | {rates['this'] / 1e6:.3f} | "
                  f"{rates['this'] / rates['base']:.3f} |", flush=True)


def in_process(args):
    sys.path.insert(0, str(ROOT))
    import time

    def rate_of(renderer):
        def run():
            t = time.process_time()
            renderer.render(args.spp)
            return args.width * args.height * args.spp / (time.process_time() - t)
        renderer.render(args.spp)       # build and warm up
        return run

    if "2" in args.tables:
        families_unused(args, rate_of)
    if "3" in args.tables:
        each_phase(args, rate_of)


def families_unused(args, rate_of):
    from volcl.features import detect
    from volcl.renderer import Renderer
    from volcl.scene import load
    print("\n### 2. HG-only scenes: PHASE_FAMILIES compiled in but unused\n")
    print("| scene | specialized M samples/CPU s | + PHASE_FAMILIES M samples/CPU s | ratio |")
    print("|---|---:|---:|---:|")
    for scene in args.scenes:
        sc = load(scene)
        sc.camera.width, sc.camera.height = args.width, args.height
        feats = detect(sc)
        assert not feats["PHASE_FAMILIES"], f"{scene} uses the phase families"
        rates = best_rates({"off": rate_of(Renderer(sc)), "on": rate_of(Renderer(sc, features=dict(feats, PHASE_FAMILIES=True)))},
                           args.repeat)
        print(f"| {Path(scene).name} | {rates['off'] / 1e6:.3f} | {rates['on'] / 1e6:.3f} | "
              f"{rates['on'] / rates['off']:.3f} |", flush=True)


def each_phase(args, rate_of):
    from volcl import phase as ph
    from volcl.renderer import Renderer
    from volcl.scene import load
    from volcl.scene.model import Phase
    print(f"\n### 3. {Path(args.phase_scene).name} with each phase function, against HG of its mean cosine\n")
    print("| phase function | mean cosine | M samples/CPU s | HG, same mean cosine | ratio |")
    print("|---|---:|---:|---:|---:|")
    renderers, means = {}, {}
    for name, spec in PHASES.items():
        phase = phase_of(spec)
        means[name] = ph.mean_cosine(phase)
        for key, p in ((name, phase), (name + " (HG)", Phase("hg", means[name]) if means[name] else Phase())):
            sc = load(args.phase_scene)
            sc.camera.width, sc.camera.height = args.width, args.height
            for m in sc.media:
                m.phase = p
            renderers[key] = rate_of(Renderer(sc))
    rates = best_rates(renderers, args.repeat)
    for name in PHASES:
        a, b = rates[name], rates[name + " (HG)"]
        print(f"| {name} | {means[name]:.3f} | {a / 1e6:.3f} | {b / 1e6:.3f} | {a / b:.3f} |")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--baseline-rev", help="commit to compare HG-only scenes against (skipped without)")
    p.add_argument("--scenes", nargs="*", default=[str(ROOT / "scenes" / n) for n in ("fog.xml", "smoke_sphere.xml",
                                                                                    "underwater.xml")])
    p.add_argument("--phase-scene", default=str(ROOT / "scenes" / "fog.xml"))
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--width", type=int, default=160)
    p.add_argument("--height", type=int, default=120)
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--tables", default="123", help="which of the tables to measure (default 123)")
    args = p.parse_args(argv)
    print(f"{cpu_model()}; {args.width}x{args.height}, {args.spp} spp, best of {args.repeat}, variants interleaved")
    if args.baseline_rev and "1" in args.tables:
        against_baseline(args)
    in_process(args)


if __name__ == "__main__":
    main()
