#!/usr/bin/env python3
"""Writes scenes/volumes/smoke.vol, the density grid of scenes/smoke_grid.xml: a 48^3 puff of smoke
from seeded procedural noise (numpy only, nothing downloaded; the same file on every run).

The shape is a cluster of overlapping spherical puffs whose surfaces are displaced by fractal value
noise, with a soft edge and noisy density inside. The density is 0 on the grid's border voxels, so
the clamp-to-edge lookup outside the grid and the medium's cut-off at the unit cube agree, and it is
normalized to a maximum of 1 (the scene's `scale` sets the extinction). Most of the cube is empty,
which is what the majorant grid is for.

Run it again to regenerate: python scenes/make_smoke.py [--res 48] [--seed 5]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
from volcl.scene.volfile import write_vol  # noqa: E402

OUT = HERE / "volumes" / "smoke.vol"


def value_noise(res: int, cells: int, rng: np.random.Generator) -> np.ndarray:
    """Random values on a (cells + 1)^3 lattice, interpolated with a smoothstep to res^3 points."""
    lattice = rng.random((cells + 1,) * 3)
    x = (np.arange(res) + 0.5) / res * cells
    i = np.minimum(x.astype(int), cells - 1)
    f = x - i
    f = f * f * (3 - 2 * f)
    out = 0.0
    for dz in (0, 1):
        wz = (f if dz else 1 - f)[:, None, None]
        for dy in (0, 1):
            wy = (f if dy else 1 - f)[None, :, None]
            for dx in (0, 1):
                wx = (f if dx else 1 - f)[None, None, :]
                out = out + wz * wy * wx * lattice[np.ix_(i + dz, i + dy, i + dx)]
    return out


def fbm(res: int, rng: np.random.Generator, octaves: int = 4, base_cells: int = 3) -> np.ndarray:
    """Fractal sum of value noise in [0, 1]: each octave twice the frequency, half the amplitude."""
    total, norm = 0.0, 0.0
    for o in range(octaves):
        amp = 0.5 ** o
        total = total + amp * value_noise(res, base_cells * 2 ** o, rng)
        norm += amp
    return total / norm


def smoke(res: int = 48, seed: int = 5) -> np.ndarray:
    rng = np.random.default_rng(seed)
    c = (np.arange(res) + 0.5) / res                 # voxel centres in the unit cube
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    # puffs: (centre, radius) in the unit cube, a cumulus-like heap
    puffs = [((0.5, 0.52, 0.5), 0.27), ((0.29, 0.45, 0.46), 0.2), ((0.71, 0.46, 0.55), 0.2),
             ((0.45, 0.36, 0.66), 0.18), ((0.6, 0.66, 0.4), 0.19), ((0.38, 0.64, 0.42), 0.17),
             ((0.56, 0.33, 0.33), 0.16)]
    dist = np.full(x.shape, np.inf)
    for (cx, cy, cz), r in puffs:
        dist = np.minimum(dist, np.sqrt((x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2) / r)
    shape_noise = fbm(res, rng)
    detail = fbm(res, rng, octaves=3, base_cells=5)
    d = dist + 0.6 * (shape_noise - 0.5)            # displaced puff surfaces
    edge = np.clip((1.0 - d) / 0.35, 0, 1)          # soft edge, 1 deep inside
    density = edge ** 1.5 * (0.35 + 0.65 * detail)
    density[[0, -1], :, :] = density[:, [0, -1], :] = density[:, :, [0, -1]] = 0.0
    return (density / density.max()).astype(np.float32)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--res", type=int, default=48)
    p.add_argument("--seed", type=int, default=5)
    p.add_argument("-o", "--out", default=str(OUT))
    args = p.parse_args(argv)
    data = smoke(args.res, args.seed)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    write_vol(args.out, data)
    filled = (data > 0).mean()
    print(f"{args.out}: {args.res}^3 voxels, {filled:.0%} non-zero, mean density {data.mean():.3f}")


if __name__ == "__main__":
    main()
