"""Rendering on a Dask cluster (`volcl render ... --scheduler ADDRESS`, `volcl.render(scheduler=...)`).

Dask distributed places the tasks, reruns a task elsewhere when its worker dies, and shows progress;
volcl supplies the tasks and merges their results. A render is a volcl.rounds.TiledRender whose
executor is a DaskExecutor: the rounds of tiles of volcl.rounds (every tile adds the same samples
n .. n + k - 1, and the image is merged and the stop rules checked once every tile has them) become
Dask tasks ("add these samples to this tile, starting from this state"), whose results are the
tiles' new accumulator states. The rounds are streamed: a tile's next round is submitted as soon
as its last one returns (up to LOOKAHEAD rounds ahead of the image, earlier rounds first), so no
worker waits at the end of a round for the others' last tiles, while the image, merged round by
round in a fixed order, holds the bits of a local render at every round's end. A task depends on
nothing but its arguments, so a worker that dies mid-task costs only that task, which Dask runs
again on another worker, with the same bits; the client holds every tile's state at the image's
last whole round, which is what Ctrl-C writes, a checkpoint saves and --resume continues, and what
a render whose task fails on every try keeps (WorkersFailed.result).

- The scene travels once per worker: the client scatters the volcl.Scene (its model and packed
  arrays, meshes, volumes and textures included, so files that exist only on the client are
  never read by a worker) to every worker, and tasks refer to it; if every worker holding a copy
  dies, the client sends it again (DaskExecutor.resend).
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
# task costs a few milliseconds of scheduling and transfers; 2, so that while a finished tile's next
# round travels through the client another tile's round is ready for the worker (the streamed
# rounds let tiles run ahead of each other). Against 4, one third of the tasks and a 5-20% higher
# rate on 2 one-core workers (benchmarks/cluster_scaling.py, the tile-size table).
CLUSTER_TILES_PER_WORKER = 2
# A round is at most this many times longer than the one before: more than on one machine
# (volcl.rounds.ROUND_GROWTH), since the workers built their kernels before the first round
# and each task costs milliseconds.
CLUSTER_ROUND_GROWTH = 16
LOCAL = "local:"
# Dask's periodic work that a render needs none of, slowed or off (Dask's own test suite runs
# with the same): by default every scheduler, nanny and worker checks its event loop every 20 ms,
# and workers sample their threads' stacks every 10 ms for the dashboard's profiles. On 2 cores
# this took 5% of a core in the client (with the LocalCluster's scheduler and nannies) and 4% in
# each idle worker, time a second worker could not render in; slowed, 1% and 0.4%.
QUIET_DASK = {
    "distributed.admin.tick.interval": "1s",
    "distributed.worker.profile.enabled": False,
    "distributed.admin.system-monitor.interval": "2s",
    "distributed.worker.memory.monitor-interval": "1s",
}
# Times Dask runs a task again after an exception in it (a worker that dies is handled by Dask
# itself, which moves the task; `distributed.scheduler.allowed-failures`).
TASK_RETRIES = 2
# Rounds a tile may run ahead of the image (the rounds every tile has): its look-ahead keeps the
# workers busy while a round's last tiles render, and bounds the work a stop throws away.
LOOKAHEAD = 2
# The render's last rounds are at least this many times shorter than a round (volcl.cluster._Stream).
TAIL_SPLIT = 8
# Times one executor sends the scene again after the workers lost every copy of it (each worker
# that held one died) before the render fails.
SCENE_RESENDS = 3
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
        import dask
        with _sigint_ignored(), dask.config.set(QUIET_DASK):
            cluster = distributed.LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                               dashboard_address=":0", silence_logs=40, env=local_worker_env(n))
        # Results come straight from the workers, not through the scheduler (which shares this process).
        client = distributed.Client(cluster, direct_to_workers=True)
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


def quiet_dask_env(env: dict) -> dict:
    """`env` with QUIET_DASK as Dask reads configuration from the environment (DASK_DISTRIBUTED__...),
    for a `volcl worker` process; values the environment already sets win."""
    out = dict(env)
    for key, value in QUIET_DASK.items():
        name = "DASK_" + "__".join(part.upper().replace("-", "_") for part in key.split("."))
        out.setdefault(name, str(value))
    return out


def local_worker_env(n: int) -> dict:
    """The environment of `local:N` worker processes: each renders on its share of this machine's
    cores (PoCL's CPU device would otherwise start a thread per core in every worker, and N
    workers would fight over the cores); a POCL_MAX_PTHREAD_COUNT set by the user wins."""
    threads = os.environ.get("POCL_MAX_PTHREAD_COUNT") or str(max(1, (os.cpu_count() or 1) // n))
    return {"POCL_MAX_PTHREAD_COUNT": threads}


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
    uploaded again); the samples done tell whether they are. The scene is known by the name the
    client gave it (spec["scene"]), not by the object: Dask may drop a worker's copy of the scene
    between tasks and fetch it again (its active memory manager keeps one copy of data no queued
    task needs), and the copy is the same scene."""
    from .renderer import Renderer
    name = (spec["scene"], scene.version)
    key = (name, repr(spec), tile)
    cache = getattr(_local, "renderers", None)
    if cache is None or cache.get("scene") != name:
        cache = _local.renderers = {"scene": name}
    # Taken out of the cache while the task runs, and put back by tile_round once it has
    # succeeded: a task that fails mid-pass leaves accumulators no retry may start from.
    r = cache.pop(key, None)
    if r is not None and start and r.samples_done == start:
        return r, key, True
    r = Renderer(scene, device=worker_device(), features=spec["features"], seed=spec["seed"],
                 estimator=spec["estimator"], tile=tile, engine=spec["engine"])
    return r, key, False


