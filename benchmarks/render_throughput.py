"""Render throughput of volcl against Mitsuba 3 on every shipped scene, volcl's kernel build time,
and its scene memory.

    python benchmarks/render_throughput.py [--scenes scenes/*.xml] [--size 128x128] [--spp 128]
        [--rounds 2] [--max-depth D] [--mitsuba-python PATH] [--variant llvm_ad_rgb]
        [--skip-build] [--mesh-triangles 1000000] [--noise] [-D name=value ...]

Prints, in Markdown:

* the machine: CPU model, cores, the OpenCL device volcl renders on, the Mitsuba found, the load.
* Throughput: each scene at --size and --spp (the scene parameters width, height and spp; Nori
  files, which Mitsuba cannot read, get volcl's figures alone), seed 0, measured two ways:
  - whole process: `volcl render SCENE -o OUT.exr` and Mitsuba's own command line
    (`mitsuba -m VARIANT -o OUT.exr SCENE`, next to --mitsuba-python) from start to exit: what a
    user waits for, Python start-up, scene loading, kernel builds (from warm on-disk caches: one
    untimed run of each first; volcl's process gets Python's bytecode cache as a user's shell
    does, PYTHONDONTWRITEBYTECODE unset) and the image file included;
  - render alone: volcl's Renderer.render after a 1-spp warm-up pass on the same Renderer (so
    neither kernel build nor PoCL's first-launch compilation counts); Mitsuba's mi.render after
    one untimed render (Dr.Jit traces and compiles on the first), the clock stopped after
    dr.eval + dr.sync_thread (benchmarks/mitsuba_ref.py).
  Each figure is the best of --rounds, the four measurements of a scene interleaved in every
  round so that load from other processes falls on both renderers alike. Seconds are wall time;
  "CPU s" is the process's CPU time over all its threads (both renderers use every core), which
  load from other processes on the machine disturbs less. "volcl/Mitsuba" is Mitsuba's time over
  volcl's: above 1 volcl is faster.
* With --noise, time to equal error: the render-alone CPU seconds each renderer needs for a 1%
  relative RMS error (relative_noise: from the difference of the render-alone image and a second
  render at seed + 1), per pixel and over 4x4-pixel blocks; for volcl with its default estimator
  and, where that samples equiangularly, with equiangular sampling off. A default estimator that
  does more per sample is judged here, not by samples/s.
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
import resource
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
from common import bumpy_sphere, cpu_model, log, parse_defines  # noqa: E402




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


def cpu_seconds(who=resource.RUSAGE_SELF):
    r = resource.getrusage(who)
    return r.ru_utime + r.ru_stime


def volcl_renderer(path, defines, size, seed, device):
    """A Renderer for the scene at size (width, height), warmed up by a 1-spp pass (PoCL compiles
    the work-group function at the first launch)."""
    from volcl.renderer import Renderer
    scene = load_scene(path, defines)
    scene.camera.width, scene.camera.height = size
    r = Renderer(scene, device=device, seed=seed)
    r.render(1)
    return r


def volcl_render_alone(r, spp, images=None):
    """(wall seconds, CPU seconds, invalid samples) of one render of spp samples per pixel; the
    image goes to images[r.seed] when given."""
    r.reset()
    c0 = cpu_seconds()
    res = r.render(spp)
    if images is not None:
        images[r.seed] = res.image
    return res.seconds, cpu_seconds() - c0, res.invalid


def block_means(img, block):
    """The image's RGB in float64, averaged over block x block squares (rows and columns past the
    last whole square dropped); block 1 leaves it as it is."""
    x = np.asarray(img, np.float64)[..., :3]
    if block <= 1:
        return x
    h, w = (x.shape[0] // block) * block, (x.shape[1] // block) * block
    return x[:h, :w].reshape(h // block, block, w // block, block, 3).mean((1, 3))


def relative_noise(a, b, block=1):
    """Relative mean squared error of one render from two renders with independent seeds: the
    mean over pixels and channels of (a - b)^2 / 2 (each image's variance about its expectation),
    over the image's squared mean; with block > 1, of the images' means over block x block
    squares. Bias is not in it: both renderers agree with their references
    (tests/test_mitsuba_agreement.py); what this compares is how much noise a second of each buys.
    Per pixel, a renderer that splats each sample into several pixels through the filter (Mitsuba)
    shows less variance than one that samples the filter (volcl: each sample lands in one pixel)
    for the same information; over blocks a few filter radii wide the difference shrinks, but at
    4x4 blocks it is still 1.25-1.44x for Mitsuba's Gaussian (benchmarks/noise_per_sample.py)."""
    a, b = block_means(a, block), block_means(b, block)
    mean = 0.5 * (a.mean() + b.mean())
    return float(((a - b) ** 2).mean() / 2 / max(mean, 1e-30) ** 2)


NOISE_BLOCK = 4


def seconds_to_error(seconds, rel_mse, target=0.01):
    """Time a render needs for a relative RMS error of `target`: its time times rel_mse /
    target^2 (the mean squared error of an unbiased estimate falls as 1 / samples)."""
    return seconds * rel_mse / target ** 2


def whole_process(cmd, cwd, env=None):
    """(wall seconds, CPU seconds) of a command run to its end; raises on failure."""
    c0, t0 = cpu_seconds(resource.RUSAGE_CHILDREN), time.perf_counter()
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, env=env)
    wall, cpus = time.perf_counter() - t0, cpu_seconds(resource.RUSAGE_CHILDREN) - c0
    if proc.returncode != 0:
        raise RuntimeError(f"{cmd[0]} failed (exit {proc.returncode}):\n{proc.stderr[-2000:]}")
    return wall, cpus


