"""One image rendered by several workers (the devices of this machine, volcl.devicepool; the workers
of a Dask cluster, volcl.cluster): the image cut into tiles that advance together in rounds of
samples.

A tile renders all samples of its pixels into accumulators of its own, so however the image is cut
and whichever worker renders a tile, its bits are those one device computes for those pixels
(volcl.tiles). What a split must not change is when the render stops: a time limit, a target error
and an interrupt belong to the whole image, and one device checks them between its passes. So in a
round every tile adds the same samples n .. n + k - 1, the round ends when every tile has them, and
the rules are checked between rounds on the merged image, with one device's arithmetic: after
every round the image is, bit for bit, the one a single device holds after n + k samples, so a
render stopped by any rule (or interrupted, or checkpointed) is one a single device could have
stopped at, and continuing it gives that device's bits. Within a round the tiles go to whichever
worker is free, so fast workers take more; costly tiles go first, so that no worker is left with
a long tile at the end of a round. Rounds last about `round_seconds`, from the speed measured so
far, and never run past the samples asked for, the next error check or the time limit.

Between rounds every tile's accumulators are on the host: a checkpoint holds them all; a worker
that fails loses only the round of the tile it had in hand, which another worker renders again
from the round's start; and a render whose workers all fail still has the image of its last whole
round (WorkersFailed.result).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .errors import VolclError
from .estimator import Estimator
from .prepared import Scene as PreparedScene
from .renderer import MIN_SPP_FOR_ERROR, Renderer, StopRules, build_result, data_hash, render_setup, render_target
from .result import RenderResult
from .scene.model import Scene as ModelScene
from .tiles import Tile, accumulator_slots, tiles

# Wall time of one round: short enough that an interrupt, a time limit or a checkpoint waits
# little for the round under way, long enough that the tiles' launches and read-backs cost little.
ROUND_SECONDS = 1.0
# A round is at most this many times longer (in samples) than the one before: the first rounds
# include kernel builds and uploads, and the speed measured then is not the speed to come.
ROUND_GROWTH = 4
# Tiles per worker the default tile size aims at (at least), for the balance at the end of a round.
TILES_PER_WORKER = 8
TILE_SIZES = (64, 32, 16, 8)
ARRAYS = (("sums", np.float32, (4,)), ("sums_sq", np.float32, (4,)), ("invalid", np.uint32, ()),
          ("cutoffs", np.uint32, ()))


class WorkersFailed(VolclError):
    """Every worker (device) of a render failed. `result` is the image of the last whole round
    (stop_reason 'failed'); `failures` lists (worker, reason)."""

    def __init__(self, message: str, failures=()):
        super().__init__(message)
        self.failures = list(failures)
        self.result: RenderResult | None = None


def default_tile_size(width: int, height: int, workers: int, per_worker: int = TILES_PER_WORKER) -> int:
    """The largest of TILE_SIZES that cuts the image into `per_worker` tiles per worker."""
    for size in TILE_SIZES:
        if len(tiles(width, height, size)) >= per_worker * max(workers, 1):
            return size
    return TILE_SIZES[-1]


@dataclass
class TileJob:
    """One tile's part of a round: add `count` samples per pixel to a tile that holds `start`."""
    index: int
    tile: Tile
    start: int
    count: int
    cost: float                 # seconds per sample per pixel of the tile's last round (0: unknown)
    render: "TiledRender"
    out: dict | None = None     # the tile's accumulator state after the round
    worker: str = ""            # who rendered it
    seconds: float = 0.0

    def state_in(self) -> dict | None:
        """The tile's accumulator state at the round's start (None when it holds no samples)."""
        return self.render.tile_state(self.index) if self.start else None


