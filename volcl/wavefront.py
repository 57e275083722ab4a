"""The wavefront renderer: a render_pass launch (kernels/render.cl) done as a loop of two stage
kernels over the same work-items, so that the medium steps of homogeneous media run in the CPU's
SIMD lanes.

volcl's megakernel takes one path per work-item through everything, and no CPU runtime vectorizes
it (README, "Can a wavefront stage run in the SIMD lanes?"). Here each work-item's path keeps its
state in device arrays between launches (kernels/wavefront_state.h), and every step is two
launches: the scalar stage (kernels/wavefront.cl: shadow rays, surface events, roulette, the
accumulators and the next sample, the next ray's closest hit, with the megakernel's functions) and
the lanes stage (kernels/wavefront_lanes.cl: the medium segment, written for the vectorizers).
A path renders its work-item's samples into the same accumulator entry in the same order as the
megakernel, drawing the same random numbers, so everything built on render_pass (slots, tiles,
checkpoints, several devices) works unchanged; the images agree with the megakernel's up to the
roundings of the lanes stage's arithmetic (vector exp, log and sqrt), and where a rounding sends a
path another way.

It renders scenes whose media are all homogeneous, with the path integrator, on CPU devices; the
lanes stage samples point lights itself and leaves NEE towards other lights to the scalar stage.
A scene of a few opaque triangles (tiny_lanes) needs no BVH: the lanes stage tests every triangle
for the closest hit and the medium event's two shadow rays (kernels/lanes_triangles.h), with the
BVH's bits, so those queries run in the lanes too, and it takes the roulette after a scatter.
A Renderer takes it by itself ("auto") where it pays (pays()), or when asked (engine="wavefront").
"""
from __future__ import annotations

import threading
import weakref

import numpy as np

from . import layout
from .opencl import cl
from .pack import ARG_ORDER

# kernels/wavefront_state.h: rows of the state arrays, their stride, the flag that a path is alive,
# the event of a path about to start a sample, and the lanes stage's table of lights and media
FLOAT_ROWS = 42
INT_ROWS = 13
STRIDE = 65552                  # at most STRIDE - 16 paths in flight (wavefront_state.h)
ROW_FLAGS = 2
ROW_EVENT = 5
FLAG_ALIVE = 1
EVENT_START = 17
TABLE_STRIDE = 64
TABLE_ROWS = 16
T_LIGHT_POS, T_LIGHT_VALUE, T_SIGMA_T, T_ALBEDO, T_G, T_ISO, T_LANES, T_POINT = 0, 3, 6, 9, 12, 13, 14, 15
TRI_SPACING = 16        # words between a tiny scene's triangle numbers (wavefront_state.h WF_TRI_AT)
# the most triangles of a scene the lanes stage traces itself, testing every one for every ray
# (kernels/lanes_triangles.h)
TINY_LANES = 16
# steps between looks at whether every path has finished (the host reads the flags as the next
# batch runs)
CHECK_EVERY = 8
# paths in flight (at most STRIDE - 16): few enough for their state (about 220 bytes each) to stay in the
# caches: on point_in_fog (AVX-512 host, PoCL) 4096 took 2.23 s, 2048 2.37 s, 16384 2.49 s,
# 65536 4.28 s
PATHS = 4096

LANES_FILE = "wavefront_lanes.cl"
SCALAR_FILE = "wavefront.cl"

ENGINES = ("auto", "megakernel", "wavefront")


def supported(features: dict, packed, params, device) -> str | None:
    """Why the wavefront renderer cannot render this, or None when it can: a CPU, media all
    homogeneous, no spot lights."""
    if device.kind != "cpu":
        return "the lanes stage is written for CPU vectorizers; a GPU runs the megakernel's work-items in lanes already"
    if not features.get("MEDIA"):
        return "the scene has no medium, which the lanes stage steps through"
    for name in ("GRID_MEDIA", "EMISSIVE_MEDIA", "EMISSION_NEE", "PHASE_FAMILIES", "DIRECT", "SPOT_LIGHTS"):
        if features.get(name):
            return f"feature {name} is not in the lanes stage"
    lights, media = packed.arrays["lights"], packed.arrays["media"]
    if max(len(lights), len(media)) > TABLE_STRIDE:
        return f"the lanes stage's table holds {TABLE_STRIDE} lights and media"
    if int(params["integrator"]) != layout.INTEGRATORS["path"]:
        return "the lanes stage is the path integrator's"
    return None


