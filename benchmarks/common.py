"""Small pieces the benchmark scripts share. Standard library only: mitsuba_ref.py imports this
from inside the Python that has Mitsuba, which need not have volcl."""
from __future__ import annotations

import platform
import sys
from pathlib import Path


def log(msg):
    """Progress for stderr (the tables go to stdout)."""
    print(msg, file=sys.stderr, flush=True)


def cpu_model() -> str:
    """The CPU's model name with its widest vector extension: hosts of the same model name
    differ there (an AMD EPYC with AVX2 only or with AVX-512), and Mitsuba's LLVM backend's
    speed follows the vector width, so a figure means little without it."""
    model, simd = platform.processor() or "unknown", None
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:
        return model
    for line in lines:
        key, _, value = line.partition(":")
        key = key.strip()
        if key == "model name":
            model = value.strip()
        elif key in ("flags", "Features") and simd is None:
            simd = widest_simd(set(value.split()))
    return f"{model} ({simd})" if simd else model


def widest_simd(flags: set) -> str | None:
    """The widest vector extension named in a /proc/cpuinfo flags (x86) or Features (Arm) line."""
    for flag, name in (("avx512f", "AVX-512"), ("avx2", "AVX2"), ("avx", "AVX"), ("sse4_2", "SSE4.2"),
                       ("sve2", "SVE2"), ("sve", "SVE"), ("asimd", "NEON")):
        if flag in flags:
            return name
    return None


def parse_defines(items) -> dict:
    """-D name=value arguments as a dict."""
    out = {}
    for item in items or []:
        if "=" not in item:
            raise SystemExit(f"-D {item!r}: expected name=value")
        k, v = item.split("=", 1)
        out[k.strip()] = v
    return out


def bumpy_sphere(rng, n_tris):
    """A latitude-longitude unit sphere (z up) with a smooth radial bump pattern and a little noise,
    about n_tris triangles: (vertices (n, 3), faces (m, 3)). numpy is imported here so that the
    rest of this module stays standard-library only."""
    import numpy as np
    rows = max(2, int(np.sqrt(n_tris / 4)))
    cols = max(3, n_tris // (2 * rows))
    theta = np.linspace(0.0, np.pi, rows + 1)
    phi = np.linspace(0.0, 2.0 * np.pi, cols + 1)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    r = 1.0 + 0.05 * np.sin(7 * t) * np.cos(5 * p) + 0.002 * rng.standard_normal(t.shape)
    verts = np.stack([r * np.sin(t) * np.cos(p), r * np.sin(t) * np.sin(p), r * np.cos(t)], -1).reshape(-1, 3)
    idx = np.arange((rows + 1) * (cols + 1)).reshape(rows + 1, cols + 1)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    faces = np.concatenate([np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)])
    return verts, faces
