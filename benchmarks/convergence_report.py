#!/usr/bin/env python3
"""What accuracy costs in time, per estimator choice, for the scenes where the choice matters.

For each configuration below: one `volcl converge` (error against time, doubling spp, one run per
choice; its plot is copied to docs/images/), then the same choices again from --seeds independent
seeds with a fixed CPU budget each, against the reference converge rendered. One run is a single
draw of a heavy-tailed error (paths that scatter near a point light have infinite variance in any
unidirectional estimator), so the defaults are read from the median efficiency over the seeds, not
from one curve. Everything is written to docs/convergence.md, pasted into README ("Convergence").

    python benchmarks/convergence_report.py [--max-seconds 15] [--reference-seconds 90] [--seeds 5]
                                            [--budget 3] [--only NAME ...]

About 20 minutes with the defaults on 2 cores. Raw outputs (CSV, tables, references) go to
benchmarks/out/convergence/.
"""
import argparse
import csv
import math
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "benchmarks" / "out" / "convergence"

# (name, scene, extra volcl arguments, what the configuration decides); the point light in fog gets
# twice the budget so that the equiangular choices reach 3% within it
CONFIGS = [
    ("point_in_fog", "scenes/point_in_fog.xml", ["--max-seconds", "{2x}"],
     "a point light in thin fog (sigma_t 0.15): equiangular sampling, and which MIS"),
    ("point_in_fog_dense", "scenes/point_in_fog.xml", ["-D", "sigma_t=0.5"],
     "the same light in denser fog (sigma_t 0.5), where transmittance along the ray matters"),
    ("point_beside_smoke", "benchmarks/scenes/point_beside_smoke.xml", ["--choices", "mis,equiangular+mis"],
     "a point light outside the only medium: is 'auto' right to leave equiangular sampling off?"),
    ("fog", "scenes/fog.xml", [], "an area light in fog: NEE and MIS"),
    ("cbox", "scenes/cbox.xml", [], "surfaces only: NEE and MIS"),
]


def read_curves(path):
    """choice -> (spp, seconds, rel_mse, est_rel_error) lists, from a convergence CSV."""
    curves = {}
    with open(path) as f:
        for row in csv.DictReader(f):
            c = curves.setdefault(row["choice"], ([], [], [], []))
            for lst, key in zip(c, ("spp", "seconds", "rel_mse", "est_rel_error")):
                lst.append(float(row[key]))
    return curves


