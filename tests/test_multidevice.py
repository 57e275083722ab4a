"""One render on several devices (volcl.rounds, volcl.devicepool): the bits of one device, the stopping
rules across devices, checkpoints either way, a device that fails, the load balance, and the command
line on two PoCL devices (POCL_DEVICES="pthread pthread") with an interrupt and --resume."""
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import volcl
from volcl import batch
from volcl.devicepool import DeviceFailure, DevicePool
from volcl.image import read_image
from volcl.options import OutputOptions, RenderOptions, SceneOptions
from volcl.program import ENTRY_FILE
from volcl.renderer import Renderer
from volcl.rounds import TiledRender, WorkersFailed

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "scenes"
SIZE = {"width": 37, "height": 23}     # 851 pixels: 19 accumulator slots, tiles of 8 pixels


def same(a, b):
    return (a.spp == b.spp and a.invalid == b.invalid and a.image.tobytes() == b.image.tobytes()
            and a.variance.tobytes() == b.variance.tobytes())


@pytest.fixture(scope="module")
def pair(device):
    """Two device objects with contexts, queues, programs and uploads of their own."""
    return [device.fresh(), device.fresh()]


def load(name, **defines):
    return volcl.load_file(SCENES / name, **{**SIZE, **defines})


def tiled(scene, devices, seed, round_seconds=0.0):
    """A TiledRender whose rounds are as short as can be (after the first, one sample each)."""
    return TiledRender(scene, DevicePool(devices), seed=seed, round_seconds=round_seconds)


@pytest.mark.parametrize("name", ["cbox.xml", "fog.xml"])
def test_two_devices_give_the_bits_of_one(name, device, pair):
    scene = load(name)
    one = volcl.render(scene, spp=45, seed=7, device=device)
    two = volcl.render(scene, spp=45, seed=7, device=pair)
    assert same(one, two) and two.stop_reason == "spp" and two.complete
    labels = [f"{d.label}" for d in pair]
    assert set(two.shares) <= {labels[0], labels[0] + " #2"} and abs(sum(two.shares.values()) - 1) < 1e-12
    assert two.metadata["device_shares"].count(device.name) == len(two.shares)
    # many short rounds: still the same bits
    r = tiled(scene, pair, seed=7)
    assert same(r.render(45), one) and r.rounds >= 3


def test_stopping_rules_stop_every_device_where_one_device_would(device, pair):
    scene = load("fog.xml")
    one = volcl.render(scene, seed=2, device=device, target_error=0.15, spp=4000)
    two = volcl.render(scene, seed=2, device=pair, target_error=0.15, spp=4000)
    assert two.stop_reason == "error" and same(one, two)

    timed = volcl.render(scene, seed=2, device=pair, time_limit=0.3)
    assert timed.stop_reason == "time" and timed.spp > 0
    assert same(timed, volcl.render(scene, seed=2, device=device, spp=timed.spp))

    # a stop request ends the render after a round; the same render then carries on to the bits of
    # an uninterrupted one
    r = tiled(scene, pair, seed=2)
    part = r.render(60, stop=lambda: True)
    assert part.stop_reason == "stopped" and not part.complete and 0 < part.spp < 60
    assert same(part, volcl.render(scene, seed=2, device=device, spp=part.spp))
    assert same(r.render(60 - part.spp), volcl.render(scene, seed=2, device=device, spp=60))


def test_checkpoint_states_pass_between_one_device_and_several(device, pair):
    scene = load("cbox.xml")
    whole = volcl.render(scene, spp=50, seed=5, device=device)
    many = tiled(scene, pair, seed=5)
    many.render(21)
    single = Renderer(scene, device=device, seed=5)
    single.restore({k: np.copy(v) if isinstance(v, np.ndarray) else v for k, v in many.state().items()})
    assert same(single.render(29), whole)

    single = Renderer(scene, device=device, seed=5)
    single.render(13)
    many = tiled(scene, pair, seed=5)
    many.restore(single.state())
    assert same(many.render(37), whole)
    with pytest.raises(ValueError, match="seed"):
        tiled(scene, pair, seed=6).restore(single.state())


def failing(monkeypatch, should_fail):
    """Make Renderer.advance raise where should_fail(renderer) says so (a device lost mid-render)."""
    advance = Renderer.advance

    def patched(self, spp):
        if should_fail(self):
            raise RuntimeError(f"device lost (forced, {self.device.label})")
        return advance(self, spp)
    monkeypatch.setattr(Renderer, "advance", patched)


