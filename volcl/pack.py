"""A loaded scene turned into the flat arrays the kernels read (see kernels/types.h).

Meshes become one triangle array, spheres and cylinders arrays of their own, and one BVH covers them
all. Objects that
the scene shares (a bsdf or medium referenced twice) are stored once.

A `Packer` holds what depends on the scene's structure only (which objects exist and which shape
uses which bsdf, light and media: the indices the arrays refer to each other by) and packs the
arrays in parts, so that an edited value (volcl.params) repacks only the part it lives in:

    geometry   triangles, normals, spheres, cylinders, BVH (nodes,   vertex positions, transforms
               leaves), texture coordinates and parametrizations
    lights     light records, area-light triangle CDFs, envmaps     emitter values, geometry
    shapes     per-shape bsdf, light and media indices              structure only
    bsdfs      bsdf records, textures and texels, bsdf tables       bsdf colours, IORs, roughness,
                                                                    texture data (volcl.pack_materials)
    media      media records, grid descriptors and values,          media coefficients, phase
               phase lobes and their tables
    camera     the reconstruction filter's table                    the film's filter
and the RenderParams record, which is small and repacked with every part.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from . import emission_sampler, envmap, hull, layout
from .bvh_instanced import relocate, two_level_bvh
from .bvh_wide import device_bvh, empty_wide
from .errors import VolclError
from .features import detect
from .grids import GridPacker
from .guides import guide
from .mesh import triangle_areas32
from .pack_materials import MaterialPacker, reads_uv, transmits
from .phase import PhasePacker
from .sealed import boxes_touch, sealed_media
from .scene.model import Camera, Filter, Scene
from .scene import transform as tf
from .scene.shapes import cylinder_bounds

FILTER_TABLE_SIZE = 4097

# part -> the arrays it packs, in the order parts are packed (shapes name the lights)
PARTS = {
    "geometry": ("nodes", "leaves", "triangles", "normals", "spheres", "cylinders", "tri_uvs", "uv_maps",
                 "instances"),
    "lights": ("lights", "light_tri_cdf", "light_tris", "env_data"),
    "shapes": ("shapes",),
    "bsdfs": ("bsdfs", "textures", "texels", "bsdf_tables"),
    "media": ("media", "grids", "grid_data", "phase_lobes", "phase_tables"),
    "camera": ("filter_table",),
}
# the kernel's buffer arguments, in order (kernels/render.cl)
ARG_ORDER = ("nodes", "leaves", "triangles", "normals", "spheres", "cylinders", "shapes", "bsdfs", "lights",
             "light_tri_cdf", "light_tris", "env_data", "media", "grids", "grid_data", "params", "filter_table",
             "tri_uvs", "uv_maps", "textures", "texels", "bsdf_tables", "phase_lobes", "phase_tables",
             "instances")


@dataclass
class Packed:
    arrays: dict                    # buffer name -> numpy array, in kernel argument order
    params: np.ndarray              # RENDER_PARAMS, one record
    features: dict
    triangle_count: int = 0
    sphere_count: int = 0
    bvh_seconds: float = 0.0
    stats: dict = field(default_factory=dict)
    # the scene tree's leaf packets come first; the shadow tree's (volcl.hull) follow
    scene_leaves: int = 0
    # the triangles that tree leaves out, where params["shadow_root"] uses it (else none)
    hull_faces: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))


def _index_by_identity(objs):
    index, out = {}, []
    for o in objs:
        if o is not None and id(o) not in index:
            index[id(o)] = len(out)
            out.append(o)
    return index, out


def _pack_media(media, grids: GridPacker, phases: PhasePacker):
    arr = np.zeros(max(len(media), 1), layout.MEDIUM)
    arr["sigma_t_grid"] = arr["albedo_grid"] = arr["emission_grid"] = -1
    arr["blackbody"] = arr["emission_sampler"] = -1
    for i, m in enumerate(media):
        r = arr[i]
        r["type"] = layout.MEDIUM_TYPES[m.kind]
        r["phase"], r["g"], r["phase_lobe"], r["phase_lobe_count"] = phases.add(m.phase)
        if m.kind == "heterogeneous":
            # the scale goes into the grid values (and so into the majorants) once, here
            r["sigma_t_grid"] = grids.add(m.sigma_t, m.scale, tracked=True)
            r["albedo_grid"] = grids.add(m.albedo)
            if m.radiance is not None:
                r["emission"] = m.radiance
            if m.emission_kind != "none":
                _pack_emission(r, m, grids)
            continue
        sigma_t = np.asarray(m.sigma_t, dtype=np.float64) * m.scale
        albedo = np.asarray(m.albedo, dtype=np.float64)
        r["sigma_t"], r["albedo"] = sigma_t, albedo
        if m.radiance is not None:
            r["emission"] = sigma_t * (1.0 - albedo) * m.radiance
    return arr


def shape_bounds(s) -> tuple[np.ndarray, np.ndarray]:
    """World bounds of one shape."""
    if s.kind == "sphere":
        c, r = np.asarray(s.center, np.float64), float(s.radius)
        return c - r, c + r
    if s.kind == "cylinder":
        lo, hi = cylinder_bounds(s.cylinder)
        return np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    v = np.asarray(s.vertices, np.float64)
    return v.min(0), v.max(0)


def _pack_spot(rec, e) -> None:
    """Mitsuba's spot: position, the frame its falloff is measured in, and the falloff's constants
    (kernels/lights.h spot_falloff)."""
    rec["position"] = e.position
    rec["to_local"] = np.linalg.inv(np.asarray(e.to_world, np.float64)[:3, :3]).reshape(9)
    cutoff, beam = math.radians(e.cutoff_angle), math.radians(e.beam_width)
    rec["cos_cutoff"], rec["cos_beam"], rec["cutoff"] = math.cos(cutoff), math.cos(beam), cutoff
    rec["tan_cutoff"] = math.tan(cutoff)
    # a beam as wide as the cutoff has no transition (never evaluated there: infinite is harmless)
    rec["inv_transition"] = 1.0 / (cutoff - beam) if cutoff != beam else np.inf


def _pack_emission(r, m, grids: GridPacker) -> None:
    """A heterogeneous medium's spatially varying emission: its grid, scales and the blackbody table."""
    r["emission_mode"] = layout.EMISSION_MODES[m.emission_kind]
    r["emission_grid"] = grids.add(m.emission_volume)
    r["emission_scale"] = m.emission_scale
    if m.emission_kind == "temperature":
        r["blackbody"] = grids.blackbody_table()
        r["temperature_scale"], r["temperature_offset"] = m.temperature_scale, m.temperature_offset


