"""The installed package (not the checkout) finds and builds its OpenCL kernels."""
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

PROBE = """
import volcl, volcl.program as p
from volcl import device
from volcl.device import cl
from volcl.features import all_features
d = device.choose()
p.build_program(cl.Context([d.device]), all_features())
print(volcl.__file__)
print(p.kernels_dir())
"""


def test_non_editable_install_builds_its_kernels(tmp_path):
    target = tmp_path / "site"
    cmd = [sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target", str(target), str(ROOT)]
    subprocess.run(cmd, check=True, cwd=tmp_path, capture_output=True, text=True)
    env = dict(os.environ, PYTHONPATH=str(target))
    out = subprocess.run([sys.executable, "-c", PROBE], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    module_file, kernels = out.stdout.split()
    assert Path(module_file).is_relative_to(target), "imported the checkout instead of the installed package"
    assert Path(kernels).is_relative_to(target), f"kernels found outside the installed package: {kernels}"
    assert (Path(kernels) / "render.cl").is_file()
