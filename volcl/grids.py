"""Grid volumes as the kernels read them: one descriptor per use (layout.GRID_VOLUME), and one
float32 buffer holding every grid's voxels and the coarse majorant grids used for tracking.

Sparse grids (OpenVDB and NanoVDB files, volcl/vdb.py) keep their bricks of 8^3 voxels on the
device: a brick index over the padded box (one entry a brick: the offset of its voxels, or of the
one value it holds), the stored bricks, and the one-value bricks' values (kernels/grid.h). Their
majorant cells are the bricks themselves, each bounding what lookups inside it read: its own voxels
and the layer of voxels around it in the 26 neighbouring bricks, taken from each brick's maxima over
its faces, edges and corners (sparse_majorants), so no brick is ever expanded.

Lookup conventions (Mitsuba 3's, see kernels/grid.h): voxel i of an axis with n voxels is centred
at (i + 0.5) / n of the unit cube; trilinear lookups interpolate between centres and clamp to the
edge voxels; nearest lookups take voxel floor(x * n). `lookup` below is the numpy reference of the
kernel's grid_lookup, used by the tests.

A majorant cell must bound every value a lookup inside it can return (delta and ratio tracking are
biased wherever the density exceeds the majorant). With trilinear filtering a point's value mixes
the voxels whose centres bracket it, so a cell's support reaches one voxel beyond the voxels it
overlaps; the support is also widened by a hair (SUPPORT_EPS voxels) so that a point the kernel
places in a cell with float32 rounding still lies within the support, and the maximum is raised
by MAJORANT_MARGIN (relative), far above the rounding of the float32 interpolation.
"""
from __future__ import annotations

import numpy as np

from . import layout
from .errors import VolclError
from .scene.model import Volume

# A majorant cell spans about this many voxels per axis: tight enough that sparse grids waste few
# null collisions, coarse enough that the DDA takes few steps (benchmarks/grid_majorants.py).
MAJORANT_CELL_VOXELS = 4
MAJORANT_MAX_CELLS = 64
SUPPORT_EPS = 1e-3
MAJORANT_MARGIN = 1e-5


