"""A parameter sweep from Python: editing a loaded scene with traverse() + update() against
reloading the scene file at every step.

    python benchmarks/param_sweep.py [--scene scenes/fog.xml] [--key fog.sigma_t.value]
        [--values 0.05:0.5] [--steps 50] [--width 64] [--height 64] [--spp 16] [--device SEL]

Each of --steps steps sets --key to the next of --steps values spaced evenly over --values and
renders --spp samples per pixel with seed = step. Three ways of doing that, interleaved step by step
(so that load from other processes on a shared machine falls on all three alike):

  update    the scene is loaded once; each step sets the value, calls params.update() (which
            repacks the media records and uploads the arrays that changed) and renders.
  reload    each step writes the value into the scene file's text and loads it again
            (volcl.load_string with the file's folder: parsing, meshes, BVH, packing), then renders:
            the scene is uploaded anew, the device and its built programs are reused.
  reload, new device
            as `reload`, on a fresh volcl.Device each step (a new OpenCL context, the program built
            again from the drivers' disk caches): what every render cost before volcl kept one
            context and program cache per device.
  command line
            what a sweep without the Python API does: the value written into a copy of the file and
            `volcl render` run on it, one process per step (Python start-up and imports, the device
            check, loading, building, rendering, writing the EXR). --no-cli leaves it out.

The update and reload images are checked to be bit-identical at every step. Printed: seconds per
step (mean over the steps, and its parts: setting up the scene, rendering) and the ratios.
"""
from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))
from common import cpu_model, log  # noqa: E402



def value_text(v: float) -> str:
    return repr(float(v))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scene", default=str(ROOT / "scenes" / "fog.xml"))
    p.add_argument("--key", default="fog.sigma_t.value")
    p.add_argument("--values", default="0.05:0.5", help="LOW:HIGH (default 0.05:0.5)")
    p.add_argument("--steps", type=int, default=50)
    p.add_argument("--width", type=int, default=64)
    p.add_argument("--height", type=int, default=64)
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--device")
    p.add_argument("--no-cli", action="store_true", help="leave out the command-line variant")
    args = p.parse_args(argv)

    import volcl
    from volcl import device as devmod

    path = Path(args.scene)
    xml = path.read_text()
    low, high = (float(x) for x in args.values.split(":"))
    values = np.linspace(low, high, args.steps)
    dev = devmod.choose(args.device)
    size = dict(width=args.width, height=args.height, spp=args.spp)
    obj, name = args.key.split(".", 1)
    param = name.split(".")[0]

    # the file with its value replaced: the parameter of the object with that id (a homogeneous
    # medium's <rgb name="sigma_t" .../> inside <medium ... id="fog">)
    block = re.search(rf'<(\w+)[^>]*id="{re.escape(obj)}".*?</\1>', xml, re.S)
    prop = re.compile(rf'(<\w+ name="{re.escape(param)}" value=")[^"]*(")')
    if block is None or not prop.search(block.group(0)):
        raise SystemExit(f"{path}: no object id={obj!r} with a parameter {param!r} to rewrite")

    def with_value(v):
        inner = prop.sub(lambda m: m.group(1) + value_text(v) + m.group(2), block.group(0), count=1)
        return xml[:block.start()] + inner + xml[block.end():]

    # warm-up: the program built, PoCL's first-launch compilation done, for every variant
    scene = volcl.load_string(with_value(values[0]), base_dir=path.parent, **size)
    volcl.render(scene, spp=1, device=dev)
    params = volcl.traverse(scene)
    volcl.render(scene, spp=1, device=dev.fresh())

    import os
    import subprocess
    import tempfile
    work = Path(tempfile.mkdtemp(prefix="volcl-sweep-"))
    for entry in path.parent.iterdir():         # the copy finds the file's meshes and volumes
        if entry.is_dir():
            (work / entry.name).symlink_to(entry)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    cli = [sys.executable, "-m", "volcl", "render", "-q", "--checkpoint-every", "0", "-D", f"width={args.width}",
           "-D", f"height={args.height}", "--spp", str(args.spp)] + (["--device", dev.key])

    names = ("update", "reload", "reload, new device") + (() if args.no_cli else ("command line",))
    setup = {n: [] for n in names}
    render = {n: [] for n in names}
    for step, v in enumerate(values):
        t0 = time.perf_counter()
        params[args.key] = float(v)
        params.update()
        t1 = time.perf_counter()
        a = volcl.render(scene, seed=step, device=dev)
        t2 = time.perf_counter()
        setup["update"].append(t1 - t0)
        render["update"].append(t2 - t1)

        t0 = time.perf_counter()
        again = volcl.load_string(with_value(v), base_dir=path.parent, **size)
        t1 = time.perf_counter()
        b = volcl.render(again, seed=step, device=dev)
        t2 = time.perf_counter()
        setup["reload"].append(t1 - t0)
        render["reload"].append(t2 - t1)
        if a.image.tobytes() != b.image.tobytes() or a.variance.tobytes() != b.variance.tobytes():
            raise SystemExit(f"step {step}: the updated scene and the reloaded one render different images")

        t0 = time.perf_counter()
        again = volcl.load_string(with_value(v), base_dir=path.parent, **size)
        fresh = dev.fresh()
        t1 = time.perf_counter()
        volcl.render(again, seed=step, device=fresh)
        t2 = time.perf_counter()
        setup["reload, new device"].append(t1 - t0)
        render["reload, new device"].append(t2 - t1)
        del fresh, again

        if not args.no_cli:
            t0 = time.perf_counter()
            copy = work / f"step{step}.xml"
            copy.write_text(with_value(v))
            t1 = time.perf_counter()
            run = subprocess.run(cli + [str(copy), "-o", str(work / f"step{step}.exr"), "--seed", str(step)],
                                 env=env, capture_output=True, text=True)
            t2 = time.perf_counter()
            if run.returncode != 0:
                raise SystemExit(f"volcl render failed: {run.stderr}")
            setup["command line"].append(t1 - t0)
            render["command line"].append(t2 - t1)
        if step % 10 == 9:
            log(f"step {step + 1}/{args.steps}")

    mean = {n: float(np.mean(np.add(setup[n], render[n]))) for n in names}
    print(f"# Parameter sweep: {args.steps} steps of {args.key} over {low:g}..{high:g}, {path.name} at "
          f"{args.width}x{args.height}, {args.spp} spp\n")
    print(f"device {dev.label}; CPU {cpu_model()}; `python benchmarks/param_sweep.py`; the variants "
          f"interleaved step by step; update and reload images bit-identical at every step\n")
    print("| variant | seconds per step | of which: scene set-up | of which: render (upload, build, passes) "
          "| step time / update's |")
    print("|---|---:|---:|---:|---:|")
    for n in names:
        print(f"| {n} | {mean[n]:.4f} | {np.mean(setup[n]):.4f} | {np.mean(render[n]):.4f} | "
              f"{mean[n] / mean['update']:.2f}x |")
    base = float(np.mean(render["update"]))
    print("\nTime per step beyond the update variant's render: "
          + ", ".join(f"{n} {1e3 * (mean[n] - base):.1f} ms" for n in names) + ".")


if __name__ == "__main__":
    main()