def filter_profile(f: Filter, x: np.ndarray) -> np.ndarray:
    """The 1D reconstruction filter's (unnormalized) weight at offsets x, in pixels."""
    r = f.radius
    if f.kind == "box":
        return (np.abs(x) <= r).astype(np.float64)
    if f.kind == "tent":
        return np.maximum(0.0, 1.0 - np.abs(x) / r)
    # gaussian, shifted to reach zero at the radius (Mitsuba and Nori)
    return np.maximum(0.0, np.exp(-x * x / (2 * f.stddev ** 2)) - math.exp(-r * r / (2 * f.stddev ** 2)))


def filter_table(f: Filter, size: int = FILTER_TABLE_SIZE) -> np.ndarray:
    """For sample_filter_offset: the filter's normalized CDF at `size` equally spaced offsets
    spanning [-radius, radius], then size - 1 guide entries (entry i: the first interval whose CDF
    passes i / (size - 1)). Each interval's mass is integrated with 64-point Gauss-Legendre, so the
    sampled shares are the filter's own to float64 precision."""
    edges = np.linspace(-f.radius, f.radius, size)
    nodes, weights = np.polynomial.legendre.leggauss(64)
    half = 0.5 * np.diff(edges)
    mid = 0.5 * (edges[1:] + edges[:-1])
    mass = (filter_profile(f, mid[:, None] + half[:, None] * nodes[None]) * weights).sum(1) * half
    cdf = np.concatenate([[0.0], np.cumsum(mass)])
    cdf = (cdf / cdf[-1]).astype(np.float32)
    # the search runs over the entries past cdf[0] = 0: the ends of the intervals
    return np.concatenate([cdf, guide(cdf[1:])])


def filter_cdf_size(table: np.ndarray) -> int:
    """The number of CDF entries in a filter_table (the rest is its guide)."""
    return (len(table) + 1) // 2


def hide_emitters_mode(scene: Scene) -> str:
    """How camera rays treat emitters (kernels/types.h HIDE_EMITTERS_*): Mitsuba's path, volpath and
    direct pass through area emitters when hiding them; volpathmis (and Nori) only skip their
    emission."""
    integ = scene.integrator
    if not integ.hide_emitters:
        return "off"
    return "skip" if scene.dialect == "mitsuba" and integ.kind in ("path", "volpath", "direct") else "dark"


def roulette_depth(scene: Scene) -> int:
    """The kernel's rr_depth: it plays Russian roulette after a bounce that brings the path's depth
    to rr_depth or more (kernels/integrator.h path_roulette), as Mitsuba's path integrator does.
    Mitsuba's volpath and volpathmis test depth > rr_depth at the top of their loop instead
    (src/integrators/volpath.cpp, volpathmis.cpp in 3.9), one bounce later: every path gets one
    more segment before its first roulette, the same expected image with less noise at more cost
    per sample (point_in_fog: 14% more medium events, 13% more kernel instructions)."""
    integ = scene.integrator
    late = scene.dialect == "mitsuba" and integ.kind in ("volpath", "volpathmis")
    return integ.rr_depth + 1 if late else integ.rr_depth