def majorant_resolution(res_xyz, cells: int | None = None) -> tuple[int, int, int]:
    """Majorant cells along x, y, z for a grid of res_xyz voxels; `cells` forces that many per axis
    (1 = one global majorant)."""
    if cells is not None:
        return (int(cells),) * 3
    return tuple(int(np.clip(-(-n // MAJORANT_CELL_VOXELS), 1, MAJORANT_MAX_CELLS)) for n in res_xyz)


def support(n: int, cells: int, filter: str) -> tuple[np.ndarray, np.ndarray]:
    """Inclusive voxel index ranges [lo, hi] that lookups in each of `cells` equal cells along an
    axis of n voxels can read."""
    a = np.arange(cells) / cells
    b = np.arange(1, cells + 1) / cells
    if filter == "nearest":
        lo = np.floor(a * n - SUPPORT_EPS)
        hi = np.floor(b * n + SUPPORT_EPS)
    else:
        lo = np.floor(a * n - 0.5 - SUPPORT_EPS)
        hi = np.floor(b * n - 0.5 + SUPPORT_EPS) + 1
    return np.clip(lo, 0, n - 1).astype(int), np.clip(hi, 0, n - 1).astype(int)


def majorant_grid(data: np.ndarray, filter: str, maj_res) -> np.ndarray:
    """(mz, my, mx) float32 majorants of data (z, y, x, c): per cell, the largest channel value over
    the cell's lookup support, raised by MAJORANT_MARGIN. The max over a box is separable, so it is
    taken one axis at a time (a loop over cells, at most MAJORANT_MAX_CELLS per axis)."""
    m = np.asarray(data, np.float64).max(axis=-1)                 # (z, y, x)
    for axis, cells in zip((2, 1, 0), maj_res):                    # x, y, z
        lo, hi = support(m.shape[axis], cells, filter)
        m = np.stack([np.take(m, np.arange(l, h + 1), axis=axis).max(axis=axis) for l, h in zip(lo, hi)],
                     axis=axis)
    return (m * (1 + MAJORANT_MARGIN)).astype(np.float32)


def _brick_region_maxima(values: np.ndarray) -> np.ndarray:
    """(n, 3, 3, 3) maxima over channels of bricks values (n, 512, c): entry [sz, sy, sx] over the
    brick's low layer (s = 0), all of it (1) or its high layer (2) along each axis."""
    b = values.max(axis=-1).reshape(-1, 8, 8, 8)                     # (n, z, y, x)
    for axis in (1, 2, 3):
        lo = np.take(b, 0, axis=axis)
        hi = np.take(b, 7, axis=axis)
        b = np.stack([lo, b.max(axis=axis), hi], axis=axis)
    return b


def sparse_majorants(sg, scale: float) -> np.ndarray:
    """(bz, by, bx) float32 majorants of a SparseGrid's padded box, one cell a brick: for brick k the
    largest value (over channels, times scale) among its own voxels and the voxels next to it,
    which is every voxel a trilinear or nearest lookup inside it reads. Outside the box the field
    is zero (the kernels clip rays to the box)."""
    # scaled in float32 first, as the stored values are, so that the cells equal majorant_grid's
    # over the same values bit for bit
    f = np.float32(scale)
    nb = sg.padded_counts()
    bg = float(np.max(sg.background * f))
    regions = np.full(tuple(nb[::-1]) + (3, 3, 3), bg, np.float64)
    if len(sg.coords):
        c = sg.coords + 1
        regions[c[:, 2], c[:, 1], c[:, 0]] = _brick_region_maxima(sg.bricks * f)
    if len(sg.tile_coords):
        t = sg.tile_coords + 1
        regions[t[:, 2], t[:, 1], t[:, 0]] = (sg.tile_values * f).max(axis=-1)[:, None, None, None]
    padded = np.pad(regions, [(1, 1)] * 3 + [(0, 0)] * 3, constant_values=0.0)
    out = np.zeros(tuple(nb[::-1]), np.float64)
    bz, by, bx = out.shape
    for oz in (-1, 0, 1):
        for oy in (-1, 0, 1):
            for ox in (-1, 0, 1):
                # the neighbour at offset o contributes its layer facing this brick: s = 1 - o
                part = padded[1 + oz:1 + oz + bz, 1 + oy:1 + oy + by, 1 + ox:1 + ox + bx,
                              1 - oz, 1 - oy, 1 - ox]
                np.maximum(out, part, out=out)
    return (out * (1 + MAJORANT_MARGIN)).astype(np.float32)


def sparse_chunk(sg, scale: float, base: int) -> np.ndarray:
    """The float32 words a SparseGrid occupies at offset `base` of grid_data: the brick index
    (int32 bit patterns; entry >= 0: the offset of a stored brick's voxels, < 0: -1 - the offset of
    a one-value brick's value), the stored bricks, then the background and the tile values."""
    nb = sg.padded_counts()
    n_index = int(np.prod(nb))
    c = sg.channels
    pool_at = base + n_index
    const_at = pool_at + sg.bricks.size
    if const_at + (1 + len(sg.tile_values)) * c >= 2 ** 31:
        raise VolclError(f"the scene's grid volumes hold {const_at} floats; the kernels index at most "
                         f"2^31 - 1")
    grid = sg.brick_grid()
    index = np.empty(grid.shape, np.int64)
    stored = grid >= 0
    index[stored] = pool_at + grid[stored] * 512 * c
    index[grid == -1] = -1 - const_at
    tiles = grid <= -2
    index[tiles] = -1 - (const_at + (1 + (-2 - grid[tiles])) * c)
    words = np.concatenate([index.astype(np.int32).reshape(-1).view(np.float32),
                            (sg.bricks.astype(np.float32) * np.float32(scale)).reshape(-1),
                            (sg.background.astype(np.float32) * np.float32(scale)).reshape(-1),
                            (sg.tile_values.astype(np.float32) * np.float32(scale)).reshape(-1)])
    return words


def grid_cost_text(cost: dict) -> str:
    """One sparse grid's device cost (GridPacker.sparse) in words: bytes per active voxel, and what
    the same box would cost dense."""
    active = max(cost["active_voxels"], 1)
    return (f"grid '{cost['name']}' of {cost['path'] or '(array)'}: {cost['active_voxels']} active voxels in "
            f"{cost['stored_bricks']} bricks of 8^3, {cost['bytes']} bytes ({cost['bytes'] / active:.2f} bytes "
            f"per active voxel; its {cost['box_voxels']}-voxel box dense would take {4 * cost['box_voxels']} bytes)")


def grid_cost_notes(costs) -> str:
    """What each sparse grid costs, as the end of an out-of-memory message ('' without any)."""
    return "".join(f"; {grid_cost_text(c)}" for c in costs)


def lookup(data: np.ndarray, filter: str, p_local: np.ndarray) -> np.ndarray:
    """Reference lookup (float64) of data (z, y, x, c) at local points (n, 3): the kernel's
    grid_lookup in numpy. Returns (n, c)."""
    res = np.array(data.shape[2::-1], np.float64)                  # x, y, z
    p = np.asarray(p_local, np.float64)
    if filter == "nearest":
        # the voxel index jumps at the faces: round p * res in float32 as the kernel does
        x = np.asarray(p_local, np.float32) * res.astype(np.float32)
        i = np.clip(np.floor(x), 0, res - 1).astype(int)
        return data[i[:, 2], i[:, 1], i[:, 0]].astype(np.float64)
    u = np.clip(p * res - 0.5, 0, res - 1)
    f = np.floor(u)
    w = u - f
    i0 = f.astype(int)
    i1 = np.minimum(i0 + 1, res.astype(int) - 1)
    out = 0.0
    for cz in (0, 1):
        for cy in (0, 1):
            for cx in (0, 1):
                ix = i1[:, 0] if cx else i0[:, 0]
                iy = i1[:, 1] if cy else i0[:, 1]
                iz = i1[:, 2] if cz else i0[:, 2]
                wt = ((w[:, 0] if cx else 1 - w[:, 0]) * (w[:, 1] if cy else 1 - w[:, 1])
                      * (w[:, 2] if cz else 1 - w[:, 2]))
                out = out + wt[:, None] * data[iz, iy, ix].astype(np.float64)
    return out


class GridPacker:
    """Collects grid descriptors and their data for one scene."""

    def __init__(self, majorant_cells: int | None = None):
        self.majorant_cells = majorant_cells
        self.descriptors: list[np.ndarray] = []
        self.chunks: list[np.ndarray] = []
        self.size = 0
        self.voxels = 0
        self.majorant_count = 0
        self.sparse: list[dict] = []      # per sparse grid: what it costs on the device

    def _append(self, values: np.ndarray) -> int:
        offset = self.size
        flat = np.ascontiguousarray(values, np.float32).reshape(-1)
        self.chunks.append(flat)
        self.size += flat.size
        if self.size >= 2 ** 31:
            raise VolclError(f"the scene's grid volumes hold {self.size} floats; the kernels index at most "
                             f"2^31 - 1 (use coarser grids)")
        return offset

    def add(self, volume: Volume, scale: float = 1.0, tracked: bool = False) -> int:
        """Index of a new descriptor for `volume`, values times `scale`; `tracked`: build its
        majorant grid (extinction grids). A constant volume becomes a 1x1x1 grid, which clamping
        extends over all space (the tracked ones still end at their unit cube, as in Mitsuba)."""
        if volume.kind == "sparse":
            return self._add_sparse(volume, scale, tracked)
        if volume.kind == "grid":
            data = np.asarray(volume.data, np.float32)
            filt = volume.filter
        else:
            value = np.asarray(volume.value, np.float64)
            data = (value[:1] if np.ptp(value) == 0 else value).reshape(1, 1, 1, -1).astype(np.float32)
            filt = "nearest"
        data = data * np.float32(scale)
        rec = np.zeros((), layout.GRID_VOLUME)
        rec["to_local"] = np.linalg.inv(np.asarray(volume.to_world, np.float64))[:3, :4].reshape(12)
        zres, yres, xres, channels = data.shape
        rec["res"] = (xres, yres, zres)
        rec["channels"] = channels
        rec["filter"] = layout.GRID_FILTERS[filt]
        rec["data"] = self._append(data)
        self.voxels += data[..., 0].size
        rec["majorants"] = -1
        if tracked:
            maj_res = majorant_resolution((xres, yres, zres), self.majorant_cells)
            rec["maj_res"] = maj_res
            rec["majorants"] = self._append(majorant_grid(data, filt, maj_res))
            self.majorant_count += int(np.prod(maj_res))
        self.descriptors.append(rec)
        return len(self.descriptors) - 1

    def _add_sparse(self, volume: Volume, scale: float, tracked: bool) -> int:
        sg = volume.sparse
        rec = np.zeros((), layout.GRID_VOLUME)
        rec["to_local"] = np.linalg.inv(np.asarray(volume.to_world, np.float64))[:3, :4].reshape(12)
        nb = sg.padded_counts()
        rec["res"] = nb * 8
        rec["channels"] = sg.channels
        rec["filter"] = layout.GRID_FILTERS[volume.filter]
        rec["layout"] = layout.GRID_LAYOUTS["sparse"]
        rec["data"] = self._append(sparse_chunk(sg, scale, self.size))
        rec["majorants"] = -1
        cost = dict(name=sg.name, path=sg.path, active_voxels=sg.active_voxels, stored_bricks=len(sg.coords),
                    box_voxels=int(np.prod(nb)) * 512, bytes=sg.stored_bytes())
        if tracked:
            rec["maj_res"] = nb
            rec["majorants"] = self._append(sparse_majorants(sg, scale))
            self.majorant_count += int(np.prod(nb))
            cost["bytes"] += 4 * int(np.prod(nb))
        self.voxels += len(sg.coords) * 512
        self.sparse.append(cost)
        self.descriptors.append(rec)
        return len(self.descriptors) - 1

    def add_words(self, words: np.ndarray) -> int:
        """Offset of float32 words appended to grid_data (tables the kernels read beside grids)."""
        return self._append(words)

    def blackbody_table(self) -> int:
        """Offset of the blackbody colour table (once per scene): t_min, log(t_max / t_min), size,
        then size rgb triples (volcl/blackbody.py)."""
        if getattr(self, "_blackbody", None) is None:
            from . import blackbody
            head = np.array([blackbody.T_CUTOFF, np.log(blackbody.T_MAX / blackbody.T_CUTOFF),
                             blackbody.TABLE_SIZE], np.float32)
            self._blackbody = self._append(np.concatenate([head, blackbody.table().reshape(-1)]))
        return self._blackbody

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(descriptors, grid_data); one dummy entry each when the scene has no grids, since
        OpenCL buffers cannot be empty."""
        desc = np.zeros(max(len(self.descriptors), 1), layout.GRID_VOLUME)
        for i, rec in enumerate(self.descriptors):
            desc[i] = rec
        data = np.concatenate(self.chunks) if self.chunks else np.zeros(1, np.float32)
        return desc, data
