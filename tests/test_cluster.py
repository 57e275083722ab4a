"""Rendering on a Dask cluster (volcl.cluster), with distributed.LocalCluster worker processes: the bits
of a local render, a worker killed mid-render, a batch of scenes and a sweep with their outputs named,
scenes whose files only the client has, checkpoints between the cluster and one device."""
import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

if os.environ.get("CI"):
    import distributed      # ./quickstart test installs it: in CI its absence is a failure, not a skip
else:
    distributed = pytest.importorskip("distributed")

import volcl  # noqa: E402
from volcl import batch, cluster  # noqa: E402
from volcl.image import read_image  # noqa: E402
from volcl.options import OutputOptions, RenderOptions, SceneOptions  # noqa: E402
from volcl.renderer import Renderer  # noqa: E402
from volcl.rounds import TiledRender  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "scenes"
SIZE = {"width": 37, "height": 23}


def same(a, b):
    return (a.spp == b.spp and a.invalid == b.invalid and a.image.tobytes() == b.image.tobytes()
            and a.variance.tobytes() == b.variance.tobytes())


@pytest.fixture(scope="module")
def client():
    """Two single-threaded worker processes, as `--scheduler local:2` starts them."""
    c = cluster.connect("local:2")
    c.wait_for_workers(2, timeout=120)
    yield c
    cluster.close(c)


def on_cluster(scene, client, seed, round_seconds=0.0):
    """A TiledRender on the cluster with rounds as short as can be (after the first, one sample)."""
    return TiledRender(scene, cluster.DaskExecutor(client), seed=seed, round_seconds=round_seconds)


def test_a_cluster_render_has_the_bits_of_a_local_one(client, device):
    scene = volcl.load_file(SCENES / "fog.xml", **SIZE)
    local = volcl.render(scene, spp=30, seed=6, device=device)
    remote = volcl.render(scene, spp=30, seed=6, scheduler=client)
    assert same(local, remote) and remote.complete
    workers = set(client.scheduler_info()["workers"])
    assert {label.split()[0] for label in remote.shares} <= workers
    assert abs(sum(remote.shares.values()) - 1) < 1e-12
    assert all(w in remote.metadata["device"] for w in {label.split()[0] for label in remote.shares})
    timed = on_cluster(scene, client, seed=6, round_seconds=0.1).render(time_limit=0.5)   # no spp: until the time
    assert timed.stop_reason == "time" and timed.spp > 0
    assert same(timed, volcl.render(scene, spp=timed.spp, seed=6, device=device))


