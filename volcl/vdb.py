"""OpenVDB (.vdb) and NanoVDB (.nvdb) grids, read into volcl's sparse brick layout.

Reading. `.vdb` files go through the OpenVDB library itself: Debian's python3-openvdb (module
`pyopenvdb`) is built for Debian's own /usr/bin/python3, which need not be the interpreter volcl
runs on (its virtual environment may come from another CPython, whose ABI that extension module
does not match). volcl therefore runs volcl/openvdb_helper.py under that interpreter as a separate
process and reads the bricks it writes: the library's answers, without tying volcl's environment to
Debian's numpy and Python. `VOLCL_OPENVDB_PYTHON` names another interpreter that has `pyopenvdb`.
`.nvdb` files are turned into a temporary `.vdb` by NanoVDB's own converter (`nanovdb_convert`,
Debian's libnanovdb-tools, built from the same OpenVDB release), which reads every version and
codec of the NanoVDB layout its library knows (Blosc and zip, quantized Fp4/Fp8/Fp16/FpN grids),
then read as above; `VOLCL_NANOVDB_CONVERT` names another converter.

Meaning (OpenVDB's, as its BoxSampler and pbrt-v4's nanovdb medium sample a grid): voxel (i, j, k)
holds the value at index-space point (i, j, k), the grid's transform takes index space to its
world, trilinear lookups interpolate between the eight voxels around a point, and every voxel
outside the stored region holds the grid's background. volcl's `to_world` is applied after the
grid's own index-to-world transform.

Layout (SparseGrid): the index space is cut into bricks of 8^3 voxels aligned as OpenVDB's leaf
nodes are. A brick that holds more than one value is stored whole; one that holds a single value
(a tile, or a part of the background) is that value alone. The bricks span the stored region plus
one brick of background on every side, so that the edge of the box the kernels clip rays to lies
where the grid is already background and filtered lookups there read it as OpenVDB would; the
same box as a dense Mitsuba-style grid (`dense`) therefore holds exactly the same field.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

from .errors import VolclError

BRICK = 8
HELPER = Path(__file__).with_name("openvdb_helper.py")
# Largest region (in voxels, counted over whole bricks) volcl reads from one grid: 2^34 voxels is a
# 2560^3 box, whose brick index alone (4 bytes a brick) is 128 MiB.
MAX_REGION_VOXELS = 2 ** 34


@dataclass
class SparseGrid:
    """One grid of a VDB file in bricks. Brick coordinates are (x, y, z) relative to `origin` (in
    bricks of the index space); brick data is (n, 512, channels), voxels z slowest, x fastest."""
    path: str
    name: str
    value_type: str
    channels: int
    background: np.ndarray            # (channels,)
    index_to_world: np.ndarray        # 4x4
    origin: np.ndarray                # (3,) int: index-space brick of coords (0, 0, 0)
    counts: np.ndarray                # (3,) bricks per axis that hold anything but background
    coords: np.ndarray                # (n, 3) stored bricks
    bricks: np.ndarray                # (n, 512, channels) float32
    tile_coords: np.ndarray           # (m, 3) one-value bricks other than the background
    tile_values: np.ndarray           # (m, channels)
    active_voxels: int = 0
    grid_class: str = ""
    extra: dict = field(default_factory=dict)

    @property
    def empty(self) -> bool:
        return not np.any(self.counts > 0)

    def padded_counts(self) -> np.ndarray:
        """Bricks per axis of the padded box (one background brick on every side)."""
        return self.counts + 2

    def unit_to_world(self) -> np.ndarray:
        """The map of the padded box, as the unit cube, to the grid's world: voxel i of its n
        voxels along an axis is centred at (i + 0.5) / n of the cube, as in a Mitsuba grid."""
        lo = BRICK * (self.origin - 1) - 0.5
        n = BRICK * self.padded_counts()
        m = np.eye(4)
        m[:3, :3] = np.diag(n.astype(np.float64))
        m[:3, 3] = lo
        return self.index_to_world @ m

    def brick_grid(self) -> np.ndarray:
        """(bz, by, bx) of the padded box: -1 background, k >= 0 stored brick k, -(2 + j) tile j."""
        nb = self.padded_counts()
        g = np.full((nb[2], nb[1], nb[0]), -1, np.int64)
        c = self.coords + 1
        g[c[:, 2], c[:, 1], c[:, 0]] = np.arange(len(c))
        t = self.tile_coords + 1
        g[t[:, 2], t[:, 1], t[:, 0]] = -2 - np.arange(len(t))
        return g

    def dense(self) -> np.ndarray:
        """(z, y, x, channels) float32 values over the padded box (tests, the dense benchmark)."""
        nb = self.padded_counts()
        out = np.empty((nb[2] * BRICK, nb[1] * BRICK, nb[0] * BRICK, self.channels), np.float32)
        out[...] = self.background
        view = out.reshape(nb[2], BRICK, nb[1], BRICK, nb[0], BRICK, self.channels)
        for (x, y, z), values in zip(self.coords + 1, self.bricks):
            view[z, :, y, :, x, :, :] = values.reshape(BRICK, BRICK, BRICK, self.channels)
        for (x, y, z), value in zip(self.tile_coords + 1, self.tile_values):
            view[z, :, y, :, x, :, :] = value
        return out

    def index_box(self) -> tuple[np.ndarray, np.ndarray]:
        """Inclusive index-space voxel box of the padded box (x, y, z)."""
        lo = BRICK * (self.origin - 1)
        return lo, lo + BRICK * self.padded_counts() - 1

    def stored_bytes(self) -> int:
        """What the device layout holds for this grid: the brick index, the stored bricks and the
        tile values (kernels/grid.h), not counting the majorant grid."""
        return 4 * (int(np.prod(self.padded_counts())) + self.bricks.size + self.tile_values.size + self.channels)


def from_dense(values: np.ndarray, ijk=(0, 0, 0), background=0.0, index_to_world=None, name: str = "density"
               ) -> SparseGrid:
    """A SparseGrid of the array values (z, y, x) or (z, y, x, c) whose voxel [0, 0, 0] sits at index
    ijk (x, y, z), cut into bricks as openvdb_helper.py cuts a file's grid (tests, benchmarks)."""
    a = np.asarray(values, np.float32)
    a = a[..., None] if a.ndim == 3 else a
    c = a.shape[-1]
    bg = np.broadcast_to(np.asarray(background, np.float32), (c,)).copy()
    nz = np.argwhere(np.any(a != bg, axis=-1))
    empty = SparseGrid(path="", name=name, value_type="float" if c == 1 else "vec3s", channels=c, background=bg,
                       index_to_world=np.eye(4) if index_to_world is None else np.asarray(index_to_world, float),
                       origin=np.zeros(3, np.int64), counts=np.zeros(3, np.int64),
                       coords=np.zeros((0, 3), np.int64), bricks=np.zeros((0, 512, c), np.float32),
                       tile_coords=np.zeros((0, 3), np.int64), tile_values=np.zeros((0, c), np.float32))
    if not len(nz):
        return empty
    ijk = np.asarray(ijk, np.int64)
    lo = nz.min(axis=0)[::-1] + ijk              # x, y, z index box of the values
    hi = nz.max(axis=0)[::-1] + ijk
    lo_b, hi_b = np.floor_divide(lo, BRICK), np.floor_divide(hi, BRICK)
    nb = hi_b - lo_b + 1
    box = np.empty((nb[2] * BRICK, nb[1] * BRICK, nb[0] * BRICK, c), np.float32)
    box[...] = bg
    o = ijk - lo_b * BRICK                         # where the array starts in the box (x, y, z)
    src = [slice(max(0, -o[k]), min(a.shape[2 - k], box.shape[2 - k] - o[k])) for k in range(3)]
    dst = [slice(s.start + o[k], s.stop + o[k]) for k, s in enumerate(src)]
    box[dst[2], dst[1], dst[0]] = a[src[2], src[1], src[0]]
    b = box.reshape(nb[2], BRICK, nb[1], BRICK, nb[0], BRICK, c).transpose(4, 2, 0, 1, 3, 5, 6)
    b = b.reshape(nb[0], nb[1], nb[2], BRICK ** 3, c)           # [bx, by, bz]
    uniform = np.all(b == b[:, :, :, :1], axis=(3, 4))
    stored = np.argwhere(~uniform)
    tiles = np.argwhere(uniform & np.any(b[:, :, :, 0] != bg, axis=-1))
    empty.origin, empty.counts = lo_b, nb
    empty.coords = stored
    empty.bricks = b[~uniform].reshape(-1, BRICK ** 3, c)
    empty.tile_coords = tiles
    empty.tile_values = b[tiles[:, 0], tiles[:, 1], tiles[:, 2], 0].reshape(-1, c)
    empty.active_voxels = int(np.sum(np.any(a != bg, axis=-1)))
    return empty


