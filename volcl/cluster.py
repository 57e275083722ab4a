"""Rendering on a Dask cluster (`volcl render ... --scheduler ADDRESS`, `volcl.render(scheduler=...)`).

Dask distributed places the tasks, reruns a task elsewhere when its worker dies, and shows progress;
volcl supplies the tasks and merges their results. A render is a volcl.rounds.TiledRender whose
executor is a DaskExecutor: each round's tiles become Dask tasks ("add these samples to this
tile, starting from this state"), whose results are the tiles' new accumulator states. A task
depends on nothing but its arguments, so a worker that dies mid-task costs only that task, which
Dask runs again on another worker, with the same bits; the client holds every tile's state after
every round, which is what Ctrl-C writes, a checkpoint saves and --resume continues.

- The scene travels once per worker: the client scatters the volcl.Scene (its model and packed
  arrays, meshes, volumes and textures included, so files that exist only on the client are
  never read by a worker) to every worker, and tasks refer to it.
- Each worker thread renders on a volcl device of its own process (volcl.cluster.worker_device:
  the worker's VOLCL_DEVICE, else the device volcl chooses; threads share a device when there
  are more threads than devices), whose program is built once per worker process and kept.
- Workers: `volcl worker ADDRESS` (a `dask worker` with this module as its preload), or any
  `dask worker ADDRESS --preload volcl.cluster`; `--scheduler local:N` starts a LocalCluster of N
  single-threaded worker processes on this machine.
"""
from __future__ import annotations

import contextlib
import os
import signal
import threading
import time

from .errors import VolclError
from .rounds import TileJob, TiledRender, WorkersFailed

# A round's wall time on a cluster: each round's tile states cross the network twice (to the
# workers and back), so rounds are longer than on one machine.
CLUSTER_ROUND_SECONDS = 4.0
# Tiles per worker thread the default tile size aims at: fewer than on one machine, since every
# task costs a few milliseconds of scheduling and transfers.
CLUSTER_TILES_PER_WORKER = 4
LOCAL = "local:"
# Times Dask runs a task again after an exception in it (a worker that dies is handled by Dask
# itself, which moves the task; `distributed.scheduler.allowed-failures`).
TASK_RETRIES = 2
# How long the client tries to reach a scheduler at an address.
CONNECT_SECONDS = 30.0
# How long a render waits for a first worker to join a scheduler that has none.
WORKER_WAIT_SECONDS = 60.0


def _import_distributed():
    try:
        import distributed
    except ImportError:
        raise VolclError("--scheduler needs Dask distributed: pip install 'volcl[cluster]' (or: pip install "
                         "dask distributed)") from None
    return distributed


def connect(scheduler):
    """A distributed.Client for `scheduler`: a Client (used as it is), 'local:N' (a LocalCluster of N
    single-threaded worker processes, closed with the client), or a scheduler address
    ('tcp://host:8786', 'host:8786')."""
    distributed = _import_distributed()
    if isinstance(scheduler, distributed.Client):
        return scheduler
    if not isinstance(scheduler, str) or not scheduler.strip():
        raise VolclError(f"--scheduler {scheduler!r}: expected a scheduler address (tcp://host:8786) or local:N")
    text = scheduler.strip()
    if text.startswith(LOCAL):
        try:
            n = int(text[len(LOCAL):])
        except ValueError:
            n = 0
        if n < 1:
            raise VolclError(f"--scheduler {scheduler!r}: expected local:N with N >= 1 worker processes")
        # The workers must outlive a Ctrl-C, which a terminal sends to the whole process group:
        # they start with SIGINT ignored (inherited), and the client alone decides what to do.
        with _sigint_ignored():
            cluster = distributed.LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                               dashboard_address=":0", silence_logs=40)
        client = distributed.Client(cluster)
        client._volcl_cluster = cluster     # closed with the client (close())
        return client
    try:
        return distributed.Client(text, timeout=CONNECT_SECONDS)
    except ValueError as exc:       # an address Dask cannot parse (unknown scheme, no port)
        raise VolclError(f"--scheduler {scheduler}: not a scheduler address ({exc}); expected tcp://HOST:PORT "
                         "(dask scheduler prints it) or local:N") from None
    except OSError as exc:
        raise VolclError(f"--scheduler {scheduler}: cannot reach the Dask scheduler ({exc}); start one with "
                         "`dask scheduler` and workers with `volcl worker ADDRESS`") from None