def test_local_workers_render_on_their_share_of_the_cores(client):
    """local:2: each worker process's PoCL device runs on cores / 2 threads (one on 2 cores), not a
    thread per core in each; a POCL_MAX_PTHREAD_COUNT of the user's wins."""
    def pocl_threads():
        import pyopencl as cl
        units = [d.max_compute_units for p in cl.get_platforms() if "Portable" in p.name for d in p.get_devices()]
        return os.environ.get("POCL_MAX_PTHREAD_COUNT"), units
    want = os.environ.get("POCL_MAX_PTHREAD_COUNT") or str(max(1, os.cpu_count() // 2))
    seen = client.run(pocl_threads)
    assert len(seen) == 2
    for threads, units in seen.values():
        assert threads == want and all(u == int(want) for u in units), seen


def test_local_workers_run_dask_quietly(client):
    """local:N workers (and `volcl worker`, through the environment) start with Dask's periodic
    work slowed or off (cluster.QUIET_DASK): it took CPU the renders needed."""
    import dask

    def config():
        import dask
        return {key: dask.config.get(key) for key in cluster.QUIET_DASK}
    for seen in client.run(config).values():
        assert seen == cluster.QUIET_DASK, seen
    env = cluster.quiet_dask_env({"DASK_DISTRIBUTED__ADMIN__TICK__INTERVAL": "200ms"})
    assert env["DASK_DISTRIBUTED__ADMIN__TICK__INTERVAL"] == "200ms"       # the user's own setting wins
    parsed = dask.config.collect_env(env)
    assert parsed["distributed"]["worker"]["profile"]["enabled"] is False
    assert parsed["distributed"]["worker"]["memory"]["monitor_interval"] == "1s"
    assert parsed["distributed"]["admin"]["system_monitor"]["interval"] == "2s"


def test_checkpoints_pass_between_the_cluster_and_one_device(client, device):
    scene = volcl.load_file(SCENES / "cbox.xml", **SIZE)
    whole = volcl.render(scene, spp=40, seed=2, device=device)
    r = on_cluster(scene, client, seed=2)
    part = r.render(40, stop=lambda: True)          # Ctrl-C: stopped after the first round
    assert part.stop_reason == "stopped" and 0 < part.spp < 40
    assert same(part, volcl.render(scene, spp=part.spp, seed=2, device=device))
    single = Renderer(scene, device=device, seed=2)
    single.restore({k: np.copy(v) if isinstance(v, np.ndarray) else v for k, v in r.state().items()})
    assert same(single.render(40 - part.spp), whole)
    first = Renderer(scene, device=device, seed=2)
    first.render(11)
    resumed = on_cluster(scene, client, seed=2)
    resumed.restore(first.state())
    assert same(resumed.render(29), whole)


def test_a_worker_killed_mid_render_loses_nothing(client, device):
    """SIGKILL to one worker process while a round's tasks run: Dask runs them again elsewhere and
    the image is the local one, bit for bit."""
    scene = volcl.load_file(SCENES / "fog.xml", **SIZE)
    local = volcl.render(scene, spp=60, seed=4, device=device)
    pids = client.run(os.getpid)
    victim = sorted(pids)[0]
    r = on_cluster(scene, client, seed=4)
    seen = {"tiles": 0, "killed": False}

    def tile_done(job):
        seen["tiles"] += 1
        if seen["tiles"] == len(r.tile_list) + 3 and not seen["killed"]:     # in the second round
            os.kill(pids[victim], signal.SIGKILL)
            seen["killed"] = True
    r.on_tile = tile_done
    try:
        result = r.render(60)
    finally:
        client.wait_for_workers(2, timeout=120)     # the nanny brings the worker back
    assert seen["killed"] and same(result, local)


def test_every_worker_killed_mid_render_loses_nothing(client, device):
    """SIGKILL to both worker processes in the second round: the scene's copies on the workers die
    with them (Dask cannot recompute data the client scattered), so the render sends it again to
    the workers the nannies start, and the image is the local one, bit for bit."""
    scene = volcl.load_file(SCENES / "fog.xml", **SIZE)
    local = volcl.render(scene, spp=40, seed=5, device=device)
    pids = client.run(os.getpid)
    r = on_cluster(scene, client, seed=5)
    seen = {"tiles": 0}

    def tile_done(job):
        seen["tiles"] += 1
        if seen["tiles"] == len(r.tile_list) + 1:
            for pid in pids.values():
                os.kill(pid, signal.SIGKILL)
    r.on_tile = tile_done
    try:
        result = r.render(40)
    finally:
        client.wait_for_workers(2, timeout=120)
    assert set(client.run(os.getpid).values()).isdisjoint(pids.values())
    assert same(result, local) and result.complete
    assert result.info["failures"] == [("scene", "every worker holding a copy died (sent again)")]


def fail_on_workers(client, tile, from_spp, others_wait=0.0):
    """Make every try of `tile`'s tasks that start at `from_spp` or later raise, in every worker
    process (their volcl.cluster._tile_renderer replaced), and the other tiles' tasks before
    `from_spp` start `others_wait` seconds late (so that the failure comes while the rounds before
    it are still rendering); returns a function that counts those tries and undoes it."""
    def install():
        import time
        from volcl import cluster as c
        original = getattr(c._tile_renderer, "original", c._tile_renderer)

        def failing(scene, spec, t, start=0):
            if t == tile and start >= from_spp:
                failing.tries += 1
                raise RuntimeError("injected failure")
            if t != tile and start < from_spp:
                time.sleep(others_wait)
            return original(scene, spec, t, start)
        failing.original, failing.tries = original, 0
        c._tile_renderer = failing

    def undo():
        from volcl import cluster as c
        tries = getattr(c._tile_renderer, "tries", 0)
        c._tile_renderer = getattr(c._tile_renderer, "original", c._tile_renderer)
        return tries
    client.run(install)
    return lambda: sum(client.run(undo).values())


def test_a_task_failing_on_every_try_stops_the_render_with_its_last_whole_round(client, device, tmp_path):
    """A tile whose task raises on each of its tries (in the worker processes): WorkersFailed, with
    the image of the last round before it, which is a local render's (the other tiles, slowed,
    are still rendering the rounds before it when it fails: they finish and are merged); the batch
    renderer writes that image and a checkpoint, and --resume continues to the bits of a whole
    render."""
    client.wait_for_workers(2, timeout=120)         # every worker gets the injected failure
    scene = volcl.load_file(SCENES / "fog.xml", **SIZE)
    r = on_cluster(scene, client, seed=7)           # rounds: one pass of the slots, then 1 spp each
    done = r.slots + 2
    undo = fail_on_workers(client, r.tile_list[-1], done, others_wait=0.2)
    try:
        with pytest.raises(cluster.WorkersFailed, match="injected failure") as info:
            r.render(done + 10)
    finally:
        tries = undo()
    assert tries == 1 + cluster.TASK_RETRIES
    failed = info.value.result
    assert failed.stop_reason == "failed" and failed.spp == done and not failed.complete
    assert same(failed, volcl.render(scene, spp=done, seed=7, device=device))
    assert any("injected failure" in why for _, why in info.value.failures)

    out = tmp_path / "fog.exr"
    options = dict(scene_options=SceneOptions(**SIZE), scheduler=client)
    first = r.slots                                 # the batch's first round: one pass of the slots
    undo = fail_on_workers(client, r.tile_list[0], first, others_wait=0.5)
    try:
        with pytest.raises(volcl.VolclError, match=f"injected failure.*wrote the image of the {first} spp every "
                                                   f"pixel has to .*continue with --resume"):
            batch.run([SCENES / "fog.xml"], render=RenderOptions(spp=3 * first, seed=7),
                      output=OutputOptions(output=out, quiet=True), **options)
    finally:
        undo()
    pixels, attrs = read_image(out)
    assert attrs["volcl:spp"] == first and attrs["volcl:complete"] == 0
    assert pixels[..., :3].tobytes() == volcl.render(scene, spp=first, seed=7, device=device).image.tobytes()
    assert batch.run([SCENES / "fog.xml"], render=RenderOptions(spp=3 * first),
                     output=OutputOptions(output=out, quiet=True, resume=True), **options) == 0
    pixels, attrs = read_image(out)
    assert attrs["volcl:spp"] == 3 * first
    assert pixels[..., :3].tobytes() == volcl.render(scene, spp=3 * first, seed=7, device=device).image.tobytes()


def copy_scene(tmp_path, name, *folders):
    for folder in folders:
        shutil.copytree(SCENES / folder, tmp_path / folder)
    shutil.copy(SCENES / name, tmp_path / name)
    return tmp_path / name


def test_scenes_whose_files_only_the_client_has(client, device, tmp_path):
    """Meshes and a density grid read on the client, then deleted: the workers render from what the
    scene carries."""
    cbox = copy_scene(tmp_path, "cbox.xml", "meshes")
    smoke = copy_scene(tmp_path, "smoke_grid.xml", "volumes")
    scenes = [volcl.load_file(p, width=24, height=16) for p in (cbox, smoke)]
    shutil.rmtree(tmp_path / "meshes")
    shutil.rmtree(tmp_path / "volumes")
    for scene in scenes:
        local = volcl.render(scene, spp=8, seed=1, device=device)
        assert same(volcl.render(scene, spp=8, seed=1, scheduler=client), local)


def test_a_batch_and_a_sweep_on_the_cluster_are_named_as_the_batch_renderer_names_them(client, device, tmp_path):
    scenes = [SCENES / "cbox.xml", SCENES / "fog.xml", SCENES / "smoke_sphere.xml"]
    rc = batch.run(scenes, scene_options=SceneOptions(width=24, height=16),
                   render=RenderOptions(spp=6, seed=3), output=OutputOptions(output_dir=tmp_path, quiet=True),
                   scheduler=client)
    assert rc == 0
    for s in scenes:
        pixels, attrs = read_image(tmp_path / f"{s.stem}.exr")
        local = volcl.render(volcl.load_file(s, width=24, height=16), spp=6, seed=3, device=device)
        assert pixels[..., :3].tobytes() == local.image.tobytes()
        assert attrs["volcl:device"].count("tcp://") >= 1 and attrs["volcl:complete"] == 1

    # one scene, -D max_depth=1..3 and a sweep file of two extinctions: six outputs
    sweep = tmp_path / "sweep.txt"
    sweep.write_text("# extinction\nsigma_t=0.1\nsigma_t=0.3  # denser\n")
    out = tmp_path / "sweep"
    rc = batch.run([SCENES / "point_in_fog.xml"],
                   scene_options=SceneOptions(defines={"max_depth": "1..3"}, width=16, height=12, sweep=sweep),
                   render=RenderOptions(spp=4, seed=1), output=OutputOptions(output_dir=out, quiet=True),
                   scheduler=client)
    assert rc == 0
    names = sorted(p.name for p in out.glob("*.exr"))
    assert names == [f"point_in_fog_max_depth_{d}_sigma_t_{s}.exr" for d in (1, 2, 3) for s in ("0.1", "0.3")]
    pixels, attrs = read_image(out / "point_in_fog_max_depth_2_sigma_t_0.3.exr")
    local = volcl.render(volcl.load_file(SCENES / "point_in_fog.xml", width=16, height=12, max_depth=2,
                                         sigma_t=0.3), spp=4, seed=1, device=device)
    assert pixels[..., :3].tobytes() == local.image.tobytes()
    assert '"sigma_t": "0.3"' in attrs["volcl:defines"]

    # a render kept as a checkpoint, resumed on the cluster to more samples: a local render's bits
    out = tmp_path / "resumed.exr"
    options = dict(scene_options=SceneOptions(width=24, height=16), scheduler=client)
    assert batch.run([SCENES / "fog.xml"], render=RenderOptions(spp=5, seed=9),
                     output=OutputOptions(output=out, quiet=True, keep_checkpoint=True), **options) == 0
    assert batch.run([SCENES / "fog.xml"], render=RenderOptions(spp=17),
                     output=OutputOptions(output=out, quiet=True, resume=True), **options) == 0
    pixels, attrs = read_image(out)
    local = volcl.render(volcl.load_file(SCENES / "fog.xml", width=24, height=16), spp=17, seed=9, device=device)
    assert attrs["volcl:spp"] == 17 and pixels[..., :3].tobytes() == local.image.tobytes()


def test_the_command_line_starts_a_local_cluster(tmp_path, device):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    r = subprocess.run([sys.executable, "-m", "volcl", "render", str(SCENES / "fog.xml"), "--scheduler", "local:2",
                        "--width", "24", "--height", "16", "--spp", "8", "--seed", "5", "-o", str(tmp_path / "f.exr"),
                        "-q"], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "2 workers" in r.stderr and re.search(r"workers tcp://\S+ .+? \(\d+%\)", r.stdout), r.stdout + r.stderr
    pixels, _ = read_image(tmp_path / "f.exr")
    local = volcl.render(volcl.load_file(SCENES / "fog.xml", width=24, height=16), spp=8, seed=5, device=device)
    assert pixels[..., :3].tobytes() == local.image.tobytes()
    r = subprocess.run([sys.executable, "-m", "volcl", "render", str(SCENES / "fog.xml"), "--scheduler", "local:0"],
                       cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "local:N with N >= 1" in r.stderr


def test_ctrl_c_on_the_client_writes_what_has_arrived_and_resume_continues(tmp_path, device):
    """SIGINT to `volcl render --scheduler local:2` mid-render: the rounds that came back are written
    with a checkpoint (exit 130); --resume continues to the bits of an uninterrupted local render."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    out = tmp_path / "fog.exr"
    args = [sys.executable, "-m", "volcl", "render", str(SCENES / "fog.xml"), "-o", str(out), "--width", "24",
            "--height", "16", "--seed", "3"]
    proc = subprocess.Popen([*args, "--scheduler", "local:2", "--spp", str(10 ** 7)], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    lines = []
    try:
        for line in proc.stderr:             # the first progress line comes after the first round
            lines.append(line)
            if re.search(r"\d+/\d+ spp", line):
                break
        proc.send_signal(signal.SIGINT)
        _, rest = proc.communicate(timeout=120)
        lines.append(rest)
    finally:
        if proc.poll() is None:
            proc.kill()
    stderr = "".join(lines)
    assert proc.returncode == 130, stderr
    m = re.search(r"interrupted after (\d+) spp; wrote", stderr)
    assert m and int(m.group(1)) > 0, stderr
    done = int(m.group(1))
    pixels, attrs = read_image(out)
    assert attrs["volcl:spp"] == done and attrs["volcl:complete"] == 0
    scene = volcl.load_file(SCENES / "fog.xml", width=24, height=16)
    assert pixels[..., :3].tobytes() == volcl.render(scene, spp=done, seed=3, device=device).image.tobytes()
    total = done + 5
    r = subprocess.run([*args, "--spp", str(total), "--resume", "--device", device.key, "-q"], cwd=ROOT, env=env,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and f"at {done} spp" in r.stderr, r.stderr
    pixels, attrs = read_image(out)
    assert attrs["volcl:spp"] == total and attrs["volcl:complete"] == 1
    assert pixels[..., :3].tobytes() == volcl.render(scene, spp=total, seed=3, device=device).image.tobytes()



def test_bad_scheduler_addresses_are_named(monkeypatch):
    monkeypatch.setattr(cluster, "CONNECT_SECONDS", 1.0)
    with pytest.raises(volcl.VolclError, match="bogus://x: not a scheduler address .*unknown address scheme"):
        cluster.connect("bogus://x")
    with pytest.raises(volcl.VolclError, match="tcp://127.0.0.1:1: cannot reach the Dask scheduler"):
        cluster.connect("tcp://127.0.0.1:1")
    with pytest.raises(volcl.VolclError, match="expected local:N with N >= 1"):
        cluster.connect("local:two")
    with pytest.raises(volcl.VolclError, match="expected a scheduler address"):
        volcl.render(volcl.load_file(SCENES / "fog.xml", **SIZE), scheduler=3.5)


def test_volcl_worker_joins_a_scheduler_with_volcls_preload(client, device, tmp_path):
    """`volcl worker ADDRESS` (dask worker with volcl.cluster as its preload) joins, names its device
    and renders its share."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    log = tmp_path / "worker.log"
    before = set(client.scheduler_info()["workers"])
    with open(log, "w") as f:
        worker = subprocess.Popen([sys.executable, "-m", "volcl", "worker", client.scheduler.address, "--nthreads", "1",
                                   "--device", device.key, "--", "--name", "volcl-test-worker"],
                                  cwd=ROOT, env=env, stdout=f, stderr=subprocess.STDOUT)
    try:
        client.wait_for_workers(len(before) + 1, timeout=120)
        new = set(client.scheduler_info()["workers"]) - before
        assert len(new) == 1
        scene = volcl.load_file(SCENES / "fog.xml", width=32, height=24)
        result = volcl.render(scene, spp=12, seed=2, scheduler=client)
        assert same(result, volcl.render(scene, spp=12, seed=2, device=device))
    finally:
        worker.terminate()
        worker.wait(60)
    text = log.read_text()
    assert f"renders on {device.key} {device.name}" in text, text
