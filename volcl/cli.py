"""The `volcl` command: render scenes, list devices, describe a scene, run Nori t-test files."""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
import warnings
from pathlib import Path

# numpy's OpenBLAS starts a thread per core when numpy is imported, which this command never uses
# (its matrices are 4x4; the work is on the OpenCL device): one thread saves that start-up. Set
# before numpy is first imported (volcl's package imports nothing heavy); a user's own setting wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from . import __version__
from .errors import VolclError


def _defines(items):
    out = {}
    for item in items or []:
        if "=" not in item:
            raise VolclError(f"-D {item!r}: expected name=value")
        k, v = item.split("=", 1)
        out[k.strip()] = v
    return out


def _scene_options(args):
    from .options import SceneOptions
    return SceneOptions(defines=_defines(args.define), width=args.width, height=args.height,
                        sensor=getattr(args, "sensor", None))


def _load(path, args):
    """The volcl.Scene of a scene file (volcl.batch.load_scene: warnings printed)."""
    from .batch import load_scene
    return load_scene(path, _scene_options(args))


def _features(args):
    if not getattr(args, "features", None):
        return None
    from .features import parse_override
    try:
        return parse_override(args.features)
    except ValueError as exc:
        raise VolclError(f"--features: {exc}") from None


def _on_off(value):
    return value == "on"


def _estimator(args):
    from .estimator import Estimator
    return Estimator(nee=_on_off(args.nee), mis=_on_off(args.mis), equiangular=args.equiangular,
                     equiangular_mis=args.equiangular_mis, emission_nee=_on_off(args.emission_nee))


def cmd_render(args):
    """The command line made into volcl.options, handed to volcl.batch."""
    from . import batch
    from .options import OutputOptions, RenderOptions
    output = OutputOptions(output=args.output and Path(args.output),
                           output_dir=args.output_dir and Path(args.output_dir),
                           checkpoint_every=args.checkpoint_every, resume=args.resume,
                           keep_checkpoint=args.keep_checkpoint, quiet=args.quiet, verbose=args.verbose)
    render = RenderOptions(spp=args.spp, seed=args.seed, time_limit=args.time_limit, target_error=args.target_error,
                           min_spp=args.min_spp, estimator=_estimator(args), features=_features(args),
                           tile_size=args.tile_size)
    scene_options = _scene_options(args)
    if args.sweep:
        from dataclasses import replace
        scene_options = replace(scene_options, sweep=Path(args.sweep))
    if args.scheduler and args.scheduler.startswith("local:"):
        import logging      # the cluster is this command's own: its workers' comings and goings are noise
        logging.getLogger("distributed").setLevel(logging.WARNING)
    if args.scheduler and args.device:
        raise VolclError("--scheduler renders on the cluster's workers, each on the device it chose (start them "
                         "with `volcl worker ADDRESS --device ...`); --device is for renders on this machine")
    return batch.run(args.scenes, args.device, scene_options, render, output, scheduler=args.scheduler)


def cmd_worker(args):
    """`volcl worker ADDRESS`: a Dask worker (distributed's own command) with volcl's preload."""
    import os
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise VolclError("volcl worker needs Dask distributed: pip install 'volcl[cluster]'") from None
    from .cluster import quiet_dask_env
    env = quiet_dask_env(os.environ)
    if args.device:
        env["VOLCL_DEVICE"] = args.device
    extra = list(args.dask_args)
    # dask worker's own options before --preload: what follows a preload is the preload's
    cmd = [sys.executable, "-m", "distributed.cli.dask_worker", args.scheduler, "--nthreads", str(args.nthreads),
           *extra, "--preload", "volcl.cluster"]
    os.execvpe(sys.executable, cmd, env)


def cmd_devices(args):
    from . import selftest
    from .device import is_simulator, kernels_build, list_devices
    devs = list_devices()
    if not devs:
        from .device import INSTALL_HINT
        print(f"no OpenCL platform found; {INSTALL_HINT}")
        return 1
    print(f"{'index':6} {'type':5} {'units':>5} {'memory':>9}  {'OpenCL C':12} {'kernels':8} {'self-test':10} "
          "name (vendor, platform)")
    for d in devs:
        dev = d.device
        ok, why = kernels_build(d)
        test = None
        if ok and not is_simulator(d):
            test = selftest.run(d)
        mem = f"{dev.global_mem_size / 2**30:.1f} GiB"
        status = "build" if ok else "FAIL"
        tested = "-" if test is None else (f"ok {test.seconds:.1f} s" if test.ok else "FAIL")
        note = f": {why}" if not ok else (": simulator, not self-tested" if test is None else
                                          ("" if test.ok else f": {test.message}"))
        print(f"{d.key:6} {d.kind:5} {dev.max_compute_units:5} {mem:>9}  {dev.opencl_c_version.replace('OpenCL C ', ''):12} "
              f"{status:8} {tested:10} {d.name} ({dev.vendor.strip()}, {d.platform_name}){note}", flush=True)
    return 0


