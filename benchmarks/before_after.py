"""Two volcl source trees on every shipped scene: samples/s of each, and whether the images are
identical bit for bit.

    python benchmarks/before_after.py --before DIR [--after DIR] [--scenes scenes/*.xml]
        [--spp 16] [--size 128x96] [--rounds 3] [--device SELECTOR] [--save-images DIR]

DIR is the root of a volcl checkout (for an older commit: `git worktree add` or
`git archive COMMIT | tar -x -C DIR`); --after defaults to this checkout. One worker process per
tree imports volcl from that tree and keeps a Renderer per scene, so kernel builds and scene
loading happen once; the workers then render in turns, scene after scene and round after round,
so load from other processes on the machine falls on both alike. Each render: the scene at --size
(every shipped scene's camera is resized; the Nori ones too), seed 0, a reset Renderer, --spp
samples per pixel after one untimed 1-spp pass. Reported per scene and tree: the best of --rounds
in M samples/s of wall time and of process CPU time (the render's CPU seconds over all threads,
less disturbed by other processes than wall time), their after/before ratios, and whether the two
images are bit-identical (otherwise the count of differing pixels and the largest relative
difference of a pixel's mean). A render's image does not depend on timing, so the rounds agree.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

WORKER = r"""
import json, resource, sys, time
sys.path.insert(0, {root!r})
import numpy as np
from volcl import device as devmod
from volcl.scene import load
try:
    from volcl.renderer import Renderer
except ImportError:         # the renderer's module before it was renamed
    from volcl.render import Renderer

def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime

dev = devmod.choose({device!r})
renderers = {{}}
print("READY", flush=True)
for line in sys.stdin:
    job = json.loads(line)
    key = job["scene"]
    if key not in renderers:
        sc = load(key)
        sc.camera.width, sc.camera.height = job["width"], job["height"]
        renderers[key] = Renderer(sc, device=dev, seed=0)
        renderers[key].render(1)
    r = renderers[key]
    r.reset()
    c0, t0 = cpu(), time.perf_counter()
    res = r.render(job["spp"])
    wall, cpus = time.perf_counter() - t0, cpu() - c0
    np.save(job["image"], res.image)
    print("RESULT " + json.dumps({{"wall": wall, "cpu": cpus, "render": res.seconds,
                                   "samples": r.width * r.height * job["spp"], "invalid": res.invalid}}),
          flush=True)
"""


class Worker:
    def __init__(self, root, device):
        env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1")
        self.proc = subprocess.Popen([sys.executable, "-c", WORKER.format(root=str(root), device=device)],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env,
                                     cwd=str(root))
        self._expect("READY")

    def _expect(self, tag):
        while True:
            line = self.proc.stdout.readline()
            if not line:
                raise RuntimeError(f"worker died (exit {self.proc.wait()})")
            if line.startswith(tag):
                return line[len(tag):].strip()

    def render(self, **job):
        self.proc.stdin.write(json.dumps(job) + "\n")
        self.proc.stdin.flush()
        return json.loads(self._expect("RESULT "))

    def close(self):
        self.proc.stdin.close()
        self.proc.wait()


def compare(a, b):
    """'identical', or how far apart two images are."""
    if a.shape == b.shape and np.array_equal(a.view(np.uint32), b.view(np.uint32)):
        return "identical"
    diff = np.any(a != b, axis=-1)
    rel = np.abs(a.astype(np.float64) - b) / np.maximum(np.abs(b.astype(np.float64)), 1e-6)
    return f"{int(diff.sum())} px differ (max rel {rel.max():.2g})"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--before", required=True, type=Path)
    p.add_argument("--after", type=Path, default=ROOT)
    p.add_argument("--scenes", nargs="+", type=Path, default=sorted((ROOT / "scenes").glob("*.xml")))
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--size", default="128x96")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--device", default=None)
    p.add_argument("--save-images", type=Path, default=None, help="keep the images here (.npy)")
    args = p.parse_args(argv)
    width, height = (int(x) for x in args.size.lower().split("x"))
    out = args.save_images or Path(os.environ.get("TMPDIR", "/tmp")) / f"volcl-before-after-{os.getpid()}"
    out.mkdir(parents=True, exist_ok=True)

    trees = {"before": args.before.resolve(), "after": args.after.resolve()}
    workers = {k: Worker(v, args.device) for k, v in trees.items()}
    best = {}
    try:
        for rnd in range(args.rounds):
            for i, scene in enumerate(args.scenes):
                # alternate which tree goes first, so neither always follows the other's cache state
                order = list(trees) if (rnd + i) % 2 == 0 else list(trees)[::-1]
                for k in order:
                    img = out / f"{scene.stem}.{k}.npy"
                    print(f"round {rnd + 1}: {scene.name} {k} ...", file=sys.stderr, flush=True)
                    r = workers[k].render(scene=str(scene.resolve()), width=width, height=height,
                                          spp=args.spp, image=str(img))
                    b = best.setdefault((scene.name, k), {"wall": np.inf, "cpu": np.inf})
                    b["wall"], b["cpu"] = min(b["wall"], r["wall"]), min(b["cpu"], r["cpu"])
                    b["samples"], b["invalid"] = r["samples"], r["invalid"]
    finally:
        for w in workers.values():
            w.close()

    print(f"# volcl before / after: {width}x{height}, {args.spp} spp, best of {args.rounds} rounds\n")
    print(f"- before: {trees['before']}\n- after: {trees['after']}\n")
    print("| scene | before M samples/s (wall / CPU) | after M samples/s (wall / CPU) | after/before wall | "
          "after/before CPU | image |")
    print("|---|---|---|---|---|---|")
    for scene in args.scenes:
        b, a = best[(scene.name, "before")], best[(scene.name, "after")]
        rate = lambda r, k: r["samples"] / r[k] / 1e6      # noqa: E731
        same = compare(np.load(out / f"{scene.stem}.after.npy"), np.load(out / f"{scene.stem}.before.npy"))
        print(f"| {scene.name} | {rate(b, 'wall'):.3f} / {rate(b, 'cpu'):.3f} | {rate(a, 'wall'):.3f} / "
              f"{rate(a, 'cpu'):.3f} | {b['wall'] / a['wall']:.2f} | {b['cpu'] / a['cpu']:.2f} | {same} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