def merge_bricks(parts: list[SparseGrid]) -> SparseGrid:
    """One SparseGrid holding the bricks of `parts` (same channels and background, no brick in two
    of them), in the index space they share (benchmarks, tests: grids spread over a large box)."""
    origin = np.min([p.origin for p in parts], axis=0)
    hi = np.max([p.origin + p.counts for p in parts], axis=0)
    out = from_dense(np.zeros((1, 1, 1, parts[0].channels), np.float32), background=parts[0].background,
                     name=parts[0].name)
    out.origin, out.counts = origin, hi - origin
    out.coords = np.concatenate([p.coords + p.origin - origin for p in parts])
    out.bricks = np.concatenate([p.bricks for p in parts])
    out.tile_coords = np.concatenate([p.tile_coords + p.origin - origin for p in parts])
    out.tile_values = np.concatenate([p.tile_values for p in parts])
    out.active_voxels = sum(p.active_voxels for p in parts)
    if len(np.unique(out.coords, axis=0)) != len(out.coords):
        raise ValueError("merge_bricks: two parts hold the same brick")
    return out


def _python() -> str:
    return os.environ.get("VOLCL_OPENVDB_PYTHON", "/usr/bin/python3")


def _run_helper(*args: str) -> dict:
    exe = _python()
    if not (os.path.isfile(exe) and os.access(exe, os.X_OK)):
        raise VolclError(f"reading OpenVDB files needs the OpenVDB library's Python module under "
                         f"{exe}, which does not exist (install Debian's python3-openvdb, or set "
                         f"VOLCL_OPENVDB_PYTHON to an interpreter that has pyopenvdb)")
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    proc = subprocess.run([exe, "-I", str(HELPER), *args], capture_output=True, text=True, env=env)
    if proc.returncode == 2:
        raise VolclError(f"{proc.stderr.strip()}: install Debian's python3-openvdb (./quickstart does), "
                         f"or set VOLCL_OPENVDB_PYTHON to an interpreter that has pyopenvdb")
    if proc.returncode != 0:
        raise VolclError(proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else
                         f"the OpenVDB reader failed (exit status {proc.returncode})")
    return json.loads(proc.stdout)


