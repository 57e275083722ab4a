"""Reads OpenVDB files through the OpenVDB library's Python module (`pyopenvdb`), as a program of its
own: Debian's python3-openvdb is built for Debian's /usr/bin/python3, not for the interpreter volcl's
virtual environment may run on, so volcl starts this file under that interpreter (volcl/vdb.py) and
reads back what it writes. It imports nothing of volcl's, only pyopenvdb and numpy.

    python3 openvdb_helper.py grids FILE              -> JSON: the file's grids, their types and sizes
    python3 openvdb_helper.py read FILE GRID OUT.npz MAX_VOXELS
                                                      -> the grid in 8^3 bricks (OUT.npz), JSON summary
    python3 openvdb_helper.py write OUT.vdb SPEC.json ARRAYS.npz
                                                      -> a .vdb file of the grids SPEC describes

A grid is read as OpenVDB's own samplers see it: every voxel's value, active or not, inside the
region that holds anything but the background (leaf nodes, active voxels and tiles, inactive tiles
with another value); the background elsewhere. The region is cut into bricks of 8^3 voxels aligned
to the index grid (OpenVDB's leaf nodes have that size and alignment, and every tile is a union of
them); a brick whose voxels all hold one value is kept as that value alone.
"""
import json
import sys

import numpy as np

BRICK = 8
FLOAT_TYPES = ("float", "double", "half")
VECTOR_TYPES = ("vec3s", "vec3d", "vec3f")


def fail(message, code=3):
    sys.stderr.write(message + "\n")
    sys.exit(code)


def open_module():
    try:
        import pyopenvdb
    except ImportError as exc:
        fail(f"the OpenVDB Python module is not installed for {sys.executable} ({exc})", 2)
    return pyopenvdb


def grid_list(vdb, path):
    try:
        grids = vdb.readAllGridMetadata(path)
    except Exception as exc:            # pyopenvdb raises plain RuntimeErrors / IOErrors
        fail(f"not a readable OpenVDB file: {exc}")
    out = []
    for g in grids:
        meta = dict(g.metadata)
        lo, hi = meta.get("file_bbox_min"), meta.get("file_bbox_max")
        out.append({"name": g.name, "type": g.valueTypeName, "class": str(g.gridClass),
                    "bbox": [list(lo), list(hi)] if lo is not None and hi is not None and lo[0] <= hi[0] else None,
                    "voxels": int(meta.get("file_voxel_count", 0))})
    return out


def index_to_world(grid):
    """The 4x4 affine index-to-world matrix (column vectors), probed at the origin and unit axes."""
    t = grid.transform
    if not (t.isLinear() if callable(t.isLinear) else t.isLinear):
        fail(f"grid '{grid.name}' has a non-linear (frustum) transform, which volcl cannot place")
    o = np.array(t.indexToWorld((0.0, 0.0, 0.0)), np.float64)
    m = np.eye(4)
    m[:3, 3] = o
    for axis in range(3):
        e = [0.0, 0.0, 0.0]
        e[axis] = 1.0
        m[:3, axis] = np.array(t.indexToWorld(tuple(e)), np.float64) - o
    return m


def differs(value, background):
    return bool(np.any(np.asarray(value, np.float64) != np.asarray(background, np.float64)))


def value_region(grid, background):
    """Inclusive index box (lo, hi) of everything that is not background, or None."""
    boxes = []
    for box in (grid.evalActiveVoxelBoundingBox(), grid.evalLeafBoundingBox()):
        lo, hi = np.array(box[0]), np.array(box[1])
        if np.all(hi >= lo) and grid.activeVoxelCount() + grid.leafCount() > 0:
            boxes.append((lo, hi))
    # inactive tiles with a value of their own (inactive voxels lie in leaves, covered above)
    for item in grid.iterOffValues():
        if item.count > 1 and differs(item.value, background):
            boxes.append((np.array(item.min), np.array(item.max)))
    if not boxes:
        return None
    return np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)


