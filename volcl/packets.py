"""The packet renderer (kernels/packets.cl): render_pass for scenes small enough to test whole, with
each work item rendering PACKET_WIDTH of render_pass's work items as the lanes of one packet, whose
rays (continuation and shadow rays together) are traced in the SIMD lanes against every primitive
(kernels/packet_queries.h) instead of by a tree walk per ray.

The lanes run the megakernel's path functions (lanes that hit a plain diffuse triangle take that
step together in the vector lanes where vector_step_pays, kernels/packet_lanes.h, and those at a
rough plastic one where bsdf_steps_pay too, kernels/lanes_rough.h, with the same arithmetic), so
a pixel gets the same samples, added in the same order into the same accumulator
entry; the queries make the tree's tests with its arithmetic, so the hits have its bits, but for
which of two primitives at the same distance wins where the tree visits them in another order.
Everything built on render_pass (slots, tiles, checkpoints, several devices) works unchanged.
"""
from __future__ import annotations

import numpy as np

from . import device as devmod
from . import layout, wavefront
from .opencl import cl

SOURCE_FILE = "packets.cl"
KERNEL = "render_packets"
# lanes of a packet: float16 fills an AVX-512 register (PoCL splits it in two 256-bit halves); 8
# lanes ran as fast on both runtimes (cbox, textured_cbox on the AMD AVX-512 host)
PACKET_WIDTH = 16
# the most primitives (used triangle lanes and spheres) the packet renderer tests for every ray:
# testing every one costs about as much as the tree walk near 40 (cbox with an icosphere: 34
# primitives 1.07-1.13x the megakernel's speed, 94 0.63-0.72x, 334 0.24-0.29x; README)
MAX_PRIMITIVES = 40
# packets per work-group: PoCL ran its work-groups of 64 packets at 0.77x the speed of single ones
# (cbox; each packet's lanes hold a few KB of path state, which a group of them keeps apart)
GROUP_PACKETS = 1
# features whose surfaces or media let light through, which a shadow ray as an occlusion query
# cannot follow, or that the queries do not test
EXCLUDED = ("MEDIA", "NULL_BSDF", "MASK", "THINDIELECTRIC", "EMISSION_NEE", "INSTANCES", "CYLINDERS", "DIRECT")


def primitive_count(packed) -> int:
    """The triangles and spheres the queries test: the scene tree's used leaf lanes."""
    leaves = packed.arrays["leaves"][:packed.scene_leaves]
    used = np.any(leaves["v"] != 0, axis=1) | (leaves["prim"] < 0)
    return int(used.sum())


def runs_on(device) -> bool:
    """Whether the packet renderer renders on this device (volcl.device.Device): CPUs."""
    return device.kind == "cpu"


def vector_step_pays(device) -> bool:
    """Whether the packet renderer takes its diffuse lanes' steps together in the vector lanes
    (kernels/packet_lanes.h) on this device by default: on PoCL (cbox 1.24x the scalar steps'
    speed, textured_cbox 1.12x), not on Intel's CPU runtime, whose compiler leaves the loop over
    the lanes scalar (0.73x and 0.83x: README). Packets(vector_step=) overrides it."""
    return devmod.is_pocl(device)


def bsdf_steps_pay(device) -> bool:
    """Whether the vector step also takes the lanes at rough plastic triangles (kernels/lanes_rough.h)
    on this device, where it takes a vector step at all: on PoCL, whose vector code gives its scalar code's bits there; not on
    Intel's CPU runtime, whose vector code rounds the microfacet arithmetic otherwise (a weight
    3e-3 off, which sends a path elsewhere: benchmarks/shading_lanes.py, README), and whose vector
    steps ran slower than its scalar ones anyway. Packets(bsdf_steps=) overrides it."""
    return devmod.is_pocl(device)


def supported(features: dict, packed, params, device) -> str | None:
    """Why the packet renderer cannot render this, or None when it can."""
    if not runs_on(device):
        return "the packet renderer is written for a CPU's SIMD lanes"
    for name in EXCLUDED:
        if features.get(name):
            return f"feature {name} is not in the packet renderer"
    if int(params["integrator"]) != layout.INTEGRATORS["path"]:
        return "the packet renderer is the path integrator's"
    n = primitive_count(packed)
    if n > MAX_PRIMITIVES:
        return f"the scene has {n} primitives; the packet renderer tests at most {MAX_PRIMITIVES} for every ray"
    return None


class Packets:
    """The packet renderer's kernel for one Renderer, launched where render_pass would be."""

    engine = "packet"

    def __init__(self, device, features: dict, packed, vector_step: bool | None = None,
                 bsdf_steps: bool | None = None):
        """vector_step: whether diffuse lanes take their steps in the vector lanes where the scene
        allows (default: where vector_step_pays); bsdf_steps: whether lanes at rough plastic
        triangles take theirs there too, with a vector step (default: where bsdf_steps_pay);
        self.bsdf_steps names the steps the kernel takes."""
        self.device = device
        self.width = width = PACKET_WIDTH
        extra = (f"-DVOLCL_PACKET_WIDTH={width}",)
        if vector_step is None:
            vector_step = vector_step_pays(device)
        if bsdf_steps is None:
            bsdf_steps = bsdf_steps_pay(device)
        lanes = wavefront.diffuse_lanes(packed, bsdfs=bsdf_steps) if vector_step else None
        self.bsdf_steps = ()
        if lanes is not None:
            table, slots = lanes.table, lanes.slots
            extra += ("-DVOLCL_PACKET_LANES=1", f"-DVOLCL_WF_TINY={lanes.tris}",
                      f"-DVOLCL_WF_LIGHT_TRIS={lanes.light_tris}", f"-DVOLCL_WF_CHECKERS={lanes.checkers}",
                      f"-DVOLCL_PACKET_BITMAPS={lanes.bitmaps}")
            if lanes.rough:
                extra += ("-DVOLCL_PACKET_ROUGH=1",)
            self.bsdf_steps = ("rough",) if lanes.rough else ()
        else:
            table, slots = np.zeros(1, np.float32), np.full(1, -1, np.int32)
        self.vector_step = lanes is not None
        flags = cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR
        self.lanes_args = (cl.Buffer(device.ctx, flags, hostbuf=table), cl.Buffer(device.ctx, flags, hostbuf=slots))
        self.kernel = cl.Kernel(device.program(features, SOURCE_FILE, extra), KERNEL)
        self.sources = [(SOURCE_FILE, extra)]
        self.group_items = GROUP_PACKETS
        self.leaf_ends = (np.int32(packed.scene_leaves), np.int32(len(packed.arrays["leaves"])))

    def run(self, scene_args, accum, launch_args, items: int):
        """What render_pass(scene_args, accum, launch_args) renders over `items` work items."""
        self.kernel.set_args(*scene_args, *accum, *launch_args, *self.leaf_ends, *self.lanes_args)
        packets = -(-items // self.width)
        size = -(-packets // self.group_items) * self.group_items
        cl.enqueue_nd_range_kernel(self.device.queue, self.kernel, (size,), (self.group_items,))
