"""Mitsuba 3 as an outside reference for the benchmarks, always in a separate process.

volcl never imports Mitsuba: the benchmarks run it through whatever Python interpreter has it,
found in this order:
  1. --mitsuba-python PATH (the scripts' command-line option),
  2. the environment variable VOLCL_MITSUBA_PYTHON,
  3. the interpreter running the benchmark, if `import mitsuba` works there.
Otherwise the Mitsuba columns are skipped with "Mitsuba 3 not found: pass --mitsuba-python".

As a module: `find_mitsuba_python()`, `mitsuba_info()` and `render_mitsuba()`, which renders a
scene file to an EXR and returns the measured warm render seconds: the scene is rendered once
untimed (Dr.Jit traces and compiles its kernels on the first render), then `repeat` more times with
the clock stopped only after `dr.eval` and `dr.sync_thread`; the best of those is returned.

As a script, in the interpreter that has Mitsuba (this is the subprocess side):

    python mitsuba_ref.py --render SCENE.xml --out OUT.exr [--variant llvm_ad_rgb] [--spp 256]
                          [--seed 0] [--repeat 1] [--no-warmup] [-D name=value ...]

prints one line `MITSUBA_REF_RESULT {json}` with seconds, first_seconds, cpu_seconds (the least
process CPU time, all threads, of a timed render), version and the image's mean. Without --render it reports which Mitsuba the lookup above finds.

Only the standard library is imported at module level, so the file runs unchanged in either
interpreter.
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import os
import subprocess
import sys
import time

from common import parse_defines

ENV_VAR = "VOLCL_MITSUBA_PYTHON"
NOT_FOUND = "Mitsuba 3 not found: pass --mitsuba-python"
RESULT_TAG = "MITSUBA_REF_RESULT "
DEFAULT_VARIANT = "llvm_ad_rgb"


class MitsubaError(RuntimeError):
    """Mitsuba failed to load or render a scene (the message carries its stderr)."""


def add_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--mitsuba-python", metavar="PATH",
                        help=f"Python interpreter that can `import mitsuba` (default: ${ENV_VAR}, "
                             f"else this interpreter if it has Mitsuba)")


def find_mitsuba_python(explicit: str | None = None) -> str | None:
    """The interpreter to run Mitsuba with, or None. An explicit path or the environment variable
    is returned as given (checked later by mitsuba_info); the current interpreter only if it has
    Mitsuba. No other place is searched."""
    if explicit:
        return explicit
    env = os.environ.get(ENV_VAR)
    if env:
        return env
    if importlib.util.find_spec("mitsuba") is not None:
        return sys.executable
    return None


def mitsuba_info(python: str, timeout: float = 120) -> dict:
    """{'version', 'variants', 'python'} of the Mitsuba that `python` imports; raises MitsubaError
    when that interpreter cannot run or has no Mitsuba."""
    code = ("import json, mitsuba as mi; "
            "print(json.dumps({'version': mi.__version__, 'variants': list(mi.variants())}))")
    try:
        proc = subprocess.run([python, "-c", code], capture_output=True, text=True, timeout=timeout)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise MitsubaError(f"cannot run {python}: {exc}") from None
    if proc.returncode != 0:
        tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        raise MitsubaError(f"{python} cannot import mitsuba: {tail}")
    info = json.loads(proc.stdout.strip().splitlines()[-1])
    info["python"] = python
    return info


def locate(explicit: str | None = None, variant: str | None = None, log=None) -> dict | None:
    """find_mitsuba_python + mitsuba_info in one step: the info dict, or None after printing why
    Mitsuba is unavailable (to `log`, default stderr)."""
    log = log or (lambda msg: print(msg, file=sys.stderr))
    python = find_mitsuba_python(explicit)
    if python is None:
        log(NOT_FOUND)
        return None
    try:
        info = mitsuba_info(python)
    except MitsubaError as exc:
        log(f"{NOT_FOUND} ({exc})")
        return None
    if variant and variant not in info["variants"]:
        log(f"Mitsuba {info['version']} at {python} has no variant {variant!r} "
            f"(it has {', '.join(info['variants'])}); skipping Mitsuba")
        return None
    return info


def render_mitsuba(scene: str, out: str | None, python: str, variant: str = DEFAULT_VARIANT,
                   spp: int = 256, seed: int = 0, defines: dict | None = None, repeat: int = 1,
                   warmup: bool = True, timeout: float | None = 3600, details: bool = False,
                   size: tuple | None = None):
    """Render `scene` with Mitsuba in a subprocess and write `out` (EXR; None: no file).

    Returns the best warm render seconds of `repeat` timed renders (after one untimed warm-up
    render unless warmup=False, in which case the single render's time includes JIT compilation).
    With details=True returns the whole result dict instead (seconds, first_seconds, all_seconds,
    version, variant, mean, width, height). size=(width, height) renders the first sensor's film at
    that size instead of the file's (keep the aspect ratio: the field of view stays as loaded)."""
    cmd = [python, os.path.abspath(__file__), "--render", os.path.abspath(scene), "--variant", variant,
           "--spp", str(spp), "--seed", str(seed), "--repeat", str(repeat)]
    if out:
        cmd += ["--out", os.path.abspath(out)]
    if not warmup:
        cmd.append("--no-warmup")
    if size:
        cmd += ["--size", f"{size[0]}x{size[1]}"]
    for k, v in (defines or {}).items():
        cmd += ["-D", f"{k}={v}"]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        raise MitsubaError(f"Mitsuba render of {scene} timed out after {timeout} s") from None
    except OSError as exc:
        raise MitsubaError(f"cannot run {python}: {exc}") from None
    # a Mitsuba warning ends with a colour reset and no newline, so the tag may start mid-line
    lines = [ln[ln.index(RESULT_TAG):] for ln in proc.stdout.splitlines() if RESULT_TAG in ln]
    if proc.returncode != 0 or not lines:
        tail = "\n".join((proc.stderr.strip() or proc.stdout.strip()).splitlines()[-15:])
        raise MitsubaError(f"Mitsuba failed on {scene} (exit {proc.returncode}):\n{tail}")
    result = json.loads(lines[-1][len(RESULT_TAG):])
    return result if details else result["seconds"]


# ----------------------------------------------------------------------------------------------
# subprocess side: runs in the interpreter that has Mitsuba


def _render_here(args) -> dict:
    import drjit as dr
    import mitsuba as mi
    mi.set_variant(args.variant)
    defines = parse_defines(args.define)
    # spp goes to mi.render, not load_file: Mitsuba rejects parameters a file does not use
    scene = mi.load_file(args.render, **defines)
    if args.size:
        width, height = (int(v) for v in args.size.split("x"))
        params = mi.traverse(scene.sensors()[0])
        params["film.size"] = [width, height]
        params["film.crop_size"] = [width, height]
        params.update()

    import resource

    def cpu():
        r = resource.getrusage(resource.RUSAGE_SELF)
        return r.ru_utime + r.ru_stime

    cpu_times = []

    def once():
        c0, t0 = cpu(), time.perf_counter()
        img = mi.render(scene, spp=args.spp, seed=args.seed)
        dr.eval(img)
        dr.sync_thread()
        cpu_times.append(cpu() - c0)
        return img, time.perf_counter() - t0

    img, first = once()
    times = []
    if args.no_warmup:
        times.append(first)
    else:
        for _ in range(max(1, args.repeat)):
            img, dt = once()
            times.append(dt)
    if args.out:
        mi.Bitmap(img).write(args.out)
    h, w = int(img.shape[0]), int(img.shape[1])
    try:
        import numpy as np
        mean = np.asarray(img, dtype=np.float64).reshape(h * w, -1).mean(0).tolist()
    except ImportError:
        mean = None
    warm_cpu = cpu_times[1:] if len(cpu_times) > 1 else cpu_times
    return {"seconds": min(times), "first_seconds": first, "all_seconds": times, "cpu_seconds": min(warm_cpu),
            "version": mi.__version__, "variant": args.variant, "width": w, "height": h,
            "spp": args.spp, "seed": args.seed, "mean": mean}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--render", metavar="SCENE", help="render SCENE here (this interpreter must have Mitsuba)")
    p.add_argument("--out", help="output EXR")
    p.add_argument("--variant", default=DEFAULT_VARIANT)
    p.add_argument("--spp", type=int, default=256)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--repeat", type=int, default=1, help="timed warm renders; the best is reported")
    p.add_argument("--no-warmup", action="store_true", help="time the first render (includes JIT)")
    p.add_argument("--size", metavar="WxH", help="render the film at this size")
    p.add_argument("-D", "--define", action="append", metavar="NAME=VALUE",
                   help="scene parameter (<default>) passed to mi.load_file")
    add_argument(p)
    args = p.parse_args(argv)
    if args.render:
        print(RESULT_TAG + json.dumps(_render_here(args)), flush=True)
        return 0
    info = locate(args.mitsuba_python, log=print)
    if info is None:
        return 1
    print(f"Mitsuba {info['version']} via {info['python']}; variants: {', '.join(info['variants'])}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