def user_env():
    """The environment of a user's shell for `python -m volcl`: with bytecode caching on. A
    PYTHONDONTWRITEBYTECODE=1 here (some sandboxes and CI images set it) would have every run
    compile volcl's modules from source again, about 0.07 s, which an installed package never
    does (pip compiles it at install, as it did Mitsuba's Python files). The warm-up round writes
    the cache."""
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def volcl_command(path, defines, size, spp, out, device):
    cmd = [sys.executable, "-m", "volcl", "render", str(path), "-o", str(out), "--spp", str(spp), "--seed", "0",
           "--width", str(size[0]), "--height", str(size[1]), "-q"]
    if device:
        cmd += ["--device", device]
    for k, v in defines.items():
        cmd += ["-D", f"{k}={v}"]
    return cmd


def mitsuba_command(mts_python, variant, path, defines, size, spp, out):
    exe = Path(mts_python).parent / "mitsuba"
    cmd = [str(exe), "-m", variant, "-o", str(out), "-D", f"spp={spp}", "-D", f"width={size[0]}",
           "-D", f"height={size[1]}"]
    for k, v in defines.items():
        cmd += ["-D", f"{k}={v}"]
    return cmd + [str(path)]


def is_mitsuba_file(path):
    from volcl.scene.xml import parse_file
    root = parse_file(str(path))
    return root.tag == "scene" and "version" in root.attrs