def test_a_device_that_fails_has_its_tiles_rendered_by_the_others(device, pair, monkeypatch):
    scene = load("fog.xml")
    one = volcl.render(scene, spp=40, seed=9, device=device)
    bad = pair[1]
    calls = {"n": 0}

    def fail_second_tile(r):
        if r.device is bad:
            calls["n"] += 1
            return calls["n"] >= 2
        return False
    failing(monkeypatch, fail_second_tile)
    with pytest.warns(DeviceFailure, match="failed .*device lost.*its tiles go to"):
        two = volcl.render(scene, spp=40, seed=9, device=pair)
    assert same(one, two) and two.complete
    assert [label for label, _ in two.info["failures"]] == [bad.label + " #2"]


def test_every_device_failing_stops_with_a_clear_error_and_the_last_whole_round(device, pair, monkeypatch,
                                                                              tmp_path):
    scene = load("fog.xml")
    failing(monkeypatch, lambda r: r.samples_done > 0)     # the first round succeeds, no later one
    with pytest.warns(DeviceFailure):
        with pytest.raises(WorkersFailed, match="every device failed .*device lost") as info:
            tiled(scene, pair, seed=3).render(60)
    partial = info.value.result
    assert partial.stop_reason == "failed" and not partial.complete and partial.spp == 19   # one round of slots
    monkeypatch.undo()
    assert same(partial, volcl.render(scene, spp=19, seed=3, device=device))

    # the batch runner writes that image and a checkpoint, and fails the scene with the reason
    failing(monkeypatch, lambda r: r.samples_done > 0)
    out = tmp_path / "fog.exr"
    with pytest.raises(volcl.VolclError, match=r"every device failed.*wrote the image of the 19 spp"):
        batch.run([SCENES / "fog.xml"], device=pair, scene_options=SceneOptions(**SIZE),
                  render=RenderOptions(spp=60, seed=3), output=OutputOptions(output=out, quiet=True))
    pixels, attrs = read_image(out)
    assert attrs["volcl:spp"] == 19 and attrs["volcl:complete"] == 0 and attrs["volcl:stop_reason"] == "failed"
    assert pixels[..., :3].tobytes() == partial.image.tobytes()
    assert (tmp_path / "fog.exr.checkpoint.npz").is_file()


def test_a_slow_device_takes_fewer_tiles(pair, monkeypatch):
    """Tiles come from a shared list: a device three times slower renders about a quarter of them."""
    slow = pair[1]
    advance = Renderer.advance

    def patched(self, spp):
        t0 = time.perf_counter()
        advance(self, spp)
        if self.device is slow:
            time.sleep(3 * (time.perf_counter() - t0) + 0.002)
    monkeypatch.setattr(Renderer, "advance", patched)
    result = volcl.render(load("fog.xml", width=64, height=48), spp=96, seed=1, device=pair)
    fast_share = result.shares[pair[0].label]
    assert fast_share > 0.6, result.shares


@pytest.mark.parametrize("name, engine", [("point_in_fog.xml", "wavefront"), ("fog.xml", "megakernel")])
def test_devices_prepare_exactly_the_programs_their_tiles_launch(name, engine, device):
    """prepare() builds what the tiles' renderers use and nothing else: a scene "auto" gives the
    wavefront builds the wavefront's programs, not an unused megakernel counted as build time."""
    if device.kind != "cpu":
        pytest.skip("the wavefront renders on CPUs only")
    devs = [device.fresh(), device.fresh()]     # program caches of their own, empty
    r = tiled(load(name), devs, seed=3)
    prepared = [d.builds for d in devs]
    r.render(6)
    assert [d.builds for d in devs] == prepared, "a tile's renderer built a program prepare() did not"
    renderers = [t for w in r.executor.workers for t in w.renderers.values()]
    assert renderers and {t.engine for t in renderers} == {engine}
    t = renderers[0]
    used = t.wavefront.sources if t.wavefront is not None else [(ENTRY_FILE, ())]
    for d in devs:
        assert len(d.programs) == len(used) and all(d.has_program(r.features, f, x) for f, x in used)
    built = sum(d.programs.seconds(r.features, f, x) for d in devs for f, x in used)
    assert r.build_seconds == pytest.approx(built, rel=0.05, abs=0.01)    # the build time reported is theirs


# -- the command line on two PoCL devices -------------------------------------------------------------

def pocl_env(tmp_path, **extra):
    """The environment of a volcl process that sees two PoCL devices and no other OpenCL driver."""
    icds = [f for f in Path("/etc/OpenCL/vendors").glob("*.icd") if "pocl" in f.read_text().lower()]
    if not icds:
        pytest.skip("no PoCL .icd file in /etc/OpenCL/vendors")
    vendors = tmp_path / "vendors"
    vendors.mkdir(exist_ok=True)
    (vendors / "pocl.icd").write_text(icds[0].read_text())
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
               POCL_DEVICES="pthread pthread", OCL_ICD_VENDORS=str(vendors))
    env.pop("VOLCL_DEVICE", None)
    env.update(extra)
    return env