def _grid_text(volume):
    if volume.kind == "sparse":
        x, y, z = volume.sparse.padded_counts() * 8
        c = volume.sparse.channels
        return (f"sparse grid '{volume.grid_name}', {x}x{y}x{z} box in bricks of 8^3, "
                f"{c} channel{'s' if c > 1 else ''}, {volume.filter}")
    if volume.kind != "grid":
        return "constant extinction"
    z, y, x, c = volume.data.shape
    return f"{x}x{y}x{z} grid, {c} channel{'s' if c > 1 else ''}, {volume.filter}"


def cmd_info(args):
    from .features import FLAGS, describe
    prepared = _load(args.scene, args)
    scene, packed = prepared.model, prepared.packed
    feats = _features(args) or prepared.features
    cam = scene.camera
    print(f"scene      {args.scene} ({scene.dialect} dialect)")
    print(f"camera     {cam.width}x{cam.height}, fov {cam.fov:g} ({cam.fov_axis}), filter {cam.rfilter.kind}")
    print(f"integrator {scene.integrator.kind}, max_depth {scene.integrator.max_depth}, spp {scene.spp}")
    cylinders = packed.stats.get("cylinders", 0)
    print(f"shapes     {len(scene.shapes)} ({packed.triangle_count} triangles, {packed.sphere_count} spheres"
          + (f", {cylinders} cylinders)" if cylinders else ")"))
    if scene.instances:
        groups = len({id(i.group) for i in scene.instances})
        print(f"instances  {len(scene.instances)} of {groups} shape group{'s' if groups != 1 else ''} "
              f"(each group's geometry stored once)")
    kinds = ["area"] * sum(s.emitter_radiance is not None for s in scene.shapes) + [
        f"envmap {e.image.shape[1]}x{e.image.shape[0]}, {packed.arrays['env_data'].nbytes / 2**20:.1f} MiB"
        if e.kind == "envmap" else e.kind for e in scene.emitters]
    print(f"emitters   {len(kinds)}" + (f" ({', '.join(kinds)})" if kinds else ""))
    media_kinds = [m.kind + (f" ({_grid_text(m.sigma_t)})" if m.kind == "heterogeneous" else "") for m in scene.media]
    print(f"media      {len(scene.media)}" + (f": {', '.join(media_kinds)}" if media_kinds else ""))
    from .grids import grid_cost_text
    for cost in packed.stats.get("sparse_grids", ()):
        print(f"sparse     {grid_cost_text(cost)}")
    print(f"features   {describe(feats)}")
    print("flags      " + " ".join(f"VOLCL_HAS_{n}={int(feats[n])}" for n in FLAGS))
    if not args.no_build:
        from . import device as devmod
        dev = devmod.choose(args.device)
        t0 = time.perf_counter()
        dev.program(feats)
        print(f"build      {time.perf_counter() - t0:.2f} s on {dev.key} {dev.name}")
    return 0


def cmd_test(args):
    """Nori's t-test files: each scene's mean radiance against its reference value."""
    from . import device as devmod
    from .renderer import Renderer
    from .scene import load
    from .scene.model import TTest
    test = load(args.file, _defines(args.define))
    if not isinstance(test, TTest):
        raise VolclError(f"{args.file}: not a <test type=\"ttest\"> file")
    device = devmod.choose(args.device)
    n = len(test.scenes)
    alpha = 1 - (1 - test.significance) ** (1 / n)     # Sidak: the whole file at the stated level
    failed = 0
    for i, (scene, ref) in enumerate(zip(test.scenes, test.references)):
        result = Renderer(scene, device=device, seed=args.seed).render(args.spp)
        mean = float(result.image.mean())
        npix = result.image.shape[0] * result.image.shape[1]
        se = math.sqrt(float(result.variance.mean()) / npix)
        z = (mean - ref) / se if se > 0 else (0.0 if mean == ref else math.inf)
        p = math.erfc(abs(z) / math.sqrt(2))
        ok = p > alpha and result.invalid == 0
        failed += not ok
        print(f"test {i + 1}/{n} ({scene.integrator.kind}): mean {mean:.5f} reference {ref:g} "
              f"std.err {se:.5f} p={p:.3g} alpha={alpha:.3g} {'passed' if ok else 'FAILED'}")
    print(f"{n - failed} passed, {failed} failed")
    return 1 if failed else 0