def warm(scene, spec) -> str:
    """A task run once on each worker before the first round: the programs of the tiles' engine
    built (a tile's Renderer builds those and no others), the scene uploaded, so that render time
    is rendering."""
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
    lookahead = LOOKAHEAD       # 1: each round waits for the one before (benchmarks compare)
    round_growth = CLUSTER_ROUND_GROWTH

    def __init__(self, client):
        self.client = client
        self.failures: list = []
        self._scene = None          # the scene's future on the workers
        self._prepared = None       # the scene itself, sent again if the workers lose every copy
        self._prepares = 0
        self._resends = 0
        self._spec = None
        self._labels: list = []
        self._renders = 0
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
        self._prepares += 1
        self._spec = {"features": render.feature_override, "seed": render.seed, "estimator": render.estimator,
                      "engine": render.ENGINE, "scene": f"{self._id}-{self._prepares}"}
        self._prepared = render.prepared
        self._scene = self.client.scatter(render.prepared, broadcast=True, hash=False)
        futures = [self.client.submit(warm, self._scene, self._spec, workers=[addr], pure=False,
                                      key=f"{self._id}-warm-{i}")
                   for i, addr in enumerate(self.workers)]
        self._labels = [str(label) for label in self._wait(futures)]

    def _wait(self, futures) -> list:
        try:
            for _ in _import_distributed().as_completed(futures, loop=self.client.loop):  # Ctrl-C is not held
                pass
        except BaseException:
            self.client.cancel(futures)
            raise
        return [f.result() for f in futures]

    def stream(self, render: TiledRender, target, rules, progress) -> str:
        """TiledRender.render's rounds, overlapped: a tile's next round is submitted as soon as its
        last one returns, so no worker waits at the end of a round for the others' last tiles; a
        round is merged into the image (and the rules checked) once every tile has it. The stop
        reason; WorkersFailed (with the last whole round) when a task fails on every try."""
        self._renders += 1
        run = _Stream(self, render, target, rules, f"{self._id}-{self._renders}")
        try:
            return run.go(progress)
        except WorkersFailed as exc:
            exc.result = render.result()
            exc.result.stop_reason = "failed"
            raise
        finally:
            run.cancel()

    def scene_lost(self) -> bool:
        """Whether the workers hold no copy of the scene (each worker that had one has died: the client
        scattered it, so Dask cannot compute it again, and the tasks that need it are cancelled)."""
        if self._scene.status != "finished":
            return True
        return not self.client.who_has([self._scene]).get(self._scene.key)

    def resend(self):
        """Scatter the scene again (to the workers the nannies restarted, or any that joined), under a
        new key, once per loss; WorkersFailed after SCENE_RESENDS losses in one executor."""
        if self._resends >= SCENE_RESENDS:
            raise WorkersFailed(f"the workers lost every copy of the scene {self._resends + 1} times; "
                                "giving up (are they running out of memory? see their logs)")
        self._resends += 1
        self.failures.append(("scene", "every worker holding a copy died (sent again)"))
        wait_for_workers(self.client)
        self._scene.release()
        self._scene = self.client.scatter(self._prepared, broadcast=True, hash=False)

    def close(self):
        self._prepared = None
        if self._scene is not None:
            self._scene.release()
            self._scene = None