class TiledRender:
    """A progressive render of one image by the workers of `executor`, with Renderer's interface
    (render, state, restore, result, samples_done, data_hash), so batches, checkpoints and the API
    take either. `executor` renders a round's TileJobs (volcl.devicepool.DevicePool,
    volcl.cluster.DaskExecutor); `tile_size` (pixels, or (width, height)) defaults to
    default_tile_size."""

    # the engine every tile's Renderer is asked for; executors that build programs before the
    # first round (DevicePool.prepare, the cluster's warm task) ask for the same, so that they
    # build what the tiles launch
    ENGINE = "auto"

    def __init__(self, scene, executor, seed: int | None = None, estimator: Estimator | None = None,
                 features: dict | None = None, tile_size=None, round_seconds: float = ROUND_SECONDS):
        if isinstance(scene, ModelScene):
            scene = PreparedScene(scene)
        self.prepared = scene
        self.scene = scene.model
        self.version = scene.version
        self.executor = executor
        self.estimator = estimator or Estimator()
        self.feature_override = features
        self.features, self.params = render_setup(scene, self.estimator, features, seed)
        self.seed = int(self.params["seed"])
        self.width, self.height = self.scene.camera.width, self.scene.camera.height
        self.slots = accumulator_slots(self.width, self.height)
        size = tile_size or default_tile_size(self.width, self.height, executor.size,
                                              getattr(executor, "tiles_per_worker", TILES_PER_WORKER))
        self.tile_list = tiles(self.width, self.height, size)
        self.round_seconds = float(round_seconds)
        shape = (self.slots, self.height, self.width)
        self._arrays = {key: np.zeros(shape + extra, dtype) for key, dtype, extra in ARRAYS}
        self._cost = [0.0] * len(self.tile_list)
        self.samples_done = 0
        self.seconds = 0.0
        self.spp_requested = 0
        self.rounds = 0
        self.build_seconds = 0.0    # kernel builds the tiles waited for (summed over workers)
        self.work: dict = {}        # worker label -> pixel samples rendered (this session)
        self.on_tile = None         # called with each TileJob as it is done (progress over tiles)
        executor.prepare(self)      # programs built, scene uploaded, before any render time counts

    @property
    def packed(self):
        return self.prepared.packed

    def data_hash(self) -> str:
        return data_hash(self.params, self.packed)

    @property
    def device_label(self) -> str:
        """Every worker that rendered (or, before any round, every worker), as one text."""
        return ", ".join(self.work or self.executor.labels)

    def tile_renderer(self, device, tile: Tile) -> Renderer:
        """A Renderer of one of this render's tiles on `device` (a worker calls this)."""
        return Renderer(self.prepared, device=device, features=self.feature_override, seed=self.seed,
                        estimator=self.estimator, tile=tile, engine=self.ENGINE)

    def tile_state(self, index: int) -> dict:
        """Tile `index`'s accumulator state (as Renderer.state gives it), copied from the image's."""
        t = self.tile_list[index]
        out = {key: np.ascontiguousarray(a[:, t.rows, t.columns]).reshape((-1,) + a.shape[3:])
               for key, a in self._arrays.items()}
        out.update(samples_done=self.samples_done, seconds=0.0, slots=self.slots, width=self.width,
                   height=self.height, seed=self.seed, tile=(t.x, t.y, t.width, t.height))
        return out

    def tile_done(self, job: TileJob):
        """An executor's word that `job` is rendered (from any thread)."""
        if self.on_tile is not None:
            self.on_tile(job)

    def _put(self, job: TileJob):
        t = job.tile
        st = job.out
        if int(st["samples_done"]) != job.start + job.count:
            raise VolclError(f"{job.worker} returned tile {t} with {st['samples_done']} spp, not "
                             f"{job.start + job.count}")
        for key, a in self._arrays.items():
            a[:, t.rows, t.columns] = np.asarray(st[key]).reshape((self.slots, t.height, t.width) + a.shape[3:])

    # -- Renderer's interface ------------------------------------------------------------------

    def state(self) -> dict:
        """The whole image's accumulator state, as one device's Renderer.state gives it (the
        arrays are this render's own: copy them to keep them past the next round)."""
        out = {key: a.reshape((-1,) + a.shape[3:]) for key, a in self._arrays.items()}
        out.update(samples_done=self.samples_done, seconds=self.seconds, slots=self.slots, width=self.width,
                   height=self.height, seed=self.seed, tile=(0, 0, self.width, self.height))
        return out

    def restore(self, state: dict):
        """Continue from a whole-image state (Renderer.state of any render of this scene and seed)."""
        for key in ("slots", "width", "height", "seed"):
            if int(state[key]) != getattr(self, key):
                raise ValueError(f"state has {key} {int(state[key])}, this render {getattr(self, key)}")
        held = tuple(int(v) for v in state.get("tile", (0, 0, self.width, self.height)))
        if held != (0, 0, self.width, self.height):
            raise ValueError(f"state holds tile {held}; a render on several devices continues whole images")
        for key, dtype, extra in ARRAYS:
            a = np.asarray(state[key])
            want = (self.slots * self.width * self.height,) + extra
            if a.dtype != dtype or a.shape != want:
                raise ValueError(f"state {key}: {a.dtype}{a.shape}, expected {np.dtype(dtype)}{want}")
            self._arrays[key][...] = a.reshape(self._arrays[key].shape)
        self.samples_done = int(state["samples_done"])
        self.seconds = float(state["seconds"])
        self.executor.forget()

    def result(self) -> RenderResult:
        result = build_result(self, self.state(), Tile(0, 0, self.width, self.height))
        total = sum(self.work.values())
        if total:
            result.shares = {label: n / total for label, n in self.work.items()}
        result.info["workers"] = list(self.executor.labels)
        result.info["cluster"] = bool(getattr(self.executor, "cluster", False))
        if self.executor.failures:
            result.info["failures"] = list(self.executor.failures)
        return result

    def render(self, spp: int | None = None, progress=None, time_limit: float | None = None,
               target_error: float | None = None, min_spp: int = MIN_SPP_FOR_ERROR, stop=None) -> RenderResult:
        """Renderer.render's rules, checked between rounds. Raises WorkersFailed (with the image of
        the last whole round) when no worker is left."""
        target = render_target(self, spp, time_limit, target_error)
        rules = StopRules(time_limit, target_error, min_spp, stop)
        stream = getattr(self.executor, "stream", None)     # an executor that runs rounds overlapped
        reason = stream(self, target, rules, progress) if stream else self._rounds(target, rules, progress)
        result = self.result()
        result.stop_reason = reason
        return result

    def _rounds(self, target, rules, progress) -> str:
        """Round after round, each begun once the one before has ended; the stop reason."""
        rate, last = None, 0
        while target is None or self.samples_done < target:
            count = self.round_length(rate, last, target, rules)
            t0 = time.perf_counter()
            self._round(count)
            seconds = time.perf_counter() - t0
            rate, last = count / max(seconds, 1e-9), count
            reason = self.round_ended(count, seconds, progress, rules)
            if reason is not None:
                return reason
        return "spp"

    def round_ended(self, count: int, seconds: float, progress, rules) -> str | None:
        """Book a round of `count` samples that took `seconds` and check the rules (its reason to stop)."""
        self.seconds += seconds
        self.samples_done += count
        self.rounds += 1
        if progress is not None:
            progress(count)
        return rules.reason(self)

    def round_length(self, rate, last, target, rules, done: int | None = None, growth: int = ROUND_GROWTH) -> int:
        """Samples per pixel of the round that begins at `done` (default samples_done), after one of
        `last` samples, at `rate` samples per second of the whole image (None: before any round), and
        at most `growth` times `last`."""
        done = self.samples_done if done is None else done
        first_pass = self.slots - done % self.slots     # what one device's next pass would add
        if rate is None:
            count = first_pass
        else:
            count = max(1, min(int(rate * self.round_seconds), growth * last))
            if count >= first_pass:     # end on a whole round of slots: no partial-slot passes
                count = first_pass + (count - first_pass) // self.slots * self.slots
            left = rules.seconds_left()
            if left is not None:
                count = min(count, max(1, int(left * rate)))
        if target is not None:
            count = min(count, target - done)
        return rules.cap(done, count)

    def _round(self, count: int):
        """Every tile from samples_done to samples_done + count; the image changes only once all
        tiles have them (so a failure leaves the last whole round)."""
        jobs = [TileJob(i, t, self.samples_done, count, self._cost[i], self)
                for i, t in enumerate(self.tile_list)]
        try:
            self.executor.run(self, jobs)
        except WorkersFailed as exc:
            exc.result = self.result()
            exc.result.stop_reason = "failed"
            raise
        self.merge(jobs)

    def merge(self, jobs: list[TileJob]):
        """Every tile's part of a round, rendered, into the image (tile order: the bits do not depend on it)."""
        for job in jobs:
            self._put(job)
        for job in jobs:
            self._cost[job.index] = job.seconds / job.count
            self.work[job.worker] = self.work.get(job.worker, 0) + job.tile.pixels * job.count


def renderer_for(scene, devices=None, executor=None, seed=None, estimator=None, features=None,
                 tile_size=None, notify=None):
    """A Renderer on one device, or a TiledRender on several devices (`devices`, resolved by
    volcl.device.resolve_many) or on an executor's workers (a Dask cluster, volcl.cluster)."""
    if executor is not None:
        from .cluster import CLUSTER_ROUND_SECONDS
        return TiledRender(scene, executor, seed=seed, estimator=estimator, features=features,
                           tile_size=tile_size, round_seconds=CLUSTER_ROUND_SECONDS)
    from . import device as devmod
    devs = devmod.resolve_many(devices)
    if len(devs) == 1 and tile_size is None:
        return Renderer(scene, device=devs[0], features=features, seed=seed, estimator=estimator)
    from .devicepool import DevicePool
    return TiledRender(scene, DevicePool(devs, notify=notify), seed=seed, estimator=estimator, features=features,
                       tile_size=tile_size)