def pays(packed, params) -> bool:
    """Whether "auto" takes the wavefront renderer for a scene it supports: where the lanes stage
    does most of the work, the camera inside a medium (every camera segment is a medium segment) lit
    by point lights alone (all NEE in the lanes). Measured on the shipped scenes (README, "The
    wavefront renderer"): point_in_fog 1.84x the megakernel's speed on PoCL and 2.25x on Intel's
    runtime (tested whole, tiny_lanes; 1.03-1.26x and 1.22-1.48x through the BVH); scenes with
    area or environment lights, or the camera outside the medium, 0.45x-0.83x."""
    lights = packed.arrays["lights"]
    return (int(params["camera_medium"]) >= 0 and len(lights) > 0
            and bool(np.all(lights["type"] == layout.LIGHT_TYPES["point"])))


def _used_lanes(leaves) -> np.ndarray:
    """(packets, lanes) mask of the leaf packets' lanes that hold a triangle (unused lanes hold the
    zero triangle)."""
    return np.any(leaves["v"] != 0, axis=1)


def tiny_lanes(packed, features: dict) -> tuple[int, int]:
    """The triangles the lanes stage tests for every ray when the scene is small enough to trace
    whole, as (how many, a mask of those that end a leaf packet): at most TINY_LANES triangles, every
    primitive an opaque triangle (so a shadow ray is blocked by any hit); else (0, 0)."""
    leaves = packed.arrays["leaves"]
    used = _used_lanes(leaves)
    count = int(used.sum())
    if (features.get("INSTANCES") or count == 0 or count > TINY_LANES or np.any(leaves["prim"] < 0)
            or not np.all(leaves["opaque"][used] == -1)):
        return 0, 0
    # the packets' lanes are filled first to last: a packet's last used lane ends it
    ends = np.cumsum(used.sum(axis=1))[used.any(axis=1)] - 1
    return count, int(np.sum(1 << ends))


def lanes_table(packed, tiny: int = 0) -> np.ndarray:
    """The lights' and media's parameters the lanes stage reads (wavefront_state.h's table), and
    with `tiny` the scene's triangles in packet order (lanes_triangles.h)."""
    t = np.zeros((TABLE_ROWS, TABLE_STRIDE), np.float32)
    tri = np.zeros((10, tiny, TRI_SPACING), np.float32)
    if tiny:
        leaves = packed.arrays["leaves"]
        used = _used_lanes(leaves)
        tri[:9, :, 0] = leaves["v"].transpose(1, 0, 2)[:, used]
        tri[9, :, 0] = leaves["prim"][used].astype(np.int32).view(np.float32)
    lights, media = packed.arrays["lights"], packed.arrays["media"]
    t[T_LIGHT_POS:T_LIGHT_POS + 3, :len(lights)] = lights["position"].T
    t[T_LIGHT_VALUE:T_LIGHT_VALUE + 3, :len(lights)] = lights["value"].T
    t[T_SIGMA_T:T_SIGMA_T + 3, :len(media)] = media["sigma_t"].T
    t[T_ALBEDO:T_ALBEDO + 3, :len(media)] = media["albedo"].T
    hg = media["phase"] == layout.PHASE_TYPES["hg"]
    t[T_G, :len(media)] = np.where(hg, media["g"], 0.0)
    t[T_ISO, :len(media)] = media["phase"] == layout.PHASE_TYPES["isotropic"]
    t[T_LANES, :len(media)] = (media["type"] == layout.MEDIUM_TYPES["homogeneous"]) & (t[T_ISO, :len(media)] + hg > 0)
    t[T_POINT, :len(lights)] = lights["type"] == layout.LIGHT_TYPES["point"]
    return np.concatenate([t.reshape(-1), tri.reshape(-1)])


class _DeviceState:
    """The path state arrays of one device (14 MB), shared by its wavefront renderers, one run at a
    time: a render on several devices makes a Renderer for every tile it hands out."""

    def __init__(self, device):
        mf = cl.mem_flags
        self.fs = cl.Buffer(device.ctx, mf.READ_WRITE, 4 * FLOAT_ROWS * STRIDE)
        self.is_ = cl.Buffer(device.ctx, mf.READ_WRITE, 4 * INT_ROWS * STRIDE)
        self.next_job = cl.Buffer(device.ctx, mf.READ_WRITE, 4)
        # zeroed once, so that no stage reads a word never written
        cl.enqueue_copy(device.queue, self.fs, np.zeros(FLOAT_ROWS * STRIDE, np.float32))
        cl.enqueue_copy(device.queue, self.is_, np.zeros(INT_ROWS * STRIDE, np.int32))
        self.lock = threading.Lock()


