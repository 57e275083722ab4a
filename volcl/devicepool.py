"""The devices of this machine rendering one image together (volcl.rounds): one thread per device
takes the round's tiles from a shared list, so a fast device takes more of them.

Each device keeps its own context, program and scene upload (volcl.device.Device), and keeps the
accumulators of the tiles it rendered last between rounds (a Renderer per tile), so a tile that
stays on its device is not uploaded again; a device takes its own tiles first, then tiles nobody
holds, then tiles of the device with the most work still waiting (whose accumulators it uploads
from the host copy). A device that fails (an OpenCL error, a lost GPU, a build that fails on it)
is retired: the tile it had in hand goes back into the list and the other devices render it
again from the round's start; when no device is left the round raises WorkersFailed.
"""
from __future__ import annotations

import threading
import time
import warnings

from . import wavefront
from .rounds import TileJob, TiledRender, WorkersFailed


class DeviceFailure(UserWarning):
    """A device of a render on several devices failed; the others carry on."""


class _Worker:
    def __init__(self, device, label: str):
        self.device = device
        self.label = label
        self.alive = True
        self.renderers: dict = {}   # tile index -> Renderer holding that tile's accumulators
        self.tiles = 0              # tile rounds rendered


def _reason(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[-1] if text else ''}".rstrip(": ")


def _labels(devices) -> list[str]:
    """Device labels, made distinct where two objects stand for one device (Device.fresh)."""
    out = []
    for d in devices:
        label, n = d.label, 2
        while label in out:
            label, n = f"{d.label} #{n}", n + 1
        out.append(label)
    return out


