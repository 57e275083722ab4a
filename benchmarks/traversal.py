"""Ray traversal of volcl's device BVH against Embree, on the same rays over the same triangles.

    python benchmarks/traversal.py [--rays 1000000] [--repeat 5] [--scenes cbox 100k 1m]
        [--device SELECTOR] [--threads-note]

Scenes: the Nori Cornell box (../shared/nori/cbox/cbox_path_mis.xml: its spheres are meshes, so
both tracers see only triangles), and a bumpy sphere of about 100k and 1M triangles on a floor
(benchmarks/common.py bumpy_sphere, the same mesh as render_throughput.py's memory table).

Rays, made once per scene in numpy and given to both tracers as the same float32 arrays:
* camera: one jittered ray per pixel of the scene's camera at about --rays pixels (coherent);
* bounce: from each camera ray's hit point (Embree's hit), offset off the surface as volcl offsets
  origins (1e-5 of the hit triangle's coordinate magnitude), in a cosine-distributed direction
  about the geometric normal facing the camera ray (incoherent, like diffuse path segments).

Queries: closest hit (volcl `bvh_trace`, Embree `rtcIntersect1` through embreex's
EmbreeScene.run(query='DISTANCE')) and any hit (volcl `bvh_trace(any_hit)`, Embree
`rtcOccluded1`, query='OCCLUDED') with unbounded rays. volcl runs benchmarks/kernels/trace.cl on its
OpenCL device (all cores; the rays are uploaded beforehand and only the kernel is timed, from
enqueue to finish); embreex runs Embree on the calling thread, one ray after the other. Each figure
is the best of --repeat runs, the two tracers' runs interleaved so load from other processes hits
both alike. "agree" is the share of rays on which both report the same hit or miss and, for
closest hits, the same distance to 1e-4 relative. "M rays/s" counts wall time: volcl on all the
device's cores, Embree on one. "M rays/CPU s" divides by the CPU seconds the process spent (all
its threads): the rate per busy core, which other processes on the machine disturb less, and the
fair comparison of the two traversals' code.

Embree is a benchmark-only dependency (`pip install embreex`); without it its columns are skipped.
"""
from __future__ import annotations

import argparse
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))
from common import bumpy_sphere, cpu_model, log  # noqa: E402

NORI_CBOX = ROOT.parent / "shared" / "nori" / "cbox" / "cbox_path_mis.xml"
KERNEL = HERE / "kernels" / "trace.cl"


def cpu_seconds():
    """CPU time of this process, all threads (the OpenCL driver's worker threads included)."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime



# ------------------------------------------------------------------------------------ scenes

def mesh_scene(n_triangles, seed=0):
    """The bumpy sphere on a floor under a quad light, as a volcl Scene (render_throughput.py)."""
    from volcl.scene.model import Bsdf, Camera, Scene, Shape
    from volcl.scene.transform import lookat
    z_up, faces = bumpy_sphere(np.random.default_rng(seed), n_triangles)
    verts = z_up[:, [0, 2, 1]] + np.array([0.0, 1.0, 0.0])
    quad = np.array([[0, 1, 2], [0, 2, 3]])
    floor = np.array([[-5, 0, -5], [5, 0, -5], [5, 0, 5], [-5, 0, 5]], float)
    light = np.array([[-1, 4, -1], [-1, 4, 1], [1, 4, 1], [1, 4, -1]], float)
    shapes = [Shape("mesh", Bsdf("diffuse"), vertices=verts, faces=faces.astype(np.int64)),
              Shape("mesh", Bsdf("diffuse"), vertices=floor, faces=quad),
              Shape("mesh", Bsdf("diffuse"), vertices=light, faces=quad, emitter_radiance=np.full(3, 10.0))]
    cam = Camera(to_world=lookat([0, 2, -6], [0, 1, 0], [0, 1, 0]), fov=40, width=256, height=256)
    return Scene(path=f"<bumpy sphere, {n_triangles} triangles>", dialect="mitsuba", camera=cam, spp=1,
                 shapes=shapes)


def load_scene(name):
    from volcl.scene import load
    if name == "cbox":
        return "Nori cbox", load(NORI_CBOX)
    n = {"100k": 100_000, "1m": 1_000_000}[name.lower()]
    return f"bumpy sphere {n // 1000}k", mesh_scene(n)


def camera_rays(scene, n_rays, rng):
    """One jittered pinhole ray per pixel of a grid with the camera's aspect and about n_rays pixels."""
    from volcl.pack import camera_tangents
    cam = scene.camera
    aspect = cam.width / cam.height
    h = max(1, int(round(np.sqrt(n_rays / aspect))))
    w = max(1, int(round(h * aspect)))
    tx, ty = camera_tangents(cam)
    py, px = np.mgrid[0:h, 0:w]
    sx = (px.ravel() + rng.random(w * h)) / w
    sy = (py.ravel() + rng.random(w * h)) / h
    dc = np.stack([(1 - 2 * sx) * tx, (1 - 2 * sy) * ty, np.ones(w * h)], 1)
    m = np.asarray(cam.to_world, np.float64)
    d = dc @ m[:3, :3].T
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.broadcast_to(m[:3, 3], d.shape)
    return np.ascontiguousarray(o, np.float32), np.ascontiguousarray(d, np.float32)