def cmd_converge(args):
    from . import device as devmod
    from .converge import converge, markdown_table
    scene = _load(args.scene, args)
    if args.max_seconds <= 0:
        raise VolclError(f"--max-seconds {args.max_seconds}: expected a positive number of seconds")
    choices = [c.strip() for c in args.choices.split(",")] if args.choices else None
    report = converge(scene, name=args.name or Path(args.scene).stem, reference=args.reference, out=args.out,
                      max_seconds=args.max_seconds, reference_seconds=args.reference_seconds, choices=choices,
                      seed=args.seed, device=devmod.choose(args.device), features=_features(args),
                      quiet=args.quiet, clock=args.clock)
    print(markdown_table(report))
    for p in (report.csv_path, report.plot_path, report.table_path):
        print(f"wrote {p}")
    return 0


def _show_skipped_devices():
    """A device the default choice passes over (volcl.device.DeviceSkipped) is named on stderr as
    `volcl: warning: ...`, every time, instead of in Python's warning format."""
    from .device import DeviceSkipped
    shown = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, DeviceSkipped):
            print(f"volcl: warning: {message}", file=sys.stderr, flush=True)
        else:
            shown(message, category, filename, lineno, file, line)
    warnings.showwarning = show
    warnings.simplefilter("always", DeviceSkipped)


