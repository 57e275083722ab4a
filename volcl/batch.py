"""`volcl render`: one scene or a batch, built to be trusted with long jobs.

- Outputs are named after the scenes (cbox.xml -> cbox.exr, in --output-dir or the working
  folder); scenes that share a name get their folders in the output name (x/cbox.xml and
  y/cbox.xml -> x_cbox.exr and y_cbox.exr), so no output overwrites another.
- A scene that fails is reported and the batch goes on; a table at the end says what happened to
  every scene, and the exit status says whether anything failed.
- SIGINT (Ctrl-C) or SIGTERM: the pass under way finishes, the image rendered so far is written
  (with its sample count in the metadata) beside a checkpoint, the batch stops, and volcl exits
  with 128 + the signal number (130, 143). A second signal stops at once without writing.
- Every --checkpoint-every minutes the accumulated state is saved (volcl/checkpoint.py);
  --resume continues from it, bit-identical to a render that never stopped.
"""
from __future__ import annotations

import os
import signal
import sys
import time
import traceback
from dataclasses import dataclass, field, replace
from pathlib import Path

from . import checkpoint
from .errors import VolclError
from .options import OutputOptions, RenderOptions, SceneOptions

PROGRESS_LINE_SECONDS = 10.0        # progress lines when stderr is not a terminal (logs)
EXIT_FAILED = 1


@dataclass
class Job:
    scene: str
    output: Path
    status: str = "not rendered"
    spp: int | None = None
    seconds: float | None = None
    error: str = ""
    defines: dict | None = None     # this job's -D values (a sweep's set), None: the batch's
    swept: dict = field(default_factory=dict)   # the values of `defines` that vary in the sweep

    @property
    def failed(self) -> bool:
        return self.status == "FAILED"

    @property
    def label(self) -> str:
        """The scene, with the swept values of this job ('fog.xml [frame=3]')."""
        swept = " ".join(f"{k}={v}" for k, v in self.swept.items())
        return self.scene + (f" [{swept}]" if swept else "")


def make_jobs(scenes, scene_options: SceneOptions, output: OutputOptions) -> list[Job]:
    """The batch's jobs: each scene once, or once per set of a sweep (-D ranges, --sweep), named
    after the scene and the swept values."""
    from . import sweep
    sets = sweep.combine(scene_options.defines, scene_options.sweep)
    names = sweep.varying(sets)
    one_output = output.output if len(scenes) == 1 else None
    if output.output is not None and len(scenes) > 1:
        output_paths(scenes, output.output, output.output_dir)     # the error it gives
    base = [Path(one_output)] if one_output is not None else output_paths(scenes, None, output.output_dir)
    jobs, taken = [], {}
    for scene, out in zip(scenes, base):
        for values in sets:
            path = out.with_name(out.stem + sweep.suffix(values, names, sets) + out.suffix) if names else out
            if path in taken:
                raise VolclError(f"{scene} with {values} and {taken[path]} would both write {path}; a sweep "
                                 "lists each set of values once")
            taken[path] = f"{scene} with {values}"
            jobs.append(Job(str(scene), path, defines=values if names else None,
                            swept={n: values[n] for n in names if n in values}))
    return jobs


def output_paths(scenes, output=None, output_dir=None, suffix=".exr") -> list[Path]:
    """The output file of each scene: -o for a single scene, else named after the scene file in
    output_dir (or the working folder). Scenes sharing a file name are told apart by their folders
    below the folder they have in common."""
    if output is not None:
        if len(scenes) > 1:
            raise VolclError("-o names one output file; with several scenes outputs are named after the "
                             "scenes (use --output-dir DIR to put them elsewhere)")
        if output_dir is not None:
            raise VolclError("-o and --output-dir exclude each other; give -o a path with its folder")
        return [Path(output)]
    folder = Path(output_dir) if output_dir is not None else Path(".")
    resolved = [Path(s).resolve() for s in scenes]
    seen = {}
    for given, p in zip(scenes, resolved):
        if p in seen:
            raise VolclError(f"scene {given} is given twice (also as {seen[p]})")
        seen[p] = given
    by_stem: dict[str, list[Path]] = {}
    for p in resolved:
        by_stem.setdefault(p.stem, []).append(p)
    names = []
    for p in resolved:
        group = by_stem[p.stem]
        if len(group) == 1:
            names.append(p.stem)
        else:
            common = Path(os.path.commonpath([q.parent for q in group]))
            names.append("_".join(p.with_suffix("").relative_to(common).parts))
    outs = [folder / (n + suffix) for n in names]
    taken = {}
    for given, out in zip(scenes, outs):
        if out in taken:
            raise VolclError(f"scenes {taken[out]} and {given} would both write {out}; render them "
                             "in separate runs with different --output-dir")
        taken[out] = given
    return outs


