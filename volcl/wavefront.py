"""The wavefront renderer: a render_pass launch (kernels/render.cl) done as a loop of two stage
kernels over the same work-items, so that the medium steps of homogeneous media, and the diffuse
bounces of small scenes without media, run in the CPU's SIMD lanes.

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
A scene of a few opaque triangles and spheres (tiny_lanes) needs no BVH: the lanes stage tests
every primitive for the closest hit and the medium event's two shadow rays
(kernels/lanes_triangles.h), with the BVH's bits, so those queries run in the lanes too, and it
takes the roulette after a scatter. Such a scene without media (surface_lanes) gets the surface
stage instead (kernels/wavefront_surface.cl): the closest hit, and at a plain diffuse triangle the
whole bounce (NEE towards point lights and area lights on triangles, its shadow ray, the new
direction, the roulette), bit for bit the megakernel's; other surfaces go to the scalar stage.
A Renderer takes it by itself ("auto") where it pays (pays()), or when asked (engine="wavefront").
"""
from __future__ import annotations

import threading
from typing import NamedTuple
import weakref

import numpy as np

from . import device as devmod
from . import layout
from . import lanes_bsdfs
from . import packets
from .errors import VolclError
from .opencl import cl
from .pack import ARG_ORDER
from .program import ENTRY_FILE

# kernels/wavefront_state.h: rows of the state arrays, their stride, the flag that a path is alive,
# and the lanes stage's table of lights and media
FLOAT_ROWS = 42
INT_ROWS = 13
STRIDE = 65552                  # at most STRIDE - 16 paths in flight (wavefront_state.h)
ROW_FLAGS = 2
FLAG_ALIVE = 1
TABLE_STRIDE = 64
TABLE_ROWS = 18
T_LIGHT_POS, T_LIGHT_VALUE, T_SIGMA_T, T_ALBEDO, T_G, T_ISO, T_LANES, T_POINT, T_AREA, T_SEALED = (
    0, 3, 6, 9, 12, 13, 14, 15, 16, 17)
TRI_SPACING = 16        # words between a tiny scene's triangle numbers (wavefront_state.h WF_TRI_AT)
TRI_COORDS, SPHERE_COORDS, LIGHT_TRI_COORDS = 35, 5, 16     # numbers per triangle, sphere, light triangle
TRI_COORDS_BSDFS = 57   # per triangle in the packet renderer's table, with its bsdf steps' numbers
# the most triangles and spheres of a scene the lanes stage traces itself, testing every one for
# every ray (kernels/lanes_triangles.h), and light triangles the surface stage samples
TINY_LANES = 16
TINY_SPHERES = 4
TINY_LIGHT_TRIANGLES = 16
# bsdf flags that a diffuse surface in the surface stage must not have (the others concern
# microfacets and bump maps)
FLAG_UV, FLAG_UV_FRAME, FLAG_PASSES = (layout.BSDF_FLAGS[k] for k in ("uv", "uv_frame", "passes"))
# steps between looks at whether every path has finished (the host reads the flags as the next
# batch runs)
CHECK_EVERY = 8
# paths in flight (at most STRIDE - 16): few enough for their state (about 220 bytes each) to stay in the
# caches: on point_in_fog (AVX-512 host, PoCL) 4096 took 2.23 s, 2048 2.37 s, 16384 2.49 s,
# 65536 4.28 s
PATHS = 4096

# the medium stage's paths per work-item on PoCL (lanes_loop)
LOOP_PATHS = 16

LANES_FILE = "wavefront_lanes.cl"
SURFACE_FILE = "wavefront_surface.cl"
SCALAR_FILE = "wavefront.cl"

ENGINES = ("auto", "megakernel", "wavefront", "packet")


def supported(features: dict, packed, params, device) -> str | None:
    """Why the wavefront renderer cannot render this, or None when it can: a CPU, media all
    homogeneous, no spot lights; or no media and what the surface stage takes (surface_lanes)."""
    if device.kind != "cpu":
        return "the lanes stage is written for CPU vectorizers; a GPU runs the megakernel's work-items in lanes already"
    if not features.get("MEDIA"):
        return surface_lanes(packed, features, params)
    for name in ("GRID_MEDIA", "EMISSIVE_MEDIA", "EMISSION_NEE", "PHASE_FAMILIES", "DIRECT", "SPOT_LIGHTS"):
        if features.get(name):
            return f"feature {name} is not in the lanes stage"
    lights, media = packed.arrays["lights"], packed.arrays["media"]
    if max(len(lights), len(media)) > TABLE_STRIDE:
        return f"the lanes stage's table holds {TABLE_STRIDE} lights and media"
    if int(params["integrator"]) != layout.INTEGRATORS["path"]:
        return "the lanes stage is the path integrator's"
    return None


