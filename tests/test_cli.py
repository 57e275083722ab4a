"""The volcl command line: rendering to EXR and PNG, devices, Nori t-tests, batch behaviour, errors."""
import hashlib
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from volcl import __version__ as volcl_version
from volcl.image import read_image

ROOT = Path(__file__).resolve().parent.parent
SHARED = ROOT.parent / "shared"


def volcl(*args, cwd=ROOT):
    """Run the checkout's volcl command, from any working directory."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    return subprocess.run([sys.executable, "-m", "volcl", *map(str, args)], cwd=cwd, env=env,
                          capture_output=True, text=True)


def test_render_png_and_exr_with_metadata(tmp_path):
    png, exr = tmp_path / "cbox.png", tmp_path / "cbox.exr"
    r = volcl("render", "scenes/cbox.xml", "-o", png, "--spp", 2, "--width", 40, "--height", 30, "-q")
    assert r.returncode == 0, r.stderr
    assert "samples/s" in r.stdout and "features" in r.stdout
    img, _ = read_image(png)
    assert img.shape == (30, 40, 3)
    r = volcl("render", "scenes/cbox.xml", "-o", exr, "--spp", 3, "--width", 40, "--height", 30, "--seed", 5, "-q")
    assert r.returncode == 0, r.stderr
    img, attrs = read_image(exr)
    assert img.shape == (30, 40, 6)    # RGB and the variance layer
    assert attrs["volcl:spp"] == 3 and attrs["volcl:seed"] == 5 and attrs["volcl:invalid_samples"] == 0
    assert "spheres" in attrs["volcl:features"]
    meta = {k.split(":", 1)[1]: v for k, v in attrs.items() if k.startswith("volcl:")}
    assert set(meta) == {"scene", "scene_sha256", "defines", "spp", "spp_requested", "complete", "seed",
                         "device", "features", "kernel_sha256", "render_seconds", "version", "invalid_samples",
                         "tracking_cutoffs", "rel_error", "stop_reason", "estimator", "device_shares"}
    assert meta["scene"] == str(ROOT / "scenes" / "cbox.xml") and meta["version"] == volcl_version
    assert meta["scene_sha256"] == hashlib.sha256((ROOT / "scenes" / "cbox.xml").read_bytes()).hexdigest()
    assert meta["spp_requested"] == 3 and meta["complete"] == 1 and meta["render_seconds"] > 0
    assert meta["device"].split()[0].count(":") == 1 and meta["defines"] == "{}"
    assert np.isfinite(img).all() and img[..., :3].mean() > 0
    assert not list(tmp_path.glob(".*")), "temporary files left behind"


def test_define_overrides_scene_default(tmp_path):
    out = tmp_path / "d.exr"
    r = volcl("render", "scenes/cbox.xml", "-o", out, "-D", "spp=2", "-D", "width=20", "-D", "height=10", "-q")
    assert r.returncode == 0, r.stderr
    img, attrs = read_image(out)
    assert img.shape[:2] == (10, 20) and attrs["volcl:spp"] == 2


def test_devices_lists_a_device_whose_kernels_build():
    r = volcl("devices")
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert lines[0].split()[:3] == ["index", "type", "units"]
    assert any(" build " in line for line in lines[1:])


def test_unknown_device_is_a_clear_error(tmp_path):
    r = volcl("render", "scenes/cbox.xml", "-o", tmp_path / "x.png", "--device", "no-such-device", "--spp", 1)
    assert r.returncode == 2
    assert "no OpenCL device matches --device 'no-such-device'" in r.stderr and "available" in r.stderr


def test_bad_scene_names_file_and_line(tmp_path):
    bad = tmp_path / "bad.xml"
    bad.write_text('<scene version="3.0.0">\n  <shape type="teapot"/>\n</scene>\n')
    r = volcl("render", bad, "-o", tmp_path / "x.png")
    assert r.returncode == 2
    assert f"{bad}:2" in r.stderr and "teapot" in r.stderr
    assert not (tmp_path / "x.png").exists()


def test_batch_renders_the_good_scenes_and_reports_the_broken_one(tmp_path):
    bad = tmp_path / "broken.xml"
    bad.write_text("<scene version='3.0.0'><shape type='obj'><string name='filename' value='none.obj'/></shape></scene>")
    good = ROOT / "scenes" / "cbox.xml"
    r = volcl("render", good, bad, "--spp", 1, "--width", 16, "--height", 16, "-q", cwd=tmp_path)
    assert r.returncode == 1
    assert (tmp_path / "cbox.exr").is_file()
    assert "1 of 2 scenes rendered" in r.stdout and "FAILED" in r.stdout and "broken.xml" in r.stdout
    table = r.stdout[r.stdout.index("scene "):].splitlines()
    assert table[0].split() == ["scene", "output", "spp", "seconds", "status"]
    assert re.match(rf"{re.escape(str(good))}\s+cbox\.exr\s+1\s+[\d.]+\s+ok$", table[1]), r.stdout
    assert re.match(rf"{re.escape(str(bad))}\s+broken\.exr\s+-\s+-\s+FAILED$", table[2]), r.stdout
    assert "none.obj" in r.stdout and "none.obj" in r.stderr     # why it failed, in the table and as it happens


@pytest.mark.skipif(not (SHARED / "nori" / "furnace").is_dir(), reason="../shared/nori is not beside the checkout")
def test_nori_furnace_t_test_file_passes():
    """Nori's own test file: furnaces with L = 2 and 5 for three integrators."""
    r = volcl("test", SHARED / "nori" / "furnace" / "test-furnace.xml")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "6 passed, 0 failed" in r.stdout