def bounce_rays(tris, o, d, t, prim, rng):
    """Cosine-distributed rays leaving the closest hits (t finite) of rays o + t d."""
    hit = np.isfinite(t)
    o, d, t, prim = o[hit].astype(np.float64), d[hit].astype(np.float64), t[hit], prim[hit]
    tri = tris[prim].astype(np.float64)
    p = o + t[:, None] * d
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    n *= -np.sign(np.einsum("ij,ij->i", n, d))[:, None]
    # cosine-weighted hemisphere about n
    u1, u2 = rng.random(len(p)), rng.random(len(p))
    r, phi = np.sqrt(u1), 2 * np.pi * u2
    a = np.where(np.abs(n[:, :1]) > 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    s = np.cross(n, a)
    s /= np.linalg.norm(s, axis=1, keepdims=True)
    b = np.cross(n, s)
    dirs = (r * np.cos(phi))[:, None] * s + (r * np.sin(phi))[:, None] * b + np.sqrt(1 - u1)[:, None] * n
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    mag = np.abs(tri).max(axis=(1, 2))
    origin = p + (1e-5 * mag)[:, None] * n
    return np.ascontiguousarray(origin, np.float32), np.ascontiguousarray(dirs, np.float32)


# ------------------------------------------------------------------------------------ tracers

class Volcl:
    def __init__(self, scene, device):
        from volcl.device import cl
        from volcl.features import all_features
        from volcl.pack import pack
        from volcl.program import build_program
        self.cl = cl
        self.packed = pack(scene)
        a = self.packed.arrays
        self.ctx = cl.Context([device.device])
        self.queue = cl.CommandQueue(self.ctx)
        feats = dict(all_features(), spheres=self.packed.sphere_count > 0)
        self.program = build_program(self.ctx, feats, KERNEL)
        mf = cl.mem_flags
        self.scene_bufs = [cl.Buffer(self.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(a[k]))
                           for k in ("nodes", "leaves", "triangles", "spheres")]
        self.closest = cl.Kernel(self.program, "trace_closest")
        self.any = cl.Kernel(self.program, "trace_any")

    def triangles(self):
        t = self.packed.arrays["triangles"][:self.packed.triangle_count]
        return np.stack([t["p0"], t["p1"], t["p2"]], 1)

    def upload(self, o, d):
        cl, mf = self.cl, self.cl.mem_flags
        n = len(o)
        bufs = {"n": n,
                "o": cl.Buffer(self.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=o),
                "d": cl.Buffer(self.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=d),
                "tmax": cl.Buffer(self.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR,
                                  hostbuf=np.full(n, np.inf, np.float32)),
                "t": cl.Buffer(self.ctx, mf.WRITE_ONLY, 4 * n),
                "prim": cl.Buffer(self.ctx, mf.WRITE_ONLY, 4 * n),
                "occ": cl.Buffer(self.ctx, mf.WRITE_ONLY, 4 * n)}
        return bufs

    def run(self, bufs, query):
        n = bufs["n"]
        if query == "closest":
            args = (bufs["o"], bufs["d"], bufs["t"], bufs["prim"])
            kernel = self.closest
        else:
            args = (bufs["o"], bufs["d"], bufs["tmax"], bufs["occ"])
            kernel = self.any
        self.queue.finish()
        c0, t0 = cpu_seconds(), time.perf_counter()
        kernel(self.queue, (n,), None, *self.scene_bufs, *args, np.int32(n))
        self.queue.finish()
        return time.perf_counter() - t0, cpu_seconds() - c0

    def results(self, bufs, query):
        n = bufs["n"]
        if query == "closest":
            t, prim = np.empty(n, np.float32), np.empty(n, np.int32)
            self.cl.enqueue_copy(self.queue, t, bufs["t"])
            self.cl.enqueue_copy(self.queue, prim, bufs["prim"])
            self.queue.finish()
            return t, prim
        occ = np.empty(n, np.int32)
        self.cl.enqueue_copy(self.queue, occ, bufs["occ"])
        self.queue.finish()
        return occ.astype(bool)


class Embree:
    def __init__(self, tris):
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh
        self.scene = rtcore_scene.EmbreeScene()
        self.mesh = TriangleMesh(self.scene, np.ascontiguousarray(tris, np.float32))

    def run(self, o, d, query):
        c0, t0 = cpu_seconds(), time.perf_counter()
        out = self.scene.run(o, d, query="DISTANCE" if query == "closest" else "OCCLUDED")
        return (time.perf_counter() - t0, cpu_seconds() - c0), out

    def closest(self, o, d):
        res = self.scene.run(o, d, output=1)
        t = np.where(res["geomID"] >= 0, res["tfar"], np.inf).astype(np.float32)
        # embreex reports misses with geomID -1 (RTC_INVALID_GEOMETRY_ID as int32)
        return t, res["primID"].astype(np.int64)


def have_embree():
    try:
        import embreex  # noqa: F401
        return True
    except ImportError:
        return False


# ------------------------------------------------------------------------------------ main

def table(header, rows):
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    return "\n".join(out + ["| " + " | ".join(str(c) for c in r) + " |" for r in rows])


def agreement(query, v, e):
    if query == "any":
        return float(np.mean(v == (np.asarray(e) != -1)))     # embreex: -1 = not occluded
    tv, te = v[0], np.asarray(e, np.float32)
    hv, he = np.isfinite(tv), np.isfinite(te) & (te < 1e30)
    same = hv == he
    both = hv & he
    close = np.ones_like(same)
    close[both] = np.abs(tv[both] - te[both]) <= 1e-4 * np.maximum(te[both], 1e-3)
    return float(np.mean(same & close))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rays", type=int, default=1_000_000, help="camera rays per scene (about)")
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--scenes", nargs="+", default=["cbox", "100k", "1m"])
    p.add_argument("--device", help="volcl device selector")
    p.add_argument("--seed", type=int, default=1)
    args = p.parse_args(argv)

    from volcl import device as devmod
    device = devmod.choose(args.device)
    embree = have_embree()
    print("# Ray traversal: volcl against Embree\n")
    print(f"- CPU: {cpu_model()}, {os.cpu_count()} cores; load average at start "
          f"{' '.join(Path('/proc/loadavg').read_text().split()[:3])}")
    print(f"- volcl device: {device.name} ({device.platform_name}, {device.device.max_compute_units} compute units)")
    if embree:
        import embreex
        print(f"- Embree via embreex {getattr(embreex, '__version__', '?')}, one thread (the caller's)")
    else:
        print("- embreex not installed: Embree columns skipped (pip install embreex)")
    print(f"- best of {args.repeat}, interleaved\n")

    rows = []
    rng = np.random.default_rng(args.seed)
    for name in args.scenes:
        label, scene = load_scene(name)
        log(f"{label}: packing and building ...")
        v = Volcl(scene, device)
        tris = v.triangles()
        e = Embree(tris) if embree else None
        o, d = camera_rays(scene, args.rays, rng)
        if e is not None:
            t_hit, prim = e.closest(o, d)
        else:
            v_bufs = v.upload(o, d)
            v.run(v_bufs, "closest")
            t_hit, prim = v.results(v_bufs, "closest")
        bo, bd = bounce_rays(tris, o, d, t_hit, prim, rng)
        for kind, (ro, rd) in (("camera", (o, d)), ("bounce", (bo, bd))):
            bufs = v.upload(ro, rd)
            for query in ("closest", "any"):
                log(f"{label}: {kind} rays, {query} hit ...")
                v.run(bufs, query)              # first launch: PoCL finishes compiling here
                best_v = best_e = np.array([np.inf, np.inf])
                e_out = None
                for _ in range(args.repeat):
                    best_v = np.minimum(best_v, v.run(bufs, query))
                    if e is not None:
                        secs, e_out = e.run(ro, rd, query)
                        best_e = np.minimum(best_e, secs)
                n = len(ro)
                v_rate = n / best_v / 1e6
                row = [label, f"{len(tris):,}", kind, query, f"{n:,}", f"{v_rate[0]:.2f}"]
                if e is not None:
                    e_rate = n / best_e / 1e6
                    agree = agreement(query, v.results(bufs, query), e_out)
                    row += [f"{e_rate[0]:.2f}", f"{v_rate[0] / e_rate[0]:.2f}", f"{v_rate[1]:.2f}",
                            f"{e_rate[1]:.2f}", f"{v_rate[1] / e_rate[1]:.2f}", f"{100 * agree:.3f}%"]
                else:
                    row += ["–", "–", f"{v_rate[1]:.2f}", "–", "–", "–"]
                rows.append(row)
    print(table(["scene", "triangles", "rays", "query", "count", "volcl M rays/s", "Embree M rays/s",
                 "volcl / Embree", "volcl M rays/CPU s", "Embree M rays/CPU s", "volcl / Embree per CPU s",
                 "agree"], rows))
    print(f"\nload average at end: {' '.join(Path('/proc/loadavg').read_text().split()[:3])}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