def read_grid(vdb, path, name, out, max_voxels):
    names = [g["name"] for g in grid_list(vdb, path)]
    if name not in names:
        json.dump({"missing": True, "grids": grid_list(vdb, path)}, sys.stdout)
        return
    grid = vdb.read(path, name)
    vtype = grid.valueTypeName
    if vtype in FLOAT_TYPES:
        channels = 1
    elif vtype in VECTOR_TYPES:
        channels = 3
    else:
        json.dump({"unsupported": vtype, "grids": grid_list(vdb, path)}, sys.stdout)
        return
    background = np.array(grid.background, np.float32).reshape(channels)
    region = value_region(grid, background)
    summary = {"name": name, "type": vtype, "channels": channels, "class": str(grid.gridClass),
               "background": background.tolist(), "index_to_world": index_to_world(grid).tolist(),
               "active_voxels": int(grid.activeVoxelCount()), "leaf_count": int(grid.leafCount())}
    if region is None:
        lo_b = np.zeros(3, np.int64)
        nb = np.zeros(3, np.int64)
    else:
        lo_b = np.floor_divide(region[0], BRICK)
        nb = np.floor_divide(region[1], BRICK) - lo_b + 1
    summary["brick_origin"] = lo_b.tolist()
    summary["brick_counts"] = nb.tolist()
    if int(np.prod(nb)) * BRICK ** 3 > max_voxels:
        summary["too_large"] = True
        json.dump(summary, sys.stdout)
        return
    coords, bricks, tile_coords, tile_values = [], [], [], []
    ny, nz = int(nb[1]) * BRICK, int(nb[2]) * BRICK
    shape = (BRICK, ny, nz) + ((3,) if channels == 3 else ())
    for bx in range(int(nb[0])):
        # one slab of bricks along x; copyToArray indexes the array [x][y][z] from ijk
        slab = np.zeros(shape, np.float32)
        origin = (int((lo_b[0] + bx) * BRICK), int(lo_b[1] * BRICK), int(lo_b[2] * BRICK))
        grid.copyToArray(slab, ijk=origin)
        s = slab.reshape(BRICK, nb[1], BRICK, nb[2], BRICK, channels)
        # -> (by, bz, z, y, x, c): each brick in volcl's order, z slowest and x fastest
        s = s.transpose(1, 3, 4, 2, 0, 5).reshape(int(nb[1]), int(nb[2]), BRICK ** 3, channels)
        first = s[:, :, :1, :]
        uniform = np.all(s == first, axis=(2, 3))
        for by, bz in zip(*np.nonzero(~uniform)):
            coords.append((bx, by, bz))
            bricks.append(s[by, bz])
        for by, bz in zip(*np.nonzero(uniform)):
            v = s[by, bz, 0]
            if differs(v, background):
                tile_coords.append((bx, by, bz))
                tile_values.append(v)
    np.savez(out,
             coords=np.array(coords, np.int32).reshape(-1, 3),
             bricks=np.array(bricks, np.float32).reshape(-1, BRICK ** 3, channels),
             tile_coords=np.array(tile_coords, np.int32).reshape(-1, 3),
             tile_values=np.array(tile_values, np.float32).reshape(-1, channels))
    json.dump(summary, sys.stdout)


def write_grids(vdb, out, spec_path, arrays_path):
    """SPEC: a list of grids, each {name, array (a key of ARRAYS, indexed [x][y][z][c]), ijk (index of
    the array's first voxel), index_to_world (4x4, column vectors), background, tolerance (values
    within it of the background stay inactive), tiles: [[min, max, value, active], ...], fog}."""
    with open(spec_path) as f:
        spec = json.load(f)
    arrays = np.load(arrays_path)
    grids = []
    for g in spec:
        a = arrays[g["array"]] if g.get("array") else None
        vector = (a is not None and a.ndim == 4) or isinstance(g.get("background"), list)
        bg = g.get("background", (0.0, 0.0, 0.0) if vector else 0.0)
        grid = vdb.Vec3SGrid(tuple(bg)) if vector else vdb.FloatGrid(float(bg))
        grid.name = g["name"]
        if a is not None:
            tol = float(g.get("tolerance", 0.0))
            grid.copyFromArray(np.ascontiguousarray(a, np.float32), ijk=tuple(g.get("ijk", (0, 0, 0))),
                               tolerance=(tol, tol, tol) if vector else tol)
        for lo, hi, value, active in g.get("tiles", ()):
            grid.fill(tuple(lo), tuple(hi), tuple(value) if vector else float(value), active=bool(active))
        m = np.array(g.get("index_to_world", np.eye(4)), np.float64)
        # pyopenvdb takes the matrix in OpenVDB's row-vector convention
        grid.transform = vdb.createLinearTransform(matrix=m.T.tolist())
        if g.get("fog", True):
            grid.gridClass = vdb.GridClass.FOG_VOLUME
        grids.append(grid)
    vdb.write(out, grids=grids)


def main(argv):
    vdb = open_module()
    if len(argv) == 2 and argv[0] == "grids":
        json.dump({"grids": grid_list(vdb, argv[1])}, sys.stdout)
    elif len(argv) == 5 and argv[0] == "read":
        read_grid(vdb, argv[1], argv[2], argv[3], int(argv[4]))
    elif len(argv) == 4 and argv[0] == "write":
        write_grids(vdb, argv[1], argv[2], argv[3])
    else:
        fail(__doc__, 64)


if __name__ == "__main__":
    main(sys.argv[1:])