def test_nori_cornell_box_renders(tmp_path):
    """The Nori dialect's Cornell box (mirror and glass spheres) renders without invalid samples."""
    scene = SHARED / "nori" / "cbox" / "cbox_path_mis.xml"
    if not scene.is_file():
        pytest.skip("../shared/nori is not beside the checkout")
    out = tmp_path / "cbox.exr"
    r = volcl("render", scene, "-o", out, "--spp", 2, "--width", 80, "--height", 60, "-q")
    assert r.returncode == 0, r.stderr
    img, attrs = read_image(out)
    assert attrs["volcl:invalid_samples"] == 0 and img[..., :3].mean() > 0.05


def test_define_that_the_scene_never_reads_is_an_error(tmp_path):
    r = volcl("render", "scenes/cbox.xml", "-o", tmp_path / "x.png", "-D", "sppp=4")
    assert r.returncode == 2
    assert "-D sppp" in r.stderr and "spp" in r.stderr


OVERFLOWING = """<scene version="3.0.0">
    <sensor type="perspective"><float name="fov" value="90"/>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="6"/></film>
        <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
    </sensor>
    <!-- a furnace whose walls emit near the float32 maximum: every path's sum overflows to inf -->
    <shape type="cube">
        <boolean name="flip_normals" value="true"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.9"/></bsdf>
        <emitter type="area"><rgb name="radiance" value="3e38"/></emitter>
    </shape>
</scene>
"""


def test_invalid_samples_are_reported_in_summary_and_metadata(tmp_path):
    """Samples that come out NaN or infinite are counted on the device, left out of the image, and
    reported: the summary line and the EXR's volcl:invalid_samples carry the same count."""
    scene = tmp_path / "overflow.xml"
    scene.write_text(OVERFLOWING)
    out = tmp_path / "overflow.exr"
    r = volcl("render", scene, "-o", out, "-q")
    assert r.returncode == 0, r.stderr
    img, attrs = read_image(out)
    count = attrs["volcl:invalid_samples"]
    assert 0 < count <= 8 * 6 * 4
    assert f"invalid samples {count}," in r.stdout
    assert np.isfinite(img).all(), "invalid samples must be left out of the image"


def test_render_grid_scene_reports_tracking_cutoffs(tmp_path):
    """The smoke scene (a heterogeneous medium): the summary line and the EXR carry the number of
    tracking cut-offs, zero here."""
    exr = tmp_path / "smoke.exr"
    r = volcl("render", "scenes/smoke_grid.xml", "-o", exr, "--spp", 2, "--width", 24, "--height", 24, "-q")
    assert r.returncode == 0, r.stderr
    assert "tracking cut-offs 0" in r.stdout
    img, attrs = read_image(exr)
    assert attrs["volcl:tracking_cutoffs"] == 0 and attrs["volcl:invalid_samples"] == 0
    assert "grid_media" in attrs["volcl:features"]
    r = volcl("info", "scenes/smoke_grid.xml", "--no-build")
    assert r.returncode == 0, r.stderr
    assert "heterogeneous (48x48x48 grid, 1 channel, trilinear)" in r.stdout
    assert "VOLCL_HAS_GRID_MEDIA=1" in r.stdout


