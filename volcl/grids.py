"""Grid volumes as the kernels read them: one descriptor per use (layout.GRID_VOLUME), and one
float32 buffer holding every grid's voxels and the coarse majorant grids used for tracking.

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

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(descriptors, grid_data); one dummy entry each when the scene has no grids, since
        OpenCL buffers cannot be empty."""
        desc = np.zeros(max(len(self.descriptors), 1), layout.GRID_VOLUME)
        for i, rec in enumerate(self.descriptors):
            desc[i] = rec
        data = np.concatenate(self.chunks) if self.chunks else np.zeros(1, np.float32)
        return desc, data
