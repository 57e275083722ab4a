"""Instancing (Mitsuba's shapegroup + instance) against the same scene flattened: device memory,
load and BVH build time, and render throughput.

    python benchmarks/instancing.py [--instances 256] [--triangles 10000] [--size 96x72] [--spp 16]
        [--rounds 3]

The scene: one bumpy-sphere mesh of about --triangles triangles (a PLY file), placed --instances
times on a grid, each instance with its own rotation and non-uniform scale, over a floor, lit by
an area light. "instanced": one <shape type="shapegroup"> and --instances <shape type="instance">
elements; "flattened": --instances <shape type="ply"> elements reading the same file with the same
to_world (meshes take any affine map, so both scenes hold the same surfaces). Both render with
seeds 7 and 8, path integrator, max_depth 3.

Prints, in Markdown: the machine; per variant the triangles stored on the device, the scene
buffers' bytes (Renderer.packed.arrays: BVH nodes, leaf packets, triangles, instance records, ...),
scene load (parse, mesh files) and Renderer set-up (packing, BVH build, kernel build from a warm
cache) seconds, and the best of --rounds renders (the variants interleaved in every round) as
wall seconds, process CPU seconds and samples per second; and how well the two images agree (the
largest |z| of their block-mean differences over the standard error both renders' variances give).
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))
from common import bumpy_sphere, cpu_model, log  # noqa: E402



def placements(n, rng):
    """n affine to_world matrices (4x4): a grid, each with a random rotation and non-uniform scale."""
    side = int(np.ceil(np.sqrt(n)))
    out = []
    for k in range(n):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        m = np.eye(4)
        m[:3, :3] = q @ np.diag(rng.uniform(0.25, 0.45, 3))
        m[:3, 3] = [(k % side - (side - 1) / 2) * 1.0, 0.0, (k // side - (side - 1) / 2) * 1.0]
        out.append(m)
    return out


def matrix(m):
    return '<transform name="to_world"><matrix value="' + " ".join(f"{v:.9g}" for v in m.ravel()) + '"/></transform>'


def scene_text(variant, mats, size, spp):
    w, h = size
    extent = 0.6 * int(np.ceil(np.sqrt(len(mats))))
    head = f'''<scene version="3.0.0">
<integrator type="path"><integer name="max_depth" value="3"/></integrator>
<sensor type="perspective"><float name="fov" value="50"/>
  <transform name="to_world"><lookat origin="0, {1.6 * extent}, {1.8 * extent}" target="0, 0, 0" up="0, 1, 0"/></transform>
  <film type="hdrfilm"><integer name="width" value="{w}"/><integer name="height" value="{h}"/><rfilter type="box"/></film>
  <sampler type="independent"><integer name="sample_count" value="{spp}"/></sampler></sensor>
<shape type="rectangle"><transform name="to_world"><scale value="{extent}"/><rotate x="1" angle="90"/>
  <translate y="{2 * extent}"/></transform><emitter type="area"><rgb name="radiance" value="4"/></emitter></shape>
<shape type="rectangle"><transform name="to_world"><scale value="{2 * extent}"/><rotate x="1" angle="-90"/>
  <translate y="-0.5"/></transform><bsdf type="diffuse"/></shape>
'''
    mesh = '<shape type="ply"><string name="filename" value="blob.ply"/><bsdf type="diffuse"><rgb name="reflectance" value="0.7, 0.4, 0.2"/></bsdf>'
    if variant == "instanced":
        body = f'<shape type="shapegroup" id="blob">{mesh}</shape></shape>\n' + "\n".join(
            f'<shape type="instance"><ref id="blob"/>{matrix(m)}</shape>' for m in mats)
    else:
        body = "\n".join(mesh + matrix(m) + "</shape>" for m in mats)
    return head + body + "\n</scene>\n"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--instances", type=int, default=256)
    p.add_argument("--triangles", type=int, default=10000)
    p.add_argument("--size", default="96x72")
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--rounds", type=int, default=3)
    a = p.parse_args(argv)
    size = tuple(int(v) for v in a.size.split("x"))
    import trimesh
    from volcl.renderer import Renderer
    from volcl.scene import load

    rng = np.random.default_rng(1)
    verts, faces = bumpy_sphere(rng, a.triangles)
    mats = placements(a.instances, rng)
    folder = Path(tempfile.mkdtemp(prefix="volcl_instancing_"))
    trimesh.Trimesh(verts, faces, process=False).export(folder / "blob.ply")
    variants = ("instanced", "flattened")
    rows, renderers = {}, {}
    for v in variants:
        path = folder / f"{v}.xml"
        path.write_text(scene_text(v, mats, size, a.spp))
        t0 = time.perf_counter()
        scene = load(path)
        t_load = time.perf_counter() - t0
        t0 = time.perf_counter()
        r = Renderer(scene, seed=7 if v == "instanced" else 8)     # independent images
        r.render(1)             # uploads, the first launch's compilation
        t_setup = time.perf_counter() - t0
        arrays = r.packed.arrays
        rows[v] = dict(tris=len(arrays["triangles"]), bytes=sum(x.nbytes for x in arrays.values()),
                       bvh=r.packed.bvh_seconds, load=t_load, setup=t_setup, wall=np.inf, cpu=np.inf)
        renderers[v] = r
        log(f"{v}: {rows[v]['tris']} triangles stored, {rows[v]['bytes'] / 2**20:.1f} MiB, load {t_load:.2f} s")
    results = {}
    for rnd in range(a.rounds):
        for v in variants:
            c0, t0 = time.process_time(), time.perf_counter()
            res = renderers[v].render(a.spp)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            rows[v]["wall"], rows[v]["cpu"] = min(rows[v]["wall"], wall), min(rows[v]["cpu"], cpu)
            results[v] = res
            log(f"round {rnd}: {v} {wall:.2f} s")
    samples = size[0] * size[1] * a.spp
    print(f"Machine: {cpu_model()}; device: {results['instanced'].device}")
    print(f"{a.instances} instances of a {len(faces)}-triangle mesh, {size[0]}x{size[1]}, {a.spp} spp, "
          f"best of {a.rounds} interleaved rounds\n")
    print("| variant | triangles stored | scene buffers MiB | load s | BVH build s | set-up s | render s | CPU s | samples/s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for v in variants:
        r = rows[v]
        print(f"| {v} | {r['tris']} | {r['bytes'] / 2**20:.1f} | {r['load']:.2f} | {r['bvh']:.2f} | {r['setup']:.2f} "
              f"| {r['wall']:.2f} | {r['cpu']:.2f} | {samples / r['wall']:.3g} |")
    ri, rf = rows["instanced"], rows["flattened"]
    print(f"\nflattened / instanced: memory {rf['bytes'] / ri['bytes']:.1f}x, BVH build {rf['bvh'] / max(ri['bvh'], 1e-9):.1f}x, "
          f"render CPU time {rf['cpu'] / ri['cpu']:.2f}x (above 1: instancing is faster)")
    ia, fa = results["instanced"], results["flattened"]
    diff = ia.image.astype(np.float64) - fa.image.astype(np.float64)
    var = ia.variance.astype(np.float64) + fa.variance.astype(np.float64)
    z = []
    for ys in np.array_split(np.arange(size[1]), 4):
        for xs in np.array_split(np.arange(size[0]), 4):
            d, vv = diff[np.ix_(ys, xs)].reshape(-1, 3), var[np.ix_(ys, xs)].reshape(-1, 3)
            z.append(np.abs(d.mean(0)) / np.maximum(np.sqrt(vv.sum(0)) / len(d), 1e-30))
    print(f"images (independent seeds): largest block |z| {np.max(z):.2f} over 48 block means")
    return 0


if __name__ == "__main__":
    sys.exit(main())
