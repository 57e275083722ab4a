"""`volcl converge`: what accuracy costs in time, per estimator choice.

Each choice that applies to the scene (volcl.estimator.applicable_choices) renders progressively,
doubling its samples per pixel; after each doubling the image is compared with a reference (relative
RMSE, volcl.accuracy). The choices take turns, level by level, so that all of them run under the
same load on a shared machine; each stops once its render time passes the budget. Render time
excludes kernel builds and image read-backs, and is process CPU time by default (CLOCKS).

Outputs, named after the scene in the output folder: <stem>_convergence.csv (every measurement),
<stem>_convergence.png (log-log plot of error against seconds) and <stem>_convergence.md (time to
10%, 3% and 1% relative RMSE, and efficiency), plus <stem>_reference.exr when the reference was
rendered here.
"""
from __future__ import annotations

import csv
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .accuracy import relative_mse, time_to_error
from .errors import VolclError
from .estimator import CHOICES, Estimator, applicable_choices
from .prepared import Scene as PreparedScene
from .renderer import Renderer
from .scene.model import Scene

TARGETS = (0.10, 0.03, 0.01)


@dataclass
class Curve:
    choice: str
    estimator: Estimator
    spp: list = field(default_factory=list)
    seconds: list = field(default_factory=list)
    rel_mse: list = field(default_factory=list)         # against the reference, its noise taken out
    est_rel_error: list = field(default_factory=list)   # the render's own estimate
    samples_per_second: float = 0.0
    build_seconds: float = 0.0

    @property
    def rel_rmse(self) -> list:
        return [math.sqrt(max(m, 0.0)) for m in self.rel_mse]

    def time_to(self, target: float) -> float | None:
        return time_to_error(self.seconds, self.rel_rmse, target)

    def efficiency(self) -> float:
        """1 / (relative MSE x seconds), the median over the last three measurements (where an
        unbiased estimator's product has settled to a constant)."""
        prods = [m * t for m, t in zip(self.rel_mse[-3:], self.seconds[-3:]) if t > 0]
        prods = [p for p in prods if p > 0]
        return 1.0 / float(np.median(prods)) if prods else math.inf


@dataclass
class Report:
    scene: str
    width: int
    height: int
    reference: str
    reference_rel_error: float
    curves: list
    clock: str = "cpu"
    csv_path: Path | None = None
    plot_path: Path | None = None
    table_path: Path | None = None

    def curve(self, choice: str) -> Curve:
        return next(c for c in self.curves if c.choice == choice)


def _fmt_time(t, unit="s"):
    if t is None:
        return "not reached"
    return f"{t:.3g} {unit}"


def markdown_table(report: Report) -> str:
    unit = "CPU s" if report.clock == "cpu" else "s"
    lines = [f"**{report.scene}** at {report.width}x{report.height}; reference: {report.reference} "
             f"(its own relative error {100 * report.reference_rel_error:.2f}%); times in "
             f"{'process CPU seconds' if report.clock == 'cpu' else 'wall-clock seconds'}.", "",
             f"| estimator | time to 10% | time to 3% | time to 1% | efficiency 1/(relMSE x {unit}) | samples/{unit} |",
             "|---|---|---|---|---|---|"]
    for c in report.curves:
        times = " | ".join(_fmt_time(c.time_to(e), unit) for e in TARGETS)
        lines.append(f"| `{c.choice}` ({c.estimator.describe()}) | {times} | {c.efficiency():.3g} | "
                     f"{c.samples_per_second / 1e6:.2f} M |")
    return "\n".join(lines) + "\n"


def write_csv(report: Report, path: Path):
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["scene", "choice", "spp", "seconds", "clock", "rel_rmse", "rel_mse", "est_rel_error"])
        for c in report.curves:
            for row in zip(c.spp, c.seconds, c.rel_rmse, c.rel_mse, c.est_rel_error):
                w.writerow([report.scene, c.choice, row[0], f"{row[1]:.6g}", report.clock, f"{row[2]:.6g}",
                            f"{row[3]:.6g}", f"{row[4]:.6g}"])


def plot(report: Report, path: Path):
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise VolclError("volcl converge plots with matplotlib, a dependency of volcl that is missing "
                         "here: pip install matplotlib") from None
    fig, ax = plt.subplots(figsize=(6.4, 4.4), dpi=100)
    for c in report.curves:
        ok = [(t, e) for t, e in zip(c.seconds, c.rel_rmse) if t > 0 and e > 0]
        if ok:
            ax.loglog(*zip(*ok), marker="o", markersize=3, label=c.choice)
    for e in TARGETS:
        ax.axhline(e, color="0.6", linestyle=":", linewidth=0.8)
    # a guide of slope -1/2: the rate every unbiased estimator converges at
    ts = [t for c in report.curves for t in c.seconds if t > 0]
    es = [e for c in report.curves for e in c.rel_rmse if e > 0]
    if ts and es:
        t0, t1 = min(ts), max(ts)
        e0 = max(es)
        ax.loglog([t0, t1], [e0, e0 * math.sqrt(t0 / t1)], color="0.75", linestyle="--", linewidth=0.8,
                  label="slope -1/2")
    ax.set_xlabel("render time (process CPU s)" if report.clock == "cpu" else "render time (wall-clock s)")
    ax.set_ylabel("relative RMSE")
    ax.set_title(f"{report.scene} ({report.width}x{report.height})")
    ax.grid(True, which="both", color="0.92", linewidth=0.5)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def load_reference(path, width: int, height: int):
    from .image import read_image
    pixels, _ = read_image(path)
    if pixels.shape[:2] != (height, width):
        raise VolclError(f"reference {path} is {pixels.shape[1]}x{pixels.shape[0]}, the scene renders "
                         f"{width}x{height}; pass --width/--height to match it")
    variance = pixels[..., 3:6] if pixels.shape[2] >= 6 else None
    return pixels[..., :3], variance


