"""OpenCL devices: listing them, proving volcl's kernels build on them, and choosing one.

A `Device` stands for one OpenCL device and owns what renders on it share: one context, one
command queue and one ProgramCache. There is one Device object per OpenCL device in a process
(`list_devices` and `choose` hand out the same objects), so a script that renders in a loop builds
each program once and never piles up contexts. What belongs to one scene (its buffers) or one
render (its accumulators, its kernel object) lives in volcl.upload and volcl.renderer, and goes
when they go.

A device is chosen by proving that volcl's kernels build on it and render known answers right
(volcl/selftest.py), never by its name: some drivers list a device whose compiler then fails every
build, and one compiler built kernels that computed wrong images.
"""
from __future__ import annotations

import os
import threading
import time
import warnings

from .errors import VolclError
from .opencl import cl
from .program import ENTRY_FILE, ProgramCache, program_key

# the --device value for every device volcl may render on (a render on several devices, volcl.rounds)
ALL = "all"
# Work-group size of every launch (where the device and kernel allow it), the global size rounded up
# to a multiple of it (the kernel ignores the items past the end): drivers that compile a kernel
# per work-group size (PoCL does, and picks a size from the global size when given none) then
# compile once, however many sizes of tiles and launches a render has.
GROUP_ITEMS = 64
INSTALL_HINT = ("install an OpenCL driver, e.g. on Debian: apt-get install pocl-opencl-icd "
                "(and binutils, which PoCL needs to link kernels)")


class Device:
    """One OpenCL device, with its context, queue and built programs (created when first needed)."""

    def __init__(self, platform_index: int, device_index: int, device, platform_name: str):
        self.platform_index = platform_index
        self.device_index = device_index
        self.device = device
        self.platform_name = platform_name
        self._lock = threading.Lock()
        self._ctx = None
        self._queue = None
        self._programs = None
        self._check = None          # (ok, why) of the build check, once made
        self._trusted = None        # (ok, why) of check(): build check and self-test, once made

    def __repr__(self) -> str:
        return f"<volcl.Device {self.key} {self.name!r} ({self.kind}, {self.platform_name})>"

    def fresh(self) -> "Device":
        """Another Device object for the same OpenCL device, with a context, queue and program cache
        of its own (and so scene uploads of its own): for a thread that should not share this
        one's queue. It is not in the list that devices() hands out."""
        return Device(self.platform_index, self.device_index, self.device, self.platform_name)

    @property
    def key(self) -> str:
        return f"{self.platform_index}:{self.device_index}"

    @property
    def name(self) -> str:
        return self.device.name.strip()

    @property
    def label(self) -> str:
        """How renders name the device (summaries, EXR metadata): index and name."""
        return f"{self.key} {self.name}"

    @property
    def kind(self) -> str:
        t = self.device.type
        if t & cl.device_type.GPU:
            return "gpu"
        if t & cl.device_type.CPU:
            return "cpu"
        return "accelerator" if t & cl.device_type.ACCELERATOR else "other"

    def _open(self):
        with self._lock:
            if self._ctx is None:
                ctx = cl.Context([self.device])
                self._queue = cl.CommandQueue(ctx)
                self._programs = ProgramCache(ctx)
                self._ctx = ctx

    @property
    def ctx(self):
        if self._ctx is None:
            self._open()
        return self._ctx

    @property
    def queue(self):
        if self._ctx is None:
            self._open()
        return self._queue

    @property
    def programs(self) -> ProgramCache:
        if self._ctx is None:
            self._open()
        return self._programs

    def program(self, features: dict, source_file=ENTRY_FILE, extra: tuple = ()):
        """The program for this feature set, built on the first request and kept."""
        return self.programs.get(features, source_file, extra)

    def has_program(self, features: dict, source_file=ENTRY_FILE, extra: tuple = ()) -> bool:
        return self._programs is not None and program_key(features, source_file, extra) in self._programs

    @property
    def builds(self) -> int:
        """Programs built on this device so far in this process."""
        return 0 if self._programs is None else self._programs.builds


# Device objects by OpenCL device, so every listing hands out the same ones.
_devices: dict = {}
_devices_lock = threading.Lock()

# The older name of Device.
DeviceInfo = Device


def list_devices() -> list[Device]:
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
        for di, d in enumerate(devices):
            key = (pi, di, d.int_ptr)
            with _devices_lock:
                if key not in _devices:
                    _devices[key] = Device(pi, di, d, p.name.strip())
                out.append(_devices[key])
    return out


