"""Next-event estimation towards emissive media: the tables that sample a point in proportion to an
upper bound of emission (kernels/emission_nee.h reads them).

Every emissive medium is covered by cells: a heterogeneous medium by the majorant cells of its
extinction grid's voxels (up to 128 per axis; the bricks of a large sparse grid), a homogeneous one by a
single box, the bounds of the shapes it fills. A cell's bound of sigma_a * Le over it is the extinction
majorant, times a bound of max(1 - albedo), times a bound of the radiance, each read over the cell
from the grid it comes from (its own cells mapped onto the extinction cell, or the grid's largest
value where the two frames are not axis-aligned to each other). Where the cells are voxels and the
grids share them, the weight is sigma_a Le at the voxel's centre plus BOUND_SHARE of the bound (Le
of a blackbody rises steeply with temperature, so the bound alone over-weights the cool voxels next
to hot ones); elsewhere it is the bound. A point is drawn in two steps, a medium by its total
weight (weight times cell volume) and a cell by its weight, then uniformly in the cell; its density
per unit volume is p_medium * p_cell / cell volume, zero outside the cells.

The weights only steer the sampling: the estimate divides by the density the kernel samples with, and
the path's own collision estimate keeps the full weight wherever that density is zero, so a loose or
even a wrong bound costs variance, never bias. What must be exact is that density: the CDFs are
rounded to float32 first and each probability is the difference of the rounded values, which is
exactly the share of [0, 1) a uniform number falls into.

Words appended to grid_data (ints as int32 bit patterns):
    table (RenderParams.emission_table): count, then per medium (medium index, CDF end)
    per medium (Medium.emission_sampler): kind (0 box, 1 grid), cells, p_medium, 1 / cell volume,
        res x y z, to_world (3x4: unit cube -> world), to_local (3x4), cell probabilities (cells),
        CDF (cells + 1, from 0 to 1)
"""
from __future__ import annotations

import numpy as np

from . import blackbody
from .grids import majorant_grid, sparse_majorants

HEADER_WORDS = 31
# grids are sampled by voxel, up to this many cells per axis (at most 2 x 128^3 floats, 16 MiB)
MAX_CELLS_PER_AXIS = 128
DENSIFY_VOXELS = 128 ** 3
# where cells are voxels, a cell's weight is its centre's emission plus this share of its bound
BOUND_SHARE = 0.05
KIND_BOX, KIND_GRID = 0, 1


def _int_words(values) -> np.ndarray:
    return np.asarray(values, np.int32).view(np.float32)


