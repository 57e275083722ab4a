"""pyopencl, imported once the environment its drivers need is in place.

PoCL caches compiled kernels and fails without a writable cache directory, so POCL_CACHE_DIR is set
(when the user has not set it) before pyopencl loads any driver; drivers pip installed into this
Python environment are registered with the ICD loader (_register_pypi_drivers). Every module that
talks to OpenCL imports `cl` from here.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import sys
from pathlib import Path


def _prepare_environment():
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

__all__ = ["cl"]