def _advance(bar, seconds: float):
    """Move the progress bar on by `seconds` of render time, never past its total (a render's last
    pass may overrun its budget)."""
    bar.update(max(0.0, min(round(seconds, 1), bar.total - bar.n)))


# Clocks a render's cost can be measured with. 'cpu' is the process's CPU time, every OpenCL
# worker thread of the CPU device included: on a machine shared with other work it measures what
# the estimator costs, while wall time also measures the others' load. 'wall' is elapsed time (the
# right measure on a dedicated machine, and for GPU devices, whose work is not process CPU time).
CLOCKS = {"cpu": time.process_time, "wall": time.perf_counter}


def converge(scene: Scene | PreparedScene, name: str = "scene", reference=None, out=None, max_seconds: float = 20.0,
             reference_seconds: float | None = None, choices=None, seed: int = 1, device=None,
             features=None, quiet: bool = False, clock: str = "cpu") -> Report:
    """Measure error against time for each estimator choice; see the module docstring. `reference`:
    a path to an EXR of the same size (its variance layer, when present, is used to take its noise
    out of the error), or None to render one here with the default estimator for
    `reference_seconds` (default 4 x max_seconds) of wall time. Costs are measured on `clock`."""
    if clock not in CLOCKS:
        raise VolclError(f"clock {clock!r}: expected one of {', '.join(CLOCKS)}")
    from tqdm import tqdm

    from . import device as devmod
    from .image import write_image

    device = devmod.resolve(device)
    prepared = scene if isinstance(scene, PreparedScene) else PreparedScene(scene)
    scene = prepared.model
    names = list(choices) if choices else applicable_choices(scene)
    unknown = [c for c in names if c not in CHOICES]
    if unknown:
        raise VolclError(f"unknown estimator choice {unknown[0]!r}; choices: {', '.join(CHOICES)}")
    w, h = scene.camera.width, scene.camera.height
    out = Path(out) if out is not None else None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    ref_seconds = reference_seconds if reference_seconds is not None else 4 * max_seconds
    total = max_seconds * len(names) + (0 if reference is not None else ref_seconds)
    bar = tqdm(total=round(total, 1), desc=name, unit="s", disable=quiet, leave=False, file=sys.stderr,
               bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.0f}/{total:.0f} s render time {postfix}")

    if reference is not None:
        ref_image, ref_var = load_reference(reference, w, h)
        ref_label = str(reference)
    else:
        bar.set_postfix_str("reference")
        r = Renderer(prepared, device=device, features=features, seed=seed + 1000)
        res = r.render(time_limit=ref_seconds, progress=None)
        _advance(bar, res.seconds)
        ref_image, ref_var = res.image, res.variance
        ref_label = f"volcl, default estimator, {res.spp} spp in {res.seconds:.0f} s"
        if out is not None:
            write_image(out / f"{name}_reference.exr", res.image,
                        {"spp": res.spp, "seed": seed + 1000, "render_seconds": round(res.seconds, 3)},
                        {"variance": res.variance})
    ref_rel = math.sqrt(max(float(np.mean(ref_var)), 0.0)) / float(np.mean(ref_image)) \
        if ref_var is not None and float(np.mean(ref_image)) > 0 else float("nan")

    renderers, curves = {}, []
    for i, c in enumerate(names):
        r = Renderer(prepared, device=device, features=features, seed=seed + i, estimator=CHOICES[c])
        r.render(1)     # the first launch pays one-time driver costs; keep them out of the timings
        r.reset()
        renderers[c] = r
        curves.append(Curve(c, CHOICES[c], build_seconds=r.build_seconds))

    now = CLOCKS[clock]
    active = list(curves)
    spp = 1
    while active:
        for curve in list(active):
            r = renderers[curve.choice]
            spent = curve.seconds[-1] if curve.seconds else 0.0
            add = spp - r.samples_done
            if spent > 0:
                # the last level gets only what the budget has left, at the rate measured so far
                add = max(1, min(add, int((max_seconds - spent) * r.samples_done / spent)))
            bar.set_postfix_str(f"{curve.choice} {r.samples_done + add} spp")
            t0 = now()
            res = r.render(add)
            spent += now() - t0
            _advance(bar, min(spent, max_seconds) - min(curve.seconds[-1] if curve.seconds else 0.0, max_seconds))
            curve.spp.append(res.spp)
            curve.seconds.append(spent)
            curve.rel_mse.append(relative_mse(res.image, ref_image, ref_var))
            curve.est_rel_error.append(res.rel_error)
            curve.samples_per_second = w * h * res.spp / spent
            if spent >= 0.98 * max_seconds or r.samples_done < spp:
                active.remove(curve)
        spp *= 2
    bar.close()

    report = Report(name, w, h, ref_label, ref_rel, curves, clock=clock)
    if out is not None:
        report.csv_path = out / f"{name}_convergence.csv"
        report.plot_path = out / f"{name}_convergence.png"
        report.table_path = out / f"{name}_convergence.md"
        write_csv(report, report.csv_path)
        plot(report, report.plot_path)
        report.table_path.write_text(markdown_table(report))
    return report