def kernels_build(dev: Device) -> tuple[bool, str]:
    """Whether volcl's render kernel (every feature on) builds on this device, and why not. The
    answer is kept: a device is checked once per process, and the program built stays in its
    cache."""
    if dev._check is None:
        from .features import all_features
        try:
            dev.program(all_features())
            dev._check = (True, "")
        except Exception as exc:  # any driver failure means: not usable
            text = str(exc).strip().splitlines()
            dev._check = (False, text[-1] if text else type(exc).__name__)
    return dev._check


class DeviceSkipped(UserWarning):
    """A device the default choice passed over because volcl's kernels fail on it."""


def is_simulator(dev: Device) -> bool:
    """Oclgrind simulates a device thousands of times slower than any real one: it is used only
    when selected by name, and not self-tested (the test would take many minutes)."""
    return "oclgrind" in dev.platform_name.lower()


def check(dev: Device) -> tuple[bool, str]:
    """Whether volcl can trust this device: its kernels build (every feature on) and it passes the
    self-test (volcl/selftest.py); otherwise why not. Checked once per device and process, and
    not at all where the same driver passed with the same kernels before (volcl.trusted)."""
    if dev._trusted is None:
        from . import trusted
        if not is_simulator(dev) and trusted.passed_before(dev):
            dev._trusted = (True, "")
            return dev._trusted
        t0 = time.perf_counter()
        ok, why = kernels_build(dev)
        if not ok:
            why = f"kernels do not build: {why}"
        elif not is_simulator(dev):
            from . import selftest
            result = selftest.run(dev)
            ok, why = result.ok, ("" if result.ok else f"self-test failed: {result.message}")
            if ok:
                trusted.record_pass(dev, time.perf_counter() - t0)
        dev._trusted = (ok, why)
    return dev._trusted


def is_pocl(dev) -> bool:
    """Whether the device is PoCL's (anything with a platform_name)."""
    return "portable computing language" in dev.platform_name.lower()


def _preference(dev: Device) -> tuple:
    """Default order: GPUs, then PoCL's CPU device, then other devices in platform order. On the
    AVX2 hosts measured PoCL rendered as fast as Intel's runtime or faster on every scene (README,
    "Throughput on each implementation"); on an AVX-512 host Intel's was 1.01-1.15x faster per CPU
    second, but its first build of a feature set takes seconds, and the tests' default device is
    PoCL. The loader's platform order follows the order of files in a folder, which is no order at
    all."""
    return (dev.kind != "gpu", not is_pocl(dev))


def _match(devs: list[Device], sel: str) -> list[Device]:
    sel = sel.strip()
    if sel.lower() in ("cpu", "gpu"):
        return [d for d in devs if d.kind == sel.lower()]
    if ":" in sel and all(part.isdigit() for part in sel.split(":", 1)):
        return [d for d in devs if d.key == sel]
    if sel.isdigit():
        return [d for d in devs if d.key == f"0:{sel}"]
    # platforms first: a CPU's model name ("Intel(R) Xeon(R)") is also in other runtimes' device
    # names, and --device Intel means Intel's runtime before PoCL's device on that CPU
    s = sel.lower()
    by_platform = [d for d in devs if s in d.platform_name.lower()]
    return by_platform + [d for d in devs if s in d.name.lower() and d not in by_platform]


def choose(selector: str | None = None) -> Device:
    """The device to render on: `selector` (or VOLCL_DEVICE) narrows the candidates; among them the
    first that passes check() (kernels build, self-test passes) wins, in _preference's order. Each
    candidate passed over is named in a DeviceSkipped warning; simulators are candidates only when
    the selector names them. A selector of several devices ('all', 'A,B') gives the first of them
    (choose_many gives them all)."""
    selector = selector or os.environ.get("VOLCL_DEVICE") or None
    if selector and (selector.strip() == ALL or "," in selector):
        return choose_many(selector)[0]         # what renders on one device takes of a set
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


def usable(dev: Device) -> tuple[bool, str]:
    """Whether volcl may render on this device as one of 'all' (its kernels build and it passes the
    self-test; a simulator never does), and why not."""
    if is_simulator(dev):
        return False, "a simulator, used only when named"
    return check(dev)


