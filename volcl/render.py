"""Rendering on the device: upload the packed scene once, launch one sample pass at a time,
accumulate on the device, and read back the mean image with its per-pixel variance.

Accumulation layout. The device keeps `slots` accumulators per pixel (several when the image is
too small to fill the device with one sample per pixel). Sample index i of a pixel always lands in
slot i % slots, and each slot adds its samples in increasing sample index, so the float32 sums,
and with them the image, are bit-identical however the samples were grouped: one render() call or
many, a checkpoint restored in another process, any launch size. `slots` depends on the image
size only, never on the device or on timing. (A different `slots` partitions the samples
differently and changes the last bits; the Renderer's `slots` argument exists for tests.)
"""
from __future__ import annotations

import hashlib
import math
import time
from dataclasses import dataclass, field

import numpy as np

from . import device as devmod
from .accuracy import relative_standard_error
from .device import cl
from .estimator import Estimator
from .features import describe
from .pack import pack
from .program import build_program, build_seconds, note_build
from .scene.model import Scene

# Work items per launch: enough to fill a device, small enough to keep a launch short.
MIN_ITEMS = 1 << 14
MAX_ITEMS = 1 << 19
# GPUs that drive a display reset kernels running longer than a watchdog limit (about 2 s on
# Windows, 5 s on X11), and a desktop stutters long before that: on a GPU each launch is kept
# under this many seconds by sizing the next launch from the time the last one took.
GPU_LAUNCH_SECONDS = 0.1
_DEFAULT = object()
# Samples per pixel before a target error is trusted: with fewer, a pixel whose rare bright paths
# have not turned up yet reports a small variance along with its small mean (README, "Accuracy").
MIN_SPP_FOR_ERROR = 16


@dataclass
class RenderResult:
    image: np.ndarray           # (h, w, 3) float32 mean radiance
    variance: np.ndarray        # (h, w, 3) variance of that mean, from the samples themselves
    spp: int
    invalid: int                # samples that came out NaN, infinite or negative and were left out
    seconds: float
    device: str
    features: dict
    build_seconds: float
    stats: dict = field(default_factory=dict)
    # medium segments whose delta / ratio tracking hit its step bound and was cut short (each a
    # biased estimate; never happens in ordinary scenes, see kernels/media.h)
    tracking_cutoffs: int = 0
    stop_reason: str = "spp"    # the rule that ended the render: 'spp', 'time' or 'error'

    @property
    def rel_error(self) -> float:
        """The image's estimated relative standard error (volcl.accuracy.relative_standard_error)."""
        return relative_standard_error(self.image, self.variance)

    @property
    def samples_per_second(self) -> float:
        h, w = self.image.shape[:2]
        return h * w * self.spp / self.seconds if self.seconds > 0 else float("inf")


