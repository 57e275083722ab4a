"""Rendering on a Dask cluster (volcl.cluster): samples/s on one and on two single-threaded worker
processes of this machine, and what each task costs beyond its rendering.

    python benchmarks/cluster_scaling.py [--scene scenes/fog.xml] [--size 128x96] [--spp 128] [--repeat 2]

Both clusters (distributed.LocalCluster as `--scheduler local:N` starts it, one thread per worker,
POCL_MAX_PTHREAD_COUNT=1 so that a worker is one core) are started first and kept. Two schedules
are compared: "streamed" (volcl's: a tile's next round is submitted as soon as its last one
returns) and "barrier" (lookahead 1: each round starts once the one before has ended everywhere,
as volcl did before). The renders of every variant are interleaved, each variant after a warm-up
render, and the best of the repeats is quoted. Every cluster image is checked bit for bit against
a local render.

Figures: wall seconds and samples/s; CPU seconds of the workers (each worker process's
time.process_time, its communication threads included) and of this process (the client, and
the LocalCluster's scheduler, which runs in it); the overhead per task, the workers' time not
spent in a task's rendering (restoring, rendering and reading back its tile, as timed on the
worker): (wall seconds x workers - sum of task seconds) / tasks, which includes the time a worker
waits for a task; and the same for tiles of 64, 32 and 16 pixels with 2 workers.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

SCHEDULES = {"streamed": 2, "barrier": 1}       # lookahead (volcl.cluster.LOOKAHEAD is the streamed one)


def measure(scene, client, spp, lookahead, tile_size=None):
    from volcl import cluster
    from volcl.rounds import TiledRender
    ex = cluster.DaskExecutor(client)
    ex.lookahead = lookahead
    r = TiledRender(scene, ex, seed=1, tile_size=tile_size, round_seconds=cluster.CLUSTER_ROUND_SECONDS)
    tasks = {"n": 0, "seconds": 0.0}

    def on_tile(job):
        tasks["n"] += 1
        tasks["seconds"] += job.seconds
    r.on_tile = on_tile
    workers0 = client.run(time.process_time)
    cpu0, t0 = time.process_time(), time.perf_counter()
    result = r.render(spp)
    wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    workers1 = client.run(time.process_time)
    ex.close()
    n = len(workers1)
    return {"result": result, "wall": wall, "client_cpu": cpu,
            "worker_cpu": sum(workers1[w] - workers0.get(w, 0.0) for w in workers1),
            "overhead": (wall * n - tasks["seconds"]) / max(tasks["n"], 1),
            "tasks": tasks["n"], "rounds": r.rounds,
            "rate": result.image.size // 3 * result.spp / wall}


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scene", type=Path, default=ROOT / "scenes" / "fog.xml")
    p.add_argument("--size", default="128x96")
    p.add_argument("--spp", type=int, default=128)
    p.add_argument("--repeat", type=int, default=2)
    args = p.parse_args()
    os.environ["POCL_MAX_PTHREAD_COUNT"] = "1"      # before PoCL loads here and in the workers
    import logging
    logging.getLogger("distributed").setLevel(logging.WARNING)
    import volcl
    from volcl import cluster
    w, h = (int(v) for v in args.size.split("x"))
    scene = volcl.load_file(args.scene, width=w, height=h)
    local = volcl.render(scene, spp=args.spp, seed=1)
    clients = {n: cluster.connect(f"local:{n}") for n in (1, 2)}
    threads = {n: set(c.run(lambda: os.environ.get("POCL_MAX_PTHREAD_COUNT")).values()) for n, c in clients.items()}
    variants = [(n, s) for s in SCHEDULES for n in clients]
    for n, c in clients.items():
        c.wait_for_workers(n)
        measure(scene, c, 1, SCHEDULES["streamed"])    # kernels built, scene shipped

    def check(m):
        assert m["result"].image.tobytes() == local.image.tobytes(), "cluster image differs from the local one"
        return m
    best = {}
    for _ in range(args.repeat):
        for n, s in variants:
            m = check(measure(scene, clients[n], args.spp, SCHEDULES[s]))
            if (n, s) not in best or m["rate"] > best[n, s]["rate"]:
                best[n, s] = m
    print(f"{args.scene.name}, {args.size}, {args.spp} spp, best of {args.repeat} (interleaved); "
          f"{os.cpu_count()} CPU cores, load average {os.getloadavg()[0]:.1f} at the end; workers' "
          f"POCL_MAX_PTHREAD_COUNT {threads}\n")
    print("| schedule | workers | M samples/s | vs 1 worker | wall s | workers' CPU s | client CPU s | "
          "M samples per worker CPU s | tasks | rounds | overhead per task |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for n, s in variants:
        m = best[n, s]
        print(f"| {s} | {n} | {m['rate'] / 1e6:.3f} | {m['rate'] / best[1, s]['rate']:.2f}x | {m['wall']:.2f} | "
              f"{m['worker_cpu']:.2f} | {m['client_cpu']:.2f} | "
              f"{m['result'].image.size // 3 * args.spp / m['worker_cpu'] / 1e6:.3f} | {m['tasks']} | "
              f"{m['rounds']} | {1e3 * m['overhead']:.1f} ms |")
    print("\noverhead per task against tile size (2 workers, one render each, interleaved):\n")
    print("| tile size | schedule | tasks | overhead per task | M samples/s |")
    print("|---:|---|---:|---:|---:|")
    for size in (64, 32, 16):
        measure(scene, clients[2], 1, SCHEDULES["streamed"], tile_size=size)     # the tiles' renderers made
        for s in SCHEDULES:
            m = check(measure(scene, clients[2], args.spp, SCHEDULES[s], tile_size=size))
            print(f"| {size} | {s} | {m['tasks']} | {1e3 * m['overhead']:.1f} ms | {m['rate'] / 1e6:.3f} |")
    for c in clients.values():
        cluster.close(c)


if __name__ == "__main__":
    main()
