"""Finding the OpenCL sources and building the render program once per feature set.

Sources live in the top-level kernels/ folder of a checkout and ship inside the installed package
as volcl/kernels; they are compiled with -I so compiler messages name the real file and line.
Builds are cached in memory per (context, feature set) and on disk by pyopencl and the driver; the
options carry a hash of every kernel file, so an edited header can never reuse a stale binary.
"""
from __future__ import annotations

import hashlib
import json
import os
import shlex
import time
import warnings
from functools import lru_cache
from pathlib import Path

from . import features as feat
from .device import cl

ENTRY_FILE = "render.cl"


@lru_cache(maxsize=None)
def kernels_dir() -> Path:
    here = Path(__file__).resolve().parent
    for candidate in (here / "kernels", here.parent / "kernels"):
        if (candidate / ENTRY_FILE).is_file():
            return candidate
    raise FileNotFoundError(f"volcl's OpenCL sources ({ENTRY_FILE}) are neither in {here / 'kernels'} "
                            f"nor in {here.parent / 'kernels'}; the installation is incomplete")


@lru_cache(maxsize=None)
def sources_hash() -> str:
    h = hashlib.sha256()
    for f in sorted(kernels_dir().glob("*")):
        if f.suffix in (".cl", ".h"):
            h.update(f.name.encode())
            h.update(f.read_bytes())
    return h.hexdigest()[:16]


def env_build_options() -> list[str]:
    """Options from VOLCL_BUILD_OPTIONS, appended to every kernel build (shell-style quoting), so
    tools such as Oclgrind (which needs -cl-opt-disable) or a driver's own flags can be used
    without editing code."""
    return shlex.split(os.environ.get("VOLCL_BUILD_OPTIONS", ""))


def build_options(features: dict[str, bool], extra: tuple[str, ...] = ()) -> list[str]:
    return ([f"-I{kernels_dir()}", "-cl-std=CL1.2", f"-DVOLCL_SOURCE_HASH=0x{sources_hash()}"]
            + feat.defines(features) + list(extra) + env_build_options())


_cache: dict = {}
last_build_seconds: dict = {}


def _key(ctx, features, source_file, extra) -> tuple:
    # the environment's options are part of the key: changing VOLCL_BUILD_OPTIONS rebuilds
    return (id(ctx), str(source_file), tuple(sorted(features.items())), tuple(extra),
            tuple(env_build_options()))


def build_program(ctx, features: dict[str, bool], source_file=ENTRY_FILE,
                  extra: tuple[str, ...] = ()):
    """The built program for this context and feature set; built at most once per process."""
    key = _key(ctx, features, source_file, extra)
    prog = _cache.get(key)
    if prog is None:
        # test kernels pass a path of their own; they include volcl's headers through -I
        path = Path(source_file) if Path(source_file).is_absolute() else kernels_dir() / source_file
        src = path.read_text()
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            # Intel's compiler always logs (remarks, "Kernel was not vectorized"); pyopencl turns any
            # log into a CompilerWarning. Kernel warnings are caught by tests/test_kernel_warnings.py.
            warnings.simplefilter("ignore", cl.CompilerWarning)
            prog = cl.Program(ctx, src).build(options=build_options(features, extra))
        last_build_seconds[key] = time.perf_counter() - t0
        _cache[key] = (prog, ctx)   # keep ctx alive so id(ctx) is never reused by another context
        return prog
    return prog[0]


def build_seconds(ctx, features, source_file: str = ENTRY_FILE, extra: tuple[str, ...] = ()) -> float:
    return last_build_seconds.get(_key(ctx, features, source_file, extra), 0.0)


def _build_log_path() -> Path:
    return Path(os.environ.get("POCL_CACHE_DIR", ".")).parent / "builds.json"


def note_build(device_name: str, features: dict[str, bool], seconds: float) -> tuple[float, bool]:
    """Remember the first (cold) build time of each kernel version, feature set and device, so a
    later warm build can be shown beside it. Returns (cold seconds, whether this build was it)."""
    key = f"{sources_hash()} {device_name} {feat.describe(features)}"
    path = _build_log_path()
    try:
        log = json.loads(path.read_text())
    except (OSError, ValueError):
        log = {}
    if key in log:
        return float(log[key]), False
    log[key] = round(seconds, 4)
    try:
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(json.dumps(log, indent=0))
        os.replace(tmp, path)
    except OSError:
        pass    # a read-only cache only costs the cold/warm comparison
    return seconds, True