def main(argv=None):
    from .estimator import CHOICES
    p = argparse.ArgumentParser(prog="volcl", description="volcl: a volumetric path tracer on OpenCL")
    p.add_argument("--version", action="version", version=f"volcl {__version__}")
    sub = p.add_subparsers(dest="command", required=True)

    def scene_opts(sp):
        sp.add_argument("-D", "--define", action="append", metavar="NAME=VALUE",
                        help="override a scene <default> parameter")
        sp.add_argument("--width", type=int)
        sp.add_argument("--height", type=int)
        sp.add_argument("--device", help="device index P:D, name substring, 'cpu' or 'gpu' (default: $VOLCL_DEVICE)"
                        + ("; 'all' or a list 'A,B,...': one render on several devices" if sp.prog.endswith("render")
                           else "; of a list, the first"))
        sp.add_argument("--features", help="'all': compile every feature instead of only the scene's")
        sp.add_argument("--sensor", type=int, metavar="N",
                        help="render the scene's sensor N (0-based, in file order; default 0)")
        sp.add_argument("-v", "--verbose", action="store_true")

    def estimator_opts(sp):
        sp.add_argument("--nee", choices=("on", "off"), default="on",
                        help="next-event estimation: sample lights at every vertex (default on)")
        sp.add_argument("--mis", choices=("on", "off"), default="on",
                        help="combine light sampling with BSDF / phase sampling by MIS (default on)")
        sp.add_argument("--equiangular", choices=("auto", "on", "off"), default="auto",
                        help="equiangular sampling towards point and spot lights in media; auto: where "
                             "such a light is inside a medium (default auto)")
        sp.add_argument("--equiangular-mis", choices=("two", "one"), default="two",
                        help="combine equiangular and distance samples by two-sample (default) or "
                             "one-sample MIS")
        sp.add_argument("--emission-nee", choices=("on", "off"), default="on",
                        help="with --nee on: also sample points of emissive media, combined with the "
                             "collision estimate by MIS (default on; compiled only for scenes with one)")

    r = sub.add_parser("render", help="render one or more scenes")
    r.add_argument("scenes", nargs="+", metavar="SCENE")
    r.add_argument("-o", "--output", help="output file of a single scene; .exr (linear float) or .png (sRGB)")
    r.add_argument("--output-dir", metavar="DIR",
                   help="folder for outputs named after the scenes (default: the working folder)")
    r.add_argument("--spp", type=int, help="samples per pixel (default: the scene's sampler)")
    r.add_argument("--seed", type=int)
    r.add_argument("--checkpoint-every", type=float, default=5.0, metavar="MINUTES",
                   help="save the render's state beside the output every MINUTES (default 5; 0: never)")
    r.add_argument("--resume", action="store_true",
                   help="continue from OUTPUT.checkpoint.npz where one exists; keep finished outputs")
    r.add_argument("--keep-checkpoint", action="store_true",
                   help="keep the checkpoint of a finished render (to add samples later with --resume --spp)")
    r.add_argument("-q", "--quiet", action="store_true", help="no progress bar (or progress lines in logs)")
    r.add_argument("--time-limit", type=float, metavar="SECONDS",
                   help="stop after this much render time (or at --spp, or the scene's spp, if sooner)")
    r.add_argument("--target-error", type=float, metavar="E",
                   help="stop once the image's estimated relative error is at most E (e.g. 0.02)")
    r.add_argument("--min-spp", type=int, default=16, metavar="N",
                   help="samples per pixel before --target-error trusts the estimate (default 16)")
    r.add_argument("--tile-size", type=int, metavar="PIXELS",
                   help="tile size of a render on several devices (default: 8 or more tiles per device, "
                        "at most 64 pixels square)")
    r.add_argument("--sweep", metavar="FILE",
                   help="render each scene once per line of FILE, a set of -D values (name=value ...); "
                        "-D name=A..B[:STEP] sweeps integers too")
    r.add_argument("--scheduler", metavar="ADDRESS",
                   help="render on a Dask cluster: its scheduler's address (tcp://host:8786), or local:N "
                        "for N single-threaded worker processes on this machine")
    estimator_opts(r)
    scene_opts(r)
    r.set_defaults(func=cmd_render)

    w = sub.add_parser("worker", help="a Dask worker for `volcl render --scheduler` (dask worker with volcl's preload)",
                       epilog="Options after -- go to `dask worker` (--name, --memory-limit, ...).")
    w.add_argument("scheduler", metavar="ADDRESS", help="the scheduler's address, e.g. tcp://10.0.0.1:8786")
    w.add_argument("--nthreads", type=int, default=1,
                   help="render threads; each takes one of the worker's devices in turn (default 1)")
    w.add_argument("--device", help="the devices this worker renders on (as volcl render --device; default: "
                                    "$VOLCL_DEVICE, else the first device whose kernels build)")
    w.set_defaults(func=cmd_worker)

    c = sub.add_parser("converge", help="error against render time for each estimator choice that applies")
    c.add_argument("scene")
    c.add_argument("--reference", metavar="REF.exr",
                   help="reference image (default: rendered first, with the default estimator)")
    c.add_argument("--out", default=".", metavar="DIR", help="folder for the CSV, plot and table (default .)")
    c.add_argument("--max-seconds", type=float, default=20.0, metavar="S",
                   help="render time per estimator choice (default 20)")
    c.add_argument("--reference-seconds", type=float, metavar="S",
                   help="render time of the reference when none is given (default 4 x --max-seconds)")
    c.add_argument("--choices", help="comma-separated subset of: " + ", ".join(CHOICES)
                   + " (default: those that apply to the scene)")
    c.add_argument("--name", help="name for the outputs and the table (default: the scene file's stem)")
    c.add_argument("--clock", choices=("cpu", "wall"), default="cpu",
                   help="measure render cost as process CPU time (default; robust on a shared machine) "
                        "or wall-clock time")
    c.add_argument("--seed", type=int, default=1)
    c.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    scene_opts(c)
    c.set_defaults(func=cmd_converge)

    d = sub.add_parser("devices", help="list OpenCL devices, whether volcl's kernels build on them and "
                                      "whether they pass its self-test")
    d.set_defaults(func=cmd_devices)

    i = sub.add_parser("info", help="what a scene contains and which kernel features it compiles")
    i.add_argument("scene")
    i.add_argument("--no-build", action="store_true")
    scene_opts(i)
    i.set_defaults(func=cmd_info)

    t = sub.add_parser("test", help="run a Nori <test type=\"ttest\"> file")
    t.add_argument("file")
    t.add_argument("--spp", type=int, default=65536, help="samples per pixel per scene (default 65536)")
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--device")
    t.add_argument("-D", "--define", action="append", metavar="NAME=VALUE")
    t.set_defaults(func=cmd_test)

    argv = list(sys.argv[1:] if argv is None else argv)
    passthrough = []
    if argv[:1] == ["worker"] and "--" in argv:     # the rest is dask worker's
        passthrough, argv = argv[argv.index("--") + 1:], argv[:argv.index("--")]
    args = p.parse_args(argv)
    args.dask_args = passthrough
    try:
        with warnings.catch_warnings():
            _show_skipped_devices()
            return args.func(args)
    except VolclError as exc:
        print(f"volcl: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:     # before the render's handlers, or a second signal
        signum = getattr(exc, "signum", 2)
        print("volcl: interrupted; nothing more written", file=sys.stderr)
        return 128 + signum


def entry():
    """The `volcl` command and `python -m volcl`: main(), then the end of the process."""
    leave(main())


def leave(code: int):
    """End the process with exit status `code` once everything it wrote is out.

    Python's own teardown after a render (freeing every module and object, then unloading the
    OpenCL runtimes' libraries) takes 40-60 ms, a tenth of a short command's whole time, and
    changes nothing on disk or screen. So after the exit handlers have run (they flush and close
    what libraries left open: logging, Dask's clients, temporary folders), the process ends at
    once; not while another thread is still working, whose work Python's exit would wait for."""
    import atexit
    import threading
    if any(t.is_alive() and not t.daemon for t in threading.enumerate() if t is not threading.main_thread()):
        sys.exit(code)
    run_handlers = getattr(atexit, "_run_exitfuncs", None)     # CPython's; elsewhere the usual exit
    if run_handlers is None:
        sys.exit(code)
    run_handlers()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):       # a closed pipe or stream: nothing more reaches it
            pass
    os._exit(0 if code is None else code if isinstance(code, int) else 1)


if __name__ == "__main__":
    entry()
