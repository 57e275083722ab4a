"""Finding the OpenCL sources and building the render program once per feature set and device.

Sources live in the top-level kernels/ folder of a checkout and ship inside the installed package
as volcl/kernels; they are compiled with -I so compiler messages name the real file and line.
Built programs are kept in memory by a ProgramCache, one per OpenCL context (volcl.device.Device
owns both), and on disk by pyopencl and the driver; the options carry a hash of every kernel file,
so an edited header can never reuse a stale binary.
"""
from __future__ import annotations

import hashlib
import json
import os
import shlex
import threading
import time
import warnings
from functools import lru_cache
from pathlib import Path

from . import features as feat
from .opencl import cl

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


def _source_path(source_file) -> Path:
    # test kernels pass a path of their own; they include volcl's headers through -I
    return Path(source_file) if Path(source_file).is_absolute() else kernels_dir() / source_file


def build_program(ctx, features: dict[str, bool], source_file=ENTRY_FILE, extra: tuple[str, ...] = ()):
    """Build the program for `ctx` now (pyopencl's and the driver's disk caches may make it quick);
    nothing is kept in memory. Renders get their programs from a ProgramCache instead."""
    src = _source_path(source_file).read_text()
    with warnings.catch_warnings():
        # Intel's compiler always logs (remarks, "Kernel was not vectorized"); pyopencl turns any
        # log into a CompilerWarning. Kernel warnings are caught by tests/test_kernel_warnings.py.
        warnings.simplefilter("ignore", cl.CompilerWarning)
        return cl.Program(ctx, src).build(options=build_options(features, extra))


def program_key(features: dict[str, bool], source_file=ENTRY_FILE, extra: tuple[str, ...] = ()) -> tuple:
    # the environment's options are part of the key: changing VOLCL_BUILD_OPTIONS rebuilds
    return (str(source_file), tuple(sorted((k, bool(v)) for k, v in features.items())), tuple(extra),
            tuple(env_build_options()))


class ProgramCache:
    """The programs built for one OpenCL context, each built once: keyed by source file, feature set
    and extra options. Safe to use from several threads (a program asked for by two threads at
    once is built once)."""

    def __init__(self, ctx):
        self.ctx = ctx
        self._programs: dict[tuple, object] = {}
        self._seconds: dict[tuple, float] = {}
        self._lock = threading.Lock()
        self.builds = 0             # programs built (not found in memory) so far

    def __contains__(self, key) -> bool:
        return key in self._programs

    def __len__(self) -> int:
        return len(self._programs)

    def get(self, features: dict[str, bool], source_file=ENTRY_FILE, extra: tuple[str, ...] = ()):
        key = program_key(features, source_file, extra)
        prog = self._programs.get(key)
        if prog is not None:
            return prog
        with self._lock:
            prog = self._programs.get(key)
            if prog is None:
                t0 = time.perf_counter()
                prog = build_program(self.ctx, features, source_file, extra)
                self._seconds[key] = time.perf_counter() - t0
                self._programs[key] = prog
                self.builds += 1
        return prog

    def seconds(self, features: dict[str, bool], source_file=ENTRY_FILE, extra: tuple[str, ...] = ()) -> float:
        """How long building this program took (0 if it was never built here)."""
        return self._seconds.get(program_key(features, source_file, extra), 0.0)

    def seconds_of(self, features: dict[str, bool], sources) -> float:
        """How long building these programs took: `sources` are (source file, extra options) pairs."""
        return sum(self.seconds(features, f, extra) for f, extra in sources)


def _build_log_path() -> Path:
    return Path(os.environ.get("POCL_CACHE_DIR", ".")).parent / "builds.json"


def note_build(device_name: str, features: dict[str, bool], seconds: float, engine: str = "") -> tuple[float, bool]:
    """Remember the first (cold) build time of each kernel version, feature set, device and engine
    (the megakernel's: "", or "wavefront"), so a later warm build can be shown beside it. Returns
    (cold seconds, whether this build was it)."""
    key = f"{sources_hash()} {device_name} {feat.describe(features)}" + (f" {engine}" if engine else "")
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
