"""Shared fixtures: the OpenCL device the tests run on, and test-kernel builds.

`device` is the device volcl would choose. A test (or a whole module, with `pytestmark`) marked
`@pytest.mark.every_implementation` gets `device` parametrized instead: once per OpenCL
implementation present (the first device of each platform; Oclgrind, a simulator, has its own
test), with ids such as `pocl` and `intel`. Fixtures built on `device` (cl_env, test_program)
follow it. `--implementations` (or VOLCL_TEST_IMPLEMENTATIONS) narrows that set: `all` (the
default), `default` (volcl's own choice only), or comma-separated ids.
"""
import os
import re
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from volcl import device as devmod  # noqa: E402
from volcl.device import cl  # noqa: E402
from volcl.features import all_features  # noqa: E402

TEST_KERNELS = Path(__file__).resolve().parent / "kernels"

# short ids for the implementations volcl is tested on; others get one from their platform name
_IDS = (("portable computing language", "pocl"), ("intel", "intel"), ("nvidia", "nvidia"),
        ("amd accelerated", "amd"), ("rusticl", "rusticl"), ("clover", "clover"), ("apple", "apple"))


def implementation_id(info) -> str:
    name = info.platform_name.lower()
    for key, short in _IDS:
        if key in name:
            return short
    return re.sub(r"[^a-z0-9]+", "-", name).strip("-") or f"platform{info.platform_index}"


def implementations() -> list:
    """The first device of each OpenCL platform present, simulators left out."""
    seen, out = set(), []
    for d in devmod.list_devices():
        if devmod.is_simulator(d) or d.platform_index in seen:
            continue
        seen.add(d.platform_index)
        out.append(d)
    return out


def pytest_addoption(parser):
    parser.addoption("--implementations", default=os.environ.get("VOLCL_TEST_IMPLEMENTATIONS", "all"),
                     help="OpenCL implementations for tests marked every_implementation: 'all' (default), "
                          "'default' (volcl's choice only) or comma-separated ids (pocl,intel)")


def pytest_configure(config):
    config.addinivalue_line("markers", "every_implementation: run on every OpenCL implementation present "
                                       "(parametrizes the device fixture)")
    import stats    # the sampling suite's family-wise significance covers every implementation tested
    stats.SUITE_TESTS = stats.SUITE_TESTS_PER_IMPLEMENTATION * len(_selected_implementations(config))


_selected = None


def _selected_implementations(config) -> list:
    global _selected
    if _selected is None:
        want = config.getoption("--implementations").strip().lower()
        if want == "default":
            _selected = [None]
        else:
            found = implementations()
            if want != "all":
                names = {w.strip() for w in want.split(",") if w.strip()}
                found = [d for d in found if implementation_id(d) in names]
            _selected = found or [None]
    return _selected


def pytest_generate_tests(metafunc):
    if "device" in metafunc.fixturenames and metafunc.definition.get_closest_marker("every_implementation"):
        devs = _selected_implementations(metafunc.config)
        metafunc.parametrize("device", devs, indirect=True, scope="session",
                             ids=[implementation_id(d) if d is not None else "default" for d in devs])


@pytest.fixture(scope="session")
def device(request):
    """The device volcl would choose (tests fail, not skip, when there is none); in tests marked
    every_implementation, each implementation present in turn."""
    param = getattr(request, "param", None)
    return param if param is not None else devmod.choose()


@pytest.fixture(scope="session")
def cl_env(device):
    """The device's own context and queue (volcl.device.Device), which renders share."""
    return device.ctx, device.queue


@pytest.fixture(scope="session")
def test_program(device):
    """Builds tests/kernels/<name> with every feature on (so every routine exists), once per
    session: the device's program cache keeps it."""
    def build(name, features=None):
        return device.program(features or all_features(), TEST_KERNELS / name)
    return build


def run_kernel(cl_env, program, name, n, outputs, *scalars, inputs=()):
    """Launch kernel `name` over n work items. outputs: list of (dtype, per-item shape); inputs: numpy
    arrays uploaded read-only and passed first. Returns the output arrays."""
    ctx, queue = cl_env
    mf = cl.mem_flags
    in_bufs = [cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(a)) for a in inputs]
    outs = [np.zeros((n,) + tuple(shape), dtype) for dtype, shape in outputs]
    out_bufs = [cl.Buffer(ctx, mf.WRITE_ONLY, max(o.nbytes, 4)) for o in outs]
    kernel = cl.Kernel(program, name)
    kernel(queue, (n,), None, *in_bufs, *out_bufs, *scalars)
    for o, b in zip(outs, out_bufs):
        cl.enqueue_copy(queue, o, b)
    queue.finish()
    return outs