def pays(features: dict, packed, params, device) -> bool:
    """Whether "auto" takes the wavefront renderer for a scene it supports, as measured on the
    shipped scenes (README, "The wavefront renderer"):
    - with media, where the lanes stage does most of the work: the camera inside a medium (every
      camera segment is a medium segment) lit by point lights alone (all NEE in the lanes).
      point_in_fog: 1.84x the megakernel's speed on PoCL and 2.25x on Intel's runtime (tested
      whole, tiny_lanes; 1.03-1.26x and 1.22-1.48x through the BVH); scenes with area or
      environment lights, or the camera outside the medium, 0.45x-0.83x;
    - without media (the surface stage), where surface_stage_pays() says so; start() gives every
      such scene to the packet renderer first (volcl.packets), which takes them all."""
    lights = packed.arrays["lights"]
    if not features.get("MEDIA"):
        return surface_stage_pays(device)
    if int(params["camera_medium"]) < 0:
        return False
    return len(lights) > 0 and bool(np.all(lights["type"] == layout.LIGHT_TYPES["point"]))


def start(engine: str, features: dict, packed, params, device):
    """The engine of a render, with the programs it launches built on `device` and no others:
    (a Wavefront or a volcl.packets.Packets, or None for the megakernel; those programs as (source
    file, extra options)). `engine` is "megakernel", "wavefront", "packet", or "auto": the packet
    renderer where volcl.packets.supported() (it was faster than the megakernel on every scene it
    takes), else the wavefront where supported() and pays().
    A render on several devices calls this on each before its tiles' renderers do (which then
    find the programs built)."""
    if engine not in ENGINES:
        raise VolclError(f"engine {engine!r}: expected one of {', '.join(ENGINES)}")
    if engine in ("packet", "auto"):
        why_not = packets.supported(features, packed, params, device)
        if why_not is not None and engine == "packet":
            raise VolclError(f"the packet renderer cannot render this scene: {why_not}")
        if why_not is None:
            pk = packets.Packets(device, features, packed)
            return pk, pk.sources
    if engine != "megakernel":
        why_not = supported(features, packed, params, device)
        if why_not is not None and engine == "wavefront":
            raise VolclError(f"the wavefront renderer cannot render this scene: {why_not}")
        if why_not is None and (engine == "wavefront" or pays(features, packed, params, device)):
            wf = Wavefront(device, features, packed)
            return wf, wf.sources
    device.program(features)
    return None, [(ENTRY_FILE, ())]


def lanes_loop(device) -> int:
    """Paths per work-item of the medium stage (kernels/wavefront_lanes.cl VOLCL_WF_LOOP), in a loop
    LLVM's loop vectorizer runs in the SIMD lanes: LOOP_PATHS on PoCL, whose vectorizer across
    work-items the SLP vectorizer's packing stopped on AVX2 (README, "The medium stage as a loop
    of its own"); 0 (one path per work-item) on other runtimes."""
    return LOOP_PATHS if devmod.is_pocl(device) else 0


def surface_stage_pays(device) -> bool:
    """Whether "auto" takes the surface stage on this device (where surface_lanes() takes the
    scene): on Intel's CPU runtime (cbox 1.12-1.21x the megakernel's speed), not on PoCL
    (0.72-0.80x: its vectorized stage runs 8 lanes and took about twice Intel's time a path)."""
    return device.kind == "cpu" and "intel" in device.platform_name.lower()


def scene_leaves(packed) -> np.ndarray:
    """The leaf packets of the scene's tree (the shadow tree's follow them: volcl.hull)."""
    return packed.arrays["leaves"][:packed.scene_leaves]


def hull_skip(packed, count: int) -> int:
    """A mask of the tested triangles (in packet order) that shadow rays from surfaces skip: the
    faces of the scene's convex hull, where the megakernel leaves them out too (volcl.hull)."""
    _, codes = _tiny_triangles(packed, count)
    return int(np.sum(1 << np.flatnonzero(np.isin(codes, packed.hull_faces))))


