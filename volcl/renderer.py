"""Rendering on one device: launch sample passes over a tile (by default the whole image), one or,
on CPUs where a pass is small, several to a launch, accumulate on the device, and read back the
mean image with its per-pixel variance.

Accumulation layout. The device keeps `slots` accumulators per pixel (several when the image is
too small to fill the device with one sample per pixel). Sample index i of a pixel always lands in
slot i % slots, and each slot adds its samples in increasing sample index, so the float32 sums,
and with them the image, are bit-identical however the samples were grouped: one render() call or
many, a checkpoint restored in another process, any launch size, any tile. `slots` depends on the
size of the whole image only (volcl.tiles.accumulator_slots), never on the tile, the device or on
timing. (A different `slots` partitions the samples differently and changes the last bits; the
Renderer's `slots` argument exists for tests.)

What a Renderer owns: its accumulators, its RenderParams buffer (seed and estimator switches) and
its kernel object. What it shares: the scene's buffers on the device (volcl.prepared.Scene.upload)
and the device's context, queue and built programs (volcl.device.Device).
"""
from __future__ import annotations

import hashlib
import math
import time

import numpy as np

from . import __version__
from . import device as devmod
from . import wavefront
from .errors import VolclError
from .estimator import Estimator
from .features import describe
from .grids import grid_cost_notes
from .opencl import cl
from .pack import ARG_ORDER
from .prepared import Scene as PreparedScene
from .program import note_build, sources_hash
from .result import RenderResult
from .scene.model import Scene as ModelScene
from .tiles import MIN_ITEMS, Tile, accumulator_slots, slice_state

# Work items per launch: enough to fill a device (MIN_ITEMS), small enough to keep a launch short.
MAX_ITEMS = 1 << 19
# GPUs that drive a display reset kernels running longer than a watchdog limit (about 2 s on
# Windows, 5 s on X11), and a desktop stutters long before that: on a GPU each launch is kept
# under this many seconds by sizing the next launch from the time the last one took.
GPU_LAUNCH_SECONDS = 0.1
_DEFAULT = object()
# Samples per pixel before a target error is trusted: with fewer, a pixel whose rare bright paths
# have not turned up yet reports a small variance along with its small mean (README, "Accuracy").
MIN_SPP_FOR_ERROR = 16
# On a device without a launch time budget (CPUs), render() runs several whole rounds of the slots
# in one launch once it knows how long a round takes, up to this long, so that a time limit, an
# interrupt or the progress bar waits little for the launch under way. A pass of its own costs a
# launch and a wait for it (on PoCL's CPU device 5-9% of a 128x128 render at one round per launch).
MULTI_PASS_SECONDS = 0.25
# bytes of accumulators per pixel and slot: sums and sums of squares (float4 each), invalid and
# cut-off counts (uint each)
ACCUMULATOR_BYTES = 40