def _cdf(weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(probabilities, CDF) in float32, each probability the exact width of its CDF interval."""
    w = np.asarray(weights, np.float64).reshape(-1)
    c = np.concatenate([[0.0], np.cumsum(w)]) / w.sum()
    c32 = c.astype(np.float32)
    c32[0], c32[-1] = 0.0, 1.0
    c32 = np.maximum.accumulate(c32)
    return (c32[1:].astype(np.float64) - c32[:-1].astype(np.float64)).astype(np.float32), c32


def _bound_grid(volume, transform: str):
    """(grid of upper bounds over cells of the volume's unit cube (z, y, x), its to_world) of
    f(value) max over channels, f = the identity ('max'), the negation ('neg') or 1 - value
    ('one_minus'); a 1x1x1 grid for constants and where no tighter bound is at hand."""
    def f(a):
        a = np.asarray(a, np.float64)
        return a if transform == "max" else (-a if transform == "neg" else 1.0 - a)
    if volume.kind == "const":
        return np.full((1, 1, 1), float(np.max(f(volume.value)))), None
    data = _voxels(volume)
    if data is not None:
        return (majorant_grid(f(data), volume.filter, _fine_res(data)).astype(np.float64),
                np.asarray(volume.to_world, np.float64))
    if transform == "max":
        return sparse_majorants(volume.sparse, 1.0).astype(np.float64), np.asarray(volume.to_world, np.float64)
    return np.full((1, 1, 1), float(np.max(f(volume.values())))), None


def _cells_bound(grid: np.ndarray, grid_to_world, cell_to_world: np.ndarray, cell_res) -> np.ndarray:
    """(z, y, x) bound over each of cell_res cells of the unit cube of cell_to_world, from a bound
    grid over the unit cube of grid_to_world (clamped at its faces, as lookups are)."""
    out_shape = tuple(int(n) for n in cell_res[::-1])
    if grid.size == 1 or grid_to_world is None:
        return np.full(out_shape, float(grid.max()))
    m = np.linalg.inv(grid_to_world) @ cell_to_world           # cell cube -> grid cube
    lin = m[:3, :3]
    if np.abs(lin - np.diag(np.diag(lin))).max() > 1e-9 * np.abs(lin).max():
        return np.full(out_shape, float(grid.max()))
    out = grid
    for axis_xyz in range(3):
        n_cells, g = int(cell_res[axis_xyz]), grid.shape[2 - axis_xyz]
        a = m[axis_xyz, axis_xyz] * np.arange(n_cells + 1) / n_cells + m[axis_xyz, 3]
        # the bound cells a cell overlaps (one touching it at a face only is not needed: the bound
        # cells already cover their lookups' whole support)
        lo = np.clip(np.floor(np.minimum(a[:-1], a[1:]) * g + 1e-6), 0, g - 1).astype(int)
        hi = np.clip(np.ceil(np.maximum(a[:-1], a[1:]) * g - 1e-6) - 1, 0, g - 1).astype(int)
        hi = np.maximum(hi, lo)
        ax = 2 - axis_xyz
        out = np.stack([np.take(out, np.arange(l, h + 1), axis=ax).max(axis=ax) for l, h in zip(lo, hi)], axis=ax)
    return out


def _blackbody_prefix_max() -> np.ndarray:
    return np.maximum.accumulate(blackbody.table().max(axis=1))


def _radiance_bound(m, cell_to_world, cell_res) -> np.ndarray:
    """Per cell, a bound of the largest channel of a heterogeneous medium's Le."""
    if m.emission_kind == "none":
        return np.full(tuple(int(n) for n in cell_res[::-1]), float(np.max(m.radiance)))
    scale = abs(float(m.emission_scale))
    if m.emission_kind == "radiance":
        g, w = _bound_grid(m.emission_volume, "max")
        return scale * np.maximum(_cells_bound(g, w, cell_to_world, cell_res), 0.0)
    sign = 1.0 if m.temperature_scale >= 0 else -1.0
    g, w = _bound_grid(m.emission_volume, "max" if sign > 0 else "neg")
    t_max = (sign * _cells_bound(g, w, cell_to_world, cell_res) - m.temperature_offset) * m.temperature_scale
    # the table's knots are evenly spaced in log T: the interpolated colour over [cut-off, t_max]
    # is at most the largest knot value up to the first knot at or above t_max
    n = blackbody.TABLE_SIZE
    x = np.log(np.maximum(t_max, blackbody.T_CUTOFF) / blackbody.T_CUTOFF) / np.log(blackbody.T_MAX / blackbody.T_CUTOFF)
    knot = np.clip(np.ceil(x * (n - 1)), 0, n - 1).astype(int)
    return np.where(t_max > blackbody.T_CUTOFF, scale * _blackbody_prefix_max()[knot], 0.0)


def _voxels(volume):
    """A grid's values (z, y, x, c) where they are at hand densely: dense grids, and sparse ones
    whose padded box holds at most DENSIFY_VOXELS voxels (bounds only: the device keeps the bricks);
    None otherwise."""
    if volume.kind == "grid":
        return volume.data
    if volume.kind == "sparse" and int(np.prod(volume.sparse.padded_counts())) * 512 <= DENSIFY_VOXELS:
        return volume.sparse.dense()
    return None


def _fine_res(data) -> tuple:
    """Sampling cells along x, y, z for voxels (z, y, x, c): one per voxel, at most MAX_CELLS_PER_AXIS."""
    return tuple(min(int(n), MAX_CELLS_PER_AXIS) for n in data.shape[2::-1])


def _grid_cells(m, rec, desc, majorants) -> tuple[np.ndarray, np.ndarray, tuple]:
    """(weights (z, y, x), to_world, res) of a heterogeneous medium's sampling cells: a dense
    extinction grid's voxels (its own bound per cell, finer than the tracking majorants: emission
    varies on the scale of voxels; also a small sparse grid's), a large sparse one's bricks, a
    constant one's majorant cell."""
    to_world = np.asarray(m.sigma_t.to_world, np.float64)
    data = _voxels(m.sigma_t)
    if data is not None:
        res = _fine_res(data)
        data = np.asarray(data, np.float32) * np.float32(m.scale)
        maj = majorant_grid(data, m.sigma_t.filter, res).astype(np.float64)
    else:
        res = tuple(int(n) for n in desc["maj_res"])
        maj = np.asarray(majorants, np.float64).reshape(res[::-1])
    g, w = _bound_grid(m.albedo, "one_minus")
    absorb = np.clip(_cells_bound(g, w, to_world, res), 0.0, None)
    bound = maj * absorb * _radiance_bound(m, to_world, res)
    point = _voxel_emission(m, data, res) if data is not None else None
    if point is None:
        return bound, to_world, res
    # cells centred on voxels: the emission at the voxel centre, which is what a point of the cell
    # mostly gets, mixed with a share of the bound so that no cell that can emit is left out
    return point + BOUND_SHARE * bound, to_world, res


def _voxel_emission(m, sigma_t, res):
    """sigma_a Le (largest channel) at the voxel centres where the sampling cells are the extinction
    grid's voxels and the albedo and emission grids share its frame and voxels; else None."""
    if tuple(sigma_t.shape[2::-1]) != tuple(res):
        return None

    def same_frame(v):
        return (v.kind in ("grid", "sparse") and np.allclose(v.to_world, m.sigma_t.to_world)
                and _voxels(v) is not None and _voxels(v).shape[:3] == sigma_t.shape[:3])
    if m.albedo.kind == "const":
        absorb = float(np.max(1.0 - np.asarray(m.albedo.value, np.float64)))
    elif same_frame(m.albedo):
        absorb = (1.0 - np.asarray(_voxels(m.albedo), np.float64)).max(-1)
    else:
        return None
    sig = np.asarray(sigma_t, np.float64).max(-1) * float(m.scale)
    if m.emission_kind == "none":
        le = float(np.max(m.radiance))
    elif not same_frame(m.emission_volume):
        return None
    elif m.emission_kind == "radiance":
        le = abs(float(m.emission_scale)) * np.asarray(_voxels(m.emission_volume), np.float64).max(-1)
    else:
        t = (np.asarray(_voxels(m.emission_volume), np.float64)[..., 0] - m.temperature_offset) * m.temperature_scale
        le = abs(float(m.emission_scale)) * blackbody.table_lookup(t).max(-1)
    return np.clip(sig * absorb * le, 0.0, None)


def _box_cells(packed_medium, box) -> tuple[np.ndarray, np.ndarray, tuple]:
    lo, hi = (np.asarray(b, np.float64) for b in box)
    to_world = np.eye(4)
    to_world[:3, :3] = np.diag(hi - lo)
    to_world[:3, 3] = lo
    return np.full((1, 1, 1), float(np.max(packed_medium["emission"]))), to_world, (1, 1, 1)


def build(media, packed_media, grid_desc: list, grid_values, boxes: dict, append) -> int:
    """Append the sampling tables of every emissive medium that has cells of positive weight; set
    their records' emission_sampler. Returns the table's offset, or -1 when nothing can be sampled.
    grid_values(offset, n): n floats of grid_data; boxes: medium index -> (lo, hi) of a homogeneous
    medium's region (media without one are not sampled); append(words) -> offset."""
    entries = []
    for i, m in enumerate(media):
        if not m.emissive:
            continue
        r = packed_media[i]
        if m.kind == "heterogeneous":
            desc = grid_desc[int(r["sigma_t_grid"])]
            n = int(np.prod(desc["maj_res"]))
            weights, to_world, res = _grid_cells(m, r, desc, grid_values(int(desc["majorants"]), n))
            kind = KIND_GRID
        elif i in boxes and np.all(np.asarray(boxes[i][1]) > np.asarray(boxes[i][0])):
            weights, to_world, res = _box_cells(r, boxes[i])
            kind = KIND_BOX
        else:
            continue
        weights = np.nan_to_num(np.maximum(weights, 0.0), posinf=0.0)
        cell_volume = abs(np.linalg.det(to_world[:3, :3])) / float(np.prod(res))
        mass = float(weights.sum()) * cell_volume
        if not mass > 0 or not np.isfinite(mass):
            continue
        entries.append((i, kind, weights, to_world, res, cell_volume, mass))
    if not entries:
        return -1
    p_media, media_cdf = _cdf([e[-1] for e in entries])
    for (i, kind, weights, to_world, res, cell_volume, _), p in zip(entries, p_media):
        probs, cdf = _cdf(weights)
        head = np.zeros(HEADER_WORDS, np.float32)
        head[0:2] = _int_words([kind, probs.size])
        head[2], head[3] = p, 1.0 / cell_volume
        head[4:7] = _int_words(res)
        head[7:19] = to_world[:3, :4].reshape(12)
        head[19:31] = np.linalg.inv(to_world)[:3, :4].reshape(12)
        packed_media[i]["emission_sampler"] = append(np.concatenate([head, probs, cdf]))
    table = np.zeros(1 + 2 * len(entries), np.float32)
    table[0:1] = _int_words([len(entries)])
    table[1::2] = _int_words([e[0] for e in entries])
    table[2::2] = media_cdf[1:]
    return append(table)
