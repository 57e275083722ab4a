"""`volcl render` with long jobs: signals, checkpoints and resume, batches, output names."""
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from volcl.batch import output_paths
from volcl.errors import VolclError
from volcl.image import read_image

ROOT = Path(__file__).resolve().parent.parent
CBOX = ROOT / "scenes" / "cbox.xml"
SMALL = ("--width", 32, "--height", 32)
FOREVER = 10 ** 7                           # spp no test waits for
ENV = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))


def volcl(*args, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", "volcl", *map(str, args)], cwd=cwd, env=ENV,
                          capture_output=True, text=True, timeout=120)


class Running:
    """A `volcl` subprocess whose stderr is read as it comes."""

    PROGRESS = re.compile(r"(\d+)/(\d+) spp")

    def __init__(self, *args, cwd=ROOT):
        self.proc = subprocess.Popen([sys.executable, "-m", "volcl", *map(str, args)], cwd=cwd, env=ENV,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.lines = []
        self.progress = threading.Event()
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    def _read(self):
        for line in self.proc.stderr:
            self.lines.append(line)
            if self.PROGRESS.search(line):
                self.progress.set()

    def wait_for_progress(self, timeout=60):
        assert self.progress.wait(timeout), "no progress line: " + "".join(self.lines)

    def finish(self, timeout=60):
        out = self.proc.stdout.read()
        rc = self.proc.wait(timeout)
        self.reader.join(timeout)
        return rc, out, "".join(self.lines)


def exr(path):
    pixels, attrs = read_image(path)
    return pixels, {k.split(":", 1)[1]: v for k, v in attrs.items() if k.startswith("volcl:")}


def interrupt_after_progress(sig, *args, cwd=ROOT, settle=0.5):
    job = Running("render", *args, cwd=cwd)
    try:
        job.wait_for_progress()
        time.sleep(settle)                      # some passes beyond the first
        job.proc.send_signal(sig)
        return job.finish()
    finally:
        if job.proc.poll() is None:
            job.proc.kill()


def test_sigint_writes_the_partial_image_and_resume_ends_bit_identical(tmp_path):
    out = tmp_path / "cbox.exr"
    rc, stdout, stderr = interrupt_after_progress(signal.SIGINT, CBOX, "-o", out, "--spp", FOREVER, *SMALL,
                                                  "--seed", 11)
    assert rc == 130, stderr
    m = re.search(r"interrupted after (\d+) spp; wrote (\S+)", stderr)
    assert m and m.group(2) == str(out), stderr
    done = int(m.group(1))
    pixels, meta = exr(out)
    assert 0 < meta["spp"] == done < FOREVER
    assert meta["spp_requested"] == FOREVER and meta["complete"] == 0 and meta["seed"] == 11
    assert pixels.shape == (32, 32, 6) and np.isfinite(pixels).all() and pixels[..., :3].mean() > 0
    ckpt = tmp_path / "cbox.exr.checkpoint.npz"
    assert ckpt.is_file() and "--resume" in stderr

    # resume (the seed comes from the checkpoint) to a total that is not a whole round of slots,
    # and render the same total without stopping: the images agree bit for bit
    total = done + 41
    r = volcl("render", CBOX, "-o", out, "--spp", total, *SMALL, "--resume", "-q")
    assert r.returncode == 0, r.stderr
    assert f"resuming from {ckpt} at {done} spp" in r.stderr
    assert not ckpt.exists(), "checkpoint left behind after a finished render"
    r = volcl("render", CBOX, "-o", tmp_path / "straight.exr", "--spp", total, *SMALL, "--seed", 11, "-q")
    assert r.returncode == 0, r.stderr
    resumed, meta = exr(out)
    straight, _ = exr(tmp_path / "straight.exr")
    assert meta["spp"] == total and meta["complete"] == 1
    assert np.array_equal(resumed, straight)

    # --resume again: the finished output is kept, nothing is rendered
    r = volcl("render", CBOX, "-o", out, "--spp", total, *SMALL, "--resume")
    assert r.returncode == 0 and "already rendered" in r.stdout, r.stdout + r.stderr


def test_sigterm_stops_the_batch_and_names_the_scenes_not_rendered(tmp_path):
    scenes = []
    for folder in ("scenes", "other"):          # same file name: outputs scenes_cbox.exr, other_cbox.exr
        (tmp_path / folder).mkdir()
        shutil.copy(CBOX, tmp_path / folder / "cbox.xml")
        shutil.copytree(ROOT / "scenes" / "meshes", tmp_path / folder / "meshes")
        scenes.append(tmp_path / folder / "cbox.xml")
    other = tmp_path / "other"
    rc, stdout, stderr = interrupt_after_progress(signal.SIGTERM, *scenes, "--output-dir", tmp_path / "out",
                                                  "--spp", FOREVER, *SMALL, "--checkpoint-every", 0)
    assert rc == 143, stderr
    first = tmp_path / "out" / "scenes_cbox.exr"
    assert f"wrote {first}" in stderr and "SIGTERM" in stderr
    _, meta = exr(first)
    assert 0 < meta["spp"] < FOREVER and meta["complete"] == 0
    assert not (tmp_path / "out" / "other_cbox.exr").exists()
    assert not list((tmp_path / "out").glob("*.npz")), "--checkpoint-every 0 wrote a checkpoint"
    assert f"not rendered: {other / 'cbox.xml'}" in stderr
    table = stdout[stdout.index("scene "):].splitlines()
    assert re.search(r"scenes_cbox\.exr\s+\d+\s+[\d.]+\s+interrupted", table[1]), stdout
    assert table[2].endswith("not rendered") and "0 of 2 scenes rendered" in stdout


def test_checkpoint_survives_sigkill_and_refuses_another_scene(tmp_path):
    """Periodic checkpoints (every 0.1 s here): after a SIGKILL the last one resumes bit for bit."""
    out = tmp_path / "k.exr"
    ckpt = tmp_path / "k.exr.checkpoint.npz"
    job = Running("render", CBOX, "-o", out, "--spp", FOREVER, *SMALL, "--checkpoint-every", 0.1 / 60)
    try:
        job.wait_for_progress()
        deadline = time.monotonic() + 60
        while not ckpt.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.3)
        job.proc.kill()
        job.finish()
    finally:
        if job.proc.poll() is None:
            job.proc.kill()
    assert not out.exists() and ckpt.exists()
    with np.load(ckpt) as z:
        done = json.loads(str(z["meta"]))["samples_done"]
    assert done > 0

    r = volcl("render", CBOX, "-o", out, "--spp", done + 20, *SMALL, "-D", "max_depth=3", "--resume")
    assert r.returncode == 2 and "belongs to a different render" in r.stderr and "-D overrides" in r.stderr
    assert ckpt.exists() and not out.exists()

    r = volcl("render", CBOX, "-o", out, "--spp", done + 20, *SMALL, "--resume", "-q")
    assert r.returncode == 0, r.stderr
    r = volcl("render", CBOX, "-o", tmp_path / "straight.exr", "--spp", done + 20, *SMALL, "-q")
    assert r.returncode == 0, r.stderr
    assert np.array_equal(exr(out)[0], exr(tmp_path / "straight.exr")[0])


def test_output_names_follow_the_scenes_without_clobbering(tmp_path, monkeypatch):
    assert output_paths(["a/x.xml", "b/y.xml"]) == [Path("x.exr"), Path("y.exr")]
    assert output_paths(["a/x.xml"], output_dir="o") == [Path("o/x.exr")]
    assert output_paths(["s.xml"], output="r.png") == [Path("r.png")]
    monkeypatch.chdir(tmp_path)
    assert output_paths(["p/a/x.xml", "p/b/x.xml", "q.xml"]) == [Path("a_x.exr"), Path("b_x.exr"), Path("q.exr")]
    assert output_paths(["p/x.xml", "p/c/x.xml"]) == [Path("x.exr"), Path("c_x.exr")]
    with pytest.raises(VolclError, match="-o names one output file"):
        output_paths(["a.xml", "b.xml"], output="x.exr")
    with pytest.raises(VolclError, match="given twice"):
        output_paths(["a.xml", "./a.xml"])
    with pytest.raises(VolclError, match="would both write"):
        output_paths(["a/b/x.xml", "a/b_x.xml", "a/c/x.xml"])