def camera_tangents(cam: Camera) -> tuple[float, float]:
    """tan(fov/2) along x and y from Mitsuba's fov_axis rules; (1, height / width) for an
    orthographic camera, whose frame spans x in [-1, 1]."""
    w, h = cam.width, cam.height
    if cam.kind == "orthographic":
        return 1.0, h / w
    t = math.tan(math.radians(cam.fov) / 2)
    axis = cam.fov_axis
    if axis == "smaller":
        axis = "x" if w <= h else "y"
    elif axis == "larger":
        axis = "x" if w >= h else "y"
    if axis == "x":
        tx = t
    elif axis == "y":
        tx = t * w / h
    else:   # diagonal
        tx = t * w / math.hypot(w, h)
    return tx, tx * h / w


def near_clip_bounds(cam: Camera) -> tuple[np.ndarray, np.ndarray] | None:
    """World bounds of every camera ray's stretch between where it leaves the camera and the near
    clip plane (kernels/integrator.h camera_start_medium walks it), padded for the filter's reach
    past the image, the principal point and the lens; None for an orthographic camera, whose rays
    leave from the whole film plane."""
    if cam.kind == "orthographic":
        return None
    tx, ty = camera_tangents(cam)
    reach = 1.0 + 2.0 * max(cam.rfilter.radius, 1.0) / min(cam.width, cam.height)
    x = tx * (reach + 2.0 * abs(cam.principal_point[0]))
    y = ty * (reach + 2.0 * abs(cam.principal_point[1]))
    lens = cam.aperture_radius if cam.kind == "thinlens" else 0.0
    if lens:
        slope = lens / max(cam.focus_distance, 1e-30)
        x, y = x + slope, y + slope
    n = cam.near_clip
    corners = np.array([[sx * (lens + n * x), sy * (lens + n * y), z]
                        for sx in (-1, 1) for sy in (-1, 1) for z in (-n, n)], np.float64)
    m = np.asarray(cam.to_world, np.float64)
    world = corners @ m[:3, :3].T + m[:3, 3]
    return world.min(0), world.max(0)


def _surface_may_touch(s, lo, hi) -> bool:
    """Whether shape s's surface may reach into the box [lo, hi]: a sphere's unless the box lies wholly
    inside or outside it, a mesh's where a triangle's bounds touch the box (a camera inside a fog box
    is far from its faces), other shapes by their bounds."""
    if not boxes_touch(shape_bounds(s), (lo, hi)):
        return False
    if s.kind == "sphere":
        c = np.asarray(s.center, np.float64)
        near = np.linalg.norm(np.clip(c, lo, hi) - c)
        far = np.linalg.norm(np.maximum(np.abs(lo - c), np.abs(hi - c)))
        return bool(near <= s.radius <= far)
    if s.kind == "mesh":
        tri = np.asarray(s.vertices, np.float64)[s.faces]
        return bool(np.any(np.all(tri.min(1) <= hi, axis=1) & np.all(lo <= tri.max(1), axis=1)))
    return True