class DevicePool:
    """Renders the TileJobs of a round on `devices` (volcl Devices), one thread each.
    `notify(text)` is told of each device that fails (default: a DeviceFailure warning)."""

    JOIN_SECONDS = 0.2      # how often the waiting thread wakes (signal handlers run then)

    def __init__(self, devices, notify=None):
        if not devices:
            raise ValueError("DevicePool: no devices")
        self.workers = [_Worker(d, label) for d, label in zip(devices, _labels(devices))]
        self.failures: list = []    # (label, reason)
        self.notify = notify or (lambda text: warnings.warn(text, DeviceFailure, stacklevel=2))
        self._cond = threading.Condition()
        self._owner: dict = {}      # tile index -> the _Worker holding its accumulators
        self._pending: list = []
        self._in_flight = 0
        self._abort = False

    @property
    def labels(self) -> list[str]:
        return [w.label for w in self.workers]

    @property
    def size(self) -> int:
        return sum(w.alive for w in self.workers)

    def forget(self):
        """Drop every device's tile accumulators (the render restarted from another state)."""
        with self._cond:
            for w in self.workers:
                w.renderers.clear()
            self._owner.clear()

    def prepare(self, render: TiledRender):
        """Build the programs of the engine the render's tiles take (volcl.wavefront.start) and
        upload its scene on every device at once, before the first round (so that render time is
        rendering, as on one device). A device that fails here is retired; WorkersFailed when none
        is left."""
        def setup(w):
            try:
                builds = w.device.builds
                # the tiles' renderers make the same choice and find its programs built; the
                # Wavefront made here (a table of a few KB) is dropped, each renderer makes its own
                _, sources = wavefront.start(render.ENGINE, render.features, render.packed, render.params, w.device)
                if w.device.builds > builds:
                    seconds = w.device.programs.seconds_of(render.features, sources)
                    with self._cond:    # the devices' threads add to one total
                        render.build_seconds += seconds
                render.prepared.upload(w.device)
            except Exception as exc:  # noqa: BLE001  (any driver failure retires the device)
                with self._cond:
                    self._fail(w, exc)
        threads = [threading.Thread(target=setup, args=(w,), daemon=True) for w in self.workers if w.alive]
        for t in threads:
            t.start()
        self._join(threads)
        if not self.size:
            raise WorkersFailed("no device could set up the render (" + "; ".join(
                f"{label}: {why}" for label, why in self.failures) + ")", self.failures)

    def run(self, render: TiledRender, jobs: list[TileJob]):
        """Render every job (job.out filled), or raise WorkersFailed when no device is left."""
        with self._cond:
            self._pending = sorted(jobs, key=lambda j: -j.cost)
            self._in_flight = 0
            self._abort = False
        threads = [threading.Thread(target=self._serve, args=(w, render), name=f"volcl {w.label}", daemon=True)
                   for w in self.workers if w.alive]
        for t in threads:
            t.start()
        self._join(threads)
        if any(j.out is None for j in jobs):
            raise WorkersFailed("every device failed (" + "; ".join(f"{label}: {why}" for label, why in self.failures)
                                + ")", self.failures)

    def _join(self, threads):
        """Wait for the threads, waking to let signal handlers run. On an exception there (a second
        Ctrl-C) no new tile starts, and the work under way (a launch or two) is still waited for:
        a process that exits while another thread is inside a driver call may abort."""
        try:
            for t in threads:
                while t.is_alive():
                    t.join(self.JOIN_SECONDS)
        except BaseException:
            with self._cond:
                self._abort = True
                self._cond.notify_all()
            for t in threads:
                t.join()
            raise

    def _serve(self, w: _Worker, render: TiledRender):
        while True:
            with self._cond:
                while True:
                    if self._abort or not w.alive:
                        return
                    if self._pending:
                        job = self._pick(w)
                        self._in_flight += 1
                        break
                    if self._in_flight == 0:    # the round is done
                        return
                    self._cond.wait()           # a tile under way elsewhere may come back
            try:
                self._render(w, render, job)
            except Exception as exc:  # the device is lost to this render, not the render
                with self._cond:
                    self._in_flight -= 1
                    self._fail(w, exc)
                    self._pending.append(job)
                    self._pending.sort(key=lambda j: -j.cost)
                    self._cond.notify_all()
                return
            with self._cond:
                self._in_flight -= 1
                w.tiles += 1
                self._cond.notify_all()

    def _pick(self, w: _Worker) -> TileJob:
        """The next job for `w` (under the lock): its own tiles first, costliest first; then tiles
        nobody holds; then from the device with the most work waiting."""
        pending = self._pending
        for want in (w, None):
            for i, job in enumerate(pending):
                if self._owner.get(job.index) is want:
                    return pending.pop(i)
        waiting: dict = {}
        for job in pending:
            owner = self._owner.get(job.index)
            waiting[owner] = waiting.get(owner, 0.0) + job.cost * job.count * job.tile.pixels + 1e-9
        busiest = max(waiting, key=waiting.get)
        for i, job in enumerate(pending):
            if self._owner.get(job.index) is busiest:
                return pending.pop(i)
        return pending.pop(0)

    def _render(self, w: _Worker, render: TiledRender, job: TileJob):
        r = w.renderers.get(job.index)
        if r is None or r.samples_done != job.start:
            r = render.tile_renderer(w.device, job.tile)
            state = job.state_in()
            if state is not None:
                r.restore(state)
            with self._cond:
                old = self._owner.get(job.index)
                if old is not None and old is not w:
                    old.renderers.pop(job.index, None)
                self._owner[job.index] = w
                w.renderers[job.index] = r
        t0 = time.perf_counter()
        r.advance(job.count)
        out = r.state()
        job.seconds = time.perf_counter() - t0
        job.worker = w.label
        job.out = out
        render.tile_done(job)

    def _fail(self, w: _Worker, exc: BaseException):
        """Retire `w` (under the lock): its tiles' accumulators are dropped, the host has them."""
        w.alive = False
        for index in list(w.renderers):
            if self._owner.get(index) is w:
                del self._owner[index]
        w.renderers.clear()
        why = _reason(exc)
        self.failures.append((w.label, why))
        left = [x.label for x in self.workers if x.alive]
        if left:
            self.notify(f"device {w.label} failed ({why}); its tiles go to {', '.join(left)}")
        else:
            self.notify(f"device {w.label} failed ({why}); no device is left")
