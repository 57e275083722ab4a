"""Benchmark of volcl.bvh.build_bvh on seeded triangle soups of several sizes.

Each soup is a tessellated bumpy sphere (about 70 % of the triangles, with sliver triangles at the
poles) plus small random triangles scattered in a shell around it. Prints machine info, then one
table row per size: binary build time (best of --repeat runs), SAH cost, node count, node memory
per triangle, maximum depth and average leaf size; then the device's wide BVH collapsed from it
(volcl.bvh_wide): collapse time, wide nodes, children per node, the deepest traversal stack, and
bytes per triangle of the wide nodes and of the leaf packets.

    python benchmarks/bvh_build.py [--sizes 100000 1000000] [--repeat 3] [--max-leaf 4] [--bins 16]
"""
import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from volcl.bvh import build_bvh, node_depths, sah_cost  # noqa: E402
from volcl.bvh_wide import collapse, pack_leaves, stack_need, used_slots  # noqa: E402
from common import bumpy_sphere, cpu_model  # noqa: E402



def scattered(rng, n_tris):
    """Small random triangles in a shell of radius 1.2 to 3 around the sphere."""
    direction = rng.standard_normal((n_tris, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    centre = direction * rng.uniform(1.2, 3.0, (n_tris, 1))
    return centre[:, None, :] + 0.01 * rng.standard_normal((n_tris, 3, 3))


def triangle_soup(n, seed=0):
    rng = np.random.default_rng(seed)
    verts, faces = bumpy_sphere(rng, int(0.7 * n))
    sphere = verts[faces][:n]
    tris = np.concatenate([sphere, scattered(rng, n - len(sphere))])
    return tris[rng.permutation(n)]  # input order carries no spatial coherence


def measure(n, repeat, max_leaf, bins):
    tris = triangle_soup(n)
    lo, hi = tris.min(axis=1), tris.max(axis=1)
    best = np.inf
    for _ in range(repeat):
        start = time.perf_counter()
        nodes, order = build_bvh(lo, hi, max_leaf=max_leaf, bins=bins)
        best = min(best, time.perf_counter() - start)
    leaves = nodes["count"] > 0
    best_c = np.inf
    for _ in range(repeat):
        start = time.perf_counter()
        wide = collapse(nodes)
        best_c = min(best_c, time.perf_counter() - start)
    wide, packets = pack_leaves(wide, np.arange(n, dtype=np.int32)[order], tris, np.ones(n, bool))
    used = used_slots(wide)
    return {
        "collapse s": best_c, "wide nodes": len(wide), "children": used.sum() / len(wide),
        "stack": stack_need(wide), "wide B/tri": wide.nbytes / n, "packet B/tri": packets.nbytes / n,
        "triangles": n,
        "build s": best,
        "SAH cost": sah_cost(nodes),
        "nodes": len(nodes),
        "B/tri": nodes.nbytes / n,
        "max depth": int(node_depths(nodes).max()),
        "avg leaf": n / np.count_nonzero(leaves),
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[100_000, 1_000_000])
    parser.add_argument("--repeat", type=int, default=3, help="runs per size; the best is kept")
    parser.add_argument("--max-leaf", type=int, default=4)
    parser.add_argument("--bins", type=int, default=16)
    args = parser.parse_args()

    print(f"cpu: {cpu_model()}, {os.cpu_count()} logical cores")
    print(f"python {platform.python_version()}, numpy {np.__version__}, "
          f"max_leaf {args.max_leaf}, bins {args.bins}, best of {args.repeat}")
    header = f"{'triangles':>10} {'build s':>8} {'SAH cost':>9} {'nodes':>9} {'B/tri':>6} " \
             f"{'max depth':>9} {'avg leaf':>8}"
    print(header)
    print("-" * len(header))
    wide = []
    for n in args.sizes:
        r = measure(n, args.repeat, args.max_leaf, args.bins)
        print(f"{r['triangles']:>10} {r['build s']:>8.3f} {r['SAH cost']:>9.2f} {r['nodes']:>9} "
              f"{r['B/tri']:>6.1f} {r['max depth']:>9} {r['avg leaf']:>8.2f}", flush=True)
        wide.append(r)
    header = f"{'triangles':>10} {'collapse s':>10} {'wide nodes':>10} {'children':>8} {'stack':>5} " \
             f"{'node B/tri':>10} {'packet B/tri':>12}"
    print()
    print(header)
    print("-" * len(header))
    for r in wide:
        print(f"{r['triangles']:>10} {r['collapse s']:>10.3f} {r['wide nodes']:>10} {r['children']:>8.2f} "
              f"{r['stack']:>5} {r['wide B/tri']:>10.1f} {r['packet B/tri']:>12.1f}")


if __name__ == "__main__":
    main()