_states: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()
_states_lock = threading.Lock()


def device_state(device) -> _DeviceState:
    with _states_lock:
        state = _states.get(device)
        if state is None:
            state = _states[device] = _DeviceState(device)
        return state


class Wavefront:
    """The stage kernels of one Renderer's feature set, and the loop that runs them."""

    def __init__(self, device, features: dict, packed, group_items: int, paths: int = PATHS, tiny: bool = True):
        self.device = device
        self.tiny, ends = tiny_lanes(packed, features) if tiny else (0, 0)
        extra = (f"-DVOLCL_WF_TINY={self.tiny}", f"-DVOLCL_WF_TINY_ENDS={ends}") if self.tiny else ()
        program = device.program(features, SCALAR_FILE, extra)
        self.scalar = cl.Kernel(program, "wavefront_scalar")
        self.add = cl.Kernel(program, "wavefront_add")
        self.lanes = cl.Kernel(device.program(features, LANES_FILE, extra), "wavefront_medium")
        self.group_items = group_items
        self.paths = -(-min(paths, STRIDE - 16) // group_items) * group_items
        self.table = cl.Buffer(device.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                               hostbuf=lanes_table(packed, self.tiny))
        self.results = None
        self.steps = 0          # stage pairs launched so far (benchmarks read it)

    def run(self, scene_args, accum, launch_args, items: int):
        """Everything render_pass(scene_args, accum, launch_args) would render over `items`
        work-items (scene_args in volcl.pack.ARG_ORDER; launch_args: sample_base, tile x, y, width,
        pixels, first, count, slots, passes)."""
        state = device_state(self.device)
        with state.lock:
            self._run(state, scene_args, accum, launch_args, items)

    def _run(self, state, scene_args, accum, launch_args, items: int):
        queue = self.device.queue
        passes = int(launch_args[-1])
        jobs = items * passes
        if self.results is None or self.results.size < 16 * jobs:
            self.results = cl.Buffer(self.device.ctx, cl.mem_flags.READ_WRITE, 16 * jobs)
        n = min(self.paths, -(-jobs // self.group_items) * self.group_items)
        ints = np.zeros((2, n), np.int32)
        ints[0] = FLAG_ALIVE
        ints[1] = EVENT_START
        for k, row in enumerate((ROW_FLAGS, ROW_EVENT)):
            cl.enqueue_copy(queue, state.is_, ints[k], dst_offset=4 * row * STRIDE)
        cl.enqueue_copy(queue, state.next_job, np.zeros(1, np.int32))
        params = dict(zip(ARG_ORDER, scene_args))["params"]
        self.lanes.set_args(state.fs, state.is_, self.table, params)
        self.scalar.set_args(*scene_args, self.results, state.next_job, *launch_args, state.fs, state.is_)
        size, local = (n,), (self.group_items,)
        # the paths' flags after each batch of steps, read without waiting: the host looks at the
        # last batch's while the device runs the next (one batch of finished paths at the end is
        # the price; waiting for every read left the device idle between batches)
        flags = [np.empty(n, np.int32), np.empty(n, np.int32)]
        reads = []
        while True:
            for _ in range(CHECK_EVERY):
                cl.enqueue_nd_range_kernel(queue, self.scalar, size, local)
                cl.enqueue_nd_range_kernel(queue, self.lanes, size, local)
                self.steps += 1
            host = flags[len(reads) % 2]
            reads.append((cl.enqueue_copy(queue, host, state.is_, src_offset=4 * ROW_FLAGS * STRIDE,
                                          is_blocking=False), host))
            if len(reads) > 1:
                event, done = reads[-2]
                event.wait()
                if not np.any(done & FLAG_ALIVE):
                    break
        reads[-1][0].wait()
        t = launch_args
        self.add.set_args(self.results, *accum, t[4], t[5], t[6], t[7], t[8])
        cl.enqueue_nd_range_kernel(queue, self.add, (-(-items // self.group_items) * self.group_items,), local)