def choose_many(selector: str | None = None) -> list[Device]:
    """The devices of one render: 'all' (every device volcl may render on), 'A,B,...' (each part
    chosen as `choose` chooses), or one selector (one device). None: VOLCL_DEVICE, else the one
    device `choose` picks."""
    selector = selector or os.environ.get("VOLCL_DEVICE") or None
    if selector is None:
        return [choose()]
    parts = [p.strip() for p in selector.split(",")]
    if any(not p for p in parts):
        raise VolclError(f"--device {selector!r}: an empty name in the list; give 'all', one device "
                         "('P:D', a name substring, 'cpu', 'gpu') or several separated by commas ('0:0,0:1')")
    if parts == [ALL]:
        devs = list_devices()
        if not devs:
            raise VolclError(f"no OpenCL device found; {INSTALL_HINT}")
        good, failures = [], []
        for d in devs:
            ok, why = usable(d)
            (good.append(d) if ok else failures.append(f"{d.key} {d.name} ({d.platform_name}): {why}"))
        if not good:
            raise VolclError("no OpenCL device passes volcl's checks (" + "; ".join(failures) + f"); {INSTALL_HINT}")
        for f in failures:
            warnings.warn(f"--device all: skipping OpenCL device {f}", DeviceSkipped, stacklevel=2)
        return good
    if ALL in parts:
        raise VolclError(f"--device {selector!r}: 'all' stands alone, not in a list")
    return _distinct([choose(p) for p in parts], selector)


def _distinct(devs: list, what) -> list:
    seen = set()
    for d in devs:
        if id(d) in seen:
            raise VolclError(f"--device {what!r} names device {d.key} {d.name} twice; name each device once")
        seen.add(id(d))
    return devs


def resolve_many(device=None) -> list[Device]:
    """The devices of one render from what a caller may pass: a Device, a list of Devices and
    selectors, a selector string ('all', 'A,B', 'P:D', a name substring, 'cpu', 'gpu') or None
    (VOLCL_DEVICE, else the first device whose kernels build)."""
    if isinstance(device, Device):
        return [device]
    if device is None or isinstance(device, str):
        return choose_many(device)
    if isinstance(device, (list, tuple)):
        if not device:
            raise VolclError("device: an empty list of devices")
        return _distinct([d for item in device for d in resolve_many(item)], device)
    raise TypeError(f"device: expected a volcl Device, a list of them, a selector string or None, not "
                    f"{type(device).__name__}")


def resolve(device=None) -> Device:
    """A Device from what a caller may pass: a Device, a selector string ('P:D', a name
    substring, 'cpu', 'gpu'), or None (VOLCL_DEVICE, else the first device choose() trusts)."""
    if isinstance(device, Device):
        return device
    if device is None or isinstance(device, str):
        return choose(device)
    raise TypeError(f"device: expected a volcl Device, a selector string or None, not {type(device).__name__}")


def _size(n: int) -> str:
    return f"{n / 2**20:.1f} MiB" if n < 2**30 else f"{n / 2**30:.2f} GiB"


# what to cut down when one buffer is too large
_FEWER = {"texels": "smaller or fewer textures", "tri_uvs": "fewer textured triangles",
          "grid_data": "smaller volume grids", "env_data": "a smaller environment map"}


def check_fits(info: Device, buffers: dict[str, int], accumulator_bytes: int = 0, notes: str = "") -> None:
    """Raise VolclError when a scene's buffers (name -> bytes) cannot live on the device: one of them
    above its largest single allocation, or all of them (with the image accumulators) above its
    global memory. Checked before anything is uploaded, so the user gets the numbers instead of a
    driver's out-of-resources error (or a crash) halfway through. `notes` (what the largest parts
    cost, e.g. sparse grids' bytes per active voxel) ends the message."""
    dev = info.device
    max_alloc, global_mem = int(dev.max_mem_alloc_size), int(dev.global_mem_size)
    name, biggest = max(buffers.items(), key=lambda item: item[1])
    if biggest > max_alloc:
        fewer = _FEWER.get(name, "fewer triangles")
        raise VolclError(f"the scene is too large for device {info.key} {info.name}: its {name} buffer "
                         f"needs {_size(biggest)} ({biggest} bytes), but the device allocates at most "
                         f"{_size(max_alloc)} ({max_alloc} bytes) in one buffer; simplify the scene "
                         f"({fewer}) or choose a device with more memory (--device)" + notes)
    total = sum(buffers.values()) + accumulator_bytes
    if total > global_mem:
        raise VolclError(f"the scene is too large for device {info.key} {info.name}: its buffers and "
                         f"image accumulators need {_size(total)} ({total} bytes), but the device has "
                         f"{_size(global_mem)} ({global_mem} bytes) of global memory; simplify the scene "
                         f"or lower the resolution, or choose a device with more memory (--device)" + notes)


def group_items(kernels, device) -> int:
    """GROUP_ITEMS, or the largest power of two below it that every one of `kernels` runs with on
    the OpenCL device `device`."""
    limit = int(device.max_work_group_size)
    for kernel in kernels:
        limit = min(limit, int(kernel.get_work_group_info(cl.kernel_work_group_info.WORK_GROUP_SIZE, device)))
    n = GROUP_ITEMS
    while n > limit:
        n //= 2
    return max(n, 1)