BUILD_PROBE = r"""
import json, sys, time
sys.path.insert(0, {root!r})
t0 = time.perf_counter()
from volcl import device as devmod
from volcl.scene import load
from volcl.renderer import Renderer
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


def _measure(kind, path, defs, args, mts, device, renderers, tmp, warmup, images=None):
    """One measurement: (wall s, CPU s[, invalid samples]); the render-alone images, when `images`
    is given, go to images[(scene name, renderer)][seed]."""
    out = tmp / f"{path.stem}.{kind.split()[0]}.exr"
    size = tuple(int(x) for x in args.size.lower().split("x"))
    if kind == "volcl whole":
        return whole_process(volcl_command(path, defs, size, args.spp, out, args.device), ROOT, user_env())
    if kind == "Mitsuba whole":
        return whole_process(mitsuba_command(mts["python"], args.variant, path, defs, size, args.spp, out),
                             path.parent)
    if kind == "volcl render":
        if path not in renderers:
            renderers.clear()       # one scene's buffers on the device at a time
            renderers[path] = volcl_renderer(path, defs, size, args.seed, device)
        if warmup:
            return None
        return volcl_render_alone(renderers[path], args.spp,
                                  None if images is None else images.setdefault((path.name, "volcl"), {}))
    if warmup:
        return None
    out = tmp / f"{path.stem}.mitsuba_render.exr" if images is not None else None
    res = mitsuba_ref.render_mitsuba(str(path), str(out) if out else None, mts["python"], args.variant, args.spp,
                                     args.seed, dict(defs, width=str(size[0]), height=str(size[1])), 1, details=True)
    if out:
        images.setdefault((path.name, "Mitsuba"), {})[args.seed] = read_exr(out)
    return res["seconds"], res["cpu_seconds"]


def read_exr(path):
    from volcl.image import read_image
    return read_image(path)[0]


def noise_rows(scenes, defines, args, mts, device, best, images, tmp):
    """Time to 1% relative RMS error, from the render-alone images (seed args.seed) and one more
    render of each at seed args.seed + 1: volcl's default estimator, volcl with equiangular
    sampling off where the default uses it, and Mitsuba. Seconds are render-alone CPU seconds (the
    best of the rounds; the extra estimator's from its own single render)."""
    from volcl.estimator import Estimator
    from volcl.renderer import Renderer
    size = tuple(int(x) for x in args.size.lower().split("x"))
    rows = []
    for path in scenes:
        defs = dict(defines)
        cells = {}
        v = best.get((path.name, "volcl render"))
        imgs = images.get((path.name, "volcl"), {})
        if v and args.seed in imgs:
            log(f"noise: {path.name}: volcl, seed {args.seed + 1} ...")
            other = volcl_renderer(path, defs, size, args.seed + 1, device)
            volcl_render_alone(other, args.spp, imgs)
            cells["volcl"] = [seconds_to_error(v["cpu"], relative_noise(imgs[args.seed], imgs[args.seed + 1], blk))
                              for blk in (1, NOISE_BLOCK)]
            if other.estimator.uses_equiangular(other.scene, other.packed.features):
                log(f"noise: {path.name}: volcl, equiangular off ...")
                off = {}
                cpu_off = None
                for seed in (args.seed, args.seed + 1):
                    scene = load_scene(path, defs)
                    scene.camera.width, scene.camera.height = size
                    r = Renderer(scene, device=device, seed=seed, estimator=Estimator(equiangular="off"))
                    r.render(1)
                    c = volcl_render_alone(r, args.spp, off)[1]
                    cpu_off = c if cpu_off is None else cpu_off
                cells["volcl eq off"] = [seconds_to_error(cpu_off, relative_noise(off[args.seed], off[args.seed + 1], blk))
                                         for blk in (1, NOISE_BLOCK)]
        m = best.get((path.name, "Mitsuba render"))
        mimgs = images.get((path.name, "Mitsuba"), {})
        if m and args.seed in mimgs:
            log(f"noise: {path.name}: Mitsuba, seed {args.seed + 1} ...")
            out = tmp / f"{path.stem}.mitsuba_noise.exr"
            try:
                mitsuba_ref.render_mitsuba(str(path), str(out), mts["python"], args.variant, args.spp, args.seed + 1,
                                           dict(defs, width=str(size[0]), height=str(size[1])), 1, details=True)
                again = read_exr(out)
                cells["Mitsuba"] = [seconds_to_error(m["cpu"], relative_noise(mimgs[args.seed], again, blk))
                                    for blk in (1, NOISE_BLOCK)]
            except mitsuba_ref.MitsubaError as exc:
                log(str(exc))
        fmt = lambda k: " / ".join(f"{x:.3g}" for x in cells[k]) if k in cells else "–"   # noqa: E731
        ratio = (" / ".join(f"{m_ / v_:.2f}" for m_, v_ in zip(cells["Mitsuba"], cells["volcl"]))
                 if "Mitsuba" in cells and "volcl" in cells else "–")
        rows.append([path.name, fmt("volcl"), fmt("volcl eq off"), fmt("Mitsuba"), ratio])
    return rows


# ------------------------------------------------------------------------------------ main

def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenes", nargs="+", type=Path, default=sorted((ROOT / "scenes").glob("*.xml")))
    p.add_argument("--size", default="128x128", help="WIDTHxHEIGHT (default 128x128)")
    p.add_argument("--spp", type=int, default=128)
    p.add_argument("--rounds", type=int, default=2, help="rounds of every measurement; the best counts")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--max-depth", default=None, help="max_depth for every scene (default: each scene's own)")
    p.add_argument("--variant", default=mitsuba_ref.DEFAULT_VARIANT)
    p.add_argument("--device", help="volcl device selector (default: $VOLCL_DEVICE or the first that builds)")
    p.add_argument("--mesh-triangles", type=int, default=1_000_000,
                   help="triangles of the synthetic mesh for the memory table (0: skip)")
    p.add_argument("--skip-build", action="store_true", help="skip the kernel build measurements")
    p.add_argument("--noise", action="store_true",
                   help="also time to 1%% relative RMS error (one more render of each at seed + 1)")
    p.add_argument("-D", "--define", action="append", metavar="NAME=VALUE",
                   help="scene parameter for both renderers")
    mitsuba_ref.add_argument(p)
    args = p.parse_args(argv)

    from volcl import __version__
    from volcl import device as devmod
    from volcl.renderer import Renderer
    defines = parse_defines(args.define)
    width, height = (int(x) for x in args.size.lower().split("x"))
    if args.max_depth is not None:
        defines["max_depth"] = args.max_depth
    device = devmod.choose(args.device)
    mts = mitsuba_ref.locate(args.mitsuba_python, args.variant, log=print)
    scenes = [pth.resolve() for pth in args.scenes]
    scene_path = scenes[0]

    print("# volcl render throughput\n")
    print(f"- CPU: {cpu_model()}, {cores()} cores ({platform.machine()}, {platform.system()})")
    print(f"- volcl {__version__} device: {device.key} {device.name} ({device.platform_name}, "
          f"{device.device.max_compute_units} compute units)")
    if mts:
        print(f"- Mitsuba {mts['version']} variant {args.variant} via {mts['python']}")
    else:
        print("- Mitsuba: not found, its columns are skipped")
    print(f"- {width}x{height}, {args.spp} spp, best of {args.rounds} rounds"
          + (f", max_depth {args.max_depth}" if args.max_depth is not None else ", each scene's max_depth"))
    print(f"- load average at start (1/5/15 min): {load_average()}; other processes on the machine skew timings\n")

    # throughput: per scene, per round, the four measurements interleaved
    best = {}
    renderers = {}
    images = {}
    noise = None
    with tempfile.TemporaryDirectory(prefix="volcl-throughput-") as tmp:
        for rnd in range(-1, args.rounds):          # round -1 warms every cache, untimed
            for path in scenes:
                mitsuba_ok = bool(mts) and is_mitsuba_file(path)
                defs = dict(defines)
                kinds = ["volcl whole", "volcl render"] + (["Mitsuba whole", "Mitsuba render"] if mitsuba_ok else [])
                for kind in kinds:
                    log(f"round {rnd + 1}: {path.name}: {kind} ...")
                    try:
                        r = _measure(kind, path, defs, args, mts, device, renderers, Path(tmp), rnd < 0,
                                     images if args.noise else None)
                    except (RuntimeError, mitsuba_ref.MitsubaError) as exc:
                        log(str(exc))
                        r = None
                    if rnd < 0 or r is None:
                        best.setdefault((path.name, kind), None)
                        continue
                    b = best.get((path.name, kind)) or {"wall": np.inf, "cpu": np.inf, "invalid": 0}
                    b["wall"], b["cpu"] = min(b["wall"], r[0]), min(b["cpu"], r[1])
                    b["invalid"] = max(b["invalid"], r[2] if len(r) > 2 else 0)
                    best[(path.name, kind)] = b
        if args.noise:
            renderers.clear()
            noise = noise_rows(scenes, defines, args, mts, device, best, images, Path(tmp))
    rows = []
    for path in scenes:
        row = [path.name]
        for what in ("whole", "render"):
            v, m = best.get((path.name, f"volcl {what}")), best.get((path.name, f"Mitsuba {what}"))
            cell = lambda b: "failed" if b is None else f"{b['wall']:.2f} / {b['cpu']:.2f}"   # noqa: E731
            row += [cell(v), cell(m) if (path.name, f"Mitsuba {what}") in best else "–"]
            if v and m:
                row.append(f"{m['wall'] / v['wall']:.2f} / {m['cpu'] / v['cpu']:.2f}")
            else:
                row.append("–")
        v = best.get((path.name, "volcl render"))
        samples = width * height * args.spp
        row.append(f"{samples / v['wall'] / 1e6:.2f}" if v else "–")
        m = best.get((path.name, "Mitsuba render"))
        row.append(f"{samples / m['wall'] / 1e6:.2f}" if m else "–")
        if v and v["invalid"]:
            row[0] += f" ({v['invalid']} invalid)"
        rows.append(row)
    print(f"## Throughput ({width}x{height}, {args.spp} spp)\n")
    print(table(["scene", "volcl whole process s (wall / CPU)", "Mitsuba whole process s (wall / CPU)",
                 "volcl/Mitsuba whole (wall / CPU)", "volcl render s (wall / CPU)",
                 "Mitsuba render s (wall / CPU)", "volcl/Mitsuba render (wall / CPU)",
                 "volcl M samples/s", "Mitsuba M samples/s"], rows))
    print()
    if noise:
        print(f"## Time to 1% relative RMS error ({width}x{height}, from two {args.spp}-spp renders per column)\n")
        print("Render-alone CPU seconds times the relative mean squared error (from the difference of two "
              "renders with independent seeds) over 1e-4, per pixel / over the means of "
              f"{NOISE_BLOCK}x{NOISE_BLOCK} blocks; lower is better. \"volcl/Mitsuba\" is Mitsuba's "
              "time over volcl's default's. A few fireflies in one of the two renders move a figure a lot.\n")
        print(table(["scene", "volcl default CPU s (pixel / block)", "volcl equiangular off CPU s",
                     "Mitsuba CPU s", "volcl/Mitsuba"], noise))
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
        brows.append(["specialized", "in-process (2nd Renderer on the device: program reused)", "–",
                      f"{r2.build_seconds:.2f}",
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