class Packer:
    """The kernel arrays of one scene, packed part by part (see the module docstring). The scene's
    structure must not change after construction; its values may, followed by pack(parts)."""

    def __init__(self, scene: Scene, max_leaf: int = 4, majorant_cells: int | None = None):
        self.scene = scene
        self.max_leaf = max_leaf
        self.majorant_cells = majorant_cells
        self.shape_index = {id(s): i for i, s in enumerate(scene.shapes)}
        # spots' projection textures share the texture buffers, after the bsdfs' textures
        self.materials = MaterialPacker([s.bsdf for s in scene.shapes],
                                        [e.texture for e in scene.emitters if e.texture is not None])
        self.bsdf_index = self.materials.index
        # texture coordinates only for shapes whose bsdf reads them; analytic uvs for spheres and disks
        self.uv_shapes = {id(s) for s in scene.shapes if reads_uv(s.bsdf)}
        self.uv_map_shapes = [s for s in scene.shapes if id(s) in self.uv_shapes
                              and (s.kind == "sphere" or s.uv_map == "disk")]
        self.uv_map_index = {id(s): i for i, s in enumerate(self.uv_map_shapes)}
        self.medium_index, self.media = _index_by_identity(
            [scene.camera.medium] + [m for s in scene.shapes for m in (s.interior, s.exterior)]
            + list(scene.media))
        self.sphere_shapes = [s for s in scene.shapes if s.kind == "sphere"]
        self.cylinder_shapes = [s for s in scene.shapes if s.kind == "cylinder"]
        # analytic index of each analytic shape (kernels/cylinder.h): spheres, then cylinders from a base
        self.analytic_of_shape = {id(s): i for i, s in enumerate(self.sphere_shapes)}
        self.analytic_of_shape.update({id(s): layout.CYLINDER_CODE_BASE + i
                                       for i, s in enumerate(self.cylinder_shapes)})
        self.first_tri, offset = {}, 0
        for s in scene.shapes:
            if s.kind == "mesh":
                self.first_tri[id(s)] = offset
                offset += len(s.faces)
        self.arrays: dict[str, np.ndarray] = {}
        self.triangle_count = offset
        self.bvh_seconds = 0.0
        self.bounds = (np.zeros(3), np.zeros(3))
        self.scene_leaves, self.shadow_root, self.hull = 0, 0, None     # _pack_geometry's
        self.light_count, self.env_light, self.shape_light = 0, -1, {}
        self.stats = {"cylinders": len(self.cylinder_shapes)}
        self._envmaps: dict = {}        # id(emitter) -> (image, scale, its tables), see _envmap_tables

    def medium_id(self, m) -> int:
        return -1 if m is None else self.medium_index[id(m)]

    def pack(self, parts=tuple(PARTS)) -> Packed:
        """Pack `parts` (all by default) and the RenderParams record."""
        for part in sorted(parts, key=list(PARTS).index):
            getattr(self, "_pack_" + part)()
        self._seal_media()
        params = self._params()
        self.arrays["params"] = params.reshape(1)      # a view: Packed.params edits it
        ordered = {name: self.arrays[name] for name in ARG_ORDER}
        faces = self.hull[0] if params["shadow_root"] else np.zeros(0, np.int64)
        return Packed(ordered, params, detect(self.scene), self.triangle_count,
                      len(self.sphere_shapes), self.bvh_seconds, dict(self.stats), self.scene_leaves, faces)

    # -- parts ----------------------------------------------------------------------------------

    def _triangles(self):
        """Every mesh's triangles, the per-triangle shape index, and packed shading normals."""
        verts, shapes, normals, normal_owner = [], [], [], []
        for s in self.scene.shapes:
            if s.kind != "mesh":
                continue
            tri = s.vertices[s.faces]                       # (m, 3, 3)
            verts.append(tri)
            shapes.append(np.full(len(tri), self.shape_index[id(s)], np.int32))
            has = s.normals is not None
            normals.append(s.normals[s.faces] if has else np.zeros((0, 3, 3)))
            normal_owner.append(np.full(len(tri), has))
        if not verts:
            return np.zeros((0, 3, 3)), np.zeros(0, np.int32), np.zeros((0, 3, 3)), np.zeros(0, bool)
        return (np.concatenate(verts), np.concatenate(shapes), np.concatenate(normals),
                np.concatenate(normal_owner))

    def _pack_geometry(self):
        tri_v, tri_shape, tri_n, tri_has_n = self._triangles()
        ntri = len(tri_v)
        tris = np.zeros(max(ntri, 1), layout.TRIANGLE)
        if ntri:
            tris["p0"][:ntri], tris["p1"][:ntri], tris["p2"][:ntri] = tri_v[:, 0], tri_v[:, 1], tri_v[:, 2]
            tris["shape"][:ntri] = tri_shape
            nidx = np.cumsum(tri_has_n) - 1
            tris["normals"][:ntri] = np.where(tri_has_n, nidx, -1)
        normals = np.zeros(max(int(tri_has_n.sum()), 1), layout.TRIANGLE_NORMALS)
        if tri_has_n.any():
            sel = tri_n
            normals["n0"][:len(sel)], normals["n1"][:len(sel)], normals["n2"][:len(sel)] = \
                sel[:, 0], sel[:, 1], sel[:, 2]
        tris["uvs"] = -1
        tri_uvs = self._triangle_uvs(tris)

        spheres = np.zeros(max(len(self.sphere_shapes), 1), layout.SPHERE)
        for i, s in enumerate(self.sphere_shapes):
            spheres[i]["center"], spheres[i]["radius"] = s.center, s.radius
            spheres[i]["shape"], spheres[i]["flip"] = self.shape_index[id(s)], int(s.flip_normals)
        cylinders = np.zeros(max(len(self.cylinder_shapes), 1), layout.CYLINDER)
        for i, s in enumerate(self.cylinder_shapes):
            cylinders[i]["to_world"] = s.cylinder[:3, :4].reshape(12)
            cylinders[i]["to_object"] = np.linalg.inv(s.cylinder)[:3, :4].reshape(12)
            cylinders[i]["shape"], cylinders[i]["flip"] = self.shape_index[id(s)], int(s.flip_normals)

        # one BVH over triangles (codes >= 0) and analytic shapes (codes < 0: -(analytic index + 1))
        lo = [tri_v.min(axis=1)] if ntri else []
        hi = [tri_v.max(axis=1)] if ntri else []
        codes = [np.arange(ntri, dtype=np.int32)]
        if self.sphere_shapes:
            c = np.array([s.center for s in self.sphere_shapes], np.float64)
            r = np.array([s.radius for s in self.sphere_shapes], np.float64)[:, None]
            lo.append(c - r)
            hi.append(c + r)
            codes.append(-1 - np.arange(len(self.sphere_shapes), dtype=np.int32))
        if self.cylinder_shapes:
            boxes = [cylinder_bounds(s.cylinder) for s in self.cylinder_shapes]
            lo.append(np.array([b[0] for b in boxes]))
            hi.append(np.array([b[1] for b in boxes]))
            codes.append((-1 - layout.CYLINDER_CODE_BASE - np.arange(len(self.cylinder_shapes))).astype(np.int32))
        codes = np.concatenate(codes)
        self.arrays["instances"] = np.zeros(1, layout.INSTANCE)     # _instanced_bvh's, where there are any
        t0 = time.perf_counter()
        if len(codes):
            # shadow rays stop at the first opaque surface (kernels/bvh.h TRACE_SHADOW); a shape's
            # bsdf kind is structure, so the mask never needs repacking after an edit
            shape_opaque = np.array([not transmits(s.bsdf) for s in self.scene.shapes], bool)
            analytic_shape = np.array([self.shape_index[id(s)] for s in self.sphere_shapes + self.cylinder_shapes],
                                      np.int64)
            opaque = np.concatenate([shape_opaque[tri_shape], shape_opaque[analytic_shape]])
            if self.scene.instances:
                nodes, leaves = self._instanced_bvh(codes, np.concatenate(lo), np.concatenate(hi), tri_v, opaque,
                                                    np.concatenate([tri_shape, analytic_shape]))
            else:
                lo, hi = np.concatenate(lo), np.concatenate(hi)
                nodes, leaves = device_bvh(codes, lo, hi, tri_v, opaque, max_leaf=self.max_leaf)
                self.bounds = (lo.min(0), hi.max(0))
        else:
            nodes, leaves = empty_wide(), np.zeros(1, layout.LEAF_PACKET)
            self.bounds = (np.zeros(3), np.zeros(3))
        self.scene_leaves, self.shadow_root, self.hull = len(leaves), 0, None
        if len(codes) and not self.scene.instances and len(codes) <= hull.MAX_PRIMITIVES:
            nodes, leaves = self._shadow_tree(nodes, leaves, codes, lo, hi, tri_v, spheres, opaque)
        self.bvh_seconds = time.perf_counter() - t0
        self.triangle_count = ntri
        self.arrays.update(nodes=nodes, leaves=leaves, triangles=tris, normals=normals, spheres=spheres,
                           cylinders=cylinders, tri_uvs=tri_uvs, uv_maps=self._uv_maps())

    def _shadow_tree(self, nodes, leaves, codes, lo, hi, tri_v, spheres, opaque):
        """The scene's tree followed by a second one without the faces of its convex hull
        (volcl.hull), for shadow rays from surfaces (RenderParams.shadow_root, set by _params where
        every point and spot light lies in the hull); unchanged where no face qualifies."""
        ntri, n_sph = len(tri_v), len(self.sphere_shapes)
        tri32 = np.asarray(tri_v, np.float32)
        cyl = slice(ntri + n_sph, None)
        faces, planes, tol = hull.hull_faces(tri32, spheres["center"][:n_sph], spheres["radius"][:n_sph],
                                             lo[cyl], hi[cyl])
        if not faces.any():
            return nodes, leaves
        keep = np.concatenate([~faces, np.ones(len(codes) - ntri, bool)])
        if keep.any():
            s_nodes, s_leaves = device_bvh(codes[keep], lo[keep], hi[keep], tri_v, opaque[keep],
                                           max_leaf=self.max_leaf)
        else:
            s_nodes, s_leaves = empty_wide(), np.zeros(1, layout.LEAF_PACKET)
        self.shadow_root, self.hull = len(nodes), (np.flatnonzero(faces), planes, tol)
        return (np.concatenate([nodes, relocate(s_nodes, len(nodes), len(leaves))]),
                np.concatenate([leaves, s_leaves]))

    def _instanced_bvh(self, codes, lo, hi, tri_v, opaque, prim_shape):
        """The two-level BVH (volcl.bvh_instanced) of a scene with instances; sets self.bounds to
        the world box of what the instances place and the scene's own shapes."""
        group_index = {}
        for inst in self.scene.instances:
            group_index.setdefault(id(inst.group), len(group_index))
        shape_group = np.array([group_index.get(id(s.group), -1) if s.group is not None else -1
                                for s in self.scene.shapes], np.int64)
        placements = [(group_index[id(i.group)], i.to_world) for i in self.scene.instances]
        nodes, leaves, records, bounds = two_level_bvh(codes, lo, hi, tri_v, opaque, shape_group[prim_shape],
                                                       placements, max_leaf=self.max_leaf)
        self.arrays["instances"] = records
        self.stats["instances"] = len(self.scene.instances)
        self.bounds = bounds if bounds is not None else (np.zeros(3), np.zeros(3))
        return nodes, leaves

    def _triangle_uvs(self, tris: np.ndarray) -> np.ndarray:
        """Corner uvs of the triangles whose bsdf reads them (kernels/texcoords.h), and their index
        in each Triangle record. A mesh without uvs gets Mitsuba's barycentric ones: (0, 0), (1, 0),
        (0, 1) at the corners in the file's order (flip_normals reversed the corners)."""
        rows = []
        count = 0
        for s in self.scene.shapes:
            if s.kind != "mesh" or id(s) not in self.uv_shapes:
                continue
            m = len(s.faces)
            if s.uvs is not None:
                corner = np.asarray(s.uvs, np.float64)[s.faces]
            else:
                canonical = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
                corner = np.broadcast_to(canonical[::-1] if s.flip_normals else canonical, (m, 3, 2))
            rows.append(corner.reshape(m, 6))
            first = self.first_tri[id(s)]
            tris["uvs"][first:first + m] = np.arange(count, count + m)
            count += m
        out = np.zeros(max(count, 1), layout.TRIANGLE_UV)
        if rows:
            out["uv"][:count] = np.concatenate(rows)
        return out

    def _uv_maps(self) -> np.ndarray:
        """The unit sphere's or unit disk's frame of each analytic parametrization (texcoords.h)."""
        out = np.zeros(max(len(self.uv_map_shapes), 1), layout.UV_MAP)
        for i, s in enumerate(self.uv_map_shapes):
            if s.kind == "sphere":
                center, radius = s.local
                frame = np.asarray(s.to_world, np.float64) @ tf.translate(center) @ tf.scale(radius)
                out[i]["kind"] = layout.UV_MAP_KINDS["sphere"]
            else:
                frame = np.asarray(s.to_world, np.float64)
                out[i]["kind"] = layout.UV_MAP_KINDS["disk"]
            out[i]["to_world"] = frame[:3, :4].reshape(12)
            out[i]["to_object"] = np.linalg.inv(frame)[:3, :4].reshape(12)
        return out

    def _pack_lights(self):
        """Area lights first (one per emitting shape), then the scene's other emitters."""
        lights, light_cdf, light_tris = [], [], []
        self.shape_light = {}
        for s in self.scene.shapes:
            if s.emitter_radiance is None:
                continue
            rec = np.zeros((), layout.LIGHT)
            rec["type"] = layout.LIGHT_TYPES["area"]
            rec["value"] = s.emitter_radiance
            rec["sphere"] = -1
            if s.kind == "sphere":
                rec["sphere"] = self.analytic_of_shape[id(s)]
                rec["area"] = 4 * math.pi * s.radius ** 2
            elif s.kind == "cylinder":
                # Mitsuba's area: 2 pi |to_world x| |to_world z| (exact for a circular cross-section)
                rec["sphere"] = self.analytic_of_shape[id(s)]
                rec["area"] = 2 * math.pi * np.linalg.norm(s.cylinder[:3, 0]) * np.linalg.norm(s.cylinder[:3, 2])
            else:
                # areas of the float32 triangles the kernel samples: a sliver that collapses in
                # float32 must not be picked (kernels/lights.h)
                areas = triangle_areas32(s.vertices, s.faces)
                keep = np.nonzero(areas > 0)[0]
                total = areas[keep].sum()
                rec["area"] = total
                rec["tri_start"], rec["tri_count"] = len(light_cdf), len(keep)
                cdf = np.cumsum(areas[keep]) / total
                cdf[-1] = 1.0
                light_cdf.extend(cdf.tolist())
                light_tris.extend((self.first_tri[id(s)] + keep).tolist())
            self.shape_light[id(s)] = len(lights)
            lights.append(rec)
        env_light, env_data = -1, []     # env_data: the envmap's tables (one at most)
        environments = [e for e in self.scene.emitters if e.kind in ("constant", "envmap")]
        if len(environments) > 1 and any(e.kind == "envmap" for e in environments):
            raise VolclError("only one environment emitter (envmap or constant) can be in a scene, as in Mitsuba")
        for e in self.scene.emitters:
            rec = np.zeros((), layout.LIGHT)
            rec["type"] = layout.LIGHT_TYPES[e.kind]
            rec["value"] = e.value
            rec["sphere"] = -1
            if e.kind == "point":
                rec["position"] = e.position
            elif e.kind == "spot":
                _pack_spot(rec, e)
                rec["texture"] = self.materials.tex(e.texture)
            elif e.kind == "directional":
                rec["direction"] = np.asarray(e.direction) / np.linalg.norm(e.direction)
            elif e.kind == "constant":
                if env_light >= 0:      # two constant environments add up to one
                    lights[env_light]["value"] = lights[env_light]["value"] + np.asarray(e.value, np.float32)
                    continue
                env_light = len(lights)
            elif e.kind == "envmap":
                data, res, norm = self._envmap_tables(e)
                rec["to_local"] = np.linalg.inv(np.asarray(e.to_world, np.float64)[:3, :3]).reshape(9)
                rec["env_res"], rec["env_data"], rec["env_norm"] = res, 0, norm   # the one environment
                env_data.append(data)
                env_light = len(lights)
            lights.append(rec)
        light_arr = np.zeros(max(len(lights), 1), layout.LIGHT)
        for i, rec in enumerate(lights):
            light_arr[i] = rec
        self.light_count, self.env_light = len(lights), env_light
        self.arrays.update(lights=light_arr, light_tri_cdf=np.asarray(light_cdf or [1.0], np.float32),
                           light_tris=np.asarray(light_tris or [0], np.int32),
                           env_data=env_data[0] if env_data else np.zeros(1, np.float32))
        self.stats["env_texels"] = sum(int(np.prod(e.image.shape[:2])) for e in environments if e.kind == "envmap")

    def _envmap_tables(self, e):
        """(tables, (W, H), env_norm) of an envmap (volcl.envmap), kept while its image and scale
        stay the same: repacking the lights for another light's edit does not rebuild them."""
        cached = self._envmaps.get(id(e))
        if cached is not None and cached[0] is e.image and cached[1] == e.scale:
            return cached[2]
        texels = envmap.texels_for(e.image, e.scale)
        data, norm = envmap.tables(texels)
        result = (data, (texels.shape[1], texels.shape[0]), norm)
        self._envmaps[id(e)] = (e.image, e.scale, result)
        return result

    def _pack_shapes(self):
        shape_arr = np.zeros(max(len(self.scene.shapes), 1), layout.SHAPE_INFO)
        for i, s in enumerate(self.scene.shapes):
            r = shape_arr[i]
            r["bsdf"] = self.bsdf_index[id(s.bsdf)]
            r["light"] = self.shape_light.get(id(s), -1)
            r["interior"], r["exterior"] = self.medium_id(s.interior), self.medium_id(s.exterior)
            r["is_transition"] = int(s.interior is not None or s.exterior is not None)
            r["uv_map"] = self.uv_map_index.get(id(s), -1)
        self.arrays["shapes"] = shape_arr

    def _pack_bsdfs(self):
        self.arrays.update(self.materials.arrays())

    def _pack_media(self):
        grids = GridPacker(self.majorant_cells)
        phases = PhasePacker()
        media = _pack_media(self.media, grids, phases)
        self.emission_table = emission_sampler.build(self.media, media, grids.descriptors, grids.values,
                                                     self._medium_boxes(), grids.add_words)
        grid_desc, grid_data = grids.arrays()
        phase_lobes, phase_tables = phases.arrays()
        self.stats.update(grid_voxels=grids.voxels, majorant_cells=grids.majorant_count, sparse_grids=grids.sparse,
                          phase_table_ratio_error=max(phases.ratio_errors, default=0.0))
        self.arrays.update(media=media, grids=grid_desc, grid_data=grid_data, phase_lobes=phase_lobes,
                           phase_tables=phase_tables)

    def _seal_media(self):
        """Medium.sealed (volcl.sealed), after every pack: it depends on the shapes, lights and bsdfs,
        which other parts pack. The media array is replaced, not edited, when it changes, so that an
        update sees the change and uploads it."""
        sealed = np.zeros(len(self.arrays["media"]), np.int32)
        sealed[:len(self.media)] = sealed_media(self.scene, self.media, shape_bounds)
        if not np.array_equal(self.arrays["media"]["sealed"], sealed):
            media = self.arrays["media"].copy()
            media["sealed"] = sealed
            self.arrays["media"] = media

    def _medium_boxes(self) -> dict:
        """medium index -> (lo, hi): the bounds of the shapes a homogeneous emissive medium fills, or
        of the whole scene where no shape names it as interior (the camera's medium, or outside a
        shape); emission NEE samples points in it (volcl.emission_sampler)."""
        boxes = {}
        for i, m in enumerate(self.media):
            if m.kind != "homogeneous" or not m.emissive:
                continue
            inside = [shape_bounds(s) for s in self.scene.shapes if s.interior is m]
            boxes[i] = ((np.min([b[0] for b in inside], 0), np.max([b[1] for b in inside], 0)) if inside
                        else self.bounds)
        return boxes

    def _pack_camera(self):
        self.arrays["filter_table"] = filter_table(self.scene.camera.rfilter)

    def _params(self) -> np.ndarray:
        cam = self.scene.camera
        params = np.zeros((), layout.RENDER_PARAMS)
        m = np.asarray(cam.to_world, np.float64)
        params["cam_to_world"] = m[:3, :4].reshape(12)
        params["tan_half"] = camera_tangents(cam)
        params["near_clip"], params["far_clip"] = cam.near_clip, cam.far_clip
        params["width"], params["height"] = cam.width, cam.height
        params["camera_type"] = layout.CAMERA_TYPES[cam.kind]
        params["aperture_radius"], params["focus_distance"] = cam.aperture_radius, cam.focus_distance
        params["principal_point"] = cam.principal_point
        integ = self.scene.integrator
        params["max_depth"] = integ.max_depth
        params["rr_depth"] = roulette_depth(self.scene)
        params["hide_emitters"] = layout.HIDE_EMITTERS[hide_emitters_mode(self.scene)]
        params["emitter_samples"], params["bsdf_samples"] = integ.emitter_samples, integ.bsdf_samples
        params["integrator"] = layout.INTEGRATORS["direct" if integ.kind == "direct" else "path"]
        params["specular_chains_only"] = int(integ.specular_chains_only)
        params["camera_medium"] = self.medium_id(cam.medium)
        params["light_count"] = self.light_count
        params["env_light"] = self.env_light
        params["filter_size"] = FILTER_TABLE_SIZE
        params["filter_radius"] = cam.rfilter.radius
        params["sample_border"] = int(cam.sample_border)
        params["seed"] = self.scene.seed & 0xFFFFFFFF
        params["nee"], params["mis"] = 1, 1
        params["majorant_scale"] = 1.0
        params["emission_table"] = getattr(self, "emission_table", -1)
        params["emission_nee"] = int(params["emission_table"] >= 0)
        lo, hi = self.bounds
        params["scene_center"] = 0.5 * (lo + hi)
        params["scene_radius"] = 0.5 * float(np.linalg.norm(hi - lo))
        params["camera_walk"] = int(self._camera_walk(params["scene_radius"]))
        params["shadow_root"] = self.shadow_root if self._lights_in_hull() else 0
        return params

    def _lights_in_hull(self) -> bool:
        """Whether every point and spot light lies in the convex hull whose faces the shadow tree
        leaves out (volcl.hull): a light outside it sends shadow rays through those faces."""
        if self.hull is None:
            return False
        _, planes, tol = self.hull
        at = [np.asarray(e.position, np.float32) for e in self.scene.emitters if e.kind in ("point", "spot")]
        return hull.inside(at, planes, tol)

    def _camera_walk(self, scene_radius: float) -> bool:
        """Whether a surface may lie where camera rays are walked to the near clip plane: if none can,
        the walk finds nothing, and the kernels skip it (a BVH query per camera ray)."""
        box = near_clip_bounds(self.scene.camera)
        if box is None or self.scene.instances:
            return True
        # the walk starts a little behind the camera (camera_start_medium's `back`), and float32 rounding
        pad = 1e-4 * (float(np.abs(self.scene.camera.to_world[:3, 3]).max()) + scene_radius) + 1e-6
        lo, hi = box[0] - pad, box[1] + pad
        return any(_surface_may_touch(s, lo, hi) for s in self.scene.shapes)


def pack(scene: Scene, features: dict | None = None, max_leaf: int = 4, majorant_cells: int | None = None,
         majorant_scale: float = 1.0) -> Packed:
    """The scene as kernel arrays. majorant_cells: majorant cells per axis of every extinction grid
    (default: about one per MAJORANT_CELL_VOXELS voxels; 1 = a single global majorant);
    majorant_scale (>= 1) multiplies every majorant on the device, a test knob that must not change
    the expected image."""
    packed = Packer(scene, max_leaf=max_leaf, majorant_cells=majorant_cells).pack()
    packed.params["majorant_scale"] = majorant_scale
    if features is not None:
        packed.features = features
    return packed