MOMENT_SCENE = '''<scene version="2.0.0">
<integrator type="moment"><integrator type="path"><integer name="max_depth" value="1"/></integrator></integrator>
<sensor type="perspective"><float name="fov" value="20"/>
    <transform name="to_world"><lookat origin="0, 0, 3" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="6"/><rfilter type="box"/></film>
    <sampler type="independent"><integer name="sample_count" value="3"/></sampler></sensor>
<sensor type="orthographic">
    <film type="hdrfilm"><integer name="width" value="5"/><integer name="height" value="4"/><rfilter type="box"/></film>
    <sampler type="independent"><integer name="sample_count" value="2"/></sampler></sensor>
<shape type="rectangle"><transform name="to_world"><scale value="5"/></transform>
    <emitter type="area"><rgb name="radiance" value="0.5, 1, 2"/></emitter></shape>
</scene>
'''


def test_moment_layer_sensor_choice_and_scene_spp_under_a_time_limit(tmp_path):
    """Mitsuba's moment integrator: the image of the wrapped one, and the second moment of the
    samples as m2.R/G/B (every sample sees the emitter: L^2 exactly); --sensor picks a sensor; a time
    limit without --spp stops at the scene's own sample count."""
    scene = tmp_path / "moment.xml"
    scene.write_text(MOMENT_SCENE)
    out = tmp_path / "m.exr"
    r = volcl("render", scene, "-o", out, "--time-limit", 600, "-q")
    assert r.returncode == 0, r.stderr
    assert "2 sensors" in r.stderr and "--sensor" in r.stderr
    img, attrs = read_image(out)
    assert img.shape == (6, 8, 9)           # RGB, variance, m2
    assert attrs["volcl:spp"] == 3 and attrs["volcl:stop_reason"] == "spp"
    # channels come back in the EXR's order: R G B, m2.R/G/B, variance.R/G/B
    assert np.allclose(img[..., :3], [0.5, 1, 2]) and np.allclose(img[..., 3:6], [0.25, 1, 4])
    assert np.allclose(img[..., 6:9], 0)
    r = volcl("render", scene, "-o", out, "--sensor", 1, "-q")
    assert r.returncode == 0, r.stderr
    assert "2 sensors" not in r.stderr
    img, attrs = read_image(out)
    assert img.shape[:2] == (4, 5) and attrs["volcl:spp"] == 2
    r = volcl("render", scene, "-o", out, "--sensor", 2, "-q")
    assert r.returncode == 2 and "0 to 1" in r.stderr


def _leave_run(body, tmp_path):
    """A Python process that runs `body` and then volcl.cli.leave(3); its result."""
    code = "import atexit, sys, threading, time\nfrom volcl.cli import leave\n" + body + "\nleave(3)\n"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    return subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=60)


def test_leaving_runs_the_exit_handlers_and_keeps_the_status(tmp_path):
    # the process skips Python's teardown, not what libraries registered to run at exit
    r = _leave_run("atexit.register(lambda: open('handler', 'w').write('ran'))\nprint('out', end='')", tmp_path)
    assert r.returncode == 3
    assert r.stdout == "out"        # buffered output is flushed
    assert (tmp_path / "handler").read_text() == "ran"


def test_leaving_waits_for_a_working_thread(tmp_path):
    body = ("def work():\n    time.sleep(0.5)\n    open('thread', 'w').write('done')\n"
            "threading.Thread(target=work).start()")
    r = _leave_run(body, tmp_path)
    assert r.returncode == 3
    assert (tmp_path / "thread").read_text() == "done"


def test_volcl_command_ends_with_the_status_of_main(tmp_path):
    ok = volcl("render", ROOT / "scenes" / "cbox.xml", "--spp", 1, "--width", 8, "--height", 8,
               "-o", tmp_path / "a.exr", "-q", cwd=tmp_path)
    assert ok.returncode == 0 and (tmp_path / "a.exr").is_file()
    bad = volcl("render", tmp_path / "missing.xml", cwd=tmp_path)
    assert bad.returncode == 2 and "missing.xml" in bad.stderr