@contextlib.contextmanager
def _sigint_ignored():
    try:
        old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:              # not the main thread: signals are not ours to change
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


def close(client):
    """Close a client made by connect (and the LocalCluster it started)."""
    cluster = getattr(client, "_volcl_cluster", None)
    client.close()
    if cluster is not None:
        cluster.close()


def wait_for_workers(client, seconds: float = WORKER_WAIT_SECONDS):
    """Return once the scheduler has a worker; WorkersFailed after `seconds` without one."""
    if client.scheduler_info()["workers"]:
        return
    try:
        client.wait_for_workers(1, timeout=seconds)
    except TimeoutError:
        raise WorkersFailed(f"the Dask scheduler {client.scheduler.address} has had no workers for {seconds:g} s; "
                            "start them with `volcl worker ADDRESS`") from None


def describe(client) -> str:
    """'2 workers, 2 threads: tcp://10.0.0.5:40331 (1 thread), ...'."""
    workers = client.scheduler_info()["workers"]
    threads = sum(w.get("nthreads", 1) for w in workers.values())
    listing = ", ".join(f"{addr} ({w.get('nthreads', 1)} thread{'s' if w.get('nthreads', 1) != 1 else ''})"
                        for addr, w in workers.items())
    return f"{len(workers)} workers, {threads} threads" + (f": {listing}" if listing else "")


# -- the worker side --------------------------------------------------------------------------------

_local = threading.local()
_devices_lock = threading.Lock()
_devices: list = []
_taken = [0]


def worker_device():
    """This worker thread's volcl device: the worker process's devices (VOLCL_DEVICE, else the one
    volcl chooses) handed to its threads in turn, each kept for the thread's life."""
    dev = getattr(_local, "device", None)
    if dev is None:
        from . import device as devmod
        with _devices_lock:
            if not _devices:
                _devices.extend(devmod.choose_many(None))
            dev = _devices[_taken[0] % len(_devices)]
            _taken[0] += 1
        _local.device = dev
    return dev


def _worker_label(dev) -> str:
    try:
        from distributed import get_worker
        name = get_worker().address
    except (ImportError, ValueError):
        name = f"pid {os.getpid()}"
    return f"{name} {dev.name}"


def _tile_renderer(scene, spec, tile, start=0):
    """A Renderer of `tile` on this thread's device. The thread keeps the renderers of the tiles it
    rendered for the scene it rendered last: when the tile comes back at the sample count it left
    with, its accumulators are already on the device (the state the task carries is then not
    uploaded again); the samples done tell whether they are."""
    from .renderer import Renderer
    key = (id(scene), scene.version, repr(spec), tile)
    cache = getattr(_local, "renderers", None)
    if cache is None or cache.get("scene") != (id(scene), scene.version):
        cache = _local.renderers = {"scene": (id(scene), scene.version)}
    # Taken out of the cache while the task runs, and put back by tile_round once it has
    # succeeded: a task that fails mid-pass leaves accumulators no retry may start from.
    r = cache.pop(key, None)
    if r is not None and start and r.samples_done == start:
        return r, key, True
    r = Renderer(scene, device=worker_device(), features=spec["features"], seed=spec["seed"],
                 estimator=spec["estimator"], tile=tile)
    return r, key, False


def warm(scene, spec) -> str:
    """A task run once on each worker before the first round: the program built, the scene
    uploaded, so that render time is rendering."""
    dev = worker_device()
    _tile_renderer(scene, spec, (0, 0, 1, 1))
    return _worker_label(dev)


def tile_round(scene, spec, tile, state, count) -> dict:
    """A task: `count` more samples per pixel of `tile`, from `state` (None: from none)."""
    t0 = time.perf_counter()
    start = 0 if state is None else int(state["samples_done"])
    r, key, resident = _tile_renderer(scene, spec, tile, start)
    if state is not None and not resident:
        r.restore(state)
    r.advance(count)
    out = r.state()
    _local.renderers[key] = r
    return {"state": out, "worker": _worker_label(r.device), "seconds": time.perf_counter() - t0}


