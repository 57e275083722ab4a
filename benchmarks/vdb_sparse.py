"""Sparse bricks against the dense box: memory and samples/s on a cloud in a 512^3 bounding box.

    python benchmarks/vdb_sparse.py [--size 512] [--puff 96] [--spp 8] [--repeat 3] [--width 64]

Five copies of scenes/make_smoke.py's puff (--puff voxels a side) at the corners and the middle of a
--size^3 index box, in bricks of 8^3 as volcl reads them from a .vdb file, are rendered in a constant environment (albedo 0.9, HG g = 0.3) twice: as the sparse grid (brick
index, stored bricks, one majorant a brick) and as the dense grid of the same padded box (volcl's
default majorant grid, at most 64 cells per axis). Printed per variant: the bytes of the grid_data
buffer (voxels and majorants), bytes per active voxel, packing seconds, the best of --repeat renders
(the repeats interleave the two variants, after a 1-spp warm-up each) in seconds and M samples/s,
and the two images' difference in standard errors (both estimate the same image). Needs memory for
the dense box (4 bytes a voxel and its copies while packing: about 2 GB at 512).
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scenes"))
sys.path.insert(0, str(ROOT / "tests"))      # scenebuild
from common import cpu_model, log  # noqa: E402



def make_grid(size: int, puff: int):
    """Copies of the puff at the corners and the middle of a size^3 index box, cut into bricks as
    the file reader cuts them (vdb.from_dense; tests/test_sparse_grids.py checks the two agree)."""
    from make_smoke import smoke
    from volcl import vdb
    a = smoke(puff, seed=5)
    far = size - puff
    spots = [(0, 0, 0), (far, far, far), (0, far, far // 2), (far, 0, far // 3), (far // 2, far // 2, far)]
    sg = vdb.merge_bricks([vdb.from_dense(a, ijk=ijk) for ijk in spots])
    sg.path = f"({len(spots)} puffs)"
    return sg


def scene_of(volume, width, seed):
    from scenebuild import camera, constant_env, hetero_medium, look_at, scene, sphere
    from volcl.scene.model import Bsdf
    med = hetero_medium(volume, 0.9, g=0.3, scale=40.0)
    ball = sphere((0, 0, 0), 0.9, Bsdf("null"), interior=med)
    cam = camera(width, width, fov=40, to_world=look_at((0.4, 0.6, 3.2), (0, 0, 0)))
    return scene([ball], [constant_env(1.0)], cam=cam, seed=seed)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--size", type=int, default=512)
    p.add_argument("--puff", type=int, default=96)
    p.add_argument("--spp", type=int, default=8)
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--width", type=int, default=64)
    args = p.parse_args(argv)
    from volcl import device as devmod
    from volcl.prepared import Scene as PreparedScene
    from volcl.renderer import Renderer
    from volcl.scene.model import Volume, rgb
    sg = make_grid(args.size, args.puff)
    n = sg.padded_counts() * 8
    # the unit cube (the padded box) onto [-0.5, 0.5]^3 of the world, voxels cubic
    to_world = np.diag(list(n / n.max()) + [1.0])
    to_world[:3, 3] = -0.5 * n / n.max()
    sparse = Volume("sparse", value=rgb(0.0), to_world=to_world, sparse=sg, grid_name="density")
    log(f"{sg.active_voxels} active voxels in {len(sg.coords)} bricks; box {n[0]}x{n[1]}x{n[2]}")
    device = devmod.choose()
    variants = {}
    for name in ("sparse", "dense"):
        t0 = time.perf_counter()
        vol = sparse if name == "sparse" else Volume("grid", value=rgb(0.0), data=sg.dense(), to_world=to_world)
        prepared = PreparedScene(scene_of(vol, args.width, seed=1))
        grid_bytes = prepared.buffer_sizes()["grid_data"]
        pack_s = time.perf_counter() - t0
        r = Renderer(prepared, device=device, seed=11 if name == "sparse" else 12)
        r.render(1)
        variants[name] = dict(renderer=r, bytes=grid_bytes, pack=pack_s, best=math.inf, result=None)
        log(f"{name}: packed in {pack_s:.1f} s, grid_data {grid_bytes / 2**20:.1f} MiB")
    for _ in range(args.repeat):
        for v in variants.values():
            t0 = time.perf_counter()
            v["result"] = v["renderer"].render(args.spp)
            v["best"] = min(v["best"], time.perf_counter() - t0)
    samples = args.width * args.width * args.spp
    print(f"# {args.size}^3-bounded sparse cloud: {sg.active_voxels} active voxels "
          f"({sg.active_voxels / np.prod(n):.2%} of the {n[0]}x{n[1]}x{n[2]} padded box), {len(sg.coords)} stored bricks; "
          f"{args.width}x{args.width} at {args.spp} spp, best of {args.repeat}; {cpu_model()}")
    print(f"{'layout':8} {'grid_data MiB':>13} {'B/active voxel':>15} {'pack s':>7} {'render s':>9} {'M samples/s':>12}")
    for name, v in variants.items():
        print(f"{name:8} {v['bytes'] / 2**20:13.1f} {v['bytes'] / sg.active_voxels:15.2f} {v['pack']:7.1f} "
              f"{v['best']:9.2f} {samples / v['best'] / 1e6:12.3f}")
    a, b = variants["sparse"]["result"], variants["dense"]["result"]
    diff = (a.image.astype(np.float64) - b.image).mean(axis=(0, 1))
    se = np.sqrt((a.variance.astype(np.float64) + b.variance).sum(axis=(0, 1))) / (a.image.shape[0] * a.image.shape[1])
    print(f"memory dense / sparse: {variants['dense']['bytes'] / variants['sparse']['bytes']:.1f}x; "
          f"speed sparse / dense: {variants['dense']['best'] / variants['sparse']['best']:.2f}x; "
          f"image mean {a.image.mean():.4f} (the environment alone: 1); "
          f"difference (sparse - dense) / standard error per channel: "
          + " ".join(f"{z:+.2f}" for z in diff / se))


if __name__ == "__main__":
    main()
