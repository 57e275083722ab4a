#!/usr/bin/env python3
"""Writes the OpenVDB files of scenes/vdb_cloud.xml and scenes/vdb_fire.xml through OpenVDB itself
(volcl.vdb.write runs OpenVDB's Python module under Debian's python3): seeded procedural noise,
nothing downloaded, the same files on every run.

- volumes/cloud.vdb, grid `density`: the puff of scenes/make_smoke.py at 96^3, stored sparsely
  (only its non-zero bricks), with OpenVDB's index bounds starting below zero and a transform of its
  own (voxels 1/96 apart, centred on the origin), so the scene only moves and scales it.
- volumes/fireball.vdb, grids `density` (soot and gas, highest in a shell) and `temperature` (in
  kelvin, hottest in the core and cooling outwards, with noise): a small explosion at 64^3.

Run again to regenerate: python scenes/make_vdb.py
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))
from make_smoke import fbm, smoke  # noqa: E402
from volcl import vdb  # noqa: E402

VOLUMES = HERE / "volumes"


def centred_transform(res: int) -> np.ndarray:
    """Index -> world for a res^3 grid written at index -res/2: voxel centres 1/res apart around 0."""
    m = np.diag([1.0 / res, 1.0 / res, 1.0 / res, 1.0])
    m[:3, 3] = 0.5 / res
    return m


def fireball(res: int = 64, seed: int = 11) -> tuple[np.ndarray, np.ndarray]:
    """(density, temperature) arrays (z, y, x): a rising ball of burning gas."""
    rng = np.random.default_rng(seed)
    c = (np.arange(res) + 0.5) / res - 0.5
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    lift = 0.08 * (y + 0.5) ** 2                       # the top spreads a little
    r = np.sqrt(x ** 2 + (y + 0.05) ** 2 + z ** 2) / (0.36 + lift)
    turb = fbm(res, rng, octaves=4, base_cells=3) - 0.5
    fine = fbm(res, rng, octaves=3, base_cells=6)
    d = r + 0.55 * turb
    edge = np.clip((1.0 - d) / 0.3, 0, 1)
    density = edge ** 1.2 * (0.4 + 0.6 * fine)
    heat = np.clip(1.0 - d / 1.1, 0, 1) * (0.6 + 0.4 * fine)
    temperature = np.where(density > 0, 900.0 + 1700.0 * heat, 0.0)
    for a in (density, temperature):
        a[[0, -1], :, :] = a[:, [0, -1], :] = a[:, :, [0, -1]] = 0.0
    return (density / density.max()).astype(np.float32), temperature.astype(np.float32)


def main():
    VOLUMES.mkdir(exist_ok=True)
    cloud = smoke(96, seed=5)
    # arrays for volcl.vdb.write are indexed [x][y][z]
    vdb.write(str(VOLUMES / "cloud.vdb"), [dict(name="density", array=cloud.transpose(2, 1, 0), ijk=(-48, -48, -48),
                                                index_to_world=centred_transform(96))])
    density, temperature = fireball()
    fire_m = centred_transform(64)
    vdb.write(str(VOLUMES / "fireball.vdb"), [
        dict(name="density", array=density.transpose(2, 1, 0), ijk=(-32, -32, -32), index_to_world=fire_m,
             ),
        dict(name="temperature", array=temperature.transpose(2, 1, 0), ijk=(-32, -32, -32),
             index_to_world=fire_m, fog=False)])
    for name in ("cloud.vdb", "fireball.vdb"):
        for g in vdb.grids(str(VOLUMES / name)):
            sg = vdb.read(str(VOLUMES / name), g["name"])
            box = int(np.prod(sg.padded_counts())) * 512
            print(f"{name} '{g['name']}': {sg.active_voxels} active voxels, {len(sg.coords)} bricks, "
                  f"{sg.stored_bytes()} bytes on the device against {4 * box} dense "
                  f"({sg.stored_bytes() / max(sg.active_voxels, 1):.2f} bytes per active voxel)")


if __name__ == "__main__":
    main()