def _used_lanes(leaves) -> np.ndarray:
    """(packets, lanes) mask of the leaf packets' triangle lanes (unused lanes hold the zero
    triangle, analytic ones a negative code)."""
    return np.any(leaves["v"] != 0, axis=1)


def tiny_lanes(packed, features: dict) -> tuple[int, int, int]:
    """What the lanes stage tests for every ray when the scene is small enough to trace whole, as
    (triangles, a mask of those that end a leaf packet, spheres): at most TINY_LANES triangles and
    TINY_SPHERES spheres, every primitive opaque (so a shadow ray is blocked by any hit); else
    (0, 0, 0)."""
    leaves = scene_leaves(packed)
    used = _used_lanes(leaves)
    spheres = leaves["prim"] < 0
    count, n_spheres = int(used.sum()), int(spheres.sum())
    if (features.get("INSTANCES") or features.get("CYLINDERS") or count == 0 or count > TINY_LANES
            or n_spheres > TINY_SPHERES or not np.all(leaves["opaque"][used | spheres] == -1)):
        return 0, 0, 0
    # the packets' lanes are filled first to last: a packet's last used lane ends it
    ends = np.cumsum(used.sum(axis=1))[used.any(axis=1)] - 1
    return count, int(np.sum(1 << ends)), n_spheres


def _library_normals(p0, p1, p2):
    """normalize(cross(p1 - p0, p2 - p0)) in float32 as the OpenCL library computes it on PoCL (no
    fused multiply-adds, v * (1 / sqrt(|v|^2))), and where that holds: not for a zero, tiny or
    huge cross product, which the library scales first."""
    a, b = (p1 - p0).astype(np.float32), (p2 - p0).astype(np.float32)
    c = np.stack([a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1], a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
                  a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]], axis=1)
    with np.errstate(all="ignore"):
        l2 = (c[:, 0] * c[:, 0] + c[:, 1] * c[:, 1]) + c[:, 2] * c[:, 2]
        n = c * (np.float32(1.0) / np.sqrt(l2))[:, None]
    ok = (l2 >= np.finfo(np.float32).tiny) & np.isfinite(l2)
    return n.astype(np.float32), ok


def _tiny_triangles(packed, count):
    """The tested triangles' corners (count, 3, 3) and primitive codes, in packet order."""
    leaves = scene_leaves(packed)
    used = _used_lanes(leaves)
    return leaves["v"].transpose(0, 2, 1)[used].reshape(count, 3, 3), leaves["prim"][used]


def _lanes_surfaces(packed, corners, codes, steps=False):
    """Which tested triangles the surface stage scatters from itself (wavefront_surface.cl): plain
    diffuse, untextured or with a checkerboard of two colours on the mesh's uv, flat, not
    emitting, with a normal whose library bits are known; their normals and bsdf records, which
    of them are checkerboards (_checkers); and with `steps` those the packet renderer's bsdf steps
    take (volcl.lanes_bsdfs.Surfaces; none without)."""
    tris, shapes, bsdfs = packed.arrays["triangles"], packed.arrays["shapes"], packed.arrays["bsdfs"]
    shape = shapes[tris["shape"][codes]]
    bsdf = bsdfs[shape["bsdf"]]
    ng, ok = _library_normals(corners[:, 0], corners[:, 1], corners[:, 2])
    checker = _checkers(packed, codes, shape, bsdf)
    plain = (bsdf["color_tex"] < 0) & (bsdf["flags"] & FLAG_UV == 0)
    surface = ok & (shape["light"] < 0) & (tris["normals"][codes] < 0)
    lanes = (surface & (bsdf["type"] == layout.BSDF_TYPES["diffuse"]) & (plain | checker)
             & (bsdf["flags"] & (FLAG_UV_FRAME | FLAG_PASSES) == 0))
    more = lanes_bsdfs.surfaces(packed, codes, shape, bsdf, surface & steps)
    return lanes, ng, bsdf, checker & lanes, more


