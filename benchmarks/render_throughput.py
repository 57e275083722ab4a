"""Render throughput of volcl against Mitsuba 3, volcl's kernel build time, and its scene memory.

    python benchmarks/render_throughput.py [--scene scenes/cbox.xml] [--spp 256] [--repeat 3]
        [--max-depth 1 2 -1] [--mitsuba-python PATH] [--variant llvm_ad_rgb]
        [--mesh-triangles 1000000] [-D name=value ...]

Prints, in Markdown:

* the machine: CPU model, cores, the OpenCL device volcl renders on, the Mitsuba found.
* Throughput: the scene (default scenes/cbox.xml, 256x256) rendered at --spp samples per pixel by
  volcl (kernel specialized to the scene's features, the default) and by Mitsuba 3 (--variant,
  default llvm_ad_rgb, the same file and spp), once per --max-depth value (passed as the scene
  parameter `max_depth`: 1 = emitters seen directly, 2 = direct lighting, -1 = unlimited paths).
  "seconds" is the best of --repeat warm renders: volcl after a 1-spp warm-up pass on the same
  Renderer (so neither kernel build nor PoCL's first-launch compilation counts), Mitsuba after one
  untimed render (Dr.Jit traces and compiles on the first) with the clock stopped after
  dr.eval + dr.sync_thread. "M samples/s" is width * height * spp / seconds / 1e6 (camera samples,
  whatever the path length). "volcl/Mitsuba" is volcl's samples/s over Mitsuba's at the same
  max_depth: above 1 volcl is faster. Both use every core of the machine.
* Kernel build: seconds for clBuildProgram of the render program (Renderer.build_seconds) and the
  extra time of the first 1-spp pass over a second one (PoCL compiles the work-group function
  lazily at the first launch), each in a fresh Python process: "cold" with empty pyopencl/PoCL
  kernel caches (a new POCL_CACHE_DIR, PYOPENCL_NO_CACHE=1), "warm" in a new process reusing the
  cache the cold run just filled. Rows for the specialized kernel and for the all-features kernel
  (--features all), both on a device taken without volcl.device.choose()'s check, and for what
  `volcl render` pays: choose() first builds the all-features kernel to check the device
  ("device check s"), then the Renderer builds the specialized one. "total" runs from the device
  lookup to the first 1-spp image (Python and volcl import time excluded). "in-process" is a
  second Renderer (new OpenCL context) in this process.
* Device memory: bytes of the scene buffers a Renderer uploads (Renderer.packed.arrays: BVH
  nodes, primitive ids, triangles, normals, spheres, shapes, bsdfs, lights, media, parameters,
  filter table; not the per-pixel accumulation buffers) divided by the triangle count, for the
  scene and for a synthetic mesh of --mesh-triangles triangles (a finely tessellated bumpy
  sphere on a floor, lit by a quad, built in memory). For a 12-triangle Cornell box the fixed
  parts dominate; the big mesh shows the per-triangle cost itself.

Progress goes to stderr; the tables to stdout.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))
import mitsuba_ref  # noqa: E402
from common import bumpy_sphere, cpu_model, parse_defines  # noqa: E402


def log(msg):
    print(msg, file=sys.stderr, flush=True)



def cores():
    total = os.cpu_count() or 0
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:
        usable = total
    return f"{usable}" if usable == total else f"{usable} usable of {total}"


def load_average():
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "unknown"


def table(header, rows):
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(out)



# ------------------------------------------------------------------------------------ volcl

def load_scene(path, defines):
    from volcl.scene import load
    from volcl.scene.model import Scene
    scene = load(path, defines)
    if not isinstance(scene, Scene):
        raise SystemExit(f"{path} is not a scene")
    return scene


def volcl_throughput(path, defines, spp, repeat, seed, device):
    """(best seconds, width, height, invalid samples) of `repeat` warm renders."""
    from volcl.render import Renderer
    scene = load_scene(path, defines)
    r = Renderer(scene, device=device, seed=seed)
    r.render(1)             # first launch: PoCL compiles the work-group function here
    best, invalid = float("inf"), 0
    for _ in range(repeat):
        r.reset()
        res = r.render(spp)
        best = min(best, res.seconds)
        invalid = max(invalid, res.invalid)
    return best, r.width, r.height, invalid


BUILD_PROBE = r"""
import json, sys, time
sys.path.insert(0, {root!r})
t0 = time.perf_counter()
from volcl import device as devmod
from volcl.scene import load
from volcl.render import Renderer
from volcl.features import all_features
scene = load({scene!r}, {defines!r})
t1 = time.perf_counter()
if {mode!r} == "cli":
    dev = devmod.choose({key!r})        # what `volcl render` does: checks the device by building every feature
else:
    dev = [d for d in devmod.list_devices() if d.key == {key!r}][0]     # no check build