def volcl_cli(*args, env):
    return subprocess.run([sys.executable, "-m", "volcl", *map(str, args)], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=300)


def exr(path):
    pixels, attrs = read_image(path)
    return pixels, {k.split(":", 1)[1]: v for k, v in attrs.items() if k.startswith("volcl:")}


def test_device_all_on_two_pocl_devices_renders_the_bits_of_one(tmp_path, device):
    env = pocl_env(tmp_path)
    r = volcl_cli("render", SCENES / "cbox.xml", SCENES / "fog.xml", "--device", "all", "--spp", 24, "--seed", 4,
                  "--width", SIZE["width"], "--height", SIZE["height"], "--output-dir", tmp_path, "-q", env=env)
    assert r.returncode == 0, r.stderr
    for name in ("cbox", "fog"):
        pixels, meta = exr(tmp_path / f"{name}.exr")
        one = volcl.render(load(f"{name}.xml"), spp=24, seed=4, device=device)
        assert pixels[..., :3].tobytes() == one.image.tobytes() and pixels[..., 3:].tobytes() == one.variance.tobytes()
        assert meta["device"].startswith("0:") and meta["device"].count(":") == 2, meta["device"]
        shares = [float(x.rsplit(" ", 1)[1]) for x in meta["device_shares"].split(", ")]
        assert abs(sum(shares) - 1) < 0.01 and meta["complete"] == 1
    assert re.search(r"devices 0:\d .+? \(\d+%\), 0:\d .+? \(\d+%\)", r.stdout), r.stdout


def test_interrupt_and_resume_on_two_devices_end_with_the_bits_of_one(tmp_path, device):
    """VOLCL_DEVICE=all, SIGINT mid-render: a partial image and a checkpoint holding every tile;
    --resume on the device list continues to the image one device renders."""
    out = tmp_path / "fog.exr"
    env = pocl_env(tmp_path, VOLCL_DEVICE="all")
    args = ["render", SCENES / "fog.xml", "-o", out, "--width", SIZE["width"], "--height", SIZE["height"]]
    proc = subprocess.Popen([sys.executable, "-m", "volcl", *map(str, [*args, "--spp", 10 ** 7, "--seed", 8])],
                            cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    lines, progress = [], threading.Event()

    def read():
        for line in proc.stderr:
            lines.append(line)
            if re.search(r"\d+/\d+ spp", line):
                progress.set()
    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        assert progress.wait(120), "".join(lines)
        time.sleep(1.0)
        proc.send_signal(signal.SIGINT)
        assert proc.wait(120) == 130, "".join(lines)
    finally:
        if proc.poll() is None:
            proc.kill()
    reader.join(10)
    stderr = "".join(lines)
    m = re.search(r"interrupted after (\d+) spp; wrote", stderr)
    assert m, stderr
    done = int(m.group(1))
    _, meta = exr(out)
    assert meta["spp"] == done and meta["complete"] == 0 and meta["device"].count(":") == 2
    total = done + 23
    r = volcl_cli(*args, "--spp", total, "--resume", "--device", "0:1,0:0", "-q", env=dict(env, VOLCL_DEVICE=""))
    assert r.returncode == 0, r.stderr
    assert f"at {done} spp" in r.stderr
    pixels, meta = exr(out)
    one = volcl.render(load("fog.xml"), spp=total, seed=8, device=device)
    assert meta["spp"] == total and meta["complete"] == 1
    assert pixels[..., :3].tobytes() == one.image.tobytes() and pixels[..., 3:].tobytes() == one.variance.tobytes()


def test_device_lists_are_checked(tmp_path):
    env = pocl_env(tmp_path)
    r = volcl_cli("render", SCENES / "fog.xml", "--device", "0:0,0:0", "-o", tmp_path / "x.exr", env=env)
    assert r.returncode == 2 and "names device 0:0" in r.stderr and "twice" in r.stderr
    r = volcl_cli("render", SCENES / "fog.xml", "--device", "0:0,all", "-o", tmp_path / "x.exr", env=env)
    assert r.returncode == 2 and "'all' stands alone" in r.stderr
    r = volcl_cli("render", SCENES / "fog.xml", "--device", "0:0,", "-o", tmp_path / "x.exr", env=env)
    assert r.returncode == 2 and "empty name" in r.stderr