def _checkers(packed, codes, shape, bsdf):
    """Which tested triangles' reflectance is a checkerboard of two colours (no nested textures)
    on their mesh's own uv, which the lanes evaluate as texcoords_triangle and texture_leaf do."""
    textures = packed.arrays["textures"]
    index = bsdf["color_tex"]
    if len(textures) == 0 or not np.any(index >= 0):
        return np.zeros(len(codes), bool)
    t = textures[np.maximum(index, 0)]
    return ((index >= 0) & (t["type"] == layout.TEXTURE_TYPES["checkerboard"]) & (t["child0"] < 0)
            & (t["child1"] < 0) & (shape["uv_map"] < 0) & (packed.arrays["triangles"]["uvs"][codes] >= 0))


def surface_lanes(packed, features: dict, params) -> str | None:
    """Why the surface stage (wavefront_surface.cl) cannot take this scene, or None when it can: a
    scene without media tested whole (tiny_lanes), lit by point lights and area lights on at most
    TINY_LIGHT_TRIANGLES flat triangles, rendered by the path integrator."""
    if features.get("MEDIA"):
        return "the surface stage is for scenes without media"
    if tiny_lanes(packed, features)[0] == 0:
        return (f"the scene is not small enough to test whole (at most {TINY_LANES} opaque triangles and "
                f"{TINY_SPHERES} spheres)")
    why = lanes_lights(packed)
    if why:
        return f"the surface stage {why}"
    if int(params["integrator"]) != layout.INTEGRATORS["path"]:
        return "the lanes stage is the path integrator's"
    return None


def lanes_lights(packed) -> str | None:
    """What keeps the diffuse scatter in the lanes (lanes_surface.h lanes_light_sample) from sampling
    the scene's lights, or None where it samples them all: point lights and area lights on at most
    TINY_LIGHT_TRIANGLES flat triangles."""
    lights = packed.arrays["lights"]
    area = lights["type"] == layout.LIGHT_TYPES["area"]
    point = lights["type"] == layout.LIGHT_TYPES["point"]
    if not np.all(point | (area & (lights["sphere"] < 0))):
        return "samples point lights and area lights on triangles only"
    if len(lights) > TABLE_STRIDE or int(lights["tri_count"][area].sum()) > TINY_LIGHT_TRIANGLES:
        return f"samples at most {TINY_LIGHT_TRIANGLES} light triangles"
    tri = packed.arrays["triangles"][_light_triangles(packed)[0]]
    _, ok = _library_normals(tri["p0"], tri["p1"], tri["p2"])
    if not np.all(ok & (tri["normals"] < 0)):
        return "samples flat light triangles whose normals' library bits are known"
    return None


class LanesTable(NamedTuple):
    """What the lanes scatter from (diffuse_lanes): the table, a slot per triangle row (-1 where
    the lanes do not scatter from it), the table's triangle and light triangle counts
    (VOLCL_WF_TINY, VOLCL_WF_LIGHT_TRIS), and 1 or 0: some of them checkered (VOLCL_WF_CHECKERS),
    rough plastic (VOLCL_PACKET_ROUGH), reading a bitmap (VOLCL_PACKET_BITMAPS)."""
    table: np.ndarray
    slots: np.ndarray
    tris: int
    light_tris: int
    checkers: int
    rough: int
    bitmaps: int


def diffuse_lanes(packed, bsdfs: bool = False) -> LanesTable | None:
    """The table with which the lanes scatter from the scene's plain diffuse triangles
    (lanes_surface.h: untextured or checkered with two colours, flat, not emitting), and with
    `bsdfs` also from those the packet renderer's bsdf steps take (volcl.lanes_bsdfs), every used
    triangle of the scene's leaf packets in packet order. None where there is no such triangle or
    the lanes cannot sample the lights."""
    leaves = scene_leaves(packed)
    count = int(_used_lanes(leaves).sum())
    if count == 0 or lanes_lights(packed):
        return None
    corners, codes = _tiny_triangles(packed, count)
    lanes, _, _, checker, more = _lanes_surfaces(packed, corners, codes, bsdfs)
    taken = lanes | more.rough
    if not taken.any():
        return None
    slots = np.full(max(len(packed.arrays["triangles"]), 1), -1, np.int32)
    slots[codes[taken]] = np.flatnonzero(taken)
    return LanesTable(lanes_table(packed, count, 0, True, bsdfs), slots, count, len(_light_triangles(packed)[0]),
                      int(checker.any()), int(more.rough.any()), int((more.bitmap >= 0).any()))


