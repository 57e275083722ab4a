"""Shared fixtures: the OpenCL device the tests run on, and test-kernel builds."""
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


@pytest.fixture(scope="session")
def device():
    """The device volcl would choose: tests fail (not skip) when there is none."""
    return devmod.choose()


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
