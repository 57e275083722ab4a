"""Device selection and device limits: a user-caused problem is a VolclError with the numbers."""
from types import SimpleNamespace

import numpy as np
import pytest

from scenebuild import furnace
from volcl import device as devmod
from volcl.errors import VolclError
from volcl.renderer import Renderer


def test_unknown_device_selector_lists_what_exists():
    with pytest.raises(VolclError) as info:
        devmod.choose("no-such-device-anywhere")
    message = str(info.value)
    assert "no OpenCL device matches --device 'no-such-device-anywhere'" in message
    assert "available:" in message and "'P:D'" in message


def test_device_index_out_of_range():
    with pytest.raises(VolclError, match="no OpenCL device matches --device '99:99'"):
        devmod.choose("99:99")


def _small_device(global_mem, max_alloc):
    dev = SimpleNamespace(name="Tiny Test Device", global_mem_size=global_mem, max_mem_alloc_size=max_alloc)
    return devmod.DeviceInfo(7, 3, dev, "test platform")


def test_scene_above_the_largest_allocation(device):
    """Checked before any upload: the packed buffers against CL_DEVICE_MAX_MEM_ALLOC_SIZE."""
    sc = furnace(0.5)
    with pytest.raises(VolclError) as info:
        Renderer(sc, device=_small_device(global_mem=1 << 30, max_alloc=256))
    message = str(info.value)
    assert "too large for device 7:3 Tiny Test Device" in message
    assert "at most 0.0 MiB (256 bytes) in one buffer" in message
    assert "buffer needs" in message


def test_scene_above_global_memory(device):
    sc = furnace(0.5)
    sc.camera.width, sc.camera.height = 4096, 4096       # accumulators: 40 bytes per pixel
    with pytest.raises(VolclError) as info:
        Renderer(sc, device=_small_device(global_mem=64 << 20, max_alloc=64 << 20))
    message = str(info.value)
    assert "image accumulators need 640.0 MiB" in message and "64.0 MiB (67108864 bytes) of global memory" in message


def test_check_fits_names_the_buffer():
    info = _small_device(global_mem=10_000, max_alloc=1_000)
    devmod.check_fits(info, {"nodes": 1_000, "triangles": 900})
    with pytest.raises(VolclError, match=r"its triangles buffer needs .*\(1001 bytes\)"):
        devmod.check_fits(info, {"nodes": 10, "triangles": 1_001})
    with pytest.raises(VolclError, match=r"need .*\(10001 bytes\)"):
        devmod.check_fits(info, {"nodes": 1_000, "triangles": 1_000}, accumulator_bytes=8_001)


def test_a_normal_scene_fits_the_real_device(device):
    r = Renderer(furnace(0.5), device=device)
    assert np.isfinite(r.render(1).image).all()