def efficiency(seconds, rel_mse):
    """As volcl.converge.Curve.efficiency: 1 / median(relMSE x t) over the last three points."""
    prods = sorted(m * t for m, t in zip(rel_mse[-3:], seconds[-3:]) if m > 0 and t > 0)
    return 1.0 / prods[len(prods) // 2] if prods else math.inf


def repeated(scene_path, defines, choices, reference, width, height, seeds, budget):
    """choice -> efficiencies 1 / (relative MSE x CPU s), one per seed, each run rendering passes
    until `budget` CPU seconds are spent. Runs are interleaved (seed by seed, choice by choice) so
    that load from other users falls on all choices alike."""
    sys.path.insert(0, str(ROOT))
    from volcl.accuracy import relative_mse
    from volcl.converge import load_reference
    from volcl.estimator import CHOICES
    from volcl.renderer import Renderer
    from volcl.scene import load
    sc = load(ROOT / scene_path, defines)
    sc.camera.width, sc.camera.height = width, height
    ref, ref_var = load_reference(reference, width, height)
    out = {c: [] for c in choices}
    for seed in range(100, 100 + seeds):
        for c in choices:
            r = Renderer(sc, seed=seed, estimator=CHOICES[c])
            r.render(1)         # one-time driver costs stay out of the budget
            r.reset()
            spent = 0.0
            while spent < budget:
                t0 = time.process_time()
                r.render(r.slots)
                spent += time.process_time() - t0
            res = r.result()
            out[c].append(1.0 / (max(relative_mse(res.image, ref, ref_var), 1e-30) * spent))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max-seconds", type=float, default=15.0, help="CPU seconds per estimator choice")
    ap.add_argument("--reference-seconds", type=float, default=90.0, help="wall seconds per reference")
    ap.add_argument("--width", type=int, default=48)
    ap.add_argument("--height", type=int, default=36)
    ap.add_argument("--seeds", type=int, default=5, help="independent runs per choice for the defaults table")
    ap.add_argument("--budget", type=float, default=3.0, help="CPU seconds per run of the defaults table")
    ap.add_argument("--only", nargs="*", help="configuration names to run (default: all)")
    args = ap.parse_args()

    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    images = ROOT / "docs" / "images"
    images.mkdir(parents=True, exist_ok=True)
    sections, summary = [], []
    for name, scene, extra, what in CONFIGS:
        if args.only and name not in args.only:
            continue
        out = OUT / name
        extra = [a.replace("{2x}", str(2 * args.max_seconds)) for a in extra]
        cmd = [sys.executable, "-m", "volcl", "converge", scene, "--name", name, "--out", str(out),
               "--width", str(args.width), "--height", str(args.height),
               "--max-seconds", str(args.max_seconds), "--reference-seconds", str(args.reference_seconds), *extra]
        print("$ volcl " + " ".join(cmd[3:]), file=sys.stderr)
        subprocess.run(cmd, cwd=ROOT, env=env, check=True, stdout=subprocess.DEVNULL)
        shutil.copy(out / f"{name}_convergence.png", images / f"convergence_{name}.png")
        table = (out / f"{name}_convergence.md").read_text()
        shown = " ".join(extra + ["--width", str(args.width), "--height", str(args.height)])
        sections.append(f"#### {name}: {what}\n\n`volcl converge {scene} {shown}`\n\n"
                        f"![{name}](docs/images/convergence_{name}.png)\n\n{table}")
        curves = read_curves(out / f"{name}_convergence.csv")
        defines = dict(extra[i + 1].split("=", 1) for i, a in enumerate(extra) if a == "-D")
        print(f"  {args.seeds} seeds x {len(curves)} choices x {args.budget:g} CPU s", file=sys.stderr)
        effs = repeated(scene, defines, list(curves), out / f"{name}_reference.exr", args.width, args.height,
                        args.seeds, args.budget)
        base = float(np.median(effs["mis"]))
        for choice, (spp, sec, mse, est) in curves.items():
            # the render's own error estimate against the measured one, once 16 spp are in
            ratios = [e / math.sqrt(m) for s, m, e in zip(spp, mse, est) if s >= 16 and m > 0]
            calib = math.exp(sum(map(math.log, ratios)) / len(ratios)) if ratios else float("nan")
            e = effs[choice]
            summary.append(f"| {name} | `{choice}` | {np.median(e):.3g} | {min(e):.3g} to {max(e):.3g} "
                           f"| {np.median(e) / base:.2f} | {calib:.2f} |")

    head = [f"Measured by `python benchmarks/convergence_report.py` at {args.width}x{args.height} on this "
            "project's machine (2 shared cores, PoCL). Efficiency is 1 / (relative MSE x CPU seconds) of a run "
            f"given {args.budget:g} CPU s, over {args.seeds} independent seeds: the median, the range, and the "
            "median divided by that of `mis` (distance sampling, NEE and MIS, no equiangular sampling). "
            "'estimate / measured' is the geometric mean, over the `volcl converge` measurements from 16 spp on, "
            "of the render's own relative error estimate divided by the relative RMSE against the reference.", "",
            "| configuration | estimator | efficiency (median) | range | vs mis | estimate / measured |",
            "|---|---|---|---|---|---|", *summary, "",
            f"Convergence runs: {args.max_seconds:g} CPU s per estimator choice, references rendered for "
            f"{args.reference_seconds:g} s (wall) with the default estimator.", ""]
    if not args.only or "point_in_fog" in args.only:
        # the scene itself, for README: to 3% estimated relative error or two minutes
        cmd = [sys.executable, "-m", "volcl", "render", "scenes/point_in_fog.xml", "-o",
               str(images / "point_in_fog.png"), "--width", "240", "--height", "180", "--target-error", "0.03",
               "--time-limit", "120", "-q"]
        print("$ volcl " + " ".join(cmd[3:]), file=sys.stderr)
        subprocess.run(cmd, cwd=ROOT, env=env, check=True)
    doc = ROOT / "docs" / "convergence.md"
    doc.write_text("\n".join(head) + "\n" + "\n".join(sections))
    print(f"wrote {doc} and docs/images/convergence_*.png", file=sys.stderr)


if __name__ == "__main__":
    main()
