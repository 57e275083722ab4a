"""Devices that passed volcl's checks, remembered between processes.

Proving a device (volcl.device.check: the every-feature build and the self-test's renders) costs
most of a short render's start-up, and its answer depends only on what compiles and runs: volcl's
version and kernel sources, the build options, and the driver (platform and device name, version
and driver version; a CPU device's name carries the CPU model). A pass is recorded under a key of
all of these in volcl's cache folder, and a later process with the same key trusts the device
without repeating the work; any change of driver, kernels or options gives a new key and a new
check. Failures are never recorded (a device that failed is checked again, and says why).
VOLCL_DEVICE_CHECK=always makes every process check afresh.
"""
from __future__ import annotations

import hashlib
import json
import os
import time
from pathlib import Path

ENV = "VOLCL_DEVICE_CHECK"


def _path() -> Path:
    base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
    return base / "volcl" / "trusted.json"


def key(dev) -> str:
    """What a device's check depends on, hashed."""
    from . import __version__
    from .features import all_features
    from .program import build_options, sources_hash
    d, p = dev.device, dev.device.platform
    parts = [__version__, sources_hash(), " ".join(build_options(all_features())), dev.platform_name,
             p.version, d.name, d.vendor, d.version, d.driver_version]
    return hashlib.sha256("\n".join(str(x).strip() for x in parts).encode()).hexdigest()[:24]


def enabled() -> bool:
    return os.environ.get(ENV, "").strip().lower() != "always"


def _read() -> dict:
    try:
        data = json.loads(_path().read_text())
        return data if isinstance(data, dict) else {}
    except (OSError, ValueError):
        return {}


def passed_before(dev) -> bool:
    """Whether a device with this key passed the checks in an earlier process."""
    return enabled() and key(dev) in _read()


def record_pass(dev, seconds: float):
    """Remember that this device passed (a read-only cache only costs the next process a check)."""
    if not enabled():
        return
    path = _path()
    data = _read()
    data[key(dev)] = {"device": dev.name, "platform": dev.platform_name, "seconds": round(seconds, 3),
                      "when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(json.dumps(data, indent=1))
        os.replace(tmp, path)
    except OSError:
        pass
