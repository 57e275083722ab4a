"""OpenCL devices: listing them, proving volcl's kernels build on them, and choosing one.

A device is chosen by proving that a kernel builds on it, never by its name: some drivers list a
device whose compiler then fails every build.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path

from .errors import VolclError

INSTALL_HINT = ("install an OpenCL driver, e.g. on Debian: apt-get install pocl-opencl-icd "
                "(and binutils, which PoCL needs to link kernels)")


def _prepare_environment():
    """PoCL caches compiled kernels and fails without a writable cache directory."""
    if "POCL_CACHE_DIR" not in os.environ:
        base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
        cache = base / "volcl" / "pocl"
        try:
            cache.mkdir(parents=True, exist_ok=True)
        except OSError:
            import tempfile
            cache = Path(tempfile.gettempdir()) / f"volcl-pocl-{os.getuid()}"
            cache.mkdir(parents=True, exist_ok=True)
        os.environ["POCL_CACHE_DIR"] = str(cache)


# OpenCL drivers that install from PyPI into a Python environment, with no system .icd file:
# Intel's CPU runtime (intel-opencl-rt) puts libintelocl.so in <prefix>/lib.
PYPI_DRIVERS = ("libintelocl.so",)
SYSTEM_VENDORS = Path("/etc/OpenCL/vendors")


def _cache_base() -> Path:
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "volcl"


def _register_pypi_drivers():
    """Make drivers installed by pip into this environment visible to the OpenCL loader.

    The ICD loader finds drivers through the .icd files in /etc/OpenCL/vendors, or in the folder
    OCL_ICD_VENDORS names instead: that folder replaces the system one, it does not add to it. So
    when this environment holds such a driver and OCL_ICD_VENDORS is unset, volcl writes a folder
    with an .icd file for it beside a copy of every system .icd file (PoCL, GPU drivers), and
    points OCL_ICD_VENDORS there for this process. A user's own OCL_ICD_VENDORS is left alone."""
    if "OCL_ICD_VENDORS" in os.environ:
        return
    libs = [p for p in (Path(sys.prefix) / "lib" / name for name in PYPI_DRIVERS) if p.is_file()]
    if not libs:
        return
    system = os.environ.get("OPENCL_VENDOR_PATH", str(SYSTEM_VENDORS))
    entries = {}
    try:
        for f in sorted(Path(system).glob("*.icd")):
            entries[f.name] = f.read_text()
    except OSError:
        pass
    for lib in libs:
        entries[f"pypi-{lib.stem}.icd"] = f"{lib}\n"
    digest = hashlib.sha256(repr(sorted(entries.items())).encode()).hexdigest()[:16]
    import tempfile
    for base in (_cache_base(), Path(tempfile.gettempdir()) / f"volcl-{os.getuid()}"):
        folder = base / f"icd-{digest}"
        try:
            if not folder.is_dir():
                tmp = base / f"icd-{digest}.{os.getpid()}.tmp"
                tmp.mkdir(parents=True, exist_ok=True)
                for name, text in entries.items():
                    (tmp / name).write_text(text)
                try:
                    os.rename(tmp, folder)
                except OSError:     # another process made it first
                    shutil.rmtree(tmp, ignore_errors=True)
            os.environ["OCL_ICD_VENDORS"] = str(folder)
            return
        except OSError:
            continue


_prepare_environment()
_register_pypi_drivers()
import pyopencl as cl  # noqa: E402  (needs the environment above)


@dataclass
class DeviceInfo:
    platform_index: int
    device_index: int
    device: object
    platform_name: str

    @property
    def key(self) -> str:
        return f"{self.platform_index}:{self.device_index}"

    @property
    def name(self) -> str:
        return self.device.name.strip()

    @property
    def kind(self) -> str:
        t = self.device.type
        if t & cl.device_type.GPU:
            return "gpu"
        if t & cl.device_type.CPU:
            return "cpu"
        return "accelerator" if t & cl.device_type.ACCELERATOR else "other"


def list_devices() -> list[DeviceInfo]:
    try:
        platforms = cl.get_platforms()
    except cl.Error:
        return []
    out = []
    for pi, p in enumerate(platforms):
        try:
            devices = p.get_devices()
        except cl.Error:
            continue
        out.extend(DeviceInfo(pi, di, d, p.name.strip()) for di, d in enumerate(devices))
    return out


def kernels_build(info: DeviceInfo) -> tuple[bool, str]:
    """Whether volcl's render kernel (every feature on) builds on this device, and why not."""
    from .program import build_program
    from .features import all_features
    try:
        ctx = cl.Context([info.device])
        build_program(ctx, all_features())
        return True, ""
    except Exception as exc:  # any driver failure means: not usable
        text = str(exc).strip().splitlines()
        return False, text[-1] if text else type(exc).__name__


class DeviceSkipped(UserWarning):
    """A device the default choice passed over because volcl's kernels fail on it."""