def _converter() -> str:
    exe = os.environ.get("VOLCL_NANOVDB_CONVERT") or shutil.which("nanovdb_convert")
    if not exe:
        raise VolclError("reading NanoVDB files needs NanoVDB's converter nanovdb_convert (install Debian's "
                         "libnanovdb-tools; ./quickstart does), or set VOLCL_NANOVDB_CONVERT")
    return exe


def _is_nanovdb(path: str) -> bool:
    return path.lower().endswith(".nvdb")


def _check_magic(path: str) -> None:
    """A clear error for a file that is not VDB at all, before any library sees it."""
    with open(path, "rb") as f:
        head = f.read(8)
    if _is_nanovdb(path):
        # NanoVDB files start with a 64-bit magic number whose bytes spell NanoVDB (versions 0 and 1)
        if not head.startswith(b"NanoVDB"):
            raise VolclError(f"{path} is not a NanoVDB file (it does not start with NanoVDB's magic "
                             f"number; found {head!r})")
    elif head[:4] != b"\x20\x42\x44\x56":
        raise VolclError(f"{path} is not an OpenVDB file (it does not start with OpenVDB's magic "
                         f"number 0x56444220; found {head[:4]!r})")


class _Converted:
    """A .nvdb file as a temporary .vdb file (removed on exit from the with block)."""

    def __init__(self, path: str):
        self.path = path

    def __enter__(self) -> str:
        if not _is_nanovdb(self.path):
            return self.path
        self.tmp = tempfile.mkdtemp(prefix="volcl-nvdb-")
        out = os.path.join(self.tmp, "grid.vdb")
        proc = subprocess.run([_converter(), "-f", self.path, out], capture_output=True, text=True)
        if proc.returncode != 0 or not os.path.exists(out):
            msg = (proc.stderr or proc.stdout).strip()
            raise VolclError(f"{self.path}: NanoVDB's converter could not read it"
                             + (f" ({msg.splitlines()[-1]})" if msg else ""))
        return out

    def __exit__(self, *exc):
        if _is_nanovdb(self.path):
            shutil.rmtree(self.tmp, ignore_errors=True)


def _key(path: str) -> tuple:
    st = os.stat(path)
    return os.path.abspath(path), st.st_mtime_ns, st.st_size


def grids(path: str) -> list[dict]:
    """The grids in a .vdb or .nvdb file: name, type ('float', 'vec3s', ...), class, bbox, voxels."""
    return _grids(_key(path))


@lru_cache(maxsize=16)
def _grids(key) -> list[dict]:
    path = key[0]
    _check_magic(path)
    with _Converted(path) as vdb_path:
        out = _run_helper("grids", vdb_path)["grids"]
    if not out:
        raise VolclError(f"{path} holds no grids (an empty or damaged OpenVDB file)")
    return out


