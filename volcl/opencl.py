"""pyopencl, imported once the environment its drivers need is in place.

PoCL caches compiled kernels and fails without a writable cache directory, so POCL_CACHE_DIR is set
(when the user has not set it) before pyopencl loads any driver. Every module that talks to OpenCL
imports `cl` from here.
"""
from __future__ import annotations

import os
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


_prepare_environment()
import pyopencl as cl  # noqa: E402  (needs the environment above)

__all__ = ["cl"]
