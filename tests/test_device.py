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


def test_a_name_selector_takes_platform_matches_first():
    """On an Intel CPU, PoCL's device is named after the CPU ("pthread-...-Intel(R) Xeon(R)"): a
    selector that names a platform takes that platform's devices before devices that merely carry
    the word in their names, whatever order the loader lists them in."""
    def dev(p, name, platform):
        return devmod.Device(p, 0, SimpleNamespace(name=name), platform)
    pocl = dev(0, "pthread-skylake-avx512-Intel(R) Xeon(R) Processor", "Portable Computing Language")
    intel = dev(1, "Intel(R) Xeon(R) Processor", "Intel(R) OpenCL")
    amd = dev(2, "AMD EPYC 7R13", "Portable Computing Language")
    for order in ([pocl, intel, amd], [intel, amd, pocl]):
        assert devmod._match(order, "intel")[0] is intel
        assert set(devmod._match(order, "Intel")) == {pocl, intel}
        assert devmod._match(order, "portable") == [d for d in order if d is not intel]
        assert devmod._match(order, "EPYC") == [amd]
        assert devmod._match(order, "1:0") == [intel]


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


def _counting_checks(monkeypatch, ok=True):
    """Fake build check and self-test that count their calls (the real ones are tested elsewhere)."""
    from volcl import selftest
    calls = []
    monkeypatch.setattr(devmod, "kernels_build", lambda d: (calls.append("build") or (True, "")))
    monkeypatch.setattr(selftest, "run", lambda d: (calls.append("self-test")
                                                    or selftest.SelfTest(ok, "ok" if ok else "furnace off", 0.0)))
    return calls


def _real_device():
    return next(d for d in devmod.list_devices() if not devmod.is_simulator(d))


def test_a_passed_check_is_trusted_by_later_processes(monkeypatch, tmp_path):
    """What a later process does: a fresh Device object for the same driver skips the build check
    and the self-test once one passed; VOLCL_DEVICE_CHECK=always checks again."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.delenv("VOLCL_DEVICE_CHECK", raising=False)
    calls = _counting_checks(monkeypatch)
    dev = _real_device()
    assert devmod.check(dev.fresh()) == (True, "") and calls == ["build", "self-test"]
    assert (tmp_path / "volcl" / "trusted.json").is_file()
    assert devmod.check(dev.fresh()) == (True, "") and calls == ["build", "self-test"]
    monkeypatch.setenv("VOLCL_DEVICE_CHECK", "always")
    assert devmod.check(dev.fresh()) == (True, "") and calls == ["build", "self-test"] * 2


def test_a_failed_check_is_not_remembered(monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.delenv("VOLCL_DEVICE_CHECK", raising=False)
    calls = _counting_checks(monkeypatch, ok=False)
    dev = _real_device()
    for _ in range(2):
        ok, why = devmod.check(dev.fresh())
        assert not ok and "self-test failed: furnace off" in why
    assert calls == ["build", "self-test"] * 2


def test_the_trust_key_changes_with_the_driver_and_the_kernels(monkeypatch):
    from volcl import program, trusted
    platform = SimpleNamespace(version="OpenCL 3.0 PoCL 5.0")
    cl_dev = SimpleNamespace(name="cpu", vendor="v", version="OpenCL 3.0", driver_version="5.0", platform=platform)
    dev = SimpleNamespace(device=cl_dev, platform_name="Portable Computing Language")
    keys = {trusted.key(dev)}
    cl_dev.driver_version = "5.1"
    keys.add(trusted.key(dev))
    platform.version = "OpenCL 3.0 PoCL 5.1"
    keys.add(trusted.key(dev))
    cl_dev.name = "another cpu"
    keys.add(trusted.key(dev))
    monkeypatch.setattr(program, "sources_hash", lambda: "0123456789abcdef")
    keys.add(trusted.key(dev))
    monkeypatch.setenv("VOLCL_BUILD_OPTIONS", "-cl-opt-disable")
    keys.add(trusted.key(dev))
    assert len(keys) == 6