class Renderer:
    """A render in progress on one device: a scene (a volcl.prepared.Scene, or a model Scene,
    which is then packed and uploaded for this renderer alone), a seed, an estimator and a tile,
    accumulating sample passes.

    `slots` and `launch_pixels` (pixels per launch) override the defaults, for tests.
    `engine`: "megakernel", "wavefront" (volcl.wavefront's stage kernels on CPUs: homogeneous media,
    or small scenes without media; the same samples), "packet" (volcl.packets: a packet of work items
    per work item on CPUs, its rays traced together in the SIMD lanes, for small scenes of opaque
    surfaces; the same samples), or "auto": the packet renderer where volcl.packets.supported(),
    else the wavefront renderer where volcl.wavefront.pays().
    `launch_seconds` is the time budget of one launch: by default GPU_LAUNCH_SECONDS on GPUs and
    none elsewhere (a CPU device runs fixed launches of up to MAX_ITEMS work items, with no timing
    in between). `majorant_cells` applies when a model Scene is packed here.
    """

    ARG_ORDER = ARG_ORDER

    def __init__(self, scene, device=None, features: dict | None = None, seed: int | None = None,
                 slots: int | None = None, launch_pixels: int | None = None, launch_seconds=_DEFAULT,
                 majorant_cells: int | None = None, majorant_scale: float = 1.0,
                 estimator: Estimator | None = None, tile=None, engine: str = "auto"):
        if isinstance(scene, ModelScene):
            scene = PreparedScene(scene, majorant_cells=majorant_cells)
        elif majorant_cells is not None:
            raise ValueError("majorant_cells is a packing choice: give it to volcl.prepared.Scene")
        self.prepared = scene
        self.scene = scene.model
        self.version = scene.version
        self.device = devmod.resolve(device)
        self.estimator = estimator or Estimator()
        self.features, self.params = render_setup(scene, self.estimator, features, seed, majorant_scale)
        self.seed = int(self.params["seed"])
        self.width, self.height = self.scene.camera.width, self.scene.camera.height
        self.tile = Tile.of(tile, self.width, self.height)
        self.npix = self.tile.pixels
        self.slots = int(slots) if slots else accumulator_slots(self.width, self.height)
        # a scene too large for the device is the user's to fix: say so before uploading anything
        devmod.check_fits(self.device, scene.buffer_sizes(),
                          accumulator_bytes=ACCUMULATOR_BYTES * max(self.slots * self.npix, MIN_ITEMS),
                          notes=grid_cost_notes(scene.packed.stats.get("sparse_grids", ())))
        self.uploaded = scene.upload(self.device)
        ctx = self.device.ctx
        self.queue = self.device.queue
        # only the chosen engine's programs are built: a wavefront render never launches the megakernel
        builds = self.device.builds
        self.wavefront, sources = wavefront.start(engine, self.features, self.packed, self.params, self.device)
        if self.wavefront is None:     # start() built its program, or found it built
            self.program = self.device.program(self.features)
            self.kernel = cl.Kernel(self.program, "render_pass")
            self.group_items = devmod.group_items([self.kernel], self.device.device)
        else:
            self.group_items = self.wavefront.group_items
        self._note_builds(builds, sources)
        mf = cl.mem_flags
        self.params_buffer = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=self.params.reshape(1))
        if launch_seconds is _DEFAULT:
            launch_seconds = GPU_LAUNCH_SECONDS if self.device.kind == "gpu" else None
        self.launch_seconds = launch_seconds
        if launch_pixels:
            self.launch_pixels = int(launch_pixels)
        elif launch_seconds is None:
            self.launch_pixels = max(1, MAX_ITEMS // self.slots)
        else:                       # start small; _launch grows it towards the time budget
            self.launch_pixels = max(1, (MIN_ITEMS >> 2) // self.slots)
        self.adaptive = launch_seconds is not None and not launch_pixels
        self.launches = 0
        n = self.slots * self.npix
        self.sums = cl.Buffer(ctx, mf.READ_WRITE, 16 * n)
        self.sums_sq = cl.Buffer(ctx, mf.READ_WRITE, 16 * n)
        self.invalid = cl.Buffer(ctx, mf.READ_WRITE, 4 * n)
        self.cutoffs = cl.Buffer(ctx, mf.READ_WRITE, 4 * n)
        self.spp_requested = 0
        self.reset()

    def _note_builds(self, builds: int, sources):
        """Whether this render had programs built for it (the device's count passed `builds`), and
        their time (programs `sources`, (source file, extra options) pairs, of this feature set),
        logged as cold or warm (volcl.program)."""
        self.built = self.device.builds > builds
        if self.built:
            self.build_seconds = self.device.programs.seconds_of(self.features, sources)
            self.cold_build_seconds, self.build_was_cold = note_build(
                self.device.name, self.features, self.build_seconds, "" if self.wavefront is None else "wavefront")
        else:
            self.build_seconds, self.cold_build_seconds, self.build_was_cold = 0.0, None, False

    @property
    def engine(self) -> str:
        return "megakernel" if self.wavefront is None else getattr(self.wavefront, "engine", "wavefront")

    @property
    def packed(self):
        return self.prepared.packed

    def reset(self):
        # zeros written from the host rather than clEnqueueFillBuffer: Oclgrind 21.10 takes a
        # filled buffer for uninitialized memory and reports every accumulator update
        for buf in (self.sums, self.sums_sq, self.invalid, self.cutoffs):
            cl.enqueue_copy(self.queue, buf, np.zeros(buf.size // 4, np.uint32))
        self.samples_done = 0
        self.seconds = 0.0

    def data_hash(self) -> str:
        """sha256 of everything the kernel reads except the seed: two renderers with equal hashes
        (and equal seeds, features and kernel sources) compute the same samples."""
        return data_hash(self.params, self.packed)

    def _launch(self, sample_base: int, slots: int, accum, passes: int = 1):
        """Samples sample_base .. sample_base + slots - 1 of every pixel of the tile, into slots
        0 .. slots - 1 of the accumulators `accum`, in launches of `launch_pixels` pixels; with
        passes > 1 (slots then all of them), that many whole rounds of the slots in each launch."""
        args = self.uploaded.args(self.params_buffer)
        t = self.tile
        first = 0
        while first < self.npix:
            count = min(self.launch_pixels, self.npix - first)
            launch = (np.uint32(sample_base), np.int32(t.x), np.int32(t.y), np.int32(t.width), np.int32(self.npix),
                      np.int32(first), np.int32(count), np.int32(slots), np.int32(passes))
            if self.wavefront is not None:
                self.wavefront.run(args, accum, launch, count * slots)
                self.launches += 1
                first += count
                continue
            self.kernel.set_args(*args, *accum, *launch)
            t0 = time.perf_counter()
            items = -(-count * slots // self.group_items) * self.group_items
            event = cl.enqueue_nd_range_kernel(self.queue, self.kernel, (items,), (self.group_items,))
            self.launches += 1
            if self.adaptive:
                event.wait()
                self._resize_launch(count * slots, time.perf_counter() - t0)
            first += count

    def _resize_launch(self, items: int, seconds: float):
        """Next launch's pixel count: aim at half the budget (parts of the image differ in cost),
        grow at most 2x per launch, shrink at once. Launch sizes are powers of two work items, so
        a driver that compiles per launch size (PoCL does) sees few sizes."""
        rate = items / max(seconds, 1e-6)
        want = max(1.0, 0.5 * self.launch_seconds * rate)
        items_next = 1 << int(np.floor(np.log2(want)))
        self.launch_pixels = int(np.clip(items_next // self.slots, 1, min(2 * self.launch_pixels, self.npix)))

    def _pass(self, done: int, count: int, passes: int = 1):
        """Add samples done .. done + count - 1 (all in one round of the slots) to every pixel; with
        passes > 1 (count then a whole round, from its start), that many rounds in each launch."""
        first_slot = done % self.slots
        assert first_slot + count <= self.slots
        assert passes == 1 or (first_slot == 0 and count == self.slots)
        if first_slot == 0:
            self._launch(done, count, (self.sums, self.sums_sq, self.invalid, self.cutoffs), passes)
            return
        # Slots first_slot.. of the accumulators: the kernel writes slots from 0, so those rows go
        # through scratch buffers and back; the kernel does the same float operations on the same
        # values as it would in place.
        n = count * self.npix
        mf = cl.mem_flags
        rows = [(self.sums, 16), (self.sums_sq, 16), (self.invalid, 4), (self.cutoffs, 4)]
        scratch = [cl.Buffer(self.device.ctx, mf.READ_WRITE, size * n) for _, size in rows]
        for (buf, size), tmp in zip(rows, scratch):
            cl.enqueue_copy(self.queue, tmp, buf, src_offset=size * first_slot * self.npix, byte_count=size * n)
        self._launch(done, count, scratch)
        for (buf, size), tmp in zip(rows, scratch):
            cl.enqueue_copy(self.queue, buf, tmp, dst_offset=size * first_slot * self.npix, byte_count=size * n)

    def render(self, spp: int | None = None, progress=None, time_limit: float | None = None,
               target_error: float | None = None, min_spp: int = MIN_SPP_FOR_ERROR, stop=None) -> RenderResult:
        """Add samples per pixel until the first of the given rules is met, and return the image of
        everything accumulated so far:
          spp           this many more samples per pixel;
          time_limit    this many seconds spent in this call;
          target_error  the image's estimated relative standard error (RenderResult.rel_error) at
                        or below this, checked between passes once min_spp samples are in;
          stop()        a callback returning true (checked between passes: signals, checkpoints).
        With none of spp, time_limit and target_error, the scene's own spp. RenderResult.stop_reason
        names the rule that ended it; progress(n) is called after each pass with the samples added."""
        target = render_target(self, spp, time_limit, target_error)
        rules = StopRules(time_limit, target_error, min_spp, stop)
        reason = "spp"
        round_seconds = None       # of one whole round of the slots, as last measured
        while target is None or self.samples_done < target:
            t0 = time.perf_counter()
            done = self.samples_done
            count = self.slots - done % self.slots
            if target is not None:
                count = min(count, target - done)
            count = rules.cap(done, count)
            rounds = 1
            if count == self.slots and round_seconds is not None:
                limit = MULTI_PASS_SECONDS if rules.time_limit is None else min(MULTI_PASS_SECONDS, rules.seconds_left())
                rounds = max(1, int(limit / max(round_seconds, 1e-9)))
                if target is not None:
                    rounds = min(rounds, (target - done) // self.slots)
                rounds = max(1, rules.cap(done, rounds * self.slots) // self.slots)
            count = self._step(count, rounds)
            self.queue.finish()
            self.samples_done += count
            seconds = time.perf_counter() - t0
            self.seconds += seconds
            if count % self.slots == 0:
                round_seconds = seconds / (count // self.slots)
            if progress is not None:
                progress(count)
            reason = rules.reason(self) or reason
            if reason != "spp":
                break
        result = self.result()
        result.stop_reason = reason
        return result

    def state(self) -> dict:
        """The accumulated state, raw: what a checkpoint stores to continue bit for bit. `tile` is
        (x, y, width, height); volcl.tiles.merge_states joins the states of tiles."""
        n = self.slots * self.npix
        sums = np.empty((n, 4), np.float32)
        sums_sq = np.empty((n, 4), np.float32)
        invalid = np.empty(n, np.uint32)
        cutoffs = np.empty(n, np.uint32)
        cl.enqueue_copy(self.queue, sums, self.sums)
        cl.enqueue_copy(self.queue, sums_sq, self.sums_sq)
        cl.enqueue_copy(self.queue, invalid, self.invalid)
        cl.enqueue_copy(self.queue, cutoffs, self.cutoffs)
        self.queue.finish()
        t = self.tile
        return {"sums": sums, "sums_sq": sums_sq, "invalid": invalid, "cutoffs": cutoffs,
                "samples_done": self.samples_done, "seconds": self.seconds, "slots": self.slots,
                "width": self.width, "height": self.height, "seed": self.seed,
                "tile": (t.x, t.y, t.width, t.height)}

    def restore(self, state: dict):
        """Continue from state() of a renderer of the same scene, seed and image size: of this
        tile, or of the whole image (of which this tile's part is taken)."""
        for key in ("slots", "width", "height", "seed"):
            if int(state[key]) != getattr(self, key):
                raise ValueError(f"state has {key} {int(state[key])}, this renderer {getattr(self, key)}")
        whole = (0, 0, self.width, self.height)
        held = tuple(int(v) for v in state.get("tile", whole))
        mine = (self.tile.x, self.tile.y, self.tile.width, self.tile.height)
        if held != mine:
            if held != whole:
                raise ValueError(f"state holds tile {held}, this renderer renders {mine}")
            state = slice_state(state, self.tile)
        n = self.slots * self.npix
        arrays = [(self.sums, "sums", np.float32, (n, 4)), (self.sums_sq, "sums_sq", np.float32, (n, 4)),
                  (self.invalid, "invalid", np.uint32, (n,)), (self.cutoffs, "cutoffs", np.uint32, (n,))]
        for buf, key, dtype, shape in arrays:
            a = np.ascontiguousarray(state[key])
            if a.dtype != dtype or a.shape != shape:
                raise ValueError(f"state {key}: {a.dtype}{a.shape}, expected {np.dtype(dtype)}{shape}")
            cl.enqueue_copy(self.queue, buf, a)
        self.queue.finish()
        self.samples_done = int(state["samples_done"])
        self.seconds = float(state["seconds"])

    def advance(self, spp: int):
        """Add `spp` samples per pixel in passes, with no stopping rules and no read-back (the
        tiles of a render on several devices advance so, volcl.rounds). On a device without a
        launch time budget (CPUs), whole rounds of the slots go several to a launch, up to
        MAX_ITEMS samples: a small tile's pass is too short to pay a launch of its own (on PoCL's
        CPU device a launch costs about half a millisecond, a 32x32 tile's pass of fog a few)."""
        end = self.samples_done + spp
        while self.samples_done < end:
            t0 = time.perf_counter()
            done = self.samples_done
            count = self._step(min(self.slots - done % self.slots, end - done), (end - done) // self.slots)
            self.queue.finish()
            self.samples_done += count
            self.seconds += time.perf_counter() - t0

    def _step(self, count: int, rounds: int) -> int:
        """Add samples samples_done .. samples_done + count - 1 (within one round of the slots), or,
        where count is a whole round, up to `rounds` whole rounds in one launch on a device without
        a launch time budget whose launches hold the whole tile (each work item then renders its
        slot's samples of those rounds in turn, adding them in the order separate passes would).
        Returns the samples per pixel added."""
        passes = 1
        if count == self.slots and not self.adaptive and self.launch_pixels >= self.npix:
            passes = max(1, min(rounds, MAX_ITEMS // (self.slots * self.npix)))
        self._pass(self.samples_done, count, passes)
        return passes * count

    @property
    def device_label(self) -> str:
        return self.device.label

    def result(self) -> RenderResult:
        return build_result(self, self.state(), self.tile)


def render_setup(prepared: PreparedScene, estimator: Estimator, features: dict | None = None,
                 seed: int | None = None, majorant_scale: float = 1.0) -> tuple[dict, np.ndarray]:
    """(feature flags to compile, RenderParams record) of a render of `prepared` with this
    estimator and seed (the scene's seed when None); every tile and device of a render shares them."""
    packed = prepared.packed
    feats, estimator_params = estimator.resolve(prepared.model, features, detected=packed.features)
    params = packed.params.copy()
    for name, value in estimator_params.items():
        params[name] = value
    params["majorant_scale"] = majorant_scale
    if seed is not None:
        params["seed"] = seed & 0xFFFFFFFF
    return feats, params


def data_hash(params: np.ndarray, packed) -> str:
    """sha256 of everything the kernel reads except the seed (Renderer.data_hash)."""
    h = hashlib.sha256()
    for name in ARG_ORDER:
        a = np.array(params.reshape(1) if name == "params" else packed.arrays[name])
        if name == "params":
            a["seed"] = 0
        h.update(name.encode())
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def build_result(render, state: dict, tile: Tile) -> RenderResult:
    """The RenderResult of an accumulator state (Renderer.state) of `tile`, described by `render`
    (a Renderer, or a volcl.rounds.TiledRender for a whole image made on several devices)."""
    slots, npix = int(state["slots"]), tile.pixels
    s = state["sums"].astype(np.float64).reshape(slots, npix, 4).sum(0)
    ss = state["sums_sq"].astype(np.float64).reshape(slots, npix, 4).sum(0)
    count = s[:, 3:4]
    safe = np.maximum(count, 1)
    mean = s[:, :3] / safe
    sample_var = np.maximum(ss[:, :3] / safe - mean ** 2, 0) * safe / np.maximum(safe - 1, 1)
    var_mean = sample_var / safe
    shape = (tile.height, tile.width, 3)
    second_moment = (ss[:, :3] / safe).reshape(shape).astype(np.float32)
    packed = render.packed
    whole = tile.pixels == render.width * render.height
    info = dict(render.prepared.info, estimator=render.estimator.describe(), kernel_sha256=sources_hash(),
                version=__version__, spp_requested=render.spp_requested)
    return RenderResult(
        image=mean.reshape(shape).astype(np.float32), variance=var_mean.reshape(shape).astype(np.float32),
        spp=render.samples_done, invalid=int(state["invalid"].sum()), seconds=render.seconds,
        device=render.device_label, features=render.features,
        build_seconds=render.build_seconds, tracking_cutoffs=int(state["cutoffs"].sum(dtype=np.uint64)),
        stats={"triangles": packed.triangle_count, "spheres": packed.sphere_count,
               "bvh_seconds": packed.bvh_seconds, "features": describe(render.features), **packed.stats},
        seed=render.seed, tile=None if whole else tile, image_size=(render.width, render.height), info=info,
        second_moment=second_moment)


def render_target(render, spp, time_limit, target_error) -> int | None:
    """The spp at which a progressive render's call ends (None: another rule ends it), recorded as
    its spp_requested; the scene's own spp when no rule is given. `render` is a Renderer or a
    TiledRender; one whose scene was updated since it began is refused."""
    if render.prepared.version != render.version:
        raise VolclError("the scene was updated after this render began, so its samples would mix two "
                         "scenes; start a new render (volcl.render does) to see the update")
    if spp is None and time_limit is None and target_error is None:
        spp = render.scene.spp
    target = None if spp is None else render.samples_done + spp
    render.spp_requested = target or 0
    return target


class StopRules:
    """The rules that end a progressive render besides its spp, checked between passes (on one
    device) or rounds (volcl.rounds), in this order: time_limit seconds since the render began,
    the image's estimated relative error at or below target_error (checked from min_spp samples
    on, at spp counts _ErrorCheck picks), and stop() returning true."""

    def __init__(self, time_limit=None, target_error=None, min_spp: int = MIN_SPP_FOR_ERROR, stop=None):
        self.time_limit = time_limit
        self.check = None if target_error is None else _ErrorCheck(target_error, max(min_spp, 1))
        self.stop = stop
        self.t_start = time.perf_counter()

    def cap(self, done: int, count: int) -> int:
        """`count` samples, or fewer so as to end at the next error check."""
        return count if self.check is None else max(1, min(count, self.check.next_at - done))

    def seconds_left(self) -> float | None:
        return None if self.time_limit is None else self.time_limit - (time.perf_counter() - self.t_start)

    def reason(self, render) -> str | None:
        """'time', 'error' or 'stopped' when a rule is met by `render` (a Renderer or TiledRender)."""
        if self.time_limit is not None and self.seconds_left() <= 0:
            return "time"
        if self.check is not None and render.samples_done >= self.check.next_at and self.check.reached(render):
            return "error"
        if self.stop is not None and self.stop():
            return "stopped"
        return None


class _ErrorCheck:
    """When to read the image back to test a target error. Each check predicts, from the error's
    1/sqrt(spp) fall, the spp at which the target will be met and checks next there (at least 5%
    and at most 100% more samples later), so a render overshoots its target by little and spends
    few read-backs."""

    def __init__(self, target: float, min_spp: int):
        self.target = target
        self.next_at = min_spp
        self.last = math.inf

    def reached(self, renderer: "Renderer") -> bool:
        n = renderer.samples_done
        self.last = renderer.result().rel_error
        if self.last <= self.target:
            return True
        wanted = n * (self.last / self.target) ** 2 if math.isfinite(self.last) else 2 * n
        self.next_at = int(math.ceil(min(max(wanted, 1.05 * n, n + 1), 2 * n)))
        return False


def render(scene, spp: int | None = None, device=None, features=None, seed=None, progress=None,
           time_limit=None, target_error=None, estimator: Estimator | None = None, majorant_cells=None,
           majorant_scale=1.0, tile=None) -> RenderResult:
    """One render with every knob the renderer has (tests and benchmarks use the feature
    override and the majorant knobs); volcl.render is the documented entry point."""
    r = Renderer(scene, device=device, features=features, seed=seed, estimator=estimator,
                 majorant_cells=majorant_cells, majorant_scale=majorant_scale, tile=tile)
    return r.render(spp, progress=progress, time_limit=time_limit, target_error=target_error)