def dask_setup(worker):
    """Dask's preload hook (`dask worker ADDRESS --preload volcl.cluster`): find this worker's
    devices and build volcl's kernels on them now, so a worker that cannot render says so at once."""
    from . import device as devmod
    devs = devmod.choose_many(None)
    with _devices_lock:
        if not _devices:
            _devices.extend(devs)
    names = ", ".join(d.label for d in devs)
    print(f"volcl: worker {worker.address} renders on {names}", flush=True)


# -- the client side --------------------------------------------------------------------------------

class DaskExecutor:
    """Renders a TiledRender's rounds as Dask tasks on `client`'s workers (volcl.rounds)."""

    cluster = True              # results name workers (summaries say so)
    tiles_per_worker = CLUSTER_TILES_PER_WORKER

    WAIT_SECONDS = 0.2      # how often the client wakes while a round runs (signal handlers run then)

    def __init__(self, client):
        self.client = client
        self.failures: list = []
        self._scene = None          # the scene's future on the workers
        self._spec = None
        self._labels: list = []
        self._round = 0
        self._id = f"volcl-{os.getpid()}-{id(self):x}"

    @property
    def workers(self) -> dict:
        return self.client.scheduler_info()["workers"]

    @property
    def size(self) -> int:
        """Worker threads (tasks the cluster runs at once)."""
        return max(1, sum(w.get("nthreads", 1) for w in self.workers.values()))

    @property
    def labels(self) -> list:
        return self._labels or sorted(self.workers)

    def forget(self):
        pass                        # workers keep no tile state between tasks

    def prepare(self, render: TiledRender):
        """Scatter the scene to every worker (once), build the program and upload there."""
        wait_for_workers(self.client)
        self._spec = {"features": render.feature_override, "seed": render.seed, "estimator": render.estimator}
        self._scene = self.client.scatter(render.prepared, broadcast=True, hash=False)
        futures = [self.client.submit(warm, self._scene, self._spec, workers=[addr], pure=False,
                                      key=f"{self._id}-warm-{i}")
                   for i, addr in enumerate(self.workers)]
        self._labels = [str(label) for label in self._wait(futures)]

    def _wait(self, futures) -> list:
        distributed = _import_distributed()
        try:
            for _ in _as_completed(distributed, futures, self.WAIT_SECONDS):
                pass
        except BaseException:
            for f in futures:
                f.cancel()
            raise
        return [f.result() for f in futures]

    def run(self, render: TiledRender, jobs: list[TileJob]):
        distributed = _import_distributed()
        self._round += 1
        futures = []
        for job in jobs:
            f = self.client.submit(tile_round, self._scene, self._spec, job.tile, job.state_in(), job.count,
                                   key=f"{self._id}-r{self._round}-t{job.index}", pure=False,
                                   retries=TASK_RETRIES)
            futures.append((f, job))
        by_future = dict(futures)
        try:
            for f in _as_completed(distributed, [f for f, _ in futures], self.WAIT_SECONDS):
                job = by_future[f]
                try:
                    out = f.result()
                except Exception as exc:  # noqa: BLE001  (the task failed on every try)
                    self.failures.append((f"task {f.key}", f"{type(exc).__name__}: {exc}"))
                    for g, _ in futures:
                        g.cancel()
                    raise WorkersFailed(f"tile {job.tile} failed on the cluster ({type(exc).__name__}: {exc})",
                                        self.failures) from exc
                job.out, job.worker, job.seconds = out["state"], out["worker"], out["seconds"]
                render.tile_done(job)
        except BaseException:
            for g, _ in futures:
                g.cancel()
            raise

    def close(self):
        if self._scene is not None:
            self._scene.release()
            self._scene = None


def _as_completed(distributed, futures, wake_seconds):
    """Futures as they finish; the waiting wakes every wake_seconds so that the client's signal
    handlers run (a blocking wait would hold Ctrl-C until a task ends)."""
    pending = list(futures)
    while pending:
        try:
            distributed.wait(pending, timeout=wake_seconds, return_when="FIRST_COMPLETED")
        except TimeoutError:
            pass
        done = [f for f in pending if f.done()]
        pending = [f for f in pending if not f.done()]
        yield from done
