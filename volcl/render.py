"""Rendering on the device: upload the packed scene once, launch one sample pass at a time,
accumulate on the device, and read back the mean image with its per-pixel variance."""
from __future__ import annotations

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
from .program import build_program, build_seconds
from .scene.model import Scene

# Work items per launch: enough to fill a device, small enough to keep a launch short.
MIN_ITEMS = 1 << 14
MAX_ITEMS = 1 << 19
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
    """A scene uploaded to one device with its program built, ready for sample passes."""

    ARG_ORDER = ("nodes", "prim_ids", "triangles", "normals", "spheres", "shapes", "bsdfs", "lights",
                 "light_tri_cdf", "light_tris", "media", "params", "filter_table")

    def __init__(self, scene: Scene, device: devmod.DeviceInfo | None = None, features: dict | None = None,
                 seed: int | None = None, estimator: Estimator | None = None):
        self.scene = scene
        self.device = device or devmod.choose()
        self.estimator = estimator or Estimator()
        features, estimator_params = self.estimator.resolve(scene, features)
        self.packed = pack(scene, features)
        for name, value in estimator_params.items():
            self.packed.arrays["params"][name] = value
        if seed is not None:
            self.packed.arrays["params"]["seed"] = seed & 0xFFFFFFFF
        self.seed = int(self.packed.arrays["params"]["seed"][0])
        self.ctx = cl.Context([self.device.device])
        self.queue = cl.CommandQueue(self.ctx)
        t0 = time.perf_counter()
        self.program = build_program(self.ctx, self.packed.features)
        self.build_seconds = build_seconds(self.ctx, self.packed.features) or (time.perf_counter() - t0)
        self.kernel = cl.Kernel(self.program, "render_pass")
        mf = cl.mem_flags
        self.buffers = [cl.Buffer(self.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR,
                                  hostbuf=np.ascontiguousarray(self.packed.arrays[name]))
                        for name in self.ARG_ORDER]
        self.width, self.height = scene.camera.width, scene.camera.height
        self.npix = self.width * self.height
        self.slots = int(np.clip(MIN_ITEMS // self.npix, 1, 4096))
        self.tile = max(1, MAX_ITEMS // self.slots)
        n = self.slots * self.npix
        self.sums = cl.Buffer(self.ctx, mf.READ_WRITE, 16 * n)
        self.sums_sq = cl.Buffer(self.ctx, mf.READ_WRITE, 16 * n)
        self.invalid = cl.Buffer(self.ctx, mf.READ_WRITE, 4 * n)
        self.reset()

    def reset(self):
        for buf in (self.sums, self.sums_sq, self.invalid):
            cl.enqueue_fill_buffer(self.queue, buf, np.zeros(1, np.float32), 0, buf.size)
        self.samples_done = 0
        self.seconds = 0.0

    def _launch(self, sample_base: int, slots: int):
        for first in range(0, self.npix, self.tile):
            count = min(self.tile, self.npix - first)
            self.kernel.set_args(*self.buffers, self.sums, self.sums_sq, self.invalid,
                                 np.uint32(sample_base), np.int32(first), np.int32(count), np.int32(slots))
            cl.enqueue_nd_range_kernel(self.queue, self.kernel, (count * slots,), None)

    def render(self, spp: int | None = None, progress=None, time_limit: float | None = None,
               target_error: float | None = None, min_spp: int = MIN_SPP_FOR_ERROR) -> RenderResult:
        """Add samples per pixel until the first of the given rules is met, and return the image of
        everything accumulated so far:
          spp           this many more samples per pixel;
          time_limit    this many seconds spent in this call;
          target_error  the image's estimated relative standard error (RenderResult.rel_error) at
                        or below this, checked between passes once min_spp samples are in.
        With none of them, the scene's own spp. RenderResult.stop_reason names the rule that ended it."""
        if spp is None and time_limit is None and target_error is None:
            spp = self.scene.spp
        target = None if spp is None else self.samples_done + spp
        check = None if target_error is None else _ErrorCheck(target_error, max(min_spp, 1))
        reason = "spp"
        t0 = time.perf_counter()
        while target is None or self.samples_done < target:
            slots = self.slots if target is None else min(self.slots, target - self.samples_done)
            if check is not None:
                slots = max(1, min(slots, check.next_at - self.samples_done))
            self._launch(self.samples_done, slots)
            self.queue.finish()
            self.samples_done += slots
            if progress is not None:
                progress(slots)
            if time_limit is not None and time.perf_counter() - t0 >= time_limit:
                reason = "time"
                break
            if check is not None and self.samples_done >= check.next_at and check.reached(self):
                reason = "error"
                break
        self.seconds += time.perf_counter() - t0
        result = self.result()
        result.stop_reason = reason
        return result

    def result(self) -> RenderResult:
        n = self.slots * self.npix
        sums = np.empty((n, 4), np.float32)
        sums_sq = np.empty((n, 4), np.float32)
        invalid = np.empty(n, np.uint32)
        cl.enqueue_copy(self.queue, sums, self.sums)
        cl.enqueue_copy(self.queue, sums_sq, self.sums_sq)
        cl.enqueue_copy(self.queue, invalid, self.invalid)
        s = sums.astype(np.float64).reshape(self.slots, self.npix, 4).sum(0)
        ss = sums_sq.astype(np.float64).reshape(self.slots, self.npix, 4).sum(0)
        count = s[:, 3:4]
        safe = np.maximum(count, 1)
        mean = s[:, :3] / safe
        sample_var = np.maximum(ss[:, :3] / safe - mean ** 2, 0) * safe / np.maximum(safe - 1, 1)
        var_mean = sample_var / safe
        shape = (self.height, self.width, 3)
        return RenderResult(
            image=mean.reshape(shape).astype(np.float32), variance=var_mean.reshape(shape).astype(np.float32),
            spp=self.samples_done, invalid=int(invalid.sum()), seconds=self.seconds,
            device=f"{self.device.key} {self.device.name}", features=self.packed.features,
            build_seconds=self.build_seconds,
            stats={"triangles": self.packed.triangle_count, "spheres": self.packed.sphere_count,
                   "bvh_seconds": self.packed.bvh_seconds, "features": describe(self.packed.features)})


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
           time_limit=None, target_error=None, estimator: Estimator | None = None) -> RenderResult:
    r = Renderer(scene, device=device, features=features, seed=seed, estimator=estimator)
    if spp is None and time_limit is None and target_error is None:
        spp = scene.spp
    return r.render(spp, progress=progress, time_limit=time_limit, target_error=target_error)