class Renderer:
    """A scene uploaded to one device with its program built, ready for sample passes.

    `slots` and `tile` (pixels per launch) override the defaults, for tests. `launch_seconds` is
    the time budget of one launch: by default GPU_LAUNCH_SECONDS on GPUs and none elsewhere (a CPU
    device runs fixed launches of up to MAX_ITEMS work items, with no timing in between).
    """

    ARG_ORDER = ("nodes", "leaves", "triangles", "normals", "spheres", "shapes", "bsdfs", "lights",
                 "light_tri_cdf", "light_tris", "media", "grids", "grid_data", "params", "filter_table")

    def __init__(self, scene: Scene, device: devmod.DeviceInfo | None = None, features: dict | None = None,
                 seed: int | None = None, slots: int | None = None, tile: int | None = None,
                 launch_seconds=_DEFAULT, majorant_cells: int | None = None, majorant_scale: float = 1.0,
                 estimator: Estimator | None = None):
        self.scene = scene
        self.device = device or devmod.choose()
        self.estimator = estimator or Estimator()
        features, estimator_params = self.estimator.resolve(scene, features)
        self.packed = pack(scene, features, majorant_cells=majorant_cells, majorant_scale=majorant_scale)
        for name, value in estimator_params.items():
            self.packed.arrays["params"][name] = value
        # a scene too large for the device is the user's to fix: say so before uploading anything
        # (accumulators: sums, sums_sq, invalid, cutoffs for at least MIN_ITEMS slots, see below)
        devmod.check_fits(self.device, {name: self.packed.arrays[name].nbytes for name in self.ARG_ORDER},
                          accumulator_bytes=40 * max(scene.camera.width * scene.camera.height, MIN_ITEMS))
        if seed is not None:
            self.packed.arrays["params"]["seed"] = seed & 0xFFFFFFFF
        self.seed = int(self.packed.arrays["params"]["seed"][0])
        self.ctx = cl.Context([self.device.device])
        self.queue = cl.CommandQueue(self.ctx)
        t0 = time.perf_counter()
        self.program = build_program(self.ctx, self.packed.features)
        self.build_seconds = build_seconds(self.ctx, self.packed.features) or (time.perf_counter() - t0)
        self.cold_build_seconds, self.build_was_cold = note_build(self.device.name, self.packed.features,
                                                                  self.build_seconds)
        self.kernel = cl.Kernel(self.program, "render_pass")
        mf = cl.mem_flags
        self.buffers = [cl.Buffer(self.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR,
                                  hostbuf=np.ascontiguousarray(self.packed.arrays[name]))
                        for name in self.ARG_ORDER]
        self.width, self.height = scene.camera.width, scene.camera.height
        self.npix = self.width * self.height
        self.slots = int(slots) if slots else int(np.clip(MIN_ITEMS // self.npix, 1, 4096))
        if launch_seconds is _DEFAULT:
            launch_seconds = GPU_LAUNCH_SECONDS if self.device.kind == "gpu" else None
        self.launch_seconds = launch_seconds
        if tile:
            self.tile = int(tile)
        elif launch_seconds is None:
            self.tile = max(1, MAX_ITEMS // self.slots)
        else:                       # start small; _launch grows it towards the time budget
            self.tile = max(1, (MIN_ITEMS >> 2) // self.slots)
        self.adaptive = launch_seconds is not None and not tile
        self.launches = 0
        n = self.slots * self.npix
        self.sums = cl.Buffer(self.ctx, mf.READ_WRITE, 16 * n)
        self.sums_sq = cl.Buffer(self.ctx, mf.READ_WRITE, 16 * n)
        self.invalid = cl.Buffer(self.ctx, mf.READ_WRITE, 4 * n)
        self.cutoffs = cl.Buffer(self.ctx, mf.READ_WRITE, 4 * n)
        self.reset()

    def reset(self):
        for buf in (self.sums, self.sums_sq, self.invalid, self.cutoffs):
            cl.enqueue_fill_buffer(self.queue, buf, np.zeros(1, np.float32), 0, buf.size)
        self.samples_done = 0
        self.seconds = 0.0

    def data_hash(self) -> str:
        """sha256 of everything the kernel reads except the seed: two renderers with equal hashes
        (and equal seeds, features and kernel sources) compute the same samples."""
        h = hashlib.sha256()
        for name in self.ARG_ORDER:
            a = np.array(self.packed.arrays[name])
            if name == "params":
                a["seed"] = 0
            h.update(name.encode())
            h.update(np.ascontiguousarray(a).tobytes())
        return h.hexdigest()

    def _launch(self, sample_base: int, slots: int, accum):
        """Samples sample_base .. sample_base + slots - 1 of every pixel, into slots 0 .. slots - 1
        of the accumulators `accum`, in launches of `tile` pixels."""
        first = 0
        while first < self.npix:
            count = min(self.tile, self.npix - first)
            self.kernel.set_args(*self.buffers, *accum,
                                 np.uint32(sample_base), np.int32(first), np.int32(count), np.int32(slots))
            t0 = time.perf_counter()
            event = cl.enqueue_nd_range_kernel(self.queue, self.kernel, (count * slots,), None)
            self.launches += 1
            if self.adaptive:
                event.wait()
                self._resize_tile(count * slots, time.perf_counter() - t0)
            first += count

    def _resize_tile(self, items: int, seconds: float):
        """Next launch's pixel count: aim at half the budget (tiles differ in cost across the
        image), grow at most 2x per launch, shrink at once. Launch sizes are powers of two work
        items, so a driver that compiles per launch size (PoCL does) sees few sizes."""
        rate = items / max(seconds, 1e-6)
        want = max(1.0, 0.5 * self.launch_seconds * rate)
        items_next = 1 << int(np.floor(np.log2(want)))
        self.tile = int(np.clip(items_next // self.slots, 1, min(2 * self.tile, self.npix)))

    def _pass(self, done: int, count: int):
        """Add samples done .. done + count - 1 (all in one round of the slots) to every pixel."""
        first_slot = done % self.slots
        assert first_slot + count <= self.slots
        if first_slot == 0:
            self._launch(done, count, (self.sums, self.sums_sq, self.invalid, self.cutoffs))
            return
        # Slots first_slot.. of the accumulators: the kernel writes slots from 0, so those rows go
        # through scratch buffers and back; the kernel does the same float operations on the same
        # values as it would in place.
        n = count * self.npix
        mf = cl.mem_flags
        rows = [(self.sums, 16), (self.sums_sq, 16), (self.invalid, 4), (self.cutoffs, 4)]
        scratch = [cl.Buffer(self.ctx, mf.READ_WRITE, size * n) for _, size in rows]
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
        if spp is None and time_limit is None and target_error is None:
            spp = self.scene.spp
        target = None if spp is None else self.samples_done + spp
        check = None if target_error is None else _ErrorCheck(target_error, max(min_spp, 1))
        reason = "spp"
        t_start = time.perf_counter()
        while target is None or self.samples_done < target:
            t0 = time.perf_counter()
            count = self.slots - self.samples_done % self.slots
            if target is not None:
                count = min(count, target - self.samples_done)
            if check is not None:
                count = max(1, min(count, check.next_at - self.samples_done))
            self._pass(self.samples_done, count)
            self.queue.finish()
            self.samples_done += count
            self.seconds += time.perf_counter() - t0
            if progress is not None:
                progress(count)
            if time_limit is not None and time.perf_counter() - t_start >= time_limit:
                reason = "time"
                break
            if check is not None and self.samples_done >= check.next_at and check.reached(self):
                reason = "error"
                break
            if stop is not None and stop():
                reason = "stopped"
                break
        result = self.result()
        result.stop_reason = reason
        return result

    def state(self) -> dict:
        """The accumulated state, raw: what a checkpoint stores to continue bit for bit."""
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
        return {"sums": sums, "sums_sq": sums_sq, "invalid": invalid, "cutoffs": cutoffs,
                "samples_done": self.samples_done, "seconds": self.seconds, "slots": self.slots,
                "width": self.width, "height": self.height, "seed": self.seed}

    def restore(self, state: dict):
        """Continue from state() of a renderer of the same scene, seed and image size."""
        for key in ("slots", "width", "height", "seed"):
            if int(state[key]) != getattr(self, key):
                raise ValueError(f"state has {key} {int(state[key])}, this renderer {getattr(self, key)}")
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

    def result(self) -> RenderResult:
        st = self.state()
        s = st["sums"].astype(np.float64).reshape(self.slots, self.npix, 4).sum(0)
        ss = st["sums_sq"].astype(np.float64).reshape(self.slots, self.npix, 4).sum(0)
        count = s[:, 3:4]
        safe = np.maximum(count, 1)
        mean = s[:, :3] / safe
        sample_var = np.maximum(ss[:, :3] / safe - mean ** 2, 0) * safe / np.maximum(safe - 1, 1)
        var_mean = sample_var / safe
        shape = (self.height, self.width, 3)
        return RenderResult(
            image=mean.reshape(shape).astype(np.float32), variance=var_mean.reshape(shape).astype(np.float32),
            spp=self.samples_done, invalid=int(st["invalid"].sum()), seconds=self.seconds,
            device=f"{self.device.key} {self.device.name}", features=self.packed.features,
            build_seconds=self.build_seconds, tracking_cutoffs=int(st["cutoffs"].sum(dtype=np.uint64)),
            stats={"triangles": self.packed.triangle_count, "spheres": self.packed.sphere_count,
                   "bvh_seconds": self.packed.bvh_seconds, "features": describe(self.packed.features),
                   **self.packed.stats})


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


def render(scene: Scene, spp: int | None = None, device=None, features=None, seed=None, progress=None,
           time_limit=None, target_error=None, estimator: Estimator | None = None, majorant_cells=None,
           majorant_scale=1.0) -> RenderResult:
    r = Renderer(scene, device=device, features=features, seed=seed, estimator=estimator,
                 majorant_cells=majorant_cells, majorant_scale=majorant_scale)
    if spp is None and time_limit is None and target_error is None:
        spp = scene.spp
    return r.render(spp, progress=progress, time_limit=time_limit, target_error=target_error)