def is_simulator(info: DeviceInfo) -> bool:
    """Oclgrind simulates a device thousands of times slower than any real one: it is used only
    when selected by name, and not self-tested (the test would take many minutes)."""
    return "oclgrind" in info.platform_name.lower()


_checked: dict = {}


def check(info: DeviceInfo) -> tuple[bool, str]:
    """Whether volcl can trust this device: its kernels build (every feature on) and it passes the
    self-test (volcl/selftest.py); otherwise why not. Checked once per device and process."""
    key = (info.platform_index, info.device_index, info.platform_name, info.name)
    if key not in _checked:
        ok, why = kernels_build(info)
        if ok and not is_simulator(info):
            from . import selftest
            result = selftest.run(info)
            ok, why = result.ok, ("" if result.ok else f"self-test failed: {result.message}")
        elif not ok:
            why = f"kernels do not build: {why}"
        _checked[key] = (ok, why)
    return _checked[key]


def _match(devs: list[DeviceInfo], sel: str) -> list[DeviceInfo]:
    sel = sel.strip()
    if sel.lower() in ("cpu", "gpu"):
        return [d for d in devs if d.kind == sel.lower()]
    if ":" in sel and all(part.isdigit() for part in sel.split(":", 1)):
        return [d for d in devs if d.key == sel]
    if sel.isdigit():
        return [d for d in devs if d.key == f"0:{sel}"]
    return [d for d in devs if sel.lower() in d.name.lower() or sel.lower() in d.platform_name.lower()]


def _preference(info: DeviceInfo) -> tuple:
    """Default order: GPUs, then PoCL's CPU device, then other devices in platform order. On CPUs
    PoCL rendered as fast as Intel's runtime or faster on every scene measured (README, "Throughput
    on each implementation"), and the loader's platform order follows the order of files in a
    folder, which is no order at all."""
    return (info.kind != "gpu", "portable computing language" not in info.platform_name.lower())


def choose(selector: str | None = None) -> DeviceInfo:
    """The device to render on: `selector` (or VOLCL_DEVICE) narrows the candidates; among them the
    first that passes check() (kernels build, self-test passes) wins, in _preference's order.
    Each candidate passed over is named in a DeviceSkipped warning; simulators are candidates only
    when the selector names them."""
    selector = selector or os.environ.get("VOLCL_DEVICE") or None
    devs = list_devices()
    if not devs:
        raise VolclError(f"no OpenCL device found; {INSTALL_HINT}")
    if selector:
        candidates = _match(devs, selector)
        if not candidates:
            listing = ", ".join(f"{d.key} {d.name} ({d.kind})" for d in devs)
            raise VolclError(f"no OpenCL device matches --device {selector!r}; available: {listing}; "
                             "select by index 'P:D', a name substring, 'cpu' or 'gpu'")
    else:
        candidates = sorted((d for d in devs if not is_simulator(d)), key=_preference)
    failures = []
    for d in candidates:
        ok, why = check(d)
        if ok:
            return d
        failures.append(f"{d.key} {d.name} ({d.platform_name}): {why}")
        warnings.warn(f"skipping OpenCL device {failures[-1]}", DeviceSkipped, stacklevel=2)
    raise VolclError("no OpenCL device passes volcl's checks (" + "; ".join(failures) + f"); {INSTALL_HINT}")


def _size(n: int) -> str:
    return f"{n / 2**20:.1f} MiB" if n < 2**30 else f"{n / 2**30:.2f} GiB"


def check_fits(info: DeviceInfo, buffers: dict[str, int], accumulator_bytes: int = 0) -> None:
    """Raise VolclError when a scene's buffers (name -> bytes) cannot live on the device: one of them
    above its largest single allocation, or all of them (with the image accumulators) above its
    global memory. Checked before anything is uploaded, so the user gets the numbers instead of a
    driver's out-of-resources error (or a crash) halfway through."""
    dev = info.device
    max_alloc, global_mem = int(dev.max_mem_alloc_size), int(dev.global_mem_size)
    name, biggest = max(buffers.items(), key=lambda item: item[1])
    if biggest > max_alloc:
        raise VolclError(f"the scene is too large for device {info.key} {info.name}: its {name} buffer "
                         f"needs {_size(biggest)} ({biggest} bytes), but the device allocates at most "
                         f"{_size(max_alloc)} ({max_alloc} bytes) in one buffer; simplify the scene "
                         f"(fewer triangles) or choose a device with more memory (--device)")
    total = sum(buffers.values()) + accumulator_bytes
    if total > global_mem:
        raise VolclError(f"the scene is too large for device {info.key} {info.name}: its buffers and "
                         f"image accumulators need {_size(total)} ({total} bytes), but the device has "
                         f"{_size(global_mem)} ({global_mem} bytes) of global memory; simplify the scene "
                         f"or lower the resolution, or choose a device with more memory (--device)")