def _light_triangles(packed):
    """The area lights' triangles in light order: (triangle rows, owning light, cdf, cdf before)."""
    lights = packed.arrays["lights"]
    cdf, rows = packed.arrays["light_tri_cdf"], packed.arrays["light_tris"]
    out = [], [], [], []
    for li, light in enumerate(lights):
        if light["type"] != layout.LIGHT_TYPES["area"] or light["sphere"] >= 0:
            continue
        start, n = int(light["tri_start"]), int(light["tri_count"])
        c = cdf[start:start + n]
        out[0].extend(rows[start:start + n])
        out[1].extend([li] * n)
        out[2].extend(c)
        out[3].extend(np.concatenate([[0.0], c[:-1]]))
    return (np.asarray(out[0], np.int64), np.asarray(out[1], np.int32), np.asarray(out[2], np.float32),
            np.asarray(out[3], np.float32))


def lanes_table(packed, tiny: int = 0, spheres: int = 0, surface: bool = False, bsdfs: bool = False) -> np.ndarray:
    """The lights' and media's parameters the lanes stage reads (wavefront_state.h's table); with
    `tiny` the scene's triangles and spheres in packet order (lanes_triangles.h), with `surface`
    the tested triangles' diffuse surfaces and the light triangles (wavefront_surface.cl), and with
    `bsdfs` those of the packet renderer's bsdf steps (volcl.lanes_bsdfs)."""
    t = np.zeros((TABLE_ROWS, TABLE_STRIDE), np.float32)
    corners, codes = _tiny_triangles(packed, tiny) if tiny else (None, None)
    if tiny and surface:
        lanes, ng, bsdf, checker, more = _lanes_surfaces(packed, corners, codes, bsdfs)
    # the rough coordinates where the kernel takes the rough step (VOLCL_PACKET_ROUGH: WF_TRI_COORDS)
    rough = bool(tiny and surface and more.rough.any())
    assert not (rough and spheres), "the rough step's numbers take the spheres' place"
    tri = np.zeros((TRI_COORDS_BSDFS if rough else TRI_COORDS, tiny, TRI_SPACING), np.float32)
    sph = np.zeros((SPHERE_COORDS, spheres, TRI_SPACING), np.float32)
    if tiny:
        tri[:9, :, 0] = corners.reshape(tiny, 9).T
        tri[9, :, 0] = codes.astype(np.int32).view(np.float32)
        if surface:
            tri[10:13, :, 0] = ng.T
            tri[13, :, 0] = np.abs(corners).max(axis=(1, 2))
            tri[14, :, 0] = np.where(more.rough, lanes_bsdfs.ROUGH, lanes)
            tri[15:18, :, 0] = bsdf["color"].T
            tri[18, :, 0] = bsdf["twosided"] != 0
            if checker.any():
                # a checkerboard's first colour in the reflectance's place, then its flag, the
                # triangle's uvs, the texture's to_uv and second colour
                tex = packed.arrays["textures"][np.maximum(bsdf["color_tex"], 0)]
                uvs = packed.arrays["tri_uvs"]["uv"][np.maximum(packed.arrays["triangles"]["uvs"][codes], 0)]
                tri[15:18, checker, 0] = tex["color0"][checker].T
                tri[19, :, 0] = checker
                tri[20:26, checker, 0] = uvs[checker].T
                tri[26:32, checker, 0] = tex["to_uv"][checker].T
                tri[32:35, checker, 0] = tex["color1"][checker].T
            if rough:
                lanes_bsdfs.fill(tri, packed, codes, bsdf, more)
    if spheres:
        leaves = scene_leaves(packed)
        code = leaves["prim"][leaves["prim"] < 0]
        rec = packed.arrays["spheres"][-code - 1]
        sph[0:3, :, 0] = rec["center"].T
        sph[3, :, 0] = rec["radius"]
        sph[4, :, 0] = code.astype(np.int32).view(np.float32)
    rows, owner, cdf, before = _light_triangles(packed) if surface else ((),) * 4
    lt = np.zeros((LIGHT_TRI_COORDS, len(rows), TRI_SPACING), np.float32)
    if len(rows):
        ltri = packed.arrays["triangles"][rows]
        ng, _ = _library_normals(ltri["p0"], ltri["p1"], ltri["p2"])
        lt[0, :, 0] = owner.view(np.float32)
        lt[1, :, 0] = cdf
        lt[2, :, 0] = before
        lt[3, :, 0] = np.r_[owner[1:] != owner[:-1], True]
        lt[4:13, :, 0] = np.concatenate([ltri["p0"], ltri["p1"], ltri["p2"]], axis=1).T
        lt[13:16, :, 0] = ng.T
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
    t[T_AREA, :len(lights)] = lights["area"]
    t[T_SEALED, :len(media)] = media["sealed"] != 0
    return np.concatenate([t.reshape(-1), tri.reshape(-1), sph.reshape(-1), lt.reshape(-1)])


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

    def __init__(self, device, features: dict, packed, group_items: int | None = None, paths: int = PATHS,
                 tiny: bool = True, loop: int | None = None):
        """loop: the medium stage's paths per work-item (default lanes_loop(device); 0: one)."""
        self.device = device
        # a scene without media is the surface stage's (supported() has checked that it can take it)
        self.surface = not features.get("MEDIA")
        self.tiny, ends, spheres = tiny_lanes(packed, features) if tiny or self.surface else (0, 0, 0)
        light_tris = len(_light_triangles(packed)[0]) if self.surface else 0
        checkers = int(_lanes_surfaces(packed, *_tiny_triangles(packed, self.tiny))[3].any()) \
            if self.surface and self.tiny else 0
        skip = hull_skip(packed, self.tiny) if self.surface and self.tiny else 0
        extra = (f"-DVOLCL_WF_TINY={self.tiny}", f"-DVOLCL_WF_TINY_ENDS={ends}", f"-DVOLCL_WF_SPHERES={spheres}",
                 f"-DVOLCL_WF_LIGHT_TRIS={light_tris}", f"-DVOLCL_WF_HULL_SKIP={skip}",
                 f"-DVOLCL_WF_CHECKERS={checkers}") if self.tiny else ()
        program = device.program(features, SCALAR_FILE, extra)
        self.scalar = cl.Kernel(program, "wavefront_scalar")
        self.add = cl.Kernel(program, "wavefront_add")
        self.begin = cl.Kernel(program, "wavefront_begin")
        lanes_file, kernel = (SURFACE_FILE, "wavefront_surface") if self.surface else (LANES_FILE, "wavefront_medium")
        self.loop = 0 if self.surface else (lanes_loop(device) if loop is None else int(loop))
        lanes_extra = extra + (f"-DVOLCL_WF_LOOP={self.loop}",) if self.loop else extra
        self.lanes = cl.Kernel(device.program(features, lanes_file, lanes_extra), kernel)
        self.sources = [(SCALAR_FILE, extra), (lanes_file, lanes_extra)]   # its programs (source, extra options)
        if group_items is None:
            group_items = devmod.group_items([self.scalar, self.add, self.begin, self.lanes], device.device)
        self.group_items = group_items
        # waves in whole work-groups of every kernel, the medium stage's loops included
        self.unit = unit = max(group_items, self.loop)
        self.paths = -(-min(paths, STRIDE - 16) // unit) * unit
        self.table = cl.Buffer(device.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                               hostbuf=lanes_table(packed, self.tiny, spheres, self.surface))
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
        n = min(self.paths, -(-jobs // self.unit) * self.unit)
        size, local = (n,), (self.group_items,)
        lanes_size = ((n // self.loop,), (max(self.group_items // self.loop, 1),)) if self.loop else (size, local)
        # every path alive, about to take a job (a kernel writes the rows: Oclgrind 21.10 does not
        # count a host write at an offset into a buffer as initializing it)
        self.begin(queue, size, local, state.is_, np.int32(n))
        cl.enqueue_copy(queue, state.next_job, np.zeros(1, np.int32))
        params = dict(zip(ARG_ORDER, scene_args))["params"]
        self.lanes.set_args(state.fs, state.is_, self.table, params)
        self.scalar.set_args(*scene_args, self.results, state.next_job, *launch_args, state.fs, state.is_)
        # the paths' flags after each batch of steps, read without waiting: the host looks at the
        # last batch's while the device runs the next (one batch of finished paths at the end is
        # the price; waiting for every read left the device idle between batches)
        flags = [np.empty(n, np.int32), np.empty(n, np.int32)]
        reads = []
        while True:
            for _ in range(CHECK_EVERY):
                cl.enqueue_nd_range_kernel(queue, self.scalar, size, local)
                cl.enqueue_nd_range_kernel(queue, self.lanes, *lanes_size)
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