t2 = time.perf_counter()
r = Renderer(scene, device=dev, features=all_features() if {mode!r} == "all" else None)
t3 = time.perf_counter()
first = r.render(1).seconds
second = r.render(1).seconds - first
print("BUILD_PROBE " + json.dumps({{"choose": t2 - t1, "build": r.build_seconds, "renderer": t3 - t2,
                                    "first": first, "second": second}}))
"""


def build_probe(path, defines, key, cache_dir, cold, mode):
    """Kernel build figures from a fresh process whose PoCL cache is `cache_dir`."""
    env = dict(os.environ, POCL_CACHE_DIR=cache_dir)
    if cold:
        env["PYOPENCL_NO_CACHE"] = "1"
    code = BUILD_PROBE.format(root=str(ROOT), scene=str(path), defines=defines, key=key, mode=mode)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("BUILD_PROBE ")]
    if proc.returncode != 0 or not lines:
        raise RuntimeError(f"build probe failed:\n{proc.stderr[-2000:]}")
    return json.loads(lines[-1][len("BUILD_PROBE "):])


def scene_bytes(renderer):
    arrays = renderer.packed.arrays
    return {name: int(np.asarray(arrays[name]).nbytes) for name in renderer.ARG_ORDER}


def synthetic_mesh_scene(n_triangles, seed=0):
    """A bumpy sphere of about n_triangles triangles on a floor quad, lit by a quad above."""
    from volcl.scene.model import Bsdf, Camera, Scene, Shape
    from volcl.scene.transform import lookat
    z_up, faces = bumpy_sphere(np.random.default_rng(seed), n_triangles)
    verts = z_up[:, [0, 2, 1]] + np.array([0.0, 1.0, 0.0])      # y up, resting on the floor
    quad = np.array([[0, 1, 2], [0, 2, 3]])
    floor = np.array([[-5, 0, -5], [5, 0, -5], [5, 0, 5], [-5, 0, 5]], float)
    light = np.array([[-1, 4, -1], [-1, 4, 1], [1, 4, 1], [1, 4, -1]], float)
    shapes = [
        Shape("mesh", Bsdf("diffuse"), vertices=verts, faces=faces.astype(np.int64)),
        Shape("mesh", Bsdf("diffuse"), vertices=floor, faces=quad),
        Shape("mesh", Bsdf("diffuse", reflectance=np.zeros(3)), vertices=light, faces=quad,
              emitter_radiance=np.full(3, 10.0)),
    ]
    cam = Camera(to_world=lookat([0, 2, -6], [0, 1, 0], [0, 1, 0]), fov=40, width=256, height=256)
    return Scene(path="<synthetic mesh>", dialect="mitsuba", camera=cam, spp=4, shapes=shapes)


def memory_row(label, renderer):
    sizes = scene_bytes(renderer)
    ntri = renderer.packed.triangle_count
    total = sum(sizes.values())
    per = lambda *names: f"{sum(sizes[n] for n in names) / max(ntri, 1):.1f}"   # noqa: E731
    return [label, f"{ntri:,}", renderer.packed.sphere_count, f"{total / 2**20:.2f}",
            f"{total / max(ntri, 1):.1f}", per("nodes", "leaves"), per("triangles", "normals"),
            f"{renderer.packed.bvh_seconds:.2f}"]


# ------------------------------------------------------------------------------------ main

def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scene", default=str(ROOT / "scenes" / "cbox.xml"))
    p.add_argument("--spp", type=int, default=256)
    p.add_argument("--repeat", type=int, default=3, help="timed renders per row; the best counts (default 3)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--max-depth", nargs="+", default=["1", "2", "-1"], metavar="D",
                   help="max_depth values, one pair of rows each (default 1 2 -1); 'scene' = as in the file")
    p.add_argument("--variant", default=mitsuba_ref.DEFAULT_VARIANT)
    p.add_argument("--device", help="volcl device selector (default: $VOLCL_DEVICE or the first that builds)")
    p.add_argument("--mesh-triangles", type=int, default=1_000_000,
                   help="triangles of the synthetic mesh for the memory table (0: skip)")
    p.add_argument("--skip-build", action="store_true", help="skip the kernel build measurements")
    p.add_argument("-D", "--define", action="append", metavar="NAME=VALUE",
                   help="scene parameter for both renderers")
    mitsuba_ref.add_argument(p)
    args = p.parse_args(argv)

    from volcl import __version__
    from volcl import device as devmod
    from volcl.render import Renderer
    defines = parse_defines(args.define)
    scene_path = Path(args.scene).resolve()
    device = devmod.choose(args.device)
    mts = mitsuba_ref.locate(args.mitsuba_python, args.variant, log=print)

    print(f"# volcl render throughput: {scene_path.name}\n")
    print(f"- CPU: {cpu_model()}, {cores()} cores ({platform.machine()}, {platform.system()})")
    print(f"- volcl {__version__} device: {device.key} {device.name} ({device.platform_name}, "
          f"{device.device.max_compute_units} compute units)")
    if mts:
        print(f"- Mitsuba {mts['version']} variant {args.variant} via {mts['python']}")
    else:
        print("- Mitsuba: not found, its columns are skipped")
    print(f"- scene {scene_path}, {args.spp} spp, best of {args.repeat}")
    print(f"- load average at start (1/5/15 min): {load_average()}; other processes on the machine skew timings\n")

    # throughput
    rows = []
    for d in args.max_depth:
        defs = dict(defines) if d == "scene" else dict(defines, max_depth=d)
        log(f"volcl max_depth={d} ...")
        secs, w, h, invalid = volcl_throughput(scene_path, defs, args.spp, args.repeat, args.seed, device)
        samples = w * h * args.spp
        v_rate = samples / secs
        m_rate = None
        m_cells = ["–", "–", "–"]
        if mts:
            log(f"Mitsuba {args.variant} max_depth={d} ...")
            try:
                res = mitsuba_ref.render_mitsuba(str(scene_path), None, mts["python"], args.variant, args.spp,
                                                 args.seed, defs, args.repeat, details=True)
                m_rate = res["width"] * res["height"] * args.spp / res["seconds"]
                m_cells = [f"{res['seconds']:.3f}", f"{m_rate / 1e6:.2f}", "1.00"]
            except mitsuba_ref.MitsubaError as exc:
                log(str(exc))
                m_cells = ["failed", "–", "–"]
        ratio = f"{v_rate / m_rate:.2f}" if m_rate else "–"
        note = f" ({invalid} invalid)" if invalid else ""
        rows.append([d, "volcl", args.spp, f"{secs:.3f}", f"{v_rate / 1e6:.2f}{note}", ratio])
        if mts:
            rows.append([d, f"Mitsuba {args.variant}", args.spp] + m_cells)
    print(f"## Throughput ({w}x{h}, {args.spp} spp)\n")
    print(table(["max_depth", "renderer", "spp", "seconds", "M samples/s", "volcl/Mitsuba"], rows))
    print()

    # kernel build
    if not args.skip_build:
        brows = []
        kinds = (("specialized", "specialized"), ("all features", "all"),
                 ("specialized, as `volcl render` (device check + render kernel)", "cli"))
        for label, mode in kinds:
            with tempfile.TemporaryDirectory(prefix="volcl-bench-pocl-") as cache:
                for state, cold in (("cold", True), ("warm", False)):
                    log(f"kernel build: {label}, {state} ...")
                    try:
                        b = build_probe(scene_path, defines, device.key, cache, cold, mode)
                    except RuntimeError as exc:
                        log(str(exc))
                        brows.append([label, f"{state} (fresh process)", "failed", "", "", ""])
                        continue
                    extra = max(0.0, b["first"] - b["second"])
                    brows.append([label, f"{state} (fresh process)",
                                  f"{b['choose']:.2f}" if mode == "cli" else "–", f"{b['build']:.2f}",
                                  f"{extra:.2f}", f"{b['choose'] + b['renderer'] + b['first']:.2f}"])
        scene = load_scene(scene_path, defines)
        Renderer(scene, device=device)
        t0 = time.perf_counter()
        r2 = Renderer(scene, device=device)
        t1 = time.perf_counter()
        first = r2.render(1).seconds
        second = r2.render(1).seconds - first
        brows.append(["specialized", "in-process (2nd Renderer, new context)", "–", f"{r2.build_seconds:.2f}",
                      f"{max(0.0, first - second):.2f}", f"{t1 - t0 + first:.2f}"])
        print("## Kernel build (volcl)\n")
        print(table(["kernel", "caches", "device check s", "clBuildProgram s", "first-launch extra s",
                     "total to first 1-spp image s"], brows))
        print()

    # memory
    mrows = []
    log("memory: scene ...")
    scene = load_scene(scene_path, defines)
    mrows.append(memory_row(scene_path.name, Renderer(scene, device=device)))
    if args.mesh_triangles > 0:
        log(f"memory: {args.mesh_triangles:,}-triangle mesh (BVH build) ...")
        mesh = synthetic_mesh_scene(args.mesh_triangles)
        mrows.append(memory_row(f"synthetic mesh ({args.mesh_triangles:,} requested)", Renderer(mesh, device=device)))
    print("## Device memory of the scene buffers (volcl)\n")
    print(table(["scene", "triangles", "spheres", "total MiB", "bytes/triangle",
                 "BVH (nodes + leaf packets) bytes/tri", "triangles + normals bytes/tri", "BVH build s"], mrows))
    print(f"\nload average at end: {load_average()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