class _Stream:
    """The rounds of one render on the cluster: round k adds samples starts[k] .. starts[k + 1] - 1
    to every tile. Round lengths are decided as the first tile needs them, from the speed the
    tasks report; tiles run at most LOOKAHEAD rounds ahead of the image (the rounds merged), and
    earlier rounds have priority, so the image's next round is never starved."""

    def __init__(self, executor: DaskExecutor, render: TiledRender, target, rules, key: str):
        self.ex, self.render, self.target, self.rules, self.key = executor, render, target, rules, key
        self.n = len(render.tile_list)
        self.starts = [render.samples_done]
        self.held: list[list] = []      # held[k][i]: tile i's TileJob of round k, once rendered
        self.merged = 0                 # rounds in the image
        self.waiting: list = []         # (tile, round) held back by LOOKAHEAD
        self.cost = [0.0] * self.n      # worker seconds per sample of each tile, as last measured
        # (the client's own loop: the default client may be another one)
        self.ac = _import_distributed().as_completed(loop=executor.client.loop, with_results=True,
                                                     raise_errors=False)
        self.jobs: dict = {}            # future -> TileJob in flight
        self.t0 = time.perf_counter()
        # The first round a task failed in on every try, and that failure: rounds from it on are not
        # submitted, and the rounds before it finish and are merged before the render stops, so the
        # image it keeps does not depend on how far the other tiles had got.
        self.broken: float = float("inf")
        self.error: WorkersFailed | None = None

    def count(self, k: int) -> int | None:
        """Round k's samples per pixel (None: the render ends before round k)."""
        while len(self.held) <= k:
            start = self.starts[-1]
            if self.target is not None and start >= self.target:
                return None
            last = self.starts[-1] - self.starts[-2] if len(self.starts) > 1 else 0
            rate = self.rate()
            count = self.render.round_length(rate, last, self.target, self.rules, done=start,
                                             growth=self.ex.round_growth)
            if rate is not None and self.target is not None and count == self.target - start:
                count = self._tail(count, rate, start)
            self.starts.append(start + count)
            self.held.append([None] * self.n)
        return self.starts[k + 1] - self.starts[k]

    def _tail(self, count: int, rate: float, start: int) -> int:
        """The render's last rounds halve, down to 1/TAIL_SPLIT of a round's seconds: the tasks a
        worker may be left alone with at the end are short."""
        shortest = max(1, int(rate * self.render.round_seconds / TAIL_SPLIT))
        if count <= shortest:
            return count
        half = max(shortest, count // 2)
        if count - half < shortest:                 # no shorter round after it
            return count
        slots = self.render.slots
        first_pass = slots - start % slots           # whole passes of the slots, as round_length keeps
        return half if half < first_pass else first_pass + (half - first_pass) // slots * slots

    def rate(self) -> float | None:
        """Samples per pixel per second of the whole image on all workers, from the tasks' times."""
        known = [(c, t.pixels) for c, t in zip(self.cost, self.render.tile_list) if c > 0]
        if not known:
            return None
        per_pixel = sum(c for c, _ in known) / sum(p for _, p in known)
        seconds = sum(c if c > 0 else per_pixel * t.pixels for c, t in zip(self.cost, self.render.tile_list))
        return self.ex.size / seconds

    def submit(self, i: int, k: int):
        """Tile i's round k, from its state at the round's start (the image's, or its round k - 1)."""
        if k >= self.broken:
            return
        count = self.count(k)
        if count is None:
            return
        if k - self.merged >= self.ex.lookahead:
            self.waiting.append((i, k))
            return
        job = TileJob(i, self.render.tile_list[i], self.starts[k], count, self.cost[i], self.render)
        state = None if job.start == 0 else (self.render.tile_state(i) if k == self.merged
                                             else self.held[k - 1][i].out)
        f = self.ex.client.submit(tile_round, self.ex._scene, self.ex._spec, job.tile, state, count,
                                  key=f"{self.prefix()}r{k}-t{i}", pure=False,
                                  retries=TASK_RETRIES, priority=-k)
        job.round = k
        self.jobs[f] = job
        self.ac.add(f)

    def go(self, progress) -> str:
        for i in range(self.n):
            self.submit(i, 0)
        for f, out in self.ac:
            job = self.jobs.pop(f)
            if f.status == "cancelled" and self.cancelled_with_scene(f):
                self.submit(job.index, job.round)       # a new task, on the scene sent again
                continue
            if f.status in ("error", "cancelled"):
                self.failed(f, job, out)
                if self.merged >= self.broken:
                    raise self.error
                continue
            if f.status != "finished":          # its result lost with its worker: Dask computes it again
                self.jobs[f] = job
                self.ac.add(f)
                continue
            if job.round >= self.broken:        # a round the image will never have
                continue
            job.out, job.worker, job.seconds = out["state"], out["worker"], out["seconds"]
            self.cost[job.index] = job.seconds / job.count
            self.held[job.round][job.index] = job
            self.render.tile_done(job)
            self.submit(job.index, job.round + 1)
            while self.merged < min(len(self.held), self.broken) and all(self.held[self.merged]):
                reason = self.merge(progress)
                if reason is not None:
                    return reason
            if self.merged >= self.broken:
                raise self.error
        if self.error is not None:
            raise self.error
        return "spp"

    def cancelled_with_scene(self, f) -> bool:
        """Whether cancelled task `f` was cancelled because the scene it needs was lost; if so, the
        scene is sent again (once: the other tasks cancelled with it find it sent)."""
        if not f.key.startswith(self.prefix()):        # submitted before the scene was sent again
            return True
        if self.ex.scene_lost():
            self.ex.resend()
            return True
        return False

    def prefix(self) -> str:
        """The keys of the tasks that need the scene as last sent."""
        return f"{self.key}-s{self.ex._resends}-"

    def merge(self, progress) -> str | None:
        """The image's next round, which every tile has; the rules' reason to stop, if any."""
        k = self.merged
        jobs, self.held[k] = self.held[k], [True] * self.n     # round k's states go to the image
        self.render.merge(jobs)
        now = time.perf_counter()
        reason = self.render.round_ended(self.starts[k + 1] - self.starts[k], now - self.t0, progress, self.rules)
        self.t0 = now
        self.merged += 1
        if reason is None:
            waiting, self.waiting = self.waiting, []
            for i, r in waiting:
                self.submit(i, r)
        return reason

    def failed(self, f, job, out):
        """A task failed on every try: its round and the ones after it are given up."""
        if isinstance(out, BaseException):      # cancelled
            why = f"{type(out).__name__}: {out}"
        else:
            why = f"{out[0].__name__}: {out[1]}"
        self.ex.failures.append((f"task {f.key}", why))
        if job.round < self.broken:
            self.broken = job.round
            self.error = WorkersFailed(f"tile {job.tile} failed on the cluster on each of its {1 + TASK_RETRIES} "
                                       f"tries ({why})", self.ex.failures)

    def cancel(self):
        """Tasks still in flight (the render has stopped, failed or ended) are not wanted."""
        if self.jobs:
            self.ex.client.cancel(list(self.jobs))
        self.jobs.clear()
        self.ac.clear()