def describe_grids(found: list[dict]) -> str:
    return ", ".join(f"'{g['name']}' ({g['type']})" for g in found)


def read(path: str, grid: str) -> SparseGrid:
    """Grid `grid` of a .vdb or .nvdb file. Errors (VolclError) name the file and, for a grid that
    is not there, the grids that are."""
    return _read(_key(path), grid)


@lru_cache(maxsize=16)
def _read(key, grid: str) -> SparseGrid:
    path = key[0]
    _check_magic(path)
    with _Converted(path) as vdb_path, tempfile.TemporaryDirectory(prefix="volcl-vdb-") as tmp:
        out = os.path.join(tmp, "bricks.npz")
        s = _run_helper("read", vdb_path, grid, out, str(MAX_REGION_VOXELS))
        if s.get("missing") and not s["grids"]:
            raise VolclError(f"{path} holds no grids (an empty or damaged OpenVDB file)")
        if s.get("missing"):
            raise VolclError(f"{path} has no grid named '{grid}'; its grids: {describe_grids(s['grids'])}")
        if "unsupported" in s:
            raise VolclError(f"grid '{grid}' of {path} holds {s['unsupported']} values; volcl reads "
                             f"float, double and half grids (and vec3 grids where a colour is allowed)")
        if s.get("too_large"):
            nb = np.array(s["brick_counts"])
            raise VolclError(f"grid '{grid}' of {path} spans {nb[0] * BRICK}x{nb[1] * BRICK}x"
                             f"{nb[2] * BRICK} voxels ({int(np.prod(nb)) * BRICK ** 3:.3g} in its "
                             f"bricks), more than volcl reads from one grid ({MAX_REGION_VOXELS:.3g})")
        with np.load(out) as z:
            arrays = {k: z[k] for k in z.files}
    return SparseGrid(path=path, name=grid, value_type=s["type"], channels=s["channels"],
                      background=np.array(s["background"], np.float32),
                      index_to_world=np.array(s["index_to_world"], np.float64),
                      origin=np.array(s["brick_origin"], np.int64), counts=np.array(s["brick_counts"], np.int64),
                      coords=arrays["coords"].astype(np.int64), bricks=arrays["bricks"],
                      tile_coords=arrays["tile_coords"].astype(np.int64), tile_values=arrays["tile_values"],
                      active_voxels=s["active_voxels"], grid_class=s["class"])


def write(path: str, grids: list[dict]) -> None:
    """Write grids to a .vdb file through OpenVDB (volcl/openvdb_helper.py write_grids says what each
    dict holds; 'array' is a numpy array indexed [x][y][z] or [x][y][z][3]), or to a .nvdb file by
    converting that with nanovdb_convert. For tests and the scene scripts."""
    with tempfile.TemporaryDirectory(prefix="volcl-vdbw-") as tmp:
        spec, arrays = [], {}
        for i, g in enumerate(grids):
            g = dict(g)
            if g.get("array") is not None:
                arrays[f"a{i}"] = np.asarray(g.pop("array"), np.float32)
                g["array"] = f"a{i}"
            if "index_to_world" in g:
                g["index_to_world"] = np.asarray(g["index_to_world"], np.float64).tolist()
            spec.append(g)
        spec_path, arrays_path = os.path.join(tmp, "spec.json"), os.path.join(tmp, "arrays.npz")
        with open(spec_path, "w") as f:
            json.dump(spec, f)
        np.savez(arrays_path, **arrays)
        target = os.path.join(tmp, "grids.vdb") if _is_nanovdb(path) else str(path)
        proc = subprocess.run([_python(), "-I", str(HELPER), "write", target, spec_path, arrays_path],
                              capture_output=True, text=True)
        if proc.returncode != 0:
            raise VolclError(f"writing {path} failed: {proc.stderr.strip()}")
        if _is_nanovdb(path):
            proc = subprocess.run([_converter(), "-f", target, str(path)], capture_output=True, text=True)
            if proc.returncode != 0:
                raise VolclError(f"converting to {path} failed: {(proc.stderr or proc.stdout).strip()}")


def available() -> tuple[bool, str]:
    """Whether .vdb files can be read here, and why not."""
    try:
        probe = subprocess.run([_python(), "-I", "-c", "import pyopenvdb"], capture_output=True, text=True)
    except OSError as exc:
        return False, str(exc)
    return probe.returncode == 0, probe.stderr.strip()


if __name__ == "__main__":        # python -m volcl.vdb FILE: list a file's grids
    for g in grids(sys.argv[1]):
        print(g)