class Interrupted(KeyboardInterrupt):
    """A second SIGINT/SIGTERM: stop now, write nothing more (volcl exits with 128 + signum)."""

    def __init__(self, signum):
        super().__init__(signum)
        self.signum = signum


class StopRequest:
    """While active, SIGINT and SIGTERM ask the render to stop after the current pass (`requested`
    turns true); a second signal raises Interrupted at once."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self):
        self.signum = None
        self._old = {}

    @property
    def requested(self) -> bool:
        return self.signum is not None

    @property
    def exit_status(self) -> int:
        return 128 + self.signum

    def _handle(self, signum, frame):
        if self.signum is not None:
            raise Interrupted(signum)
        self.signum = signum
        print(f"\nvolcl: {signal.Signals(signum).name} received: stopping after the current pass "
              "(send it again to stop at once without writing)", file=sys.stderr, flush=True)

    def __enter__(self):
        for s in self.SIGNALS:
            self._old[s] = signal.signal(s, self._handle)
        return self

    def __exit__(self, *exc):
        for s, old in self._old.items():
            signal.signal(s, old)
        return False


class Progress:
    """A tqdm bar on a terminal; otherwise (a log file, a pipe) a line after the first pass and
    then every PROGRESS_LINE_SECONDS."""

    def __init__(self, name, done, total, quiet):
        self.name, self.done, self.total, self.quiet = name, done, total, quiet
        self.bar = None
        self.t0 = time.monotonic()
        self.last_line = None
        if not quiet and sys.stderr.isatty():
            from tqdm import tqdm
            self.bar = tqdm(total=total, initial=done, desc=name, unit="spp", leave=False, file=sys.stderr)

    tiles_total = 0

    def tile(self, job):
        """A tile of the round under way is in (renders on several devices or a cluster)."""
        if self.bar is not None and self.tiles_total:
            self._tiles = getattr(self, "_tiles", 0) % self.tiles_total + 1
            self.bar.set_postfix_str(f"tiles {self._tiles}/{self.tiles_total}", refresh=True)

    def update(self, n):
        self.done += n
        if self.bar is not None:
            self.bar.update(n)
        elif not self.quiet:
            now = time.monotonic()
            if self.last_line is None or now - self.last_line >= PROGRESS_LINE_SECONDS:
                self.last_line = now
                total = "?" if self.total is None else self.total
                print(f"volcl: {self.name}: {self.done}/{total} spp, {now - self.t0:.1f} s",
                      file=sys.stderr, flush=True)

    def close(self):
        if self.bar is not None:
            self.bar.close()


def _already_rendered(out: Path, scene_path, defines: dict, spp: int, scene, seed) -> bool:
    """Whether `out` is a finished render of this scene file, these -D overrides, size and seed
    with at least `spp` samples (what --resume leaves alone)."""
    from .image import read_image
    if not out.is_file() or out.suffix.lower() != ".exr":
        return False
    try:
        pixels, attrs = read_image(out)
    except VolclError:
        return False
    return (attrs.get("volcl:complete") == 1 and attrs.get("volcl:spp", 0) >= spp
            and attrs.get("volcl:scene_sha256") == checkpoint.file_sha256(scene_path)
            and attrs.get("volcl:defines") == checkpoint.defines_key(defines)
            and pixels.shape[:2] == (scene.height, scene.width)
            and (seed is None or attrs.get("volcl:seed") == seed & 0xFFFFFFFF))


def load_scene(path, options: SceneOptions):
    """The volcl.Scene of a scene file, its warnings printed."""
    from .api import prepare
    from .scene import load
    from .scene.model import Scene, select_sensor
    model = load(path, options.defines)
    if options.sensor is not None and isinstance(model, Scene):
        select_sensor(model, options.sensor)
        model.warnings = [w for w in model.warnings if "volcl renders the first" not in w]
    return prepare(model, path, options.defines, options.width, options.height,
                   warn=lambda w: print(f"warning: {w}", file=sys.stderr))


def _notify(text: str):
    print(f"volcl: warning: {text}", file=sys.stderr, flush=True)


def render_job(job: Job, devices, stop: StopRequest, scene_options: SceneOptions, render: RenderOptions,
               output: OutputOptions, executor=None, position: str = ""):
    """Render one scene into job.output, updating job, on `devices` (a list of volcl Devices: one
    device, or a render shared by several, volcl.rounds) or on `executor`'s workers (a cluster).
    Raises VolclError for what a user can fix."""
    from .image import check_writable, write_image
    from .renderer import Renderer
    from .rounds import WorkersFailed, renderer_for
    out = check_writable(job.output)
    if job.defines is not None:
        scene_options = replace(scene_options, defines=job.defines)
    scene = load_scene(job.scene, scene_options)
    defines = scene_options.defines
    # --spp caps --time-limit and --target-error; without it the scene's spp caps a time limit (the
    # render stops at whichever comes first), while a target error runs until it is met
    spp = render.spp or (None if render.target_error else scene.spp)
    estimator = render.estimator
    if not estimator.nee and any(e.kind in ("point", "spot", "directional") for e in scene.model.emitters):
        print(f"volcl: warning: {job.scene}: with --nee off, point, spot and directional lights are never found (no "
              "path can hit them)", file=sys.stderr)
    ckpt = checkpoint.path_for(out)
    state = meta = None
    if output.resume:
        if ckpt.is_file():
            state, meta = checkpoint.load(ckpt)
        elif spp is not None and _already_rendered(out, job.scene, defines, spp, scene, render.seed):
            job.status, job.spp = "done earlier, kept", spp
            print(f"{out}: already rendered with {spp} spp or more; kept", flush=True)
            return
    seed = render.seed if render.seed is not None else (meta["seed"] if meta else None)
    renderer = renderer_for(scene, devices, executor, seed=seed, estimator=estimator, features=render.features,
                            tile_size=render.tile_size, notify=_notify)
    ident = checkpoint.identity(renderer, job.scene, defines)
    if state is not None:
        checkpoint.check(ckpt, meta, ident, renderer.seed)
        renderer.restore(state)
        print(f"volcl: {job.scene}: resuming from {ckpt} at {renderer.samples_done} spp", file=sys.stderr)
    elif ckpt.is_file():
        print(f"volcl: warning: {ckpt} exists and is ignored (--resume continues from it); it will be "
              "replaced", file=sys.stderr)
    if output.verbose and not isinstance(renderer, Renderer):
        print(f"{job.scene}: {renderer.packed.triangle_count} triangles, {renderer.packed.sphere_count} spheres, "
              f"BVH {renderer.packed.bvh_seconds:.2f} s, {len(renderer.tile_list)} tiles on "
              f"{renderer.device_label}", file=sys.stderr)
    elif output.verbose:
        if not renderer.built:
            build = "kernel program reused (built earlier in this run)"
        elif renderer.build_was_cold:
            build = (f"kernel build {renderer.build_seconds:.2f} s (the first of this kernel version and feature "
                     f"set on this machine)")
        else:
            build = (f"kernel build {renderer.build_seconds:.2f} s from the caches (the first build here took "
                     f"{renderer.cold_build_seconds:.2f} s)")
        print(f"{job.scene}: {renderer.packed.triangle_count} triangles, {renderer.packed.sphere_count} spheres, "
              f"BVH {renderer.packed.bvh_seconds:.2f} s, {build}", file=sys.stderr)
    if stop.requested:          # a signal came while the scene loaded or the kernel built
        return
    resumed_at = renderer.samples_done
    interval = output.checkpoint_every * 60.0 if output.checkpoint_every else None
    extra = {"spp_requested": spp or 0}
    last_save = time.monotonic()

    def after_pass():
        nonlocal last_save
        if interval is not None and time.monotonic() - last_save >= interval:
            checkpoint.save(ckpt, renderer, ident, extra)
            last_save = time.monotonic()
        return stop.requested

    name = Path(job.scene).name + "".join(f" {k}={v}" for k, v in job.swept.items())
    progress = Progress(position + name, renderer.samples_done, spp, output.quiet)
    if hasattr(renderer, "tile_list"):
        progress.tiles_total = len(renderer.tile_list)
        renderer.on_tile = progress.tile
    failed = None
    try:
        result = renderer.render(None if spp is None else max(spp - renderer.samples_done, 0),
                                 progress=progress.update, stop=after_pass, time_limit=render.time_limit,
                                 target_error=render.target_error, min_spp=render.min_spp)
    except WorkersFailed as exc:        # every device (worker) failed: keep what every pixel has
        failed, result = exc, exc.result
    finally:
        progress.close()
    result.info["spp_requested"] = spp or 0     # the total asked for, across resumed sessions
    complete = result.complete
    if interval is not None and (not complete or output.keep_checkpoint):
        checkpoint.save(ckpt, renderer, ident, extra)
    layers = None
    if out.suffix.lower() == ".exr":
        layers = {"variance": result.variance}
        if scene.model.integrator.moment:   # Mitsuba's moment integrator: the samples' second moment too
            layers["m2"] = result.second_moment
    write_image(out, result.image, result.metadata, layers)
    if complete and not output.keep_checkpoint and ckpt.is_file():
        ckpt.unlink()
    job.spp, job.seconds = result.spp, result.seconds
    if failed is not None:
        kept = f" and {ckpt} (continue with --resume)" if interval is not None else ""
        raise VolclError(f"{failed}; wrote the image of the {result.spp} spp every pixel has to {out}{kept}")
    if complete:
        job.status = f"ok (resumed at {resumed_at} spp)" if resumed_at else "ok"
    else:
        job.status = f"interrupted ({result.spp} of {spp or '?'} spp)"
        kept = f" and {ckpt} (continue with --resume)" if interval is not None else ""
        print(f"volcl: interrupted after {result.spp} spp; wrote {out}{kept}", file=sys.stderr, flush=True)
    print(f"{out}: {result.spp} spp in {result.seconds:.2f} s ({_STOPPED[result.stop_reason]}), "
          f"{result.samples_per_second / 1e6:.2f} M samples/s, relative error {100 * result.rel_error:.2f}%, "
          f"invalid samples {result.invalid}, tracking cut-offs {result.tracking_cutoffs}, {_devices_text(result)}, "
          f"features {result.stats['features']}", flush=True)


def _devices_text(result) -> str:
    """'device D' or 'devices D1 (52%), D2 (48%)', with the devices that failed."""
    if not result.shares:
        return f"device {result.device}"
    parts = [f"{label} ({100 * share:.0f}%)" for label, share in result.shares.items()]
    failed = [f"{label} failed: {why}" for label, why in result.info.get("failures", [])]
    noun = "workers" if result.info.get("cluster") else "devices"
    return f"{noun} {', '.join(parts)}" + (f" [{'; '.join(failed)}]" if failed else "")


_STOPPED = {"spp": "spp reached", "time": "time limit reached", "error": "target error reached",
            "stopped": "interrupted", "failed": "every device failed"}


def print_table(jobs: list[Job], file=sys.stdout):
    rows = [("scene", "output", "spp", "seconds", "status")]
    for j in jobs:
        rows.append((j.label, str(j.output), "-" if j.spp is None else str(j.spp),
                     "-" if j.seconds is None else f"{j.seconds:.2f}", j.status))
    widths = [max(len(r[i]) for r in rows) for i in range(4)]
    for r in rows:
        print("  ".join(c.ljust(w) if i != 2 and i != 3 else c.rjust(w)
                        for i, (c, w) in enumerate(zip(r[:4], widths))) + "  " + r[4], file=file)
    for j in jobs:
        if j.failed:
            print(f"FAILED {j.label}: {j.error}", file=file)


def run(scenes: list, device=None, scene_options: SceneOptions | None = None,
        render: RenderOptions | None = None, output: OutputOptions | None = None, scheduler=None) -> int:
    """Render every scene file of `scenes` (each once per set of a sweep) on `device` (a
    volcl.Device, a list of them, a selector such as 'all' or '0:0,0:1', or None:
    volcl.device.resolve_many), or on the workers of a Dask cluster (`scheduler`: an address,
    'local:N' or a distributed.Client; volcl.cluster). The exit status: 0, EXIT_FAILED if a scene
    failed, 128 + the signal number if interrupted."""
    from . import device as devmod
    scene_options = scene_options or SceneOptions()
    render = render or RenderOptions()
    output = output or OutputOptions()
    jobs = make_jobs(scenes, scene_options, output)
    if output.output_dir is not None:
        Path(output.output_dir).mkdir(parents=True, exist_ok=True)
    single = len(jobs) == 1
    client = None
    with StopRequest() as stop:
        try:
            if scheduler is not None:
                from . import cluster
                client = cluster.connect(scheduler)
                devices = None
                cluster.wait_for_workers(client)
                workers = cluster.describe(client)
                print(f"volcl: cluster {client.scheduler.address}: {workers}", file=sys.stderr, flush=True)
            else:
                devices = devmod.resolve_many(device)
            for i, job in enumerate(jobs):
                if stop.requested:
                    break
                position = f"[{i + 1}/{len(jobs)}] " if len(jobs) > 1 else ""
                executor = None if client is None else cluster.DaskExecutor(client)
                try:
                    render_job(job, devices, stop, scene_options, render, output, executor, position)
                except Exception as exc:
                    if single:
                        raise
                    job.status = "FAILED"
                    job.error = str(exc) if isinstance(exc, VolclError) else f"{type(exc).__name__}: {exc}"
                    print(f"volcl: error: {job.label}: {job.error}", file=sys.stderr, flush=True)
                    if output.verbose and not isinstance(exc, VolclError):
                        traceback.print_exc()
                finally:
                    if executor is not None:
                        executor.close()
        finally:
            if client is not None and not isinstance(scheduler, type(client)):
                cluster.close(client)
    if not single:
        done = sum(j.status.startswith(("ok", "done earlier")) for j in jobs)
        print(f"\n{done} of {len(jobs)} scenes rendered")
        print_table(jobs)
    if stop.requested:
        left = [j.label for j in jobs if j.status == "not rendered"]
        if left:
            print(f"volcl: interrupted; not rendered: {', '.join(left)}", file=sys.stderr)
        return stop.exit_status
    return EXIT_FAILED if any(j.failed for j in jobs) else 0
